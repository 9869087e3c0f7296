"""The consensus method and the classic peers behind :func:`fusionkit.pipeline.merge`.

Every method returns the same :class:`~fusionkit.pipeline.MergeResult`, so the command line and
the benchmark compare them on equal terms. The peers place N maps as follows:

* ``map-merge`` / ``map-merge-shipped``: :func:`fusionkit.baselines.map_merge.estimate_maps`
  (its own largest component and maximum spanning tree; corrected or shipped chaining);
* ``hough-spectrum``, ``fourier-mellin``: the method's ``estimate_pair`` on every pair, its own
  accept decision, and a maximum spanning tree by its own confidence grown from the reference.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import replace

import numpy as np

from ..fusion import fuse_maps
from ..transform import Transform2D

__all__ = ["CONSENSUS", "PEERS", "merge_with"]

CONSENSUS = "consensus"
#: Peer method names -> (baselines module, chaining for map-merge)
PEERS = {
    "map-merge": ("map_merge", "corrected"),
    "map-merge-shipped": ("map_merge", "shipped"),
    "hough-spectrum": ("hough_spectrum", None),
    "fourier-mellin": ("fourier_mellin", None),
}


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


def _residual(a, b, t) -> float | None:
    """Median distance (m) from B's walls, placed in A by ``t`` (B -> A), to A's nearest wall,
    over those landing where A is known: how far a bent map's walls stay from the other's."""
    if len(b.points) == 0:
        return None
    ri, ci, inside = a.cells(t(b.points))
    ri, ci = ri[inside], ci[inside]
    keep = a.known[ri, ci]
    if not keep.any():
        return None
    return float(np.median(a.dist[ri[keep], ci[keep]])) * a.resolution


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


def _common_confidence(grids, transforms, tree, groups, config):
    """Each placed map's confidence from the consensus method's test (``exp(-nfa)`` of the link
    that placed it, 0..1), for a peer whose own score is on a scale of its own."""
    from . import ConsensusConfig, placement_confidence, prepare_maps
    cfg = config.consensus if config.consensus is not None else ConsensusConfig()
    cfg = replace(cfg, max_false_merge=config.max_false_merge, use_scans=False)
    n = len(grids)
    group_of, group_tf, group_conf, group_trees = groups
    links = [(p, q, transforms) for p, q in tree]
    for g_tree in group_trees:
        links += [(p, q, group_tf) for p, q in g_tree]
    links = [(p, q, frame) for p, q, frame in links if frame[p] is not None and frame[q] is not None]
    if not links:
        return [1.0 if k == config.reference else 0.0 for k in range(n)], groups
    needed = sorted({k for p, q, _ in links for k in (p, q)})
    built = prepare_maps([grids[k] for k in needed], config=cfg)
    index = dict(zip(needed, built))
    conf = [0.0] * n
    conf[config.reference] = 1.0
    g_conf = list(group_conf)
    for p, q, frame in links:
        c = placement_confidence(index[p], index[q], frame[p].inverse @ frame[q], config=cfg,
                                 seed=config.seed + q)
        if frame is transforms:
            conf[q] = c
        else:
            g_conf[q] = c
    for k in range(n):
        if group_of[k] and group_tf[k] is not None and k == min(m for m in range(n) if group_of[m] == group_of[k]):
            g_conf[k] = 1.0
    return conf, (group_of, group_tf, g_conf, group_trees)


def _peer(method: str, grids, reference: int, seed: int, emit):
    """Transforms, confidences, tree and reasons of a peer method."""
    import importlib
    from ..pipeline import MergeEvent
    module_name, chaining = PEERS[method]
    mod = importlib.import_module(f"..baselines.{module_name}", __package__)
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


def merge_with(method: str, grids: list, scans: list, names: list, config, emit, t_start: float):
    """Run ``method`` (consensus or a peer) and build the :class:`MergeResult`."""
    from ..pairing import FusionPlan
    from ..pipeline import MapGroup, MapPlacement, MergeEvent, MergeResult, MergeStep
    n = len(grids)
    ref = config.reference
    seconds: dict = {}
    steps = []
    logs: tuple = tuple(scans)
    virtual = tuple(False for _ in range(n))
    overlap = [0] * n
    t0 = time.perf_counter()
    if method == CONSENSUS:
        from . import ConsensusConfig, estimate_maps
        cfg = config.consensus if config.consensus is not None else ConsensusConfig()
        cfg = replace(cfg, max_false_merge=config.max_false_merge)

        def cb(stage, step, total, pair):
            label = names[step] if pair is None else f"{names[pair[1]]} -> {names[pair[0]]}"
            emit(MergeEvent(stage, step, total, label, pair))

        res = estimate_maps(grids, scans, config=cfg, reference=ref, seed=config.seed,
                            virtual_poses=config.virtual_poses, callback=cb)
        g = res.graph
        transforms, conf = list(g.transforms), list(g.confidences)
        tree, reasons = list(g.tree), list(g.reasons)
        groups = (list(g.groups), list(g.group_transforms), list(g.group_confidences),
                  list(g.group_trees))
        rivals = list(g.rivals) if g.rivals else [()] * n
        residual = [None] * n
        for a, b in tree:
            residual[b] = _residual(res.indexes[a], res.indexes[b],
                                    transforms[a].inverse @ transforms[b])
        for (i, j), p in res.pairs.items():
            ov = p.best.check.overlap if p.best is not None else 0
            steps.append(MergeStep(i, j, None, p.transform, p.confidence, ov,
                                   p.accepted or (i, j) in g.resolved, p.hypotheses))
        for a, b in tree:
            p = res.pairs.get((min(a, b), max(a, b)))
            overlap[b] = p.best.check.overlap if p is not None and p.best is not None else 0
        counts = np.zeros((n, n), int)
        for (i, j), p in res.pairs.items():
            counts[i, j] = counts[j, i] = len(p.plausible)
        virtual = tuple(ix.virtual for ix in res.indexes)
        logs = tuple(ix.log for ix in res.indexes)
        seconds.update(res.seconds)
    else:
        transforms, conf, tree, reasons, estimates, groups = _peer(method, grids, ref, config.seed, emit)
        rivals, residual = [()] * n, [None] * n
        seconds["align"] = time.perf_counter() - t0
        # confidence on the one scale of every method: the consensus test of each link placed
        t1 = time.perf_counter()
        conf, groups = _common_confidence(grids, transforms, tree, groups, config)
        seconds["confidence"] = time.perf_counter() - t1
        counts = np.zeros((n, n), int)
        for (i, j), e in estimates.items():
            counts[i, j] = counts[j, i] = int(bool(e.accepted))
            steps.append(MergeStep(i, j, None, e.transform, float(e.confidence), 0, bool(e.accepted), 0))
    placed_order = [ref]
    for k in [x for edge in tree for x in edge] + list(range(n)):
        if transforms[k] is not None and k not in placed_order:
            placed_order.append(k)
    plan = FusionPlan(counts, tuple(tree), tuple(k for k in range(n) if transforms[k] is None))

    t0 = time.perf_counter()
    emit(MergeEvent("fuse", 0, 1, "fusing"))
    fused = fuse_maps(grids, transforms, order=placed_order, keep_steps=True)
    group_of, group_tf, group_conf, group_trees = groups
    fused_groups = []
    for number, g_tree in enumerate(group_trees, start=1):
        members = [k for k in range(n) if group_of[k] == number]
        order = [members[0]] + [q for _, q in g_tree if q != members[0]]
        tf = [group_tf[k] if group_of[k] == number else None for k in range(n)]
        fused_groups.append(MapGroup(number, tuple(members), tuple(tf),
                                     fuse_maps(grids, tf, order=order).grid))
    seconds["fuse"] = time.perf_counter() - t0
    seconds["total"] = time.perf_counter() - t_start
    placements = []
    for k in range(n):
        g = group_of[k]
        extra = {}
        if g is not None:
            extra["group"] = g
        if g:
            extra.update(group_transform=group_tf[k],
                         group_reference=min(m for m in range(n) if group_of[m] == g))
        if transforms[k] is None and rivals[k]:
            extra["rivals"] = rivals[k]
        if transforms[k] is not None and residual[k] is not None:
            extra["residual"] = residual[k]
        placements.append(MapPlacement(
            k, names[k], transforms[k] is not None, transforms[k],
            float(conf[k]) if transforms[k] is not None else float(group_conf[k]) if g else 0.0,
            int(overlap[k]), reasons[k] if transforms[k] is None else "", **extra))
    emit(MergeEvent("done", 1, 1, "done"))
    return MergeResult(fused.grid, tuple(placements), tuple(tree), tuple(placed_order), fused, (),
                       plan, {}, tuple(steps), logs, virtual, config, seconds, tuple(fused_groups))


