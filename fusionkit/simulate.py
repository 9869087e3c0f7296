"""Multi-robot LIDAR simulation: the data of the paper's Section 4.

N robots start at random free places of a ground-truth world and move about it without any
coordination ("no control or constraints on robot movements", the paper's Section 4), each
recording its pose and a 2-D LIDAR scan at every step. Each robot knows only its own odometry,
so its poses, and the map built from its scans, are in its OWN frame: origin at its start
pose. The true transform from that frame into the world frame is kept for evaluation only.

Motion
    ``"waypoint"`` (default): each robot repeatedly picks a random free goal and drives to it
    along the shortest grid path (breadth-first search over the free space that keeps
    ``clearance`` from walls), steering at a carrot point ``lookahead`` ahead, with random
    heading noise. This random-waypoint walk crosses doors and so explores the building.
    ``"wander"``: a random walk whose turn rate drifts smoothly (an Ornstein-Uhlenbeck
    process) and which turns towards open space when a wall comes within ``lookahead``.
    In both, a step that would bring the robot closer than ``clearance`` to an occupied or
    unknown cell is not taken.

Sensor
    Beams are cast through the world with an exact grid traversal (Amanatides & Woo): occupied
    cells return the beam, free and unknown cells let it pass (in a real map, unknown cells are
    mostly grey fringes of walls and unobserved floor; robots never drive into them). Gaussian
    range noise is added, and beams without a return within ``max_range`` are ``inf``, as in
    ``sensor_msgs/LaserScan``.

Odometry drift
    With ``drift_xy``/``drift_theta`` > 0 each step's odometry increment gets gaussian errors
    whose standard deviation grows with the square root of the distance travelled, so the
    recorded poses (and the maps) bend away from the truth as a real robot's would.

All randomness comes from ``numpy.random.default_rng(seed)``: drawn in Python and passed to the
kernels, so a seed gives identical arrays on every machine and run.
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ._validate import whole as _int
from .errors import InputError
from .grid import OccupancyGrid
from .mapping import MappingConfig, build_grid
from .resample import resample
from .scanlog import ScanLog
from .sim_lidar import LidarConfig, _blocked, _cast, cast_scans
from .sim_motion import MOTION_MODES, MotionConfig, _navigable, _own_frame_odometry, _walk_all
from .transform import Transform2D

__all__ = ["LidarConfig", "MotionConfig", "SimulationConfig", "RobotRun", "Simulation",
           "Coverage", "simulate", "cast_scans", "write_run", "MOTION_MODES", "MAX_BEAM_VALUES"]

#: Largest number of recorded range values (robots x poses x beams) one simulation may hold.
MAX_BEAM_VALUES = 500_000_000
#: Scans cast per kernel call (bounds memory and paces the progress callback).
_CHUNK = 2500



@dataclass(frozen=True)
class SimulationConfig:
    """What to simulate.

    Attributes
    ----------
    robots : int
        Number of robots (1 to 64).
    poses : int
        Poses (and scans) recorded by each robot (10 to 1,000,000).
    lidar : LidarConfig
    motion : MotionConfig
    mapping : MappingConfig or None
        How each robot's scans become its map; ``None`` uses :class:`MappingConfig` defaults
        at the world's resolution.
    seed : int
        Seed of every random draw (>= 0).
    """

    robots: int = 5
    poses: int = 5000
    lidar: LidarConfig = field(default_factory=LidarConfig)
    motion: MotionConfig = field(default_factory=MotionConfig)
    mapping: MappingConfig | None = None
    seed: int = 0

    def __post_init__(self):
        robots = _int(self.robots, "the number of robots")
        if not 1 <= robots <= 64:
            raise InputError(f"the number of robots must be between 1 and 64, got {robots}")
        poses = _int(self.poses, "the number of poses")
        if not 10 <= poses <= 1_000_000:
            raise InputError(f"the number of poses per robot must be between 10 and 1000000, got {poses}")
        seed = _int(self.seed, "the seed")
        if seed < 0:
            raise InputError(f"the seed must be >= 0, got {seed}")
        for attr, cls in (("lidar", LidarConfig), ("motion", MotionConfig)):
            if not isinstance(getattr(self, attr), cls):
                raise InputError(f"{attr} must be a {cls.__name__}, got {type(getattr(self, attr)).__name__}")
        if self.mapping is not None and not isinstance(self.mapping, MappingConfig):
            raise InputError(f"mapping must be a MappingConfig or None, got {type(self.mapping).__name__}")
        values = robots * poses * self.lidar.beams
        if values > MAX_BEAM_VALUES:
            raise InputError(
                f"{robots} robots x {poses} poses x {self.lidar.beams} beams = {values} ranges "
                f"({values * 4 / 1e9:.1f} GB) is more than the {MAX_BEAM_VALUES} fusionkit records; "
                f"use fewer robots, poses or beams")
        object.__setattr__(self, "robots", robots)
        object.__setattr__(self, "poses", poses)
        object.__setattr__(self, "seed", seed)


# ---------------------------------------------------------------------------------------------
# Results
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class RobotRun:
    """What one simulated robot recorded, and the truth about it.

    Attributes
    ----------
    name : str
        ``"robot_k"``, k from 1.
    scans : ScanLog
        Poses (its odometry, in its own frame: the first pose is ``(0, 0, 0)``) and ranges.
    grid : OccupancyGrid
        Its map, built from ``scans``, in its own frame.
    transform : Transform2D
        Maps its own frame into the world frame (its true start pose in the world).
    trajectory : (P, 3) float64
        True poses in the world frame: x, y (m), theta (rad).
    path_length : float
        Distance travelled (m), from the true trajectory.
    """

    name: str
    scans: ScanLog
    grid: OccupancyGrid
    transform: Transform2D
    trajectory: np.ndarray
    path_length: float


@dataclass(frozen=True)
class Coverage:
    """How much of the world the robots' maps know (fractions 0..1 of the world's known
    cells; the completeness of CONTRACTS section 7 with the true transforms)."""

    per_robot: tuple[float, ...]
    combined: float


@dataclass(frozen=True, eq=False)
class Simulation:
    """A simulated multi-robot run: the world, the settings and each robot's data."""

    world: OccupancyGrid
    config: SimulationConfig
    robots: tuple[RobotRun, ...]

    def coverage(self) -> Coverage:
        """Fraction of the world's known cells each robot's map knows once moved into the
        world by its true transform (nearest neighbour), and that all maps together know."""
        known_world = self.world.known_mask()
        total = max(int(known_world.sum()), 1)
        union = np.zeros_like(known_world)
        per = []
        for r in self.robots:
            k = resample(r.grid, r.transform, self.world).known_mask() & known_world
            union |= k
            per.append(float(k.sum()) / total)
        return Coverage(tuple(per), float(union.sum()) / total)




def simulate(world: OccupancyGrid, config: SimulationConfig = SimulationConfig(), *,
             progress: Callable[[int, int], None] | None = None) -> Simulation:
    """Simulate ``config.robots`` robots exploring ``world`` and build each one's map.

    Parameters
    ----------
    world : OccupancyGrid
        Ground truth (map frame = world frame). Robots move in its free cells, keeping
        ``config.motion.clearance`` from occupied and unknown cells, within its largest
        connected free region.
    config : SimulationConfig
    progress : callable, optional
        Called as ``progress(done, total)`` while scans are cast and maps built.

    Returns
    -------
    Simulation
        Per robot: its scan log and map in its own frame (origin at its start pose), the true
        own-frame -> world transform, the true world trajectory and its path length.

    Raises
    ------
    InputError
        A world without free space, or without room for the robots' start positions.
    """
    if not isinstance(world, OccupancyGrid):
        raise InputError(f"the world must be an OccupancyGrid, got {type(world).__name__}")
    if not isinstance(config, SimulationConfig):
        raise InputError(f"config must be a SimulationConfig, got {type(config).__name__}")
    lidar, motion = config.lidar, config.motion
    R, P, B = config.robots, config.poses, lidar.beams
    res = world.resolution
    nav, start_ok = _navigable(world, motion)
    rs, cs = np.nonzero(start_ok)
    if rs.size < R:
        raise InputError(
            f"{world.name or 'the world'} has room for only {rs.size} start position(s) at least "
            f"{motion.start_clearance:g} m from walls, fewer than the {R} robots; use fewer robots, "
            f"a smaller start clearance or a larger world")

    root = np.random.default_rng(config.seed)
    start_rng, *robot_rngs = root.spawn(1 + R)
    streams = [r.spawn(3) for r in robot_rngs]  # per robot: motion, range noise, odometry drift

    pick = start_rng.choice(rs.size, size=R, replace=False)
    jitter = start_rng.uniform(0.25, 0.75, size=(R, 2))
    starts = np.column_stack([cs[pick] + jitter[:, 0], rs[pick] + jitter[:, 1],
                              start_rng.uniform(-math.pi, math.pi, R)])
    u_goal = np.empty((R, P))
    n_turn = np.empty((R, P))
    u_misc = np.empty((R, P))
    for k in range(R):
        g = streams[k][0]
        u_goal[k] = g.random(P)
        n_turn[k] = g.standard_normal(P)
        u_misc[k] = g.random(P)
    goals = np.flatnonzero(nav.ravel()).astype(np.int64)
    out = np.empty((R, P, 3))
    _walk_all(nav.astype(np.uint8), goals, starts, motion.step / res,
              motion.max_turn_rate * motion.scan_period, motion.turn_noise,
              max(1, int(round(motion.lookahead / res))), max(1, int(round(0.5 / res))),
              1 if motion.mode == "wander" else 0, u_goal, n_turn, u_misc, out)
    # cell units (continuous col, row) -> metres in the grid frame -> world (map) frame
    local = out.copy()
    local[..., :2] *= res
    traj = [world.origin_transform.apply_pose(local[k]) for k in range(R)]

    blocked = _blocked(world)
    total = 2 * R * P
    done = 0
    if progress is not None:
        progress(0, total)
    logs = []
    truths = []
    for k in range(R):
        start = Transform2D(*traj[k][0])
        own = start.inverse.apply_pose(traj[k])
        own[0] = 0.0
        poses = _own_frame_odometry(own, motion, streams[k][2])
        ranges = np.empty((P, B), np.float32)
        for a in range(0, P, _CHUNK):
            b = min(P, a + _CHUNK)
            noise = None
            if lidar.range_noise > 0:
                noise = streams[k][1].standard_normal((b - a, B), dtype=np.float32)
                noise *= np.float32(lidar.range_noise)
            ranges[a:b] = _cast(world, blocked, traj[k][a:b], lidar, noise)
            done += b - a
            if progress is not None:
                progress(done, total)
        logs.append(ScanLog(poses, ranges, lidar.angle_min, lidar.angle_increment, lidar.max_range))
        truths.append(start)

    mapping = config.mapping if config.mapping is not None else MappingConfig(resolution=res)
    names = [f"robot_{k + 1}" for k in range(R)]
    grids: list[OccupancyGrid | None] = [None] * R
    # the mapping kernel releases the GIL: build the maps side by side
    workers = max(1, min(R, os.cpu_count() or 1))
    with ThreadPoolExecutor(max_workers=workers) as pool:
        futures = {pool.submit(build_grid, logs[k], mapping, name=names[k]): k for k in range(R)}
        for fut in futures:
            k = futures[fut]
            grids[k] = fut.result()
            done += P
            if progress is not None:
                progress(done, total)

    robots = []
    for k in range(R):
        steps = np.diff(traj[k][:, :2], axis=0)
        length = float(np.hypot(steps[:, 0], steps[:, 1]).sum())
        traj[k].setflags(write=False)
        robots.append(RobotRun(names[k], logs[k], grids[k], truths[k], traj[k], length))
    return Simulation(world, config, tuple(robots))


from .sim_output import write_run  # noqa: E402  (re-exported: it needs Simulation defined)


from ._callable_module import callable_as  # noqa: E402

# ``fusionkit.simulate`` is this module once it is imported: callable as simulate() all the same
callable_as(__name__, "simulate")
