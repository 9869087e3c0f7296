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
maps are known; a wrong one draws walls across the other map's open floor.
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
           "verify", "DEFAULT_GATES", "NullModel", "null_model", "search_tests"]

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
def _icp_kernel(pts, tx, ty, th, dist, near_r, near_c, usable, gates, iterations, min_pairs, settle):
    """ICP in A's cell frame (units: cells). ``pts`` are B's points already in cell units of a
    frame aligned with A's cells; only points landing on ``usable`` cells (A known) are paired.
    Returns ``(tx, ty, th, pairs)`` of the final motion."""
    rows, cols = dist.shape
    n = pts.shape[0]
    pairs = 0
    for g in range(gates.shape[0]):
        gate = gates[g]
        for _ in range(iterations):
            c = math.cos(th)
            s = math.sin(th)
            sx = 0.0
            sy = 0.0
            dx = 0.0
            dy = 0.0
            m = 0
            # first pass: centroids of the paired points
            for k in range(n):
                x = c * pts[k, 0] - s * pts[k, 1] + tx
                y = s * pts[k, 0] + c * pts[k, 1] + ty
                ci = int(math.floor(x))
                ri = int(math.floor(y))
                if 0 <= ri < rows and 0 <= ci < cols and usable[ri, ci] and dist[ri, ci] <= gate:
                    sx += pts[k, 0]
                    sy += pts[k, 1]
                    dx += near_c[ri, ci] + 0.5
                    dy += near_r[ri, ci] + 0.5
                    m += 1
            pairs = m
            if m < min_pairs:
                return tx, ty, th, m
            sx /= m
            sy /= m
            dx /= m
            dy /= m
            num = 0.0
            den = 0.0
            for k in range(n):
                x = c * pts[k, 0] - s * pts[k, 1] + tx
                y = s * pts[k, 0] + c * pts[k, 1] + ty
                ci = int(math.floor(x))
                ri = int(math.floor(y))
                if 0 <= ri < rows and 0 <= ci < cols and usable[ri, ci] and dist[ri, ci] <= gate:
                    px = pts[k, 0] - sx
                    py = pts[k, 1] - sy
                    qx = near_c[ri, ci] + 0.5 - dx
                    qy = near_r[ri, ci] + 0.5 - dy
                    num += px * qy - py * qx
                    den += px * qx + py * qy
            nth = math.atan2(num, den)
            nc = math.cos(nth)
            ns = math.sin(nth)
            ntx = dx - (nc * sx - ns * sy)
            nty = dy - (ns * sx + nc * sy)
            moved = abs(ntx - tx) + abs(nty - ty)
            turned = abs(math.atan2(math.sin(nth - th), math.cos(nth - th)))
            tx, ty, th = ntx, nty, nth
            if moved < settle and turned < 1e-4:
                break
    return tx, ty, th, pairs


def _to_cells(a: MapIndex, t: Transform2D) -> Transform2D:
    """``t`` (B map frame -> A map frame, m) as a motion into A's cell frame, in cells, for
    points given in B's map frame divided by the resolution."""
    local = a.grid.origin_transform.inverse @ t
    res = a.resolution
    return Transform2D(local.x / res, local.y / res, local.theta)


def _from_cells(a: MapIndex, t: Transform2D) -> Transform2D:
    res = a.resolution
    return a.grid.origin_transform @ Transform2D(t.x * res, t.y * res, t.theta)


def refine_icp(a: MapIndex, points_b: np.ndarray, start: Transform2D, *,
               gates=DEFAULT_GATES, iterations: int = 10) -> Transform2D:
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
    """
    if len(points_b) == 0:
        return start
    c = _to_cells(a, start)
    pts = np.ascontiguousarray(points_b / a.resolution, np.float64)
    tx, ty, th, _ = _icp_kernel(pts, c.x, c.y, c.theta, a.dist, a.nearest[0], a.nearest[1],
                                a.usable, np.asarray(gates, np.float64), int(iterations), 10, 0.05)
    return _from_cells(a, Transform2D(tx, ty, th))


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
        Wall cells (both directions) within one cell of the other map's walls.
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
def _count_kernel(pts, tx, ty, th, known, near, clear):
    """For points (cells of a frame aligned with A's cells) moved by ``(tx, ty, th)``: how many
    land on A's known cells or beside its walls, how many beside its walls, how many on its
    clear free space."""
    rows, cols = known.shape
    c = math.cos(th)
    s = math.sin(th)
    n = 0
    m = 0
    bad = 0
    for k in range(pts.shape[0]):
        ci = int(math.floor(c * pts[k, 0] - s * pts[k, 1] + tx))
        ri = int(math.floor(s * pts[k, 0] + c * pts[k, 1] + ty))
        if 0 <= ri < rows and 0 <= ci < cols:
            if near[ri, ci]:
                n += 1
                m += 1
            elif known[ri, ci]:
                n += 1
            if clear[ri, ci]:
                bad += 1
    return n, m, bad


def _one_way(a: MapIndex, points_b: np.ndarray, t: Transform2D) -> tuple[int, int, int]:
    """For B's walls moved by ``t``: how many land on A's known cells (or beside A's walls),
    how many beside A's walls, how many on A's clear free space."""
    if len(points_b) == 0:
        return 0, 0, 0
    c = _to_cells(a, t)
    pts = points_b / a.resolution
    n, m, bad = _count_kernel(pts, c.x, c.y, c.theta, a.known, a.near, a.clear)
    return int(n), int(m), int(bad)


def _one_way_numpy(a: MapIndex, points_b: np.ndarray, t: Transform2D) -> tuple[int, int, int]:
    """The same count written plainly in numpy (the reference the kernel is tested against)."""
    ri, ci, inside = a.cells(t(points_b))
    ri, ci = ri[inside], ci[inside]
    near = a.near[ri, ci]
    n = int((a.known[ri, ci] | near).sum())
    return n, int(near.sum()), int(a.clear[ri, ci].sum())


def verify(a: MapIndex, b: MapIndex, t: Transform2D) -> Check:
    """Check the transform ``t`` (B's frame -> A's frame) on both maps' walls."""
    n_ab, near_ab, bad_ab = _one_way(a, b.points, t)
    n_ba, near_ba, bad_ba = _one_way(b, a.points, t.inverse)
    f_ab = near_ab / n_ab if n_ab else 0.0
    f_ba = near_ba / n_ba if n_ba else 0.0
    total = n_ab + n_ba
    return Check(min(f_ab, f_ba), f_ab, f_ba, min(n_ab, n_ba), near_ab + near_ba,
                 (n_ab - near_ab) + (n_ba - near_ba), bad_ab + bad_ba,
                 (bad_ab + bad_ba) / total if total else 1.0)



def _trials(chk) -> tuple[float, float]:
    """``(hits, trials)`` of a check: wall cells meeting the other map's walls, out of the wall
    cells compared, a cell on the other's clear free space counted as three misses (the
    robust weighting of :meth:`Check.evidence`)."""
    return float(chk.agreeing), float(chk.agreeing + chk.disagreeing + 2 * chk.conflicts)


def _kl(f: float, p: float) -> float:
    """Kullback-Leibler divergence of Bernoulli(f) from Bernoulli(p) (nats)."""
    f = min(max(f, 1e-12), 1 - 1e-12)
    p = min(max(p, 1e-12), 1 - 1e-12)
    return f * math.log(f / p) + (1 - f) * math.log((1 - f) / (1 - p))


@dataclass(frozen=True)
class NullModel:
    """How well two maps' walls meet at wrong placements, and the test a placement is judged by.

    The wrong placements are ``len(fractions)`` placements refined by ICP from random starts
    (a wall of B put on a wall of A at a random rotation) that end away from the placement
    under test: the best a local search finds where the maps do not belong together. At each,
    ``fractions`` holds the share of compared wall cells that meet the other map's walls (a
    cell on clear free space counting as three misses) and ``trials`` the cells compared.
    ``p0`` is their pooled share: the chance that a wall cell meets a wall at a wrong placement.
    Wall cells come in lines, so neighbouring cells agree or not together; ``design`` is the
    factor by which the shares vary more than independent cells would (their variance over the
    binomial one), and a placement's cells count as ``trials / design`` independent ones.

    A placement whose share ``f > p0`` of ``n`` compared cells is then reached by one wrong
    placement with probability at most ``exp(-(n / design) KL(f || p0))`` (Chernoff), and its
    number of false alarms is that times ``tests``, the number of distinct placements a search
    can end on (:func:`search_tests`): the expected count of wrong placements that would fit
    as well, which the user bounds by ``max_false_merge``. Neither depends on the cell size,
    the extent or the clutter of the maps; all three enter through the maps' own wrong
    placements. ``calibration`` (decades) is added to that count's logarithm: measured on
    pairs of different buildings, the model's tail is lighter than the truth's (BENCHMARKS.md).
    """

    fractions: np.ndarray
    trials: np.ndarray
    p0: float
    design: float
    tests: float
    calibration: float = 0.0

    @property
    def usable(self) -> bool:
        """Whether enough wrong placements overlapped to judge by (eight or more)."""
        return len(self.fractions) >= 8

    def log10_nfa(self, chk) -> float:
        """``log10`` of the number of false alarms of a placement with check ``chk``."""
        if not self.usable:
            return math.inf
        k, n = _trials(chk)
        top = math.log10(self.tests) + self.calibration
        if n <= 0:
            return top
        f = k / n
        if f <= self.p0:
            return top
        return top - (n / self.design) * _kl(f, self.p0) / math.log(10.0)

    def nfa(self, chk) -> float:
        """Number of false alarms of a placement with check ``chk``."""
        lg = self.log10_nfa(chk)
        return math.inf if lg == math.inf else 10.0 ** min(lg, 300.0)

    def distinguishable(self, best, other, risk: float) -> bool:
        """Whether placement ``best`` meets walls significantly more often than ``other`` (a
        one-sided test of two shares at level ``risk``, with the design effect): when not, the
        two fit about as well and the maps alone cannot tell them apart."""
        kb, nb = _trials(best)
        ko, no = _trials(other)
        if nb <= 0:
            return False
        if no <= 0:
            return True
        fb, fo = kb / nb, ko / no
        pooled = (kb + ko) / (nb + no)
        var = max(pooled * (1 - pooled), 1e-9) * self.design * (1 / nb + 1 / no)
        z = (fb - fo) / math.sqrt(var)
        return z > _z_quantile(risk)


def _z_quantile(risk: float) -> float:
    """The standard normal quantile exceeded with probability ``risk``."""
    from scipy.special import ndtri
    return float(-ndtri(risk))


def search_tests(a: MapIndex, b: MapIndex, basin_cells: float = 8.0, ) -> float:
    """Distinct placements of B in A a search can end on: where B's centre can land on A's
    known area, and at which rotation, counted in ICP basins (``basin_cells`` cells wide,
    the widest pairing gate; the rotation step that moves B's farthest wall by that much)."""
    known = float(np.count_nonzero(a.known))
    positions = max(known / (basin_cells * basin_cells), 1.0)
    if len(b.points):
        centre = b.points.mean(axis=0)
        reach = float(np.sqrt(((b.points - centre) ** 2).sum(axis=1)).max()) / b.resolution
    else:
        reach = 1.0
    rotations = max(2 * math.pi * max(reach, basin_cells) / basin_cells, 1.0)
    return positions * rotations


def null_model(a: MapIndex, b: MapIndex, away_from: Transform2D, box: np.ndarray, *,
               samples: int = 64, distinct: float, points: np.ndarray | None = None,
               calibration: float = 0.0, correlation: float = 3.0,
               seed=0) -> tuple[NullModel, list]:
    """Sample the evidence of wrong placements of B in A (see :class:`NullModel`).

    Parameters
    ----------
    a, b : MapIndex
    away_from : Transform2D
        The placement under test (B -> A): samples ending within ``distinct`` m of it (at
        B's corners ``box``) are not wrong placements and are drawn again (up to three times
        as many starts in all).
    samples : int
        Wrong placements wanted.
    points : (K, 2) float, optional
        B's wall points the ICP runs on (default ``b.refine_points``).
    calibration : float
        See :class:`NullModel`.
    correlation : float
        Length of wall (m) whose cells agree or not together, the prior the measured design
        effect is shrunk towards.
    seed : int or numpy.random.Generator

    Returns
    -------
    (NullModel, list of (Transform2D, Check))
        The model and the wrong placements sampled (rivals of the placement under test).
    """
    from ._pair import displacement
    rng = np.random.default_rng(seed)
    pts = b.refine_points if points is None else points
    out = []
    if len(a.points) and len(pts):
        for _ in range(3 * samples):
            if len(out) >= samples:
                break
            th = float(rng.uniform(-math.pi, math.pi))
            pa = a.points[int(rng.integers(len(a.points)))]
            pb = pts[int(rng.integers(len(pts)))]
            c, s = math.cos(th), math.sin(th)
            start = Transform2D(float(pa[0] - (c * pb[0] - s * pb[1])),
                                float(pa[1] - (s * pb[0] + c * pb[1])), th)
            t = refine_icp(a, pts, start)
            if displacement(t, away_from, box) <= distinct:
                continue
            out.append((t, verify(a, b, t)))
    kn = np.array([_trials(chk) for _, chk in out], float).reshape(-1, 2)
    kn = kn[kn[:, 1] > 0]
    if len(kn):
        f = kn[:, 0] / kn[:, 1]
        p0 = float(kn[:, 0].sum() / kn[:, 1].sum())
        binom = max(p0 * (1 - p0), 1e-9) / kn[:, 1]
        # the median ratio (over that of a chi-square with one degree of freedom, 0.455): a few
        # wrong placements on repeated structure must not hide how alike the others are
        measured = max(float(np.median((f - p0) ** 2 / binom)) / 0.455, 1.0)
        # sixty-odd wrong placements measure it only roughly (from a few tens to a few hundred
        # cells on one map): shrink it towards the cells of ``correlation`` metres of wall
        # (geometric mean)
        design = math.sqrt(measured * max(correlation / a.resolution, 1.0))
    else:
        f, p0, design = np.zeros(0), 1.0, 1.0
    return NullModel(f, kn[:, 1], p0, design, search_tests(a, b), calibration), out
