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

import dataclasses
import json
import math
import os
import shutil
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
from scipy import ndimage

from ._atomic import check_not_input, write_text_atomic
from ._jit import njit, pjit, prange
from .errors import FusionkitError, InputError
from .grid import OccupancyGrid
from .mapping import MappingConfig, build_grid
from .raycast import cast_rays
from .resample import resample
from .scanlog import ScanLog, save_scans
from .transform import Transform2D, wrap_angle

__all__ = ["LidarConfig", "MotionConfig", "SimulationConfig", "RobotRun", "Simulation",
           "Coverage", "simulate", "cast_scans", "write_run", "MOTION_MODES", "MAX_BEAM_VALUES"]

#: Motion models of :class:`MotionConfig`.
MOTION_MODES = ("waypoint", "wander")
#: Largest number of recorded range values (robots x poses x beams) one simulation may hold.
MAX_BEAM_VALUES = 500_000_000
#: Scans cast per kernel call (bounds memory and paces the progress callback).
_CHUNK = 2500


def _num(value, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise InputError(f"{name} must be a finite number, got {value!r}")
    return v


def _int(value, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        if isinstance(value, float) and value.is_integer():
            return int(value)
        raise InputError(f"{name} must be a whole number, got {value!r}")
    return int(value)


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


@dataclass(frozen=True)
class MotionConfig:
    """How the robots move and how good their odometry is.

    Attributes
    ----------
    mode : {"waypoint", "wander"}
        Random-waypoint walk along shortest paths, or a smooth random walk that turns away
        from walls (see the module notes).
    speed : float
        Forward speed (m/s), > 0.
    scan_period : float
        Time between two recorded poses (s), > 0; a step is ``speed * scan_period`` m.
    max_turn_rate : float
        Largest turn rate (rad/s).
    turn_noise : float
        Standard deviation of the random heading change per step (rad).
    clearance : float
        Least distance (m, cell centre to cell centre) the robot keeps from occupied and
        unknown cells.
    start_clearance : float
        Least distance (m) of a start position from occupied and unknown cells.
    lookahead : float
        Distance (m) of the carrot point ("waypoint") or of the wall probe ("wander").
    drift_xy : float
        Odometry translation error (m) accumulated per square-root metre travelled: after
        ``d`` metres the position error has a standard deviation of about
        ``drift_xy * sqrt(d)`` per axis. 0 (default) means perfect odometry.
    drift_theta : float
        Odometry heading error (rad) per square-root metre travelled. 0 by default.
    """

    mode: str = "waypoint"
    speed: float = 0.5
    scan_period: float = 0.2
    max_turn_rate: float = 2.0
    turn_noise: float = 0.05
    clearance: float = 0.3
    start_clearance: float = 0.6
    lookahead: float = 1.5
    drift_xy: float = 0.0
    drift_theta: float = 0.0

    def __post_init__(self):
        mode = str(self.mode).lower()
        if mode not in MOTION_MODES:
            raise InputError(f"motion mode {self.mode!r} is unknown; use one of {', '.join(MOTION_MODES)}")
        object.__setattr__(self, "mode", mode)
        checks = (
            ("speed", "robot speed", 0.0, 10.0, True, "m/s"),
            ("scan_period", "scan period", 0.0, 10.0, True, "s"),
            ("max_turn_rate", "max turn rate", 0.0, 100.0, True, "rad/s"),
            ("turn_noise", "turn noise", 0.0, math.pi, False, "rad"),
            ("clearance", "clearance", 0.0, 10.0, False, "m"),
            ("start_clearance", "start clearance", 0.0, 20.0, False, "m"),
            ("lookahead", "lookahead", 0.0, 20.0, True, "m"),
            ("drift_xy", "odometry drift_xy", 0.0, 1.0, False, "m per sqrt(m)"),
            ("drift_theta", "odometry drift_theta", 0.0, 1.0, False, "rad per sqrt(m)"),
        )
        for attr, label, lo, hi, open_lo, unit in checks:
            v = _num(getattr(self, attr), label)
            if not ((v > lo) if open_lo else (v >= lo)) or v > hi:
                raise InputError(f"{label} must be {'>' if open_lo else '>='} {lo:g} and <= {hi:g} "
                                 f"{unit}, got {v:g}")
            object.__setattr__(self, attr, v)
        if self.step > 5.0:
            raise InputError(f"a step of {self.step:g} m (speed x scan period) is too long to simulate "
                             f"a LIDAR robot; lower the speed or the scan period")

    @property
    def step(self) -> float:
        """Distance travelled per recorded pose (m)."""
        return self.speed * self.scan_period


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


# ---------------------------------------------------------------------------------------------
# Motion kernels (cell units: x = continuous column, y = continuous row)
# ---------------------------------------------------------------------------------------------
@njit
def _wrap(a):
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@njit
def _free_at(nav, x, y):
    c = int(math.floor(x))
    r = int(math.floor(y))
    if r < 0 or c < 0 or r >= nav.shape[0] or c >= nav.shape[1]:
        return False
    return nav[r, c] != 0


@njit
def _clear_line(nav, x0, y0, x1, y1):
    """True when every point of the segment (sampled every half cell) lies in a navigable cell."""
    d = math.hypot(x1 - x0, y1 - y0)
    n = int(math.ceil(d / 0.5)) + 1
    for k in range(n + 1):
        t = k / n
        if not _free_at(nav, x0 + t * (x1 - x0), y0 + t * (y1 - y0)):
            return False
    return True


@njit
def _bfs(nav, gr, gc, dist, queue):
    """4-connected breadth-first distances (cells) from the goal cell over navigable cells;
    -1 where unreachable."""
    rows, cols = nav.shape
    dist[:, :] = -1
    dist[gr, gc] = 0
    queue[0] = gr * cols + gc
    head = 0
    tail = 1
    while head < tail:
        q = queue[head]
        head += 1
        r = q // cols
        c = q - r * cols
        d = dist[r, c] + 1
        for k in range(4):
            rr = r + (1 if k == 0 else (-1 if k == 1 else 0))
            cc = c + (1 if k == 2 else (-1 if k == 3 else 0))
            if 0 <= rr < rows and 0 <= cc < cols and nav[rr, cc] != 0 and dist[rr, cc] < 0:
                dist[rr, cc] = d
                queue[tail] = rr * cols + cc
                tail += 1


@njit
def _carrot(nav, dist, x, y, look, path_r, path_c):
    """The farthest point, at most ``look`` cells down the distance field from the robot, that
    the robot can reach in a straight line (returns cell-centre coordinates x, y)."""
    rows, cols = nav.shape
    cr = int(math.floor(y))
    cc = int(math.floor(x))
    k = 0
    path_r[0] = cr
    path_c[0] = cc
    for _ in range(look):
        d = dist[cr, cc]
        if d <= 0:
            break
        best = d
        br = -1
        bc = -1
        for dr in range(-1, 2):
            for dc in range(-1, 2):
                if dr == 0 and dc == 0:
                    continue
                rr = cr + dr
                c2 = cc + dc
                if rr < 0 or c2 < 0 or rr >= rows or c2 >= cols:
                    continue
                v = dist[rr, c2]
                if v < 0 or v >= best:
                    continue
                if dr != 0 and dc != 0 and (dist[cr + dr, cc] < 0 or dist[cr, cc + dc] < 0):
                    continue  # no corner cutting
                best = v
                br = rr
                bc = c2
        if br < 0:
            break
        cr = br
        cc = bc
        k += 1
        path_r[k] = cr
        path_c[k] = cc
    for j in range(k, 0, -1):
        tx = path_c[j] + 0.5
        ty = path_r[j] + 0.5
        if _clear_line(nav, x, y, tx, ty):
            return tx, ty
    j = 1 if k >= 1 else 0
    return path_c[j] + 0.5, path_r[j] + 0.5


@njit
def _open_direction(nav, x, y, th, reach, u):
    """Of 16 headings (rotated by ``u`` of a sector), the one with the longest straight free
    run (up to ``reach`` cells); ties go to the heading closest to ``th``."""
    best = -1.0
    best_a = th + math.pi
    for k in range(16):
        a = th + (k + u) * (2.0 * math.pi / 16.0)
        ca = math.cos(a)
        sa = math.sin(a)
        run = 0.0
        while run < reach and _free_at(nav, x + (run + 0.5) * ca, y + (run + 0.5) * sa):
            run += 0.5
        score = run - 0.01 * abs(_wrap(a - th))
        if score > best:
            best = score
            best_a = a
    return _wrap(best_a)


@njit
def _walk_one(nav, goals, x, y, th, step, max_turn, turn_noise, look, reach, wander,
              u_goal, n_turn, u_misc, out):
    """One robot's trajectory in cell units; ``out`` (P, 3) receives x, y, theta."""
    rows, cols = nav.shape
    n = out.shape[0]
    ng = goals.shape[0]
    dist = np.empty((rows, cols), np.int32)
    queue = np.empty(rows * cols, np.int32)
    path_r = np.empty(look + 1, np.int64)
    path_c = np.empty(look + 1, np.int64)
    have_goal = False
    age = 0
    budget = 0
    stuck = 0
    omega = 0.0
    escaping = False
    escape_dir = 0.0
    out[0, 0] = x
    out[0, 1] = y
    out[0, 2] = th
    for i in range(1, n):
        ri = int(math.floor(y))
        ci = int(math.floor(x))
        if wander == 0:
            if have_goal:
                d_here = dist[ri, ci]
                if d_here <= reach or age > budget or stuck > 25:
                    have_goal = False
            if not have_goal:
                g = goals[min(int(u_goal[i] * ng), ng - 1)]
                gr = g // cols
                _bfs(nav, gr, g - gr * cols, dist, queue)
                d0 = dist[ri, ci]
                if d0 > reach:
                    have_goal = True
                    age = 0
                    stuck = 0
                    budget = int(3.0 * d0 / step) + 100
            if have_goal:
                tx, ty = _carrot(nav, dist, x, y, look, path_r, path_c)
                desired = math.atan2(ty - y, tx - x)
            else:
                desired = th
            err = _wrap(desired - th)
            turn = min(max(err, -max_turn), max_turn) + turn_noise * n_turn[i]
            th = _wrap(th + turn)
            v = step * max(0.0, math.cos(_wrap(desired - th)))
        else:
            # smooth random turning: the turn rate is an Ornstein-Uhlenbeck process
            omega = 0.85 * omega + turn_noise * n_turn[i]
            ahead = _clear_line(nav, x, y, x + look * math.cos(th), y + look * math.sin(th))
            if ahead and stuck == 0:
                escaping = False
                turn = min(max(omega, -max_turn), max_turn)
                v = step
            else:
                if not escaping or stuck > 2 or abs(_wrap(escape_dir - th)) < 0.05:
                    # turn towards open space: the most open of 16 directions (randomly rotated)
                    escape_dir = _open_direction(nav, x, y, th, 4 * look, u_misc[i])
                    escaping = True
                    stuck = 0
                err = _wrap(escape_dir - th)
                turn = min(max(err, -max_turn), max_turn)
                omega = 0.0
                v = step * max(0.0, math.cos(_wrap(escape_dir - th - turn)))
            th = _wrap(th + turn)
        if v > 0.0:
            nx = x + v * math.cos(th)
            ny = y + v * math.sin(th)
            if _clear_line(nav, x, y, nx, ny):
                x = nx
                y = ny
                stuck = 0
            else:
                stuck += 1
        age += 1
        out[i, 0] = x
        out[i, 1] = y
        out[i, 2] = th


@pjit
def _walk_all(nav, goals, starts, step, max_turn, turn_noise, look, reach, wander,
              u_goal, n_turn, u_misc, out):
    """All robots' trajectories, one robot per thread. ``out`` (R, P, 3)."""
    for k in prange(starts.shape[0]):
        _walk_one(nav, goals, starts[k, 0], starts[k, 1], starts[k, 2], step, max_turn,
                  turn_noise, look, reach, wander, u_goal[k], n_turn[k], u_misc[k], out[k])


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


# ---------------------------------------------------------------------------------------------
# Simulation
# ---------------------------------------------------------------------------------------------
def _navigable(world: OccupancyGrid, motion: MotionConfig):
    """Navigable cells (the largest 4-connected region) and the cells a robot may start in."""
    name = world.name or "the world"
    free = world.free_mask()
    if not free.any():
        raise InputError(f"{name} has no free cells; give a world map with free space to drive in")
    padded = np.pad(free, 1, constant_values=False)
    edt = ndimage.distance_transform_edt(padded)[1:-1, 1:-1]
    res = world.resolution
    nav = edt * res >= max(motion.clearance, 1e-9)
    lab, n = ndimage.label(nav)
    if n == 0:
        raise InputError(
            f"{name} has no free space at least {motion.clearance:g} m from walls; use a smaller "
            f"clearance or a world with wider free areas")
    sizes = np.bincount(lab.ravel())
    sizes[0] = 0
    nav = lab == int(np.argmax(sizes))
    start_ok = nav & (edt * res >= motion.start_clearance)
    return nav, start_ok


def _own_frame_odometry(own: np.ndarray, motion: MotionConfig, rng: np.random.Generator) -> np.ndarray:
    """Odometry poses: the true own-frame increments with random-walk errors (see MotionConfig)."""
    if motion.drift_xy == 0 and motion.drift_theta == 0:
        return own
    th = own[:, 2]
    dp = np.diff(own[:, :2], axis=0)
    c, s = np.cos(th[:-1]), np.sin(th[:-1])
    # increment in the robot frame of the previous pose
    dx = c * dp[:, 0] + s * dp[:, 1]
    dy = -s * dp[:, 0] + c * dp[:, 1]
    dth = wrap_angle(np.diff(th))
    sqrt_d = np.sqrt(np.hypot(dx, dy))  # error variances grow linearly with distance
    e = rng.standard_normal((len(dx), 3))
    dx = dx + motion.drift_xy * sqrt_d * e[:, 0]
    dy = dy + motion.drift_xy * sqrt_d * e[:, 1]
    dth = dth + motion.drift_theta * sqrt_d * e[:, 2]
    th_o = np.concatenate([[0.0], np.cumsum(dth)])
    c, s = np.cos(th_o[:-1]), np.sin(th_o[:-1])
    x = np.concatenate([[0.0], np.cumsum(c * dx - s * dy)])
    y = np.concatenate([[0.0], np.cumsum(s * dx + c * dy)])
    return np.column_stack([x, y, wrap_angle(th_o)])


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


# ---------------------------------------------------------------------------------------------
# Writing a run (CONTRACTS section 5)
# ---------------------------------------------------------------------------------------------
_RUN_SUFFIXES = (".yaml", ".pgm", ".scans.npz")


def _previous_robot_files(out: Path) -> list[Path]:
    """Robot files an earlier run in ``out`` listed in its truth.json."""
    try:
        doc = json.loads((out / "truth.json").read_text(encoding="utf-8"))
        names = [str(r["name"]) for r in doc.get("robots", [])]
    except (OSError, ValueError, TypeError, KeyError, AttributeError):
        return []
    files = []
    for n in names:
        if n and "/" not in n and "\\" not in n and not n.startswith("."):
            files += [out / (n + s) for s in _RUN_SUFFIXES]
    return files


def write_run(sim: Simulation, out_dir, *, world_path=None) -> Path:
    """Write a simulation as CONTRACTS section 5 lays it out, and return the truth.json path.

    Files, in ``out_dir``: per robot ``robot_k.yaml`` + ``robot_k.pgm`` (its map, own frame)
    and ``robot_k.scans.npz`` (its scan log, own frame); ``world.yaml`` + ``world.pgm`` (the
    ground truth); ``truth.json`` with ``world`` (``"world.yaml"``, relative to truth.json),
    ``seed``, ``robots`` (per robot ``name``, ``map``, ``transform`` own frame -> world,
    ``poses``, ``path_length_m``), ``config`` (every setting) and, when ``world_path`` is
    given, ``world_source``.

    Parameters
    ----------
    sim : Simulation
    out_dir : str or os.PathLike
        Must not exist, be empty, or hold an earlier run (a ``truth.json``): that run's files
        are replaced (its robot files that the new run does not write are removed).
    world_path : str or os.PathLike, optional
        The map file the world was loaded from; it is recorded, and never overwritten.

    Raises
    ------
    InputError
        ``out_dir`` is a file, or a non-empty directory without a ``truth.json``, or writing
        would overwrite ``world_path``.

    Notes
    -----
    Everything is first written to a temporary directory beside ``out_dir`` and moved into
    place at the end, ``truth.json`` last; on failure ``out_dir`` is left as it was.
    """
    from .mapio import map_info, save_map

    if not isinstance(sim, Simulation):
        raise InputError(f"write_run needs a Simulation, got {type(sim).__name__}")
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: exists and is not a directory; give a directory for the run")
    previous: list[Path] = []
    if out.is_dir() and any(out.iterdir()):
        if not (out / "truth.json").is_file():
            raise InputError(
                f"{out}: the directory is not empty and holds no truth.json of an earlier run; "
                f"choose a new or empty directory")
        previous = _previous_robot_files(out)
    names = [r.name for r in sim.robots]
    files = [n + s for n in names for s in _RUN_SUFFIXES] + ["world.yaml", "world.pgm", "truth.json"]
    if world_path is not None:
        protected = [Path(world_path)]
        try:
            protected.append(Path(map_info(world_path)["image"]))
        except FusionkitError:  # an unreadable YAML names no image to protect
            pass
        check_not_input([out / f for f in files], protected)

    parent = out.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{out}: cannot create its parent directory ({exc.strerror or exc})") from None
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=parent))
    try:
        os.chmod(tmp, 0o755)  # mkdtemp makes it private; the run directory is an ordinary one
        robots = []
        for r in sim.robots:
            save_map(r.grid, tmp / f"{r.name}.yaml")
            save_scans(tmp / f"{r.name}.scans.npz", r.scans)
            robots.append({"name": r.name, "map": f"{r.name}.yaml",
                           "transform": r.transform.as_dict(digits=9),
                           "poses": int(r.scans.n_scans),
                           "path_length_m": round(r.path_length, 3)})
        world = sim.world.with_data(sim.world.trinary(), name="world")
        save_map(world, tmp / "world.yaml")
        truth = {"world": "world.yaml", "seed": sim.config.seed, "robots": robots}
        if world_path is not None:
            truth["world_source"] = str(world_path)
        cfg = dataclasses.asdict(sim.config)
        if sim.config.mapping is None:
            cfg["mapping"] = dataclasses.asdict(MappingConfig(resolution=sim.world.resolution))
        truth["config"] = cfg
        write_text_atomic(tmp / "truth.json", json.dumps(truth, indent=2) + "\n")

        if not out.exists():
            os.rename(tmp, out)
        else:
            for f in files[:-1]:
                os.replace(tmp / f, out / f)
            keep = {out / f for f in files}
            for p in previous:
                if p not in keep and p.is_file():
                    p.unlink()
            os.replace(tmp / "truth.json", out / "truth.json")
    except OSError as exc:
        raise InputError(f"{out}: the run could not be written ({exc.strerror or exc})") from None
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return out / "truth.json"
