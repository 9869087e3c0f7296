"""fusionkit: multi-robot occupancy-grid map fusion for collaborative SLAM.

The method follows "Map Fusion for Precise Yet Efficient Collaborative SLAM": unique poses by
the DFT of the scans (Algorithm 1), the fusion order by Pearson correlation of their spectra
(eq. 2), the alignment by Particle Swarm Optimization of a mask MSE (eq. 3), then transform
(eq. 4) and fusion (Section 3.6), measured by the paper's Table 1 metrics.
"""

from __future__ import annotations

__version__ = "0.1.0"

from .errors import FusionkitError, InputError, MapFormatError, NotMergedError, ScanLogError
from .grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from .transform import Transform2D
from .scanlog import ScanLog, load_scans, save_scans, scans_path_for
from .mapping import MappingConfig, build_grid
from .resample import resample, canvas_for

__all__ = [
    "__version__", "FusionkitError", "InputError", "MapFormatError", "NotMergedError",
    "ScanLogError", "OccupancyGrid", "FREE", "OCCUPIED", "UNKNOWN", "Transform2D", "ScanLog",
    "load_scans", "save_scans", "scans_path_for", "MappingConfig", "build_grid", "resample",
    "canvas_for",
]
