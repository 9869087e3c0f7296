"""Building a robot's occupancy grid from its scans (log-odds ray tracing).

Each beam marks the cells it passes as more likely free and, when it returned, its end cell as
more likely occupied (the standard inverse sensor model; Thrun, Burgard & Fox, *Probabilistic
Robotics*, ch. 9). The summed log-odds are thresholded to the three states of CONTRACTS
section 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._jit import njit
from ._validate import number, whole
from .errors import InputError
from .grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from .scanlog import ScanLog

__all__ = ["MappingConfig", "build_grid", "MAX_CELLS"]

#: Largest grid fusionkit allocates (cells); beyond it a map is refused, not half-built.
MAX_CELLS = 200_000_000


@dataclass(frozen=True)
class MappingConfig:
    """Log-odds occupancy mapping settings.

    Attributes
    ----------
    resolution : float
        Cell size (m).
    l_occ, l_free : float
        Log-odds added to a beam's end cell / to each cell it passes.
    l_clamp : float
        Log-odds are clamped to ``[-l_clamp, l_clamp]``.
    occ_thresh, free_thresh : float
        A cell is occupied when its log-odds exceed ``occ_thresh``, free when below
        ``-free_thresh``, unknown otherwise.
    max_free_range : float or None
        No-return beams clear free space up to this distance (m); ``None`` uses ``range_max``.
    margin : int
        Unknown cells around the observed area.
    """

    resolution: float = 0.1
    l_occ: float = 0.85
    l_free: float = 0.4
    l_clamp: float = 6.0
    occ_thresh: float = 0.6
    free_thresh: float = 0.6
    max_free_range: float | None = None
    margin: int = 5

    def __post_init__(self):
        values = {name: number(getattr(self, name), name)
                  for name in ("resolution", "l_occ", "l_free", "l_clamp", "occ_thresh", "free_thresh")}
        for name, v in values.items():
            object.__setattr__(self, name, v)
        if values["resolution"] <= 0:
            raise InputError(f"mapping resolution must be > 0 m, got {self.resolution}")
        if self.l_occ <= 0 or self.l_free <= 0:
            raise InputError("l_occ and l_free must be > 0")
        if values["l_clamp"] <= 0:
            raise InputError(f"l_clamp must be > 0 (log-odds are clamped to [-l_clamp, l_clamp]), "
                             f"got {values['l_clamp']:g}")
        for name in ("occ_thresh", "free_thresh"):
            if not 0 <= values[name] < values["l_clamp"]:
                # at or over the clamp no cell is ever occupied (free); below 0, the unsure are
                raise InputError(f"{name} must be >= 0 and below l_clamp ({values['l_clamp']:g}), "
                                 f"got {values[name]:g}")
        if self.max_free_range is not None:
            object.__setattr__(self, "max_free_range", number(self.max_free_range, "max_free_range"))
            if self.max_free_range < 0:   # 0: a no-return beam clears nothing
                raise InputError(f"max_free_range must be >= 0 m (or None), got {self.max_free_range:g}")
        object.__setattr__(self, "margin", whole(self.margin, "margin"))
        if self.margin < 0:
            raise InputError("margin must be >= 0 cells")


@njit
def _integrate(poses, ranges, angles, range_max, free_range, x0, y0, res, rows, cols,
               l_occ, l_free, l_clamp):
    """Accumulate log-odds along each beam with an exact grid traversal (Amanatides & Woo)."""
    L = np.zeros((rows, cols), np.float32)
    n, b = ranges.shape
    for i in range(n):
        px = (poses[i, 0] - x0) / res
        py = (poses[i, 1] - y0) / res
        th = poses[i, 2]
        for j in range(b):
            r = ranges[i, j]
            hit = math.isfinite(r) and r <= range_max
            if not hit:
                r = free_range
            a = th + angles[j]
            dx = math.cos(a)
            dy = math.sin(a)
            # the end cell is the one just behind the measured surface: a beam that stops on a
            # cell boundary marks the wall cell, whichever side it came from
            ex = px + dx * (r / res + 0.25)
            ey = py + dy * (r / res + 0.25)
            cx = int(math.floor(px))
            cy = int(math.floor(py))
            tx_end = int(math.floor(ex))
            ty_end = int(math.floor(ey))
            stepx = 1 if dx > 0 else -1
            stepy = 1 if dy > 0 else -1
            if dx != 0.0:
                nx = (cx + (1 if dx > 0 else 0) - px) / dx
                ddx = abs(1.0 / dx)
            else:
                nx = 1e30
                ddx = 1e30
            if dy != 0.0:
                ny = (cy + (1 if dy > 0 else 0) - py) / dy
                ddy = abs(1.0 / dy)
            else:
                ny = 1e30
                ddy = 1e30
            dist = r / res
            steps = 0
            max_steps = int(abs(tx_end - cx) + abs(ty_end - cy)) + 2
            while steps <= max_steps:
                if cx == tx_end and cy == ty_end:
                    break
                if 0 <= cy < rows and 0 <= cx < cols:
                    v = L[cy, cx] - l_free
                    L[cy, cx] = v if v > -l_clamp else -l_clamp
                if nx < ny:
                    if nx > dist:
                        break
                    cx += stepx
                    nx += ddx
                else:
                    if ny > dist:
                        break
                    cy += stepy
                    ny += ddy
                steps += 1
            if hit and 0 <= ty_end < rows and 0 <= tx_end < cols:
                v = L[ty_end, tx_end] + l_occ
                L[ty_end, tx_end] = v if v < l_clamp else l_clamp
    return L


def build_grid(log: ScanLog, config: MappingConfig = MappingConfig(), *, name: str = "") -> OccupancyGrid:
    """Ray-trace ``log``'s scans into a trinary occupancy grid in the log's own map frame.

    The grid is axis-aligned, covers every beam end point (and no-return beams up to
    ``max_free_range``) plus ``config.margin`` cells, and its origin is snapped to the
    resolution.
    """
    if not isinstance(log, ScanLog):
        raise InputError(f"build_grid takes a ScanLog (poses and ranges), got {type(log).__name__}")
    if not isinstance(config, MappingConfig):
        raise InputError(f"build_grid's config must be a MappingConfig, got {type(config).__name__}")
    if log.n_scans == 0:
        raise InputError("the scan log holds no scan: there is nothing to map")
    res = config.resolution
    free_range = config.max_free_range if config.max_free_range is not None else log.range_max
    ranges = np.where(np.isfinite(log.ranges) & (log.ranges <= log.range_max), log.ranges,
                      np.float32(np.inf)).astype(np.float32)
    reach = np.where(np.isfinite(ranges), ranges, np.float32(free_range))
    ang = log.poses[:, 2:3] + log.beam_angles[None, :]
    xs = log.poses[:, 0:1] + reach * np.cos(ang)
    ys = log.poses[:, 1:2] + reach * np.sin(ang)
    xmin = min(xs.min(), log.poses[:, 0].min())
    xmax = max(xs.max(), log.poses[:, 0].max())
    ymin = min(ys.min(), log.poses[:, 1].min())
    ymax = max(ys.max(), log.poses[:, 1].max())
    m = config.margin * res
    x0 = math.floor((xmin - m) / res) * res
    y0 = math.floor((ymin - m) / res) * res
    cols = int(math.ceil((xmax + m - x0) / res)) + 1
    rows = int(math.ceil((ymax + m - y0) / res)) + 1
    if rows * cols > MAX_CELLS:
        raise InputError(
            f"the scans span {cols * res:.0f} x {rows * res:.0f} m, {rows * cols} cells at {res} m: "
            f"too large; use a coarser resolution (--resolution)")
    L = _integrate(log.poses, ranges, log.beam_angles.astype(np.float64), float(log.range_max),
                   float(free_range), float(x0), float(y0), float(res), rows, cols,
                   float(config.l_occ), float(config.l_free), float(config.l_clamp))
    data = np.full((rows, cols), UNKNOWN, np.int8)
    data[L < -config.free_thresh] = FREE
    data[L > config.occ_thresh] = OCCUPIED
    return OccupancyGrid(data, res, (x0, y0, 0.0), name)
