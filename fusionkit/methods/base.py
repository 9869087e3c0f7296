"""What every merging method takes and gives.

:func:`fusionkit.pipeline.merge` loads and checks the maps, hands them to the chosen method as a
:class:`PreparedMaps`, with the method's own frozen settings, and gets back a
:class:`MethodResult`: where each map goes (a :class:`Placement`), the links that placed them,
the order to fuse them in and what the method did on the way (its :class:`MergeStep` s and the
time of each stage). The fusion and the result are :func:`~fusionkit.pipeline.merge`'s.

A method is any object with a ``name``, ``settings(config)`` (its frozen settings picked from a
:class:`~fusionkit.pipeline.MergeConfig`) and ``place(maps, settings, emit)``
(:class:`Method`); :mod:`fusionkit.methods` maps the ``--method`` names to them.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Callable, Protocol

import numpy as np

from ..alignment import Alignment
from ..pairing import FusionPlan
from ..pso import PSOState
from ..transform import Transform2D

__all__ = ["MergeEvent", "MergeStep", "PreparedMaps", "Placement", "PlacedGroup", "MethodResult",
           "Method", "Emit", "tree_result", "common_confidence"]


@dataclass(frozen=True)
class MergeEvent:
    """Progress of a merge, as the callback sees it.

    ``stage`` is one of ``"scans"``, ``"unique_poses"``, ``"pairing"``, ``"align"``, ``"fuse"``,
    ``"done"``; ``step`` of ``total`` counts work in that stage; ``label`` says what is being
    done ("robot_2 -> robot_1"); during ``"align"``, ``pso`` is the swarm's state after each
    iteration and ``pair`` the ``(placed, new)`` map indices.
    """

    stage: str
    step: int
    total: int
    label: str = ""
    pair: tuple | None = None
    pso: PSOState | None = None


#: What a method calls to report progress (it raises when the caller asked to stop).
Emit = Callable[[MergeEvent], None]


@dataclass(frozen=True, eq=False)
class MergeStep:
    """One alignment of the fusion order: map ``new`` against the fused maps (anchor ``placed``)."""

    placed: int
    new: int
    alignment: Alignment | None
    transform: Transform2D | None
    confidence: float
    overlap_cells: int
    accepted: bool
    matches: int


@dataclass(frozen=True, eq=False)
class PreparedMaps:
    """The maps a method places: grids of one resolution, the recorded scans of each (None
    where a map has none), their names and the index of the reference map."""

    grids: tuple
    scans: tuple
    names: tuple
    reference: int

    def __len__(self) -> int:
        return len(self.grids)


@dataclass(frozen=True)
class Placement:
    """Where a method put one map: ``transform`` maps its frame into the reference frame
    (None: left out, with the ``reason``); ``confidence`` in [0, 1], how sure the method is
    that the placement is right (1 for the reference; for a map in another group, of its
    placement in that group); ``overlap_cells`` the overlap it was measured on.

    ``group`` is 0 for the reference's group, 1, 2, ... for a group of maps linked among
    themselves but not to the reference (None: no group); such a map has its
    ``group_transform`` into the frame of map ``group_reference``. ``rivals`` lists distinct
    placements ``(transform, confidence)`` nearly as good as the best (why a map was refused as
    ambiguous); ``residual`` (m) how far a placed map's walls stay from the other's."""

    transform: Transform2D | None
    confidence: float
    reason: str = ""
    overlap_cells: int = 0
    group: int | None = None
    group_transform: Transform2D | None = None
    group_reference: int | None = None
    rivals: tuple = ()
    residual: float | None = None


@dataclass(frozen=True, eq=False)
class PlacedGroup:
    """Maps linked among themselves but not to the reference's group: group ``number`` (1, 2,
    ...), its ``members`` (input indices; the first one's frame is the group's), each map's
    ``transforms`` into that frame (None outside the group) and the ``order`` to fuse them in."""

    number: int
    members: tuple
    transforms: tuple
    order: tuple


@dataclass(frozen=True, eq=False)
class MethodResult:
    """What a method gives back.

    Attributes
    ----------
    placements : tuple of Placement
        One per map, in input order.
    links : tuple of (int, int)
        The accepted ``(placed, new)`` links, in the order they were made (the groups: a map
        is merged when a chain of links joins it to the reference).
    order : tuple of int
        The merged maps in the order to fuse them (the reference among them).
    plan : FusionPlan
        Support between every two maps and the planned links.
    steps : tuple of MergeStep
        Every alignment tried, accepted or not.
    scans : tuple of ScanLog or None
        The scans used (virtual ones where cast).
    virtual : tuple of bool
        Which maps got virtual scans.
    unique, agreements
        The paper's method's unique poses and pair agreements (empty for the others).
    seconds : dict
        Wall time per stage.
    groups : tuple of PlacedGroup
        Groups of maps left out that link among themselves, largest first.
    """

    placements: tuple
    links: tuple
    order: tuple
    plan: FusionPlan
    steps: tuple
    scans: tuple
    virtual: tuple
    unique: tuple = ()
    agreements: dict = field(default_factory=dict)
    seconds: dict = field(default_factory=dict)
    groups: tuple = ()


class Method(Protocol):
    """The interface every merging method implements. A method whose class sets
    ``finest_cells = True`` gets maps of several cell sizes at the finest of them (down to half
    the reference's); the others get them at the reference's."""

    name: str

    def settings(self, config) -> Any:
        """The method's own frozen settings, picked from a :class:`~fusionkit.pipeline.MergeConfig`."""

    def place(self, maps: PreparedMaps, settings: Any, emit: Emit) -> MethodResult:
        """Place every map in the reference frame, or leave it out with a reason."""


def tree_result(maps: PreparedMaps, transforms: list, conf: list, tree: list, reasons: list,
                overlap: list, counts: np.ndarray, steps: list, scans: tuple, virtual: tuple,
                seconds: dict, groups=None, rivals=None, residual=None) -> MethodResult:
    """The result of a method that links maps over a tree from the reference: the maps are
    fused in the order the tree reached them; a map left out has confidence 0 unless it was
    placed in another group.

    ``groups`` is ``(group_of, group_transforms, group_confidences, group_trees)`` per map
    (:func:`fusionkit.methods.consensus.group_maps`' shape); ``rivals`` and ``residual`` per map.
    """
    n = len(maps)
    ref = maps.reference
    placed_order = [ref]
    for k in [x for edge in tree for x in edge] + list(range(n)):
        if transforms[k] is not None and k not in placed_order:
            placed_order.append(k)
    plan = FusionPlan(counts, tuple(tree), tuple(k for k in range(n) if transforms[k] is None))
    if groups is None:
        groups = ([0 if t is not None else None for t in transforms], [None] * n, [0.0] * n, [])
    group_of, group_tf, group_conf, group_trees = groups
    rivals = rivals if rivals is not None else [()] * n
    residual = residual if residual is not None else [None] * n
    placed_groups = []
    for number, g_tree in enumerate(group_trees, start=1):
        members = tuple(k for k in range(n) if group_of[k] == number)
        order = (members[0],) + tuple(q for _, q in g_tree if q != members[0])
        tf = tuple(group_tf[k] if group_of[k] == number else None for k in range(n))
        placed_groups.append(PlacedGroup(number, members, tf, order))
    placements = []
    for k in range(n):
        g = group_of[k]
        in_group = bool(g) and group_tf[k] is not None
        if transforms[k] is not None:
            c = float(conf[k])
        else:
            c = float(group_conf[k]) if in_group else 0.0
        placements.append(Placement(
            transforms[k], c, reasons[k] if transforms[k] is None else "", int(overlap[k]),
            group=g, group_transform=group_tf[k] if in_group else None,
            group_reference=(min(m for m in range(n) if group_of[m] == g) if in_group else None),
            rivals=tuple(rivals[k]) if transforms[k] is None and rivals[k] else (),
            residual=residual[k] if transforms[k] is not None else None))
    return MethodResult(tuple(placements), tuple(tree), tuple(placed_order), plan, tuple(steps),
                        scans, virtual, seconds=seconds, groups=tuple(placed_groups))


def _oriented(tree, root: int) -> list:
    """The edges of ``tree`` as ``(parent, child)`` pairs, walked outwards from ``root``."""
    near: dict = {}
    for a, b in tree:
        near.setdefault(a, []).append(b)
        near.setdefault(b, []).append(a)
    out, seen, todo = [], {root}, [root]
    while todo:
        p = todo.pop(0)
        for q in sorted(near.get(p, ())):
            if q not in seen:
                seen.add(q)
                out.append((p, q))
                todo.append(q)
    return out


def common_confidence(grids, transforms, tree, groups, reference: int, seed: int,
                      consensus=None, max_false_merge: float = 0.01):
    """Each placed map's confidence from the consensus method's test (``exp(-nfa)`` of the link
    that placed it, 0..1), for a method whose own score is on a scale of its own (the peers',
    the paper's share of walls): the one scale of every method's report. ``consensus`` is the
    test's :class:`~fusionkit.methods.consensus.ConsensusConfig` (None: its defaults)."""
    from .consensus import ConsensusConfig, placement_confidence, prepare_maps
    cfg = consensus if consensus is not None else ConsensusConfig()
    cfg = replace(cfg, max_false_merge=max_false_merge, use_scans=False)
    n = len(grids)
    group_of, group_tf, group_conf, group_trees = groups
    # each link judged from the map nearer its group's root (a peer's own tree may be rooted
    # elsewhere, map-merge's at the centre map): the confidence goes to the map it placed
    links = [(p, q, transforms) for p, q in _oriented(tree, reference)]
    for g_tree in group_trees:
        root = min(k for edge in g_tree for k in edge)
        links += [(p, q, group_tf) for p, q in _oriented(g_tree, root)]
    links = [(p, q, frame) for p, q, frame in links if frame[p] is not None and frame[q] is not None]
    if not links:
        return [1.0 if k == reference else 0.0 for k in range(n)], groups
    needed = sorted({k for p, q, _ in links for k in (p, q)})
    built = prepare_maps([grids[k] for k in needed], config=cfg)
    index = dict(zip(needed, built))
    conf = [0.0] * n
    conf[reference] = 1.0
    g_conf = list(group_conf)
    for p, q, frame in links:
        c = placement_confidence(index[p], index[q], frame[p].inverse @ frame[q], config=cfg,
                                 seed=seed + q)
        if frame is transforms:
            conf[q] = c
        else:
            g_conf[q] = c
    for k in range(n):
        if group_of[k] and group_tf[k] is not None and k == min(m for m in range(n) if group_of[m] == group_of[k]):
            g_conf[k] = 1.0
    return conf, (group_of, group_tf, g_conf, group_trees)
