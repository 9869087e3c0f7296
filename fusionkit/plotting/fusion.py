"""Fusion and metrics (the paper's Section 3.6 and Table 1): fused maps, cell rules, fusion steps,
Table 1 bars.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..fusion import FusedMap
from ..grid import OccupancyGrid
from .grids import (_SHADE_FREE, _SHADE_OCCUPIED, _SHADE_UNKNOWN, _TINT, _imshow_rgb,
                    _legend_patches, _new_figure, owner_image, plot_grid, robot_colour,
                    state_legend)

__all__ = ["plot_fused", "plot_merge", "plot_cells", "plot_cell_fusion", "plot_fusion_steps",
           "plot_table1"]


def plot_fused(ax, fused, names=None, *, step: int | None = None, title: str | None = None,
               legend: bool = True):
    """Draw a :class:`~fusionkit.fusion.FusedMap` with each free cell tinted by the robot whose
    map first made it known (occupied black, unknown grey).

    Parameters
    ----------
    ax : matplotlib.axes.Axes
    fused : FusedMap
    names : sequence of str, optional
        Names of the maps given to ``fuse_maps`` (default ``robot_1``, ...).
    step : int, optional
        Draw ``fused.steps[step]`` (the map after ``step + 1`` maps were fused) instead of the
        final map; needs ``keep_steps=True``.
    title : str, optional
    legend : bool
        Name the robots' colours and the cell states.
    """
    if not isinstance(fused, FusedMap):
        raise InputError(f"plot_fused draws a FusedMap (a merge result's .fused, or fuse_maps'), "
                         f"got {type(fused).__name__}")
    order = list(fused.order)
    n = max(order) + 1 if order else 0
    names = list(names) if names is not None else [f"robot_{k + 1}" for k in range(n)]
    if len(names) < n:
        raise InputError(f"give a name for each of the {n} maps fused, got {len(names)}")
    if step is not None and not (isinstance(step, (int, np.integer)) and 0 <= step < max(len(fused.steps), 1)):
        raise InputError(f"step must be the index of a fusion step (0 to {len(fused.steps) - 1}), got {step!r}")
    grid = fused.grid
    used = order
    if step is not None:
        if not fused.steps:
            raise InputError("this FusedMap kept no steps; fuse with keep_steps=True")
        grid = fused.steps[step]
        used = order[: step + 1]
    img = owner_image(grid, fused.owner, known=grid.known_mask())
    _imshow_rgb(ax, grid, img)
    if title is not None:
        ax.set_title(title)
    if legend:
        state_legend(ax, _owner_patches(names, used), free=False)


def _owner_patches(names, used):
    """Legend entries of the robots' tints, in the order ``used``."""
    from matplotlib.colors import to_rgb

    tints = [1.0 - _TINT * (1.0 - np.array(to_rgb(robot_colour(k)))) for k in used]
    return _legend_patches(tints, [f"free, first seen by {names[k]}" for k in used])


def plot_merge(result, maps, *, names=None, title: str | None = None):
    """The inputs and the outcome of :func:`~fusionkit.pipeline.merge` in one figure: each
    input map in its own frame (left, small) and the fused map coloured by robot (right).

    Parameters
    ----------
    result : MergeResult
    maps : sequence of OccupancyGrid
        The maps given to ``merge``.
    names : sequence of str, optional
        Map names (default: the placements' names).
    title : str, optional
        Title of the fused map's panel.

    Returns
    -------
    matplotlib.figure.Figure
    """
    maps = list(maps)
    n = len(result.placements)
    if len(maps) != n:
        raise InputError(f"give the {n} maps that were merged, got {len(maps)}")
    if not all(isinstance(m, OccupancyGrid) for m in maps):
        raise InputError("plot_merge draws the maps as OccupancyGrid objects (load_map reads a "
                         "map file)")
    names = list(names) if names is not None else [p.name for p in result.placements]
    rows = int(np.ceil(n / 2))
    fig = _new_figure(14.0, max(6.0, 3.0 * rows))
    gs = fig.add_gridspec(rows, 4)
    for k, p in enumerate(result.placements):
        ax = fig.add_subplot(gs[k // 2, k % 2])
        state = "merged" if p.merged else "not merged"
        plot_grid(ax, maps[k], title=f"{names[k]}: own frame, {state}")
        ax.title.set_color(robot_colour(k))
        ax.title.set_fontsize(9)
        ax.tick_params(labelsize=7)
        ax.xaxis.label.set_fontsize(8)
        ax.yaxis.label.set_fontsize(8)
    ax = fig.add_subplot(gs[:, 2:])
    merged = sum(p.merged for p in result.placements)
    if title is None:
        order = " -> ".join(names[k] for k in result.order)
        title = (f"Fused map in {names[result.config.reference]}'s frame: {merged} of {n} maps "
                 f"merged\nfusion order {order}")
    plot_fused(ax, result.fused, names, title=title)
    return fig


def plot_cells(ax, data, *, title: str | None = None):
    """A small grid drawn cell by cell with its values written in (row 0 at the bottom)."""
    d = np.asarray(data)
    img = np.full(d.shape, _SHADE_UNKNOWN)
    img[(d >= 0) & (d < 50)] = _SHADE_FREE
    img[d >= 50] = _SHADE_OCCUPIED
    ax.imshow(img, origin="lower", cmap="gray", vmin=0, vmax=1, interpolation="nearest")
    names = {-1: "unk", 0: "free", 100: "occ"}
    for r in range(d.shape[0]):
        for c in range(d.shape[1]):
            v = int(d[r, c])
            ax.text(c, r, names.get(v, str(v)), ha="center", va="center", fontsize=8,
                    color="w" if v >= 50 else "k")
    ax.set_xticks(range(d.shape[1]))
    ax.set_yticks(range(d.shape[0]))
    ax.set_xticks(np.arange(d.shape[1] + 1) - 0.5, minor=True)
    ax.set_yticks(np.arange(d.shape[0] + 1) - 0.5, minor=True)
    ax.grid(which="minor", color="0.5", lw=0.8)
    ax.tick_params(which="minor", length=0)
    ax.set_xlabel("column j (cells)")
    ax.set_ylabel("row i (cells)")
    if title:
        ax.set_title(title)


def plot_cell_fusion(m1, m2, fused, *, names=("M1", "M2", "M_fusion")):
    """Two small co-registered maps and their fusion, cell by cell (Section 3.6)."""
    fig = _new_figure(13.5, 4.2)
    axes = fig.subplots(1, 3)
    for ax, d, name in zip(axes, (m1, m2, fused), names):
        plot_cells(ax, d, title=name)
    state_legend(axes[2], fontsize=7)
    return fig


def plot_fusion_steps(fused, names=None, *, metrics=None, title: str | None = None):
    """The fused map growing: one panel per step (``M1``, ``M1,2``, ...), cells tinted by the
    robot that first saw them; with ``metrics`` (one :class:`~fusionkit.metrics.MapMetrics`
    per step) the completeness and precision are in the panels' titles."""
    from ..metrics import format_percent, table1_label

    steps = fused.steps
    if not steps:
        raise InputError("this FusedMap kept no steps; fuse with keep_steps=True")
    n = len(steps)
    cols = min(n, 3)
    rows = int(np.ceil(n / cols))
    g = fused.grid
    aspect = g.rows / max(g.cols, 1)
    fig = _new_figure(5.2 * cols, 5.2 * cols * aspect / cols * rows + 0.9)
    axes = np.atleast_1d(fig.subplots(rows, cols)).ravel()
    order = list(fused.order)
    names = list(names) if names is not None else [f"robot_{k + 1}" for k in range(max(order) + 1)]
    for i, ax in enumerate(axes[:n]):
        t = f"{table1_label(i)}: + {names[order[i]]}"
        if metrics is not None:
            m = metrics[i]
            t += (f"\ncompleteness {format_percent(m.completeness, 1)}%, "
                  f"precision {format_percent(m.precision, 1)}%")
        plot_fused(ax, fused, names, step=i, title=t, legend=False)
        ax.title.set_fontsize(9)
    for ax in axes[n:]:
        ax.set_visible(False)
    # one legend under the panels, where it covers no map and leaves the panels one size
    state_legend(fig, _owner_patches(names, order[:n]), free=False, fontsize=8)
    fig.suptitle(title if title is not None else
                 "The fused map growing, one map per step (free cells tinted by the robot that first saw them)")
    return fig


_METRICS = (("completeness", "Completeness"), ("accuracy", "Accuracy"),
            ("precision", "Precision"), ("efficiency", "Efficiency"))


def plot_table1(rows, *, oracle=None, paper: bool = True, title: str | None = None):
    """The paper's Table 1 as bars, like its Fig. 5: one panel per metric, one group of bars
    per fusion step (``M1``, ``M1,2``, ...): fusionkit, the oracle (true transforms) and the
    paper's published values.

    Parameters
    ----------
    rows : sequence of MapMetrics
    oracle : sequence of MapMetrics, optional
    paper : bool
        Add :data:`~fusionkit.metrics.PAPER_TABLE1`.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from ..metrics import PAPER_TABLE1, table1_label

    series = [("fusionkit", list(rows), "tab:blue")]
    if oracle is not None:
        series.append(("oracle (true transforms)", list(oracle), "tab:green"))
    if paper:
        series.append(("paper, Table 1", list(PAPER_TABLE1), "0.55"))
    n = max(len(s[1]) for s in series)
    labels = [table1_label(k) for k in range(n)]
    fig = _new_figure(15.0, 4.6)
    axes = fig.subplots(1, 4, sharey=True)
    width = 0.8 / len(series)
    x = np.arange(n)
    for ax, (key, name) in zip(axes, _METRICS):
        for j, (lab, data, colour) in enumerate(series):
            vals = [getattr(data[k], key) if k < len(data) else np.nan for k in range(n)]
            ax.bar(x + (j - (len(series) - 1) / 2) * width, vals, width, color=colour,
                   edgecolor="k", linewidth=0.4, label=lab)
        ax.set_xticks(x, labels, rotation=35, ha="right", fontsize=8)
        ax.set_title(name)
        ax.set_xlabel("fused maps")
        ax.set_ylim(0, 105)
        ax.grid(axis="y", alpha=0.3)
    axes[0].set_ylabel("percent (%)")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=len(series), fontsize=9)
    fig.suptitle(title if title is not None else
                 "Table 1 as bars (the paper's Fig. 5): each metric after each fusion step")
    return fig
