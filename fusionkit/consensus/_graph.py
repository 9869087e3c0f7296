"""Placing N maps consistently from their pairwise results.

1. Loops of three accepted pairs are checked: going ``i -> j -> k`` must put map ``k`` where
   ``i -> k`` does. A pair that breaks more loops than it closes is dropped.
2. An ambiguous pair (several distinct placements verify) is decided by loops through a third
   map: when exactly one of its placements closes a loop with the other two pairs, it is taken.
3. A maximum spanning tree, grown from the reference map, chains the placements; a link's weight
   is its evidence (agreeing wall cells net of misfits, :meth:`Check.quality`).
4. Every two placed maps are then checked against each other directly; a pair of placed maps
   that overlaps but disagrees reveals a wrong link, and the weakest link of the tree path
   between them is cut (the maps beyond it are left out unless another path places them).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from ..transform import Transform2D
from ._pair import ConsensusConfig, PairResult, displacement
from ._verify import verify

__all__ = ["GraphResult", "solve_graph"]


@dataclass(frozen=True, eq=False)
class GraphResult:
    """The placement of every map.

    Attributes
    ----------
    transforms : tuple of (Transform2D or None)
        Per map, its frame -> the reference's frame; None when left out.
    confidences : tuple of float
        Per map, the verification score of the link that placed it (1 for the reference).
    tree : tuple of (int, int)
        ``(parent, child)`` links in the order the maps were placed.
    dropped : tuple of (int, int)
        Accepted pairs dropped by the loop and cross checks.
    resolved : tuple of (int, int)
        Ambiguous pairs decided by a loop through a third map.
    reasons : tuple of str
        Per map, why it was left out (empty when placed).
    """

    transforms: tuple
    confidences: tuple
    tree: tuple
    dropped: tuple
    resolved: tuple
    reasons: tuple


def _edge(edges: dict, i: int, j: int):
    """``(transform j -> i, confidence, weight)`` of an accepted pair, or None."""
    if (i, j) in edges:
        return edges[(i, j)]
    if (j, i) in edges:
        t, c, w = edges[(j, i)]
        return t.inverse, c, w
    return None


def _options(edges: dict, ambiguous: dict, i: int, j: int):
    """Candidate transforms j -> i of a pair: ``[(transform, key)]`` where ``key`` is None for an
    accepted pair and the candidate's index for an ambiguous one."""
    e = _edge(edges, i, j)
    if e is not None:
        return [(e[0], None)]
    if (i, j) in ambiguous:
        return [(c.transform, n) for n, c in enumerate(ambiguous[(i, j)])]
    if (j, i) in ambiguous:
        return [(c.transform.inverse, n) for n, c in enumerate(ambiguous[(j, i)])]
    return []


def solve_graph(pairs: dict, indexes: list, reference: int, cfg: ConsensusConfig,
                boxes: list) -> GraphResult:
    """Place every map in the reference's frame from the pairwise results ``pairs``
    (``(i, j) -> PairResult`` for ``i < j``, transforms j -> i)."""
    n = len(indexes)
    res = indexes[reference].resolution
    tol = cfg.loop_cells * res
    # weight: the evidence of the placement (agreeing walls net of misfits)
    edges = {(p.a, p.b): (p.transform, p.confidence, p.best.check.quality())
             for p in pairs.values() if p.accepted}
    ambiguous = {(p.a, p.b): p.plausible for p in pairs.values() if p.ambiguous}
    dropped: list = []
    resolved: list = []

    def consistent(i, j, k, tij, tjk, tik) -> bool:
        return displacement(tij @ tjk, tik, boxes[k]) <= tol

    # 1. loops of three accepted pairs
    while True:
        good = {e: 0 for e in edges}
        bad = {e: 0 for e in edges}
        for i, j, k in itertools.combinations(range(n), 3):
            eij, ejk, eik = _edge(edges, i, j), _edge(edges, j, k), _edge(edges, i, k)
            if eij is None or ejk is None or eik is None:
                continue
            ok = consistent(i, j, k, eij[0], ejk[0], eik[0])
            for e in ((i, j), (j, k), (i, k)):
                (good if ok else bad)[e] += 1
        worst = [e for e in edges if bad[e] > good[e]]
        if not worst:
            break
        e = min(worst, key=lambda e: (good[e] - bad[e], edges[e][2]))
        dropped.append(e)
        del edges[e]

    # 2. ambiguous pairs decided by loops through a third map
    changed = True
    while changed and ambiguous:
        changed = False
        for (i, j), cands in list(ambiguous.items()):
            closing = set()
            for k in range(n):
                if k in (i, j):
                    continue
                for tik, key_ik in _options(edges, ambiguous, i, k):
                    if key_ik is not None:
                        continue                       # the other two pairs must be accepted
                    for tkj, key_kj in _options(edges, ambiguous, k, j):
                        if key_kj is not None:
                            continue
                        for m, c in enumerate(cands):
                            if consistent(i, k, j, tik, tkj, c.transform):
                                closing.add(m)
            if len(closing) == 1:
                m = closing.pop()
                edges[(i, j)] = (cands[m].transform, cands[m].check.score, cands[m].check.quality())
                del ambiguous[(i, j)]
                resolved.append((i, j))
                changed = True

    # 3. maximum spanning tree from the reference, then 4. cross checks of the placed maps
    while True:
        transforms = [None] * n
        conf = [0.0] * n
        parent = [-1] * n
        transforms[reference] = Transform2D.identity()
        conf[reference] = 1.0
        tree = []
        while True:
            best = None
            for (i, j), (t, c, w) in edges.items():
                for p, q in ((i, j), (j, i)):
                    if transforms[p] is not None and transforms[q] is None:
                        if best is None or w > best[0]:
                            best = (w, p, q)
            if best is None:
                break
            _, p, q = best
            t_pq, c, _ = _edge(edges, p, q)                # q -> p
            transforms[q] = transforms[p] @ t_pq
            conf[q] = c
            parent[q] = p
            tree.append((p, q))
        cut = None
        if cfg.final_check:
            placed = [k for k in range(n) if transforms[k] is not None]
            worst = None
            for a, b in itertools.combinations(placed, 2):
                if parent[b] == a or parent[a] == b:
                    continue
                t_ba = transforms[a].inverse @ transforms[b]
                chk = verify(indexes[a], indexes[b], t_ba)
                if chk.overlap >= cfg.min_overlap_cells and (
                        chk.score < cfg.accept - cfg.margin or chk.conflict_fraction > 2 * cfg.max_conflict):
                    if worst is None or chk.score < worst[0]:
                        worst = (chk.score, a, b)
            if worst is not None:
                _, a, b = worst
                path = _tree_path(parent, a, b)
                cut = min(path, key=lambda e: _edge(edges, *e)[2])
        if cut is None:
            break
        key = cut if cut in edges else (cut[1], cut[0])
        dropped.append(key)
        del edges[key]

    reasons = []
    for k in range(n):
        if transforms[k] is not None:
            reasons.append("")
            continue
        mine = [p for p in pairs.values() if k in (p.a, p.b)]
        if any(p.ambiguous for p in mine):
            reasons.append("ambiguous: several placements fit and no loop through a third map decides")
        elif any(p.accepted for p in mine):
            reasons.append("its only confident links disagree with the other maps")
        else:
            best = max(mine, key=lambda p: p.confidence, default=None)
            reasons.append(best.reason if best is not None and best.reason else
                           "no confident placement against any other map")
    return GraphResult(tuple(transforms), tuple(float(c) for c in conf), tuple(tree),
                       tuple(dropped), tuple(resolved), tuple(reasons))


def _tree_path(parent: list, a: int, b: int) -> list:
    """Tree links ``(parent, child)`` on the path between ``a`` and ``b``."""
    def up(x):
        out = [x]
        while parent[x] >= 0:
            x = parent[x]
            out.append(x)
        return out
    ua, ub = up(a), up(b)
    common = next(x for x in ua if x in ub)
    path = []
    for chain in (ua, ub):
        for x in chain:
            if x == common:
                break
            path.append((parent[x], x))
    return path
