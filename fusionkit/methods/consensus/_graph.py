"""Placing N maps consistently from their pairwise results.

0. A map that fits another map about equally well in several places (an ambiguous pair) has
   repeated structure; a single fit of it with a third map that is not clearly stronger than
   those is only used once a loop confirms it (it joins the ambiguous pairs otherwise).
1. Loops of three accepted pairs are checked: going ``i -> j -> k`` must put map ``k`` where
   ``i -> k`` does. A pair that breaks more loops than it closes is dropped; between pairs that
   break as many, loops through *witnesses* decide (pairs whose placement is meaningful, fewer
   than one false alarm expected, without reaching the risk accepted) and loops through pairs
   that fit in several places (closed when one of those places is where the loop puts the map),
   then the weaker evidence.
2. An ambiguous pair (several distinct placements verify) is decided by loops through a third
   map: when exactly one of its placements closes loops with the other two pairs (accepted
   pairs first; then witnesses too), it is taken.
3. A maximum spanning tree, grown from the reference map, chains the placements; a link's weight
   is its evidence (agreeing wall cells net of misfits, :meth:`Check.evidence`).
4. Every two placed maps are then checked against each other directly; a pair of placed maps
   that overlaps but disagrees (even after a refinement within the loop tolerance, which
   absorbs the small errors a chain accumulates) reveals a wrong link, and the weakest link of
   the tree path between them is cut (the maps beyond it are left out unless another path
   places them).
5. Optionally (``pose_graph``, on by default) the placements are adjusted by least squares over
   every accepted link consistent with them, so that loops share out the links' small errors.
6. Maps left out that link among themselves form groups, each placed by steps 3-5 in the frame
   of its first map; they are not merged into the reference's map but kept, group by group.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from .candidates import boxes_apart
from ...transform import Transform2D
from ._config import ConsensusConfig
from ._verify import displacement
from ._verify import refine_icp, verify

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
    groups : tuple of (int or None)
        Per map, its group: 0 for the reference's (the placed maps), 1, 2, ... for groups of
        maps linked among themselves but not to the reference's (largest first), None for a
        map linked to no other.
    group_transforms : tuple of (Transform2D or None)
        Per map of a group other than 0, its frame -> the frame of its group's first map (the
        lowest index); None otherwise.
    group_confidences : tuple of float
        Per map of such a group, the confidence of the link that placed it in the group.
    group_trees : tuple of tuple
        Per group 1, 2, ..., its links ``(parent, child)`` in placing order.
    rivals : tuple of tuple
        Per map left out as ambiguous, its rival placements ``(transform into the reference's
        frame, confidence)`` through the placed maps it fits in several places.
    """

    transforms: tuple
    confidences: tuple
    tree: tuple
    dropped: tuple
    resolved: tuple
    reasons: tuple
    groups: tuple = ()
    group_transforms: tuple = ()
    group_confidences: tuple = ()
    group_trees: tuple = ()
    rivals: tuple = ()


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


def _witnessed(witness: dict, i: int, j: int):
    """``[(transform j -> i, "witness")]`` when ``(i, j)`` is a witness pair, else ``[]``."""
    e = _edge(witness, i, j)
    return [] if e is None else [(e[0], "witness")]


def solve_graph(pairs: dict, indexes: list, reference: int, cfg: ConsensusConfig,
                boxes: list, names=None) -> GraphResult:
    """Place every map in the reference's frame from the pairwise results ``pairs``
    (``(i, j) -> PairResult`` for ``i < j``, transforms j -> i); the reasons call map ``k``
    ``names[k]`` (default: "map k+1 of those given")."""
    n = len(indexes)
    label = (lambda k: names[k]) if names is not None else (lambda k: f"map {k + 1} of those given")
    res = indexes[reference].resolution
    tol = cfg.loop_cells * res
    # weight: the evidence of the placement (agreeing walls net of misfits)
    edges = {(p.a, p.b): (p.transform, p.confidence, p.best.rank)
             for p in pairs.values() if p.accepted}
    ambiguous = {(p.a, p.b): p.plausible for p in pairs.values() if p.ambiguous}
    # options of ambiguous pairs whose meeting walls all run one way: a loop may not place them
    sliding = {(p.a, p.b): {m for m, s in enumerate(p.diagnostics.get("sliding", ())) if s}
               for p in pairs.values() if p.ambiguous}
    # witnesses: pairs whose best placement is meaningful (fewer than one false alarm
    # expected, and no distinct placement nearly as good) without reaching the risk accepted;
    # they never place a map, but they may break ties between loops. A pair with a rival is no
    # witness: in rows of identical rooms its best placement may be one room off, and a loop
    # through it would confirm the same room's alias in the pair it is meant to decide
    witness = {(p.a, p.b): (p.transform, p.confidence, p.best.rank)
               for p in pairs.values()
               if not p.accepted and not p.ambiguous and p.best is not None and p.nfa <= 1.0
               and not p.diagnostics.get("rivals") and not p.diagnostics.get("slides")}
    dropped: list = []
    resolved: list = []
    # the pairs found ambiguous by the pair stage (not those step 0 demotes, which failed every
    # loop with the accepted pairs) break ties in step 1: their placements k -> i that do not slide
    found_ambiguous = dict(ambiguous)

    def several_places(i, k) -> list:
        slide = sliding.get((i, k) if (i, k) in found_ambiguous else (k, i), set())
        return [t for t, m in _options({}, found_ambiguous, i, k) if m not in slide]

    def consistent(i, j, k, tij, tjk, tik) -> bool:
        return displacement(tij @ tjk, tik, boxes[k]) <= tol

    # 0. a map that fits another map in several places about equally well (an ambiguous pair)
    #    has repeated structure: a single fit of it elsewhere that is not clearly stronger than
    #    those may be one more alias, so it must be confirmed by a loop before it is used
    repeated: dict = {}
    for (i, j), cands in ambiguous.items():
        q = max(c.rank for c in cands)
        for k in (i, j):
            repeated[k] = max(repeated.get(k, 0.0), q)
    doubtful = {e for e, (_, _, w) in edges.items()
                if max(repeated.get(e[0], 0.0), repeated.get(e[1], 0.0)) >= cfg.rival * w}
    demoted = []
    for (i, j) in sorted(doubtful):
        confirmed = False
        for k in range(n):
            if k in (i, j):
                continue
            # the other two pairs: accepted, or at most one of them ambiguous (one of its options)
            for t_ik, key_ik in _options(edges, ambiguous, i, k) or _witnessed(witness, i, k):
                for t_kj, key_kj in _options(edges, ambiguous, k, j) or _witnessed(witness, k, j):
                    if isinstance(key_ik, int) and isinstance(key_kj, int):
                        continue                       # two ambiguous pairs prove nothing
                    if consistent(i, k, j, t_ik, t_kj, edges[(i, j)][0]):
                        confirmed = True
        if not confirmed:
            demoted.append((i, j))
    for (i, j) in demoted:
        p = pairs[(i, j)]
        ambiguous[(i, j)] = p.plausible or (p.best,)
        del edges[(i, j)]
        dropped.append((i, j))

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
        # ties are broken by loops through a witness: a pair whose placement verified well but
        # did not gather enough evidence to be accepted on its own (too small an overlap)
        hint = {e: 0 for e in worst}
        for (i, j) in worst:
            for k in range(n):
                if k in (i, j):
                    continue
                wik, ekj = _edge(witness, i, k), _edge(edges, k, j)
                eik, wkj = _edge(edges, i, k), _edge(witness, k, j)
                for a, b in ((wik, ekj), (eik, wkj)):
                    if a is not None and b is not None:
                        hint[(i, j)] += 1 if consistent(i, k, j, a[0], b[0], edges[(i, j)][0]) else -1
                # and loops through a pair that fits in several places, closed when one of its
                # placements is where the accepted pair and the pair in doubt put it: in rows of
                # racks a placement one period off overlaps more than the truth, and the weaker
                # evidence alone would drop the truth (a pair whose places close loops with each
                # pair in doubt adds as much to each, and decides nothing)
                tij = edges[(i, j)][0]
                if ekj is not None and (opts := several_places(i, k)):
                    hint[(i, j)] += 1 if any(consistent(i, k, j, t, ekj[0], tij) for t in opts) else -1
                if eik is not None and (opts := several_places(k, j)):
                    hint[(i, j)] += 1 if any(consistent(i, k, j, eik[0], t, tij) for t in opts) else -1
        e = min(worst, key=lambda e: (good[e] - bad[e], hint[e], edges[e][2]))
        dropped.append(e)
        del edges[e]

    # 2. ambiguous pairs decided by loops through a third map: first through accepted pairs
    #    only, then also through witnesses
    def link(i, k, with_witness):
        e = _edge(edges, i, k)
        if e is None and with_witness and (i, k) not in ambiguous and (k, i) not in ambiguous:
            e = _edge(witness, i, k)
        return None if e is None else e[0]

    for with_witness in (False, True):
        changed = True
        while changed and ambiguous:
            changed = False
            for (i, j), cands in list(ambiguous.items()):
                closing = set()
                for k in range(n):
                    if k in (i, j):
                        continue
                    tik, tkj = link(i, k, with_witness), link(k, j, with_witness)
                    if tik is None or tkj is None:
                        continue
                    for m, c in enumerate(cands):
                        if consistent(i, k, j, tik, tkj, c.transform):
                            closing.add(m)
                if len(closing) == 1 and not closing <= sliding.get((i, j), set()):
                    m = closing.pop()
                    edges[(i, j)] = (cands[m].transform, cands[m].confidence, cands[m].rank)
                    del ambiguous[(i, j)]
                    witness.pop((i, j), None)
                    resolved.append((i, j))
                    changed = True

    # 3. maximum spanning tree from the reference, then 4. cross checks of the placed maps
    transforms, conf, tree = _place_group(reference, edges, indexes, cfg, boxes, tol, dropped)
    if cfg.pose_graph:
        transforms = _pose_graph(transforms, edges, boxes, reference, tol)

    # 6. maps that link among themselves but not to the reference's group form groups of their
    #    own, each placed the same way in the frame of its first map (lowest input index)
    found = []
    remaining = [k for k in range(n) if transforms[k] is None]
    while remaining:
        root = remaining[0]
        t_g, c_g, tree_g = _place_group(root, edges, indexes, cfg, boxes, tol, dropped,
                                        exclude={k for k in range(n) if transforms[k] is not None})
        members = [k for k in range(n) if t_g[k] is not None]
        remaining = [k for k in remaining if k not in members]
        if len(members) >= 2:
            if cfg.pose_graph:
                t_g = _pose_graph(t_g, edges, boxes, root, tol)
            found.append((members, t_g, c_g, tree_g))
    found.sort(key=lambda g: (-len(g[0]), g[0][0]))
    group = [0 if transforms[k] is not None else None for k in range(n)]
    group_transforms: list = [None] * n
    group_conf = [0.0] * n
    group_trees = []
    for number, (members, t_g, c_g, tree_g) in enumerate(found, start=1):
        for k in members:
            group[k] = number
            group_transforms[k] = t_g[k]
            group_conf[k] = c_g[k]
        group_trees.append(tuple(tree_g))

    # the rival placements of a map left out for ambiguity, in the reference's frame (through
    # each placed map it fits in several places)
    rivals: list = [() for _ in range(n)]
    for k in range(n):
        if transforms[k] is not None:
            continue
        found = []
        for p in pairs.values():
            if not p.ambiguous or k not in (p.a, p.b):
                continue
            other = p.b if k == p.a else p.a
            if transforms[other] is None:
                continue
            for c in p.plausible:
                t = c.transform if k == p.b else c.transform.inverse     # k -> other
                found.append((transforms[other] @ t, c.confidence))
        rivals[k] = tuple(sorted(found, key=lambda tc: -tc[1])[:8])

    reasons = []
    for k in range(n):
        if transforms[k] is not None:
            reasons.append("")
            continue
        mine = [p for p in pairs.values() if k in (p.a, p.b)]
        if group[k] is not None:
            root = min(m for m in range(n) if group[m] == group[k])
            others = len([m for m in range(n) if group[m] == group[k]]) - 1
            frame = ("its own frame (the group's first map)" if root == k else
                     f"the frame of the group's first map, {label(root)}")
            reasons.append(f"no confident link joins it to the reference's maps; it is kept in "
                           f"group {group[k]} with {others} other map{'s' if others != 1 else ''}, "
                           f"fused in {frame}")
        elif any(k in e for e in demoted if e not in edges):
            reasons.append("its structure repeats (it fits another map in several places) and no "
                           "loop through a third map confirms its one fit")
        elif any(p.ambiguous for p in mine):
            shown = "; ".join(f"({t.x:.2f} m, {t.y:.2f} m, {math.degrees(t.theta):.1f} deg)"
                              for t, _ in rivals[k][:4])
            reasons.append("ambiguous: several placements fit and no loop through a third map decides"
                           + (f"; rival placements in the reference frame: {shown}" if shown else ""))
        elif any(k in e for e in dropped):
            reasons.append("its only confident links disagree with the other maps")
        elif any(p.accepted for p in mine):
            reasons.append("its confident links reach other maps but none of them links to the "
                           "reference map")
        else:
            # the reason of the pair the test found surest (its confidence may have been
            # lowered since: a placement that may slide)
            best = min(mine, key=lambda p: p.nfa, default=None)
            if best is not None and best.reason:
                other = best.b if best.a == k else best.a
                # with three maps or more, which pair the words are about
                reasons.append(best.reason if n == 2 else
                               f"{best.reason} (against {label(other)}, its surest pair)")
            else:
                reasons.append("no confident placement against any other map")
    return GraphResult(tuple(transforms), tuple(float(c) for c in conf), tuple(tree),
                       tuple(dropped), tuple(resolved), tuple(reasons), tuple(group),
                       tuple(group_transforms), tuple(float(c) for c in group_conf),
                       tuple(group_trees), tuple(rivals))


def _place_group(root: int, edges: dict, indexes: list, cfg: ConsensusConfig, boxes: list,
                 tol: float, dropped: list, exclude=frozenset()):
    """Maximum spanning tree of the accepted links grown from ``root`` (maps in ``exclude``
    are never reached), then every two maps it placed checked against each other; a pair
    that disagrees cuts the weakest link of the tree path between them (removed from
    ``edges``, added to ``dropped``) and the tree is grown again.

    Returns the transforms into ``root``'s frame (None for maps not reached), the confidences
    of the links that placed them and the tree ``(parent, child)`` in placing order."""
    n = len(indexes)
    while True:
        transforms = [None] * n
        conf = [0.0] * n
        parent = [-1] * n
        transforms[root] = Transform2D.identity()
        conf[root] = 1.0
        tree = []
        while True:
            best = None
            for (i, j), (t, c, w) in edges.items():
                for p, q in ((i, j), (j, i)):
                    if transforms[p] is not None and transforms[q] is None and q not in exclude:
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
                if boxes_apart(boxes[a], boxes[b], t_ba, 3 * indexes[a].resolution):
                    continue                               # no common cell: nothing to disagree on
                chk = _cross_check(indexes[a], indexes[b], t_ba, cfg, boxes[b], tol)
                if chk is not None and (worst is None or chk.score < worst[0]):
                    worst = (chk.score, a, b)
            if worst is not None:
                _, a, b = worst
                path = _tree_path(parent, a, b)
                cut = min(path, key=lambda e: _edge(edges, *e)[2])
        if cut is None:
            return transforms, conf, tree
        key = cut if cut in edges else (cut[1], cut[0])
        dropped.append(key)
        del edges[key]


def _pose_graph(transforms: list, edges: dict, boxes: list, reference: int, tol: float) -> list:
    """Least-squares placement of the placed maps over every accepted link that agrees with
    the tree (within the loop tolerance).

    Each link ``(i, j)`` measures map j in map i's frame; its residual is how far the four
    corners of map j's known area land from where the link puts them (m), weighted by the
    square root of the link's evidence. With one link per map (a tree) the placement does not
    change; with loops the small errors of the links are spread over them instead of piling up
    along a chain.
    """
    placed = [k for k in range(len(transforms)) if transforms[k] is not None and k != reference]
    links = []
    for (i, j), (t, _, w) in edges.items():
        if transforms[i] is None or transforms[j] is None or w <= 0:
            continue
        pred = transforms[i].inverse @ transforms[j]
        if displacement(pred, t, boxes[j]) <= tol:
            links.append((i, j, t, math.sqrt(w)))
    if not placed or len(links) <= len(placed):
        return transforms
    index = {k: n for n, k in enumerate(placed)}
    x0 = np.array([[transforms[k].x, transforms[k].y, transforms[k].theta] for k in placed]).ravel()

    def pose(x, k):
        if k == reference:
            return transforms[reference]
        v = x[3 * index[k]: 3 * index[k] + 3]
        return Transform2D(v[0], v[1], v[2])

    def residuals(x):
        out = []
        for i, j, t, w in links:
            pred = pose(x, i).inverse @ pose(x, j)
            out.append(w * (pred(boxes[j]) - t(boxes[j])).ravel())
        return np.concatenate(out)

    sol = least_squares(residuals, x0, method="lm" if len(links) * 8 >= x0.size else "trf")
    if not sol.success:
        return transforms
    out = list(transforms)
    for k in placed:
        out[k] = pose(sol.x, k)
    return out


def _disagrees(chk, cfg: ConsensusConfig) -> bool:
    """Two placed maps disagree when, where each knows the other's area, their walls miss more
    than they meet (conflicts on open floor counted thrice, :meth:`Check.evidence`) by more
    than three times the counting noise of the cells compared."""
    counted = chk.agreeing + chk.disagreeing
    return counted > 0 and chk.evidence() < -3.0 * math.sqrt(counted)


def _cross_check(a, b, t_ba: Transform2D, cfg: ConsensusConfig, box_b, tol: float):
    """The :class:`Check` of two placed maps when they disagree, else None.

    Placed through a chain, two maps carry the small errors of every link; they are let
    off when a short refinement (within the loop tolerance) makes them agree. Walls meeting
    walls count whichever room they were seen from: two maps placed through a third often
    share only the edges of their areas, where each knows little of the other's rooms, and a
    wrong link shows as walls on open floor, which this counts in full.
    """
    chk = verify(a, b, t_ba, sides=False)
    if not _disagrees(chk, cfg):
        return None
    t2 = refine_icp(a, b.refine_points, t_ba, gates=(4.0, 3.0, 2.0))
    if displacement(t2, t_ba, box_b) <= tol and not _disagrees(verify(a, b, t2, sides=False), cfg):
        return None
    return chk


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
