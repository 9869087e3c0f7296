"""fusionkit: multi-robot occupancy-grid map fusion for collaborative SLAM.

The method follows "Map Fusion for Precise Yet Efficient Collaborative SLAM": unique poses by
the DFT of the scans (Algorithm 1), the fusion order by Pearson correlation of their spectra
(eq. 2), the alignment by Particle Swarm Optimization of a mask MSE (eq. 3), then transform
(eq. 4) and fusion (Section 3.6), measured by the paper's Table 1 metrics.

Quick start::

    import fusionkit as fk
    sim = fk.simulate(fk.default_world(), fk.SimulationConfig(robots=3, poses=1500, seed=1))
    result = fk.merge([r.grid for r in sim.robots], scans=[r.scans for r in sim.robots])
    fk.evaluate_map(result.grid, sim.world, sim.robots[0].transform)
"""

from __future__ import annotations

__version__ = "0.1.0"

from .errors import FusionkitError, InputError, MapFormatError, NotMergedError, ScanLogError
from .grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from .transform import Transform2D
from .scanlog import ScanLog, load_scans, save_scans, scans_path_for
from .mapio import load_map, map_info, save_map
from .mapping import MappingConfig, build_grid
from .resample import canvas_for, resample
from .worlds import default_world, make_world
from .simulate import LidarConfig, MotionConfig, Simulation, SimulationConfig, simulate, write_run
from .unique_poses import UniquePoses, find_unique_poses, scan_spectra
from .pairing import agreement, fusion_order, pearson_matrix
from .pso import PSOConfig, PSOResult, pso_minimize
from .alignment import AlignmentConfig, align_points, overlap_score
from .fusion import FusedMap, fuse_cells, fuse_maps
from .metrics import MapMetrics, evaluate_map, table1
from .pipeline import METHODS, MergeCancelled, MergeConfig, MergeEvent, MergeResult, merge

__all__ = [
    "__version__", "FusionkitError", "InputError", "MapFormatError", "NotMergedError",
    "ScanLogError", "OccupancyGrid", "FREE", "OCCUPIED", "UNKNOWN", "Transform2D", "ScanLog",
    "load_scans", "save_scans", "scans_path_for", "load_map", "save_map", "map_info",
    "MappingConfig", "build_grid", "resample", "canvas_for", "default_world", "make_world",
    "LidarConfig", "MotionConfig", "Simulation", "SimulationConfig", "simulate", "write_run",
    "UniquePoses", "find_unique_poses", "scan_spectra", "agreement", "fusion_order",
    "pearson_matrix", "PSOConfig", "PSOResult", "pso_minimize", "AlignmentConfig",
    "align_points", "overlap_score", "FusedMap", "fuse_cells", "fuse_maps", "MapMetrics",
    "evaluate_map", "table1", "METHODS", "MergeCancelled", "MergeConfig", "MergeEvent",
    "MergeResult", "merge",
]
