"""The settings of the consensus method."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...errors import InputError

__all__ = ["ConsensusConfig"]


@dataclass(frozen=True)
class ConsensusConfig:
    """Settings of the consensus method.

    Attributes
    ----------
    max_false_merge : float
        The false-merge risk accepted, the one number the decision turns on: a placement is
        accepted when the number of false alarms of its evidence (the expected count of wrong
        placements, among all a search can end on, that would fit as well; judged against the
        evidence the same two maps reach at many wrong placements, :class:`NullModel`) is at
        most this, and no distinct placement is nearly as good: one whose share of meeting
        walls is not significantly lower (at this risk) and whose false alarms are fewer than
        ``1 / max_false_merge`` times the best's or whose evidence is at least ``rival`` times
        the best's; nor one that passes the test itself and meets walls at least as often as the
        best, whatever its evidence (``fits_as_well``). Its meaning does not depend on the maps'
        cell size, extent or clutter.
    null_samples : int
        Wrong placements sampled (ICP from random starts) for the null distribution.
    null_wide_points : int
        Wall points the wide gates of those ICPs run on (their narrow gates run on
        ``coarse_points``); 0, the default, to run every gate on ``coarse_points``. Fewer
        points end the wrong placements a little lower (on the leave-one-world-out pairs, one
        pair of two buildings gained 0.3 decades with 300), which shifts the calibration.
    misfit_weight : float
        A placement whose wall cells that meet the other map's walls are not more than this
        many times those that miss (a cell on clear free space counting as three misses) is no
        evidence at all. Two maps of one place meet nearly everywhere they overlap, even real
        sessions (people, doors, clutter) or maps bent by drift, where the overlap is large;
        a room laid on another room of a repetitive building misses at every door and shelf
        that differs (BENCHMARKS.md: maps of one building that share no wall).
    calibration : float
        Decades added to the model's count of false alarms (:class:`NullModel`), chosen on
        pairs of maps of two different buildings, where every placement is wrong: the least
        offset at which the whole decision (the test, the rival test and ``cross_wall``) merges
        none of them, plus one decade for the spread from one set of maps to another
        (BENCHMARKS.md, leave-one-world-out; the highest of twelve draws of pairs, six of every
        family and six of small windows of real floors). It may be negative (the
        model's count is an upper bound: a Chernoff bound, every basin of the search counted
        as a test) or positive (the wrong placements drawn at random rotations miss some that
        a search finds).
    wall_correlation, wall_correlation_max : float
        Least and greatest length of wall (m) along which cells agree or not together: one
        independent trial of the test (:class:`NullModel`), so that it weighs metres of wall,
        not cells. Between the two it is measured on the maps' own wrong placements (how much
        more their shares of meeting walls spread than independent cells would): short for
        small cluttered maps, whose wrong placements all fit about equally badly; the greatest
        for long straight walls and rows of identical rooms, where a wrong placement now and
        then lines up whole walls. Chosen with ``calibration`` by leave-one-world-out
        (BENCHMARKS.md).
    test_basin : float
        Width (m) of the placements the test counts as distinct tests (the number of false
        alarms is the chance of one wrong placement times their number,
        :func:`~fusionkit.methods.consensus._null.search_tests`): in metres, so that the same two
        maps get the same count at any cell size. Chosen with ``calibration``.
    cloud_shift : float
        Largest move (cells) the refinement on recorded scans may make to a placement.
    rival : float
        A distinct placement with at least this fraction of the best one's evidence
        (:meth:`Check.evidence`) whose share of meeting walls is not significantly lower is a
        rival (so is one that passes the test and meets walls at least as often, whatever its
        evidence). In the graph stage, a map that fits a third map in several places about equally
        well has repeated structure, so its single fit elsewhere whose evidence is less than
        ``1 / rival`` times those must be confirmed by a loop.
    cross_wall : float
        Least length (m) of the walls that meet at a placement facing the direction it is least
        held in (:func:`fusionkit.methods.consensus._slide.cross_wall`). Walls that all run one
        way (one straight wall, a corridor's two sides) leave the placement free to slide along
        them, and the test, whose wrong placements are drawn at random, rarely sees those
        slides: such a placement is refused whatever its evidence. On the leave-one-world-out
        and crop draws (BENCHMARKS.md), the pairs of two buildings the test alone merges at the
        shipped calibration have 0.02-0.34 m (a window of racks laid along a straight office
        wall, windows of two floors along a corridor wall); of the right placements it merges,
        two have less than 1 m (0.69 and 0.79 m, small windows of one house), the next 1.3 m.
        0.5 m or 2 m change the out-of-sample result by less than half a point. 0 turns the
        check off.
    distinct_cells : float
        Two placements are distinct when some corner of the moving map's known area moves by
        more than this many cells between them. Another placement can rival the best one only
        when it also moves most of the moving map's walls (the median of their moves) that far:
        one turned a degree about the overlap moves only the far corners so much (a map bent
        by drift, aligned on one part or another), and is the same placement.
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
    turns, turn_step : int, float
        The best placement, and each candidate among the first ``pso_top`` that could rival it,
        turned about the moving map's walls by ``turn_step`` degrees up to ``turns`` times either
        way, are more starts of the search, refined and kept as its own are (ICP can settle a
        degree off on cluttered maps): they add candidates and take none away. 0 turns: off.
    polish : bool
        After the test, refine the placements handed on (the best and each plausible one) with
        walls paired from the points themselves (:mod:`._polish`): the search's pairing is a
        fifth of a cell off on turned walls, always the same way. It never changes a decision.
    fallback : bool
        When a map is left out, search its pairs again exhaustively: every ``fallback_step``
        degrees of rotation, three times as many candidates refined.
    fallback_step : float
        Rotation step (degrees) of that search (its placements are judged by the same test,
        with ``fallback_calibration`` more decades).
    fallback_rotations : int
        Rotations of that search's sweep (made a level up the evidence pyramid, at every
        ``fallback_step`` degrees) whose translations are then searched in full; 0 to search
        every rotation of that grid in full, at the evidence raster's own resolution.
    fallback_calibration : float
        Decades added to ``calibration`` for the placements of that search. The calibration is
        chosen on what the first search finds; searching every rotation with three times the
        starts finds better wrong placements too (a window of the UH robot house against one of
        the RoboCup arena that the first search refused at 10^-2.4 false alarms by the model
        before the offset, it placed at 10^-4.6; a window of the office laid in the warehouse,
        10^-0.3 from the first search, 10^-9.1 from the fall-back). Chosen by the calibration's
        rule on what the fall-back found for the pairs of two buildings the first search
        refused in the eight draws of BENCHMARKS.md (the fall-back), and measured on two draws
        held out from it.
    null_margin : float
        Decades: the null distribution is drawn in batches (32 wrong placements first, then 16
        at a time), and stops being drawn once the placement under test stays this far short
        of the threshold with half the design effect (cells counted as one trial), or this
        far beyond it with twice that and no wrong placement drawn coming near it
        (``null_samples`` at most; ``inf`` draws them all).
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
        Each map's best-ranked others (by a cheap signature,
        :mod:`fusionkit.methods.consensus.candidates`) that get a full estimate, plus the pairs
        that close loops; 0: every pair. A fleet of at most ``candidates + 1`` maps has every
        pair estimated.
    """

    max_false_merge: float = 0.01
    null_samples: int = 64
    null_wide_points: int = 0
    misfit_weight: float = 2.0
    calibration: float = 1.75
    wall_correlation: float = 1.5
    wall_correlation_max: float = 6.0
    test_basin: float = 0.4
    cloud_shift: float = 4.0
    rival: float = 0.6
    cross_wall: float = 1.0
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
    turns: int = 2
    turn_step: float = 1.0
    polish: bool = True
    fallback: bool = True
    fallback_step: float = 2.0
    fallback_rotations: int = 12
    fallback_calibration: float = 6.5
    null_margin: float = 2.0
    loop_cells: float = 8.0
    final_check: bool = True
    pose_graph: bool = True
    threads: int = 1
    candidates: int = 4

    def __post_init__(self):
        v = self.max_false_merge
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and 0.0 < v < 1.0):
            raise InputError(f"max_false_merge is a risk in (0, 1) (e.g. 0.01), got {v!r}")
        if not (isinstance(self.calibration, (int, float)) and not isinstance(self.calibration, bool)
                and math.isfinite(self.calibration)):
            raise InputError(f"calibration is a finite number of decades, got {self.calibration!r}")
        v = self.fallback_calibration
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                and v >= 0):
            raise InputError(f"fallback_calibration is a number of decades >= 0, got {v!r}")
        v = self.cross_wall
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                and v >= 0):
            raise InputError(f"cross_wall is a length in metres >= 0, got {v!r}")
        if not 0.0 < self.rival <= 1.0:
            raise InputError(f"rival is a fraction in (0, 1], got {self.rival}")
        v = self.misfit_weight
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                and v > 0):
            raise InputError(f"misfit_weight must be a positive number, got {v!r}")
        for name in ("scan_clusters", "rotation_peaks", "translations", "refine_top", "max_poses",
                     "max_refine_points", "coarse_points", "pso_top", "alias_peaks", "coarse_side",
                     "threads", "null_samples", "fallback_rotations",
                     "null_wide_points", "candidates", "turns"):
            v = getattr(self, name)
            least = 0 if name in ("scan_clusters", "alias_peaks", "threads",
                                  "fallback_rotations", "null_wide_points", "candidates",
                                  "turns") else (
                8 if name == "null_samples" else 1)
            if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < least:
                raise InputError(f"{name} must be a whole number >= {least}, got {v!r}")
        for name in ("coarse", "pose_spacing", "distinct_cells", "loop_cells", "fallback_step",
                     "cloud_shift", "wall_correlation", "wall_correlation_max", "test_basin",
                     "turn_step"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(f"{name} must be a positive number, got {v!r}")
        if self.wall_correlation_max < self.wall_correlation:
            raise InputError(f"wall_correlation_max ({self.wall_correlation_max}) must be at least "
                             f"wall_correlation ({self.wall_correlation})")
        v = self.null_margin
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0):
            raise InputError(f"null_margin is a positive number of decades (inf: never stop "
                             f"early), got {v!r}")
