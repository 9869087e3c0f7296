"""Slow, obvious reference implementations for the simulator's kernels.

The ray caster is checked against a different algorithm: for every beam, the entry distance of
the ray into *each* blocking cell's square (the slab method), the nearest one winning.
"""

from __future__ import annotations

import numpy as np


def slab_ranges(world, poses, angles, max_range):
    """Exact ranges (m) of beams from world-frame ``poses`` (N, 3) at ``angles`` (B,) (rad)
    through ``world``: distance to the entry point of the nearest occupied cell; ``inf`` when it
    is beyond ``max_range`` or there is none. Returns (N, B) float64."""
    res = world.resolution
    local = world.origin_transform.inverse.apply_pose(np.asarray(poses, float))
    rr, cc = np.nonzero(world.occupied_mask())
    max_cells = max_range / res
    out = np.full((len(local), len(angles)), np.inf)
    for i, (x, y, th) in enumerate(local):
        px, py = x / res, y / res
        near = np.hypot(cc + 0.5 - px, rr + 0.5 - py) <= max_cells + 1.0
        c0, r0 = cc[near].astype(float), rr[near].astype(float)
        a = th + np.asarray(angles, float)
        dx, dy = np.cos(a)[:, None], np.sin(a)[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            tx1, tx2 = (c0 - px) / dx, (c0 + 1 - px) / dx
            ty1, ty2 = (r0 - py) / dy, (r0 + 1 - py) / dy
        t_in = np.maximum(np.minimum(tx1, tx2), np.minimum(ty1, ty2))
        t_out = np.minimum(np.maximum(tx1, tx2), np.maximum(ty1, ty2))
        t = np.where((t_in <= t_out) & (t_out > 0), np.maximum(t_in, 0.0), np.inf)
        if t.shape[1] == 0:
            continue
        j = np.argmin(t, axis=1)
        best = t[np.arange(len(a)), j]
        ok = np.isfinite(best) & (best <= max_cells)
        out[i] = np.where(ok, best * res, np.inf)
    return out
