"""ROS bags in and out: LaserScan + poses to fusionkit robot logs, simulated runs to bags.

Reading (:func:`read_rosbag`, :func:`import_rosbag`) takes a ROS 1 ``.bag`` file or a ROS 2 bag
directory (SQLite ``.db3`` or ``.mcap`` storage) through the pure-Python ``rosbags`` library. Each
``sensor_msgs/LaserScan`` on the scan topic is paired with the sensor pose at its stamp, from
either

* a pose topic (``nav_msgs/Odometry``, ``geometry_msgs/PoseStamped`` or
  ``geometry_msgs/PoseWithCovarianceStamped``): the pose of the message's child frame in its
  header frame; when ``/tf_static`` holds a fixed transform from that child frame to the scan's
  frame, it is composed on (the laser's mounting), otherwise the laser is taken to sit at the
  child frame; or
* the transform tree on ``/tf`` and ``/tf_static``: the pose of the scan's frame (its
  ``header.frame_id``) in the fixed frame, through every transform on the way; when the scan's
  frame is not in the tree, the pose of the base frame.

Poses are interpolated at the scan stamp between the two bracketing samples: ``x`` and ``y``
linearly, the heading along the shorter arc. Scans outside the span of the pose samples are dropped
and counted. Messages are sorted by their header stamps (a topic whose header stamps are all zero
uses the times the bag recorded them). Readings that are NaN or below ``range_min`` become ``inf``
(no return), as ``slam_gmapping`` treats them; they are counted. Only 2-D motion is kept: the
heading is the yaw of each rotation.

Writing a simulated run as a bag is :mod:`fusionkit.rosbag_export` (:func:`export_rosbag`,
re-exported here); the pose algebra and transform tree are :mod:`fusionkit.rosbag_frames`.
"""

from __future__ import annotations

import os
import re
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Callable, Mapping

import numpy as np

from ._atomic import check_out_dir, made_out_dir
from ._inputs import regular_file
from .errors import InputError
from .io_carmen import (ImportedMap, check_name, check_outputs, default_name, mapping_config,
                        to_own_frame, write_robot_files)
from .mapping import build_grid
from .rosbag_frames import (_compose, _frame, _FrameTree, _read_tf_message, _same_robot, _sort_unique,
                            _stamp_ns, _yaw, interpolate_poses)
from .scanlog import ScanLog
from .transform import Transform2D

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


# -- options and results ------------------------------------------------------------------------
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
    """The bag and, for a ROS 2 bag folder, its files (inputs, never outputs): metadata.yaml,
    the storage files (``.db3``, ``.mcap``, their journals) and what the metadata names; not
    other files in the folder, such as an earlier import written there."""
    p = Path(path)
    files = [p]
    folder = p if p.is_dir() else (p.parent if p.suffix in (".db3", ".mcap") else None)
    if folder is not None and (folder / "metadata.yaml").is_file():
        try:
            names = os.listdir(folder)
        except OSError:
            names = []
        files += [folder / n for n in names if n == "metadata.yaml"
                  or re.search(r"\.(db3|mcap)(-shm|-wal|-journal)?$", n)]
        files += [folder / n for n in _listed_in_metadata(folder / "metadata.yaml")]
    return files


def _listed_in_metadata(metadata: Path) -> list[str]:
    """The file names a ROS 2 bag's metadata.yaml lists (none when it cannot be read)."""
    from .map_yaml import _safe_yaml
    try:
        doc = _safe_yaml(metadata.read_bytes()[: 1 << 22])
        info = doc.get("rosbag2_bagfile_information", {}) if isinstance(doc, dict) else {}
        named = list(info.get("relative_file_paths") or [])
        named += [f.get("path") for f in info.get("files") or [] if isinstance(f, dict)]
    except Exception:  # noqa: BLE001 - an unreadable metadata.yaml is said by the reader
        return []
    return [n for n in named if isinstance(n, str) and n and "\x00" not in n]


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
            raise InputError(f"{path}: not a readable ROS bag ({_msg(exc)}); give a ROS 1 .bag "
                             f"file or a ROS 2 bag's folder") from None

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
    if any(isinstance(e, UnicodeError) for e in (exc, exc.__context__)):  # a decoder's words
        return "bytes where a ROS bag holds text"
    text = str(exc) if not exc.args else " ".join(str(a) for a in exc.args)
    text = text.splitlines()[0] if text else type(exc).__name__
    return text if len(text) <= 200 else text[:200] + "..."


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
        if steps:   # the laser's mounting
            pose = _compose(pose, tree.evaluate(steps, stamps)[0])
        else:   # the laser taken to sit at the pose's frame: of the same robot
            _same_robot(path, sensor_frame, child, source.odom_topic)
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
    nm = check_name(default_name(path) if name is None else name)
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
    with made_out_dir(out_dir):
        robot = write_robot_files(out_dir, nm, own, grid, t)
    return BagImport(bag.stats, robot, robot.files)



from .rosbag_export import BagExport, ExportedRobot, _MsgFactory, export_rosbag  # noqa: E402,F401
