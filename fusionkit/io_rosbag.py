"""ROS bags in and out: LaserScan + poses to fusionkit robot logs, simulated runs to bags.

Reading (:func:`read_rosbag`, :func:`import_rosbag`) takes a ROS 1 ``.bag`` file or a ROS 2
bag directory (SQLite ``.db3`` or ``.mcap`` storage) through the pure-Python ``rosbags``
library. Each ``sensor_msgs/LaserScan`` on the scan topic is paired with the sensor pose at its
stamp, from either

* a pose topic (``nav_msgs/Odometry``, ``geometry_msgs/PoseStamped`` or
  ``geometry_msgs/PoseWithCovarianceStamped``): the pose of the message's child frame in its
  header frame; when ``/tf_static`` holds a fixed transform from that child frame to the scan's
  frame, it is composed on (the laser's mounting), otherwise the laser is taken to sit at the
  child frame; or
* the transform tree on ``/tf`` and ``/tf_static``: the pose of the scan's frame (its
  ``header.frame_id``) in the fixed frame, through every transform on the way; when the scan's
  frame is not in the tree, the pose of the base frame.

Poses are interpolated at the scan stamp between the two bracketing samples: ``x`` and ``y``
linearly, the heading along the shorter arc. Scans outside the span of the pose samples are
dropped and counted. Messages are sorted by their header stamps (a topic whose header stamps
are all zero uses the times the bag recorded them). Readings that are NaN or below
``range_min`` become ``inf`` (no return), as ``slam_gmapping`` treats them; they are counted.
Only 2-D motion is kept: the heading is the yaw of each rotation.

Writing (:func:`export_rosbag`) turns a simulated run (``robot_k.scans.npz`` and maps,
CONTRACTS section 5) into a bag: per robot ``/NAME/scan`` (``sensor_msgs/LaserScan``, frame
``NAME/laser``), ``/NAME/odom`` (``nav_msgs/Odometry``: the laser's pose in ``NAME/map``),
``/NAME/map`` (``nav_msgs/OccupancyGrid``, once, at the first stamp) and the same pose on
``/tf`` (``NAME/map`` -> ``NAME/laser``), stamped at a fixed rate from a common start time.
"""

from __future__ import annotations

import math
import os
import re
import shutil
import tempfile
from collections import Counter, defaultdict, deque
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Callable, Mapping

import numpy as np

from ._atomic import check_out_dir, check_writable, make_out_dir
from ._inputs import regular_file
from .errors import InputError
from .io_carmen import (ImportedMap, check_name, check_outputs, default_name, mapping_config,
                        to_own_frame, write_robot_files)
from .mapping import build_grid
from .scanlog import ScanLog, load_scans
from .transform import Transform2D, wrap_angle

__all__ = [
    "PoseSource", "BagStats", "BagLog", "BagImport", "ExportedRobot", "BagExport",
    "read_rosbag", "import_rosbag", "export_rosbag", "interpolate_poses", "bag_topics",
]

ProgressFn = Callable[[int, int, str], None]

SCAN_TYPE = "sensor_msgs/msg/LaserScan"
POSE_TYPES = ("nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped",
              "geometry_msgs/msg/PoseWithCovarianceStamped")
TF_TYPES = ("tf2_msgs/msg/TFMessage", "tf/msg/tfMessage")
TF_TOPICS = ("/tf", "/tf_static")


# -- options and results ----------------------------------------------------------------------------

@dataclass(frozen=True)
class PoseSource:
    """Where the scan poses come from: a pose topic, or the transform tree.

    Attributes
    ----------
    odom_topic : str or None
        A ``nav_msgs/Odometry`` (or ``PoseStamped`` / ``PoseWithCovarianceStamped``) topic.
    use_tf : bool
        Use ``/tf`` and ``/tf_static`` instead of a pose topic.
    fixed_frame : str
        With ``use_tf``: the frame the poses are expressed in.
    base_frame : str
        With ``use_tf``: the robot frame used when the scan's own frame is not in the tree;
        with a pose topic: the child frame of ``PoseStamped`` messages.
    """

    odom_topic: str | None = None
    use_tf: bool = False
    fixed_frame: str = "odom"
    base_frame: str = "base_link"

    def __post_init__(self):
        if (self.odom_topic is None) == (not self.use_tf):
            raise InputError("give the poses either as an odometry topic or from tf, not both "
                             "and not neither")
        for name in ("fixed_frame", "base_frame"):
            if not _frame(getattr(self, name)):
                raise InputError(f"{name} must be a frame name, got {getattr(self, name)!r}")


@dataclass(frozen=True)
class BagStats:
    """What reading a bag found.

    Attributes
    ----------
    topics : Mapping[str, str]
        Every topic of the bag and its message type.
    scan_messages, pose_messages, tf_messages : int
        Messages read on the scan topic, the pose topic and ``/tf`` + ``/tf_static``.
    scans : int
        Scans kept (each paired with a pose).
    outside_pose_span : int
        Scans dropped because their stamp lies outside the pose samples' time span (or, with
        tf, outside the span of a moving transform on the way).
    other_geometry : int
        Scans dropped because their beam count or angles differ from the dominant scans'.
    out_of_order_scans, out_of_order_poses : int
        Messages whose stamp was earlier than the previous one's (they are sorted).
    invalid_readings : int
        NaN readings and readings below ``range_min``, turned into ``inf``.
    stamps_from_bag : tuple[str, ...]
        Topics whose header stamps were all zero, timed by the bag's record times instead.
    sensor_frame : str
        Frame whose pose the scan poses are.
    pose_frame : str
        Frame the poses are expressed in.
    """

    topics: Mapping[str, str]
    scan_messages: int
    pose_messages: int
    tf_messages: int
    scans: int
    outside_pose_span: int
    other_geometry: int
    out_of_order_scans: int
    out_of_order_poses: int
    invalid_readings: int
    stamps_from_bag: tuple[str, ...]
    sensor_frame: str
    pose_frame: str


@dataclass(frozen=True, eq=False)
class BagLog:
    """Scans of a bag paired with poses, in time order.

    Attributes
    ----------
    scans : ScanLog
        Poses of the sensor in ``stats.pose_frame`` (m, rad); ranges (m, ``inf`` = no return).
    stamps : (N,) int64
        Scan stamps (ns).
    stats : BagStats
    source : str
    """

    scans: ScanLog
    stamps: np.ndarray
    stats: BagStats
    source: str


@dataclass(frozen=True)
class BagImport:
    """Result of :func:`import_rosbag`: what was read and the robot written."""

    stats: BagStats
    robot: ImportedMap
    files: tuple[Path, ...]


@dataclass(frozen=True)
class ExportedRobot:
    """One robot of an exported bag: its topics and how many scans and maps it holds."""

    name: str
    scan_topic: str
    odom_topic: str
    map_topic: str | None
    scans: int


@dataclass(frozen=True)
class BagExport:
    """Result of :func:`export_rosbag`.

    Attributes
    ----------
    path : Path
        The bag (a ``.bag`` file for ROS 1, a directory for ROS 2).
    format : str
        ``"ros1"`` or ``"ros2"``.
    storage : str
        ``"sqlite3"`` or ``"mcap"`` for ROS 2, ``"bag"`` for ROS 1.
    robots : tuple[ExportedRobot, ...]
    messages : int
        Messages written.
    duration_s : float
        Time from the first to the last stamp (s).
    """

    path: Path
    format: str
    storage: str
    robots: tuple[ExportedRobot, ...]
    messages: int
    duration_s: float


# -- frames, stamps and pose algebra --------------------------------------------------------------

def _frame(name) -> str:
    """A frame id without the leading '/' ROS 1 allowed."""
    return str(name or "").strip().lstrip("/")


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


# -- reading --------------------------------------------------------------------------------------

def _bag_path(path) -> Path:
    p = Path(path)
    if not p.exists():
        raise InputError(f"{p}: bag not found")
    if p.is_file() and p.suffix in (".db3", ".mcap") and (p.parent / "metadata.yaml").is_file():
        return p.parent
    if p.is_dir() and not (p / "metadata.yaml").is_file():
        raise InputError(f"{p}: a ROS 2 bag directory needs its metadata.yaml; is this a bag?")
    if not p.is_dir():
        regular_file(p, "ROS bag")
    if p.is_file() and p.suffix != ".bag":
        raise InputError(f"{p}: not a ROS bag (expected a ROS 1 .bag file or a ROS 2 bag "
                         f"directory)")
    if p.is_dir():
        for f in p.iterdir():
            if f.suffix in (".db3", ".mcap", ".yaml"):
                regular_file(f, "file of the ROS 2 bag")
    return p


def _bag_files(path) -> list[Path]:
    """The bag and, for a ROS 2 bag folder, every file in it (all are inputs, never outputs)."""
    p = Path(path)
    files = [p]
    folder = p if p.is_dir() else (p.parent if p.suffix in (".db3", ".mcap") else None)
    if folder is not None and (folder / "metadata.yaml").is_file():
        try:
            files += [folder / n for n in os.listdir(folder)]
        except OSError:
            pass
    return files


def _reader_errors():
    from rosbags.highlevel import AnyReaderError
    from rosbags.rosbag1 import ReaderError as R1
    from rosbags.rosbag2 import ReaderError as R2
    return (AnyReaderError, R1, R2)


class _Bag:
    """An open bag; errors of the reader become :class:`InputError` naming the bag."""

    def __init__(self, path: Path):
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore

        self.path = path
        self.errors = _reader_errors()
        try:
            self.reader = AnyReader([path], default_typestore=get_typestore(Stores.LATEST))
            self.reader.open()
        except self.errors + (OSError, ValueError, KeyError) as exc:
            raise InputError(f"{path}: not a readable ROS bag ({_msg(exc)})") from None

    def close(self):
        try:
            self.reader.close()
        except Exception:  # closing after a read error must not hide that error
            pass

    def topics(self) -> dict[str, str]:
        return {name: (info.msgtype or "?") for name, info in self.reader.topics.items()}

    def messages(self, topics):
        conns = [c for c in self.reader.connections if c.topic in topics]
        if not conns:
            return
        try:
            for conn, t, raw in self.reader.messages(connections=conns):
                yield conn.topic, conn.msgtype, int(t), self.reader.deserialize(raw, conn.msgtype)
        except self.errors + (OSError, ValueError, KeyError) as exc:
            raise InputError(f"{self.path}: cannot read its messages ({_msg(exc)})") from None


def _msg(exc) -> str:
    text = " ".join(str(a) for a in exc.args) if exc.args else type(exc).__name__
    return text.splitlines()[0] if text else type(exc).__name__


def _topic_list(topics: Mapping[str, str]) -> str:
    if not topics:
        return "the bag has no topics"
    return "the bag has " + ", ".join(f"{t} ({m})" for t, m in sorted(topics.items()))


def bag_topics(path) -> dict[str, str]:
    """Topics of a bag and their message types, ``{topic: "pkg/msg/Type"}``."""
    bag = _Bag(_bag_path(path))
    try:
        return bag.topics()
    finally:
        bag.close()


def _need_topic(path, topics, topic, types, what) -> None:
    if topic not in topics:
        raise InputError(f"{path}: no topic {topic}; {_topic_list(topics)}")
    if topics[topic] not in types:
        raise InputError(f"{path}: topic {topic} holds {topics[topic]}, not {what}")


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


def read_rosbag(path, scan_topic: str, poses: PoseSource, *,
                progress: ProgressFn | None = None) -> BagLog:
    """Read the LaserScans of ``scan_topic`` and pair each with the sensor pose at its stamp.

    Parameters
    ----------
    path : path-like
        ROS 1 ``.bag`` file or ROS 2 bag directory (``.db3`` or ``.mcap`` storage).
    scan_topic : str
        A ``sensor_msgs/LaserScan`` topic.
    poses : PoseSource
        Pose topic or transform tree (see the module notes).
    progress : callable, optional
        ``progress(done, total, label)`` while messages are read.

    Returns
    -------
    BagLog
        Scans in time order with poses in ``stats.pose_frame``.

    Raises
    ------
    InputError
        Missing bag or topic (the message lists the bag's topics and types), a topic of the
        wrong type, no transform path between the frames, or no scan inside the poses' span.
    """
    bag_path = _bag_path(path)
    bag = _Bag(bag_path)
    try:
        return _read(bag, bag_path, scan_topic, poses, progress)
    finally:
        bag.close()


def _read(bag: _Bag, path: Path, scan_topic: str, source: PoseSource, progress) -> BagLog:
    topics = bag.topics()
    _need_topic(path, topics, scan_topic, (SCAN_TYPE,), SCAN_TYPE)
    wanted = {scan_topic}
    if source.odom_topic is not None:
        _need_topic(path, topics, source.odom_topic, POSE_TYPES, " or ".join(POSE_TYPES))
        wanted.add(source.odom_topic)
    tf_topics = [t for t in TF_TOPICS if t in topics and topics[t] in TF_TYPES]
    if source.use_tf and "/tf" not in tf_topics:
        raise InputError(f"{path}: no /tf topic to take poses from; {_topic_list(topics)}")
    wanted.update(tf_topics)

    total = sum(bag.reader.topics[t].msgcount for t in wanted)
    scans: list = []  # (header stamp, bag stamp, frame, key, ranges, range_max)
    pose_msgs: list = []  # (header stamp, bag stamp, parent, child, x, y, yaw)
    tree = _FrameTree()
    counts = Counter()
    invalid = 0
    for done, (topic, msgtype, t_bag, msg) in enumerate(bag.messages(wanted), 1):
        counts[topic] += 1
        if topic == scan_topic:
            r = np.array(msg.ranges, dtype=np.float32)
            rmin = float(msg.range_min)
            bad = np.isnan(r) | (r < rmin) | (r < 0)
            invalid += int(bad.sum())
            r[bad] = np.inf
            key = (len(r), float(np.float32(msg.angle_min)), float(np.float32(msg.angle_increment)))
            scans.append((_stamp_ns(msg.header), t_bag, _frame(msg.header.frame_id), key, r,
                          float(msg.range_max)))
        elif topic == source.odom_topic:
            pose = msg.pose.pose if hasattr(msg.pose, "pose") else msg.pose
            child = _frame(getattr(msg, "child_frame_id", "")) or source.base_frame
            pose_msgs.append((_stamp_ns(msg.header), t_bag, _frame(msg.header.frame_id), child,
                              float(pose.position.x), float(pose.position.y),
                              _yaw(pose.orientation)))
        if topic in tf_topics:
            _read_tf_message(tree, msg, t_bag, static=(topic == "/tf_static"))
        if progress and done % 500 == 0:
            progress(done, total, "reading")
    if progress:
        progress(total, total, "read")

    if not scans:
        raise InputError(f"{path}: topic {scan_topic} has no messages")
    from_bag = []
    scan_stamps = np.array([s[0] for s in scans], dtype=np.int64)
    if not scan_stamps.any():
        scan_stamps = np.array([s[1] for s in scans], dtype=np.int64)
        from_bag.append(scan_topic)

    # Keep the dominant geometry (beam count, angles).
    keys = Counter(s[3] for s in scans)
    best = max(keys.values())
    key = next(s[3] for s in scans if keys[s[3]] == best)
    keep = np.array([s[3] == key for s in scans])
    other_geometry = int((~keep).sum())
    out_of_order_scans = int((np.diff(scan_stamps) < 0).sum()) if len(scans) > 1 else 0
    idx = np.nonzero(keep)[0]
    idx = idx[np.argsort(scan_stamps[idx], kind="stable")]
    stamps = scan_stamps[idx]
    ranges = np.stack([scans[i][4] for i in idx])
    sensor_frame = Counter(scans[i][2] for i in idx).most_common(1)[0][0]
    range_max = Counter(scans[i][5] for i in idx).most_common(1)[0][0]
    n_beams, angle_min, angle_inc = key

    if source.odom_topic is not None:
        if not pose_msgs:
            raise InputError(f"{path}: topic {source.odom_topic} has no messages")
        ps = np.array([p[0] for p in pose_msgs], dtype=np.int64)
        if not ps.any():
            ps = np.array([p[1] for p in pose_msgs], dtype=np.int64)
            from_bag.append(source.odom_topic)
        vals = np.array([p[4:] for p in pose_msgs], dtype=np.float64)
        ps, vals, out_of_order_poses = _sort_unique(ps, vals)
        pose, inside = interpolate_poses(ps, vals, stamps)
        pose_frame = Counter(p[2] for p in pose_msgs).most_common(1)[0][0]
        child = Counter(p[3] for p in pose_msgs).most_common(1)[0][0]
        steps = tree.path(child, sensor_frame, static_only=True) if sensor_frame else None
        if steps:
            offset, _ = tree.evaluate(steps, stamps)
            pose = _compose(pose, offset)
        else:
            sensor_frame = child
    else:
        fixed = source.fixed_frame
        target = sensor_frame
        steps = tree.path(fixed, target) if target else None
        if steps is None:
            target = source.base_frame
            steps = tree.path(fixed, target)
        if steps is None:
            frames = sorted(tree.frames())
            raise InputError(
                f"{path}: the transform tree links neither {sensor_frame or '(no scan frame)'} "
                f"nor {source.base_frame} to {fixed}; its frames are "
                f"{', '.join(frames) if frames else 'none'} (set the fixed and base frames)")
        pose, inside = tree.evaluate(steps, stamps)
        out_of_order_poses = tree.descents
        pose_frame, sensor_frame = fixed, target

    outside = int((~inside).sum())
    if not inside.any():
        raise InputError(f"{path}: none of the {len(stamps)} scans on {scan_topic} lies within "
                         f"the time span of the poses; do the topics come from the same run?")
    log = ScanLog(pose[inside], ranges[inside], angle_min, angle_inc, range_max)
    stats = BagStats(
        topics=MappingProxyType(dict(sorted(topics.items()))),
        scan_messages=counts[scan_topic],
        pose_messages=counts[source.odom_topic] if source.odom_topic else 0,
        tf_messages=sum(counts[t] for t in tf_topics),
        scans=log.n_scans, outside_pose_span=outside, other_geometry=other_geometry,
        out_of_order_scans=out_of_order_scans, out_of_order_poses=int(out_of_order_poses),
        invalid_readings=invalid, stamps_from_bag=tuple(from_bag),
        sensor_frame=sensor_frame, pose_frame=pose_frame)
    st = stamps[inside]
    st.setflags(write=False)
    return BagLog(log, st, stats, str(path))


def import_rosbag(path, out_dir, *, scan_topic: str, poses: PoseSource, name: str | None = None,
                  resolution: float = 0.05, no_return_free: float | None = None,
                  keep_frame: bool = False, overwrite: bool = False,
                  progress: ProgressFn | None = None) -> BagImport:
    """Convert a bag's scans into ``NAME.scans.npz`` + ``NAME.yaml``/``.pgm`` in ``out_dir``.

    Parameters
    ----------
    path : path-like
        The bag.
    out_dir : path-like
        Output directory (created if missing).
    scan_topic : str
        LaserScan topic.
    poses : PoseSource
        Pose topic or transform tree.
    name : str, optional
        File stem (default: the bag's name up to its first dot).
    resolution : float
        Map cell size (m).
    no_return_free : float or None
        Distance (m) a no-return beam marks free in the map; ``None``: up to ``range_max``.
    keep_frame : bool
        Keep the poses in the bag's pose frame; by default they are re-expressed in the frame
        of the first scan (the robot's own map frame, first pose at the origin).
    overwrite : bool
        Replace existing output files.
    progress : callable, optional
        ``progress(done, total, label)``.
    """
    nm = check_name(name or default_name(path))
    out_dir = check_out_dir(out_dir)
    yaml_path = out_dir / f"{nm}.yaml"
    outputs = [yaml_path, yaml_path.with_suffix(".pgm"), out_dir / f"{nm}.scans.npz"]
    check_outputs(outputs, _bag_files(path), overwrite=overwrite)
    bag = read_rosbag(path, scan_topic, poses, progress=progress)
    log = bag.scans
    if keep_frame:
        own, t = log, Transform2D.identity()
    else:
        own, t = to_own_frame(log)
    free = own.range_max if no_return_free is None else no_return_free
    grid = build_grid(own, mapping_config(resolution, free), name=nm)
    make_out_dir(out_dir)
    robot = write_robot_files(out_dir, nm, own, grid, t)
    return BagImport(bag.stats, robot, robot.files)


# -- writing --------------------------------------------------------------------------------------

_ROS_NAME = re.compile(r"[^A-Za-z0-9_]")


def _ros_name(stem: str) -> str:
    """A valid ROS name component from a file stem (``robot_1`` stays ``robot_1``)."""
    n = _ROS_NAME.sub("_", stem)
    return n if n and n[0].isalpha() else f"r{n}"


def _natural_key(path: Path):
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", path.name)]


def _quat(yaw: float):
    return 0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0)


class _MsgFactory:
    """Builds LaserScan, Odometry, OccupancyGrid and TFMessage for one ROS version."""

    def __init__(self, ros1: bool):
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore

        self.ros1 = ros1
        self.ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
        if "tf2_msgs/msg/TFMessage" not in self.ts.types:
            self.ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms",
                                                "tf2_msgs/msg/TFMessage"))
        T = self.ts.types
        self.Time = T["builtin_interfaces/msg/Time"]
        self.Header = T["std_msgs/msg/Header"]
        self.LaserScan = T["sensor_msgs/msg/LaserScan"]
        self.Odometry = T["nav_msgs/msg/Odometry"]
        self.Grid = T["nav_msgs/msg/OccupancyGrid"]
        self.Meta = T["nav_msgs/msg/MapMetaData"]
        self.Pose = T["geometry_msgs/msg/Pose"]
        self.PoseCov = T["geometry_msgs/msg/PoseWithCovariance"]
        self.TwistCov = T["geometry_msgs/msg/TwistWithCovariance"]
        self.Twist = T["geometry_msgs/msg/Twist"]
        self.Point = T["geometry_msgs/msg/Point"]
        self.Quat = T["geometry_msgs/msg/Quaternion"]
        self.Vec = T["geometry_msgs/msg/Vector3"]
        self.Transform = T["geometry_msgs/msg/Transform"]
        self.TStamped = T["geometry_msgs/msg/TransformStamped"]
        self.TF = T["tf2_msgs/msg/TFMessage"]
        self.seq = Counter()

    def serialize(self, msg, msgtype: str) -> bytes:
        if self.ros1:
            return bytes(self.ts.serialize_ros1(msg, msgtype))
        return bytes(self.ts.serialize_cdr(msg, msgtype))

    def header(self, stamp_ns: int, frame: str):
        t = self.Time(sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000)
        if self.ros1:
            self.seq[frame] += 1
            return self.Header(seq=self.seq[frame], stamp=t, frame_id=frame)
        return self.Header(stamp=t, frame_id=frame)

    def pose(self, x, y, yaw):
        qx, qy, qz, qw = _quat(yaw)
        return self.Pose(position=self.Point(x=float(x), y=float(y), z=0.0),
                         orientation=self.Quat(x=qx, y=qy, z=qz, w=qw))

    def scan(self, stamp, frame, log: ScanLog, i: int, scan_time: float):
        return self.LaserScan(
            header=self.header(stamp, frame), angle_min=float(log.angle_min),
            angle_max=float(log.angle_min + log.angle_increment * (log.n_beams - 1)),
            angle_increment=float(log.angle_increment), time_increment=0.0,
            scan_time=float(scan_time), range_min=0.0, range_max=float(log.range_max),
            ranges=np.ascontiguousarray(log.ranges[i], dtype=np.float32),
            intensities=np.zeros(0, np.float32))

    def odometry(self, stamp, frame, child, pose):
        zero = self.Vec(x=0.0, y=0.0, z=0.0)
        return self.Odometry(
            header=self.header(stamp, frame), child_frame_id=child,
            pose=self.PoseCov(pose=self.pose(*pose), covariance=np.zeros(36)),
            twist=self.TwistCov(twist=self.Twist(linear=zero, angular=zero),
                                covariance=np.zeros(36)))

    def tf(self, stamp, frame, child, pose):
        qx, qy, qz, qw = _quat(pose[2])
        tr = self.Transform(translation=self.Vec(x=float(pose[0]), y=float(pose[1]), z=0.0),
                            rotation=self.Quat(x=qx, y=qy, z=qz, w=qw))
        return self.TF(transforms=[self.TStamped(header=self.header(stamp, frame),
                                                 child_frame_id=child, transform=tr)])

    def grid(self, stamp, frame, grid):
        t = self.Time(sec=stamp // 1_000_000_000, nanosec=stamp % 1_000_000_000)
        info = self.Meta(map_load_time=t, resolution=float(grid.resolution), width=grid.cols,
                         height=grid.rows, origin=self.pose(*grid.origin))
        return self.Grid(header=self.header(stamp, frame), info=info,
                         data=np.ascontiguousarray(grid.data.reshape(-1), dtype=np.int8))


def _run_robots(run_dir: Path):
    from .mapio import load_map

    if not run_dir.is_dir():
        raise InputError(f"{run_dir}: run directory not found")
    npzs = sorted(run_dir.glob("*.scans.npz"), key=_natural_key)
    if not npzs:
        raise InputError(f"{run_dir}: no NAME.scans.npz scan logs in this directory; export "
                         f"needs a simulated run (fusionkit simulate --out DIR)")
    robots = []
    seen = set()
    for p in npzs:
        stem = p.name[: -len(".scans.npz")]
        name = _ros_name(stem)
        if name in seen:
            raise InputError(f"{p}: its topic name /{name} clashes with another robot's; "
                             f"rename one of the scan logs")
        seen.add(name)
        log = load_scans(p)
        yaml_path = p.with_name(stem + ".yaml")
        grid = load_map(yaml_path) if yaml_path.is_file() else None
        robots.append((name, log, grid))
    return robots


def _qos_latched():
    from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness,
                                    QosReliability, QosTime)
    zero = QosTime(0, 0)
    return [Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL,
                zero, zero, QosLiveliness.AUTOMATIC, zero, False)]


def export_rosbag(run_dir, out=None, *, fmt: str = "ros2", storage: str = "sqlite3",
                  rate: float = 10.0, start_s: float = 1.0,
                  progress: ProgressFn | None = None) -> BagExport:
    """Write a simulated run (``NAME.scans.npz`` and ``NAME.yaml`` maps) as a ROS bag.

    Scan ``i`` of every robot is stamped ``start_s + i / rate`` seconds; the robot's map is
    published once at ``start_s``. The bag is written under a temporary name beside ``out`` and
    renamed when complete, so a failed export leaves nothing behind.

    Parameters
    ----------
    run_dir : path-like
        Directory with ``NAME.scans.npz`` (and optionally ``NAME.yaml``) per robot.
    out : path-like, optional
        The bag: a ``.bag`` file for ROS 1, a directory for ROS 2. Default: ``RUN_DIR.bag``
        (ros1) or ``RUN_DIR_bag`` (ros2) beside the run directory.
    fmt : {"ros2", "ros1"}
    storage : {"sqlite3", "mcap"}
        ROS 2 storage plugin.
    rate : float
        Scans per second (Hz).
    start_s : float
        Stamp of the first scan (s).
    progress : callable, optional
        ``progress(done, total, label)`` per scan index written.

    Raises
    ------
    InputError
        No scan logs in ``run_dir``, bad options, or ``out`` already exists.
    """
    if fmt not in ("ros1", "ros2"):
        raise InputError(f"bag format must be ros1 or ros2, got {fmt!r}")
    if storage not in ("sqlite3", "mcap"):
        raise InputError(f"ROS 2 storage must be sqlite3 or mcap, got {storage!r}")
    if not (math.isfinite(rate) and 0 < rate <= 10_000):
        raise InputError(f"rate must be between 0 and 10000 Hz, got {rate}")
    if not (math.isfinite(start_s) and 0 <= start_s < 2**31):
        raise InputError(f"start time must be between 0 and 2^31 s, got {start_s}")
    run_dir = Path(run_dir)
    ros1 = fmt == "ros1"
    if out is None:
        base = run_dir.resolve()
        out = base.with_name(base.name + (".bag" if ros1 else "_bag"))
    out = Path(out)
    if ros1 and out.suffix != ".bag":
        raise InputError(f"{out}: a ROS 1 bag is a file ending in .bag")
    if not ros1 and out.suffix == ".bag":
        raise InputError(f"{out}: a ROS 2 bag is a directory; give a name not ending in .bag")
    if out.exists():
        raise InputError(f"{out} already exists; choose another output path")
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(f"{out}: the output directory {parent} does not exist; create it first")
    check_writable([out])
    robots = _run_robots(run_dir)

    _sweep_dead_exports(parent, out.name)
    tmpdir = Path(tempfile.mkdtemp(prefix=f".{out.name}.{os.getpid()}.", suffix=".tmp", dir=parent))
    try:
        tmp = tmpdir / out.name
        result = _write_bag(tmp, robots, ros1, storage, rate, start_s, progress)
        if out.exists():
            raise InputError(f"{out} appeared while the bag was written; it was left as it was")
        if ros1:
            os.link(tmp, out)  # fails rather than replace a file that appeared meanwhile
        else:
            os.rename(tmp, out)
    except FileExistsError:
        raise InputError(f"{out} appeared while the bag was written; it was left as it was") from None
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)
    return BagExport(out, fmt, "bag" if ros1 else storage, result[0], result[1], result[2])


def _sweep_dead_exports(parent: Path, name: str) -> None:
    """Remove the temporary folders of exports to ``name`` whose process is gone (killed)."""
    pattern = re.compile(re.escape(f".{name}.") + r"(\d+)\.[A-Za-z0-9_]+\.tmp")
    try:
        entries = os.listdir(parent)
    except OSError:
        return
    for entry in entries:
        m = pattern.fullmatch(entry)
        if m is None or _alive(int(m.group(1))):
            continue
        shutil.rmtree(parent / entry, ignore_errors=True)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    return True


def _write_bag(path: Path, robots, ros1: bool, storage: str, rate: float, start_s: float,
               progress):
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin, Writer as Writer2

    f = _MsgFactory(ros1)
    start = int(round(start_s * 1e9))
    period = 1e9 / rate
    if ros1:
        writer = Writer1(path)
    else:
        plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
        writer = Writer2(path, version=Writer2.VERSION_LATEST, storage_plugin=plugin)
    T_SCAN, T_ODOM = "sensor_msgs/msg/LaserScan", "nav_msgs/msg/Odometry"
    T_GRID, T_TF = "nav_msgs/msg/OccupancyGrid", "tf2_msgs/msg/TFMessage"
    count = 0
    exported = []
    with writer:
        def conn(topic, msgtype, latched=False):
            if ros1:
                return writer.add_connection(topic, msgtype, typestore=f.ts,
                                             latching=1 if latched else None)
            return writer.add_connection(topic, msgtype, typestore=f.ts,
                                         offered_qos_profiles=_qos_latched() if latched else ())

        tf_conn = conn("/tf", T_TF)
        per = []
        for name, log, grid in robots:
            c_scan = conn(f"/{name}/scan", T_SCAN)
            c_odom = conn(f"/{name}/odom", T_ODOM)
            c_map = conn(f"/{name}/map", T_GRID, latched=True) if grid is not None else None
            per.append((name, log, grid, c_scan, c_odom, c_map))
            exported.append(ExportedRobot(name, f"/{name}/scan", f"/{name}/odom",
                                          f"/{name}/map" if grid is not None else None,
                                          log.n_scans))
        for name, log, grid, _, _, c_map in per:
            if c_map is not None:
                writer.write(c_map, start, f.serialize(f.grid(start, f"{name}/map", grid), T_GRID))
                count += 1
        n_max = max(log.n_scans for _, log, *_ in per)
        for i in range(n_max):
            stamp = start + int(round(i * period))
            for name, log, grid, c_scan, c_odom, _ in per:
                if i >= log.n_scans:
                    continue
                pose = log.poses[i]
                frame, laser = f"{name}/map", f"{name}/laser"
                writer.write(c_scan, stamp, f.serialize(f.scan(stamp, laser, log, i, 1.0 / rate),
                                                        T_SCAN))
                writer.write(c_odom, stamp, f.serialize(f.odometry(stamp, frame, laser, pose),
                                                        T_ODOM))
                writer.write(tf_conn, stamp, f.serialize(f.tf(stamp, frame, laser, pose), T_TF))
                count += 3
            if progress and (i % 200 == 0 or i == n_max - 1):
                progress(i + 1, n_max, "writing")
    duration = int(round((n_max - 1) * period)) / 1e9 if n_max else 0.0
    return tuple(exported), count, duration
