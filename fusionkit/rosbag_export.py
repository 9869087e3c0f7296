"""Simulated runs written as ROS bags (ROS 1 ``.bag`` or ROS 2 folders) with ``rosbags``.

:func:`export_rosbag` turns a simulated run (``robot_k.scans.npz`` and maps, CONTRACTS section
5) into a bag: per robot ``/NAME/scan`` (``sensor_msgs/LaserScan``, frame ``NAME/laser``),
``/NAME/odom`` (``nav_msgs/Odometry``: the laser's pose in ``NAME/map``), ``/NAME/map``
(``nav_msgs/OccupancyGrid``, once, at the first stamp) and the same pose on ``/tf``
(``NAME/map`` -> ``NAME/laser``), stamped at a fixed rate from a common start time. The bag is
written in a temporary folder beside the output and moved into place when complete; the
temporary folders of killed exports are removed by the next export or other write into that
folder, or read of a map there (whatever its name).
"""

from __future__ import annotations

import math
import os
import re
import shutil
import sqlite3
import tempfile
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from ._atomic import check_writable, recover_folder
from ._guards import _write_error
from .errors import InputError
from .scanlog import ScanLog, load_scans

__all__ = ["ExportedRobot", "BagExport", "export_rosbag"]

ProgressFn = Callable[[int, int, str], None]


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
        what = "is a file, not a run directory" if run_dir.is_file() else \
            "is not a folder; give a run directory"
        raise InputError(f"{run_dir}: {what} (fusionkit simulate --out DIR)" if run_dir.exists()
                         else f"{run_dir}: run directory not found")
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
    if not ros1 and out.suffix in (".bag", ".db3", ".mcap"):
        # a folder named x.db3 holding x.db3_0.db3 is not what the name asks for
        raise InputError(f"{out}: a ROS 2 bag is a directory (its {out.suffix} files are written "
                         f"inside); give the directory's name, without {out.suffix}"
                         + (" (--storage mcap chooses MCAP files)" if out.suffix == ".mcap" else ""))
    if os.path.lexists(out):   # a dangling symbolic link too: the bag would not take its name
        raise InputError(f"{out} already exists{'' if out.exists() else ' (a symbolic link to nothing)'}; "
                         f"choose another output path")
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(f"{out}: the output directory {parent} does not exist; create it first")
    check_writable([out])
    robots = _run_robots(run_dir)
    n_max = max(log.n_scans for _, log, _ in robots)
    last = _stamp_ns(start_s, rate, n_max - 1)
    if last // 10**9 >= 2**31:   # a stamp's seconds are a 32-bit integer in ROS 1 and ROS 2
        raise InputError(f"the last of {n_max} scans would be stamped {last / 1e9:.3f} s, past 2^31 s "
                         f"(2147483648), the latest time a ROS message holds; give a higher rate or "
                         f"an earlier start")

    recover_folder(parent)   # what killed writes left there: a killed export's folder too
    try:
        tmpdir = Path(tempfile.mkdtemp(prefix=f".{out.name}.{os.getpid()}.", suffix=".tmp",
                                       dir=parent))
    except OSError as exc:   # said of the output asked for, not of the temporary folder
        raise InputError(f"{out}: cannot write in {parent} ({exc.strerror or exc}); check the "
                         f"path and its permissions") from None
    try:
        tmp = tmpdir / out.name
        try:
            result = _write_bag(tmp, robots, ros1, storage, rate, start_s, progress)
        except sqlite3.Error as exc:  # the ROS 2 sqlite3 storage: "database or disk is full"
            raise InputError(f"{out}: the bag could not be written ({exc}); check the free disk "
                             f"space and the folder's permissions") from None
        except OSError as exc:  # the ROS 1 and MCAP writers: said of the bag, not its temporary
            raise _write_error(out, exc) from None
        if out.exists():
            raise InputError(f"{out} appeared while the bag was written; it was left as it was")
        _flush(tmp)   # on disk before it takes its name: a power cut leaves no truncated bag
        if ros1:
            os.link(tmp, out)  # fails rather than replace a file that appeared meanwhile
        else:
            os.rename(tmp, out)
    except FileExistsError:
        raise InputError(f"{out} appeared while the bag was written; it was left as it was") from None
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)
    return BagExport(out, fmt, "bag" if ros1 else storage, result[0], result[1], result[2])


def _flush(bag: Path) -> None:
    """``fsync`` the bag's files (a ROS 1 file, or a ROS 2 folder's) and the folders holding
    them."""
    files = [bag] if bag.is_file() else sorted(p for p in bag.rglob("*") if p.is_file())
    for p in files + sorted({p.parent for p in files}):
        fd = os.open(p, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _stamp_ns(start_s: float, rate: float, i: int) -> int:
    """The stamp (ns) of scan ``i``: ``start_s + i / rate`` seconds."""
    return int(round(start_s * 1e9)) + int(round(i * (1e9 / rate)))


def _write_bag(path: Path, robots, ros1: bool, storage: str, rate: float, start_s: float,
               progress):
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin, Writer as Writer2

    f = _MsgFactory(ros1)
    start = _stamp_ns(start_s, rate, 0)
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
            stamp = _stamp_ns(start_s, rate, i)
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
