"""Benchmark figures: a case on its ground truth, one case's methods, the summary."""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..grid import OccupancyGrid
from ..resample import resample
from ..transform import Transform2D
from .grids import (_imshow_rgb, _legend_patches, _new_figure, owner_image, plot_grid,
                    robot_colour, state_legend, _TINT)

__all__ = ["plot_case", "plot_on_truth", "plot_bench_case", "plot_bench_summary"]


def plot_case(world: OccupancyGrid, grids, truths, *, names=None, title: str | None = None):
    """A merging problem with its answer: each map in its own frame (left, small) and the
    world with each map's known area tinted in its colour (right; for teaching, the merger
    never sees it).

    Parameters
    ----------
    world : OccupancyGrid
    grids : sequence of OccupancyGrid
        The maps, each in its own frame.
    truths : sequence of Transform2D
        Per map, its frame -> the world frame.
    names : sequence of str, optional
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.colors import to_rgb

    grids, truths = list(grids), list(truths)
    n = len(grids)
    names = list(names) if names is not None else [g.name or f"map_{k + 1}" for k, g in enumerate(grids)]
    rows = int(np.ceil(n / 2))
    fig = _new_figure(14.0, max(5.5, 3.2 * rows))
    gs = fig.add_gridspec(rows, 4)
    owner = np.full(world.shape, -1, np.int16)
    for k, (g, t) in enumerate(zip(grids, truths)):
        ax = fig.add_subplot(gs[k // 2, k % 2])
        plot_grid(ax, g, title=f"{names[k]}: own frame")
        ax.title.set_color(robot_colour(k))
        ax.title.set_fontsize(9)
        ax.tick_params(labelsize=7)
        known = resample(g, t, world).known_mask()
        owner[known & (owner < 0)] = k
    ax = fig.add_subplot(gs[:, 2:])
    img = owner_image(world, owner)
    shown = (owner >= 0) | world.occupied_mask()
    img[~shown & world.known_mask()] = 0.93  # the world no map covers: pale
    _imshow_rgb(ax, world, img)
    tints = [1.0 - _TINT * (1.0 - np.array(to_rgb(robot_colour(k)))) for k in range(n)]
    from matplotlib.patches import Patch

    extra = _legend_patches(tints, [f"seen by {names[k]}" for k in range(n)])
    extra.append(Patch(facecolor=(0.93, 0.93, 0.93), edgecolor="0.3", label="seen by none"))
    state_legend(ax, extra, free=False)
    ax.set_title(title if title is not None else
                 f"The truth: where the {n} maps lie in {world.name or 'the world'}")
    return fig


#: Colours of :func:`plot_on_truth`: unknown, world only, free, missed wall, wrong wall, right wall.
_TRUTH_COLOURS = ("#c8c8c8", "#ededed", "#cfe8c9", "#6f9fe0", "#d62728", "#1a1a1a")


def plot_on_truth(ax, fused: OccupancyGrid, world: OccupancyGrid, transform, *,
                  title: str | None = None, legend: bool = True):
    """A fused map placed in the world (by ``transform``: its frame -> the world's) over the
    ground truth: walls on true walls black, walls where the world has none red, true walls the
    map missed blue, mapped free space pale green."""
    from matplotlib.colors import ListedColormap

    placed = resample(fused, transform, world).data
    img = np.zeros(world.shape, np.int8)
    img[world.data >= 0] = 1
    img[(placed >= 0) & (placed < 50)] = 2
    img[world.data >= 50] = 3
    img[placed >= 50] = 4
    img[(placed >= 50) & (world.data >= 50)] = 5
    x0, y0 = world.origin[0], world.origin[1]
    extent = (x0, x0 + world.cols * world.resolution, y0, y0 + world.rows * world.resolution)
    ax.imshow(img, origin="lower", extent=extent, cmap=ListedColormap(_TRUTH_COLOURS), vmin=-0.5,
              vmax=5.5, interpolation="nearest")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    if title:
        ax.set_title(title)
    if legend:
        ax.legend(handles=_truth_handles(), loc="upper right", fontsize=7, framealpha=0.9)


def _truth_handles():
    """Legend entries of :func:`plot_on_truth`'s colours (all but the plain unknown)."""
    labels = ("unknown in both", "known in the world only", "free in the map",
              "true wall the map misses", "wall off the truth", "wall on the truth")
    return _legend_patches(_TRUTH_COLOURS[1:], labels[1:])


def _payload_grid(p: dict) -> OccupancyGrid:
    return OccupancyGrid(np.asarray(p["data"], np.int8), float(p["resolution"]),
                         tuple(float(v) for v in p["origin"]))


def plot_bench_case(record: dict, *, cols: int = 3):
    """Every method's fused map of one benchmark case, over the truth.

    Parameters
    ----------
    record : dict
        :func:`fusionkit.bench.run_case` with ``keep_grids=True``.
    cols : int
        Panels per row.

    Returns
    -------
    matplotlib.figure.Figure
    """
    grids = record.get("_grids")
    if grids is None:
        raise InputError("this case record holds no grids; run it with keep_grids=True")
    world = _payload_grid(grids["world"])
    ref_true = Transform2D.from_dict(grids["ref_true"])
    methods = list(record["methods"])
    cols = max(1, min(cols, len(methods)))
    rows = int(np.ceil(len(methods) / cols))
    known = np.nonzero(world.known_mask())
    aspect = (np.ptp(known[0]) + 1) / max(np.ptp(known[1]) + 1, 1)
    fig = _new_figure(max(5.2 * cols, 6.5), 5.2 * aspect * rows + 1.4)
    axes = np.atleast_1d(fig.subplots(rows, cols)).ravel()
    word = {"success": "right", "wrong": "WRONG", "refused": "refused"}
    for i, (ax, m) in enumerate(zip(axes, methods)):
        rec = record["methods"][m]
        states = ", ".join(f"map {e['map'] + 1} {word.get(e['status'], e['status'])}"
                           for e in rec["maps"])
        plot_on_truth(ax, _payload_grid(grids["fused"][m]), world, ref_true,
                      title=f"{m}\n{states}", legend=False)
        ax.title.set_fontsize(9)
        r0, r1 = known[0].min(), known[0].max() + 1
        c0, c1 = known[1].min(), known[1].max() + 1
        ox, oy, res = world.origin[0], world.origin[1], world.resolution
        ax.set_xlim(ox + c0 * res, ox + c1 * res)
        ax.set_ylim(oy + r0 * res, oy + r1 * res)
    for ax in axes[len(methods):]:
        ax.set_visible(False)
    # the legend and the title outside the panels: a map fills its panel up to the corners
    fig.legend(handles=_truth_handles(), loc="outside lower center", ncols=min(5, 2 * cols + 1),
               fontsize=8, framealpha=0.9)
    fig.suptitle(f"Case {record['index']}: {record['robots']} maps of {record['world']} "
                 f"({record['mode']});\neach method's fused map placed in the world by the "
                 f"reference map's true pose", fontsize=11)
    return fig


def plot_bench_summary(summary: dict, *, by: str = "mode"):
    """The benchmark's outcome per method: successes, wrong merges and refusals of the pairs
    (left), and the success rate broken down by ``by`` (``"mode"``, ``"robots"``,
    ``"overlap"`` or ``"world"``, right).

    Parameters
    ----------
    summary : dict
        :func:`fusionkit.bench.summarize`.

    Returns
    -------
    matplotlib.figure.Figure
    """
    methods = list(summary["methods"])
    fig = _new_figure(15.0, 0.55 * len(methods) + 3.8)
    a1, a2 = fig.subplots(1, 2)
    y = np.arange(len(methods))[::-1]
    left = np.zeros(len(methods))
    for key, colour, label in (("success", "tab:green", "success"), ("wrong", "tab:red", "wrong merge"),
                               ("refused", "0.7", "refused")):
        v = np.array([summary["methods"][m][key] for m in methods], float)
        a1.barh(y, v, left=left, color=colour, edgecolor="k", linewidth=0.4, label=label)
        left += v
    a1.set_yticks(y, methods)
    a1.set_xlabel("pairs (a map and its reference)")
    a1.set_title("Outcome of every pair, per method")
    # legends under the axes: a bar may run to the axes' edge
    a1.legend(loc="upper center", bbox_to_anchor=(0.5, -0.13), ncols=3, fontsize=8)
    a1.grid(axis="x", alpha=0.3)
    groups = list(summary["by"][by])
    width = 0.8 / max(len(groups), 1)
    for j, g in enumerate(groups):
        rates = []
        for m in methods:
            t = summary["by"][by][g].get(m)
            rates.append(t["success_rate"] if t and t["success_rate"] is not None else np.nan)
        a2.barh(y + (len(groups) - 1) / 2 * width - j * width, rates, width, label=f"{by} {g}",
                edgecolor="k", linewidth=0.4, color=f"C{j}")
    a2.set_yticks(y, methods)
    a2.set_xlim(0, 100)
    a2.set_xlabel("success rate (%) of the linked pairs")
    a2.set_title(f"Success rate by {by}")
    a2.legend(loc="upper center", bbox_to_anchor=(0.5, -0.13), ncols=min(len(groups), 6), fontsize=8)
    a2.grid(axis="x", alpha=0.3)
    return fig
