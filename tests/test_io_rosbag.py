"""ROS bags in and out: export a simulated run, import it back, pose pairing, errors, CLI."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fusionkit.errors import InputError
from fusionkit.io_rosbag import (PoseSource, bag_topics, export_rosbag, import_rosbag,
                                 interpolate_poses, read_rosbag)
from fusionkit.mapio import load_map
from fusionkit.scanlog import load_scans
from fusionkit.simulate import LidarConfig, SimulationConfig, simulate, write_run
from fusionkit.transform import wrap_angle
from fusionkit.worlds import make_world


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    """A tiny simulated run: 2 robots, 40 poses, 90 beams, in the smallest office world."""
    world = make_world("office", 1, (16.0, 14.0), 0.1)
    sim = simulate(world, SimulationConfig(robots=2, poses=40, lidar=LidarConfig(beams=90),
                                           seed=3))
    out = tmp_path_factory.mktemp("sim") / "run"
    write_run(sim, out)
    return out


def _pose_error(a, b) -> float:
    d = np.asarray(a, float) - np.asarray(b, float)
    d[:, 2] = wrap_angle(d[:, 2])
    return float(np.abs(d).max())


# -- round trip -------------------------------------------------------------------------------------

@pytest.mark.parametrize("fmt,storage,suffix", [("ros2", "sqlite3", "_bag"),
                                                ("ros2", "mcap", "_mcap"),
                                                ("ros1", "sqlite3", ".bag")])
def test_export_then_import_gives_back_the_scans_and_poses(run_dir, tmp_path, fmt, storage,
                                                           suffix):
    bag = tmp_path / f"run{suffix}"
    res = export_rosbag(run_dir, bag, fmt=fmt, storage=storage)
    assert res.path == bag and bag.exists()
    assert [r.name for r in res.robots] == ["robot_1", "robot_2"]
    assert res.messages == 2 * (3 * 40 + 1)  # scan, odom, tf per scan; one map each
    assert res.duration_s == pytest.approx(3.9)
    topics = bag_topics(bag)
    assert topics["/robot_1/scan"] == "sensor_msgs/msg/LaserScan"
    assert topics["/robot_2/odom"] == "nav_msgs/msg/Odometry"
    assert topics["/robot_1/map"] == "nav_msgs/msg/OccupancyGrid"
    for k in (1, 2):
        orig = load_scans(run_dir / f"robot_{k}.scans.npz")
        for source in (PoseSource(odom_topic=f"/robot_{k}/odom"),
                       PoseSource(use_tf=True, fixed_frame=f"robot_{k}/map")):
            got = read_rosbag(bag, f"/robot_{k}/scan", source)
            assert got.scans.ranges.dtype == np.float32
            np.testing.assert_array_equal(got.scans.ranges, orig.ranges)
            assert _pose_error(got.scans.poses, orig.poses) <= 1e-6
            assert got.scans.angle_min == pytest.approx(orig.angle_min, abs=1e-6)
            assert got.scans.angle_increment == pytest.approx(orig.angle_increment, abs=1e-7)
            assert got.scans.range_max == pytest.approx(orig.range_max, rel=1e-6)
            s = got.stats
            assert (s.scans, s.outside_pose_span, s.other_geometry) == (40, 0, 0)
            assert s.sensor_frame == f"robot_{k}/laser"
            assert s.pose_frame == f"robot_{k}/map"
    # the written map goes out and comes back unchanged
    if fmt == "ros2" and storage == "sqlite3":
        from rosbags.highlevel import AnyReader
        grid = load_map(run_dir / "robot_2.yaml")
        with AnyReader([bag]) as reader:
            conn = [c for c in reader.connections if c.topic == "/robot_2/map"]
            msgs = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(conn)]
        assert len(msgs) == 1
        m = msgs[0]
        assert (m.info.width, m.info.height) == (grid.cols, grid.rows)
        np.testing.assert_array_equal(np.asarray(m.data).reshape(grid.shape), grid.data)
        assert m.info.origin.position.x == pytest.approx(grid.origin[0])


def test_import_rosbag_writes_a_robot_log_and_map(run_dir, tmp_path):
    bag = tmp_path / "b"
    export_rosbag(run_dir, bag)
    res = import_rosbag(bag, tmp_path / "out", scan_topic="/robot_1/scan",
                        poses=PoseSource(odom_topic="/robot_1/odom"), name="r1",
                        resolution=0.1)
    assert {p.name for p in res.files} == {"r1.scans.npz", "r1.yaml", "r1.pgm"}
    orig = load_scans(run_dir / "robot_1.scans.npz")
    got = load_scans(tmp_path / "out" / "r1.scans.npz")
    np.testing.assert_array_equal(got.ranges, orig.ranges)
    assert _pose_error(got.poses, orig.poses) <= 1e-6  # the run starts at its own origin
    grid = load_map(tmp_path / "out" / "r1.yaml")
    ref = load_map(run_dir / "robot_1.yaml")
    assert grid.resolution == ref.resolution
    assert abs(grid.counts()["occupied"] - ref.counts()["occupied"]) <= 0.05 * ref.counts()["occupied"]
    with pytest.raises(InputError, match="r1.yaml and 2 more already exist; "):
        import_rosbag(bag, tmp_path / "out", scan_topic="/robot_1/scan",
                      poses=PoseSource(odom_topic="/robot_1/odom"), name="r1")


def test_export_refuses_existing_output_and_leaves_nothing_on_failure(run_dir, tmp_path,
                                                                      monkeypatch):
    bag = tmp_path / "b"
    bag.mkdir()
    with pytest.raises(InputError, match="already exists"):
        export_rosbag(run_dir, bag)
    with pytest.raises(InputError, match="ends in .bag|ending in .bag"):
        export_rosbag(run_dir, tmp_path / "x", fmt="ros1")
    (tmp_path / "d.bag").symlink_to(tmp_path / "nowhere")   # said to have "appeared while written"
    with pytest.raises(InputError, match=r"d.bag already exists \(a symbolic link to nothing\)"):
        export_rosbag(run_dir, tmp_path / "d.bag", fmt="ros1")
    for name in ("x.db3", "x.mcap"):     # a folder named x.db3 was made, holding x.db3_0.db3
        with pytest.raises(InputError, match=r"a ROS 2 bag is a directory .*without \.(db3|mcap)"):
            export_rosbag(run_dir, tmp_path / name)
        assert not (tmp_path / name).exists()
    with pytest.raises(InputError, match="no NAME.scans.npz"):
        export_rosbag(tmp_path, tmp_path / "y")

    import fusionkit.io_rosbag as io_rosbag
    real = io_rosbag._MsgFactory.scan
    calls = []

    def failing(self, *a, **k):
        calls.append(1)
        if len(calls) > 5:
            raise RuntimeError("disk full")
        return real(self, *a, **k)

    monkeypatch.setattr(io_rosbag._MsgFactory, "scan", failing)
    before = sorted(p.name for p in tmp_path.iterdir())
    for target in (tmp_path / "half_bag", tmp_path / "half.bag"):
        with pytest.raises(RuntimeError):
            export_rosbag(run_dir, target, fmt="ros1" if target.suffix == ".bag" else "ros2")
        calls.clear()
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # no bag, no temporary left


# -- hand-written bags: pairing, frames, stamps ----------------------------------------------------

class _Bag:
    """Writes a ROS 2 (sqlite3) or ROS 1 bag message by message, built from rosbags' types."""

    def __init__(self, path: Path, ros1: bool = False):
        from rosbags.rosbag1 import Writer as W1
        from rosbags.rosbag2 import Writer as W2
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore

        self.ros1 = ros1
        self.ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
        if "tf2_msgs/msg/TFMessage" not in self.ts.types:
            self.ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms",
                                                "tf2_msgs/msg/TFMessage"))
        self.w = W1(path) if ros1 else W2(path, version=9)
        self.w.open()
        self.conns = {}
        self.T = self.ts.types

    def header(self, ns, frame):
        t = self.T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
        if self.ros1:
            return self.T["std_msgs/msg/Header"](seq=0, stamp=t, frame_id=frame)
        return self.T["std_msgs/msg/Header"](stamp=t, frame_id=frame)

    def _quat(self, yaw):
        return self.T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2),
                                                      w=math.cos(yaw / 2))

    def write(self, topic, msgtype, msg, bag_ns):
        if topic not in self.conns:
            self.conns[topic] = self.w.add_connection(topic, msgtype, typestore=self.ts)
        ser = self.ts.serialize_ros1 if self.ros1 else self.ts.serialize_cdr
        self.w.write(self.conns[topic], bag_ns, bytes(ser(msg, msgtype)))

    def scan(self, topic, ns, ranges, frame="laser", range_min=0.1, bag_ns=None,
             angle_min=-1.0, inc=0.5):
        msg = self.T["sensor_msgs/msg/LaserScan"](
            header=self.header(ns, frame), angle_min=angle_min,
            angle_max=angle_min + inc * (len(ranges) - 1), angle_increment=inc,
            time_increment=0.0, scan_time=0.1, range_min=range_min, range_max=10.0,
            ranges=np.asarray(ranges, np.float32), intensities=np.zeros(0, np.float32))
        self.write(topic, "sensor_msgs/msg/LaserScan", msg, ns if bag_ns is None else bag_ns)

    def odom(self, topic, ns, pose, frame="odom", child="base_link", bag_ns=None):
        T = self.T
        pt = T["geometry_msgs/msg/Point"](x=float(pose[0]), y=float(pose[1]), z=0.0)
        p = T["geometry_msgs/msg/Pose"](position=pt, orientation=self._quat(pose[2]))
        v = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
        msg = T["nav_msgs/msg/Odometry"](
            header=self.header(ns, frame), child_frame_id=child,
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=p, covariance=np.zeros(36)),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](linear=v, angular=v),
                covariance=np.zeros(36)))
        self.write(topic, "nav_msgs/msg/Odometry", msg, ns if bag_ns is None else bag_ns)

    def tf(self, topic, ns, parent, child, pose):
        T = self.T
        tr = T["geometry_msgs/msg/Transform"](
            translation=T["geometry_msgs/msg/Vector3"](x=float(pose[0]), y=float(pose[1]), z=0.0),
            rotation=self._quat(pose[2]))
        ts = T["geometry_msgs/msg/TransformStamped"](header=self.header(ns, parent),
                                                     child_frame_id=child, transform=tr)
        self.write(topic, "tf2_msgs/msg/TFMessage", T["tf2_msgs/msg/TFMessage"](transforms=[ts]),
                   ns)

    def close(self):
        self.w.close()


def _naive_interp(stamps, poses, q):
    """Slow reference: find the bracketing samples by a scan, interpolate, wrap."""
    for i in range(len(stamps) - 1):
        if stamps[i] <= q <= stamps[i + 1]:
            a = (q - stamps[i]) / (stamps[i + 1] - stamps[i])
            x = poses[i][0] + a * (poses[i + 1][0] - poses[i][0])
            y = poses[i][1] + a * (poses[i + 1][1] - poses[i][1])
            d = math.atan2(math.sin(poses[i + 1][2] - poses[i][2]),
                           math.cos(poses[i + 1][2] - poses[i][2]))
            th = poses[i][2] + a * d
            return x, y, math.atan2(math.sin(th), math.cos(th))
    return None


def test_interpolate_poses_matches_a_slow_reference():
    rng = np.random.default_rng(5)
    stamps = np.cumsum(rng.integers(1, 10**8, 30)).astype(np.int64)
    poses = np.c_[rng.normal(size=(30, 2)), rng.uniform(-math.pi, math.pi, 30)]
    q = rng.integers(stamps[0] - 10**8, stamps[-1] + 10**8, 200).astype(np.int64)
    q[:5] = stamps[:5]
    q[5] = stamps[-1]
    out, inside = interpolate_poses(stamps, poses, q)
    for qi, oi, ins in zip(q, out, inside):
        ref = _naive_interp(stamps, poses, qi)
        assert ins == (ref is not None)
        if ref is not None:
            assert oi[:2] == pytest.approx(ref[:2], abs=1e-9)
            assert abs(wrap_angle(oi[2] - ref[2])) < 1e-9
    np.testing.assert_array_equal(out[:5], poses[:5])  # a sample's own stamp gives the sample
    np.testing.assert_array_equal(out[5], poses[-1])


@pytest.mark.parametrize("ros1", [False, True])
def test_scans_are_paired_with_interpolated_odometry(tmp_path, ros1):
    path = tmp_path / ("b.bag" if ros1 else "b")
    b = _Bag(path, ros1)
    ms = 10**6
    odom_t = [1000 * ms + 200 * ms * i for i in range(6)]  # 1.0 .. 2.0 s at 5 Hz
    odom_p = [(0.1 * i, -0.2 * i, 2.8 + 0.2 * i) for i in range(6)]  # heading crosses +-pi
    scan_t = [900 * ms + 150 * ms * i for i in range(9)]  # 0.9 .. 2.1 s
    events = [(t, "o", p) for t, p in zip(odom_t, odom_p)] + [(t, "s", None) for t in scan_t]
    # header stamps out of order with respect to the bag's record order
    events.sort(key=lambda e: (e[0] // (300 * ms), -e[0]))
    for k, (t, kind, p) in enumerate(events):
        if kind == "o":
            b.odom("/odom", t, p, bag_ns=10**9 + k)
        else:
            b.scan("/scan", t, [1.0, 2.0, float("nan"), 0.05, 5.0], bag_ns=10**9 + k)
    b.close()
    got = read_rosbag(path, "/scan", PoseSource(odom_topic="/odom"))
    s = got.stats
    inside = [t for t in scan_t if odom_t[0] <= t <= odom_t[-1]]
    assert s.scan_messages == 9 and s.scans == len(inside)
    assert s.outside_pose_span == 9 - len(inside)
    assert s.out_of_order_scans > 0 and s.out_of_order_poses > 0
    assert s.invalid_readings == 2 * 9  # one NaN and one reading below range_min per scan
    np.testing.assert_array_equal(got.stamps, inside)
    ref = np.array([_naive_interp(odom_t, odom_p, t) for t in inside])
    assert _pose_error(got.scans.poses, ref) <= 1e-9
    np.testing.assert_array_equal(got.scans.ranges[0], np.float32([1, 2, np.inf, np.inf, 5]))
    assert got.scans.angle_min == pytest.approx(-1.0) and got.scans.angle_increment == 0.5
    assert s.sensor_frame == "base_link" and s.pose_frame == "odom"


@pytest.mark.parametrize("inverted", [False, True])
def test_tf_chain_and_laser_mounting(tmp_path, inverted):
    path = tmp_path / "tfbag"
    b = _Bag(path)
    ms = 10**6
    mount = (0.2, 0.05, math.pi / 2)  # base_link -> laser, on /tf_static
    if inverted:  # published the other way round: laser -> base_link
        from fusionkit.transform import Transform2D
        inv = Transform2D(*mount).inverse
        b.tf("/tf_static", 500 * ms, "laser", "base_link", (inv.x, inv.y, inv.theta))
    else:
        b.tf("/tf_static", 500 * ms, "base_link", "laser", mount)
    truth = []
    for i in range(5):
        t = 1000 * ms + 100 * ms * i
        base = (0.5 * i, 0.1 * i, 0.3 * i)
        b.tf("/tf", t, "odom", "base_link", base)
        b.odom("/odom", t, base)
        truth.append(base)
    b.tf("/tf", 1000 * ms, "map", "odom", (1.0, 0.0, 0.0))
    b.tf("/tf", 1400 * ms, "map", "odom", (1.0, 0.0, 0.0))
    for i in range(5):
        b.scan("/scan", 1000 * ms + 100 * ms * i, [1.0, 2.0, 3.0])
    b.close()

    def expected(fixed_offset):
        out = []
        for (x, y, th) in truth:
            c, s = math.cos(th), math.sin(th)
            out.append((x + c * mount[0] - s * mount[1] + fixed_offset, y + s * mount[0] + c * mount[1],
                        th + mount[2]))
        return np.array(out)

    for source, offset in ((PoseSource(use_tf=True), 0.0),
                           (PoseSource(use_tf=True, fixed_frame="map"), 1.0),
                           (PoseSource(odom_topic="/odom"), 0.0)):
        got = read_rosbag(path, "/scan", source)
        assert got.stats.sensor_frame == "laser"
        assert _pose_error(got.scans.poses, expected(offset)) <= 1e-9
    with pytest.raises(InputError, match="links neither laser nor base_link to world"):
        read_rosbag(path, "/scan", PoseSource(use_tf=True, fixed_frame="world"))


def test_missing_or_wrong_topic_names_the_bag_topics(run_dir, tmp_path):
    bag = tmp_path / "b.bag"
    export_rosbag(run_dir, bag, fmt="ros1")
    with pytest.raises(InputError) as exc:
        read_rosbag(bag, "/scan", PoseSource(odom_topic="/robot_1/odom"))
    msg = str(exc.value)
    assert "no topic /scan" in msg
    assert "/robot_1/scan (sensor_msgs/msg/LaserScan)" in msg
    assert "/robot_2/odom (nav_msgs/msg/Odometry)" in msg
    with pytest.raises(InputError, match="holds nav_msgs/msg/Odometry, not sensor_msgs"):
        read_rosbag(bag, "/robot_1/odom", PoseSource(odom_topic="/robot_1/odom"))
    with pytest.raises(InputError, match="no topic /odom"):
        read_rosbag(bag, "/robot_1/scan", PoseSource(odom_topic="/odom"))
    with pytest.raises(InputError, match="not found"):
        read_rosbag(tmp_path / "none.bag", "/scan", PoseSource(use_tf=True))
    junk = tmp_path / "junk.bag"
    junk.write_bytes(b"#ROSBAG V2.0\nnot really")
    with pytest.raises(InputError, match="not a readable ROS bag"):
        read_rosbag(junk, "/scan", PoseSource(use_tf=True))
    with pytest.raises(InputError):
        PoseSource(odom_topic="/odom", use_tf=True)


# -- command line ------------------------------------------------------------------------------------

def _main(argv):
    from fusionkit.cli import main
    return main(argv)


def test_cli_export_and_import(run_dir, tmp_path, capsys):
    bag = tmp_path / "run.bag"
    assert _main(["export", "rosbag", str(run_dir), "--out", str(bag)]) == 0
    assert "ros1" in capsys.readouterr().out
    assert _main(["import", "rosbag", str(bag), "--scan-topic", "/robot_2/scan", "--tf",
                  "--fixed-frame", "robot_2/map", "--out", str(tmp_path / "o"),
                  "--resolution", "0.1"]) == 0
    assert "kept 40 scans" in capsys.readouterr().out
    got = load_scans(tmp_path / "o" / "run.scans.npz")
    np.testing.assert_array_equal(got.ranges, load_scans(run_dir / "robot_2.scans.npz").ranges)
    # --quiet, as merge and simulate take it in scripts: nothing printed, the same files
    assert _main(["export", "rosbag", str(run_dir), "--out", str(tmp_path / "q.bag"), "--quiet"]) == 0
    assert _main(["import", "rosbag", str(tmp_path / "q.bag"), "--scan-topic", "/robot_2/scan",
                  "--tf", "--fixed-frame", "robot_2/map", "--out", str(tmp_path / "q"),
                  "--resolution", "0.1", "--quiet"]) == 0
    assert capsys.readouterr() == ("", "")
    assert (tmp_path / "q.bag").read_bytes() == bag.read_bytes()
    np.testing.assert_array_equal(load_scans(tmp_path / "q" / "q.scans.npz").ranges, got.ranges)


@pytest.mark.parametrize("case", ["topic", "bag", "export_exists", "export_ros1_name",
                                  "export_ros1_storage", "export_ros1_format_storage",
                                  "export_past_2_31_ros1", "export_past_2_31_ros2",
                                  "export_late_start"])
def test_cli_bad_input_exits_2_with_one_line(run_dir, tmp_path, capsys, case):
    bag = tmp_path / "b"
    export_rosbag(run_dir, bag)
    argv = {
        "topic": ["import", "rosbag", str(bag), "--scan-topic", "/scan", "--odom-topic", "/odom",
                  "--out", str(tmp_path / "o")],
        "bag": ["import", "rosbag", str(tmp_path / "nope"), "--scan-topic", "/scan", "--tf",
                "--out", str(tmp_path / "o")],
        "export_exists": ["export", "rosbag", str(run_dir), "--out", str(bag)],
        "export_ros1_name": ["export", "rosbag", str(run_dir), "--out", str(tmp_path / "x"),
                             "--format", "ros1"],
        # a ROS 1 bag has no storage plugin: the option is not ignored, it is refused
        "export_ros1_storage": ["export", "rosbag", str(run_dir), "--out", str(tmp_path / "x.bag"),
                                "--storage", "mcap"],
        "export_ros1_format_storage": ["export", "rosbag", str(run_dir), "--out",
                                       str(tmp_path / "x.bag"), "--format", "ros1",
                                       "--storage", "sqlite3"],
        # each option in its range, the last scan's stamp past what a message holds (a traceback)
        "export_past_2_31_ros1": ["export", "rosbag", str(run_dir), "--out", str(tmp_path / "x.bag"),
                                  "--rate", "1e-9"],
        "export_past_2_31_ros2": ["export", "rosbag", str(run_dir), "--out", str(tmp_path / "x"),
                                  "--rate", "1e-9"],
        "export_late_start": ["export", "rosbag", str(run_dir), "--out", str(tmp_path / "x"),
                              "--start", "2147483647", "--rate", "1"],
    }[case]
    assert _main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"fusionkit {argv[0]} rosbag: error: ")
    if case == "topic":
        assert "/robot_1/scan (sensor_msgs/msg/LaserScan)" in err[0]
    assert not (tmp_path / "o").exists() and not (tmp_path / "x").exists()
    assert not (tmp_path / "x.bag").exists()
    if case.endswith("storage"):
        assert "--storage" in err[0] and "ROS 1" in err[0]
    if case.startswith("export_past") or case == "export_late_start":
        assert "2^31 s" in err[0] and "higher rate or an earlier start" in err[0], err
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]   # no temporary left


def test_cli_export_on_a_full_disk_is_one_line_and_leaves_nothing(run_dir, tmp_path, capsys,
                                                                  monkeypatch):
    """The ROS 2 sqlite3 storage reports a full disk as an sqlite3 error, not an OS error."""
    import sqlite3

    import fusionkit.io_rosbag as io_rosbag
    real = io_rosbag._MsgFactory.scan
    calls = []

    def full(self, *a, **k):
        calls.append(1)
        if len(calls) > 5:
            raise sqlite3.OperationalError("database or disk is full")
        return real(self, *a, **k)

    monkeypatch.setattr(io_rosbag._MsgFactory, "scan", full)
    assert _main(["export", "rosbag", str(run_dir), "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("fusionkit export rosbag: error: "), err
    assert "disk is full" in err[0] and "free disk space" in err[0]
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("fmt, out", [("ros1", "b.bag"), ("ros2-mcap", "b")])
def test_cli_export_on_a_full_disk_names_the_output_not_a_temporary(run_dir, tmp_path, capsys,
                                                                    monkeypatch, fmt, out):
    """The ROS 1 and MCAP writers report a full disk as an OS error on their temporary file:
    the line named '.b.bag.4242.x1y2.tmp/b.bag', a file the user never asked for."""
    import errno

    import fusionkit.io_rosbag as io_rosbag
    real = io_rosbag._MsgFactory.scan
    calls = []

    def full(self, *a, **k):
        calls.append(1)
        if len(calls) > 5:
            raise OSError(errno.ENOSPC, "No space left on device",
                          str(tmp_path / f".{out}.4242.x1y2.tmp" / out))
        return real(self, *a, **k)

    monkeypatch.setattr(io_rosbag._MsgFactory, "scan", full)
    args = ["export", "rosbag", str(run_dir), "--out", str(tmp_path / out)]
    args += ["--format", "ros1"] if fmt == "ros1" else ["--storage", "mcap"]
    assert _main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("fusionkit export rosbag: error: "), err
    assert f"{tmp_path / out}:" in err[0] and ".tmp" not in err[0], err
    assert "No space left" in err[0] and "free some disk space" in err[0], err
    assert list(tmp_path.iterdir()) == []


def test_a_file_of_random_bytes_is_refused_without_echoing_them(tmp_path):
    """The error line once held the 60 undecodable bytes of the file, escaped."""
    bag = tmp_path / "rnd.bag"
    bag.write_bytes(np.random.default_rng(0).integers(0, 256, 4000, dtype=np.uint8).tobytes())
    with pytest.raises(InputError) as info:
        import_rosbag(bag, tmp_path / "out", scan_topic="/scan",
                      poses=PoseSource(odom_topic="/odom"))
    assert "not a readable ROS bag" in str(info.value)
    assert "\\x" not in str(info.value) and len(str(info.value)) < 300
    # said in words that tell what to give, not a decoder's ('utf-8' codec can't decode byte)
    assert "codec" not in str(info.value) and "give a ROS 1 .bag" in str(info.value), str(info.value)


def test_a_bag_imported_into_its_own_folder_can_be_imported_there_again(run_dir, tmp_path):
    """The second import, --force or not, was refused: 'this output would overwrite the input
    .../bag/bag.yaml', its own earlier output, taken for a file of the bag."""
    bag = tmp_path / "bag"
    export_rosbag(run_dir, bag, fmt="ros2", storage="sqlite3")
    source = PoseSource(odom_topic="/robot_1/odom")
    import_rosbag(bag, bag, scan_topic="/robot_1/scan", poses=source)
    first = (bag / "bag.yaml").read_bytes()
    with pytest.raises(InputError, match="already exist"):
        import_rosbag(bag, bag, scan_topic="/robot_1/scan", poses=source)
    import_rosbag(bag, bag, scan_topic="/robot_1/scan", poses=source, overwrite=True)
    assert (bag / "bag.yaml").read_bytes() == first
    # the bag's own files stay inputs: an import named after one is refused
    with pytest.raises(InputError, match="overwrite the input"):
        import_rosbag(bag, bag, scan_topic="/robot_1/scan", poses=source, name="metadata",
                      overwrite=True)


def test_an_export_into_a_folder_it_cannot_write_names_the_output_not_a_temporary(run_dir, capsys):
    """It said '/proc/.x_bag.20112.xezcuhzk.tmp': No such file or directory."""
    from fusionkit.cli import main
    assert main(["export", "rosbag", str(run_dir), "--out", "/proc/x_bag"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "/proc/x_bag:" in err and ".tmp" not in err, err


@pytest.mark.parametrize("fmt, out", [("ros1", "b.bag"), ("ros2", "b")])
def test_an_exported_bag_is_on_disk_before_it_takes_its_name(run_dir, tmp_path, monkeypatch, fmt, out):
    """The bag was renamed into place unflushed: a power cut could leave a truncated bag under
    the name asked for."""
    import os

    synced, named = set(), []
    real_fsync, real_rename, real_link = os.fsync, os.rename, os.link

    def fsync(fd):
        synced.add(os.path.realpath(f"/proc/self/fd/{fd}"))
        return real_fsync(fd)

    def rename(src, dst, *a, **k):
        named.append(set(synced))
        return real_rename(src, dst, *a, **k)

    def link(src, dst, *a, **k):
        named.append(set(synced))
        return real_link(src, dst, *a, **k)

    monkeypatch.setattr(os, "fsync", fsync)
    monkeypatch.setattr(os, "rename", rename)
    monkeypatch.setattr(os, "link", link)
    res = export_rosbag(run_dir, tmp_path / out, fmt=fmt)
    monkeypatch.undo()
    bag = tmp_path / out
    files = [bag] if bag.is_file() else [p for p in bag.rglob("*") if p.is_file()]
    assert named and files
    # every file of the bag was flushed under its temporary name before the bag was named
    assert {p.name for p in files} <= {Path(s).name for s in named[-1]}, (files, named[-1])
    assert res.path == bag


def test_the_odometry_of_another_robot_is_refused(run_dir, tmp_path, capsys):
    """``--scan-topic /robot_1/scan --odom-topic /robot_2/odom`` built robot_1's scans along
    robot_2's path, exit 0, unsaid (the frames robot_1/laser and robot_2/... are not linked)."""
    bag = tmp_path / "b.bag"
    export_rosbag(run_dir, bag, fmt="ros1")
    with pytest.raises(InputError, match=r"the scans are in frame robot_1/\S+ but /robot_2/odom gives "
                                         r"the pose of robot_2/\S+, another robot's.*give the pose "
                                         r"topic of robot_1$"):
        read_rosbag(bag, "/robot_1/scan", PoseSource(odom_topic="/robot_2/odom"))
    read_rosbag(bag, "/robot_1/scan", PoseSource(odom_topic="/robot_1/odom"))   # its own: taken
    assert _main(["import", "rosbag", str(bag), "--scan-topic", "/robot_1/scan", "--odom-topic",
                  "/robot_2/odom", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "another robot's" in err and not (tmp_path / "out").exists()


def test_an_export_says_which_robots_of_the_run_it_leaves_out(run_dir, tmp_path, capsys):
    """A run where only robot_1 has its scan log was exported as robot_1 alone, unsaid."""
    import shutil
    part = tmp_path / "part"
    shutil.copytree(run_dir, part)
    (part / "robot_2.scans.npz").unlink()
    assert _main(["export", "rosbag", str(part), "--out", str(tmp_path / "p.bag")]) == 0
    out = capsys.readouterr().out
    assert "not in the bag, no scan log beside their maps: robot_2" in out
    assert _main(["export", "rosbag", str(run_dir), "--out", str(tmp_path / "w.bag")]) == 0
    assert "not in the bag" not in capsys.readouterr().out


def test_a_truth_json_that_is_a_pipe_does_not_hold_the_export(run_dir, tmp_path, capsys):
    """The robots left out were read from truth.json with a plain read: a FIFO there held the
    export for good after its bag was written."""
    import os
    import shutil
    import signal
    part = tmp_path / "part"
    shutil.copytree(run_dir, part)
    (part / "truth.json").unlink()
    os.mkfifo(part / "truth.json")

    class Held(BaseException):   # not an error the command or its reader could take for its own
        pass

    def expired(signum, frame):
        raise Held("the export waited on the pipe")
    old = signal.signal(signal.SIGALRM, expired)
    signal.alarm(20)
    try:
        assert _main(["export", "rosbag", str(part), "--out", str(tmp_path / "p.bag")]) == 0
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
    assert "not in the bag" not in capsys.readouterr().out


@pytest.mark.parametrize("scan, pose, refused", [
    ("robot_1/laser", "robot_2/base_link", True),
    ("fleet/robot_1/laser", "fleet/robot_2/base_link", True),   # namespaces within namespaces
    ("robot_1/laser", "robot_1/base_link", False),
    ("/tb3_0/base_scan", "tb3_0/base_footprint", False),
    ("robot_1/laser", "robot_1/chassis/base_link", False),
    ("laser", "base_link", False),                                # no namespace: the laser sits there
    ("robot_1/laser", "base_link", False),
])
def test_a_pose_frame_is_refused_only_under_another_robots_namespace(scan, pose, refused):
    from fusionkit.rosbag_frames import _same_robot
    if refused:
        with pytest.raises(InputError, match="another robot's"):
            _same_robot("b.bag", scan, pose, "/odom")
    else:
        _same_robot("b.bag", scan, pose, "/odom")
