"""The last refinement of a placement the search found: walls paired from the points themselves.

The search's ICP (:func:`~._verify.refine_icp`) pairs each of B's wall points with the wall
nearest the *centre of the cell* it falls in, read off A's distance transform. That is fast and
right to within a cell, which is all the search and the test need, but it is biased: on walls
that do not run along A's cell axes (a map turned by any angle) the nearest wall of a cell's
centre is often one of two at equal distance, and the distance transform settles such ties the
same way everywhere. Measured on crops of real floors turned at random, ICP started at the true
placement ends 0.19 and 0.12 cells off it on average along A's two axes, every pair the same way
(``benchmarks/placement_bias.py``).

Here each point is paired with the nearest of the walls that the four cells around it name,
measured from the point itself; ties between them have no preferred side, and the pairing
follows the point within its cell. It costs four look-ups a point instead of one, so it runs once
a pair, on the placements the search keeps, after the test has judged them: it moves a placement
by a fraction of a cell and never changes what was decided.
"""

from __future__ import annotations

import math

import numpy as np

from ..._jit import njit
from ...transform import Transform2D
from ._index import MapIndex
from ._verify import _fit_pairs, _from_cells, _gated, _in_cells, _to_cells

__all__ = ["polish", "POLISH_GATES", "POLISH_LIMIT"]

#: Pairing distances (cells) of the two stages of the polish.
POLISH_GATES = (2.0, 1.5)
#: A polish that would move B's walls by more than this many cells (typically) is not taken:
#: the placement judged is kept.
POLISH_LIMIT = 1.5


@njit
def _polish_kernel(pts, tx, ty, th, gated, near_r, near_c, gates, iterations, min_pairs):
    """ICP in A's cell frame (units: cells) pairing each of B's points ``pts`` with the nearest,
    measured from the point, of the walls nearest to the centres of the four cells around it
    (``gated``: A's distance to its nearest wall where A is usable, infinite elsewhere); the
    pairs are fitted as :func:`~._verify._icp_kernel` fits them. Returns
    ``(tx, ty, th, pairs)``."""
    rows, cols = gated.shape
    n = pts.shape[0]
    src = np.empty((n, 2))
    dst = np.empty((n, 2))
    pairs = 0
    for g in range(gates.shape[0]):
        gate2 = gates[g] * gates[g]
        for _ in range(iterations):
            c = math.cos(th)
            s = math.sin(th)
            m = 0
            for k in range(n):
                x = c * pts[k, 0] - s * pts[k, 1] + tx
                y = s * pts[k, 0] + c * pts[k, 1] + ty
                c0 = math.floor(x - 0.5)
                r0 = math.floor(y - 0.5)
                best = math.inf
                qx = 0.0
                qy = 0.0
                for dr in range(2):
                    ri = r0 + dr
                    if ri < 0 or ri >= rows:
                        continue
                    for dc in range(2):
                        ci = c0 + dc
                        if ci < 0 or ci >= cols or not gated[ri, ci] < math.inf:
                            continue
                        wx = near_c[ri, ci] + 0.5
                        wy = near_r[ri, ci] + 0.5
                        d2 = (wx - x) * (wx - x) + (wy - y) * (wy - y)
                        if d2 < best:
                            best = d2
                            qx = wx
                            qy = wy
                if best <= gate2:
                    src[m, 0] = pts[k, 0]
                    src[m, 1] = pts[k, 1]
                    dst[m, 0] = qx
                    dst[m, 1] = qy
                    m += 1
            pairs = m
            if m < min_pairs:
                return tx, ty, th, m
            tx, ty, th, moved, turned = _fit_pairs(src, dst, m, tx, ty, th)
            if moved < 0.01 and turned < 1e-5:
                break
    return tx, ty, th, pairs


def polish(a: MapIndex, b: MapIndex, t: Transform2D, *, gates=POLISH_GATES,
           iterations: int = 8, limit: float = POLISH_LIMIT) -> Transform2D:
    """``t`` (B -> A) refined on B's wall points paired from the points themselves (see the
    module notes); ``t`` itself when fewer than ten walls pair or the polish would move B's
    walls by more than ``limit`` cells (the root mean square over the points)."""
    pts = _in_cells(b, b.refine_points, a.resolution)
    if len(pts) < 10:
        return t
    cx, cy, cth = _to_cells(a, t)
    near = a.nearest
    tx, ty, th, pairs = _polish_kernel(pts, cx, cy, cth, _gated(a), near[0], near[1],
                                       np.asarray(gates, np.float64), int(iterations), 10)
    if pairs < 10:
        return t
    out = _from_cells(a, float(tx), float(ty), float(th))
    moved = out(b.refine_points) - t(b.refine_points)
    if math.sqrt(float((moved * moved).sum(axis=1).mean())) > limit * a.resolution:
        return t
    return out
