"""The a contrario test a placement is judged by: how well two maps' walls meet at many wrong
placements of one in the other (the null distribution, drawn from the two maps themselves), and
the number of false alarms of a placement's evidence against it (:class:`NullModel`).

Its threshold, the false-merge risk the user accepts, means the same thing at any cell size,
extent or clutter of the maps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...transform import Transform2D
from ._index import MapIndex
from ._memo import pair_memo, points_key, refine_memo, verify_memo
from ._verify import DEFAULT_GATES, displacement

__all__ = ["NullModel", "null_model", "search_tests", "weighted_misses"]


def _trials(chk) -> tuple[float, float]:
    """``(hits, trials)`` of a check: wall cells meeting the other map's walls, out of the wall
    cells compared, a cell on the other's clear free space counted as three misses (the
    robust weighting of :meth:`Check.evidence`)."""
    return float(chk.agreeing), float(chk.agreeing + chk.disagreeing + 2 * chk.conflicts)


def hit_share(chk) -> float:
    """The share of a check's wall cells that meet the other map's walls, a cell on its clear
    free space counted as three misses (:func:`_trials`); 0 when none is compared."""
    k, n = _trials(chk)
    return k / n if n > 0 else 0.0


def weighted_misses(chk) -> float:
    """The wall cells of a check that miss the other map's walls, a cell on its clear free space
    counted three times: the misses of :func:`_trials`."""
    k, n = _trials(chk)
    return n - k


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
    Wall cells come in lines, so neighbouring cells agree or not together: ``design`` is the
    number of cells that count as one independent trial (the design effect), and a placement's
    cells count as ``trials / design`` independent ones, so that the test weighs metres of
    wall, not cells, and means the same at any cell size. It is measured on the wrong
    placements (the variance of their shares over that of independent cells), within a least
    and a greatest length of wall (:func:`null_model`'s ``correlation`` and
    ``correlation_max``), or fixed at ``correlation`` metres.

    A placement whose share ``f > p0`` of ``n`` compared cells is then reached by one wrong
    placement with probability at most ``exp(-(n / design) KL(f || p0))`` (Chernoff), and its
    number of false alarms is that times ``tests``, the number of distinct placements a search
    can end on (:func:`search_tests`): the expected count of wrong placements that would fit
    as well, which the user bounds by ``max_false_merge``. A placement whose wall cells that
    meet are not more than ``misfit_weight`` times those that miss (counted as in ``trials``) is
    given no evidence at all. Neither depends on the cell size,
    the extent or the clutter of the maps; all three enter through the maps' own wrong
    placements. ``calibration`` (decades) is added to that count's logarithm: an offset chosen
    on pairs of maps of different buildings (BENCHMARKS.md), negative when the count, an upper
    bound, is higher than the false alarms that occur.
    """

    fractions: np.ndarray
    trials: np.ndarray
    p0: float
    design: float
    tests: float
    calibration: float = 0.0
    misfit_weight: float = 1.0

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
        if n <= 0 or self.misses_too_much(chk):
            return top
        f = k / n
        if f <= self.p0:
            return top
        return top - (n / self.design) * _kl(f, self.p0) / math.log(10.0)

    def misses_too_much(self, chk) -> bool:
        """Whether the wall cells of check ``chk`` that meet the other map's walls are not more
        than ``misfit_weight`` times those that miss (counted as in ``trials``). Such a placement
        is no evidence of being the same place, however rarely wrong placements do as well: two
        maps of one place meet nearly everywhere they overlap, while a room or rack row of a
        repetitive building laid on another misses at every door and shelf that differs."""
        return float(chk.agreeing) - self.misfit_weight * weighted_misses(chk) <= 0

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


def search_tests(a: MapIndex, b: MapIndex, basin: float = 0.4) -> float:
    """Distinct placements of B in A a search can end on: where B's centre can land on A's
    known area, and at which rotation, counted in basins ``basin`` metres wide (the rotation
    step that moves B's farthest wall by that much). Counted in metres, not cells, the number
    is the same for the same two maps at any cell size (0.4 m: the ICP's widest pairing gate
    at 0.05 m cells)."""
    known = float(np.count_nonzero(a.known)) * a.resolution * a.resolution
    positions = max(known / (basin * basin), 1.0)
    if len(b.points):
        centre = b.points.mean(axis=0)
        reach = float(np.sqrt(((b.points - centre) ** 2).sum(axis=1)).max())
    else:
        reach = basin
    rotations = max(2 * math.pi * max(reach, basin) / basin, 1.0)
    return positions * rotations


def null_model(a: MapIndex, b: MapIndex, away_from: Transform2D, box: np.ndarray, *,
               samples: int = 64, distinct: float, points: np.ndarray | None = None,
               calibration: float = 0.0, correlation: float = 3.0,
               correlation_max: float | None = None, basin: float = 0.4, settled=None,
               batch: int = 16, least: int = 32, wide_points: int = 0,
               misfit_weight: float = 1.0, seed=0) -> tuple[NullModel, list]:
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
        Length of wall (m) whose cells agree or not together: one independent trial of the
        test (see :class:`NullModel`); with ``correlation_max``, the least such length.
    correlation_max : float, optional
        Measure that length from the wrong placements themselves (how much more their shares
        spread than independent cells would), bounded by ``correlation`` and this (m).
    basin : float
        Width (m) of the placements counted as tests (:func:`search_tests`).
    settled : callable(NullModel, list) -> bool, optional
        Sequential sampling: after every ``batch`` wrong placements, the model of those drawn
        so far and the placements themselves are passed to ``settled``; when it answers that
        the decision no longer depends on more samples, sampling stops there. Without it,
        ``samples`` are drawn.
    wide_points : int
        The ICP's wide gates run on this many of ``points`` (evenly spread), its narrow ones on
        all of them, as the search's own refinement does with its starts (0: every gate on
        all of them).
    batch : int
        Wrong placements drawn between two calls of ``settled``.
    least : int
        Wrong placements drawn before ``settled`` is first asked (the spread of fewer is too
        rough to stop on).
    seed : int or numpy.random.Generator

    Returns
    -------
    (NullModel, list of (Transform2D, Check))
        The model and the wrong placements sampled (rivals of the placement under test).
    """
    rng = np.random.default_rng(seed)
    pts = b.refine_points if points is None else points
    out = []
    tests = search_tests(a, b, basin)
    wide = pts
    if 0 < wide_points < len(pts):
        wide = pts[np.linspace(0, len(pts) - 1, wide_points).astype(np.int64)]
    # the ICP's points divided by the resolution once for all the starts
    pts_cells = np.ascontiguousarray(pts / a.resolution, np.float64)
    wide_cells = np.ascontiguousarray(wide / a.resolution, np.float64)
    # a pair searched again (the fall-back) draws the same starts again when its best
    # placement and seed are the same: their refinements and checks are kept
    memo = pair_memo(a, b)
    pts_name, wide_name = points_key(pts_cells), points_key(wide_cells)
    corners_b = np.asarray(box, float).tolist()
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
            if wide_points:
                t = refine_memo(memo, a, wide_cells, wide_name, start, DEFAULT_GATES[:-2])
                t = refine_memo(memo, a, pts_cells, pts_name, t, DEFAULT_GATES[-2:])
            else:
                t = refine_memo(memo, a, pts_cells, pts_name, start, DEFAULT_GATES)
            if displacement(t, away_from, corners_b) <= distinct:
                continue
            out.append((t, verify_memo(memo, a, b, t)))
            if (settled is not None and len(out) >= least and len(out) % batch == 0
                    and len(out) < samples):
                model = _fit(out, a.resolution, tests, calibration, correlation, correlation_max,
                             misfit_weight)
                if model.usable and settled(model, out):
                    break
    return _fit(out, a.resolution, tests, calibration, correlation, correlation_max,
                misfit_weight), out


def _fit(out: list, resolution: float, tests: float, calibration: float,
         correlation: float, correlation_max: float | None = None,
         misfit_weight: float = 1.0) -> NullModel:
    """The null model of the wrong placements ``out`` (``(Transform2D, Check)`` pairs)."""
    kn = np.array([_trials(chk) for _, chk in out], float).reshape(-1, 2)
    kn = kn[kn[:, 1] > 0]
    if len(kn):
        f = kn[:, 0] / kn[:, 1]
        p0 = float(kn[:, 0].sum() / kn[:, 1].sum())
        design = correlation / resolution
        if correlation_max is not None and len(kn) >= 8 and 0.0 < p0 < 1.0:
            # the design effect of the wrong placements themselves: how much more their shares
            # spread about ``p0`` than shares of independent cells would (variance ratio, in
            # cells). It holds both the correlation of neighbouring cells and how often a wrong
            # placement lines up whole walls: long straight walls and rows of identical rooms or
            # racks spread them widely (about 10-16 m), small cluttered maps hardly (1-4 m), so
            # a wall that fits perfectly over 20 m of such a map weighs as the evidence it is.
            # Bounded, as 32 to 64 wrong placements measure it only roughly.
            spread = float(np.mean((f - p0) ** 2 * kn[:, 1]) / (p0 * (1.0 - p0)))
            design = min(max(spread, design), correlation_max / resolution)
        design = max(design, 1.0)
    else:
        f, p0, design = np.zeros(0), 1.0, 1.0
    return NullModel(f, kn[:, 1], p0, design, tests, calibration, misfit_weight)
