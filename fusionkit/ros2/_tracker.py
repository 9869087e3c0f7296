"""What the node believes about each robot's transform, and the rule that changes it.

A live merge re-estimates every transform every few seconds while the maps grow. Taking each
new estimate as it comes makes the merged map jump whenever one estimate is off; the rule here
(hysteresis) keeps the transform accepted first until a different one is *confidently better*:
it scores higher on the current maps by ``switch_margin`` in ``switch_confirmations`` successive
estimations that agree with each other. A new estimate near the accepted one (a few cells and
degrees: the same placement, fixed better on the grown maps) replaces it at once when it scores
higher, however close it is. A held transform is only kept while it still fits: when the maps
have changed under it (a robot's SLAM restarted in a new frame) so that the test of the method
no longer takes it, the robot is left out, and a new confident estimate places it at once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .. import Transform2D

__all__ = ["Decision", "Tracker", "same_place", "near_place"]


def same_place(a: Transform2D, b: Transform2D, resolution: float) -> bool:
    """Whether two transforms put a map at the same place: within 2 cells and 1 degree."""
    return (math.hypot(a.x - b.x, a.y - b.y) <= 2.0 * resolution
            and abs(math.remainder(a.theta - b.theta, 2 * math.pi)) <= math.radians(1.0))


def near_place(a: Transform2D, b: Transform2D, resolution: float) -> bool:
    """Whether two transforms are one placement fixed more or less well: within 6 cells and 2
    degrees (the consensus method's ``distinct_cells``)."""
    return (math.hypot(a.x - b.x, a.y - b.y) <= 6.0 * resolution
            and abs(math.remainder(a.theta - b.theta, 2 * math.pi)) <= math.radians(2.0))


@dataclass(frozen=True)
class Decision:
    """The outcome of one estimation for one robot.

    ``action`` is one of ``"placed"`` (first accepted transform, or the first after one was
    dropped), ``"confirmed"`` (the new estimate agrees with the accepted one), ``"refined"`` (a
    new estimate of the same placement scores higher on the current maps and replaced it),
    ``"switched"`` (a confidently better transform replaced it), ``"kept"`` (a different
    estimate was not better enough, or the method refused to place the robot this time, and
    the accepted transform still fits), ``"dropped"`` (the accepted transform no longer fits
    the current maps: the robot is left out), ``"not placed"``; ``transform`` and
    ``confidence`` are what the node now holds (None / 0 when not placed); ``why`` says why in
    words.
    """

    robot: str
    action: str
    transform: Transform2D | None
    confidence: float
    why: str = ""

    def line(self) -> str:
        """The decision as one log line."""
        if self.transform is None:
            return f"{self.robot}: {self.action} ({self.why})"
        t = self.transform
        text = (f"{self.robot}: {self.action} at x={t.x:.3f} m y={t.y:.3f} m "
                f"yaw={math.degrees(t.theta):.2f} deg, confidence {self.confidence:.2f}")
        return f"{text} ({self.why})" if self.why else text


@dataclass
class _Held:
    transform: Transform2D
    confidence: float


class Tracker:
    """Accepted transforms of the robots and the hysteresis rule.

    Parameters
    ----------
    min_confidence : float
        Least confidence (0-1) of an estimate for a robot to be placed.
    switch_margin : float
        How much higher (0-1) a different estimate must score than the accepted transform,
        both scored on the same current maps, to count towards a switch.
    switch_confirmations : int
        Successive agreeing better estimates needed for the switch.
    """

    def __init__(self, *, min_confidence: float, switch_margin: float, switch_confirmations: int):
        self.min_confidence = float(min_confidence)
        self.switch_margin = float(switch_margin)
        self.switch_confirmations = int(switch_confirmations)
        self._held: dict[str, _Held] = {}
        self._pending: dict[str, tuple[Transform2D, int]] = {}

    def held(self, robot: str) -> tuple[Transform2D, float] | None:
        """The accepted ``(transform, confidence)`` of a robot, or None."""
        h = self._held.get(robot)
        return None if h is None else (h.transform, h.confidence)

    def fix(self, robot: str, transform: Transform2D, confidence: float = 1.0) -> None:
        """Hold a transform that is known, not estimated (the reference, a known initial pose)."""
        self._held[robot] = _Held(transform, float(confidence))
        self._pending.pop(robot, None)

    def pending(self) -> bool:
        """Whether a switch is waiting for more confirming estimations."""
        return bool(self._pending)

    def forget(self, robot: str) -> None:
        self._held.pop(robot, None)
        self._pending.pop(robot, None)

    def decide(self, robot: str, estimate: Transform2D | None, confidence: float, reason: str,
               resolution: float, score=None, fits=None) -> Decision:
        """Take one new estimate of ``robot``'s transform and say what the node now holds.

        Parameters
        ----------
        estimate : Transform2D or None
            The method's placement (None when it refused to place the robot).
        confidence : float
            Its confidence, 0-1.
        reason : str
            Why the method refused, when it did.
        resolution : float
            Cell size (m) of the robot's map, for :func:`same_place`.
        score : callable(Transform2D) -> float, optional
            Scores a transform of this robot on the current maps (0-1, higher is better); asked
            only when the estimate differs from the accepted transform. Without it an estimate
            within :func:`same_place` confirms the accepted transform and any other is kept
            out.
        fits : callable(Transform2D) -> float, optional
            The confidence (0-1, on the scale of ``confidence``) the method's test gives the
            accepted transform on the current maps; asked only before the accepted transform
            would be kept against a refusal or a different estimate. Below ``min_confidence``
            the accepted transform is dropped.
        """
        decision = self._decide(robot, estimate, confidence, reason, resolution, score)
        if decision.action != "kept" or fits is None:
            return decision
        still = float(fits(decision.transform))
        if still >= self.min_confidence:
            return decision
        self.forget(robot)
        gone = (f"its placement no longer fits the current maps: confidence {still:.2f} there, "
                f"below min_confidence {self.min_confidence:.2f}")
        if estimate is not None and confidence >= self.min_confidence:
            self._held[robot] = _Held(estimate, confidence)
            return Decision(robot, "placed", estimate, confidence, f"anew, as {gone}")
        return Decision(robot, "dropped", None, 0.0, f"left out, as {gone}; {decision.why}")

    def _decide(self, robot: str, estimate, confidence: float, reason: str, resolution: float,
                score) -> Decision:
        held = self._held.get(robot)
        if estimate is not None and confidence < self.min_confidence:
            reason = f"confidence {confidence:.2f} is below min_confidence {self.min_confidence:.2f}"
            estimate = None
        if held is None:
            if estimate is None:
                return Decision(robot, "not placed", None, 0.0, reason or "no confident placement")
            self._held[robot] = _Held(estimate, confidence)
            return Decision(robot, "placed", estimate, confidence)
        if estimate is None:
            self._pending.pop(robot, None)
            return Decision(robot, "kept", held.transform, held.confidence,
                            f"new estimate refused: {reason or 'no confident placement'}")
        s_new = s_old = None
        if score is not None and estimate != held.transform:
            s_new, s_old = float(score(estimate)), float(score(held.transform))
        better = s_new is not None and s_new > s_old
        if same_place(estimate, held.transform, resolution) and not better:
            self._pending.pop(robot, None)
            held.confidence = confidence
            return Decision(robot, "confirmed", held.transform, confidence)
        if better and near_place(estimate, held.transform, resolution):
            self._pending.pop(robot, None)
            self._held[robot] = _Held(estimate, confidence)
            return Decision(robot, "refined", estimate, confidence,
                            f"the same placement fixed better: scores {s_new:.4f} against "
                            f"{s_old:.4f} on the current maps")
        if s_new is None or s_new < s_old + self.switch_margin:
            self._pending.pop(robot, None)
            why = ("a different estimate was found" if s_new is None else
                   f"a different estimate scores {s_new:.2f} against {s_old:.2f} on the current maps")
            return Decision(robot, "kept", held.transform, held.confidence, why)
        prev = self._pending.get(robot)
        count = prev[1] + 1 if prev is not None and same_place(prev[0], estimate, resolution) else 1
        if count < self.switch_confirmations:
            self._pending[robot] = (estimate, count)
            return Decision(robot, "kept", held.transform, held.confidence,
                            f"a better estimate scores {s_new:.2f} against {s_old:.2f}; "
                            f"confirmation {count} of {self.switch_confirmations}")
        self._pending.pop(robot, None)
        self._held[robot] = _Held(estimate, confidence)
        return Decision(robot, "switched", estimate, confidence,
                        f"scores {s_new:.2f} against {s_old:.2f} of the previous transform "
                        f"in {count} successive estimations")
