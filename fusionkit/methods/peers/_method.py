"""The classic peers behind :func:`fusionkit.pipeline.merge` (names ``map-merge``,
``map-merge-shipped``, ``hough-spectrum``, ``fourier-mellin`` of :mod:`fusionkit.methods`).

The peers place N maps as follows:

* ``map-merge`` / ``map-merge-shipped``: :func:`fusionkit.methods.peers.map_merge.estimate_maps`
  (its own largest component and maximum spanning tree; corrected or shipped chaining);
* ``hough-spectrum``, ``fourier-mellin``: the method's ``estimate_pair`` on every pair, its own
  accept decision, and a maximum spanning tree by its own confidence grown from the reference.
"""

from __future__ import annotations

import importlib
import itertools
import time
from dataclasses import dataclass

import numpy as np

from ...transform import Transform2D
from ..base import MergeEvent, MergeStep, PreparedMaps, tree_result

__all__ = ["PEERS", "PeerSettings", "PeerMethod"]

#: Peer method names -> (peers module, chaining for map-merge)
PEERS = {
    "map-merge": ("map_merge", "corrected"),
    "map-merge-shipped": ("map_merge", "shipped"),
    "hough-spectrum": ("hough_spectrum", None),
    "fourier-mellin": ("fourier_mellin", None),
}


@dataclass(frozen=True)
class PeerSettings:
    """A peer's settings: the seed of its random steps."""

    seed: int = 0


def _tree_from_pairs(n: int, reference: int, accepted: dict):
    """Maximum spanning tree by confidence grown from ``reference`` over ``accepted``
    (``(i, j) -> (transform j -> i, confidence)``); returns transforms, confidences, tree."""
    transforms = [None] * n
    conf = [0.0] * n
    transforms[reference] = Transform2D.identity()
    conf[reference] = 1.0
    tree = []
    while True:
        best = None
        for (i, j), (t, c) in accepted.items():
            for p, q, t_qp in ((i, j, t), (j, i, t.inverse)):
                if transforms[p] is not None and transforms[q] is None and (best is None or c > best[0]):
                    best = (c, p, q, t_qp)
        if best is None:
            return transforms, conf, tree
        c, p, q, t_qp = best
        transforms[q] = transforms[p] @ t_qp
        conf[q] = c
        tree.append((p, q))


def _peer(method: str, grids, reference: int, seed: int, emit):
    """Transforms, confidences, tree and reasons of a peer method."""
    module_name, chaining = PEERS[method]
    mod = importlib.import_module(f".{module_name}", __package__)
    n = len(grids)
    if module_name == "map_merge":
        emit(MergeEvent("align", 0, 1, method))
        est = mod.estimate_maps(grids, chaining=chaining, reference=reference, seed=seed)
        transforms = list(est.transforms)
        conf = [float(c) for c in est.confidences]
        conf[reference] = 1.0
        tree = list(est.tree)
        reasons = ["" if transforms[k] is not None else
                   "not in the largest group of confidently matched maps" for k in range(n)]
        return transforms, conf, tree, reasons, {}
    accepted = {}
    todo = list(itertools.combinations(range(n), 2))
    estimates = {}
    for s, (i, j) in enumerate(todo):
        emit(MergeEvent("align", s, len(todo), f"{grids[j].name} -> {grids[i].name}", (i, j)))
        e = mod.estimate_pair(grids[i], grids[j], seed=seed)
        estimates[(i, j)] = e
        if e.accepted and e.transform is not None:
            accepted[(i, j)] = (e.transform, float(e.confidence))
    transforms, conf, tree = _tree_from_pairs(n, reference, accepted)
    reasons = ["" if transforms[k] is not None else
               f"{method} accepted no pair linking it to the reference" for k in range(n)]
    return transforms, conf, tree, reasons, estimates


class PeerMethod:
    """One classic peer, by its name in :data:`PEERS`."""

    def __init__(self, name: str):
        if name not in PEERS:
            raise ValueError(f"unknown peer {name!r}; choose one of {', '.join(PEERS)}")
        self.name = name

    def settings(self, config) -> PeerSettings:
        return PeerSettings(config.seed)

    def place(self, maps: PreparedMaps, settings: PeerSettings, emit):
        """Run the peer on the maps and list the pairs it tried as steps."""
        t0 = time.perf_counter()
        n = len(maps)
        transforms, conf, tree, reasons, estimates = _peer(self.name, list(maps.grids), maps.reference,
                                                           settings.seed, emit)
        counts = np.zeros((n, n), int)
        steps = []
        for (i, j), e in estimates.items():
            counts[i, j] = counts[j, i] = int(bool(e.accepted))
            steps.append(MergeStep(i, j, None, e.transform, float(e.confidence), 0, bool(e.accepted), 0))
        seconds = {"align": time.perf_counter() - t0}
        return tree_result(maps, transforms, conf, tree, reasons, [0] * n, counts, steps,
                           tuple(maps.scans), tuple(False for _ in range(n)), seconds)
