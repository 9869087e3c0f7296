"""One robot as the node sees it, and one round of transform estimation over all robots."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Callable

from .. import OccupancyGrid
from ._params import NodeSettings
from ._tracker import Decision, Tracker

__all__ = ["Robot", "estimate_round"]


@dataclass(eq=False)
class Robot:
    """A discovered robot: its map topic, its last valid map and what was decided about it."""

    name: str
    topic: str
    grid: OccupancyGrid | None = None
    received: float = 0.0
    updates: int = 0
    known: bool = False          # its last map holds a known cell (an empty one is waited out)
    walls: bool = False          # ... and an occupied one (a reference needs walls)
    problem: str = ""
    vanished: bool = False
    last_action: str = ""
    last_why: str = ""
    judged: OccupancyGrid | None = None   # the map its held transform was last judged on
    sub: object = None
    pose_pub: object = None
    pose_topic: str = ""
    pose_sent: bool = False      # its transform topic holds a pose (latched)


def estimate_round(snapshot: list, reference: str, settings: NodeSettings, tracker: Tracker,
                   cancel: Callable[[], bool] = lambda: False) -> list[Decision]:
    """Estimate every robot's transform into the reference robot's map frame and let the
    tracker decide what to hold.

    Parameters
    ----------
    snapshot : list of (name, OccupancyGrid)
        Every robot with a map (the reference among them).
    reference : str
        Name of the reference robot (it is held at the identity and gets no decision).
    cancel : callable
        Returns True to stop the estimation (:class:`fusionkit.MergeCancelled`).

    Returns
    -------
    list of Decision
        One per robot other than the reference.
    """
    import fusionkit as fk

    grids = dict(snapshot)
    names = [reference] + sorted(n for n in grids if n != reference)
    result = fk.merge([grids[n] for n in names],
                      config=fk.MergeConfig(method=settings.method, reference=0, seed=settings.seed),
                      callback=lambda _ev: cancel())
    decisions = []
    for k, name in enumerate(names[1:], start=1):
        p = result.placements[k]
        estimate = p.transform if p.merged else None

        # the other held maps fused: made once for this robot, when a score first needs it
        others = functools.cache(lambda _name=name: _others_fused(grids, tracker, _name))

        def score(t, _name=name, _others=others):
            return _score_against(_others(), grids[_name], t)

        def fits(t, _name=name, _others=others):
            return _confidence_against(_others(), grids[_name], t, settings.seed)

        decisions.append(tracker.decide(name, estimate, float(p.confidence), p.reason,
                                        grids[name].resolution, score=score, fits=fits))
    return decisions


def _others_fused(grids: dict, tracker: Tracker, name: str):
    """The held maps other than ``grids[name]``, fused in the merged frame (None: none held)."""
    import fusionkit as fk

    others = [(grids[n], tracker.held(n)[0]) for n in grids
              if n != name and tracker.held(n) is not None]
    if not others:
        return None
    return fk.fuse_maps([g for g, _ in others], [t for _, t in others]).grid


def _confidence_against(fused, grid: OccupancyGrid, transform, seed: int) -> float:
    """The confidence the consensus test gives ``grid`` placed by ``transform`` on ``fused``,
    the other held maps (:func:`fusionkit.methods.consensus.placement_confidence`, 0-1: the
    scale of every method's confidence)."""
    from ..methods.consensus import placement_confidence, prepare_maps
    from .._merge_inputs import _same_resolution

    if fused is None:
        return 0.0
    a, b = prepare_maps(_same_resolution([fused, grid], 0))
    return float(placement_confidence(a, b, transform, seed=seed))


def _score_against(fused, grid: OccupancyGrid, transform) -> float:
    """How well ``grid`` placed by ``transform`` agrees with ``fused``, the other held maps
    (:func:`fusionkit.overlap_score`, 0-1)."""
    import fusionkit as fk

    if fused is None:
        return 0.0
    score, _cells = fk.overlap_score(fused, grid, transform)
    return float(score)
