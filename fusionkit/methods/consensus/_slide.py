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

import cv2
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


def _surface(b: MapIndex) -> np.ndarray:
    """Which of B's wall points (``b.points``, one per wall cell in row-major order) lie on a
    wall's surface: not every one of their eight neighbours is wall. The inside of a wall 3 or
    more cells thick has no direction of its own (its neighbourhood is a filled block); left out,
    such a wall reads as its two faces, which run the way the wall does (kept in B's
    ``cache``)."""
    got = b.cache.get("surface")
    if got is None:
        occ = b.occupied.astype(np.uint8)
        # (beyond the grid's edge counts as wall: a wall the edge cuts has no end there)
        inside = cv2.erode(occ, np.ones((3, 3), np.uint8)).astype(bool)
        got = b.cache["surface"] = ~inside[b.occupied]
    return got


def _meeting(a: MapIndex, b: MapIndex, t: Transform2D) -> np.ndarray:
    """B's wall cells on a wall's surface (in A's cell units) that land beside A's walls at
    ``t`` (B -> A)."""
    if len(b.points) == 0:
        return np.zeros((0, 2))
    cx, cy, cth = _to_cells(a, t)
    pts = _in_cells(b, b.points, a.resolution)[_surface(b)]
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
    # the major axis of each neighbourhood at angle phi; its normal at phi + 90 degrees (the
    # insides of thick walls, which have none, are not among ``p``: :func:`_surface`)
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

    Only the cells on a wall's surface count (:func:`_surface`): the inside of a thick wall has
    no direction and would count as wall running every way, so that a slide along walls drawn 5
    or more cells thick would pass. A wall 1-2 cells thick is all surface and reads its length;
    a thicker one reads about the length of its two faces."""
    ab = _least_spread(_meeting(a, b, t)) * b.resolution
    ba = _least_spread(_meeting(b, a, t.inverse)) * a.resolution
    return min(ab, ba)
