"""Benchmark figures: their legends never cover a map or a bar."""

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg

from fusionkit.plotting import plot_bench_case, plot_bench_summary


def _payload(data, resolution=0.1, origin=(0.0, 0.0, 0.0)):
    return {"data": np.asarray(data, np.int8).tolist(), "resolution": resolution, "origin": list(origin)}


def _case_record(methods):
    world = np.zeros((40, 40), np.int8)
    world[0, :] = world[-1, :] = world[:, 0] = world[:, -1] = 100
    fused = world.copy()
    fused[:, 20:] = -1                      # the fused map knows the left half only
    return {"index": 3, "robots": 2, "world": "box", "mode": "crop",
            "methods": {m: {"maps": [{"map": 1, "status": "success"}]} for m in methods},
            "_grids": {"world": _payload(world), "ref_true": {"x": 0.0, "y": 0.0, "theta": 0.0},
                       "fused": {m: _payload(fused) for m in methods}}}


def _overlaps(a, b) -> bool:
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


def _drawn(fig):
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return canvas.get_renderer()


@pytest.mark.parametrize("cols", [1, 3])
def test_a_bench_case_keeps_its_legend_off_the_maps(cols):
    fig = plot_bench_case(_case_record(["consensus", "map-merge", "fourier-mellin"]), cols=cols)
    renderer = _drawn(fig)
    panels = [ax for ax in fig.axes if ax.get_visible()]
    assert len(panels) == 3
    assert all(ax.get_legend() is None for ax in panels)
    assert len(fig.legends) == 1
    box = fig.legends[0].get_window_extent(renderer)
    assert not any(_overlaps(box, ax.get_window_extent(renderer)) for ax in panels)
    # the title is whole: it fits in the figure's width
    title = fig._suptitle.get_window_extent(renderer)
    assert title.x0 >= 0 and title.x1 <= fig.bbox.width


def test_a_bench_summary_keeps_its_legends_off_the_bars():
    summary = {"methods": {m: {"success": 4, "wrong": 0, "refused": 0} for m in ("consensus", "map-merge")},
               "by": {"mode": {"crop": {m: {"success_rate": 100.0} for m in ("consensus", "map-merge")}}}}
    fig = plot_bench_summary(summary)
    renderer = _drawn(fig)
    for ax in fig.axes:
        legend = ax.get_legend()
        assert legend is not None
        assert not _overlaps(legend.get_window_extent(renderer), ax.get_window_extent(renderer))


def _fused_two():
    from fusionkit.fusion import fuse_maps
    from fusionkit.grid import OccupancyGrid
    from fusionkit.transform import Transform2D

    data = np.zeros((30, 30), np.int8)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    a = OccupancyGrid(data, 0.1, (0.0, 0.0, 0.0))
    b = OccupancyGrid(data.copy(), 0.1, (1.0, 0.5, 0.0))
    return fuse_maps([a, b], [Transform2D(0.0, 0.0, 0.0), Transform2D(0.0, 0.0, 0.0)], keep_steps=True)


def test_a_fused_map_keeps_its_legend_off_the_map():
    from matplotlib.figure import Figure

    from fusionkit.plotting import plot_fused

    fig = Figure(figsize=(5, 4), layout="constrained")
    ax = fig.subplots()
    plot_fused(ax, _fused_two())
    renderer = _drawn(fig)
    assert not _overlaps(ax.get_legend().get_window_extent(renderer), ax.get_window_extent(renderer))


def test_the_fusion_steps_share_one_legend_under_their_panels():
    from fusionkit.plotting import plot_fusion_steps

    fig = plot_fusion_steps(_fused_two())
    renderer = _drawn(fig)
    panels = [ax for ax in fig.axes if ax.get_visible()]
    assert len(panels) == 2 and all(ax.get_legend() is None for ax in panels)
    (legend,) = fig.legends
    assert [t.get_text() for t in legend.get_texts()][:2] == ["free, first seen by robot_1",
                                                             "free, first seen by robot_2"]
    box = legend.get_window_extent(renderer)
    assert not any(_overlaps(box, ax.get_window_extent(renderer)) for ax in panels)
    # the panels are one size
    sizes = {(round(ax.get_window_extent(renderer).width), round(ax.get_window_extent(renderer).height))
             for ax in panels}
    assert len(sizes) == 1


def test_plotting_helpers_refuse_what_they_cannot_draw():
    """A path or an array as the grid, a merge result as the fused map, a tuple as the
    transform, too few names or a step past the last raised AttributeError or IndexError."""
    from matplotlib.figure import Figure

    from fusionkit.errors import InputError
    from fusionkit.fusion import fuse_maps
    from fusionkit.plotting import plot_fused, plot_grid
    from fusionkit.transform import Transform2D
    from fusionkit.worlds import default_world
    ax = Figure().add_subplot()
    world = default_world()
    for bad in ("map.yaml", world.data):
        with pytest.raises(InputError, match="plot_grid draws an OccupancyGrid"):
            plot_grid(ax, bad)
    with pytest.raises(InputError, match="transform must be a Transform2D"):
        plot_grid(ax, world, transform=(1.0, 2.0, 0.0))
    fused = fuse_maps([world, world], [Transform2D(), Transform2D()], keep_steps=True)
    with pytest.raises(InputError, match="plot_fused draws a FusedMap"):
        plot_fused(ax, fused.grid)
    with pytest.raises(InputError, match="a name for each of the 2 maps"):
        plot_fused(ax, fused, ["a"])
    with pytest.raises(InputError, match=r"step must be the index of a fusion step \(0 to 1\)"):
        plot_fused(ax, fused, step=10)
