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
    sides : (K, 2) float64
        Per wall point, a point ``side_cells`` cells from it towards the free space it was seen
        from (m, map frame): the room in front of that wall (:func:`free_sides`).
    sided : (K,) bool
        Whether that wall point was seen from one side only (free space on one side of it,
        none on the other); a wall with free space on both sides, or none, has no side.
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
    sides: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    sided: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
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


#: Half-width (cells) of the window the free side of a wall cell is judged in.
SIDE_WINDOW = 5
#: Least asymmetry of the free space around a wall cell (the mean offset of the free cells in
#: the window, over its largest value, free space filling one half) for it to have a side.
SIDE_ASYMMETRY = 0.25


def free_sides(free: np.ndarray, rows: np.ndarray, cols: np.ndarray, side_cells: float = 3.0
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For wall cells ``(rows, cols)``, the offset (cells, ``(d_col, d_row)``) ``side_cells``
    long towards the free space around each (the sum of the offsets of the free cells in a
    ``2 SIDE_WINDOW + 1`` square window), and whether that free space lies clearly on one side
    (a wall seen from one side: the room in front of it); and whether any free cell is in the
    window at all."""
    w = SIDE_WINDOW
    k = np.arange(-w, w + 1, dtype=np.float32)
    kx = np.tile(k, (2 * w + 1, 1))                      # column offset of each window cell
    f = free.astype(np.float32)
    border = cv2.BORDER_CONSTANT
    vx = cv2.filter2D(f, -1, kx, borderType=border)[rows, cols]
    vy = cv2.filter2D(f, -1, np.ascontiguousarray(kx.T), borderType=border)[rows, cols]
    # free space filling exactly one half of the window gives the largest mean offset
    full = float(np.abs(k).sum() * (2 * w + 1)) / 2.0
    # the sums are whole numbers; the norm by correctly rounded operations alone (numpy's
    # vector hypot rounds otherwise on another CPU)
    norm = np.sqrt(vx * vx + vy * vy)
    sided = norm >= SIDE_ASYMMETRY * full
    scale = np.where(norm > 0, side_cells / np.maximum(norm, 1e-9), 0.0)
    seen = cv2.boxFilter(f, -1, (2 * w + 1, 2 * w + 1), normalize=False, borderType=border)[rows, cols] > 0
    return np.stack([vx * scale, vy * scale], axis=1).astype(np.float64), sided, seen


def _wall_sides(tri: OccupancyGrid, free: np.ndarray, r: np.ndarray, c: np.ndarray,
                side_cells: float) -> tuple[np.ndarray, np.ndarray]:
    """Per wall cell ``(r, c)``, the point (m) in front of it and whether it has one
    (:attr:`MapIndex.sides`): from :func:`free_sides`; a cell deep inside a thick wall, with no
    free space in its window, takes the point of the nearest wall cell that has one, within
    ``2 SIDE_WINDOW`` cells."""
    offsets, sided, seen = free_sides(free, r, c, side_cells)
    sides = tri.cell_to_world(r + offsets[:, 1], c + offsets[:, 0])
    if len(r) and sided.any() and not seen.all():
        mask = np.zeros(free.shape, bool)
        mask[r[sided], c[sided]] = True
        dist, nearest = _nearest_walls(mask, (r[sided], c[sided]))
        number = np.full(free.shape, -1, np.int64)
        number[r, c] = np.arange(len(r))
        inner = np.nonzero(~seen & (dist[r, c] <= 2 * SIDE_WINDOW))[0]
        src = number[nearest[0, r[inner], c[inner]], nearest[1, r[inner], c[inner]]]
        sides[inner] = sides[src]
        sided = sided.copy()
        sided[inner] = True
    return np.ascontiguousarray(sides), sided


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


#: Unknown cells kept around a map's known ones by :func:`_trimmed`: more than the widest gate
#: of the refinement (8 cells), so that no wall a refinement or a check can reach is cut off
TRIM_MARGIN = 10


def _trimmed(grid: OccupancyGrid) -> OccupancyGrid:
    """``grid`` cut to the bounding box of its known cells and :data:`TRIM_MARGIN` cells around
    it, in the same frame (its origin moved with the cut); ``grid`` itself when nothing is cut.
    A map saved with a wide unknown margin (map_saver's 4000 x 4000 cells) was searched on a
    raster sized to the whole grid, so coarse that the true placement was missed: the decision
    must not depend on how much unknown surrounds a map."""
    box = grid.known_box()
    if box is None:
        return grid
    r0, c0 = max(0, box[0] - TRIM_MARGIN), max(0, box[2] - TRIM_MARGIN)
    r1, c1 = min(grid.rows, box[1] + TRIM_MARGIN), min(grid.cols, box[3] + TRIM_MARGIN)
    if (r0, c0, r1, c1) == (0, 0, grid.rows, grid.cols):
        return grid
    x, y = grid.origin_transform(np.array([c0 * grid.resolution, r0 * grid.resolution]))
    return OccupancyGrid(grid.data[r0:r1, c0:c1], grid.resolution,
                         (float(x), float(y), grid.origin[2]), name=grid.name)


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
    tri = _trimmed(grid.with_data(grid.trinary()))
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
    sides, sided = _wall_sides(tri, free, r, c, float(clear_cells))
    if len(points) > max_refine_points:
        step = len(points) / max_refine_points
        refine = points[(np.arange(max_refine_points) * step).astype(np.int64)]
    else:
        refine = points
    if log is None or log.n_scans == 0:
        return MapIndex(tri, known, occupied, near, usable, clear, dist, nearest, points,
                        np.ascontiguousarray(refine), log, bool(virtual), np.zeros(0, np.int64),
                        np.zeros((0, 0), np.float32), np.zeros((0, 0), np.complex64),
                        np.zeros((0, 2)), sides, sided)
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
                    np.ascontiguousarray(cloud), sides, sided)
