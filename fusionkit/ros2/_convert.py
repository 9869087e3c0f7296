"""``nav_msgs/msg/OccupancyGrid`` <-> :class:`~fusionkit.grid.OccupancyGrid`, with the checks a
live node needs: a message that cannot be a map is refused with a one-line reason, never
raised through the executor.

Only plain attribute access is used on the messages, so these functions take any object shaped
like the ROS message (the ROS message classes are imported by the callers).
"""

from __future__ import annotations

import array
import math

import numpy as np

from .. import OccupancyGrid, Transform2D

__all__ = ["BadMap", "grid_from_msg", "fill_msg", "yaw_from_quaternion", "quaternion_from_yaw"]


class BadMap(ValueError):
    """A received map that cannot be used; the message is the one-line reason."""


def yaw_from_quaternion(q) -> float:
    """Heading (rad) of a quaternion with fields ``x, y, z, w`` (rotation about z)."""
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def quaternion_from_yaw(q, yaw: float) -> None:
    """Set the quaternion ``q`` (fields ``x, y, z, w``) to a rotation of ``yaw`` rad about z."""
    q.x, q.y, q.z, q.w = 0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0)


def grid_from_msg(msg, *, name: str = "", max_cells: int) -> OccupancyGrid:
    """The grid held by an ``OccupancyGrid`` message.

    Parameters
    ----------
    msg : nav_msgs.msg.OccupancyGrid
        ``info.width`` columns by ``info.height`` rows, row-major ``data`` (row 0 nearest the
        origin, as :class:`~fusionkit.grid.OccupancyGrid` holds it).
    name : str
        Name given to the grid.
    max_cells : int
        Largest ``width * height`` accepted.

    Raises
    ------
    BadMap
        Empty or oversized grid, ``data`` length not ``width * height``, resolution not a
        positive finite number, non-finite origin.
    """
    info = msg.info
    w, h = int(info.width), int(info.height)
    res = float(info.resolution)
    if not (math.isfinite(res) and res > 0):
        raise BadMap(f"resolution {res!r} is not a positive number of metres")
    if w <= 0 or h <= 0:
        raise BadMap(f"the grid is empty ({w} x {h} cells)")
    if w * h > max_cells:
        raise BadMap(f"the grid has {w} x {h} = {w * h} cells, more than max_map_cells "
                     f"({max_cells}); raise max_map_cells if the map is real")
    n = len(msg.data)
    if n != w * h:
        raise BadMap(f"data holds {n} cells but width x height is {w} x {h} = {w * h}")
    p, q = info.origin.position, info.origin.orientation
    origin = (float(p.x), float(p.y), yaw_from_quaternion(q))
    if not all(math.isfinite(v) for v in origin):
        raise BadMap(f"the origin {origin} is not finite")
    data = msg.data
    buf = np.frombuffer(data, dtype=np.int8) if isinstance(data, (array.array, bytes, bytearray)) \
        else np.asarray(data, dtype=np.int8)
    grid = buf.reshape(h, w).copy()
    grid[(grid < -1) | (grid > 100)] = -1  # values outside the convention are unknown
    return OccupancyGrid(grid, res, origin, name)


def fill_msg(msg, grid: OccupancyGrid, frame_id: str, stamp) -> None:
    """Fill an ``OccupancyGrid`` message from ``grid`` (``stamp``: a ``builtin_interfaces/Time``).

    ``data`` is assigned as an ``array('b')``: assigning a numpy array element by element costs
    about 50 times as much for a large map.
    """
    msg.header.frame_id = frame_id
    msg.header.stamp = stamp
    msg.info.map_load_time = stamp
    msg.info.resolution = float(grid.resolution)
    msg.info.width = int(grid.cols)
    msg.info.height = int(grid.rows)
    ox, oy, oyaw = grid.origin
    msg.info.origin.position.x = float(ox)
    msg.info.origin.position.y = float(oy)
    msg.info.origin.position.z = 0.0
    quaternion_from_yaw(msg.info.origin.orientation, float(oyaw))
    msg.data = array.array("b", np.ascontiguousarray(grid.data, dtype=np.int8).tobytes())


def fill_pose(pose, t: Transform2D) -> None:
    """Set a ``geometry_msgs/Pose`` to the transform ``t`` (the frame's origin and heading)."""
    pose.position.x, pose.position.y, pose.position.z = float(t.x), float(t.y), 0.0
    quaternion_from_yaw(pose.orientation, float(t.theta))
