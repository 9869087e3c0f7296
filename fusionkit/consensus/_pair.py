"""One pair of maps: candidates from every source, refined, verified, decided."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from ..alignment import make_field
from ..errors import InputError
from ..transform import Transform2D
from ._hypotheses import cluster_hypotheses, scan_hypotheses
from ._index import MapIndex
from ._search import Correlator, EvidenceRaster, rotation_candidates
from ._verify import DEFAULT_GATES, Check, refine_cloud, refine_icp, refine_pso, verify

__all__ = ["ConsensusConfig", "Candidate", "PairResult", "estimate_indexed", "displacement"]


@dataclass(frozen=True)
class ConsensusConfig:
    """Settings of the consensus method.

    Attributes
    ----------
    accept : float
        Least verification score (:class:`~fusionkit.consensus.Check`, 0..1) for a placement.
    min_overlap_cells : int
        Least number of wall cells of each map that must land where the other map is known.
    min_overlap_fraction : float
        ... and at least this fraction of the smaller map's wall cells.
    min_agreement : float
        Least evidence (:meth:`Check.quality` times the cell size, in metres of wall) for a
        placement: a perfect fit of a small patch of wall is not enough to merge.
    min_agreement_cells : int
        Least evidence in cells: on coarse grids a few metres of wall are too few cells to pin a
        placement down to a cell or two (not required of placements refined on recorded scans).
    cloud_shift : float
        Largest move (cells) the refinement on recorded scans may make to a placement.
    max_conflict : float
        Largest fraction of wall cells allowed on the other map's clear free space.
    rival : float
        A second, distinct placement whose score is at least ``accept - margin`` and whose
        quality (:meth:`Check.quality`) is at least ``rival`` times the best one's makes the
        pair ambiguous: it is then only merged when a loop through a third map decides.
    margin : float
        Slack (score) of the rival test and of the cross checks between placed maps.
    distinct_cells : float
        Two placements are distinct when some corner of the moving map's known area moves by
        more than this many cells between them.
    rotation_peaks : int
        Wall-direction correlation peaks tried as rotations (each in two branches).
    translations : int
        Translation peaks kept per candidate rotation.
    refine_top : int
        At most this many grid candidates (the best correlations) are refined and verified.
    coarse : float
        Cell size (m) of the translation search.
    coarse_side : int
        ... coarser when needed to keep the searched raster's longer side within this many
        cells.
    use_scans : bool
        Use recorded scans (matched spectra) as a source of candidates.
    virtual_scans : bool
        Also cast virtual scans for maps without recorded ones and use them the same way.
    scan_clusters : int
        Clusters of scan hypotheses refined and verified.
    pose_spacing : float
        Scans used for matching are thinned to one per square of this side (m).
    max_poses : int
        At most this many scans per map are matched.
    max_refine_points : int
        Wall points used by the refiners.
    alias_peaks : int
        Translations tried, at the best placement's rotation, in search of aliases (other places
        where repeated structure fits B as well); 0 to skip that search.
    coarse_points : int
        Wall points used by the wide-gate stages of the refinement of every start (the narrow
        stages use ``max_refine_points``).
    pso_refine : bool
        When a candidate could rival the best one, polish both, and each other such candidate
        (at most ``pso_top`` in all), with the paper's swarm (eq. 3) in a small box around it
        after ICP.
    pso_top : int
        See ``pso_refine``.
    fallback : bool
        When a map is left out, search its pairs again exhaustively: every ``fallback_step``
        degrees of rotation, three times as many candidates refined.
    fallback_step : float
        Rotation step (degrees) of that search.
    fallback_strictness : float
        Factor on ``min_overlap_cells``, ``min_agreement`` and ``min_agreement_cells`` for
        placements found by it.
    loop_cells : float
        Largest disagreement (cells, at the moving map's corners) of a loop of three
        placements for it to count as consistent.
    final_check : bool
        Check every two placed maps against each other, and cut the weakest link between two
        that disagree.
    pose_graph : bool
        Adjust the placements by least squares over all consistent links (loops).
    threads : int
        Threads that prepare the maps and estimate the pairs (0: one per core). One by
        default: the pairs of most cases are too quick for threads to pay (BENCHMARKS.md).
    candidates : int
        Each map's best-ranked others (by a cheap signature, :mod:`fusionkit.candidates`) that
        get a full estimate, plus the pairs that close loops; 0: every pair. A fleet of at most
        ``candidates + 1`` maps has every pair estimated.
    """

    accept: float = 0.9
    min_overlap_cells: int = 100
    min_overlap_fraction: float = 0.15
    min_agreement: float = 20.0
    min_agreement_cells: int = 300
    cloud_shift: float = 4.0
    max_conflict: float = 0.05
    rival: float = 0.6
    margin: float = 0.04
    distinct_cells: float = 6.0
    rotation_peaks: int = 4
    translations: int = 3
    refine_top: int = 16
    coarse: float = 0.1
    coarse_side: int = 256
    use_scans: bool = True
    virtual_scans: bool = False
    scan_clusters: int = 6
    pose_spacing: float = 0.25
    max_poses: int = 1500
    max_refine_points: int = 4000
    coarse_points: int = 1000
    alias_peaks: int = 6
    pso_refine: bool = True
    pso_top: int = 4
    fallback: bool = True
    fallback_step: float = 2.0
    fallback_strictness: float = 1.5
    loop_cells: float = 8.0
    final_check: bool = True
    pose_graph: bool = True
    threads: int = 1
    candidates: int = 4

    def __post_init__(self):
        if not 0.0 < self.accept <= 1.0:
            raise InputError(f"accept is a verification score in (0, 1], got {self.accept}")
        if not (0.0 <= self.max_conflict <= 1.0 and 0.0 <= self.margin <= 1.0 and 0.0 < self.rival <= 1.0):
            raise InputError("max_conflict and margin are fractions in [0, 1], rival in (0, 1]")
        for name in ("min_overlap_cells", "min_agreement_cells", "scan_clusters", "rotation_peaks",
                     "translations", "refine_top", "max_poses", "max_refine_points", "coarse_points",
                     "pso_top", "alias_peaks", "coarse_side", "threads", "candidates"):
            v = getattr(self, name)
            least = 0 if name in ("min_overlap_cells", "min_agreement_cells", "scan_clusters",
                                  "alias_peaks", "threads", "candidates") else 1
            if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < least:
                raise InputError(f"{name} must be a whole number >= {least}, got {v!r}")
        if not 0.0 <= self.min_overlap_fraction <= 1.0:
            raise InputError(f"min_overlap_fraction is a fraction in [0, 1], got {self.min_overlap_fraction}")
        if not (math.isfinite(self.fallback_strictness) and self.fallback_strictness >= 1):
            raise InputError(f"fallback_strictness must be >= 1, got {self.fallback_strictness}")
        if not (math.isfinite(self.min_agreement) and self.min_agreement >= 0):
            raise InputError(f"min_agreement must be >= 0 m, got {self.min_agreement}")
        for name in ("coarse", "pose_spacing", "distinct_cells", "loop_cells", "fallback_step",
                     "cloud_shift"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(f"{name} must be a positive number, got {v!r}")


@dataclass(frozen=True)
class Candidate:
    """A refined, verified placement of B in A: the transform B -> A, its check and where the
    hypothesis came from (``"scans"`` or ``"walls"``)."""

    transform: Transform2D
    check: Check
    source: str

    @property
    def rank(self) -> float:
        """Ordering key: :meth:`Check.quality`."""
        return self.check.quality()


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
        Its verification score (0..1).
    accepted : bool
        Whether it passes the thresholds and has no close rival.
    ambiguous : bool
        Whether it passes the thresholds but a distinct rival does too.
    plausible : tuple of Candidate
        Every distinct candidate that passes the thresholds, best first; for an ambiguous pair
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


def corners(index: MapIndex) -> np.ndarray:
    """The four corners (m, map frame) of the bounding box of the map's known cells."""
    if "corners" not in index.cache:
        index.cache["corners"] = _corners(index)
    return index.cache["corners"]


def _corners(index: MapIndex) -> np.ndarray:
    r, c = np.nonzero(index.known)
    if r.size == 0:
        r, c = np.array([0, index.grid.rows - 1]), np.array([0, index.grid.cols - 1])
    rr = np.array([r.min(), r.min(), r.max(), r.max()], float)
    cc = np.array([c.min(), c.max(), c.min(), c.max()], float)
    return index.grid.cell_to_world(rr, cc)


def displacement(t1: Transform2D, t2: Transform2D, pts: np.ndarray) -> float:
    """Largest distance (m) between where ``t1`` and ``t2`` put the points ``pts``."""
    # the points move by t1 - t2 = (R1 - R2) p + (d1 - d2): plain arithmetic, as this is
    # called for every two candidates of a pair
    a = math.cos(t1.theta) - math.cos(t2.theta)
    b = math.sin(t1.theta) - math.sin(t2.theta)
    ex, ey = t1.x - t2.x, t1.y - t2.y
    worst = 0.0
    for x, y in pts.tolist():
        worst = max(worst, (a * x - b * y + ex) ** 2 + (b * x + a * y + ey) ** 2)
    return math.sqrt(worst)


def _plausible(chk: Check, cfg: ConsensusConfig, resolution: float, walls: int,
               strict: float = 1.0, cells: bool = True) -> bool:
    return (chk.score >= cfg.accept and chk.overlap >= strict * cfg.min_overlap_cells
            and chk.overlap >= cfg.min_overlap_fraction * walls
            and chk.quality() * resolution >= strict * cfg.min_agreement
            and (not cells or chk.quality() >= strict * cfg.min_agreement_cells)
            and chk.conflict_fraction <= cfg.max_conflict)


def estimate_indexed(a: MapIndex, b: MapIndex, cfg: ConsensusConfig, *, hist_a, hist_b,
                     evidence_a: EvidenceRaster, ia: int = 0, ib: int = 1, seed=0,
                     exhaustive: bool = False, tree_a=None) -> PairResult:
    """Place map ``b`` in map ``a`` (both prepared), from every source of candidates.

    With ``exhaustive``, the translation search also runs at every ``fallback_step`` degrees
    of rotation (for maps whose walls have no dominant directions, such as caves), and three
    times as many candidates are refined. Testing more hypotheses gives chance fits more
    opportunities, so the overlap and agreement a placement needs are then
    ``fallback_strictness`` times higher. When both maps come with recorded scans, the best
    placement is finally refined on the scans' end points (``tree_a``: a ``cKDTree`` of
    ``a.cloud``, built when not given); such a placement is not held to
    ``min_agreement_cells``, which guards against the coarseness of grids.
    """
    strict = cfg.fallback_strictness if exhaustive else 1.0
    t0 = time.perf_counter()
    if len(a.points) == 0 or len(b.points) == 0:
        empty = [k + 1 for k, ix in ((ia, a), (ib, b)) if len(ix.points) == 0]
        return PairResult(ia, ib, None, 0.0, False, False,
                          reason=" and ".join(f"map {k}" for k in empty)
                          + f" hold{'s' if len(empty) == 1 else ''} no occupied cell (wall) to "
                          "place a map by")
    starts: list[tuple[Transform2D, str]] = []
    rots = rotation_candidates(hist_a, hist_b, cfg.rotation_peaks)
    if exhaustive:
        n = max(4, int(round(360.0 / cfg.fallback_step)))
        grid = [-math.pi + 2 * math.pi * k / n for k in range(n)]
        rots += [r for r in grid if all(abs(math.remainder(r - q, 2 * math.pi))
                                        > math.radians(cfg.fallback_step / 2) for q in rots)]
    n_hyp = 0
    usable = cfg.use_scans and (cfg.virtual_scans or not (a.virtual or b.virtual))
    if usable and len(a.spectra) and len(b.spectra):
        h = scan_hypotheses(a, b)
        n_hyp = len(h)
        centre = b.points.mean(axis=0) if len(b.points) else None
        clusters = cluster_hypotheses(h, centre=centre, max_clusters=cfg.scan_clusters)
        starts += [(c.transform, "scans") for c in clusters]
        for c in clusters[:2]:
            if all(abs(math.remainder(c.transform.theta - r, 2 * math.pi)) > math.radians(2)
                   for r in rots):
                rots.append(c.transform.theta)
    wall: list[tuple[float, Transform2D]] = []
    head = set(rots[: 2 * cfg.rotation_peaks + 2])
    corr = Correlator(evidence_a, b.points)
    for th in rots:
        count = cfg.translations if th in head else 2
        wall += [(s, t) for t, s in corr.translations(th, count=count)]
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
    settled: list[Transform2D] = []

    def refine(start: Transform2D, source: str, gates=DEFAULT_GATES[:-2]) -> None:
        t = refine_icp(a, thin, start, gates=gates)
        if any(displacement(t, u, box) < res for u in settled):
            return
        settled.append(t)
        t = refine_icp(a, b.refine_points, t, gates=DEFAULT_GATES[-2:])
        if any(displacement(t, c.transform, box) < 2 * res for c in refined):
            return
        refined.append(Candidate(t, verify(a, b, t), source))

    for start, source in starts:
        refine(start, source)
    refined.sort(key=lambda c: -c.rank)
    if refined and cfg.alias_peaks and _plausible(refined[0].check, cfg, res,
                                                  min(len(a.points), len(b.points)), strict):
        # repeated structure (racks, rooms along a corridor) fits B in several places at the
        # same rotation; the rotation search keeps only a few translations per rotation, so
        # look for such aliases of the best placement in its own correlation surface: each one
        # found that verifies nearly as well makes the pair ambiguous instead of wrongly sure
        best_t = refined[0].transform
        for start, _ in corr.translations(best_t.theta, count=cfg.alias_peaks,
                                          suppress=2 * cfg.distinct_cells * res):
            refine(start, "aliases", gates=DEFAULT_GATES[1:-2])
        refined.sort(key=lambda c: -c.rank)
    seconds = time.perf_counter() - t0
    if not refined:
        return PairResult(ia, ib, None, 0.0, False, False, reason="no candidate placement found",
                          seconds=seconds, hypotheses=n_hyp)
    best = refined[0]

    def contender(c: Candidate) -> bool:
        """Whether ``c`` fits nearly as well as the current best placement."""
        return c.rank >= cfg.rival * best.rank and c.check.score >= cfg.accept - cfg.margin

    if cfg.pso_refine and any(contender(c) for c in refined[1:cfg.pso_top]):
        # polish the best placement and every contender that could rival it alike, so that
        # the rival test compares like with like (a placement without contenders is already
        # as precise as the walls allow after ICP)
        if "soft" not in a.cache:
            a.cache["soft"] = make_field(a.points, res, sigma=1.0)
        soft = a.cache["soft"]
        rng = np.random.default_rng(seed)
        for k, c in enumerate(refined[:cfg.pso_top]):
            if k and not contender(c):
                continue
            t = refine_pso(a.points, b.refine_points, c.transform, res, seed=rng, field=soft)
            t = refine_icp(a, b.refine_points, t, gates=(3.0, 2.0))
            chk = verify(a, b, t)
            if chk.quality() > c.rank:
                refined[k] = Candidate(t, chk, c.source)
        refined.sort(key=lambda c: -c.rank)
        best = refined[0]
    scan_refined = False
    if cfg.use_scans and len(a.cloud) and len(b.cloud):
        # recorded scans do not quantise walls to cells: pin the best placement down on them
        tree = tree_a if tree_a is not None else cKDTree(a.cloud)
        t = refine_cloud(a.cloud, tree, b.cloud, best.transform)
        if displacement(t, best.transform, box) <= cfg.cloud_shift * res:
            chk = verify(a, b, t)
            if chk.quality() >= 0.9 * best.rank:
                best = Candidate(t, chk, best.source)
                refined[0] = best
                scan_refined = True
    walls = min(len(a.points), len(b.points))
    plausible = []
    for c in refined:
        if _plausible(c.check, cfg, res, walls, strict) and all(
                displacement(c.transform, p.transform, box) > cfg.distinct_cells * res for p in plausible):
            plausible.append(c)
    ok = _plausible(best.check, cfg, res, walls, strict, cells=not scan_refined)
    # a rival need not pass every threshold itself: fitting nearly as well elsewhere is enough
    # to make the best placement unsure
    rivals = []
    for c in refined[1:]:
        if contender(c) and displacement(c.transform, best.transform, box) > cfg.distinct_cells * res:
            rivals.append(c)
    accepted = ok and not rivals
    if ok and rivals:
        # the placements a loop through a third map may choose from
        options = [best] + rivals
        options += [c for c in plausible if all(displacement(c.transform, o.transform, box)
                                                > cfg.distinct_cells * res for o in options)]
        plausible = options
    chk = best.check
    if accepted:
        reason = ""
    elif ok:
        reason = (f"ambiguous: {len(rivals) + 1} distinct placements agree on "
                  f"{100 * min(r.check.score for r in rivals):.0f}-{100 * chk.score:.0f}% of the walls")
    elif chk.overlap < max(strict * cfg.min_overlap_cells, cfg.min_overlap_fraction * walls):
        reason = (f"best placement overlaps only {chk.overlap} wall cells (needs "
                  f"{math.ceil(max(strict * cfg.min_overlap_cells, cfg.min_overlap_fraction * walls))})")
    elif (chk.quality() * res < strict * cfg.min_agreement
          or (not scan_refined and chk.quality() < strict * cfg.min_agreement_cells)):
        reason = (f"best placement agrees on too few walls ({chk.quality() * res:.1f} m, "
                  f"{chk.quality():.0f} cells net of misfits; needs {strict * cfg.min_agreement:g} m "
                  f"and {strict * cfg.min_agreement_cells:.0f} cells)")
    elif chk.score < cfg.accept:
        reason = (f"best placement agrees on {100 * chk.score:.0f}% of the overlapping walls "
                  f"(needs {100 * cfg.accept:.0f}%)")
    else:
        reason = (f"best placement puts {100 * chk.conflict_fraction:.1f}% of the walls on open "
                  f"floor (allows {100 * cfg.max_conflict:.1f}%)")
    return PairResult(ia, ib, best.transform, float(chk.score), bool(accepted), bool(ok and rivals),
                      tuple(plausible), best, tuple(refined), len(starts), n_hyp, reason,
                      time.perf_counter() - t0,
                      {"rotations": len(rots), "check": chk.as_dict(), "strict": strict})
