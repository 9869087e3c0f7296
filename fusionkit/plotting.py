"""Matplotlib figures of grids, trajectories and simulations.

Every function draws on axes or returns a :class:`matplotlib.figure.Figure`; nothing is shown or
saved here, so the same calls work in notebooks, scripts and tests (with the Agg backend).
Grids are drawn in metres with the map-server palette: occupied black, free white, unknown grey.
"""

from __future__ import annotations

import numpy as np

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
