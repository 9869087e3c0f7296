"""The world and the robots: simulations, scans, odometry drift, the worlds."""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..grid import OccupancyGrid
from .grids import _new_figure, plot_grid, ROBOT_COLOURS, state_legend

__all__ = ["plot_simulation", "plot_scan", "plot_drift", "plot_worlds"]


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
    ax_sig.set_title(f"The scan as a signal f(x): the range of each of its {log.n_beams} beams, "
                     f"by angle (input of eq. 1)")
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
    state_legend(fig)
    return fig
