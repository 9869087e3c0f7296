"""Frames, stamps and 2-D pose algebra of ROS bags: pose interpolation and the transform tree.

Poses are ``(x, y, yaw)`` rows (m, m, rad); only 2-D motion is kept (the heading is the yaw of
each rotation). :class:`_FrameTree` holds the fixed (``/tf_static``) and moving (``/tf``)
transforms between frames and evaluates the pose of one frame in another at given stamps.
"""

from __future__ import annotations

import math
from collections import defaultdict, deque

import numpy as np

from .errors import InputError
from .transform import wrap_angle

__all__ = ["interpolate_poses"]


# -- frames, stamps and pose algebra --------------------------------------------------------------

def _frame(name) -> str:
    """A frame id without the leading '/' ROS 1 allowed."""
    return str(name or "").strip().lstrip("/")


def _same_robot(bag, sensor_frame: str, child: str, odom_topic: str) -> None:
    """Refuse the poses of another robot: the scans' frame and the frame the pose topic locates,
    not linked by a fixed transform, under two namespaces (``robot_1/laser`` and
    ``robot_2/base_link``). Without namespaces the laser is taken to sit at the pose's frame."""
    mine, theirs = _frame(sensor_frame).split("/")[:-1], _frame(child).split("/")[:-1]
    n = min(len(mine), len(theirs))   # the namespaces both frames give (fleet/robot_1/...)
    if n and mine[:n] != theirs[:n]:
        raise InputError(f"{bag}: the scans are in frame {sensor_frame} but {odom_topic} gives the "
                         f"pose of {child}, another robot's, and no /tf_static transform links "
                         f"the two; give the pose topic of {'/'.join(mine)}")


def _stamp_ns(header) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def _yaw(q) -> float:
    """Heading (rad) of a quaternion: its rotation about z."""
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def _compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pose composition ``a (+) b`` of (N, 3) arrays: ``b`` expressed in ``a``'s frame."""
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    out = np.empty_like(a)
    out[:, 0] = a[:, 0] + c * b[:, 0] - s * b[:, 1]
    out[:, 1] = a[:, 1] + s * b[:, 0] + c * b[:, 1]
    out[:, 2] = wrap_angle(a[:, 2] + b[:, 2])
    return out


def _invert(a: np.ndarray) -> np.ndarray:
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    out = np.empty_like(a)
    out[:, 0] = -(c * a[:, 0] + s * a[:, 1])
    out[:, 1] = -(-s * a[:, 0] + c * a[:, 1])
    out[:, 2] = wrap_angle(-a[:, 2])
    return out


def _sort_unique(stamps: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Sort samples by stamp (stable) and keep the last of equal stamps; count descents."""
    descents = int((np.diff(stamps) < 0).sum()) if len(stamps) > 1 else 0
    order = np.argsort(stamps, kind="stable")
    stamps, values = stamps[order], values[order]
    keep = np.ones(len(stamps), bool)
    keep[:-1] = stamps[1:] != stamps[:-1]
    return stamps[keep], values[keep], descents


def interpolate_poses(stamps: np.ndarray, poses: np.ndarray,
                      query: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Poses at ``query`` stamps from samples ``poses`` at increasing ``stamps``.

    ``x`` and ``y`` are interpolated linearly between the bracketing samples, the heading along
    the shorter arc: ``theta = theta_0 + a * wrap(theta_1 - theta_0)``. A query equal to a
    sample's stamp returns that sample.

    Parameters
    ----------
    stamps : (M,) int64
        Sample times (ns), strictly increasing.
    poses : (M, 3) float64
        ``x, y, theta`` per sample.
    query : (N,) int64
        Times (ns) to evaluate.

    Returns
    -------
    out : (N, 3) float64
        Interpolated poses (rows outside the span are zeros).
    inside : (N,) bool
        Whether each query lies within ``[stamps[0], stamps[-1]]``.
    """
    stamps = np.asarray(stamps, dtype=np.int64)
    poses = np.asarray(poses, dtype=np.float64)
    query = np.asarray(query, dtype=np.int64)
    out = np.zeros((len(query), 3))
    if len(stamps) == 0:
        return out, np.zeros(len(query), bool)
    inside = (query >= stamps[0]) & (query <= stamps[-1])
    if len(stamps) == 1:
        out[inside] = poses[0]
        return out, inside
    i0 = np.clip(np.searchsorted(stamps, query, side="right") - 1, 0, len(stamps) - 2)
    i1 = i0 + 1
    a = ((query - stamps[i0]) / (stamps[i1] - stamps[i0]).astype(np.float64))[:, None]
    p0, p1 = poses[i0], poses[i1]
    out[:, :2] = (1.0 - a) * p0[:, :2] + a * p1[:, :2]
    dth = wrap_angle(p1[:, 2] - p0[:, 2])
    th = p0[:, 2] + a[:, 0] * dth
    exact0 = a[:, 0] == 0.0
    exact1 = a[:, 0] == 1.0
    th = np.where(exact0, p0[:, 2], np.where(exact1, p1[:, 2], wrap_angle(th)))
    out[:, 2] = th
    out[~inside] = 0.0
    return out, inside


class _FrameTree:
    """Transforms between frames: fixed ones (``/tf_static``) and moving ones (``/tf``)."""

    def __init__(self):
        self.samples = defaultdict(list)  # (parent, child) -> [(stamp, x, y, yaw)]
        self.static = {}  # (parent, child) -> (x, y, yaw)
        self.descents = 0

    def add(self, parent, child, stamp, pose, static):
        if static:
            self.static[(parent, child)] = pose
        else:
            self.samples[(parent, child)].append((stamp, *pose))

    def frames(self) -> set[str]:
        return {f for e in list(self.samples) + list(self.static) for f in e}

    def _neighbours(self, static_only):
        nb = defaultdict(list)
        edges = list(self.static) + ([] if static_only else list(self.samples))
        for parent, child in edges:
            nb[parent].append((child, (parent, child), False))
            nb[child].append((parent, (parent, child), True))
        return nb

    def path(self, start, goal, static_only=False):
        """Edges from ``start`` to ``goal`` as ``[(edge, inverted)]``, or ``None``."""
        if start == goal:
            return []
        nb = self._neighbours(static_only)
        prev = {start: None}
        queue = deque([start])
        while queue:
            f = queue.popleft()
            for g, edge, inv in nb.get(f, ()):
                if g not in prev:
                    prev[g] = (f, edge, inv)
                    if g == goal:
                        steps = []
                        while prev[g] is not None:
                            f2, e2, i2 = prev[g]
                            steps.append((e2, i2))
                            g = f2
                        return steps[::-1]
                    queue.append(g)
        return None

    def evaluate(self, steps, query) -> tuple[np.ndarray, np.ndarray]:
        """Pose of the chain's last frame in its first frame at ``query`` stamps."""
        total = np.zeros((len(query), 3))
        inside = np.ones(len(query), bool)
        for edge, inv in steps:
            if edge in self.static:
                p = np.tile(np.asarray(self.static[edge], float), (len(query), 1))
            else:
                arr = np.asarray(self.samples[edge], dtype=np.float64)
                st = np.asarray([s[0] for s in self.samples[edge]], dtype=np.int64)
                st, vals, d = _sort_unique(st, arr[:, 1:])
                self.descents += d
                p, ok = interpolate_poses(st, vals, query)
                inside &= ok
            total = _compose(total, _invert(p) if inv else p)
        return total, inside


def _read_tf_message(tree: _FrameTree, msg, stamp_bag: int, static: bool) -> None:
    for tr in msg.transforms:
        stamp = _stamp_ns(tr.header) or stamp_bag
        t, q = tr.transform.translation, tr.transform.rotation
        tree.add(_frame(tr.header.frame_id), _frame(tr.child_frame_id), stamp,
                 (float(t.x), float(t.y), _yaw(q)), static)

