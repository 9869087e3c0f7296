"""The N-map half of ``multirobot_map_merge`` (see :mod:`.map_merge`): OpenCV's
``leaveBiggestComponent``, ``findMaxSpanningTree``, the breadth-first chaining of
``AffineBasedEstimator`` and ``BundleAdjusterAffinePartial``, over the pairwise motions of
:func:`.map_merge.estimate_pair`'s matcher.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

__all__ = []


class _DisjointSets:
    """OpenCV ``cv::detail::DisjointSets`` (union by rank, path compression, stale sizes)."""

    def __init__(self, n: int):
        self.parent = list(range(n))
        self.rank = [0] * n
        self.size = [1] * n

    def find(self, e: int) -> int:
        s = e
        while s != self.parent[s]:
            s = self.parent[s]
        while e != self.parent[e]:
            self.parent[e], e = s, self.parent[e]
        return s

    def merge(self, s1: int, s2: int) -> int:
        if self.rank[s1] < self.rank[s2]:
            self.parent[s1] = s2
            self.size[s2] += self.size[s1]
            return s2
        if self.rank[s2] < self.rank[s1]:
            self.parent[s2] = s1
            self.size[s1] += self.size[s2]
            return s1
        self.parent[s1] = s2
        self.rank[s2] += 1
        self.size[s2] += self.size[s1]
        return s2


def _biggest_component(conf: np.ndarray, threshold: float) -> list[int]:
    """OpenCV ``leaveBiggestComponent``: indices of the largest set of maps joined by pairs of
    confidence >= ``threshold``."""
    n = conf.shape[0]
    comps = _DisjointSets(n)
    for i in range(n):
        for j in range(n):
            if conf[i, j] < threshold:
                continue
            c1, c2 = comps.find(i), comps.find(j)
            if c1 != c2:
                comps.merge(c1, c2)
    max_comp = int(np.argmax(comps.size))
    return [i for i in range(n) if comps.find(i) == max_comp]


def _max_spanning_tree(pairs: dict, n: int):
    """OpenCV ``findMaxSpanningTree`` over ``n`` maps (local indices): Kruskal on the pairs that
    have a motion, weighted by inliers. Returns (adjacency lists, centres)."""
    edges = [(float(pairs[i, j].num_inliers), i, j) for i in range(n) for j in range(n)
             if i != j and pairs[i, j].H is not None]
    edges.sort(key=lambda e: -e[0])                  # stable: ties keep (i, j) order
    comps = _DisjointSets(n)
    adj = [[] for _ in range(n)]
    power = [0] * n
    for _, i, j in edges:
        c1, c2 = comps.find(i), comps.find(j)
        if c1 != c2:
            comps.merge(c1, c2)
            adj[i].append(j)
            adj[j].append(i)
            power[i] += 1
            power[j] += 1
    leafs = [i for i in range(n) if power[i] == 1]
    max_dists = [0] * n
    for leaf in leafs:
        dist = [0] * n
        for frm, to in _bfs_edges(adj, leaf):
            dist[to] = dist[frm] + 1
        max_dists = [max(m, d) for m, d in zip(max_dists, dist)]
    best = min(max_dists)
    return adj, [i for i in range(n) if max_dists[i] == best]


def _bfs_edges(adj, start: int):
    """Tree edges ``(from, to)`` in ``Graph::walkBreadthFirst`` order."""
    seen = [False] * len(adj)
    seen[start] = True
    queue, k = [start], 0
    while k < len(queue):
        v = queue[k]
        k += 1
        for w in adj[v]:
            if not seen[w]:
                seen[w] = True
                queue.append(w)
                yield v, w


def _chain(pairs: dict, n: int, shipped: bool):
    """``AffineBasedEstimator``: cameras ``R_k`` (3x3, reference image -> image k) chained
    breadth-first over the maximum spanning tree from its first centre.

    Returns (cameras, centre, tree edges (from, to) in chaining order), local indices."""
    adj, centres = _max_spanning_tree(pairs, n)
    centre = centres[0]
    cams = [np.eye(3) for _ in range(n)]
    tree = []
    for frm, to in _bfs_edges(adj, centre):
        h = pairs[frm, to].H
        # shipped (CalcAffineTransform): R_to = R_from H; corrected: R_to = H R_from
        cams[to] = cams[frm] @ h if shipped else h @ cams[frm]
        tree.append((frm, to))
    return cams, centre, tree


def _sim_params(m: np.ndarray) -> np.ndarray:
    return np.array([m[0, 0], m[1, 0], m[0, 2], m[1, 2]])


def _sim_matrix(p) -> np.ndarray:
    return np.array([[p[0], -p[1], p[2]], [p[1], p[0], p[3]], [0.0, 0.0, 1.0]])


def _bundle_adjust(cams, feats, pairs, conf_thresh: float, shipped: bool):
    """``BundleAdjusterAffinePartial``: refine the four similarity parameters of every map on the
    inlier matches of the pairs whose confidence exceeds ``conf_thresh``.

    With cameras ``R_k`` mapping the reference frame into image k, a match ``(p_i, p_j)``
    predicts ``p_j = R_j R_i^-1 p_i``; OpenCV predicts ``R_i^-1 R_j p_i`` (``shipped``)."""
    n = len(cams)
    obs = []
    for i in range(n - 1):
        for j in range(i + 1, n):
            p = pairs[i, j]
            if p.confidence > conf_thresh and p.num_inliers:
                m = p.matches[p.inliers]
                obs.append((i, j, feats[i].points[m[:, 0]].astype(float),
                            feats[j].points[m[:, 1]].astype(float)))
    if not obs:
        return cams

    # Moving every map together changes no residual (a free gauge): left free, the solver
    # wanders along it and the last digits of its input decide where it stops. The map the
    # chain started from (at identity) is held where it is, as the result is renormalised to it.
    fixed = next((k for k, c in enumerate(cams) if np.array_equal(c, np.eye(3))), 0)
    held = _sim_params(cams[fixed])

    def params(x):
        return np.concatenate([x[:4 * fixed], held, x[4 * fixed:]])

    def residuals(x):
        x = params(x)
        out = []
        for i, j, pi, pj in obs:
            hi, hj = _sim_matrix(x[4 * i:4 * i + 4]), _sim_matrix(x[4 * j:4 * j + 4])
            h = np.linalg.inv(hi) @ hj if shipped else hj @ np.linalg.inv(hi)
            pred = pi @ h[:2, :2].T + h[:2, 2]
            out.append((pj - pred).ravel())
        return np.concatenate(out)

    x0 = np.concatenate([_sim_params(c) for k, c in enumerate(cams) if k != fixed])
    if residuals(x0).size < x0.size:   # too few equations for Levenberg-Marquardt
        return cams
    sol = least_squares(residuals, x0, method="lm", xtol=1e-12, ftol=1e-12, max_nfev=1000 * x0.size)
    if not np.all(np.isfinite(sol.x)):
        return cams
    x = params(sol.x)
    return [_sim_matrix(x[4 * k:4 * k + 4]) for k in range(n)]
