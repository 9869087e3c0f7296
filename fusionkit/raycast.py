"""Casting LIDAR beams through an occupancy grid (exact grid traversal, numba).

Used by the simulator (beams through the world) and to make virtual scans for maps that come
without recorded scans (beams through a robot's map).
"""

from __future__ import annotations

import math

import numpy as np

from ._jit import pjit, prange

__all__ = ["cast_rays"]


@pjit
def _cast_kernel(blocked, poses_c, angles, max_cells, out):
    """``blocked[r, c]``: 0 open, 1 a cell that returns the beam. ``poses_c`` (N, 3): col, row
    (cell units, continuous), heading (rad). ``out`` (N, B) receives ranges in cells, ``inf``
    for no return."""
    rows, cols = blocked.shape
    n = poses_c.shape[0]
    b = angles.shape[0]
    for i in prange(n):
        px = poses_c[i, 0]
        py = poses_c[i, 1]
        for j in range(b):
            a = poses_c[i, 2] + angles[j]
            dx = math.cos(a)
            dy = math.sin(a)
            cx = int(math.floor(px))
            cy = int(math.floor(py))
            stepx = 1 if dx > 0 else -1
            stepy = 1 if dy > 0 else -1
            nx = (cx + (1 if dx > 0 else 0) - px) / dx if dx != 0.0 else 1e30
            ny = (cy + (1 if dy > 0 else 0) - py) / dy if dy != 0.0 else 1e30
            ddx = abs(1.0 / dx) if dx != 0.0 else 1e30
            ddy = abs(1.0 / dy) if dy != 0.0 else 1e30
            t = 0.0
            res = np.inf
            while t <= max_cells:
                if cx < 0 or cy < 0 or cx >= cols or cy >= rows:
                    break
                if blocked[cy, cx] != 0:
                    res = t
                    break
                if nx < ny:
                    t = nx
                    nx += ddx
                    cx += stepx
                else:
                    t = ny
                    ny += ddy
                    cy += stepy
            out[i, j] = res if res <= max_cells else np.inf


def cast_rays(blocked: np.ndarray, poses_cells: np.ndarray, angles: np.ndarray,
              max_range_cells: float) -> np.ndarray:
    """Ranges (cells) of beams from ``poses_cells`` through ``blocked``.

    Parameters
    ----------
    blocked : (rows, cols) uint8
        0 open, 1 a cell that returns the beam.
    poses_cells : (N, 3) float
        ``(col, row, heading)``: position in continuous cell coordinates (cell (r, c) spans
        ``[c, c+1) x [r, r+1)``), heading in radians from the +col axis towards +row.
    angles : (B,) float
        Beam angles relative to the heading (rad).
    max_range_cells : float
        Beams longer than this return nothing.

    Returns
    -------
    (N, B) float32
        Distance from the pose to the entry point of the first wall cell (cells), ``inf`` where
        nothing returned.
    """
    out = np.empty((len(poses_cells), len(angles)), np.float64)
    _cast_kernel(np.ascontiguousarray(blocked, np.uint8),
                 np.ascontiguousarray(poses_cells, np.float64),
                 np.ascontiguousarray(angles, np.float64), float(max_range_cells), out)
    return out.astype(np.float32)
