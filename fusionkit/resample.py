"""Resampling a grid into another frame (nearest neighbour, unknown outside).

Used to move a robot's map into the reference frame (paper eq. 4 / CONTRACTS section 4) and to
sample a fused map onto the ground-truth grid for the metrics (CONTRACTS section 7).
"""

from __future__ import annotations

import math
from numbers import Real

import numpy as np

from ._jit import pjit, prange
from .errors import InputError
from .grid import UNKNOWN, OccupancyGrid
from .mapping import MAX_CELLS
from .transform import Transform2D

__all__ = ["resample", "canvas_for", "transformed_bounds"]


@pjit
def _resample_kernel(src, a00, a01, a10, a11, bx, by, out_rows, out_cols, fill):
    """For each output cell (r, c): source continuous cell coords
    ``(col_s, row_s) = A @ (c + 0.5, r + 0.5) + b``; nearest source cell, ``fill`` outside."""
    out = np.empty((out_rows, out_cols), np.int8)
    sr, sc = src.shape
    for r in prange(out_rows):
        yr = r + 0.5
        for c in range(out_cols):
            xc = c + 0.5
            cs = a00 * xc + a01 * yr + bx
            rs = a10 * xc + a11 * yr + by
            ci = int(math.floor(cs))
            ri = int(math.floor(rs))
            if 0 <= ri < sr and 0 <= ci < sc:
                out[r, c] = src[ri, ci]
            else:
                out[r, c] = fill
    return out


def _cell_affine(source: OccupancyGrid, transform: Transform2D, target: OccupancyGrid):
    """Affine map from target cell coordinates to source cell coordinates."""
    # target cell coords -> target map frame -> source map frame -> source cell coords
    t_cells_to_map = target.origin_transform
    s_map_to_cells = source.origin_transform.inverse
    chain = s_map_to_cells @ transform.inverse @ t_cells_to_map
    m = chain.matrix
    k = target.resolution / source.resolution
    a = m[:2, :2] * k
    b = m[:2, 2] / source.resolution
    return a, b


def resample(source: OccupancyGrid, transform: Transform2D, target: OccupancyGrid) -> OccupancyGrid:
    """Sample ``source`` onto the cells of ``target``.

    Parameters
    ----------
    source : OccupancyGrid
        The grid to move.
    transform : Transform2D
        Maps ``source``'s map frame into ``target``'s map frame (m, rad).
    target : OccupancyGrid
        Only its geometry (shape, resolution, origin) is used.

    Returns
    -------
    OccupancyGrid
        ``target``'s geometry, each cell the value of the source cell under its centre
        (nearest neighbour), unknown (-1) where no source cell lies.
    """
    if not (isinstance(source, OccupancyGrid) and isinstance(target, OccupancyGrid)
            and isinstance(transform, Transform2D)):
        raise InputError(f"resample(source, transform, target) takes two OccupancyGrid maps and a "
                         f"Transform2D, got {type(source).__name__}, {type(transform).__name__}, "
                         f"{type(target).__name__}")
    a, b = _cell_affine(source, transform, target)
    out = _resample_kernel(source.data, a[0, 0], a[0, 1], a[1, 0], a[1, 1], b[0], b[1],
                           target.rows, target.cols, np.int8(UNKNOWN))
    out.setflags(write=False)   # made here: the grid takes it without a copy
    return OccupancyGrid(out, target.resolution, target.origin, source.name)


def transformed_bounds(grid: OccupancyGrid, transform: Transform2D, known_only: bool = True):
    """``(xmin, ymin, xmax, ymax)`` (m) of ``grid``'s (known) cells after ``transform``."""
    if known_only:
        box = grid.known_box()
        if box is None:
            return None
        # the known cells' bounding box in cell space; its four corners bound them after any
        # rigid motion
        r0, r1, c0, c1 = box
        rr = np.array([r0, r0, r1, r1], float) - 0.5
        cc = np.array([c0, c1, c0, c1], float) - 0.5
        pts = grid.cell_to_world(rr, cc)
    else:
        h, w = grid.rows, grid.cols
        pts = grid.cell_to_world(np.array([-0.5, -0.5, h - 0.5, h - 0.5]),
                                 np.array([-0.5, w - 0.5, -0.5, w - 0.5]))
    pts = transform(pts)
    return (*pts.min(axis=0), *pts.max(axis=0))


def canvas_for(grids, transforms, resolution: float, margin_cells: int = 2) -> OccupancyGrid:
    """An all-unknown, axis-aligned grid at ``resolution`` covering every grid's known cells
    after its transform, plus a margin; the canvas frame is the transforms' target frame."""
    if isinstance(resolution, bool) or not isinstance(resolution, Real) or not 0 < resolution < math.inf:
        raise InputError(f"the canvas resolution must be a positive number of metres, got {resolution!r}")
    grids, transforms = list(grids), list(transforms)
    if len(grids) != len(transforms):
        raise InputError(f"canvas_for needs one transform per grid, got {len(grids)} grids and "
                         f"{len(transforms)} transforms")
    for k, (g, t) in enumerate(zip(grids, transforms)):
        if not isinstance(g, OccupancyGrid) or not isinstance(t, Transform2D):
            raise InputError(f"canvas_for takes OccupancyGrid maps and Transform2D transforms; item "
                             f"{k} is a {type(g).__name__} and a {type(t).__name__}")
    boxes = [transformed_bounds(g, t) for g, t in zip(grids, transforms)]
    boxes = [b for b in boxes if b is not None]
    if not boxes:
        raise InputError("no known cells in any grid: nothing to place on a canvas")
    b = np.array(boxes)
    xmin, ymin = b[:, 0].min(), b[:, 1].min()
    xmax, ymax = b[:, 2].max(), b[:, 3].max()
    m = margin_cells * resolution
    # snap the canvas origin to the resolution so repeated canvases line up
    x0 = math.floor((xmin - m) / resolution) * resolution
    y0 = math.floor((ymin - m) / resolution) * resolution
    cols = int(math.ceil((xmax + m - x0) / resolution))
    rows = int(math.ceil((ymax + m - y0) / resolution))
    if rows * cols > MAX_CELLS:
        raise InputError(f"the maps placed so cover {xmax - xmin:.6g} x {ymax - ymin:.6g} m: at "
                         f"{resolution:g} m cells, {cols} x {rows} cells, more than the {MAX_CELLS} "
                         f"fusionkit can hold; use a coarser resolution or check the transforms")
    cells = np.full((rows, cols), UNKNOWN, np.int8)
    cells.setflags(write=False)   # made here: the grid takes it without a copy
    return OccupancyGrid(cells, resolution, (x0, y0, 0.0))


from ._callable_module import callable_as  # noqa: E402

# ``fusionkit.resample`` is this module once it is imported: callable as resample() all the same
callable_as(__name__, "resample")
