"""What the three classic map-merging methods share: their result type, input checks and the
conversion between a grid's cell frame and its map frame.

Every method works in the *cell frame* of each grid: ``x`` along columns, ``y`` along rows, one
unit per cell, the lower-left corner of cell (0, 0) at the origin, so the centre of cell
``(r, c)`` is ``(c + 0.5, r + 0.5)``. Because row 0 is the row of lowest ``y`` (CONTRACTS 1) this
frame has the same handedness as the map frame, and the map frame is reached by scaling by the
resolution and applying the grid's origin pose.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field

import numpy as np

from ...errors import InputError
from ...grid import OCCUPIED, UNKNOWN, OccupancyGrid
from ...resample import resample
from ...transform import Transform2D

__all__ = [
    "PairEstimate", "prepare_pair", "cell_to_map", "map_to_cell", "make_options",
    "occupied_cell_centres", "acceptance_index", "Stopwatch", "CropPair", "crop_pair",
    "placement_error", "warp_cells",
]


@dataclass(frozen=True)
class PairEstimate:
    """One method's answer for a pair of maps.

    Attributes
    ----------
    transform : Transform2D or None
        Maps map B's frame into map A's frame (m, rad; CONTRACTS 4), or ``None`` when the method
        produced no hypothesis at all.
    confidence : float
        The method's own score for ``transform`` (its scale differs from method to method).
    accepted : bool
        The method's own accept decision at its default threshold.
    candidates : tuple of (Transform2D, float)
        Alternative hypotheses with their scores, best first (the first is ``transform``).
    method : str
        Name of the method.
    seconds : float
        Wall-clock time of the estimate (s).
    diagnostics : dict
        Method-specific intermediate figures (match counts, scale, peaks, ...).
    """

    transform: Transform2D | None
    confidence: float
    accepted: bool
    candidates: tuple = ()
    method: str = ""
    seconds: float = 0.0
    diagnostics: dict = field(default_factory=dict)


class Stopwatch:
    """Wall-clock seconds since construction (``time.perf_counter``)."""

    def __init__(self):
        self._t0 = time.perf_counter()

    def __call__(self) -> float:
        return time.perf_counter() - self._t0


def make_options(cls, options: dict, method: str):
    """Build the frozen options dataclass ``cls`` from keyword arguments, naming the valid keys
    when one is unknown."""
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(options) - names)
    if unknown:
        raise InputError(f"{method} has no option {unknown[0]!r}; valid options are "
                         f"{', '.join(sorted(names))}")
    return cls(**options)


def prepare_pair(a, b) -> tuple[OccupancyGrid, OccupancyGrid]:
    """Check two grids and bring B to A's resolution.

    Returns the two grids with their cells reduced to the three states (``trinary``). When the
    resolutions differ, B is resampled (nearest neighbour) onto a grid of A's resolution that
    keeps B's origin, so B's map frame, and therefore the meaning of the returned transform, is
    unchanged.

    Raises
    ------
    InputError
        If either input is not an :class:`~fusionkit.grid.OccupancyGrid`.
    """
    for name, g in (("first", a), ("second", b)):
        if not isinstance(g, OccupancyGrid):
            raise InputError(f"the {name} map must be an OccupancyGrid, got {type(g).__name__}")
    a = a.with_data(a.trinary())
    b = b.with_data(b.trinary())
    if not math.isclose(a.resolution, b.resolution, rel_tol=1e-9):
        k = b.resolution / a.resolution
        rows, cols = max(1, round(b.rows * k)), max(1, round(b.cols * k))
        target = OccupancyGrid(np.full((rows, cols), UNKNOWN, np.int8), a.resolution, b.origin)
        b = resample(b, Transform2D.identity(), target)
    return a, b


def cell_to_map(a: OccupancyGrid, b: OccupancyGrid, cell_transform: Transform2D) -> Transform2D:
    """Turn a transform from B's cell frame into A's cell frame (cells, rad) into the transform
    from B's map frame into A's map frame (m, rad). Both grids must share one resolution."""
    res = a.resolution
    local = Transform2D(cell_transform.x * res, cell_transform.y * res, cell_transform.theta)
    return a.origin_transform @ local @ b.origin_transform.inverse


def map_to_cell(a: OccupancyGrid, b: OccupancyGrid, map_transform: Transform2D) -> Transform2D:
    """Inverse of :func:`cell_to_map`: B-map -> A-map (m) into B-cells -> A-cells (cells)."""
    local = a.origin_transform.inverse @ map_transform @ b.origin_transform
    res = a.resolution
    return Transform2D(local.x / res, local.y / res, local.theta)


def occupied_cell_centres(data: np.ndarray) -> np.ndarray:
    """Cell-frame centres ``(x, y) = (col + 0.5, row + 0.5)`` of the occupied cells, ``(K, 2)``."""
    r, c = np.nonzero(data == OCCUPIED)
    return np.stack([c + 0.5, r + 0.5], axis=1).astype(float)


def acceptance_index(a: np.ndarray, b_on_a: np.ndarray) -> tuple[float, int, int]:
    """Birk and Carpin's acceptance index of two trinary grids on the same cells.

    ``agr`` counts cells known in both with the same state, ``dis`` cells known in both with
    different states; ``omega = agr / (agr + dis)`` (0 when no cell is known in both).

    Returns
    -------
    (omega, agr, dis)
    """
    both = (a >= 0) & (b_on_a >= 0)
    agr = int(np.count_nonzero(both & (a == b_on_a)))
    dis = int(np.count_nonzero(both & (a != b_on_a)))
    return (agr / (agr + dis) if agr + dis else 0.0), agr, dis


@dataclass(frozen=True)
class CropPair:
    """Two overlapping windows of one map, the second moved into a frame of its own.

    Attributes
    ----------
    a : OccupancyGrid
        The first window, in the source map's frame (its origin is the window's corner).
    b : OccupancyGrid
        The second window, resampled into its own frame (non-zero origin).
    truth : Transform2D
        Maps ``b``'s frame into ``a``'s frame (m, rad).
    overlap : float
        Shared area of the two windows over the area of one (0..1).
    """

    a: OccupancyGrid
    b: OccupancyGrid
    truth: Transform2D
    overlap: float


def crop_pair(grid: OccupancyGrid, rng, *, size: int = 240, min_overlap: float = 0.5,
              max_rotation: float = math.pi, origin_offset: float = 5.0,
              min_occupied: int = 200) -> CropPair:
    """Cut two overlapping ``size`` x ``size`` windows from ``grid`` and move the second one.

    The second window is shifted from the first by up to ``1 - min_overlap`` of its side in x and
    y (so the windows share at least ``min_overlap`` of their area), then resampled (nearest
    neighbour) into a frame rotated by a random angle in ``[-max_rotation, max_rotation]`` and
    offset by up to ``origin_offset`` metres: the grid a second robot would have built there.

    Parameters
    ----------
    grid : OccupancyGrid
        Source map; must be larger than ``size`` cells in both directions.
    rng : numpy.random.Generator or int
        Randomness of the windows and of the motion.
    size : int
        Side of each window (cells).
    min_overlap : float
        Least shared fraction of a window's area, in (0, 1].
    max_rotation : float
        Largest rotation of the second frame (rad).
    origin_offset : float
        Largest translation of the second frame (m).
    min_occupied : int
        Windows are redrawn (up to 200 times) until each holds this many occupied cells.

    Returns
    -------
    CropPair

    Raises
    ------
    InputError
        If the grid is too small or no windows with enough occupied cells are found.
    """
    rng = np.random.default_rng(rng)
    if not 0 < min_overlap <= 1:
        raise InputError(f"min_overlap must be in (0, 1], got {min_overlap}")
    if grid.rows <= size or grid.cols <= size:
        raise InputError(f"map {grid.name or ''} ({grid.rows}x{grid.cols} cells) is too small "
                         f"for windows of {size} cells")
    data = grid.trinary()
    # each axis shift s (fraction of the side) gives overlap (1-sx)(1-sy); bound each axis by
    # the square root so that the product stays above min_overlap
    max_shift = int((1.0 - math.sqrt(min_overlap)) * size)
    for _ in range(200):
        r0 = int(rng.integers(0, grid.rows - size))
        c0 = int(rng.integers(0, grid.cols - size))
        dr = int(rng.integers(-max_shift, max_shift + 1))
        dc = int(rng.integers(-max_shift, max_shift + 1))
        r1 = min(max(r0 + dr, 0), grid.rows - size)
        c1 = min(max(c0 + dc, 0), grid.cols - size)
        wa = data[r0:r0 + size, c0:c0 + size]
        wb = data[r1:r1 + size, c1:c1 + size]
        if min(np.count_nonzero(wa == OCCUPIED), np.count_nonzero(wb == OCCUPIED)) >= min_occupied:
            break
    else:
        raise InputError(f"map {grid.name or ''} has no {size}-cell windows with "
                         f"{min_occupied} occupied cells")
    overlap = (size - abs(r1 - r0)) * (size - abs(c1 - c0)) / float(size * size)
    a = OccupancyGrid(wa, grid.resolution, tuple(grid.origin_transform(
        np.array([c0 * grid.resolution, r0 * grid.resolution]))) + (grid.origin[2],), "a")
    b_src = OccupancyGrid(wb, grid.resolution, tuple(grid.origin_transform(
        np.array([c1 * grid.resolution, r1 * grid.resolution]))) + (grid.origin[2],), "b")
    theta = float(rng.uniform(-max_rotation, max_rotation))
    off = rng.uniform(-origin_offset, origin_offset, 2)
    truth = Transform2D(float(off[0]), float(off[1]), theta)        # b frame -> a (source) frame
    # b's grid: axis-aligned in its own frame, large enough for the rotated window
    side = int(math.ceil(size * math.sqrt(2))) + 2
    centre_src = b_src.cell_to_world(size / 2 - 0.5, size / 2 - 0.5)
    centre_b = truth.inverse(centre_src)
    half = side * grid.resolution / 2
    target = OccupancyGrid(np.full((side, side), UNKNOWN, np.int8), grid.resolution,
                           (float(centre_b[0] - half), float(centre_b[1] - half), 0.0))
    b = resample(b_src, truth.inverse, target)
    return CropPair(a, b.with_data(b.data, name="b"), truth, float(overlap))


def placement_error(estimate: Transform2D, truth: Transform2D, moving: OccupancyGrid) -> tuple[float, float]:
    """``(displacement, rotation error)`` of an estimate: how far (m) the centroid of the moving
    grid's known cells lands from where ``truth`` puts it, and the absolute angle error (rad)."""
    r, c = np.nonzero(moving.known_mask())
    if r.size == 0:
        r, c = np.array([moving.rows / 2 - 0.5]), np.array([moving.cols / 2 - 0.5])
    p = moving.cell_to_world(r.mean(), c.mean())
    d = float(np.hypot(*(estimate(p) - truth(p))))
    return d, estimate.error_to(truth)[1]


def warp_cells(b_data: np.ndarray, cell_transform: Transform2D, shape) -> np.ndarray:
    """Cells of grid ``b_data`` sampled (nearest neighbour, unknown outside) onto a grid of
    ``shape`` whose cell frame ``cell_transform`` maps ``b``'s cell frame into."""
    src = OccupancyGrid(b_data, 1.0)
    target = OccupancyGrid(np.full(shape, -1, np.int8), 1.0)
    return resample(src, cell_transform, target).data
