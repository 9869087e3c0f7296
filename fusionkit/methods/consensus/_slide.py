"""Whether the walls two maps meet along fix a placement in every direction.

Walls that all run one way (one straight wall, the two sides of a corridor, a row of parallel
racks seen side-on) hold a placement across them and not along them: slid along them, the same
walls meet as well. The test of :mod:`._null` draws its wrong placements at random and rarely
lands on those slides, so it can take a map laid along a straight wall of another building as
proof. What fixes the slide is wall facing the other way: the measure here is how much meeting
wall (m) faces the direction the placement is least held in.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from ...transform import Transform2D
from ._index import MapIndex
from ._verify import _in_cells, _states, _to_cells

__all__ = ["cross_wall"]

#: Radius (cells) of the neighbourhood a wall cell's direction is read from.
NORMAL_RADIUS = 3.0
#: Neighbours (itself included) a wall cell needs for a direction: fewer is a speck.
NORMAL_LEAST = 4
#: The most cells within ``NORMAL_RADIUS`` (lattice points of a disc of radius 3).
_BALL = 29


def _meeting(a: MapIndex, b: MapIndex, t: Transform2D) -> np.ndarray:
    """B's wall cells (in A's cell units) that land beside A's walls at ``t`` (B -> A)."""
    if len(b.points) == 0:
        return np.zeros((0, 2))
    cx, cy, cth = _to_cells(a, t)
    pts = _in_cells(b, b.points, a.resolution)
    c, s = math.cos(cth), math.sin(cth)
    x = c * pts[:, 0] - s * pts[:, 1] + cx
    y = s * pts[:, 0] + c * pts[:, 1] + cy
    col, row = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    st = _states(a)
    inside = (row >= 0) & (row < st.shape[0]) & (col >= 0) & (col < st.shape[1])
    meet = np.zeros(len(x), bool)
    meet[inside] = (st[row[inside], col[inside]] & 1) > 0
    return np.column_stack([x[meet], y[meet]])


def _least_spread(p: np.ndarray) -> float:
    """For wall cells ``p`` (cells): the smaller eigenvalue of the sum of ``n n^T`` over their
    local normals ``n`` (each the direction across the cells within ``NORMAL_RADIUS``): how many
    cells of wall face the direction they hold least."""
    if len(p) < NORMAL_LEAST:
        return 0.0
    k = min(_BALL, len(p))
    dist, idx = cKDTree(p).query(p, k=k, distance_upper_bound=NORMAL_RADIUS + 1e-9)
    dist, idx = dist.reshape(len(p), k), idx.reshape(len(p), k)
    used = np.isfinite(dist)
    count = used.sum(axis=1)
    nb = p[np.where(used, idx, 0)]                                   # (N, k, 2)
    w = used[..., None]
    mean = (nb * w).sum(axis=1) / count[:, None]
    d = (nb - mean[:, None, :]) * w
    sxx = (d[..., 0] ** 2).sum(axis=1)
    syy = (d[..., 1] ** 2).sum(axis=1)
    sxy = (d[..., 0] * d[..., 1]).sum(axis=1)
    keep = count >= NORMAL_LEAST
    # the major axis of each neighbourhood at angle phi; its normal at phi + 90 degrees. A
    # neighbourhood with no main direction (the inside of a wall 5 or more cells thick, a
    # filled block) still adds a normal: such walls are counted as running every way (see
    # ``cross_wall``)
    phi = 0.5 * np.arctan2(2.0 * sxy[keep], sxx[keep] - syy[keep])
    nx, ny = -np.sin(phi), np.cos(phi)
    txx, tyy, txy = float((nx * nx).sum()), float((ny * ny).sum()), float((nx * ny).sum())
    half = 0.5 * (txx + tyy)
    return max(0.0, half - math.sqrt(max(0.0, 0.25 * (txx - tyy) ** 2 + txy ** 2)))


def cross_wall(a: MapIndex, b: MapIndex, t: Transform2D) -> float:
    """Metres of the walls that meet at ``t`` (B -> A) facing the direction the placement is
    least held in: about 0 when they all run one way (the placement slides along them), the
    length of the shorter set of meeting walls when they run two ways. The lesser of B's walls
    in A and A's walls in B, so the order of the two maps does not matter.

    Walls drawn 5 or more cells thick are not measured well: the cells inside them have no
    direction of their own and count as wall running every way, so a slide along such walls
    can pass (a corridor of 5-cell walls slid along itself reads about 1.2 m, of 7-cell walls
    several metres, depending on the grid's heading). Weighing each normal by how line-like
    its neighbourhood is fixes that but also lowers the measure of the thin, noisy walls of
    real maps by up to a factor 5, so the threshold would have to be chosen again; not done."""
    ab = _least_spread(_meeting(a, b, t)) * b.resolution
    ba = _least_spread(_meeting(b, a, t.inverse)) * a.resolution
    return min(ab, ba)
