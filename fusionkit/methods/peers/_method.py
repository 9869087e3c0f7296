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
from ..base import MergeEvent, MergeStep, PreparedMaps, common_confidence, tree_result

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
    """A peer's settings: the seed of its random steps, and what the common confidence test
    (the consensus method's, :func:`~fusionkit.methods.base.common_confidence`) needs: its
    settings and the risk."""

    seed: int = 0
    consensus: object = None
    max_false_merge: float = 0.01


def _tree_from_pairs(n: int, reference: int, accepted: dict, exclude=frozenset()):
    """Maximum spanning tree by confidence grown from ``reference`` over ``accepted``
    (``(i, j) -> (transform j -> i, confidence)``), never reaching the maps in ``exclude``;
    returns transforms, confidences, tree."""
    transforms = [None] * n
    conf = [0.0] * n
    transforms[reference] = Transform2D.identity()
    conf[reference] = 1.0
    tree = []
    while True:
        best = None
        for (i, j), (t, c) in accepted.items():
            for p, q, t_qp in ((i, j, t), (j, i, t.inverse)):
                if (transforms[p] is not None and transforms[q] is None and q not in exclude
                        and (best is None or c > best[0])):
                    best = (c, p, q, t_qp)
        if best is None:
            return transforms, conf, tree
        c, p, q, t_qp = best
        transforms[q] = transforms[p] @ t_qp
        conf[q] = c
        tree.append((p, q))


def _groups_from_pairs(n: int, transforms: list, accepted: dict):
    """Groups of the maps left out that link among themselves over ``accepted``: per map its
    group (0 placed, 1, 2, ... by size, None alone), its transform into its group's first map,
    its confidence there; and each group's tree."""
    found = []
    remaining = [k for k in range(n) if transforms[k] is None]
    placed = {k for k in range(n) if transforms[k] is not None}
    while remaining:
        root = remaining[0]
        t_g, c_g, tree_g = _tree_from_pairs(n, root, accepted, exclude=placed)
        members = [k for k in range(n) if t_g[k] is not None]
        remaining = [k for k in remaining if k not in members]
        if len(members) >= 2:
            found.append((members, t_g, c_g, tree_g))
    found.sort(key=lambda g: (-len(g[0]), g[0][0]))
    group = [0 if transforms[k] is not None else None for k in range(n)]
    g_t, g_c, trees = [None] * n, [0.0] * n, []
    for number, (members, t_g, c_g, tree_g) in enumerate(found, start=1):
        for k in members:
            group[k], g_t[k], g_c[k] = number, t_g[k], c_g[k]
        trees.append(tuple(tree_g))
    return group, g_t, g_c, trees


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
        groups = ([0 if t is not None else None for t in transforms], [None] * n, [0.0] * n, [])
        keep = sorted(est.component)
        if len(keep) >= 2 and reference not in keep:
            # its largest group holds maps linked among themselves but not the reference: a
            # group (placed in its first map's frame), not a merge into the reference's map
            group_of = [0 if k == reference else 1 if k in keep else None for k in range(n)]
            g_conf = [1.0 if k == keep[0] else float(est.confidences[k]) if k in keep else 0.0
                      for k in range(n)]
            groups = (group_of, list(est.group_transforms), g_conf, [tuple(tree)])
            tree = []
            for k in keep:
                reasons[k] = (f"its largest group of confidently matched maps does not hold the "
                              f"reference map; it is kept in group 1 with {len(keep) - 1} "
                              f"other map{'s' if len(keep) > 2 else ''}")
        return transforms, conf, tree, reasons, {}, groups
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
    groups = _groups_from_pairs(n, transforms, accepted)
    reasons = ["" if transforms[k] is not None else
               f"{method} accepted no pair linking it to the reference" for k in range(n)]
    return transforms, conf, tree, reasons, estimates, groups


class PeerMethod:
    """One classic peer, by its name in :data:`PEERS`."""

    def __init__(self, name: str):
        if name not in PEERS:
            raise ValueError(f"unknown peer {name!r}; choose one of {', '.join(PEERS)}")
        self.name = name

    def settings(self, config) -> PeerSettings:
        return PeerSettings(config.seed, config.consensus, config.max_false_merge)

    def place(self, maps: PreparedMaps, settings: PeerSettings, emit):
        """Run the peer on the maps and list the pairs it tried as steps."""
        t0 = time.perf_counter()
        n = len(maps)
        grids = list(maps.grids)
        transforms, conf, tree, reasons, estimates, groups = _peer(self.name, grids, maps.reference,
                                                                   settings.seed, emit)
        counts = np.zeros((n, n), int)
        steps = []
        for (i, j), e in estimates.items():
            counts[i, j] = counts[j, i] = int(bool(e.accepted))
            steps.append(MergeStep(i, j, None, e.transform, float(e.confidence), 0, bool(e.accepted), 0))
        seconds = {"align": time.perf_counter() - t0}
        # confidence on the one scale of every method: the consensus test of each link placed
        t1 = time.perf_counter()
        conf, groups = common_confidence(grids, transforms, tree, groups, maps.reference,
                                         settings.seed, settings.consensus, settings.max_false_merge)
        seconds["confidence"] = time.perf_counter() - t1
        return tree_result(maps, transforms, conf, tree, reasons, [0] * n, counts, steps,
                           tuple(maps.scans), tuple(False for _ in range(n)), seconds, groups=groups)
