"""The occupancy grid value type (CONTRACTS section 1).

``data[row, col]`` is ``numpy.int8``: ``-1`` unknown, ``0`` free, ``100`` occupied. Row 0 is
the row nearest the origin (lowest y). ``origin = (x, y, yaw)`` is the pose of the lower-left
corner of cell (0, 0) in the map frame; ``resolution`` is metres per cell. The centre of cell
``(r, c)`` is ``origin_xy + R(yaw) @ ((c + 0.5) * res, (r + 0.5) * res)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .errors import InputError
from ._validate import own_array
from .transform import Transform2D

__all__ = ["OccupancyGrid", "UNKNOWN", "FREE", "OCCUPIED"]

UNKNOWN = -1
FREE = 0
OCCUPIED = 100


def _check_cells(raw: np.ndarray) -> None:
    """Refuse cell values an int8 grid cannot take as they are (an image's 0-255, probabilities
    in 0..1, NaN), with what to do instead."""
    if raw.dtype.kind == "b":
        raise InputError("grid data is a boolean mask: give cells -1 unknown, 0 free, 100 occupied "
                         "(for a wall mask, np.where(mask, 100, 0))")
    if raw.dtype.kind not in "iuf":
        raise InputError(f"grid data must be numbers (-1 unknown, 0 free, 100 occupied), got {raw.dtype}")
    if raw.dtype.kind == "f":
        if not np.isfinite(raw).all():
            raise InputError("grid data holds NaN or infinite values; give -1 for unknown cells")
        if (raw != np.round(raw)).any():
            raise InputError(f"grid data holds fractions (from {raw.min():g} to {raw.max():g}): give "
                             f"occupancy in percent, -1 unknown, 0 free to 100 occupied (probabilities "
                             f"in 0..1 times 100, rounded)")
    lo, hi = raw.min(), raw.max()
    if lo < -1 or hi > 100:
        raise InputError(f"grid data holds values from {lo:g} to {hi:g}: give -1 unknown, 0 free to 100 "
                         f"occupied (an image's pixels are read as a map by load_map)")
    if hi == 1 and raw.dtype != np.int8:
        # a wall mask of 0 and 1 (mask.astype(np.uint8)) became a map with no wall: 1 is 1 %
        # occupied; int8, a map's own type (read from a file or a ROS message), is taken as it is
        raise InputError("grid data holds no value above 1, and 1 is a cell 1 % occupied (free): "
                         "give -1 unknown, 0 free, 100 occupied (for a wall mask of 0 and 1, "
                         "np.where(mask == 1, 100, 0))")


def box_of(mask: np.ndarray) -> tuple[int, int, int, int] | None:
    """``(r0, r1, c0, c1)``: rows ``r0:r1`` and columns ``c0:c1`` hold every true cell of the 2-D
    ``mask``; None when none is true."""
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if rows.size == 0:
        return None
    return int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1


@dataclass(frozen=True, eq=False)
class OccupancyGrid:
    """A 2-D occupancy grid in the ``nav_msgs/OccupancyGrid`` convention.

    Parameters
    ----------
    data : (rows, cols) int8 array
        ``-1`` unknown, ``0`` free, ``100`` occupied (1..99 allowed as probabilities).
    resolution : float
        Metres per cell, > 0.
    origin : (x, y, yaw)
        Pose of the lower-left corner of cell (0, 0) in the map frame (m, m, rad).
    """

    data: np.ndarray
    resolution: float
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    name: str = field(default="", compare=False)

    def __post_init__(self):
        try:
            raw = np.asarray(self.data)
        except ValueError:
            raise InputError("grid data must be a 2-D array (rows, cols); rows of unequal length "
                             "were given") from None
        if raw.size:
            _check_cells(raw)   # cast as they are, 200 wrapped to -56 and 0.9 fell to 0 (free)
        data = np.ascontiguousarray(raw, dtype=np.int8)
        data = own_array(data, raw)
        if data.ndim != 2:
            raise InputError(f"grid data must be 2-D (rows, cols), got shape {data.shape}")
        try:
            res = float(self.resolution)
        except (TypeError, ValueError):
            res = math.nan
        if not (res > 0 and math.isfinite(res)):
            raise InputError(f"grid resolution must be a positive number of metres, got {self.resolution!r}")
        try:
            origin = tuple(float(v) for v in self.origin)
        except (TypeError, ValueError):
            raise InputError(f"grid origin must be (x, y, yaw) numbers, got {self.origin!r}") from None
        if len(origin) == 2:
            origin = (*origin, 0.0)
        if len(origin) != 3 or not all(math.isfinite(v) for v in origin):
            raise InputError(f"grid origin must be finite (x, y, yaw), got {self.origin}")
        if abs(origin[2]) > 2 * math.pi:
            # a yaw of 90 (degrees) turned the map by 90 rad, without a word
            raise InputError(f"grid origin's yaw {origin[2]:g} is more than a full turn: give it in "
                             f"radians (math.radians({origin[2]:g}) = {math.radians(origin[2]):.6g})")
        data.setflags(write=False)
        object.__setattr__(self, "data", data)
        object.__setattr__(self, "resolution", res)
        object.__setattr__(self, "origin", origin)

    # -- basic facts ---------------------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int]:
        return self.data.shape

    @property
    def rows(self) -> int:
        return self.data.shape[0]

    @property
    def cols(self) -> int:
        return self.data.shape[1]

    @property
    def origin_transform(self) -> Transform2D:
        """Transform from the grid's cell frame (metres, lower-left corner) into the map frame."""
        return Transform2D(*self.origin)

    def trinary(self) -> np.ndarray:
        """The three states as int8: probabilities >= 50 become occupied, 1..49 free."""
        d = self.data
        out = np.full(d.shape, UNKNOWN, np.int8)
        out[(d >= 0) & (d < 50)] = FREE
        out[d >= 50] = OCCUPIED
        return out

    def known_mask(self) -> np.ndarray:
        return self.data >= 0

    def known_box(self) -> tuple[int, int, int, int] | None:
        """Rows ``r0:r1`` and columns ``c0:c1`` of the box holding every known cell, as
        ``(r0, r1, c0, c1)``; None when no cell is known."""
        return box_of(self.known_mask())

    def occupied_mask(self) -> np.ndarray:
        return self.data >= 50

    def free_mask(self) -> np.ndarray:
        return (self.data >= 0) & (self.data < 50)

    def counts(self) -> dict:
        """Cell counts ``{"occupied", "free", "unknown"}`` of the three states."""
        occ = int(self.occupied_mask().sum())
        free = int(self.free_mask().sum())
        return {"occupied": occ, "free": free, "unknown": int(self.data.size - occ - free)}

    def with_data(self, data, name: str | None = None) -> "OccupancyGrid":
        """Same geometry, new cells."""
        return OccupancyGrid(data, self.resolution, self.origin, self.name if name is None else name)

    # -- coordinates ----------------------------------------------------------------------------
    def cell_to_world(self, rows, cols) -> np.ndarray:
        """Centres of cells ``(rows, cols)`` in the map frame, shape ``(..., 2)`` (m)."""
        r = np.asarray(rows, dtype=float)
        c = np.asarray(cols, dtype=float)
        local = np.stack([(c + 0.5) * self.resolution, (r + 0.5) * self.resolution], axis=-1)
        return self.origin_transform(local)

    def world_to_cell(self, points) -> tuple[np.ndarray, np.ndarray]:
        """Continuous cell coordinates ``(row, col)`` of map-frame points (cell (r, c) spans
        ``[r, r+1) x [c, c+1)``); ``floor`` gives the cell index."""
        local = self.origin_transform.inverse(np.asarray(points, dtype=float))
        return local[..., 1] / self.resolution, local[..., 0] / self.resolution

    def bounds(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` of the grid's four corners in the map frame (m)."""
        h, w = self.rows * self.resolution, self.cols * self.resolution
        corners = self.origin_transform(np.array([[0, 0], [w, 0], [0, h], [w, h]], float))
        return (*corners.min(axis=0), *corners.max(axis=0))

    def occupied_points(self) -> np.ndarray:
        """Map-frame centres (m) of the occupied cells, shape ``(K, 2)``."""
        r, c = np.nonzero(self.occupied_mask())
        return self.cell_to_world(r, c)

    def __repr__(self) -> str:
        n = f"{self.name!r}, " if self.name else ""
        return (f"OccupancyGrid({n}{self.cols}x{self.rows} cells (width x height), {self.resolution:g} m/cell, "
                f"origin=({self.origin[0]:g}, {self.origin[1]:g}, {self.origin[2]:g}))")
