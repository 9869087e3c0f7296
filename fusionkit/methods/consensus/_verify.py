"""Refining a hypothesis on the whole maps, and checking it.

Refiners
--------
* :func:`refine_icp`: iterative closest points on the grid. Each of B's wall points is paired
  with the nearest wall cell of A (read off A's distance transform) when that is closer than a
  gate, and the rigid motion that best fits the pairs (least squares, closed form) is applied;
  the gate shrinks from 8 to 2 cells. A numba kernel does the whole loop.
* :func:`refine_pso`: the paper's swarm (eq. 3's MSE between a softened raster of A's walls and
  B's wall points moved by eq. 4), started on the hypothesis and searching only a small box
  around it: a refiner, not a blind search.

Verification
------------
:func:`verify` moves each map's wall cells into the other and counts, where the other map is
known, those within one cell of one of its walls (agreement) and those on its clear free space,
at least three cells from any wall (conflict). A right placement agrees nearly everywhere both
maps are known; a wrong one draws walls across the other map's open floor. A wall seen from one
side only (the room in front of it, :attr:`MapIndex.sides`) agrees only where the other map
knows that room as free space: two buildings' outer walls laid back to back, or a thin wall
laid along a thick one, meet cell for cell and yet are no evidence that the maps show one place.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..._jit import njit
from ...alignment import make_field, mse_cost
from ...pso import PSOConfig, pso_minimize
from ...transform import Transform2D
from ._index import MapIndex

__all__ = ["rigid_fit", "refine_icp", "refine_icp_numpy", "refine_cloud", "refine_pso", "Check",
           "verify", "displacement", "typical_move", "DEFAULT_GATES"]

#: Pairing distances (cells) of the ICP stages, each run until the motion settles.
DEFAULT_GATES = (8.0, 5.0, 3.0, 2.0)


def rigid_fit(src: np.ndarray, dst: np.ndarray) -> Transform2D:
    """The rigid motion ``T`` minimising ``sum |T(src_k) - dst_k|^2`` (closed form, 2-D Kabsch)."""
    ms, md = src.mean(axis=0), dst.mean(axis=0)
    s, d = src - ms, dst - md
    num = float((s[:, 0] * d[:, 1] - s[:, 1] * d[:, 0]).sum())
    den = float((s[:, 0] * d[:, 0] + s[:, 1] * d[:, 1]).sum())
    th = math.atan2(num, den)
    c, sn = math.cos(th), math.sin(th)
    return Transform2D(md[0] - (c * ms[0] - sn * ms[1]), md[1] - (sn * ms[0] + c * ms[1]), th)


@njit
def _icp_kernel(pts, tx, ty, th, gated, near_r, near_c, gates, iterations, min_pairs, settle):
    """ICP in A's cell frame (units: cells). ``pts`` are B's points already in cell units of a
    frame aligned with A's cells; only points landing on cells whose ``gated`` distance (the
    distance to A's nearest wall where A is usable, infinite elsewhere) is within the gate are
    paired. Returns ``(tx, ty, th, pairs)`` of the final motion. Each step moves B's points into
    cells in one loop (which the compiler vectorises), pairs them in a second and fits the pairs
    kept (B's point and its wall) in closed form (:func:`_fit_pairs`)."""
    rows, cols = gated.shape
    n = pts.shape[0]
    src = np.empty((n, 2))
    dst = np.empty((n, 2))
    p0 = np.ascontiguousarray(pts[:, 0])
    p1 = np.ascontiguousarray(pts[:, 1])
    cc = np.empty(n, np.int64)
    rr = np.empty(n, np.int64)
    pairs = 0
    for g in range(gates.shape[0]):
        gate = gates[g]
        for _ in range(iterations):
            c = math.cos(th)
            s = math.sin(th)
            m = 0
            # B's points in A's cells
            for k in range(n):
                cc[k] = math.floor(c * p0[k] - s * p1[k] + tx)
                rr[k] = math.floor(s * p0[k] + c * p1[k] + ty)
            # the pairs
            for k in range(n):
                ci = cc[k]
                ri = rr[k]
                if 0 <= ri < rows and 0 <= ci < cols and gated[ri, ci] <= gate:
                    src[m, 0] = p0[k]
                    src[m, 1] = p1[k]
                    dst[m, 0] = near_c[ri, ci] + 0.5
                    dst[m, 1] = near_r[ri, ci] + 0.5
                    m += 1
            pairs = m
            if m < min_pairs:
                return tx, ty, th, m
            tx, ty, th, moved, turned = _fit_pairs(src, dst, m, tx, ty, th)
            if moved < settle and turned < 1e-4:
                break
    return tx, ty, th, pairs


@njit
def _fit_pairs(src, dst, m, tx, ty, th):
    """The rigid motion ``(tx, ty, theta)`` fitting ``src[:m]`` to ``dst[:m]`` (as
    :func:`rigid_fit`), and how far it moved and turned from the last one ``(tx, ty, th)``:
    ``(tx, ty, theta, moved, turned)``."""
    sx = 0.0
    sy = 0.0
    dx = 0.0
    dy = 0.0
    for k in range(m):
        sx += src[k, 0]
        sy += src[k, 1]
        dx += dst[k, 0]
        dy += dst[k, 1]
    sx, sy, dx, dy = sx / m, sy / m, dx / m, dy / m   # the centroids
    num = 0.0
    den = 0.0
    for k in range(m):
        px = src[k, 0] - sx
        py = src[k, 1] - sy
        qx = dst[k, 0] - dx
        qy = dst[k, 1] - dy
        num += px * qy - py * qx
        den += px * qx + py * qy
    nth = math.atan2(num, den)
    c = math.cos(nth)
    s = math.sin(nth)
    ntx = dx - (c * sx - s * sy)
    nty = dy - (s * sx + c * sy)
    return (ntx, nty, nth, abs(ntx - tx) + abs(nty - ty),
            abs(math.atan2(math.sin(nth - th), math.cos(nth - th))))


def _gated(a: MapIndex) -> np.ndarray:
    """A's distance to its nearest wall (cells) where another map's walls can be paired with
    it (``usable``), infinite elsewhere: one look-up tells whether a point pairs at a gate.
    Kept in A's ``cache``."""
    g = a.cache.get("gated")
    if g is None:
        g = np.where(a.usable.astype(bool), a.dist, np.float32(np.inf)).astype(np.float32)
        a.cache["gated"] = g
    return g


def _wrap(theta: float) -> float:
    # wrap_angle for a float, as Transform2D applies it
    return (theta + math.pi) % (2.0 * math.pi) - math.pi


def _origin(a: MapIndex) -> tuple:
    """A's origin transform and its inverse, with their cosines and sines (kept in A's
    ``cache``: every refinement and check of A's pairs uses them)."""
    got = a.cache.get("origin")
    if got is None:
        o = a.grid.origin_transform
        inv = o.inverse
        got = a.cache["origin"] = (o, math.cos(o.theta), math.sin(o.theta),
                                   inv, math.cos(inv.theta), math.sin(inv.theta))
    return got


def _to_cells(a: MapIndex, t: Transform2D) -> tuple[float, float, float]:
    """``t`` (B map frame -> A map frame, m) as a motion ``(x, y, theta)`` into A's cell frame,
    in cells, for points given in B's map frame divided by the resolution.

    The arithmetic of ``origin_transform.inverse @ t`` with the translation divided by the
    resolution, written out (transforms are made in the inner loops of the search)."""
    _, _, _, inv, c, s = _origin(a)
    res = a.resolution
    x = c * t.x - s * t.y + inv.x
    y = s * t.x + c * t.y + inv.y
    return x / res, y / res, _wrap(_wrap(inv.theta + t.theta))


def _from_cells(a: MapIndex, tx: float, ty: float, th: float) -> Transform2D:
    """The motion ``(tx, ty, th)`` in A's cell frame back to B map frame -> A map frame
    (``origin_transform @ Transform2D(tx * res, ty * res, th)``, written out)."""
    o, c, s, _, _, _ = _origin(a)
    res = a.resolution
    x, y = tx * res, ty * res
    return Transform2D(c * x - s * y + o.x, s * x + c * y + o.y, o.theta + _wrap(th))


def _in_cells(index: MapIndex, points: np.ndarray, resolution: float) -> np.ndarray:
    """``points`` (m) divided by ``resolution``, contiguous; for the map's own wall points
    (``index.points``, ``index.refine_points``) kept in its ``cache``, as every check and
    refinement of its pairs uses them."""
    if points is index.points or points is index.refine_points or points is index.sides:
        key = ("cells", "points" if points is index.points else
               "refine" if points is index.refine_points else "sides", resolution)
        got = index.cache.get(key)
        if got is None:
            got = index.cache[key] = np.ascontiguousarray(points / resolution, np.float64)
        return got
    return np.ascontiguousarray(points / resolution, np.float64)


def refine_icp(a: MapIndex, points_b: np.ndarray, start: Transform2D, *,
               gates=DEFAULT_GATES, iterations: int = 10, cells: bool = False) -> Transform2D:
    """Iterative closest points from ``start`` (B -> A) with pairs read off A's distance field.

    Only B's points that land where A is known are paired: a wall of B in A's unexplored space
    has no counterpart in A, and pairing it with A's nearest wall would pull the fit.

    Parameters
    ----------
    a : MapIndex
        The reference map.
    points_b : (K, 2) float
        B's wall points (m, B's frame).
    start : Transform2D
        Initial transform B -> A.
    gates : sequence of float
        Successive pairing distances (cells of A), each used for up to ``iterations`` steps
        (fewer when the motion settles below a twentieth of a cell).
    cells : bool
        Whether ``points_b`` are already divided by A's resolution (contiguous float64), as
        callers refining many starts with the same points pass them.
    """
    if len(points_b) == 0:
        return start
    cx, cy, cth = _to_cells(a, start)
    pts = points_b if cells else np.ascontiguousarray(points_b / a.resolution, np.float64)
    tx, ty, th, _ = _icp_kernel(pts, cx, cy, cth, _gated(a), a.nearest[0], a.nearest[1],
                                np.asarray(gates, np.float64), int(iterations), 10, 0.05)
    return _from_cells(a, float(tx), float(ty), float(th))


def refine_icp_numpy(a: MapIndex, points_b: np.ndarray, start: Transform2D, *,
                     gates=DEFAULT_GATES, iterations: int = 10) -> Transform2D:
    """The same refinement written plainly in numpy (the reference the kernel is tested
    against)."""
    t = start
    res = a.resolution
    for gate in gates:
        for _ in range(iterations):
            ri, ci, inside = a.cells(t(points_b))
            ok = np.zeros(len(points_b), bool)
            rin, cin = ri[inside], ci[inside]
            ok[inside] = (a.dist[rin, cin] <= gate) & a.usable[rin, cin].astype(bool)
            if ok.sum() < 10:
                return t
            dst = a.grid.cell_to_world(a.nearest[0, ri[ok], ci[ok]], a.nearest[1, ri[ok], ci[ok]])
            new = rigid_fit(points_b[ok], dst)
            dt, dr = new.error_to(t)
            t = new
            if dt < 0.05 * res and dr < 1e-4:
                break
    return t


def refine_cloud(cloud_a: np.ndarray, tree_a, cloud_b: np.ndarray, start: Transform2D, *,
                 gates=(0.4, 0.2, 0.1), iterations: int = 8, max_points: int = 1000) -> Transform2D:
    """Iterative closest points between two robots' raw scan end points (m), from ``start``
    (B -> A).

    The grids quantise walls to cells; the recorded scans do not, so on coarse grids this pins
    a placement down more finely. ``tree_a`` is a :class:`scipy.spatial.cKDTree` of
    ``cloud_a``; pairs farther apart than the current gate (m) are left out (trimmed ICP).
    """
    if len(cloud_a) < 10 or len(cloud_b) < 10:
        return start
    pts = cloud_b
    if len(pts) > max_points:
        pts = pts[np.linspace(0, len(pts) - 1, max_points).astype(np.int64)]
    t = start
    for gate in gates:
        for _ in range(iterations):
            q = t(pts)
            d, j = tree_a.query(q, distance_upper_bound=gate)
            ok = np.isfinite(d)
            if ok.sum() < 30:
                return t
            new = rigid_fit(pts[ok], cloud_a[j[ok]])
            dt, dr = new.error_to(t)
            t = new
            if dt < 1e-3 and dr < 1e-5:
                break
    return t


def refine_pso(a_points: np.ndarray, points_b: np.ndarray, start: Transform2D, resolution: float, *,
               half_width: float = 0.6, half_angle: float = math.radians(6.0),
               config: PSOConfig = PSOConfig(particles=24, iterations=30, patience=8),
               seed=0, field=None) -> Transform2D:
    """The swarm of eq. 3 in a box of ``+-half_width`` m and ``+-half_angle`` rad around
    ``start`` (expressed in eq. 4's ``(dx, dy, dphi)``); ``field`` may pass a prebuilt
    softened raster of ``a_points`` (:func:`~fusionkit.alignment.make_field`)."""
    fld = field if field is not None else make_field(a_points, resolution, sigma=1.0)
    dx, dy, dphi = start.to_paper()
    bounds = np.array([[dx - half_width, dx + half_width], [dy - half_width, dy + half_width],
                       [dphi - half_angle, dphi + half_angle]])
    init = np.array([[dx, dy, dphi]])

    def objective(params):
        return mse_cost(fld, points_b, params)                 # eq. 3

    res = pso_minimize(objective, bounds, config=config, seed=seed, init=init)
    return Transform2D.from_paper(*(float(v) for v in res.x))  # eq. 4


@dataclass(frozen=True)
class Check:
    """How two maps agree under a transform B -> A.

    Attributes
    ----------
    score : float
        The smaller of the two directions' agreement fractions: of one map's wall cells that land
        where the other map is known, the fraction within one cell of the other's walls.
    agree_ab, agree_ba : float
        Those fractions for B's walls in A and for A's walls in B.
    overlap : int
        The smaller of the two counts of wall cells landing where the other map is known.
    agreeing : int
        Wall cells (both directions) within one cell of the other map's walls (a wall seen
        from one side only where the other map knows the room in front of it as free space;
        where it does not, the cell is not counted at all).
    disagreeing : int
        Wall cells (both directions) where the other map is known but has no wall within one cell.
    conflicts : int
        Of those, the ones on the other map's clear free space (three cells or more from a wall).
    conflict_fraction : float
        ``conflicts`` over the wall cells counted in both directions.
    """

    score: float
    agree_ab: float
    agree_ba: float
    overlap: int
    agreeing: int
    disagreeing: int
    conflicts: int
    conflict_fraction: float

    def evidence(self) -> float:
        """The robust evidence the decision is taken on: agreeing wall cells, minus one per wall
        cell that misses the other map's walls, minus two more per wall cell on its clear free
        space (three cells or more from any wall). Real sessions of one building disagree at
        their true placement by moved doors, people, glass and one-cell offsets; such misfits
        cost as much as they would have supported, while a wrong placement, which draws walls
        across open floor, loses three times as much per cell."""
        return float(self.agreeing - self.disagreeing - 2 * self.conflicts)

    def quality(self, weight: float = 10.0) -> float:
        """Evidence for the placement: agreeing wall cells minus ``weight`` per disagreeing one.
        A placement that fits a large overlap with a few percent of noise outranks one that fits
        a small patch perfectly, and a shift along repeated structure loses by its misfits."""
        return self.agreeing - weight * self.disagreeing

    def as_dict(self) -> dict:
        return {"score": round(self.score, 4), "agree_ab": round(self.agree_ab, 4),
                "agree_ba": round(self.agree_ba, 4), "overlap": self.overlap,
                "agreeing": self.agreeing, "disagreeing": self.disagreeing,
                "conflicts": self.conflicts, "conflict_fraction": round(self.conflict_fraction, 4)}


@njit
def _count_kernel(pts, sides, sided, tx, ty, th, state):
    """For points (cells of a frame aligned with A's cells) moved by ``(tx, ty, th)``: how many
    land on A's known cells or beside its walls, how many beside its walls, how many on its
    clear free space. ``state``: per cell, bit 0 beside a wall, bit 1 known, bit 2 clear,
    bit 3 a wall (:func:`_states`), one look-up per point. A point that is ``sided`` (a wall
    seen from one side) and lands beside A's walls while the room in front of it (``sides``,
    moved alike; read only for sided points) does not land on A's free space (known, not a
    wall) is not counted at all: the two walls meet, but A has not seen B's room in front of
    them (two outer walls put back to back, or a thin wall laid along a thick one)."""
    rows, cols = state.shape
    c = math.cos(th)
    s = math.sin(th)
    n = 0
    m = 0
    bad = 0
    # the points' cells in one loop (vectorised), then the look-ups
    p0 = np.ascontiguousarray(pts[:, 0])
    p1 = np.ascontiguousarray(pts[:, 1])
    size = pts.shape[0]
    cc = np.empty(size, np.int64)
    rr = np.empty(size, np.int64)
    for k in range(size):
        cc[k] = math.floor(c * p0[k] - s * p1[k] + tx)
        rr[k] = math.floor(s * p0[k] + c * p1[k] + ty)
    for k in range(size):
        ci = cc[k]
        ri = rr[k]
        if 0 <= ri < rows and 0 <= ci < cols:
            st = state[ri, ci]
            near = st & 1
            if near and sided[k]:
                sc = math.floor(c * sides[k, 0] - s * sides[k, 1] + tx)
                sr = math.floor(s * sides[k, 0] + c * sides[k, 1] + ty)
                if not (0 <= sr < rows and 0 <= sc < cols and state[sr, sc] & 10 == 2):
                    continue
            n += near | ((st >> 1) & 1)
            m += near
            bad += (st >> 2) & 1
    return n, m, bad


def _states(a: MapIndex) -> np.ndarray:
    """A's cells as bits: 1 beside a wall (``near``), 2 known, 4 clear free space, 8 a wall
    (kept in A's ``cache``)."""
    st = a.cache.get("states")
    if st is None:
        st = (a.near.astype(np.uint8) | (a.known.astype(np.uint8) << 1)
              | (a.clear.astype(np.uint8) << 2) | (a.occupied.astype(np.uint8) << 3))
        a.cache["states"] = st
    return st


def _one_way(a: MapIndex, points_b: np.ndarray, t: Transform2D,
             b: MapIndex | None = None, sides: bool = True) -> tuple[int, int, int]:
    """For B's walls moved by ``t``: how many land on A's known cells (or beside A's walls),
    how many beside A's walls, how many on A's clear free space (``b``: the map the points
    belong to, whose cache keeps them in cells; with ``b``, its own ``points`` and ``sides``, a
    wall seen from one side counts only where A knows the room in front of it,
    :func:`_count_kernel`)."""
    if len(points_b) == 0:
        return 0, 0, 0
    cx, cy, cth = _to_cells(a, t)
    pts = _in_cells(b, points_b, a.resolution) if b is not None else points_b / a.resolution
    if sides and b is not None and points_b is b.points and len(b.sided) == len(points_b):
        front, sided = _in_cells(b, b.sides, a.resolution), b.sided
    else:
        front, sided = np.zeros((0, 2)), np.zeros(len(pts), np.bool_)     # no point is sided
    n, m, bad = _count_kernel(pts, front, sided, cx, cy, cth, _states(a))
    return int(n), int(m), int(bad)


def verify(a: MapIndex, b: MapIndex, t: Transform2D, *, sides: bool = True) -> Check:
    """Check the transform ``t`` (B's frame -> A's frame) on both maps' walls (without
    ``sides``, a wall meeting a wall agrees whichever room it was seen from)."""
    n_ab, near_ab, bad_ab = _one_way(a, b.points, t, b, sides)
    n_ba, near_ba, bad_ba = _one_way(b, a.points, t.inverse, a, sides)
    f_ab = near_ab / n_ab if n_ab else 0.0
    f_ba = near_ba / n_ba if n_ba else 0.0
    total = n_ab + n_ba
    return Check(min(f_ab, f_ba), f_ab, f_ba, min(n_ab, n_ba), near_ab + near_ba,
                 (n_ab - near_ab) + (n_ba - near_ba), bad_ab + bad_ba,
                 (bad_ab + bad_ba) / total if total else 1.0)


class Placements:
    """Placements kept to tell whether a new one is within a distance of any of them (as
    :func:`displacement` measures it at ``pts``), for the many starts of a search: each
    kept with its rotation's cosine and sine, and one point's move, a lower bound of the
    largest, set aside those clearly farther away before the full measure."""

    def __init__(self, pts):
        self.pts = pts if isinstance(pts, list) else np.asarray(pts, float).tolist()
        self.kept: list = []

    def add(self, t: Transform2D) -> None:
        self.kept.append((math.cos(t.theta), math.sin(t.theta), t))

    def near(self, t: Transform2D, limit: float) -> bool:
        """``any(displacement(t, u, pts) < limit for u in kept)``."""
        if not self.pts:
            return any(displacement(t, u, self.pts) < limit for _, _, u in self.kept)
        ct, st = math.cos(t.theta), math.sin(t.theta)
        x, y = self.pts[0]
        far = 4.0 * limit * limit
        for cu, su, u in self.kept:
            a = ct - cu
            b = st - su
            # the first point's move: when it alone is over twice the limit, so is the largest
            if (a * x - b * y + t.x - u.x) ** 2 + (b * x + a * y + t.y - u.y) ** 2 > far:
                continue
            if displacement(t, u, self.pts) < limit:
                return True
        return False


def displacement(t1: Transform2D, t2: Transform2D, pts) -> float:
    """Largest distance (m) between where ``t1`` and ``t2`` put the points ``pts`` (an
    ``(N, 2)`` array, or a list of ``[x, y]`` for callers comparing many placements)."""
    # the points move by t1 - t2 = (R1 - R2) p + (d1 - d2): plain arithmetic, as this is
    # called for every two candidates of a pair
    a = math.cos(t1.theta) - math.cos(t2.theta)
    b = math.sin(t1.theta) - math.sin(t2.theta)
    ex, ey = t1.x - t2.x, t1.y - t2.y
    worst = 0.0
    for x, y in (pts if isinstance(pts, list) else pts.tolist()):
        d = (a * x - b * y + ex) ** 2 + (b * x + a * y + ey) ** 2
        if d > worst:   # max(worst, d), without the call
            worst = d
    return math.sqrt(worst)


def typical_move(t1: Transform2D, t2: Transform2D, pts: np.ndarray) -> float:
    """Median distance (m) between where ``t1`` and ``t2`` put the points ``pts`` (``(N, 2)``):
    how far most of them move, where :func:`displacement` gives the farthest."""
    if len(pts) == 0:
        return 0.0
    a = math.cos(t1.theta) - math.cos(t2.theta)
    b = math.sin(t1.theta) - math.sin(t2.theta)
    dx = a * pts[:, 0] - b * pts[:, 1] + (t1.x - t2.x)
    dy = b * pts[:, 0] + a * pts[:, 1] + (t1.y - t2.y)
    return float(np.median(np.hypot(dx, dy)))
