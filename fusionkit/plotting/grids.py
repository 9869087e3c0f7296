"""Grids drawn in metres, the robots' colours and the shared figure helpers."""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..grid import OccupancyGrid
from ..resample import canvas_for, resample
from ..transform import Transform2D

__all__ = ["ROBOT_COLOURS", "grid_image", "plot_grid", "robot_colour", "state_legend", "owner_image"]


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
    if not isinstance(grid, OccupancyGrid):
        raise InputError(f"plot_grid draws an OccupancyGrid (load a map file with load_map), got "
                         f"{type(grid).__name__}")
    if transform is not None and not isinstance(transform, Transform2D):
        raise InputError(f"transform must be a Transform2D, got {type(transform).__name__}")
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


def state_legend(ax, extra=(), *, loc="outside", fontsize=7, free: bool = True):
    """Add a legend of the three cell states (free white, unknown grey, occupied black),
    after the ``extra`` legend handles; ``free=False`` leaves the free entry out. By default
    (``loc="outside"``) it stands right of the axes, where it covers no part of the map;
    any other ``loc`` places it inside the axes, as :meth:`matplotlib.axes.Axes.legend` does.
    Given a figure for ``ax``, the legend stands under all of its panels."""
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch

    handles = list(extra) + ([Patch(facecolor="white", edgecolor="0.3", label="free")] if free else [])
    handles += [Patch(facecolor=(0.78, 0.78, 0.78), edgecolor="0.3", label="unknown"),
                Patch(facecolor="black", edgecolor="0.3", label="occupied")]
    if isinstance(ax, Figure):   # a figure's legend: under all its panels
        ax.legend(handles=handles, loc="outside lower center", ncols=min(len(handles), 4),
                  fontsize=fontsize, framealpha=0.9)
    elif loc == "outside":
        ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0,
                  fontsize=fontsize, framealpha=0.9)
    else:
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
