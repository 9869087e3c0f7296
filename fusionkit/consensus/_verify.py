"""Refining a hypothesis on the whole maps and checking it.

Refiners
--------
* :func:`refine_pso`: the paper's swarm (eq. 3's MSE between a softened raster of A's walls and
  B's wall points moved by eq. 4), started on the hypothesis and searching only a small box
  around it: a refiner, not a blind search.
* :func:`refine_icp`: iterative closest points on the grid: each of B's wall points is paired
  with the nearest wall cell of A (read from A's distance transform) when closer than a
  shrinking gate, and the rigid motion that best fits the pairs (least squares, closed form) is
  applied, until it stops moving.

Verification
------------
:func:`verify` moves each map's wall cells into the other and counts, on the other's known
cells, those within one cell of a wall (agreement) and those on clear free space, at least
three cells from any wall (conflict). A right placement agrees nearly everywhere both maps are
known; a wrong one draws walls across the other map's open floor.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..alignment import make_field, mse_cost
from ..pso import PSOConfig, pso_minimize
from ..transform import Transform2D
from ._index import MapIndex

__all__ = ["rigid_fit", "refine_icp", "refine_pso", "Check", "verify"]


def rigid_fit(src: np.ndarray, dst: np.ndarray) -> Transform2D:
    """The rigid motion ``T`` minimising ``sum |T(src_k) - dst_k|^2`` (closed form, 2-D Kabsch)."""
    ms, md = src.mean(axis=0), dst.mean(axis=0)
    s, d = src - ms, dst - md
    num = float((s[:, 0] * d[:, 1] - s[:, 1] * d[:, 0]).sum())
    den = float((s[:, 0] * d[:, 0] + s[:, 1] * d[:, 1]).sum())
    th = math.atan2(num, den)
    c, sn = math.cos(th), math.sin(th)
    return Transform2D(md[0] - (c * ms[0] - sn * ms[1]), md[1] - (sn * ms[0] + c * ms[1]), th)


def refine_icp(a: MapIndex, points_b: np.ndarray, start: Transform2D, *,
               gates=(8.0, 5.0, 3.0, 2.0), iterations: int = 8) -> Transform2D:
    """Iterative closest points from ``start`` (B -> A) with pairs read off A's distance field.

    ``gates`` are the successive pairing distances (cells), each used for up to ``iterations``
    steps (fewer when the motion stops changing).
    """
    t = start
    res = a.resolution
    for gate in gates:
        for _ in range(iterations):
            q = t(points_b)
            ri, ci, inside = a.cells(q)
            ri, ci = ri[inside], ci[inside]
            src = points_b[inside]
            d = a.dist[ri, ci]
            ok = d <= gate
            if ok.sum() < 10:
                return t
            nr = a.nearest[0, ri[ok], ci[ok]]
            nc = a.nearest[1, ri[ok], ci[ok]]
            dst = a.grid.cell_to_world(nr, nc)
            new = rigid_fit(src[ok], dst)
            dt, dr = new.error_to(t)
            t = new
            if dt < 0.05 * res and dr < 1e-4:
                break
    return t


def refine_pso(a_points: np.ndarray, points_b: np.ndarray, start: Transform2D, resolution: float, *,
               half_width: float = 0.6, half_angle: float = math.radians(6.0),
               config: PSOConfig = PSOConfig(particles=24, iterations=30, patience=8),
               seed=0, field=None) -> Transform2D:
    """The swarm of eq. 3 in a box of ``+-half_width`` m and ``+-half_angle`` rad around
    ``start``. The box is expressed in eq. 4's ``(dx, dy, dphi)``; ``field`` may pass a
    prebuilt softened raster of ``a_points``."""
    fld = field if field is not None else make_field(a_points, resolution, sigma=1.0)
    dx, dy, dphi = start.to_paper()
    bounds = np.array([[dx - half_width, dx + half_width], [dy - half_width, dy + half_width],
                       [dphi - half_angle, dphi + half_angle]])
    init = np.array([[dx, dy, dphi]])

    def objective(params):
        return mse_cost(fld, points_b, params)                 # eq. 3

    res = pso_minimize(objective, bounds, config=config, seed=seed, init=init)
    return Transform2D.from_paper(*(float(v) for v in res.x))  # eq. 4


@dataclass(frozen=True)
class Check:
    """How two maps agree under a transform B -> A.

    Attributes
    ----------
    score : float
        The smaller of the two directions' agreement fractions (of a map's wall cells landing on
        the other's known cells, the fraction within one cell of the other's walls).
    agree_ab, agree_ba : float
        Those fractions for B's walls in A and A's walls in B.
    overlap : int
        The smaller of the two counts of wall cells landing on the other's known cells.
    conflicts : int
        Wall cells (both directions) on the other map's clear free space.
    conflict_fraction : float
        ``conflicts`` over the wall cells counted in both directions.
    """

    score: float
    agree_ab: float
    agree_ba: float
    overlap: int
    conflicts: int
    conflict_fraction: float

    def as_dict(self) -> dict:
        return {"score": round(self.score, 4), "agree_ab": round(self.agree_ab, 4),
                "agree_ba": round(self.agree_ba, 4), "overlap": self.overlap,
                "conflicts": self.conflicts, "conflict_fraction": round(self.conflict_fraction, 4)}


def _one_way(a: MapIndex, points_b: np.ndarray, t: Transform2D) -> tuple[int, int, int]:
    """(on A's known cells or beside its walls, beside A's walls, on A's clear free space)
    for B's walls moved by t."""
    ri, ci, inside = a.cells(t(points_b))
    ri, ci = ri[inside], ci[inside]
    near_cells = a.near[ri, ci]
    n = int((a.known[ri, ci] | near_cells).sum())
    near = int(near_cells.sum())
    bad = int(a.clear[ri, ci].sum())
    return n, near, bad


def verify(a: MapIndex, b: MapIndex, t: Transform2D) -> Check:
    """Check the transform ``t`` (B's frame -> A's frame) on both maps' walls."""
    n_ab, near_ab, bad_ab = _one_way(a, b.points, t)
    n_ba, near_ba, bad_ba = _one_way(b, a.points, t.inverse)
    f_ab = near_ab / n_ab if n_ab else 0.0
    f_ba = near_ba / n_ba if n_ba else 0.0
    total = n_ab + n_ba
    return Check(min(f_ab, f_ba), f_ab, f_ba, min(n_ab, n_ba), bad_ab + bad_ba,
                 (bad_ab + bad_ba) / total if total else 1.0)
