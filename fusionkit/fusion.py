"""Placing maps in a common frame and fusing them (the paper's eq. 4 and Section 3.6).

Two maps are fused cell by cell with the paper's rules::

    M_fusion(i, j) = unknown    if M1(i, j) = unknown and M2(i, j) = unknown
                     occupied   if M1(i, j) = occupied or M2(i, j) = occupied
                     free       otherwise

The rules are commutative and associative, so fusing many maps one after the other gives the
same cells in any order; the order only decides which map is credited with first making a cell
known (:attr:`FusedMap.owner`) and what the intermediate maps look like (:attr:`FusedMap.steps`,
the rows of the paper's Table 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from numbers import Integral, Real

import numpy as np

from .errors import InputError
from .grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from .resample import canvas_for, resample
from .transform import Transform2D

__all__ = ["fuse_cells", "FusedMap", "fuse_maps", "apply_paper_transform"]


def _three_state(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(known, occupied)`` masks of cell values (``< 0`` unknown, ``>= 50`` occupied)."""
    return a >= 0, a >= 50


def fuse_cells(a, b) -> np.ndarray:
    """Fuse two co-registered grids cell by cell (paper Section 3.6).

    Parameters
    ----------
    a, b : (rows, cols) array_like of int
        Cell values in the ``nav_msgs`` convention: ``-1`` (any negative) unknown, ``0`` free,
        ``100`` occupied; probabilities ``1..99`` count as occupied from 50 up, free below.

    Returns
    -------
    (rows, cols) ndarray of int8
        ``-1`` where both are unknown, ``100`` where either is occupied, ``0`` elsewhere.

    Raises
    ------
    InputError
        When the shapes differ, or a cell is not a number, NaN or over 100.

    Examples
    --------
    >>> fuse_cells([[-1, -1, 0]], [[-1, 100, 0]]).tolist()
    [[-1, 100, 0]]
    """
    a = np.asarray(a)
    b = np.asarray(b)
    if a.shape != b.shape:
        raise InputError(f"grids to fuse must have the same shape, got {a.shape} and {b.shape}; "
                         "resample them onto one canvas first")
    for cells in (a, b):
        if cells.dtype.kind not in "iuf":
            raise InputError(f"cells to fuse must be numbers (-1 unknown, 0 free, 100 occupied), "
                             f"got {cells.dtype}")
        if cells.size and (np.isnan(cells).any() if cells.dtype.kind == "f" else False):
            raise InputError("cells to fuse hold NaN; give -1 for unknown cells")
        if cells.size and cells.max() > 100:
            raise InputError(f"cells to fuse go up to {cells.max():g}; occupancy is at most 100")
    known_a, occ_a = _three_state(a)
    known_b, occ_b = _three_state(b)
    out = np.full(a.shape, UNKNOWN, np.int8)
    out[known_a | known_b] = FREE          # not both unknown: free ...
    out[occ_a | occ_b] = OCCUPIED          # ... unless either is occupied
    return out


@dataclass(frozen=True, eq=False)
class FusedMap:
    """The outcome of :func:`fuse_maps`.

    Attributes
    ----------
    grid : OccupancyGrid
        The fused map, three states, in the common (reference) frame: its origin is the canvas
        corner expressed in that frame.
    owner : (rows, cols) ndarray of int16
        Per cell, the index (into the ``grids`` given to :func:`fuse_maps`) of the map that first
        made it known in the fusion order; ``-1`` where the fused map is unknown.
    steps : tuple of OccupancyGrid
        With ``keep_steps=True``, the fused map after each map was added (same canvas as
        ``grid``; the last equals ``grid``); empty otherwise.
    order : tuple of int
        Indices of the maps actually fused, in fusion order (maps with a ``None`` transform are
        left out).
    """

    grid: OccupancyGrid
    owner: np.ndarray
    steps: tuple[OccupancyGrid, ...] = ()
    order: tuple[int, ...] = field(default=())


def _check_order(order, n: int) -> list[int]:
    if order is None:
        return list(range(n))
    out = []
    for k in order:
        if not isinstance(k, Integral) or isinstance(k, bool) or not 0 <= k < n:
            raise InputError(f"fusion order entries must be map indices 0..{n - 1}, got {k!r}")
        if int(k) in out:
            raise InputError(f"fusion order lists map {int(k)} twice; list each map once")
        out.append(int(k))
    return out


def fuse_maps(grids, transforms, *, order=None, resolution: float | None = None,
              keep_steps: bool = False) -> FusedMap:
    """Place every map in the common frame and fuse them (paper eq. 4 and Section 3.6).

    Parameters
    ----------
    grids : sequence of OccupancyGrid
        The maps, each in its own frame.
    transforms : sequence of Transform2D or None
        ``transforms[k]`` maps grid ``k``'s map frame into the common (reference) frame (m, rad);
        ``None`` leaves map ``k`` out.
    order : sequence of int, optional
        Indices of the maps in the order they are fused (default: index order). Maps not listed
        are left out.
    resolution : float, optional
        Cell size of the fused map (m). Default: the resolution of the reference map, i.e. the
        first map in ``order`` whose transform is the identity, else the first map fused.
    keep_steps : bool
        Keep the fused map after each map is added in :attr:`FusedMap.steps`.

    Returns
    -------
    FusedMap
        The fused grid covers the known cells of every fused map (plus a 2-cell margin), axis
        aligned in the common frame; each map is resampled onto it by nearest neighbour.

    Raises
    ------
    InputError
        Mismatched lengths, a bad ``order`` or ``resolution``, no map to fuse, or no known cell
        in any fused map.
    """
    grids = list(grids)
    transforms = list(transforms)
    if len(grids) != len(transforms):
        raise InputError(f"fuse_maps needs one transform per grid, got {len(grids)} grids and "
                         f"{len(transforms)} transforms")
    for k, (g, t) in enumerate(zip(grids, transforms)):
        if not isinstance(g, OccupancyGrid):
            raise InputError(f"map {k} is a {type(g).__name__}, not an OccupancyGrid")
        if t is not None and not isinstance(t, Transform2D):
            raise InputError(f"transform {k} is a {type(t).__name__}, not a Transform2D or None")
    used = [k for k in _check_order(order, len(grids)) if transforms[k] is not None]
    if not used:
        raise InputError("no map to fuse: every map was left out (all transforms are None)")
    if resolution is None:
        ident = [k for k in used if transforms[k].is_close(Transform2D.identity())]
        resolution = grids[(ident or used)[0]].resolution
    elif (not isinstance(resolution, Real) or isinstance(resolution, bool)
          or not (math.isfinite(resolution) and resolution > 0)):
        raise InputError(f"fused map resolution must be a positive number of metres, got {resolution!r}")

    try:
        canvas = canvas_for([grids[k] for k in used], [transforms[k] for k in used],
                            float(resolution))
    except ValueError as exc:
        raise InputError(f"cannot fuse: {exc}") from None

    fused = canvas.data.copy()
    owner = np.full(canvas.shape, -1, np.int16)
    steps = []
    for k in used:
        placed = resample(grids[k], transforms[k], canvas).data   # eq. 4: into the common frame
        newly_known = (fused < 0) & (placed >= 0)
        owner[newly_known] = k
        fused = fuse_cells(fused, placed)                          # Section 3.6 rules
        if keep_steps:
            steps.append(canvas.with_data(fused.copy(), name=f"fused step {len(steps) + 1}"))
    owner.setflags(write=False)
    grid = canvas.with_data(fused, name="fused")
    return FusedMap(grid=grid, owner=owner, steps=tuple(steps), order=tuple(used))


def apply_paper_transform(points, dx: float, dy: float, dphi: float) -> np.ndarray:
    """Translate then rotate points exactly as the paper's eq. (4) writes it.

    ``x' = (x + dx) cos(dphi) - (y + dy) sin(dphi)``,
    ``y' = (x + dx) sin(dphi) + (y + dy) cos(dphi)``.

    Parameters
    ----------
    points : (2,) or (N, 2) array_like
        ``(x, y)`` points (m).
    dx, dy : float
        Translation applied first (m).
    dphi : float
        Rotation about the origin applied second (rad, counter-clockwise).

    Returns
    -------
    ndarray, same shape as ``points``
        Equal to ``Transform2D.from_paper(dx, dy, dphi)(points)``.
    """
    p = np.asarray(points, dtype=float)
    if p.shape[-1:] != (2,):
        raise InputError(f"points must have shape (2,) or (N, 2), got {p.shape}")
    x, y = p[..., 0], p[..., 1]
    c, s = math.cos(dphi), math.sin(dphi)
    # eq. (4)
    xp = (x + dx) * c - (y + dy) * s
    yp = (x + dx) * s + (y + dy) * c
    return np.stack([xp, yp], axis=-1)
