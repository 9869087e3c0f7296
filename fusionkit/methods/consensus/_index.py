"""What the consensus method precomputes once per map: masks, the distance field of its walls,
its wall points and its scans' spectra.

Everything here is in the map's own frame: points in metres, rasters indexed ``[row, col]``
with row 0 the lowest ``y`` (CONTRACTS 1).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from ..._jit import njit
from ...grid import OccupancyGrid
from ...scanlog import ScanLog
from ...unique_poses import scan_spectra

__all__ = ["MapIndex", "index_map", "spread_indices", "first_per_cell"]


@dataclass(frozen=True, eq=False)
class MapIndex:
    """One map, prepared for matching, refinement and verification.

    Attributes
    ----------
    grid : OccupancyGrid
        The map reduced to its three states.
    known, occupied : (rows, cols) bool
        Known and occupied cells.
    near : (rows, cols) bool
        Cells within one cell (8-neighbourhood) of an occupied cell.
    usable : (rows, cols) uint8
        1 where the map is known or beside a wall: where another map's walls can be paired.
    clear : (rows, cols) bool
        Free cells at least ``clear_cells`` cells (Euclidean, about) from every occupied cell: a
        wall of another map drawn there contradicts this map.
    dist : (rows, cols) float32
        Distance (cells) of each cell to the nearest occupied cell.
    nearest : (2, rows, cols) int32
        ``(row, col)`` of that nearest occupied cell.
    points : (K, 2) float64
        Centres (m) of the occupied cells, in the map frame.
    refine_points : (L, 2) float64
        An even subset of ``points`` (at most ``max_refine_points``) used by the refiners.
    log : ScanLog or None
        The scans (recorded or virtual); None when the map is matched on its walls alone.
    virtual : bool
        Whether ``log`` was cast in the map rather than recorded.
    pose_index : (P,) int
        The scans used for matching: spread over the map (one per ``pose_spacing`` cell).
    spectra : (P, F) float32
        Their ``|DFT|`` spectra without DC (eq. 1), centred and scaled to unit norm, so that a dot
        product is Pearson's rho (eq. 2).
    ranges_fft : (P, B // 2 + 1) complex64
        FFT of their centred, clipped ranges over beam angle (for the relative heading).
    cloud : (C, 2) float64
        Recorded scans only: the end points of the returned beams (m, map frame), one per
        ``cloud_spacing`` square; empty for virtual or no scans.
    cache : dict
        Products computed from the map on first use (its softened wall raster, the corners of
        its known area) and kept for the map's other pairs.
    """

    grid: OccupancyGrid
    known: np.ndarray
    occupied: np.ndarray
    near: np.ndarray
    usable: np.ndarray
    clear: np.ndarray
    dist: np.ndarray
    nearest: np.ndarray
    points: np.ndarray
    refine_points: np.ndarray
    log: ScanLog | None
    virtual: bool
    pose_index: np.ndarray
    spectra: np.ndarray
    ranges_fft: np.ndarray
    cloud: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    cache: dict = field(default_factory=dict, repr=False)

    @property
    def resolution(self) -> float:
        return self.grid.resolution

    def cells(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Integer ``(rows, cols)`` of map-frame ``points`` and the mask of those on the grid."""
        rr, cc = self.grid.world_to_cell(points)
        ri = np.floor(rr).astype(np.int64)
        ci = np.floor(cc).astype(np.int64)
        inside = (ri >= 0) & (ri < self.grid.rows) & (ci >= 0) & (ci < self.grid.cols)
        return ri, ci, inside


def _nearest_walls(occupied: np.ndarray, walls: tuple | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per cell, the distance (cells) to a nearest occupied cell and that cell's ``(row, col)``.

    OpenCV's labelled distance transform (its labels number the wall pixels in raster order);
    its distances are within half a cell of the exact Euclidean ones. ``walls``: the
    ``np.nonzero(occupied)`` of the caller, when it has it.
    """
    rows, cols = occupied.shape
    if not occupied.any():
        return (np.full(occupied.shape, np.inf, np.float32), np.zeros((2, rows, cols), np.int32))
    dist, labels = cv2.distanceTransformWithLabels((~occupied).astype(np.uint8), cv2.DIST_L2,
                                                   cv2.DIST_MASK_PRECISE, labelType=cv2.DIST_LABEL_PIXEL)
    wr, wc = np.nonzero(occupied) if walls is None else walls
    nearest = np.empty((2, rows, cols), np.int32)
    _label_cells(labels, wr.astype(np.int32), wc.astype(np.int32), nearest)
    return dist, nearest


@njit
def _label_cells(labels, wr, wc, out):
    # out[:, i, j] = the (row, col) of wall pixel number labels[i, j] (1-based)
    for i in range(labels.shape[0]):
        for j in range(labels.shape[1]):
            k = labels[i, j] - 1
            out[0, i, j] = wr[k]
            out[1, i, j] = wc[k]


def first_per_cell(points: np.ndarray, spacing: float) -> np.ndarray:
    """Indices (ascending) of the first of ``points`` (m) in each ``spacing`` x ``spacing``
    square of the plane."""
    if len(points) == 0:
        return np.zeros(0, np.int64)
    key = np.floor(points[:, :2] / spacing).astype(np.int64)
    key -= key.min(axis=0)
    flat = key[:, 0] * (int(key[:, 1].max()) + 1) + key[:, 1]      # one integer per square
    size = int(flat.max()) + 1
    if size <= _FIRST_TABLE_LIMIT:
        return _first_kernel(flat, size)
    _, first = np.unique(flat, return_index=True)
    return np.sort(first)


#: Largest table (squares) :func:`first_per_cell` marks directly; beyond it, it sorts.
_FIRST_TABLE_LIMIT = 64_000_000


@njit
def _first_kernel(flat, size):
    seen = np.zeros(size, np.bool_)
    out = np.empty(flat.size, np.int64)
    m = 0
    for i in range(flat.size):
        f = flat[i]
        if not seen[f]:
            seen[f] = True
            out[m] = i
            m += 1
    return out[:m]


def spread_indices(poses: np.ndarray, spacing: float, limit: int) -> np.ndarray:
    """Indices of at most ``limit`` poses, one per ``spacing`` x ``spacing`` m cell of the
    plane (the first pose in each), then thinned evenly if still too many; ascending."""
    if len(poses) == 0:
        return np.zeros(0, np.int64)
    idx = first_per_cell(poses, spacing)
    if idx.size > limit:
        idx = idx[np.linspace(0, idx.size - 1, limit).round().astype(np.int64)]
    return idx


def index_map(grid: OccupancyGrid, log: ScanLog | None, *, virtual: bool, pose_spacing: float,
              max_poses: int, max_refine_points: int, clear_cells: int = 3,
              cloud_spacing: float = 0.05) -> MapIndex:
    """Precompute a :class:`MapIndex` for ``grid`` and its scans ``log``.

    Parameters
    ----------
    grid : OccupancyGrid
    log : ScanLog or None
        The map's scans, in its frame (None: no scans are matched).
    virtual : bool
        Whether the scans are virtual.
    pose_spacing : float
        Scans used for matching are thinned to one per square of this side (m).
    max_poses : int
        At most this many scans are used for matching.
    max_refine_points : int
        At most this many wall points are used by the refiners.
    clear_cells : int
        Least distance (cells) from a wall for a free cell to count as clear.
    cloud_spacing : float
        Side (m) of the squares the recorded scans' end points are thinned to.
    """
    tri = grid.with_data(grid.trinary())
    occupied = tri.occupied_mask()
    known = tri.known_mask()
    free = known & ~occupied
    r, c = np.nonzero(occupied)
    dist, nearest = _nearest_walls(occupied, (r, c))
    occ8 = occupied.astype(np.uint8)
    near = cv2.dilate(occ8, np.ones((3, 3), np.uint8)).astype(bool)
    reach = 2 * clear_cells - 1
    walls_close = cv2.dilate(occ8, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (reach, reach))).astype(bool)
    clear = free & ~walls_close
    usable = (known | near).astype(np.uint8)
    points = tri.cell_to_world(r, c)
    if len(points) > max_refine_points:
        step = len(points) / max_refine_points
        refine = points[(np.arange(max_refine_points) * step).astype(np.int64)]
    else:
        refine = points
    if log is None or log.n_scans == 0:
        return MapIndex(tri, known, occupied, near, usable, clear, dist, nearest, points,
                        np.ascontiguousarray(refine), log, bool(virtual), np.zeros(0, np.int64),
                        np.zeros((0, 0), np.float32), np.zeros((0, 0), np.complex64))
    idx = spread_indices(log.poses, pose_spacing, max_poses)
    ranges = log.clipped_ranges()[idx].astype(np.float64)
    spec = scan_spectra(ranges, dc=False)                      # eq. 1 without the DC bin
    spec = spec - spec.mean(axis=1, keepdims=True)
    norm = np.sqrt((spec * spec).sum(axis=1, keepdims=True))
    norm[norm == 0] = np.inf
    spec = (spec / norm).astype(np.float32)                     # dot product = Pearson (eq. 2)
    centred = ranges - ranges.mean(axis=1, keepdims=True)
    rfft = np.fft.rfft(centred, axis=1).astype(np.complex64)
    cloud = np.zeros((0, 2))
    if not virtual:
        ends = log.endpoints(spread_indices(log.poses, 0.5, 400))
        cloud = ends[first_per_cell(ends, cloud_spacing)]
    return MapIndex(tri, known, occupied, near, usable, clear, dist, nearest, points,
                    np.ascontiguousarray(refine), log, bool(virtual), idx, spec, rfft,
                    np.ascontiguousarray(cloud))
