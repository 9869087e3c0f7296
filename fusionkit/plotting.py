"""Matplotlib figures of grids, trajectories, simulations and every step of the method.

Every function draws on axes or returns a :class:`matplotlib.figure.Figure`; nothing is shown or
saved here, so the same calls work in notebooks, scripts and tests (with the Agg backend).
Grids are drawn in metres with the map-server palette: occupied black, free white, unknown grey.
Robot ``k`` has the colour ``robot_colour(k)`` in every figure.

The figures of the notebooks, in the order of the method: scans (:func:`plot_scan`,
:func:`plot_drift`), unique poses (:func:`plot_section_spectra`, :func:`plot_unique_summary`,
:func:`plot_rotation_invariance`), pairing (:func:`plot_rho_overview`, :func:`plot_pairing`,
:func:`plot_matches`), alignment (:func:`cost_surface`, :func:`plot_swarm_snapshots`,
:func:`plot_pso_run`), fusion and metrics (:func:`plot_fused`, :func:`plot_fusion_steps`,
:func:`plot_table1`) and benchmarks (:func:`plot_bench_case`, :func:`plot_bench_summary`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import InputError
from .grid import OccupancyGrid
from .resample import canvas_for, resample
from .transform import Transform2D

__all__ = ["plot_grid", "plot_simulation", "grid_image", "ROBOT_COLOURS"]

#: Colours of robots 1, 2, ... (cycled).
ROBOT_COLOURS = ("tab:red", "tab:blue", "tab:green", "tab:orange", "tab:purple", "tab:brown",
                 "tab:pink", "tab:olive", "tab:cyan")

_SHADE_FREE, _SHADE_UNKNOWN, _SHADE_OCCUPIED = 1.0, 0.78, 0.0


def grid_image(grid: OccupancyGrid) -> np.ndarray:
    """Grey levels ``(rows, cols)`` in [0, 1] (row 0 = lowest y): free 1, unknown 0.78,
    occupied 0."""
    states = grid.trinary()
    img = np.full(states.shape, _SHADE_UNKNOWN)
    img[states == 0] = _SHADE_FREE
    img[states == 100] = _SHADE_OCCUPIED
    return img


def plot_grid(ax, grid: OccupancyGrid, *, transform: Transform2D | None = None, title: str | None = None,
              alpha: float = 1.0, axis_labels: bool = True):
    """Draw ``grid`` on ``ax`` in metres.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
    grid : OccupancyGrid
    transform : Transform2D, optional
        Moves the grid's map frame into the frame of the axes (for example a robot's map into
        the world); the grid is resampled (nearest neighbour) onto an axis-aligned canvas.
    title : str, optional
        Axes title; defaults to the grid's name.
    alpha : float
        Opacity of the image.
    axis_labels : bool
        Label the axes "x (m)" and "y (m)".

    Returns
    -------
    matplotlib.image.AxesImage
    """
    if transform is not None or grid.origin[2] != 0.0:
        t = transform if transform is not None else Transform2D.identity()
        canvas = canvas_for([grid], [t], grid.resolution)
        grid = resample(grid, t, canvas)
    x0, y0 = grid.origin[0], grid.origin[1]
    extent = (x0, x0 + grid.cols * grid.resolution, y0, y0 + grid.rows * grid.resolution)
    im = ax.imshow(grid_image(grid), origin="lower", cmap="gray", vmin=0.0, vmax=1.0,
                   extent=extent, interpolation="nearest", alpha=alpha)
    ax.set_aspect("equal")
    if axis_labels:
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
    if title is None:
        title = grid.name
    if title:
        ax.set_title(title)
    return im


def _trajectory(ax, poses, colour, label=None, start_label=None):
    ax.plot(poses[:, 0], poses[:, 1], "-", color=colour, lw=0.8, alpha=0.8, label=label)
    ax.plot(poses[0, 0], poses[0, 1], "o", color=colour, ms=7, mec="k", label=start_label)
    # heading at the start
    L = 1.2
    ax.annotate("", xy=(poses[0, 0] + L * np.cos(poses[0, 2]), poses[0, 1] + L * np.sin(poses[0, 2])),
                xytext=(poses[0, 0], poses[0, 1]),
                arrowprops=dict(arrowstyle="->", color=colour, lw=1.5))


def plot_simulation(sim, *, max_robot_panels: int = 8):
    """A figure of a :class:`~fusionkit.simulate.Simulation`: the world with every robot's
    true trajectory (large panel), then each robot's own-frame map with its recorded poses.

    Parameters
    ----------
    sim : Simulation
    max_robot_panels : int
        At most this many robot maps are drawn.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.figure import Figure

    robots = sim.robots[:max_robot_panels]
    n = len(robots)
    cols = min(4, max(2, (n + 1) // 2)) if n > 1 else 1
    rows_small = int(np.ceil(n / cols))
    fig = Figure(figsize=(4.2 * cols + 6.5, max(6.0, 3.6 * rows_small)), layout="constrained")
    gs = fig.add_gridspec(rows_small, cols + 2)
    ax_world = fig.add_subplot(gs[:, :2])
    cov = sim.coverage()
    plot_grid(ax_world, sim.world,
              title=f"World '{sim.world.name or 'world'}': true trajectories\n"
                    f"{len(sim.robots)} robots x {sim.config.poses} poses, seed {sim.config.seed}, "
                    f"all maps cover {100 * cov.combined:.1f}%")
    for k, r in enumerate(sim.robots):
        c = ROBOT_COLOURS[k % len(ROBOT_COLOURS)]
        _trajectory(ax_world, r.trajectory, c, label=f"{r.name} ({r.path_length:.0f} m)")
    ax_world.legend(loc="upper right", fontsize=8, framealpha=0.85)
    for k, r in enumerate(robots):
        ax = fig.add_subplot(gs[k // cols, 2 + k % cols])
        c = ROBOT_COLOURS[k % len(ROBOT_COLOURS)]
        plot_grid(ax, r.grid, title=f"{r.name}: own frame, covers {100 * cov.per_robot[k]:.1f}%")
        _trajectory(ax, r.scans.poses, c, label="odometry", start_label="start (0, 0)")
        ax.title.set_fontsize(9)
        if k == 0:
            ax.legend(loc="upper right", fontsize=7, framealpha=0.85)
    return fig


# ---------------------------------------------------------------------------------------------
# The method step by step: figures of the notebooks
# ---------------------------------------------------------------------------------------------
#: Grey levels of unknown and occupied cells in the figures coloured by robot.
_RGB_UNKNOWN = np.array([0.78, 0.78, 0.78])
_RGB_OCCUPIED = np.array([0.0, 0.0, 0.0])
#: How strongly free cells take their robot's colour (0 white, 1 the full colour).
_TINT = 0.45


def robot_colour(k: int) -> str:
    """Colour of robot ``k`` (0-based) in every figure."""
    return ROBOT_COLOURS[k % len(ROBOT_COLOURS)]


def _new_figure(width: float, height: float):
    from matplotlib.figure import Figure

    return Figure(figsize=(width, height), layout="constrained")


def _legend_patches(colours, labels):
    from matplotlib.patches import Patch

    return [Patch(facecolor=c, edgecolor="0.3", label=s) for c, s in zip(colours, labels)]


def state_legend(ax, extra=(), *, loc="upper right", fontsize=7, free: bool = True):
    """Add a legend of the three cell states (free white, unknown grey, occupied black),
    after the ``extra`` legend handles; ``free=False`` leaves the free entry out."""
    from matplotlib.patches import Patch

    handles = list(extra) + ([Patch(facecolor="white", edgecolor="0.3", label="free")] if free else [])
    handles += [Patch(facecolor=(0.78, 0.78, 0.78), edgecolor="0.3", label="unknown"),
                Patch(facecolor="black", edgecolor="0.3", label="occupied")]
    ax.legend(handles=handles, loc=loc, fontsize=fontsize, framealpha=0.9)


def owner_image(grid: OccupancyGrid, owner: np.ndarray, *, known=None) -> np.ndarray:
    """RGB image ``(rows, cols, 3)`` of a fused map (row 0 = lowest y): occupied black, unknown
    grey, free cells tinted with the colour of the robot in ``owner`` (index per cell, ``-1``
    none). ``known`` restricts the drawing to some cells (the rest is drawn unknown)."""
    from matplotlib.colors import to_rgb

    states = grid.trinary()
    own = np.asarray(owner)
    if own.shape != states.shape:
        raise InputError(f"owner must have the grid's shape {states.shape}, got {own.shape}")
    img = np.empty(states.shape + (3,))
    img[:] = _RGB_UNKNOWN
    free = states == 0
    if known is not None:
        free &= known
    for k in np.unique(own[free & (own >= 0)]):
        sel = free & (own == k)
        img[sel] = 1.0 - _TINT * (1.0 - np.array(to_rgb(robot_colour(int(k)))))
    img[free & (own < 0)] = 1.0
    occ = states == 100
    if known is not None:
        occ &= known
    img[occ] = _RGB_OCCUPIED
    return img


def _imshow_rgb(ax, grid: OccupancyGrid, img: np.ndarray):
    if grid.origin[2] != 0.0:
        raise InputError("only axis-aligned grids (origin yaw 0) can be coloured by robot")
    x0, y0 = grid.origin[0], grid.origin[1]
    extent = (x0, x0 + grid.cols * grid.resolution, y0, y0 + grid.rows * grid.resolution)
    ax.imshow(img, origin="lower", extent=extent, interpolation="nearest")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")


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
    order = list(fused.order)
    n = max(order) + 1 if order else 0
    names = list(names) if names is not None else [f"robot_{k + 1}" for k in range(n)]
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
        from matplotlib.colors import to_rgb

        tints = [1.0 - _TINT * (1.0 - np.array(to_rgb(robot_colour(k)))) for k in used]
        state_legend(ax, _legend_patches(tints, [f"free, first seen by {names[k]}" for k in used]),
                     free=False)


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


def plot_scan(log, index: int, *, grid: OccupancyGrid | None = None, every: int = 3,
              colour: str = "tab:red", title: str | None = None):
    """One LIDAR scan: where its beams go on the map (left) and the ranges as a signal over the
    beam angle (right), the ``f(x)`` whose DFT is eq. 1.

    Parameters
    ----------
    log : ScanLog
    index : int
        Which scan.
    grid : OccupancyGrid, optional
        The map in the log's frame, drawn underneath.
    every : int
        Draw every ``every``-th beam on the map.
    colour : str
        Colour of the beams and the signal.
    title : str, optional
        Title of the map panel.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.lines import Line2D

    if not 0 <= index < log.n_scans:
        raise InputError(f"scan index {index} is out of range; the log has {log.n_scans} scans")
    fig = _new_figure(13.0, 5.2)
    ax_map, ax_sig = fig.subplots(1, 2, width_ratios=[1.0, 1.25])
    x, y, th = log.poses[index]
    if grid is not None:
        plot_grid(ax_map, grid, title="")
    ax_map.plot(log.poses[:, 0], log.poses[:, 1], "-", color="0.55", lw=0.6,
                label="trajectory (odometry)")
    r = log.ranges[index].astype(float)
    hit = np.isfinite(r) & (r <= log.range_max)
    ang = th + log.beam_angles
    rr = np.where(hit, r, log.range_max)
    ex, ey = x + rr * np.cos(ang), y + rr * np.sin(ang)
    sel = np.arange(0, log.n_beams, max(1, int(every)))
    for j in sel:
        ax_map.plot([x, ex[j]], [y, ey[j]], "-" if hit[j] else ":", color=colour,
                    lw=0.5, alpha=0.7 if hit[j] else 0.4)
    ax_map.plot(ex[hit], ey[hit], ".", color=colour, ms=2.5)
    ax_map.annotate("", xy=(x + 1.2 * np.cos(th), y + 1.2 * np.sin(th)), xytext=(x, y),
                    arrowprops=dict(arrowstyle="->", color="k", lw=2))
    ax_map.plot(x, y, "o", color=colour, mec="k", ms=8)
    pad = log.range_max + 0.5
    ax_map.set_xlim(x - pad, x + pad)
    ax_map.set_ylim(y - pad, y + pad)
    ax_map.set_aspect("equal")
    ax_map.set_xlabel("x (m)")
    ax_map.set_ylabel("y (m)")
    ax_map.set_title(title if title is not None else
                     f"scan {index} at x = {x:.1f} m, y = {y:.1f} m, heading {np.degrees(th):.0f} deg")
    ax_map.legend(handles=[Line2D([], [], color="0.55", lw=0.8, label="trajectory (odometry)"),
                           Line2D([], [], color=colour, lw=0.8, label="beam with a return"),
                           Line2D([], [], color=colour, lw=0.8, ls=":", alpha=0.5,
                                  label=f"no return within {log.range_max:g} m"),
                           Line2D([], [], color="k", marker=r"$\rightarrow$", ls="", ms=12,
                                  label="robot heading")],
                  loc="upper right", fontsize=7, framealpha=0.9)

    deg = np.degrees(log.beam_angles)
    ax_sig.plot(deg, rr, "-", color=colour, lw=1.0, label="range of each beam")
    ax_sig.plot(deg[~hit], np.full((~hit).sum(), log.range_max), "x", color="0.4", ms=4,
                label=f"no return (counted as range_max = {log.range_max:g} m)")
    ax_sig.set_xlabel("beam angle relative to the heading (deg)")
    ax_sig.set_ylabel("range (m)")
    ax_sig.set_xlim(deg[0], deg[-1])
    ax_sig.set_ylim(0, log.range_max * 1.08)
    ax_sig.set_title(f"The scan as a signal f(x), x = beam 0..{log.n_beams - 1} (input of eq. 1)")
    ax_sig.legend(loc="lower right", fontsize=8, framealpha=0.9)
    ax_sig.grid(alpha=0.3)
    return fig


def plot_drift(run, *, colour: str | None = None):
    """A robot's odometry against its true path (left) and the map its scans make with that
    odometry (right), both in the robot's own frame (m).

    Parameters
    ----------
    run : RobotRun
        From :func:`~fusionkit.simulate.simulate`.
    colour : str, optional
        Colour of the odometry.

    Returns
    -------
    matplotlib.figure.Figure
    """
    colour = colour or "tab:red"
    true_own = run.transform.inverse.apply_pose(run.trajectory)
    odo = run.scans.poses
    err = float(np.hypot(*(odo[-1, :2] - true_own[-1, :2])))
    fig = _new_figure(13.0, 5.2)
    ax, ax_map = fig.subplots(1, 2)
    ax.plot(true_own[:, 0], true_own[:, 1], "-", color="k", lw=0.9, label="true path")
    ax.plot(odo[:, 0], odo[:, 1], "-", color=colour, lw=0.9, alpha=0.85,
            label=f"odometry (ends {err:.2f} m off)")
    ax.plot(0, 0, "o", color=colour, mec="k", ms=7, label="start (0, 0)")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m, own frame)")
    ax.set_ylabel("y (m, own frame)")
    ax.set_title(f"{run.name}: odometry against the truth, {run.path_length:.0f} m driven")
    ax.legend(loc="best", fontsize=8, framealpha=0.9)
    plot_grid(ax_map, run.grid, title=f"{run.name}: the map built with this odometry")
    state_legend(ax_map)
    return fig


def plot_worlds(worlds, *, cols: int = 4):
    """Ground-truth maps side by side (at most ``cols`` per row), each titled with its size (m)
    and cell size."""
    worlds = list(worlds)
    cols = max(1, min(cols, len(worlds)))
    rows = int(np.ceil(len(worlds) / cols))
    fig = _new_figure(5.0 * cols + 0.6, 4.3 * rows)
    axes = np.atleast_1d(fig.subplots(rows, cols)).ravel()
    for ax, w in zip(axes, worlds):
        x0, y0, x1, y1 = w.bounds()
        plot_grid(ax, w, title=f"{w.name}: {x1 - x0:.0f} x {y1 - y0:.0f} m, {w.resolution:g} m cells")
        ax.title.set_fontsize(10)
    for ax in axes[len(worlds):]:
        ax.set_visible(False)
    state_legend(axes[len(worlds) - 1])
    return fig


# -- unique poses (Algorithm 1) ----------------------------------------------------------------
def plot_section_spectra(unique, poses, *, labels=None):
    """The overall spectrum against the spectra of a few sections (Algorithm 1, lines 1-6).

    One panel per pose in ``poses``: the robot's overall spectrum (mean of all its scans'
    ``|DFT|``, thick black) and the spectra of the ``2 * sub_sec`` scans of the pose's section
    (thin, coloured from the first scan of the section to the last).

    Parameters
    ----------
    unique : UniquePoses
    poses : sequence of int
        Pose indices (each must have a full section).
    labels : sequence of str, optional
        Panel titles' first words (default "pose i").

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib as mpl
    from matplotlib.lines import Line2D

    poses = [int(p) for p in poses]
    s = unique.sub_sec
    n = unique.spectra.shape[0]
    for p in poses:
        if not s <= p < n - s:
            raise InputError(f"pose {p} has no full section; use a pose in [{s}, {n - s})")
    labels = list(labels) if labels is not None else [f"pose {p}" for p in poses]
    fig = _new_figure(6.3 * len(poses), 4.8)
    axes = np.atleast_1d(fig.subplots(1, len(poses), sharey=True))
    u = np.arange(1, unique.spectra.shape[1] + 1)  # bin 0 (DC) is left out by default
    cmap = mpl.colormaps["viridis"]
    for ax, p, lab in zip(axes, poses, labels):
        sec = range(p - s, p + s)
        for j, k in enumerate(sec):
            ax.plot(u, unique.spectra[k], "-", lw=0.8, color=cmap(j / max(1, 2 * s - 1)), alpha=0.8)
        ax.plot(u, unique.overall_spectrum, "-", color="k", lw=2.2)
        ax.set_yscale("log")
        ax.set_xscale("log")
        ax.set_xlabel("frequency u (cycles per turn of the scan)")
        verdict = "unique" if unique.section_score[p] >= unique.delta else "typical"
        div = unique.divergence[list(sec)]
        below = int((div < unique.delta).sum())
        ax.set_title(f"{lab}: {verdict} ({below} of {2 * s} scans within delta of o_spec)",
                     fontsize=10)
        ax.grid(alpha=0.3, which="both")
        ax.legend(handles=[Line2D([], [], color="k", lw=2.2, label="overall spectrum o_spec (all poses)"),
                           Line2D([], [], color=cmap(0.0), lw=1, label=f"scan {p - s} (first of section)"),
                           Line2D([], [], color=cmap(1.0), lw=1, label=f"scan {p + s - 1} (last of section)")],
                  loc="lower left", fontsize=8, framealpha=0.9)
    axes[0].set_ylabel("|DFT(u)| (m)")
    return fig


def plot_divergence(ax, unique, *, window=None, title: str | None = None):
    """Algorithm 1 along the trajectory: each scan's divergence from the overall spectrum
    (line 6), the section score (the 2nd smallest divergence in the section) against delta, and
    the unique poses it gives (line 15).

    Parameters
    ----------
    ax : matplotlib.axes.Axes
    unique : UniquePoses
    window : (start, stop), optional
        Range of pose indices to draw.
    title : str, optional
    """
    n = unique.divergence.size
    a, b = (0, n) if window is None else (max(0, int(window[0])), min(n, int(window[1])))
    idx = np.arange(a, b)
    ax.plot(idx, unique.divergence[a:b], "-", color="0.6", lw=0.6,
            label="divergence of each scan: sum |spec - o_spec|")
    score = unique.section_score[a:b]
    ok = np.isfinite(score)
    ax.plot(idx[ok], score[ok], "-", color="tab:blue", lw=1.0,
            label="section score: 2nd smallest divergence in the section")
    ax.axhline(unique.delta, color="tab:red", ls="--", lw=1.2, label=f"delta = {unique.delta:.0f} m")
    sel = unique.indices[(unique.indices >= a) & (unique.indices < b)]
    ax.plot(sel, unique.section_score[sel], "o", color="tab:red", ms=3,
            label=f"unique poses ({sel.size} here, {unique.count} in all)")
    ax.set_xlim(a, b - 1)
    ax.set_xlabel("pose index along the trajectory")
    ax.set_ylabel("divergence (m)")
    ax.set_title(title if title is not None else
                 f"Algorithm 1: a pose is unique when at most 1 scan of its section is within "
                 f"delta (sub_sec = {unique.sub_sec})")
    ax.legend(loc="upper left", fontsize=8, framealpha=0.9, ncol=2)
    ax.grid(alpha=0.3)


def plot_unique_poses(ax, grid: OccupancyGrid, log, unique, *, colour: str = "tab:red",
                      title: str | None = None):
    """A robot's map with its trajectory and its unique poses (own frame, m)."""
    plot_grid(ax, grid, title="")
    ax.plot(log.poses[:, 0], log.poses[:, 1], "-", color="0.5", lw=0.5, alpha=0.8,
            label="trajectory")
    p = log.poses[unique.indices]
    ax.plot(p[:, 0], p[:, 1], "o", color=colour, ms=3.5, mec="k", mew=0.3,
            label=f"unique poses ({unique.count})")
    ax.set_title(title if title is not None else
                 f"{grid.name or 'map'}: where the unique poses are")
    ax.legend(loc="upper right", fontsize=8, framealpha=0.9)


def plot_unique_summary(grid: OccupancyGrid, log, unique, *, colour: str = "tab:red"):
    """Divergence along the trajectory (left) and the unique poses on the map (right)."""
    fig = _new_figure(15.0, 5.0)
    ax_d, ax_m = fig.subplots(1, 2, width_ratios=[1.6, 1.0])
    plot_divergence(ax_d, unique)
    plot_unique_poses(ax_m, grid, log, unique, colour=colour)
    return fig


def plot_unique_in_world(world: OccupancyGrid, trajectories, unique_list, names=None):
    """Every robot's unique poses where they truly are in the world (for teaching: the
    merger never sees the world frame). Distinctive places collect the unique poses of
    several robots; that is what pairing (eq. 2) relies on.

    Parameters
    ----------
    world : OccupancyGrid
    trajectories : sequence of (P, 3) arrays
        True world poses of each robot (``RobotRun.trajectory``).
    unique_list : sequence of UniquePoses
    names : sequence of str, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    names = list(names) if names is not None else [f"robot_{k + 1}" for k in range(len(unique_list))]
    fig = _new_figure(10.0, 7.0)
    ax = fig.subplots()
    plot_grid(ax, world, title="", alpha=0.7)
    for k, (traj, u) in enumerate(zip(trajectories, unique_list)):
        p = np.asarray(traj)[u.indices]
        ax.plot(p[:, 0], p[:, 1], "o", color=robot_colour(k), ms=4, mec="k", mew=0.3, alpha=0.85,
                label=f"{names[k]}: {u.count} unique poses")
    ax.set_title("Unique poses of every robot, at their true places in the world")
    ax.legend(loc="upper right", fontsize=8, framealpha=0.9)
    return fig


def plot_rotation_invariance(log, index: int, turn_deg: float):
    """Why spectra can be compared between robots: turning the robot shifts its scan
    circularly, which leaves ``|DFT|`` unchanged and moves only the phase.

    Panels: the scan and the scan of the same place with the robot turned by ``turn_deg``
    (rounded to whole beams); both magnitude spectra; the phase difference per frequency, a
    straight line whose slope is the turn.

    Parameters
    ----------
    log : ScanLog
        A 360-degree scan log.
    index : int
        Which scan.
    turn_deg : float
        How far the robot turns (degrees, counter-clockwise).

    Returns
    -------
    matplotlib.figure.Figure
    """
    from .unique_poses import scan_spectra

    if log.field_of_view < 2 * np.pi - 1e-6:
        raise InputError("rotation invariance holds for 360-degree scans only")
    r = log.clipped_ranges()[index].astype(float)
    B = r.size
    k = int(round(np.radians(turn_deg) / log.angle_increment))
    # turning the robot by +k beams: what was at beam j + k is now at beam j
    turned = np.roll(r, -k)
    deg = np.degrees(log.beam_angles)
    spec = scan_spectra(np.stack([r, turned]), dc=False)
    u = np.arange(1, spec.shape[1] + 1)
    fig = _new_figure(16.0, 4.6)
    a1, a2, a3 = fig.subplots(1, 3)
    a1.plot(deg, r, "-", color="tab:blue", lw=1.0, label="scan")
    a1.plot(deg, turned, "-", color="tab:orange", lw=1.0,
            label=f"same place, robot turned {np.degrees(k * log.angle_increment):.0f} deg")
    a1.set_xlabel("beam angle relative to the heading (deg)")
    a1.set_ylabel("range (m)")
    a1.set_title("Turning the robot shifts the scan circularly")
    a1.legend(loc="lower right", fontsize=8, framealpha=0.9)
    a1.grid(alpha=0.3)
    a2.plot(u, spec[0], "-", color="tab:blue", lw=2.5, label="|DFT| of the scan")
    a2.plot(u, spec[1], "--", color="tab:orange", lw=1.2, label="|DFT| of the turned scan")
    a2.set_xscale("log")
    a2.set_yscale("log")
    a2.set_xlabel("frequency u (cycles per turn)")
    a2.set_ylabel("|DFT(u)| (m)")
    same = np.abs(spec[0] - spec[1]).max()
    a2.set_title(f"...and leaves |DFT| unchanged (largest difference {same:.1e} m)")
    a2.legend(loc="lower left", fontsize=8, framealpha=0.9)
    a2.grid(alpha=0.3, which="both")
    F0, F1 = np.fft.rfft(r), np.fft.rfft(turned)
    nshow = min(40, spec.shape[1])
    uu = np.arange(1, nshow + 1)
    dphase = np.angle(F1[1:nshow + 1] / F0[1:nshow + 1])
    expect = np.angle(np.exp(2j * np.pi * uu * k / B))
    a3.plot(uu, np.degrees(dphase), "o", color="tab:orange", ms=7, mfc="none", mew=1.5,
            label="phase of turned - phase of scan")
    a3.plot(uu, np.degrees(expect), "x", color="k", ms=5,
            label=f"2 pi u k / B with k = {k} beams (wrapped to +-180)")
    a3.set_xlabel("frequency u (cycles per turn)")
    a3.set_ylabel("phase difference (deg)")
    a3.set_ylim(-190, 190)
    a3.set_title("The turn is all in the phase, which |DFT| drops")
    a3.legend(loc="lower left", fontsize=8, framealpha=0.9)
    a3.grid(alpha=0.3)
    return fig


# -- pairing (eq. 2) -----------------------------------------------------------------------------
def plot_rho_matrix(ax, unique_list, names, *, theta: float | None = None, title: str | None = None):
    """Pearson's rho (eq. 2) between every two unique poses of all robots, as a heat map.

    The unique poses of robot 1 come first, then robot 2's, ...; thin lines separate the robots'
    blocks. With ``theta``, only the agreeing pairs (``rho > theta``) are coloured.

    Returns
    -------
    matplotlib.image.AxesImage
    """
    from .pairing import pearson_matrix

    spectra = [u.unique_spectra for u in unique_list]
    S = np.concatenate(spectra)
    rho = pearson_matrix(S, S)
    sizes = np.array([len(s) for s in spectra])
    edges = np.concatenate([[0], np.cumsum(sizes)])
    if theta is None:
        im = ax.imshow(rho, cmap="viridis", vmin=max(-1.0, float(np.percentile(rho, 1))), vmax=1.0,
                       interpolation="nearest", origin="upper")
        label = "Pearson rho (eq. 2)"
    else:
        shown = np.where(rho > theta, rho, np.nan)
        ax.set_facecolor("0.93")
        im = ax.imshow(shown, cmap="viridis", vmin=theta, vmax=1.0, interpolation="nearest",
                       origin="upper")
        label = f"rho of the agreeing pairs (rho > theta = {theta:g})"
    for e in edges[1:-1]:
        ax.axhline(e - 0.5, color="w", lw=1.2)
        ax.axvline(e - 0.5, color="w", lw=1.2)
    centres = (edges[:-1] + edges[1:]) / 2 - 0.5
    ax.set_xticks(centres, [f"{n}\n({s})" for n, s in zip(names, sizes)], fontsize=8)
    ax.set_yticks(centres, list(names), fontsize=8)
    ax.set_xlabel("unique pose (grouped by robot; count in brackets)")
    ax.set_ylabel("unique pose (grouped by robot)")
    ax.set_title(title if title is not None else label)
    cb = ax.figure.colorbar(im, ax=ax, shrink=0.85)
    cb.set_label(label)
    return im


def agreement_curves(unique_list, thetas):
    """Agreeing unique-pose pairs of every two robots as the threshold varies.

    Returns ``{(a, b): counts}`` with ``counts[i]`` the number of pairs with ``rho > thetas[i]``.
    """
    from .pairing import agreement

    out = {}
    t = np.asarray(thetas, float)
    for a in range(len(unique_list)):
        for b in range(a + 1, len(unique_list)):
            rho = agreement(unique_list[a].unique_spectra, unique_list[b].unique_spectra, 1.0).rho
            v = np.sort(rho.ravel())
            out[(a, b)] = v.size - np.searchsorted(v, t, side="right")
    return out


def plot_agreement_curves(ax, unique_list, names, theta: float, *, thetas=None):
    """How many unique-pose pairs of each two robots agree (rho > theta) as theta varies."""
    import matplotlib as mpl

    thetas = np.linspace(0.5, 0.995, 100) if thetas is None else np.asarray(thetas)
    curves = agreement_curves(unique_list, thetas)
    cmap = mpl.colormaps["tab10"]
    for i, ((a, b), c) in enumerate(curves.items()):
        ax.plot(thetas, np.maximum(c, 0.8), "-", color=cmap(i % 10), lw=1.3,
                label=f"{names[a]} ~ {names[b]}")
    ax.axvline(theta, color="k", ls="--", lw=1.0, label=f"theta = {theta:g}")
    ax.set_yscale("log")
    ax.set_xlabel("threshold theta on Pearson rho")
    ax.set_ylabel("agreeing unique-pose pairs (rho > theta)")
    ax.set_title("Agreement of each pair of robots against theta")
    ax.legend(loc="lower left", fontsize=8, framealpha=0.9, ncol=2)
    ax.grid(alpha=0.3, which="both")


def plot_counts(ax, counts, names, *, title: str | None = None):
    """The agreement counts between every two robots as an annotated matrix."""
    c = np.asarray(counts)
    im = ax.imshow(c, cmap="Blues", interpolation="nearest")
    for i in range(c.shape[0]):
        for j in range(c.shape[1]):
            ax.text(j, i, "-" if i == j else f"{c[i, j]}", ha="center", va="center", fontsize=9,
                    color="w" if c[i, j] > 0.6 * max(c.max(), 1) else "k")
    ax.set_xticks(range(len(names)), names, rotation=30, ha="right", fontsize=8)
    ax.set_yticks(range(len(names)), names, fontsize=8)
    ax.set_title(title if title is not None else "Agreeing unique-pose pairs (counts)")
    cb = ax.figure.colorbar(im, ax=ax, shrink=0.8)
    cb.set_label("pairs with rho > theta")


def plot_fusion_plan(ax, plan, names, *, title: str | None = None):
    """The fusion order as a graph: robots on a circle, grey edges as thick as their agreement
    count, and numbered arrows for the steps (from the placed map to the map that joins)."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import FancyArrowPatch

    n = len(names)
    ang = np.pi / 2 - 2 * np.pi * np.arange(n) / n
    pos = np.column_stack([np.cos(ang), np.sin(ang)])
    c = np.asarray(plan.counts).copy()
    np.fill_diagonal(c, 0)
    cmax = max(int(c.max()), 1)
    for a in range(n):
        for b in range(a + 1, n):
            if c[a, b] > 0:
                ax.plot(*pos[[a, b]].T, "-", color="0.75", lw=1 + 7 * c[a, b] / cmax, zorder=1,
                        solid_capstyle="round")
                m = pos[[a, b]].mean(axis=0)
                ax.text(*m, f"{c[a, b]}", fontsize=8, color="0.35", ha="center", va="center",
                        bbox=dict(boxstyle="round,pad=0.15", fc="w", ec="none", alpha=0.8), zorder=2)
    bend = 0.2
    for i, (a, b) in enumerate(plan.steps):
        arr = FancyArrowPatch(pos[a], pos[b], arrowstyle="-|>", mutation_scale=18, lw=2.2,
                              color="tab:red", shrinkA=18, shrinkB=18, zorder=3,
                              connectionstyle=f"arc3,rad={bend}")
        ax.add_patch(arr)
        d = pos[b] - pos[a]
        side = np.array([d[1], -d[0]])  # the side matplotlib's arc3 bends to
        m = pos[[a, b]].mean(axis=0) + 0.5 * bend * side + 0.13 * side / max(np.hypot(*side), 1e-9)
        ax.text(*m, f"{i + 1}", fontsize=11, color="tab:red", weight="bold", ha="center",
                va="center", zorder=4)
    first = plan.steps[0][0] if plan.steps else None
    for k in range(n):
        unplaced = k in plan.unplaced
        ax.scatter(*pos[k], s=900, color="0.85" if unplaced else robot_colour(k),
                   edgecolors="k", linewidths=3 if k == first else 1, zorder=5)
        ax.text(*(pos[k] * 1.42), names[k], ha="center", va="center", fontsize=9)
        ax.text(*pos[k], f"{k + 1}", ha="center", va="center", fontsize=10, color="w",
                weight="bold", zorder=6)
    ax.set_xlim(-1.75, 1.75)
    ax.set_ylim(-1.75, 1.6)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_xlabel("(a graph: positions carry no units)")
    order = " -> ".join(names[k] for k in plan.order) if plan.steps else "none"
    ax.set_title(title if title is not None else f"Fusion order: {order}", fontsize=10)
    handles = [Line2D([], [], color="0.75", lw=4, label="agreement (width = count)"),
               Line2D([], [], color="tab:red", lw=2, marker=">", label="fusion step k: placed -> joins"),
               Line2D([], [], color="w", marker="o", mfc="w", mec="k", mew=3, ms=12, ls="",
                      label="first map (reference of the plan)")]
    if plan.unplaced:
        handles.append(Line2D([], [], color="w", marker="o", mfc="0.85", mec="k", ms=12, ls="",
                              label="agrees with no placed map"))
    ax.legend(handles=handles, loc="lower center", fontsize=7, framealpha=0.9,
              bbox_to_anchor=(0.5, -0.02), ncol=2)


def plot_rho_overview(unique_list, names, theta: float):
    """Pearson's rho between all unique poses (left) and only the pairs above ``theta``
    (right)."""
    fig = _new_figure(15.0, 6.4)
    a1, a2 = fig.subplots(1, 2)
    plot_rho_matrix(a1, unique_list, names, title="Pearson rho (eq. 2) of every two unique poses")
    plot_rho_matrix(a2, unique_list, names, theta=theta,
                    title=f"Agreeing pairs: rho > theta = {theta:g} (others grey)")
    return fig


def plot_pairing(unique_list, names, theta: float):
    """From agreement to fusion order at threshold ``theta``: the agreement of every pair of
    robots against theta (left), the counts at ``theta`` (middle) and the fusion order
    (right)."""
    from .pairing import agreement, fusion_order

    n = len(unique_list)
    counts = np.zeros((n, n), int)
    for a in range(n):
        for b in range(a + 1, n):
            c = agreement(unique_list[a].unique_spectra, unique_list[b].unique_spectra, theta).count
            counts[a, b] = counts[b, a] = c
    plan = fusion_order(counts)
    fig = _new_figure(17.0, 5.4)
    a1, a2, a3 = fig.subplots(1, 3, width_ratios=[1.2, 1.0, 1.0])
    plot_agreement_curves(a1, unique_list, names, theta)
    plot_counts(a2, counts, names, title=f"Agreeing pairs at theta = {theta:g}")
    plot_fusion_plan(a3, plan, names)
    return fig


def plot_matches(world: OccupancyGrid, poses_a, poses_b, *, tolerance: float = 1.0,
                 names=("a", "b"), title: str | None = None, max_lines: int = 400):
    """Agreeing unique-pose pairs drawn where they truly are in the world (for teaching: the
    merger never sees this): a line from robot a's pose to robot b's, green when the two poses
    are within ``tolerance`` m (the same place), red otherwise.

    Parameters
    ----------
    world : OccupancyGrid
    poses_a, poses_b : (M, 2 or 3) array
        True world positions of the two poses of each agreeing pair.
    tolerance : float
        Distance (m) under which a pair counts as the same place.
    names : (str, str)
    title : str, optional
    max_lines : int
        At most this many red lines are drawn (an even subsample); the counts use all pairs.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.lines import Line2D

    def xy(p):
        a = np.asarray(p, float)
        return a[:, :2] if a.ndim == 2 and len(a) else np.zeros((0, 2))

    pa, pb = xy(poses_a), xy(poses_b)
    if len(pa) != len(pb):
        raise InputError(f"poses_a and poses_b must pair up, got {len(pa)} and {len(pb)} poses")
    d = np.hypot(pa[:, 0] - pb[:, 0], pa[:, 1] - pb[:, 1])
    good = d < tolerance
    fig = _new_figure(10.0, 7.0)
    ax = fig.subplots()
    plot_grid(ax, world, title="", alpha=0.6)
    bad = np.flatnonzero(~good)
    if bad.size > max_lines:
        bad = bad[np.linspace(0, bad.size - 1, max_lines).round().astype(int)]
    for i in bad:
        ax.plot(*np.stack([pa[i], pb[i]]).T, "-", color="tab:red", lw=0.4, alpha=0.35)
    for i in np.flatnonzero(good):
        ax.plot(*np.stack([pa[i], pb[i]]).T, "-", color="tab:green", lw=1.2, alpha=0.9)
    ax.plot(pb[good, 0], pb[good, 1], "o", color="tab:green", ms=3)
    frac = float(good.mean()) if len(d) else 0.0
    ax.set_title(title if title is not None else
                 f"{len(d)} agreeing pairs {names[0]} ~ {names[1]}, at their true places: "
                 f"{int(good.sum())} ({100 * frac:.0f}%) are the same place", fontsize=10)
    ax.legend(handles=[Line2D([], [], color="tab:green", lw=1.5,
                              label=f"same place (< {tolerance:g} m apart)"),
                       Line2D([], [], color="tab:red", lw=1, alpha=0.6,
                              label="alike, but different places" +
                                    (f" ({max_lines} of {int((~good).sum())} drawn)"
                                     if (~good).sum() > max_lines else ""))],
              loc="upper right", fontsize=8, framealpha=0.9)
    return fig


# -- PSO alignment (eqs. 3-4) ------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class CostSurface:
    """The eq. 3 objective over a ``(dx, dy)`` grid at one ``dphi`` (for drawing).

    ``dx`` (nx,) and ``dy`` (ny,) in metres, ``dphi`` in radians, ``cost`` (ny, nx)."""

    dx: np.ndarray
    dy: np.ndarray
    dphi: float
    cost: np.ndarray

    @property
    def extent(self) -> tuple[float, float, float, float]:
        hx = (self.dx[1] - self.dx[0]) / 2 if self.dx.size > 1 else 0.5
        hy = (self.dy[1] - self.dy[0]) / 2 if self.dy.size > 1 else 0.5
        return (self.dx[0] - hx, self.dx[-1] + hx, self.dy[0] - hy, self.dy[-1] + hy)


def cost_surface(field, moving, dphi: float, *, center=(0.0, 0.0), half_width: float = 10.0,
                 n: int = 121) -> CostSurface:
    """Evaluate eq. 3 (:func:`~fusionkit.alignment.mse_cost`) on an ``n x n`` grid of
    ``(dx, dy)`` around ``center`` (m) at a fixed ``dphi`` (rad)."""
    from .alignment import mse_cost

    dx = center[0] + np.linspace(-half_width, half_width, n)
    dy = center[1] + np.linspace(-half_width, half_width, n)
    X, Y = np.meshgrid(dx, dy)
    params = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, float(dphi))])
    return CostSurface(dx, dy, float(dphi), mse_cost(field, moving, params).reshape(X.shape))


def plot_cost_surface(ax, surface: CostSurface, *, truth=None, colorbar: bool = True,
                      title: str | None = None):
    """Draw a :class:`CostSurface` (low cost dark), with the true ``(dx, dy)`` starred."""
    im = ax.imshow(surface.cost, origin="lower", extent=surface.extent, cmap="magma",
                   interpolation="nearest", aspect="equal")
    if truth is not None:
        ax.plot(truth[0], truth[1], "*", color="cyan", mec="k", ms=16, label="true (dx, dy)")
        ax.legend(loc="upper right", fontsize=8, framealpha=0.9)
    ax.set_xlabel("dx (m)")
    ax.set_ylabel("dy (m)")
    ax.set_title(title if title is not None else
                 f"MSE of the masks (eq. 3) at dphi = {np.degrees(surface.dphi):.1f} deg")
    if colorbar:
        cb = ax.figure.colorbar(im, ax=ax, shrink=0.85)
        cb.set_label("MSE (eq. 3)")
    return im


def plot_swarm(ax, surface: CostSurface, positions, *, best=None, truth=None,
               iteration: int | None = None, colorbar: bool = False):
    """The swarm over the cost surface: each particle at its ``(dx, dy)``, coloured by how far
    its ``dphi`` is from the surface's (the surface is one slice of the 3-D search space).

    ``colorbar`` adds the particles' colour scale to the axes. Returns the particles'
    ``PathCollection`` (for a colour bar shared by several axes)."""
    from matplotlib.lines import Line2D

    plot_cost_surface(ax, surface, colorbar=False, title="")
    p = np.asarray(positions, float)
    off = np.degrees(np.abs((p[:, 2] - surface.dphi + np.pi) % (2 * np.pi) - np.pi))
    sc = ax.scatter(p[:, 0], p[:, 1], c=off, cmap="winter_r", vmin=0, vmax=180, s=26,
                    edgecolors="w", linewidths=0.6, zorder=3)
    if colorbar:
        cb = ax.figure.colorbar(sc, ax=ax, shrink=0.85)
        cb.set_label("particle's dphi off the slice's (deg)")
    handles = [Line2D([], [], marker="o", color="w", mfc="tab:green", mec="w", ls="", ms=6,
                      label="particle")]
    if best is not None:
        ax.plot(best[0], best[1], "P", color="w", mec="k", ms=13, zorder=4)
        handles.append(Line2D([], [], marker="P", color="w", mec="k", ls="", ms=10,
                              label="swarm's best so far"))
    if truth is not None:
        ax.plot(truth[0], truth[1], "*", color="cyan", mec="k", ms=15, zorder=4)
        handles.append(Line2D([], [], marker="*", color="cyan", mec="k", ls="", ms=12,
                              label="true (dx, dy)"))
    ax.set_xlim(surface.extent[:2])
    ax.set_ylim(surface.extent[2:])
    ax.set_title("swarm" if iteration is None else f"iteration {iteration}")
    ax.legend(handles=handles, loc="upper right", fontsize=7, framealpha=0.9)
    return sc


def plot_surfaces(surfaces, *, truth=None, titles=None):
    """Several :class:`CostSurface` side by side (for example the whole search box and a zoom
    on the true alignment)."""
    surfaces = list(surfaces)
    fig = _new_figure(7.0 * len(surfaces), 5.6)
    axes = np.atleast_1d(fig.subplots(1, len(surfaces)))
    for i, (ax, sf) in enumerate(zip(axes, surfaces)):
        plot_cost_surface(ax, sf, truth=truth, title=None if titles is None else titles[i])
    return fig


def _state_at(states, iteration: int):
    for st in states:
        if st.iteration == iteration:
            return st
    raise InputError(f"no swarm state of iteration {iteration}; recorded iterations are "
                     f"{states[0].iteration}..{states[-1].iteration}")


def plot_swarm_snapshots(surface: CostSurface, states, iterations, *, truth=None,
                         title: str | None = None):
    """The swarm at a few iterations, side by side.

    Parameters
    ----------
    surface : CostSurface
    states : sequence of PSOState
        The swarm after each iteration, as a PSO callback receives it.
    iterations : sequence of int
        Which iterations to draw.
    truth : (dx, dy), optional
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    its = [int(i) for i in iterations]
    cols = min(len(its), 3)
    rows = int(np.ceil(len(its) / cols))
    size = 4.6 if len(its) > 1 else 6.0
    fig = _new_figure(size * cols + 1.0, size * 0.95 * rows + 0.5)
    axes = np.atleast_1d(fig.subplots(rows, cols)).ravel()
    for ax, i in zip(axes, its):
        st = _state_at(states, i)
        sc = plot_swarm(ax, surface, st.positions, best=st.best_position, truth=truth, iteration=i)
        ax.set_title(f"iteration {i}: best MSE {st.best_cost:.4f}", fontsize=9)
        if ax is not axes[0]:
            ax.get_legend().remove()
    for ax in axes[len(its):]:
        ax.set_visible(False)
    cb = fig.colorbar(sc, ax=list(axes[: len(its)]), shrink=0.8, aspect=30)
    cb.set_label("particle's dphi off the slice's (deg)")
    fig.suptitle(title if title is not None else
                 f"The swarm over the MSE surface at dphi = {np.degrees(surface.dphi):.1f} deg")
    return fig


def plot_pso_run(surface: CostSurface, states, alignment, reference, moving, *, truth=None,
                 true_cost: float | None = None):
    """One alignment by PSO: the final swarm over the cost surface, the convergence curve and
    the masks aligned by the result.

    Parameters
    ----------
    surface : CostSurface
    states : sequence of PSOState
        The swarm after each iteration (from the callback).
    alignment : Alignment
        The result of :func:`~fusionkit.alignment.align_points`.
    reference, moving : (K, 2), (L, 2) arrays
        The masks' points (m), each in its own frame.
    truth : Transform2D, optional
        The true transform moving -> reference.
    true_cost : float, optional
        The MSE at the true alignment, drawn on the convergence curve.

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig = _new_figure(17.0, 5.3)
    a1, a2, a3 = fig.subplots(1, 3)
    last = states[-1]
    t_xy = None if truth is None else truth.to_paper()[:2]
    plot_swarm(a1, surface, last.positions, best=last.best_position, truth=t_xy, colorbar=True)
    a1.set_title(f"swarm after {last.iteration} iterations ({len(last.positions)} particles)",
                 fontsize=10)
    plot_convergence(a2, {"best MSE of this run": alignment.pso})
    if true_cost is not None:
        a2.axhline(true_cost, color="k", ls="--", lw=1.0, label="MSE at the true alignment")
        a2.legend(loc="upper right", fontsize=8, framealpha=0.9)
    title = "Masks aligned by the swarm's best"
    if truth is not None:
        dt, dr = alignment.transform.error_to(truth)
        title += f"\nerror {dt:.2f} m, {np.degrees(dr):.1f} deg from the truth"
    plot_masks(a3, reference, moving, alignment.transform, title=title)
    return fig


def plot_convergence(ax, runs, *, title: str | None = None):
    """Best cost against iteration for one or more PSO runs.

    ``runs`` maps a label to a :class:`~fusionkit.pso.PSOResult` or a history array."""
    for i, (label, r) in enumerate(dict(runs).items()):
        h = np.asarray(getattr(r, "history", r), float)
        ax.plot(np.arange(h.size), h, "-", lw=1.5, label=label, color=f"C{i}")
    ax.set_xlabel("iteration")
    ax.set_ylabel("best MSE so far (eq. 3)")
    ax.set_title(title if title is not None else "Convergence of the swarm")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8, framealpha=0.9)


def plot_masks(ax, reference, moving, transform=None, *, names=("reference", "moving"),
               colours=("tab:blue", "tab:red"), title: str | None = None):
    """The two masks (scan end points of the matched unique poses) in the reference frame,
    the moving one moved by ``transform`` (m)."""
    ref = np.asarray(reference, float)
    mov = np.asarray(moving, float)
    if transform is not None:
        mov = transform(mov)
    ax.plot(ref[:, 0], ref[:, 1], ".", color=colours[0], ms=1.5, alpha=0.6,
            label=f"{names[0]} mask ({len(ref)} points)")
    ax.plot(mov[:, 0], mov[:, 1], ".", color=colours[1], ms=1.5, alpha=0.6,
            label=f"{names[1]} mask ({len(mov)} points)")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m, reference frame)")
    ax.set_ylabel("y (m, reference frame)")
    ax.set_title(title if title is not None else "Masks")
    leg = ax.legend(loc="upper right", fontsize=8, framealpha=0.9, markerscale=6)
    return leg


def plot_mask_panels(reference, moving, transforms, *, names=("reference", "moving")):
    """The two masks overlaid once per entry of ``transforms`` (``{panel title: Transform2D or
    None}``; None draws the moving mask as recorded, in its own frame)."""
    items = list(dict(transforms).items())
    fig = _new_figure(6.6 * len(items), 6.0)
    axes = np.atleast_1d(fig.subplots(1, len(items)))
    for ax, (title, t) in zip(axes, items):
        plot_masks(ax, reference, moving, t, names=names, title=title)
    return fig


# -- fusion (Section 3.6) and metrics (Table 1) -------------------------------------------------
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
    state_legend(axes[2], loc="upper left", fontsize=7)
    axes[2].get_legend().set_bbox_to_anchor((1.02, 1.0))
    return fig


def plot_fusion_steps(fused, names=None, *, metrics=None, title: str | None = None):
    """The fused map growing: one panel per step (``M1``, ``M1,2``, ...), cells tinted by the
    robot that first saw them; with ``metrics`` (one :class:`~fusionkit.metrics.MapMetrics`
    per step) the completeness and precision are in the panels' titles."""
    from .metrics import table1_label

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
            t += f"\ncompleteness {m.completeness:.1f}%, precision {m.precision:.1f}%"
        plot_fused(ax, fused, names, step=i, title=t, legend=(i == n - 1))
        ax.title.set_fontsize(9)
    for ax in axes[n:]:
        ax.set_visible(False)
    fig.suptitle(title if title is not None else
                 "The fused map growing, one map per step (free cells tinted by the robot that first saw them)")
    return fig


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
    from matplotlib.patches import Patch

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
        labels = ("unknown in both", "known in the world only", "free in the map",
                  "true wall the map misses", "wall off the truth", "wall on the truth")
        ax.legend(handles=[Patch(facecolor=c, edgecolor="0.3", label=s)
                           for c, s in zip(_TRUTH_COLOURS[1:], labels[1:])],
                  loc="upper right", fontsize=7, framealpha=0.9)


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
    fig = _new_figure(5.2 * cols, 5.2 * aspect * rows + 0.8)
    axes = np.atleast_1d(fig.subplots(rows, cols)).ravel()
    word = {"success": "right", "wrong": "WRONG", "refused": "refused"}
    for i, (ax, m) in enumerate(zip(axes, methods)):
        rec = record["methods"][m]
        states = ", ".join(f"map {e['map'] + 1} {word.get(e['status'], e['status'])}"
                           for e in rec["maps"])
        plot_on_truth(ax, _payload_grid(grids["fused"][m]), world, ref_true,
                      title=f"{m}\n{states}", legend=(i == len(methods) - 1))
        ax.title.set_fontsize(9)
        r0, r1 = known[0].min(), known[0].max() + 1
        c0, c1 = known[1].min(), known[1].max() + 1
        ox, oy, res = world.origin[0], world.origin[1], world.resolution
        ax.set_xlim(ox + c0 * res, ox + c1 * res)
        ax.set_ylim(oy + r0 * res, oy + r1 * res)
    for ax in axes[len(methods):]:
        ax.set_visible(False)
    fig.suptitle(f"Case {record['index']}: {record['robots']} maps of {record['world']} "
                 f"({record['mode']}), each method's fused map placed in the world by the "
                 f"reference map's true pose")
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
    fig = _new_figure(15.0, 0.55 * len(methods) + 3.2)
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
    a1.legend(loc="lower right", fontsize=8, framealpha=0.9)
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
    a2.legend(loc="lower right", fontsize=8, framealpha=0.9)
    a2.grid(axis="x", alpha=0.3)
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
    from .metrics import PAPER_TABLE1, table1_label

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


__all__ += ["robot_colour", "owner_image", "plot_fused", "plot_merge", "plot_scan", "plot_drift",
            "plot_section_spectra", "plot_divergence", "plot_unique_poses", "plot_unique_summary",
            "plot_rotation_invariance", "plot_rho_matrix", "agreement_curves",
            "plot_agreement_curves", "plot_counts", "plot_fusion_plan", "plot_matches",
            "CostSurface", "cost_surface", "plot_cost_surface", "plot_swarm",
            "plot_swarm_snapshots", "plot_convergence", "plot_masks", "plot_cells",
            "plot_cell_fusion", "plot_fusion_steps", "plot_table1", "state_legend", "plot_worlds",
            "plot_unique_in_world", "plot_rho_overview", "plot_pairing", "plot_surfaces",
            "plot_pso_run", "plot_mask_panels", "plot_case", "plot_on_truth", "plot_bench_case",
            "plot_bench_summary"]
