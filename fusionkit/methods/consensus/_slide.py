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

from ...transform import Transform2D
from ._index import MapIndex
from ._verify import _in_cells, _states, _to_cells

__all__ = ["cross_wall"]

#: Radius (cells) of the neighbourhood a wall cell's direction is read from.
NORMAL_RADIUS = 3
#: Neighbours (itself included) a wall cell needs for a direction: fewer is a speck.
NORMAL_LEAST = 4
#: The cell offsets ``(drow, dcol)`` within ``NORMAL_RADIUS`` (29 lattice points of a disc) and,
#: per offset, the moments summed over a neighbourhood: ``1, dc, dr, dc^2, dr^2, dc dr``.
_OFFSETS = np.array([(dr, dc) for dr in range(-NORMAL_RADIUS, NORMAL_RADIUS + 1)
                     for dc in range(-NORMAL_RADIUS, NORMAL_RADIUS + 1)
                     if dr * dr + dc * dc <= NORMAL_RADIUS * NORMAL_RADIUS], np.int64)
_MOMENTS = np.column_stack([np.ones(len(_OFFSETS)), _OFFSETS[:, 1], _OFFSETS[:, 0],
                            _OFFSETS[:, 1] ** 2, _OFFSETS[:, 0] ** 2,
                            _OFFSETS[:, 1] * _OFFSETS[:, 0]]).astype(np.float64)


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


def _surface_cells(b: MapIndex) -> np.ndarray:
    """``(row, col)`` (int64) of B's wall cells on a wall's surface, in the order of ``b.points``
    (kept in B's ``cache``)."""
    got = b.cache.get("surface cells")
    if got is None:
        got = b.cache["surface cells"] = np.argwhere(b.occupied)[_surface(b)]
    return got


def _meeting(a: MapIndex, b: MapIndex, t: Transform2D) -> np.ndarray:
    """``(row, col)`` in B's grid of B's wall cells on a wall's surface that land beside A's
    walls at ``t`` (B -> A)."""
    if len(b.points) == 0:
        return np.zeros((0, 2), np.int64)
    cx, cy, cth = _to_cells(a, t)
    rc = _surface_cells(b)
    pts = _in_cells(b, b.points, a.resolution)[_surface(b)]
    c, s = math.cos(cth), math.sin(cth)
    x = c * pts[:, 0] - s * pts[:, 1] + cx
    y = s * pts[:, 0] + c * pts[:, 1] + cy
    col, row = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    st = _states(a)
    inside = (row >= 0) & (row < st.shape[0]) & (col >= 0) & (col < st.shape[1])
    meet = np.zeros(len(x), bool)
    meet[inside] = (st[row[inside], col[inside]] & 1) > 0
    return rc[meet]


def _least_spread(cells: np.ndarray) -> float:
    """For wall cells ``cells`` (``(row, col)`` of one grid): the smaller eigenvalue of the sum
    of ``n n^T`` over their local normals ``n`` (each the direction across the cells of
    ``cells`` within ``NORMAL_RADIUS``): how many cells of wall face the direction they hold
    least.

    A cell's neighbourhood is read on the grid, in integers: its scatter (times the count) is
    exact, so whether it has a main direction at all does not depend on rounding. One that has
    none (a square pillar, a crossing: the scatter is the same every way) faces every way,
    half a cell each way. With each normal at angle ``psi`` written as the unit vector at
    ``2 psi`` (``u, v``; zero for those), the sum of ``n n^T`` has eigenvalues
    ``(m -+ |sum (u, v)|) / 2`` for ``m`` cells; the sums are exactly rounded
    (:func:`math.fsum`), so the measure is the same on any machine."""
    if len(cells) < NORMAL_LEAST:
        return 0.0
    lo = cells.min(axis=0) - NORMAL_RADIUS
    rows, cols = (cells.max(axis=0) - lo + NORMAL_RADIUS + 1).tolist()
    r, c = cells[:, 0] - lo[0], cells[:, 1] - lo[1]
    img = np.zeros(rows * cols, np.uint8)
    img[r * cols + c] = 1
    # which of the 29 neighbours are wall, then each neighbourhood's moments: sums of small
    # integers, exact in floating point in any order
    flat = (r * cols + c)[:, None] + (_OFFSETS[:, 0] * cols + _OFFSETS[:, 1])[None, :]
    near = img[flat].astype(np.float64)
    n, sx, sy, sxx, syy, sxy = (near @ _MOMENTS).T
    keep = n >= NORMAL_LEAST
    n, sx, sy, sxx, syy, sxy = (m[keep] for m in (n, sx, sy, sxx, syy, sxy))
    # the scatter times the count (exact): its anisotropy (a, b) is (cos, sin) of twice the
    # major axis' angle, times its size; the normal is at 90 degrees from the axis
    a = (n * sxx - sx * sx) - (n * syy - sy * sy)
    b = 2.0 * (n * sxy - sx * sy)
    size = np.sqrt(a * a + b * b)
    some = size > 0
    u = np.zeros(len(n))
    v = np.zeros(len(n))
    u[some], v[some] = -a[some] / size[some], -b[some] / size[some]
    m = len(n)
    return max(0.0, 0.5 * (m - math.hypot(math.fsum(u.tolist()), math.fsum(v.tolist()))))


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
