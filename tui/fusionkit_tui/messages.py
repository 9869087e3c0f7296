"""Messages the merge worker posts to the UI (the worker never touches a widget itself)."""

from __future__ import annotations

from pathlib import Path

from textual.message import Message

__all__ = ["MergeProgress", "MergeFinished", "MergeStopped", "MergeFailed", "STAGES"]

#: The stages of a merge as :class:`fusionkit.pipeline.MergeEvent` names them, with the words
#: the UI shows.
STAGES = (("scans", "scans"), ("unique_poses", "unique poses"), ("pairing", "pairing"),
          ("align", "align"), ("fuse", "fuse"))


class MergeProgress(Message):
    """A step of the merge.

    ``stage``, ``step``, ``total`` and ``label`` are those of the
    :class:`~fusionkit.pipeline.MergeEvent`; during alignment ``iteration`` and ``best_cost``
    describe the swarm after its latest iteration (None before the first) and ``pair`` is the
    ``(placed, new)`` map indices.
    """

    def __init__(self, stage: str, step: int, total: int, label: str,
                 iteration: int | None = None, best_cost: float | None = None,
                 pair: tuple | None = None) -> None:
        super().__init__()
        self.pair = pair
        self.stage = stage
        self.step = step
        self.total = total
        self.label = label
        self.iteration = iteration
        self.best_cost = best_cost


class MergeFinished(Message):
    """The merge ended with ``result`` (a :class:`~fusionkit.pipeline.MergeResult`).

    ``evaluation`` holds the Table 1 metrics when a truth.json stood beside the maps, and
    ``evaluation_error`` says why there are none when the truth file could not be used;
    ``labels`` name the inputs on screen (the shortest unique ends of their paths).
    """

    def __init__(self, result, inputs: list[Path], evaluation=None,
                 evaluation_error: str | None = None, labels: list[str] | None = None) -> None:
        super().__init__()
        self.labels = labels
        self.result = result
        self.inputs = inputs
        self.evaluation = evaluation
        self.evaluation_error = evaluation_error


class MergeStopped(Message):
    """The merge was cancelled; nothing changed."""


class MergeFailed(Message):
    """The merge failed with ``error`` (one sentence for the operator)."""

    def __init__(self, error: str) -> None:
        super().__init__()
        self.error = error
