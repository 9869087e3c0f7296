"""Virtual scans for maps that come without recorded scans.

A map saved by any SLAM package carries no scans, but the method compares scans. fusionkit
samples poses in the map's free space, away from walls, orders them into a path (a greedy
nearest-neighbour tour, so that Algorithm 1's sections hold neighbouring poses, as along a real
trajectory), and casts beams from each through the map.

Occupied *and unknown* cells return the beam. A robot's map has gaps in its walls (grazing
beams, glass, doors seen ajar) and unexplored space behind them; a real beam through such a gap
would have met the wall behind it, a cell or two further on, and returning the beam at the first
unknown cell reproduces that. Letting unknown cells swallow the beam instead makes two maps of
the same place give very different scans: on two simulated office robots, the 300 most
correlated virtual-scan pairs held 11 true correspondences (within 1 m and 5 degrees) that way,
against 146 with unknown returning the beam.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from .errors import InputError
from .grid import OccupancyGrid
from .raycast import cast_rays
from .scanlog import ScanLog

__all__ = ["virtual_scans", "sample_free_poses"]


def sample_free_poses(grid: OccupancyGrid, n_poses: int, *, clearance: float = 0.3,
                      seed=0) -> np.ndarray:
    """Up to ``n_poses`` poses (x, y, theta in the map frame) in free cells at least
    ``clearance`` m from any occupied or unknown cell, spread evenly, ordered as a path."""
    rng = np.random.default_rng(seed)
    free = grid.free_mask()
    if not free.any():
        raise InputError(f"{grid.name or 'map'}: the map has no free cells, so no place to scan from")
    dist = ndimage.distance_transform_edt(free) * grid.resolution
    ok = dist >= clearance
    if ok.sum() < 20:
        ok = dist >= min(clearance, float(dist.max()) * 0.5)
    r, c = np.nonzero(ok)
    # spread: one candidate per lattice block so that poses cover the free space evenly
    spacing = max(1, int(math.sqrt(r.size / max(n_poses, 1))))
    key = (r // spacing) * (grid.cols // spacing + 1) + (c // spacing)
    perm = rng.permutation(r.size)
    _, first = np.unique(key[perm], return_index=True)
    pick = perm[first]
    if pick.size > n_poses:
        pick = rng.choice(pick, n_poses, replace=False)
    pick = np.sort(pick)
    rr = r[pick] + rng.uniform(0.2, 0.8, pick.size)
    cc = c[pick] + rng.uniform(0.2, 0.8, pick.size)
    pts = grid.cell_to_world(rr - 0.5, cc - 0.5)
    order = _greedy_tour(pts)
    theta = rng.uniform(-math.pi, math.pi, pick.size)
    return np.column_stack([pts[order], theta])


def _greedy_tour(pts: np.ndarray) -> np.ndarray:
    """Visit order of ``pts`` by repeatedly going to the nearest unvisited point."""
    n = len(pts)
    if n == 0:
        return np.zeros(0, int)
    tree = cKDTree(pts)
    visited = np.zeros(n, bool)
    order = np.empty(n, int)
    cur = int(np.argmin(pts[:, 0] + pts[:, 1]))
    for k in range(n):
        order[k] = cur
        visited[cur] = True
        if k == n - 1:
            break
        kq = 8
        while True:
            d, idx = tree.query(pts[cur], k=min(kq, n))
            idx = np.atleast_1d(idx)
            cand = [i for i in idx if not visited[i]]
            if cand:
                cur = int(cand[0])
                break
            if kq >= n:
                cur = int(np.flatnonzero(~visited)[0])
                break
            kq *= 4
    return order


def virtual_scans(grid: OccupancyGrid, *, n_poses: int = 1500, beams: int = 360,
                  range_max: float = 8.0, clearance: float = 0.3, seed=0) -> ScanLog:
    """A 360-degree scan log cast through ``grid`` from poses sampled in its free space.

    Parameters
    ----------
    grid : OccupancyGrid
    n_poses : int
        Number of poses sampled (fewer when the free space is small).
    beams : int
        Beams per scan over 360 degrees.
    range_max : float
        Sensor range (m).
    clearance : float
        Least distance (m) of a pose from occupied or unknown cells.
    seed : int or numpy.random.Generator
    """
    if n_poses < 1 or beams < 2 or range_max <= 0:
        raise InputError("virtual scans need n_poses >= 1, beams >= 2 and range_max > 0")
    poses = sample_free_poses(grid, n_poses, clearance=clearance, seed=seed)
    blocked = (~grid.free_mask()).astype(np.uint8)      # occupied and unknown return the beam
    local = grid.origin_transform.inverse.apply_pose(poses)
    pc = np.column_stack([local[:, 0] / grid.resolution, local[:, 1] / grid.resolution, local[:, 2]])
    inc = 2 * math.pi / beams
    angles = -math.pi + inc * np.arange(beams)
    ranges = cast_rays(blocked, pc, angles, range_max / grid.resolution) * np.float32(grid.resolution)
    return ScanLog(poses, ranges, -math.pi, inc, range_max)
