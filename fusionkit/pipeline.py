"""The whole chain of the paper's Fig. 1 behind one call: :func:`merge`.

:func:`merge` loads and checks the maps, brings them to one resolution (for the default method
the finest of them down to half the reference's, to place them; the reference's, to fuse them),
hands them to the chosen method (:mod:`fusionkit.methods`: the paper's method, the consensus
method or a classic peer, all behind one interface), fuses every placed map into the reference
frame (Section 3.6, :mod:`fusionkit.fusion`) and builds the :class:`MergeResult`. For the
paper's method (:mod:`fusionkit.methods.paper`) that is, in the order of Fig. 1:

1. every map gets its scans (its ``.scans.npz``, or virtual scans cast in its free space);
2. unique poses by the DFT of the scans (Algorithm 1, :mod:`fusionkit.unique_poses`);
3. agreement between every two robots' unique poses and the fusion order (eq. 2,
   :mod:`fusionkit.pairing`);
4. for each step of the order, the alignment by PSO on the masks' MSE (eqs. 3-4,
   :mod:`fusionkit.alignment`), checked against the maps already fused: a map that does not
   fit with confidence is left out, never forced;
5. the fusion of every placed map into the reference frame (here).
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field, fields, replace
from numbers import Real
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from .alignment import AlignmentConfig
from .errors import FusionkitError, InputError
from .fusion import FusedMap, fuse_maps
from .grid import OccupancyGrid
from .labels import unique_labels
from .methods import METHODS, get_method
from .methods.base import MergeEvent, MergeStep, PreparedMaps
from .methods.consensus import ConsensusConfig
from .pairing import FusionPlan
from .pso import PSOConfig, _is_int
from ._merge_inputs import (_compared, _same_resolution, _unusable, check_scans, load_inputs,
                            scans_labels)
from .scanlog import ScanLog
from .transform import Transform2D

__all__ = ["MergeConfig", "MergeEvent", "MapPlacement", "MapGroup", "MergeStep", "MergeResult",
           "group_output_paths", "MergeCancelled",
           "merge", "METHODS", "load_inputs"]


class MergeCancelled(FusionkitError):
    """The callback asked the merge to stop."""


@dataclass(frozen=True)
class MergeConfig:
    """Settings of :func:`merge`.

    Attributes
    ----------
    method : str
        ``"consensus"`` (default): verified hypotheses from scans and walls, kept consistent
        over all maps, refused when unsure (:mod:`fusionkit.methods.consensus`; ahead of the
        paper's method and the peers in ``fusionkit bench``, see BENCHMARKS.md); ``"spectral-pso"``:
        the paper's method (unique poses, Pearson pairing, PSO; what ``fusionkit run`` and the
        notebooks reproduce); ``"map-merge"``, ``"map-merge-shipped"``, ``"hough-spectrum"``,
        ``"fourier-mellin"``: the classic peers (:mod:`fusionkit.methods.peers`). The settings
        below are the paper's method's unless noted.
    sub_sec : int
        Half-width of Algorithm 1's sections (poses).
    delta : float or None
        Algorithm 1's divergence threshold; None sets it from ``unique_count``.
    unique_count : int
        Unique poses per robot when ``delta`` is None (the paper's "standardized number").
    theta : float
        Pearson threshold above which two unique poses agree (eq. 2).
    alignment : AlignmentConfig
        Masks and swarm settings (eq. 3).
    accept : float
        Least overlap score (:func:`~fusionkit.alignment.overlap_score`) for a map to be merged.
    min_overlap_cells : int
        Least number of a map's occupied cells that must land on known cells of the fused map.
    refine : bool
        After the swarm on the unique poses' masks, polish each alignment with a local swarm on
        the whole maps' occupied cells (:func:`~fusionkit.alignment.refine_points`).
    virtual_poses : int
        Poses sampled for a map without scans.
    reference : int
        Index of the reference map (its frame is the merged frame).
    seed : int
        Seed of every random step.
    consensus : ConsensusConfig or None
        Settings of the ``"consensus"`` method (None: its defaults).
    max_false_merge : float
        The false-merge risk accepted by the ``"consensus"`` method (it overrides the
        ``ConsensusConfig``'s): the expected number of wrong placements that would fit as well
        as the one accepted (:class:`fusionkit.methods.consensus.NullModel`). Smaller is safer and
        merges less.
    """

    method: str = "consensus"
    sub_sec: int = 5
    delta: float | None = None
    unique_count: int = 200
    theta: float = 0.9
    alignment: AlignmentConfig = AlignmentConfig()
    accept: float = 0.7
    min_overlap_cells: int = 50
    refine: bool = True
    virtual_poses: int = 1500
    reference: int = 0
    seed: int = 0
    consensus: ConsensusConfig | None = None
    max_false_merge: float = 0.01

    def __post_init__(self):
        for name in ("max_false_merge", "theta", "accept", "delta"):
            v = getattr(self, name)       # numpy's numbers are numbers; "0.9" and True are not
            if isinstance(v, Real) and not isinstance(v, (bool, np.bool_)):
                object.__setattr__(self, name, float(v))
        v = self.max_false_merge
        if not (isinstance(v, float) and 0.0 < v < 1.0):
            raise InputError(f"max_false_merge is a risk in (0, 1) (e.g. 0.01), got {v!r}")
        if not isinstance(self.method, str) or self.method not in METHODS:
            raise InputError(f"unknown method {self.method!r}; choose one of {', '.join(METHODS)}")
        if not isinstance(self.alignment, AlignmentConfig):
            raise InputError(f"alignment must be an AlignmentConfig(...), got {type(self.alignment).__name__}")
        if not (self.consensus is None or isinstance(self.consensus, ConsensusConfig)):
            raise InputError(f"consensus must be a ConsensusConfig(...) or None, got "
                             f"{type(self.consensus).__name__}")
        if not isinstance(self.refine, (bool, np.bool_)):
            raise InputError(f"refine must be True or False, got {self.refine!r}")
        object.__setattr__(self, "refine", bool(self.refine))
        for name in ("theta", "accept"):      # "0.9" raised a TypeError deep in the comparison
            v = getattr(self, name)
            if not isinstance(v, float) or not math.isfinite(v):
                raise InputError(f"{name} must be a number, got {v!r}")
        for name in ("sub_sec", "unique_count", "min_overlap_cells", "virtual_poses", "reference"):
            if not _is_int(getattr(self, name)):  # 1.5 was taken
                raise InputError(f"{name} must be a whole number, got {getattr(self, name)!r}")
        if not -1.0 <= self.theta <= 1.0:
            raise InputError(f"theta is a Pearson correlation threshold in [-1, 1], got {self.theta}")
        if not (_is_int(self.seed) and 0 <= self.seed < 2**63):
            raise InputError(f"seed must be a whole number in [0, 2^63 - 1], got {self.seed!r}")
        if self.delta is not None and not (isinstance(self.delta, (int, float))
                                           and not isinstance(self.delta, bool)
                                           and 0.0 <= self.delta < math.inf):
            raise InputError(f"delta is a divergence threshold >= 0 (or None), got {self.delta!r}")
        if self.delta is None and self.unique_count < 1:
            raise InputError(f"unique_count must be >= 1, got {self.unique_count}")
        if self.reference < 0:
            raise InputError(f"reference is the index of a map (0 for the first), got {self.reference}")
        if not 0.0 <= self.accept <= 1.0:
            raise InputError(f"accept is an overlap fraction in [0, 1], got {self.accept}")
        if self.min_overlap_cells < 0 or self.virtual_poses < 20 or self.sub_sec < 1:
            raise InputError("min_overlap_cells must be >= 0, virtual_poses >= 20, sub_sec >= 1")

    @property
    def pso(self) -> PSOConfig:
        return self.alignment.pso

    def with_pso(self, **kw) -> "MergeConfig":
        """A copy with some PSO settings changed (particles, iterations, w, c1, c2, ...)."""
        try:
            pso = replace(self.alignment.pso, **kw)
        except TypeError:
            known = ", ".join(f.name for f in fields(PSOConfig))
            raise InputError(f"with_pso takes PSO settings ({known}); got {', '.join(kw)}") from None
        return replace(self, alignment=replace(self.alignment, pso=pso))


@dataclass(frozen=True)
class MapPlacement:
    """Where one input map went. ``transform`` maps its frame into the merged (reference)
    frame, None when it was not merged; ``confidence`` says how sure the method is that the
    placement is right, in [0, 1]. ``group`` is 0 for the reference's group, 1, 2, ... for a
    group of maps linked among themselves but not to it (None: no group); such a map has its
    ``group_transform`` into the frame of map ``group_reference`` (its group's first map)."""

    index: int
    name: str
    merged: bool
    transform: Transform2D | None
    confidence: float
    overlap_cells: int = 0
    reason: str = ""
    group: int | None = None
    group_transform: Transform2D | None = None
    group_reference: int | None = None
    rivals: tuple = ()
    residual: float | None = None


@dataclass(frozen=True, eq=False)
class MapGroup:
    """Maps linked among themselves but not to the reference's group: group ``number``
    (1, 2, ...), its ``members`` (input indices, the first one's frame is the group's),
    each member's ``transforms`` into that frame (None for the other maps) and their fused
    ``grid``."""

    number: int
    members: tuple
    transforms: tuple
    grid: OccupancyGrid


@dataclass(frozen=True, eq=False)
class MergeResult:
    """Everything a merge produced.

    Attributes
    ----------
    grid : OccupancyGrid
        The fused map in the reference frame (unknown where no merged map saw anything).
    placements : tuple of MapPlacement
        One per input, in input order.
    fusion_order : tuple of (int, int)
        The accepted ``(placed, new)`` steps, in the order they were fused.
    order : tuple of int
        The merged maps in the order they were fused (``fused.steps[i]`` holds the first
        ``i + 1`` of them).
    fused : FusedMap
        The fused map with each cell's contributing map (``owner``) and the cumulative steps.
    unique : tuple of UniquePoses or None
        The paper's method: Algorithm 1's result per map (None for a map it could not scan: no
        free cell and no recorded scans). Empty for the other methods.
    plan : FusionPlan
        Agreement counts and the planned order.
    agreements : dict
        The paper's method: ``(a, b) -> PairAgreement`` for every pair ``a < b``. Empty for the
        other methods.
    steps : tuple of MergeStep
        Every alignment tried, accepted or not, with its PSO history.
    scans : tuple of ScanLog or None
        The scans used per map: recorded ones, or virtual ones where the method cast them for
        a map that had none (the paper's method does; ``consensus`` does only with
        ``ConsensusConfig.virtual_scans``); None for a map without scans.
    virtual : tuple of bool
        Which maps got virtual scans.
    seconds : dict
        Wall time per stage and ``"total"``.
    groups : tuple of MapGroup
        Groups of maps left out that link among themselves, largest first.
    inputs : tuple of str
        The paths the maps were given as (empty when they were given as grids).
    """

    grid: OccupancyGrid
    placements: tuple
    fusion_order: tuple
    order: tuple
    fused: FusedMap
    unique: tuple
    plan: FusionPlan
    agreements: dict
    steps: tuple
    scans: tuple
    virtual: tuple
    config: MergeConfig
    seconds: dict = field(default_factory=dict)
    groups: tuple = ()
    inputs: tuple = ()

    @property
    def transforms(self) -> list:
        return [p.transform for p in self.placements]

    @property
    def all_merged(self) -> bool:
        return all(p.merged for p in self.placements)

    def report(self, inputs: Sequence[str] | None = None, output: str | None = None) -> dict:
        """The CONTRACTS section 6 report (``inputs`` as given on the command line, by default
        the paths given to :func:`merge`, or the maps' names when it was given grids); a map left
        out also carries the ``reason`` it was left out, a map in a group its ``group`` (and,
        outside the reference's group, ``group_transform`` and ``group_reference``); the groups'
        fused maps are listed under ``group_outputs`` (paths from :func:`group_output_paths`,
        none without ``output``)."""
        if isinstance(inputs, (str, bytes, os.PathLike)):
            raise InputError("inputs must be a list of one name or path per map, got one")
        if inputs is not None:
            names = [os.fspath(n) for n in inputs]
        else:
            names = list(self.inputs) or [p.name for p in self.placements]
        output = None if output is None else os.fspath(output)
        if len(names) != len(self.placements):
            raise InputError(f"give one input name per map: {len(names)} for {len(self.placements)} maps")
        maps = []
        for p in self.placements:
            entry = {"input": names[p.index], "merged": p.merged,
                     "confidence": round(float(p.confidence), 4),
                     "transform": None if p.transform is None else p.transform.as_dict()}
            if not p.merged:
                entry["reason"] = p.reason
            if p.group is not None:
                entry["group"] = p.group
            if p.group_transform is not None:
                entry["group_transform"] = p.group_transform.as_dict()
                entry["group_reference"] = names[p.group_reference]
            if p.rivals:
                entry["rivals"] = [{**t.as_dict(), "confidence": round(float(c), 4)}
                                   for t, c in p.rivals]
            if p.residual is not None:
                entry["residual"] = round(float(p.residual), 4)
            maps.append(entry)
        return {
            "method": self.config.method,
            "reference": names[self.config.reference],
            "output": output,
            "maps": maps,
            "fusion_order": [[names[a], names[b]] for a, b in self.fusion_order],
            "group_outputs": ([str(q) for q in group_output_paths(output, len(self.groups))]
                              if output is not None else []),
            "seconds": {k: round(v, 3) for k, v in self.seconds.items()},
        }


def group_output_paths(output: str | os.PathLike, count: int) -> list[Path]:
    """``NAME.group1.yaml``, ``NAME.group2.yaml``, ... beside the output ``NAME.yaml``: where
    the fused maps of ``count`` groups are written (CONTRACTS section 6)."""
    out = Path(output)
    return [out.with_name(f"{out.stem}.group{k}{out.suffix}") for k in range(1, count + 1)]


def merge(maps: Sequence, *, scans: Sequence[ScanLog | None] | None = None,
          config: MergeConfig = MergeConfig(),
          callback: Callable[[MergeEvent], bool | None] | None = None) -> MergeResult:
    """Fuse several robots' maps into the reference map's frame.

    Parameters
    ----------
    maps : sequence of OccupancyGrid or paths to map YAML files
        At least two maps. Paths load their ``.scans.npz`` too when one stands beside.
    scans : sequence of ScanLog or None, optional
        Scans per map (None where a map has none: the consensus method then places it by its
        walls alone, the paper's method casts virtual scans in its free space).
    config : MergeConfig
    callback : callable(MergeEvent) -> bool, optional
        Called as the merge progresses (each PSO iteration included); returning True cancels
        the merge with :class:`MergeCancelled`.

    Returns
    -------
    MergeResult

    Raises
    ------
    InputError
        Fewer than two maps, scans not matching the maps, bad settings.
    MergeCancelled
        When the callback asked to stop.
    """
    t_start = time.perf_counter()
    seconds: dict = {}
    if isinstance(maps, (str, bytes, os.PathLike, OccupancyGrid)):
        raise InputError("maps must be a list of two or more maps (OccupancyGrid objects or paths "
                         "to map YAML files), got one")
    if not isinstance(config, MergeConfig):
        raise InputError(f"config must be a MergeConfig(...), got {type(config).__name__}")
    if callback is not None and not callable(callback):
        raise InputError(f"callback must be callable (it is called with each MergeEvent), got {callback!r}")
    maps = list(maps)
    if len(maps) < 2:
        raise InputError(f"merging needs at least two maps, got {len(maps)}")
    if not 0 <= config.reference < len(maps):
        raise InputError(f"reference index {config.reference} is not one of the {len(maps)} maps")
    from_files = all(isinstance(m, (str, os.PathLike)) for m in maps)
    if from_files:
        grids, file_scans = load_inputs(maps)
        scans = file_scans if scans is None else scans
    elif all(isinstance(m, OccupancyGrid) for m in maps):
        grids = maps
    else:
        raise InputError("maps must be all OccupancyGrid objects or all paths to map YAML files")
    scans = list(scans) if scans is not None else [None] * len(grids)
    if len(scans) != len(grids):
        raise InputError(f"{len(scans)} scan logs for {len(grids)} maps: give one per map (None for none)")
    for k, log in enumerate(scans):
        if log is not None and not isinstance(log, ScanLog):
            raise InputError(f"scans[{k}] is a {type(log).__name__}: give ScanLog objects (load_scans "
                             f"reads a .scans.npz) or None for a map without scans")
    if grids is maps and len({id(g) for g in grids}) < len(grids):
        k = next(i for i, g in enumerate(grids) if any(g is h for h in grids[:i]))
        raise InputError(f"map {k + 1} is the same OccupancyGrid object as an earlier map; give "
                         f"each map once (a map merged with itself is placed on itself)")
    # maps read from files are named by the shortest end of their paths that tells them apart
    # (two runs' robot_1.yaml were both "robot_1", and a dict of placements by name lost one)
    names = (unique_labels(maps) if grids is not maps else
             [g.name or f"map_{k + 1}" for k, g in enumerate(grids)])
    # a map read from a file is named as it was given, as every other error about it is
    ref_name = os.fspath(maps[config.reference]) if grids is not maps else names[config.reference]
    if not grids[config.reference].known_mask().any():
        raise InputError(f"{ref_name}: the reference map has no known cell (all "
                         "unknown), so no map can be placed in its frame; choose another map as "
                         "the reference")
    if not grids[config.reference].occupied_mask().any():
        raise InputError(f"{ref_name}: the reference map has no wall (no occupied "
                         "cell), so no map can be placed in its frame; choose another map as the "
                         "reference")
    check_scans(grids, scans, scans_labels(maps) if grids is not maps else
                [f"scans[{k}] (of map {names[k]})" for k in range(len(grids))])
    originals = list(grids)
    grids = _same_resolution(originals, config.reference)    # fused at the reference's cells
    method = get_method(config.method)
    compared = (_compared(originals, grids, config.reference)
                if getattr(method, "finest_cells", False) else grids)

    def emit(ev: MergeEvent):
        if callback is not None and callback(ev):
            raise MergeCancelled("merge cancelled")

    placed = method.place(PreparedMaps(tuple(compared), tuple(scans), tuple(names), config.reference),
                          method.settings(config), emit)
    seconds.update(placed.seconds)

    # the fusion (Section 3.6), in the method's order
    t0 = time.perf_counter()
    emit(MergeEvent("fuse", 0, 1, "fusing"))
    transforms = [p.transform for p in placed.placements]
    fused = fuse_maps(grids, transforms, order=list(placed.order), keep_steps=True)
    # a group's map is in its first map's frame, at that map's own cell size (the maps as given,
    # not as brought to the reference's cell size)
    groups = tuple(MapGroup(g.number, g.members, g.transforms,
                            fuse_maps(originals, list(g.transforms), order=list(g.order),
                                      resolution=originals[g.members[0]].resolution).grid)
                   for g in placed.groups)
    seconds["fuse"] = time.perf_counter() - t0
    seconds["total"] = time.perf_counter() - t_start
    placements = tuple(
        MapPlacement(k, names[k], p.transform is not None, p.transform, float(p.confidence),
                     int(p.overlap_cells),
                     "" if p.transform is not None else (_unusable(grids[k]) or p.reason),
                     group=p.group, group_transform=p.group_transform,
                     group_reference=p.group_reference, rivals=p.rivals, residual=p.residual)
        for k, p in enumerate(placed.placements))
    emit(MergeEvent("done", 1, 1, "done"))
    return MergeResult(fused.grid, placements, placed.links, placed.order, fused, placed.unique,
                       placed.plan, placed.agreements, placed.steps, placed.scans, placed.virtual,
                       config, seconds, groups,
                       tuple(os.fspath(m) for m in maps) if from_files else ())
