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


#: map-merge's matcher threshold (its node's ``estimation_confidence``, OpenCV's ``conf_thresh``)
MAP_MERGE_CONFIDENCE = 1.0


def _linked_sets(conf: np.ndarray, threshold: float) -> list[list[int]]:
    """Every set of two maps or more that pairs of confidence >= ``threshold`` join, the
    largest first (ties: the one holding the first map given)."""
    n = conf.shape[0]
    root = list(range(n))

    def find(k):
        while root[k] != k:
            root[k] = root[root[k]]
            k = root[k]
        return k

    for i in range(n):
        for j in range(n):
            if i != j and conf[i, j] >= threshold:
                root[find(i)] = find(j)
    sets: dict = {}
    for k in range(n):
        sets.setdefault(find(k), []).append(k)
    return sorted((m for m in sets.values() if len(m) >= 2), key=lambda m: (-len(m), m[0]))


def _map_merge(mod, method: str, chaining: str, grids, reference: int, seed: int, emit):
    """map-merge on every set of maps its matcher links, not only its largest: the reference's
    set is merged into the reference's frame, each other set kept as a group in its first
    map's frame (its node keeps the largest set alone, and which of two sets of one size it
    kept followed the order the maps were given in)."""
    n = len(grids)
    emit(MergeEvent("align", 0, 1, method))
    est = mod.estimate_maps(grids, chaining=chaining, reference=reference, seed=seed,
                            confidence=MAP_MERGE_CONFIDENCE)
    transforms, conf, tree = [None] * n, [0.0] * n, []
    transforms[reference], conf[reference] = Transform2D.identity(), 1.0
    group_of, group_tf, group_conf, group_trees = [None] * n, [None] * n, [0.0] * n, []
    group_of[reference] = 0
    reasons = ["no pair its matcher is confident of links it to another map"] * n
    reasons[reference] = ""
    sets = _linked_sets(est.pair_confidence, MAP_MERGE_CONFIDENCE)
    others = [m for m in sets if reference not in m]
    for members in sets:
        root = reference if reference in members else members[0]
        if sorted(est.component) == members and reference in members:
            sub = est   # its largest set, estimated with every map given
            local = list(range(n))
        else:
            sub = mod.estimate_maps([grids[k] for k in members], chaining=chaining,
                                    reference=members.index(root), seed=seed,
                                    confidence=MAP_MERGE_CONFIDENCE)
            local = members
        placed = {local[a]: t for a, t in enumerate(sub.transforms) if t is not None}
        if root not in placed:
            continue    # the set's own estimate left its first map out: nothing to place by
        if reference in members:
            for k, t in placed.items():
                transforms[k] = t
                conf[k] = 1.0 if k == reference else float(sub.confidences[local.index(k)])
                group_of[k], reasons[k] = 0, ""
            tree = [(local[a], local[b]) for a, b in sub.tree] if sub is not est else list(sub.tree)
        else:
            number = others.index(members) + 1
            for k, t in placed.items():
                group_of[k], group_tf[k] = number, t
                group_conf[k] = 1.0 if k == root else float(sub.confidences[local.index(k)])
                reasons[k] = (f"its confidently matched maps do not hold the reference map; it is "
                              f"kept in group {number} with {len(placed) - 1} other "
                              f"map{'s' if len(placed) > 2 else ''}")
            group_trees.append(tuple((local[a], local[b]) for a, b in sub.tree))
    for k in range(n):
        if k != reference and transforms[k] is None and group_of[k] is None and any(
                k in m for m in sets):
            reasons[k] = "its matcher's estimate of its linked maps left it out"
    groups = (group_of, group_tf, group_conf, group_trees)
    return transforms, conf, tree, reasons, {}, groups


def _peer(method: str, grids, reference: int, seed: int, emit):
    """Transforms, confidences, tree and reasons of a peer method."""
    module_name, chaining = PEERS[method]
    mod = importlib.import_module(f".{module_name}", __package__)
    n = len(grids)
    if module_name == "map_merge":
        return _map_merge(mod, method, chaining, grids, reference, seed, emit)
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
