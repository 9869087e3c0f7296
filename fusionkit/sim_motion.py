"""Robot motion of the simulation: where the robots drive and what their odometry records.

``"waypoint"`` (default): each robot repeatedly picks a random free goal and drives to it along
the shortest grid path (breadth-first search over the free space that keeps ``clearance`` from
walls), steering at a carrot point ``lookahead`` ahead, with random heading noise. This
random-waypoint walk crosses doors and so explores the building. ``"wander"``: a random walk
whose turn rate drifts smoothly (an Ornstein-Uhlenbeck process) and which turns towards open
space when a wall comes within ``lookahead``. In both, a step that would bring the robot closer
than ``clearance`` to an occupied or unknown cell is not taken.

Odometry drift: with ``drift_xy``/``drift_theta`` > 0 each step's odometry increment gets
gaussian errors whose standard deviation grows with the square root of the distance travelled.

The kernels work in cell units (x = continuous column, y = continuous row); all randomness is
drawn by the caller and passed in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ._jit import njit, pjit, prange
from ._validate import number as _num
from .errors import InputError
from .grid import OccupancyGrid
from .transform import wrap_angle

__all__ = ["MotionConfig", "MOTION_MODES"]

#: Motion models of :class:`MotionConfig`.
MOTION_MODES = ("waypoint", "wander")


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

