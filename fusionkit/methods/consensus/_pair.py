"""One pair of maps: candidates from every source, refined, verified, decided."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial import cKDTree

from ...alignment import make_field
from ...grid import box_of
from ...transform import Transform2D
from ._config import ConsensusConfig
from ._hypotheses import cluster_hypotheses, scan_hypotheses
from ._index import MapIndex
from ._search import Correlator, EvidenceRaster, pyramid_rotations, rotation_candidates
from ._null import NullModel, hit_share, null_model, weighted_misses
from ._polish import polish
from ._memo import pair_memo, points_key, refine_memo, verify_memo
from ._slide import cross_wall
from ._verify import (DEFAULT_GATES, Check, Placements, _in_cells, displacement, refine_cloud,
                      refine_icp, refine_pso, typical_move, verify)

__all__ = ["ConsensusConfig", "Candidate", "PairResult", "estimate_indexed", "displacement"]


@dataclass(frozen=True)
class Candidate:
    """A refined, verified placement of B in A: the transform B -> A, its check and where the
    hypothesis came from (``"scans"``, ``"walls"``, ``"aliases"`` or ``"prior"``)."""

    transform: Transform2D
    check: Check
    source: str
    nfa: float = math.inf

    @property
    def rank(self) -> float:
        """Ordering key: :meth:`Check.evidence`."""
        return self.check.evidence()

    @property
    def confidence(self) -> float:
        """``exp(-nfa)``: the probability, under the pair's null distribution, that no wrong
        placement fits as well (0..1)."""
        return math.exp(-self.nfa) if math.isfinite(self.nfa) else 0.0


def _order(c: Candidate) -> tuple:
    """Sort key, best first: by evidence; placements of equal evidence by more meeting walls,
    then fewer on open floor, then by where they lie (rounded far beyond the search's
    precision). Ties then do not fall to the order the search found them in, which the rounding
    of floating point (numpy's vector functions are chosen by CPU) can change between machines."""
    t = c.transform
    return (-c.rank, -c.check.agreeing, c.check.conflicts,
            round(t.theta, 6), round(t.x, 4), round(t.y, 4))


def _side_by_side(chk: Check) -> bool:
    """Whether no wall of either map lands where the other is known under the placement checked:
    the maps lie side by side, not over each other. Such a placement meets nothing and misses
    nothing, and nothing tells it from any other: it is no candidate."""
    return chk.agreeing + chk.disagreeing == 0


@dataclass(frozen=True, eq=False)
class PairResult:
    """What the consensus method concluded about maps ``a`` and ``b``.

    Attributes
    ----------
    a, b : int
        Map indices; transforms map ``b``'s frame into ``a``'s.
    transform : Transform2D or None
        The best verified placement (None when no candidate came out at all).
    confidence : float
        How sure the method is that the placement is right (0..1): ``exp(-nfa)`` of the test,
        divided by the number of placements that fit about as well when the pair is ambiguous,
        and 0 when it may slide (``diagnostics["slides"]``); each candidate keeps the test's own
        (:attr:`Candidate.confidence`).
    accepted : bool
        Whether its number of false alarms is at most ``max_false_merge``, no distinct
        placement is nearly as good and its meeting walls fix it in every direction
        (``ConsensusConfig.cross_wall``).
    ambiguous : bool
        Whether it passes the test but a distinct rival is nearly as good (whether or not the
        best placement slides; ``diagnostics["sliding"]`` flags the options that slide, which
        the graph never places).
    plausible : tuple of Candidate
        Every distinct candidate that passes the test, best first; for an ambiguous pair
        the best one, its rivals and those.
    best : Candidate or None
    refined : tuple of Candidate
        Every distinct candidate refined and verified, best first.
    candidates : int
        Hypotheses refined.
    hypotheses : int
        Scan matches voted.
    reason : str
        Why it was not accepted (empty when accepted).
    seconds : float
    """

    a: int
    b: int
    transform: Transform2D | None
    confidence: float
    accepted: bool
    ambiguous: bool
    plausible: tuple = ()
    best: Candidate | None = None
    refined: tuple = ()
    candidates: int = 0
    hypotheses: int = 0
    reason: str = ""
    seconds: float = 0.0
    diagnostics: dict = field(default_factory=dict)
    nfa: float = math.inf
    null: NullModel | None = None


def corners(index: MapIndex) -> np.ndarray:
    """The four corners (m, map frame) of the bounding box of the map's known cells."""
    if "corners" not in index.cache:
        index.cache["corners"] = _corners(index)
    return index.cache["corners"]


def _corners(index: MapIndex) -> np.ndarray:
    # the centres of the corner cells of the box of known cells (of the whole grid without one)
    r0, r1, c0, c1 = box_of(index.known) or (0, index.grid.rows, 0, index.grid.cols)
    rr = np.array([r0, r0, r1 - 1, r1 - 1], float)
    cc = np.array([c0, c1 - 1, c0, c1 - 1], float)
    return index.grid.cell_to_world(rr, cc)


def is_rival(null: NullModel, best, other, risk: float, fraction: float) -> bool:
    """Whether a distinct placement with check ``other`` is nearly as good as the best one
    (check ``best``), which then cannot be accepted alone.

    It is when its share of meeting walls is not significantly lower than the best's (a
    one-sided test at ``risk``, with the design effect, :meth:`NullModel.distinguishable`) and
    it is either nearly as sure (its false alarms fewer than ``1 / risk`` times the best's) or
    carries at least ``fraction`` of the best's evidence. It need not pass the test itself:
    fitting nearly as well elsewhere is enough to make the best unsure. A placement that meets
    walls significantly less often is no rival, however near in decades: in rows of racks the
    truth and a wrong placement can both be 20 decades beyond chance, the one meeting every
    wall and the other two thirds of them. The calibration cancels in the difference of the
    two counts, so the answer is the same at any calibration.
    """
    if null.distinguishable(best, other, risk):
        return False
    return (null.log10_nfa(other) - null.log10_nfa(best) < -math.log10(risk)
            or other.evidence() >= fraction * best.evidence())


def fits_as_well(other, best, risk: float) -> bool:
    """Whether a distinct placement (candidate ``other``) passes the test itself (at most
    ``risk`` false alarms) and meets walls at least as often as the best one (``best``; the
    share of :func:`~._null.hit_share`, no lower): it is then a rival however much less
    evidence it carries. In rows of racks a placement one period off overlaps the other map
    more than the truth does, so it meets more walls while fitting no better (crops of the
    warehouse: 1270 wall cells meeting against 718 at the truth, none missing at either); the
    difference in evidence is one of overlap, not of fit."""
    return other.nfa <= risk and hit_share(other.check) >= hit_share(best.check)


def estimate_indexed(a: MapIndex, b: MapIndex, cfg: ConsensusConfig, *, hist_a, hist_b,
                     evidence_a: EvidenceRaster, ia: int = 0, ib: int = 1, seed=0,
                     exhaustive: bool = False, tree_a=None, priors=()) -> PairResult:
    """Place map ``b`` in map ``a`` (both prepared), from every source of candidates.

    With ``exhaustive``, the translation search also runs at every ``fallback_step`` degrees
    of rotation (for maps whose walls have no dominant directions, such as caves), and three
    times as many candidates are refined. When both maps come with recorded scans, the best
    placement is refined on the scans' end points (``tree_a``: a ``cKDTree`` of ``a.cloud``,
    built when not given). The best placement is then judged against the null distribution of
    the pair (:class:`~fusionkit.methods.consensus.NullModel`) and against every distinct placement
    found. ``priors`` are placements (B -> A) from elsewhere, such as odometry or a benchmark's
    truth, refined and judged with the search's own starts, ahead of them (a candidate is named
    after the first start that reached it, so a search start ending where a prior did is not
    counted again).
    """
    t0 = time.perf_counter()
    if len(a.points) == 0 or len(b.points) == 0:
        empty = [ix.grid.name or f"map {k + 1}" for k, ix in ((ia, a), (ib, b))
                 if len(ix.points) == 0]
        return PairResult(ia, ib, None, 0.0, False, False,
                          reason=" and ".join(empty)
                          + f" hold{'s' if len(empty) == 1 else ''} no occupied cell (wall) to "
                          "place a map by")
    starts: list[tuple[Transform2D, str]] = [(t, "prior") for t in priors]
    rots = rotation_candidates(hist_a, hist_b, cfg.rotation_peaks)
    if exhaustive:
        # every rotation, swept a level up the evidence pyramid; the best of them searched in full
        if cfg.fallback_rotations:
            grid = pyramid_rotations(evidence_a, b.points, step=math.radians(cfg.fallback_step),
                                     count=cfg.fallback_rotations)
        else:
            n = max(4, int(round(360.0 / cfg.fallback_step)))
            grid = [-math.pi + 2 * math.pi * k / n for k in range(n)]
        rots += [r for r in grid if all(abs(math.remainder(r - q, 2 * math.pi))
                                        > math.radians(cfg.fallback_step / 2) for q in rots)]
    n_hyp = 0
    usable = cfg.use_scans and (cfg.virtual_scans or not (a.virtual or b.virtual))
    memo = pair_memo(a, b)
    if usable and len(a.spectra) and len(b.spectra):
        # the scans' matches depend on the two maps alone: a pair searched again reuses them
        key = ("scans", cfg.scan_clusters)
        if key not in memo:
            h = scan_hypotheses(a, b)
            centre = b.points.mean(axis=0) if len(b.points) else None
            memo[key] = (len(h), cluster_hypotheses(h, centre=centre,
                                                    max_clusters=cfg.scan_clusters))
        n_hyp, clusters = memo[key]
        starts += [(c.transform, "scans") for c in clusters]
        for c in clusters[:2]:
            if all(abs(math.remainder(c.transform.theta - r, 2 * math.pi)) > math.radians(2)
                   for r in rots):
                rots.append(c.transform.theta)
    wall: list[tuple[float, Transform2D]] = []
    head = set(rots[: 2 * cfg.rotation_peaks + 2])
    corr = Correlator(evidence_a, b.points)

    def translations(theta: float, count: int, suppress: float = 1.0) -> list:
        # the correlation at a rotation depends on nothing else: the fall-back meets the
        # rotations of the first search again
        key = ("translations", id(evidence_a), theta, count, suppress)
        got = memo.get(key)
        if got is None or got[0] is not evidence_a:
            got = memo[key] = (evidence_a, corr.translations(theta, count=count,
                                                             suppress=suppress))
        return got[1]

    for th in rots:
        count = cfg.translations if th in head or (exhaustive and cfg.fallback_rotations) else 2
        wall += [(s, t) for t, s in translations(th, count)]
    wall.sort(key=lambda st: -st[0])
    starts += [(t, "walls") for _, t in wall[: cfg.refine_top * (3 if exhaustive else 1)]]

    box = corners(b)
    res = a.resolution
    refined: list[Candidate] = []
    # ICP in two stages: the wide gates on a thinned set of B's walls (most starts converge to
    # a few placements, which are then refined once), the narrow ones on all of them
    thin = b.refine_points
    if len(thin) > cfg.coarse_points:
        thin = thin[np.linspace(0, len(thin) - 1, cfg.coarse_points).astype(np.int64)]
    # the same points for every start: divided by the resolution once
    thin_cells = np.ascontiguousarray(thin / a.resolution, np.float64)
    refine_cells = _in_cells(b, b.refine_points, a.resolution)
    thin_name, refine_name = points_key(thin_cells), points_key(refine_cells)
    corners_b = box.tolist()
    wide_ends = Placements(corners_b)       # where the wide stage of each start ended
    kept = Placements(corners_b)            # the refined candidates' placements

    def refine(start: Transform2D, source: str, gates=DEFAULT_GATES[:-2]) -> None:
        t = refine_memo(memo, a, thin_cells, thin_name, start, gates)
        if wide_ends.near(t, res):
            return
        wide_ends.add(t)
        t = refine_memo(memo, a, refine_cells, refine_name, t, DEFAULT_GATES[-2:])
        if kept.near(t, 2 * res):
            return
        kept.add(t)
        chk = verify_memo(memo, a, b, t)
        if _side_by_side(chk):
            return
        refined.append(Candidate(t, chk, source))

    for start, source in starts:
        refine(start, source)
    refined.sort(key=_order)
    if refined and cfg.alias_peaks and refined[0].rank > 0:
        # repeated structure (racks, rooms along a corridor) fits B in several places at the
        # same rotation; the rotation search keeps only a few translations per rotation, so
        # look for such aliases of the best placement in its own correlation surface: each one
        # found that fits nearly as well makes the pair ambiguous instead of wrongly sure
        best_t = refined[0].transform
        for start, _ in translations(best_t.theta, cfg.alias_peaks,
                                     2 * cfg.distinct_cells * res):
            refine(start, "aliases", gates=DEFAULT_GATES[1:-2])
        refined.sort(key=_order)
    seconds = time.perf_counter() - t0
    if not refined:
        return PairResult(ia, ib, None, 0.0, False, False,
                          reason="no placement found that lays either map's walls where the other "
                                 "map is known", seconds=seconds, hypotheses=n_hyp)
    best = refined[0]
    distinct = cfg.distinct_cells * res
    rng = np.random.default_rng([seed, ia, ib])

    def close(c: Candidate) -> bool:
        """Whether ``c``, a distinct placement, fits nearly as well as the best one (a crude
        pre-test; the null distribution decides below)."""
        return c.rank >= 0.5 * best.rank and displacement(c.transform, best.transform, box) > distinct

    if cfg.turns and best.rank > 0:
        # ICP settles where its pairs balance, which on a cluttered map can be a degree off the
        # placement that meets the most walls (an office window: 1.1 degrees off, 56 of its
        # walls on open floor against 3 at the truth): the best placement, and each candidate
        # that could rival it, turned about B's walls a few steps either way, are more starts,
        # refined as the search's own. They add candidates and take none away, so a rival found
        # stays one
        centre = thin.mean(axis=0)
        for c in [c for k, c in enumerate(refined[:cfg.pso_top]) if k == 0 or close(c)]:
            px, py = c.transform(centre)
            for d in (sign * n * cfg.turn_step for n in range(1, cfg.turns + 1) for sign in (-1, 1)):
                refine(Transform2D(px, py, math.radians(d)) @ Transform2D(-px, -py, 0.0) @ c.transform,
                       c.source)
        refined.sort(key=_order)
        best = refined[0]
    if cfg.pso_refine and best.rank > 0 and any(close(c) for c in refined[1:cfg.pso_top]):
        # polish the best placement and every contender that could rival it alike, so that
        # the rival test compares like with like (a placement without contenders is already
        # as precise as the walls allow after ICP)
        if "soft" not in a.cache:
            a.cache["soft"] = make_field(a.points, res, sigma=1.0)
        soft = a.cache["soft"]
        for k, c in enumerate(refined[:cfg.pso_top]):
            if k and not close(c):
                continue
            t = refine_pso(a.points, b.refine_points, c.transform, res, seed=rng, field=soft)
            t = refine_icp(a, b.refine_points, t, gates=(3.0, 2.0))
            chk = verify(a, b, t)
            if chk.evidence() > c.rank:
                refined[k] = Candidate(t, chk, c.source)
        refined.sort(key=_order)
        best = refined[0]
    on_scans = False
    if cfg.use_scans and len(a.cloud) and len(b.cloud):
        # recorded scans do not quantise walls to cells: pin the best placement down on them
        key = ("cloud", best.transform.x, best.transform.y, best.transform.theta)
        if key not in memo:
            tree = tree_a if tree_a is not None else cKDTree(a.cloud)
            memo[key] = refine_cloud(a.cloud, tree, b.cloud, best.transform)
        t = memo[key]
        if displacement(t, best.transform, box) <= cfg.cloud_shift * res:
            chk = verify_memo(memo, a, b, t)
            if chk.evidence() >= 0.9 * best.rank and not _side_by_side(chk):
                best = Candidate(t, chk, best.source)
                refined[0] = best
                on_scans = True

    # the test: the best placement's evidence against the evidence of wrong placements of the
    # same two maps (a contrario: its number of false alarms), then against every distinct
    # placement found (by the search or among the wrong placements sampled)
    eps = cfg.max_false_merge

    def settled(model: NullModel, drawn: list) -> bool:
        # the decision no longer depends on more samples when it holds with walls twice or
        # half as correlated as the model assumes (a margin for the rough share ``p0`` of the
        # samples so far): far short of the threshold even at half, refused whatever more
        # samples show; far beyond it even at twice, with no wrong placement drawn near the
        # best one, accepted unless a rival is found (the search and the alias search look for
        # them too)
        th = math.log10(eps)
        if replace(model, design=model.design / 2).log10_nfa(best.check) >= th + cfg.null_margin:
            return True
        return (replace(model, design=2 * model.design).log10_nfa(best.check)
                <= th - cfg.null_margin
                and all(chk.evidence() < 0.5 * best.rank for _, chk in drawn))

    null, wrong = null_model(a, b, best.transform, box, samples=cfg.null_samples,
                             distinct=distinct, points=thin,
                             calibration=cfg.calibration + (cfg.fallback_calibration if exhaustive else 0.0),
                             correlation=cfg.wall_correlation,
                             correlation_max=cfg.wall_correlation_max,
                             basin=cfg.test_basin, settled=settled,
                             wide_points=cfg.null_wide_points,
                             misfit_weight=cfg.misfit_weight, seed=rng)

    def judged(c: Candidate) -> Candidate:
        return Candidate(c.transform, c.check, c.source, null.nfa(c.check))

    refined = [judged(c) for c in refined]
    best = refined[0]
    log_nfa = null.log10_nfa(best.check)
    significant = log_nfa <= math.log10(eps)
    others = [c for c in refined[1:] if displacement(c.transform, best.transform, box) > distinct]
    others += [Candidate(t, chk, "null", null.nfa(chk)) for t, chk in wrong]
    # another placement moves most of B's walls by more than ``distinct``: one turned a degree
    # about the overlap (a map bent by drift, aligned on one part of it or on another) moves
    # only its far corners that much, and is the same placement. Only those the two loops below
    # can use are measured: with evidence (a rival) or passing the test (plausible)
    others = [c for c in others if (c.rank > 0 or c.nfa <= eps)
              and typical_move(c.transform, best.transform, thin) > distinct]
    others.sort(key=_order)
    rivals: list[Candidate] = []
    # a rival is judged by its share of meeting walls alone: one that misses too much to be
    # evidence of itself still shows that the maps fit elsewhere nearly as well; and one that
    # passes the test fitting at least as well is a rival whatever its evidence
    shares = replace(null, misfit_weight=1.0)
    for c in others:
        if c.rank > 0 and (is_rival(shares, best.check, c.check, eps, cfg.rival)
                           or fits_as_well(c, best, eps)) and all(
                displacement(c.transform, r.transform, box) > distinct for r in rivals):
            rivals.append(c)
    plausible = [best] if significant else []
    for c in others:
        if c.nfa <= eps and all(displacement(c.transform, p.transform, box) > distinct
                                for p in plausible + rivals):
            plausible.append(c)
    # walls that all run one way hold the placement across them only: slid along them it fits
    # as well, and the wrong placements drawn at random rarely land there (:mod:`._slide`)
    # (measured only where it can change the decision: at a placement the test takes)
    checked = cfg.cross_wall > 0
    across = cross_wall(a, b, best.transform) if checked and significant else None
    slides = across is not None and across < cfg.cross_wall
    accepted = significant and not rivals and not slides
    if significant and rivals:
        plausible = [best] + rivals + plausible[1:]
    # a pair with rivals stays ambiguous, listing them, even when its best placement slides; the
    # graph never places one of its options that slides (``sliding``, one flag per option)
    ambiguous = bool(significant and rivals)
    sliding = tuple((c is best and slides) or (checked and c is not best and
                                               cross_wall(a, b, c.transform) < cfg.cross_wall)
                    for c in plausible) if ambiguous else ()
    nfa = best.nfa
    # how sure the method is that the best placement is right: the test's confidence, less
    # what the checks after it showed. Of k + 1 placements that fit about as well, nothing
    # tells the best one from the others; slid along walls that all run one way, it fits as
    # well at any shift
    confidence = (0.0 if slides and not ambiguous
                  else best.confidence / (len(rivals) + 1) if ambiguous else best.confidence)
    if accepted:
        reason = ""
    elif ambiguous:
        # the shares the rival test compares (a wall on open floor three misses)
        lo, hi = (f"{100 * f(hit_share(c.check) for c in [best] + rivals):.0f}" for f in (min, max))
        reason = (f"ambiguous: {len(rivals) + 1} distinct placements fit about as well "
                  f"({lo if lo == hi else f'{lo}-{hi}'}% of the walls meet, a wall on the other "
                  "map's open floor counted as three misses) and the maps alone cannot tell them "
                  "apart")
    elif significant:
        reason = (f"the placement may slide: the walls that meet all run one way (a straight wall, "
                  f"a corridor's two sides) and only {across:.2f} m of meeting wall runs across "
                  f"them, where {cfg.cross_wall:g} m is needed to fix it along them")
    elif best.rank <= 0:
        chk = best.check
        misses = chk.disagreeing + 2 * chk.conflicts   # what ``rank`` takes away
        reason = (f"best placement is contradicted: {chk.agreeing} wall cells meet the other "
                  f"map's walls and {chk.disagreeing} miss them, {chk.conflicts} of those on its "
                  f"open floor; counting those three times, {misses} misses weigh "
                  f"{'as much as' if misses == chk.agreeing else 'more than'} the walls that meet")
    elif null.usable and null.misses_too_much(best.check):
        chk = best.check
        reason = (f"best placement misses too much: {chk.agreeing} wall cells meet the other map's "
                  f"walls and {chk.disagreeing} miss them, {chk.conflicts} of those on its open floor; "
                  f"counting each of those three times, {weighted_misses(chk):.0f} misses, "
                  f"and two maps of one place meet more than {null.misfit_weight:g} times as often as "
                  f"they miss where they overlap (maps of a building of identical rooms that share no "
                  f"wall do not)")
    elif not null.usable:
        reason = ("nothing to judge a placement by: too few walls overlap at any placement to tell "
                  "a right one from a wrong one")
    else:
        # "99% of the walls meet where wrong placements reach 13%" read as a clear win: the
        # count of walls, too small to be sure among the placements tried, is what decides
        # (the share the test weighs, of both maps' cells together: the smaller of the two
        # maps' shares read "0% meet" beside "9 meet and 0 miss" when one map had no wall there)
        chk = best.check
        reason = (f"best placement is not distinguishable from chance: {chk.agreeing} wall cells "
                  f"meet the other map's walls and {chk.disagreeing} miss them, {chk.conflicts} "
                  f"of those on its open floor (counting those three times, "
                  f"{100 * hit_share(chk):.0f}% meet, where at wrong placements of these maps "
                  f"{100 * null.p0:.0f}% do), too few walls to be sure among the placements "
                  f"tried: 10^{log_nfa:.1f} wrong placements are expected to fit as well, where "
                  f"{eps:g} is allowed")
    if cfg.polish:
        # what was decided stays; the placements handed on lose the pairing's bias (._polish)
        done = {id(best): best if on_scans else replace(best, transform=polish(a, b, best.transform))}
        for c in plausible:
            if id(c) not in done:
                done[id(c)] = replace(c, transform=polish(a, b, c.transform))
        plausible = [done[id(c)] for c in plausible]
        refined = [done.get(id(c), c) for c in refined]
        best = done[id(best)]
    return PairResult(ia, ib, best.transform, float(confidence), bool(accepted),
                      ambiguous, tuple(plausible), best, tuple(refined),
                      len(starts), n_hyp, reason, time.perf_counter() - t0,
                      {"rotations": len(rots), "check": best.check.as_dict(),
                       "log10_nfa": log_nfa, "null_p0": null.p0, "null_design": null.design,
                       "tests": null.tests, "rivals": len(rivals), "cross_wall_m": across,
                       "slides": bool(slides), "sliding": sliding}, nfa, null)
