"""What a suite contains and how it is scored: :class:`BenchConfig` and the constants of
the suite.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

from .._validate import names
from ..errors import InputError

__all__ = ["BenchConfig", "MODES", "DEFAULT_METHODS", "OVERLAP_BINS"]


MODES = ("explore", "crop")
#: Methods compared by default: fusionkit's two and the classic peers (map-merge with its chaining
#: corrected and as shipped).
DEFAULT_METHODS = ("consensus", "spectral-pso", "map-merge", "map-merge-shipped", "hough-spectrum",
                   "fourier-mellin")
#: Overlap bins of the breakdown (lower edges).
OVERLAP_BINS = (0.0, 0.15, 0.3, 0.5)
#: Fewest occupied cells for a map to be used as a world.
MIN_WORLD_OCCUPIED = 1000
#: Fewest occupied cells for a case's map to count as placeable (linked).
MIN_MAP_WALLS = 20


@dataclass(frozen=True)
class BenchConfig:
    """What the suite contains and how it is scored.

    Attributes
    ----------
    methods : tuple of str
        Method names (:data:`fusionkit.pipeline.METHODS`).
    modes : tuple of str
        ``"explore"`` and/or ``"crop"``.
    robots : tuple of int
        Numbers of maps per case (2 to 5), cycled over the cases.
    cases : int
        Number of cases drawn from the map worlds (a log world adds one case per K besides).
    min_overlap : float
        Least overlap (0..1) linking each map to another.
    max_overlap : float
        Largest overlap of a crop with the window it was drawn beside (0..1).
    poses : int
        Poses per simulated robot (explore).
    range_noise : float
        LIDAR range noise, standard deviation (m) (explore).
    drift : float
        Odometry translation drift (m per square-root metre travelled) (explore).
    drift_theta : float
        Odometry heading drift (rad per square-root metre travelled) (explore).
    cell_noise : float
        Fraction of each crop's wall cells moved to a random neighbouring cell (crop).
    crop_fraction : float
        Side of the crop windows as a fraction of the shorter side of the world's known area.
    max_rotation_deg, max_cells : float
        Success bounds: rotation error (degrees) and centroid displacement (cells).
    seed : int
        Seed of the whole suite.
    """

    methods: tuple = DEFAULT_METHODS
    modes: tuple = MODES
    robots: tuple = (2, 3, 4, 5)
    cases: int = 20
    min_overlap: float = 0.15
    max_overlap: float = 0.85
    poses: int = 1500
    range_noise: float = 0.01
    drift: float = 0.0
    drift_theta: float = 0.0
    cell_noise: float = 0.0
    crop_fraction: float = 0.55
    max_rotation_deg: float = 2.0
    max_cells: float = 3.0
    seed: int = 0

    def __post_init__(self):
        from ..methods import METHODS
        object.__setattr__(self, "methods", names(self.methods))
        object.__setattr__(self, "modes", names(self.modes))
        object.__setattr__(self, "robots", tuple(int(k) for k in self.robots))
        if not self.methods:
            raise InputError("give at least one method to benchmark")
        for m in self.methods:
            if m not in METHODS:
                raise InputError(f"unknown method {m!r}; choose from {', '.join(METHODS)}")
        if len(set(self.methods)) != len(self.methods):
            raise InputError("a method is listed twice; list each once")
        if not self.modes or any(m not in MODES for m in self.modes):
            raise InputError(f"modes must be among {', '.join(MODES)}, got {', '.join(self.modes) or 'none'}")
        if not self.robots or any(not 2 <= k <= 5 for k in self.robots):
            raise InputError(f"robots per case must be between 2 and 5, got {self.robots}")
        if self.cases < 0:
            raise InputError(f"cases must be >= 0, got {self.cases}")
        if not isinstance(self.seed, numbers.Integral) or isinstance(self.seed, bool) or self.seed < 0:
            raise InputError(f"the seed must be a whole number >= 0, got {self.seed!r}")
        if not 0.0 < self.min_overlap < self.max_overlap <= 1.0:
            raise InputError(f"overlaps must satisfy 0 < min ({self.min_overlap}) < max "
                             f"({self.max_overlap}) <= 1")
        if self.poses < 100:
            raise InputError(f"poses per robot must be >= 100, got {self.poses}")
        for name in ("range_noise", "drift", "drift_theta", "cell_noise"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise InputError(f"{name.replace('_', ' ')} must be >= 0, got {v}")
        if self.cell_noise > 0.5:
            raise InputError(f"cell noise is a fraction of wall cells, at most 0.5, got {self.cell_noise}")
        if not 0.1 <= self.crop_fraction <= 1.0:
            raise InputError(f"crop fraction must be in [0.1, 1], got {self.crop_fraction}")
        if self.max_rotation_deg <= 0 or self.max_cells <= 0:
            raise InputError("success bounds must be > 0")
