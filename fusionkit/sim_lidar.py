"""The simulated 2-D LIDAR: its settings and the beams cast through a world.

Beams are cast through the world with an exact grid traversal (Amanatides & Woo): occupied cells
return the beam, free and unknown cells let it pass (in a real map, unknown cells are mostly grey
fringes of walls and unobserved floor; robots never drive into them). Gaussian range noise is
added, and beams without a return within ``max_range`` are ``inf``, as in
``sensor_msgs/LaserScan``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._validate import number as _num, whole as _int
from .errors import InputError
from .grid import OccupancyGrid
from .raycast import cast_rays

__all__ = ["LidarConfig", "cast_scans"]


# ---------------------------------------------------------------------------------------------
# Settings
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class LidarConfig:
    """A 2-D LIDAR in the ``sensor_msgs/LaserScan`` convention.

    Attributes
    ----------
    beams : int
        Beams per scan (2 to 10000).
    fov_deg : float
        Field of view (degrees, 0 < fov <= 360), centred on the heading. A full circle has
        beams ``2 pi / beams`` apart starting at ``-pi``; a narrower fan spans
        ``[-fov/2, +fov/2]`` with both ends included.
    max_range : float
        Sensor range (m); walls further away give no return (``inf``).
    range_noise : float
        Standard deviation of the gaussian range noise (m), >= 0.
    """

    beams: int = 360
    fov_deg: float = 360.0
    max_range: float = 8.0
    range_noise: float = 0.01

    def __post_init__(self):
        beams = _int(self.beams, "LIDAR beams")
        if not 2 <= beams <= 10_000:
            raise InputError(f"LIDAR beams must be between 2 and 10000, got {beams}")
        fov = _num(self.fov_deg, "LIDAR field of view")
        if not 0 < fov <= 360:
            raise InputError(f"LIDAR field of view must be > 0 and <= 360 degrees, got {fov:g}")
        rmax = _num(self.max_range, "LIDAR max range")
        if not 0 < rmax <= 1000:
            raise InputError(f"LIDAR max range must be > 0 and <= 1000 m, got {rmax:g}")
        noise = _num(self.range_noise, "LIDAR range noise")
        if not 0 <= noise <= rmax / 10:
            raise InputError(f"LIDAR range noise must be >= 0 and at most a tenth of the max range "
                             f"({rmax / 10:g} m), got {noise:g} m")
        object.__setattr__(self, "beams", beams)
        object.__setattr__(self, "fov_deg", fov)
        object.__setattr__(self, "max_range", rmax)
        object.__setattr__(self, "range_noise", noise)

    @property
    def full_circle(self) -> bool:
        return self.fov_deg >= 360.0

    @property
    def angle_increment(self) -> float:
        """Angle between neighbouring beams (rad)."""
        fov = math.radians(self.fov_deg)
        return fov / self.beams if self.full_circle else fov / (self.beams - 1)

    @property
    def angle_min(self) -> float:
        """Angle of beam 0 relative to the heading (rad)."""
        return -math.pi if self.full_circle else -math.radians(self.fov_deg) / 2

    @property
    def angles(self) -> np.ndarray:
        """Beam angles relative to the heading (rad), shape ``(beams,)``."""
        return self.angle_min + self.angle_increment * np.arange(self.beams)



# ---------------------------------------------------------------------------------------------
# Sensor
# ---------------------------------------------------------------------------------------------
def _blocked(world: OccupancyGrid) -> np.ndarray:
    """1 where a cell returns the beam (occupied), 0 where the beam passes (free, unknown)."""
    return world.occupied_mask().astype(np.uint8)


def _cast(world, blocked, poses_world, lidar: LidarConfig, noise) -> np.ndarray:
    local = world.origin_transform.inverse.apply_pose(poses_world)
    res = world.resolution
    pc = np.column_stack([local[:, 0] / res, local[:, 1] / res, local[:, 2]])
    # ranges (m) to the entry point of the first occupied cell; inf for no return
    r = cast_rays(blocked, pc, lidar.angles, lidar.max_range / res) * np.float32(res)
    if noise is not None:
        hit = np.isfinite(r)
        r[hit] += noise[hit]
        np.maximum(r, 0.0, out=r)
        r[r > lidar.max_range] = np.inf  # beyond range_max: no valid return (LaserScan)
    return r


def cast_scans(world: OccupancyGrid, poses, lidar: LidarConfig = LidarConfig(), *,
               rng: np.random.Generator | None = None) -> np.ndarray:
    """Simulated LIDAR ranges from world-frame poses.

    Parameters
    ----------
    world : OccupancyGrid
        Occupied cells return beams; free and unknown cells let them pass.
    poses : (N, 3) array
        Sensor poses x, y (m), theta (rad) in the world's map frame.
    lidar : LidarConfig
    rng : numpy.random.Generator, optional
        Source of the gaussian range noise; without it the ranges are exact.

    Returns
    -------
    (N, beams) float32
        Range per beam (m): the distance to where the beam enters the first occupied cell;
        ``inf`` when it returns nothing within ``lidar.max_range``.
    """
    poses = np.asarray(poses, dtype=np.float64)
    if poses.ndim != 2 or poses.shape[1] != 3 or not np.isfinite(poses).all():
        raise InputError(f"poses must be a finite (N, 3) array of x, y, theta; got shape {poses.shape}")
    noise = None
    if rng is not None and lidar.range_noise > 0:
        noise = rng.standard_normal((len(poses), lidar.beams), dtype=np.float32)
        noise *= np.float32(lidar.range_noise)
    return _cast(world, _blocked(world), poses, lidar, noise)
