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

from dataclasses import dataclass, field
from typing import Any, Callable, Protocol

import numpy as np

from ..alignment import Alignment
from ..pairing import FusionPlan
from ..pso import PSOState
from ..transform import Transform2D

__all__ = ["MergeEvent", "MergeStep", "PreparedMaps", "Placement", "MethodResult", "Method",
           "Emit", "tree_result"]


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
    (None: left out, with the ``reason``); ``confidence`` >= 0, the method's own score (1 for
    the reference; in [0, 1] but for map-merge's inlier ratio); ``overlap_cells`` the
    overlap the confidence was measured on."""

    transform: Transform2D | None
    confidence: float
    reason: str = ""
    overlap_cells: int = 0


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


class Method(Protocol):
    """The interface every merging method implements."""

    name: str

    def settings(self, config) -> Any:
        """The method's own frozen settings, picked from a :class:`~fusionkit.pipeline.MergeConfig`."""

    def place(self, maps: PreparedMaps, settings: Any, emit: Emit) -> MethodResult:
        """Place every map in the reference frame, or leave it out with a reason."""


def tree_result(maps: PreparedMaps, transforms: list, conf: list, tree: list, reasons: list,
                overlap: list, counts: np.ndarray, steps: list, scans: tuple, virtual: tuple,
                seconds: dict) -> MethodResult:
    """The result of a method that links maps over a tree from the reference: the maps are
    fused in the order the tree reached them; a map left out has confidence 0."""
    n = len(maps)
    ref = maps.reference
    placed_order = [ref]
    for k in [x for edge in tree for x in edge] + list(range(n)):
        if transforms[k] is not None and k not in placed_order:
            placed_order.append(k)
    plan = FusionPlan(counts, tuple(tree), tuple(k for k in range(n) if transforms[k] is None))
    placements = tuple(Placement(transforms[k], float(conf[k]) if transforms[k] is not None else 0.0,
                                 reasons[k] if transforms[k] is None else "", int(overlap[k]))
                       for k in range(n))
    return MethodResult(placements, tuple(tree), tuple(placed_order), plan, tuple(steps), scans,
                        virtual, seconds=seconds)
