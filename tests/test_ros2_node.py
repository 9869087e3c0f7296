"""The merge node for real: ``fusionkit ros2 play``, the node and a listener in separate
processes talking ROS 2 over loopback only (a random ``ROS_DOMAIN_ID``, discovery limited to
localhost), each process stopped by its handle, every wait bounded."""

import json
import math
import os
import random
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

import fusionkit as fk
# the module path: once imported, the submodule shadows the lazy name fk.simulate
from fusionkit.simulate import SimulationConfig, simulate, write_run

HERE = Path(__file__).parent
FUSIONKIT = [sys.executable, "-c", "import sys; from fusionkit.cli import main; sys.exit(main())"]
MERGE_NODE = [sys.executable, "-m", "fusionkit.ros2", "merge-node"]

BAD_PUBLISHER = textwrap.dedent("""
    import array, itertools, time
    import rclpy
    from nav_msgs.msg import OccupancyGrid
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    rclpy.init()
    node = rclpy.create_node("bad_robot")
    pub = node.create_publisher(OccupancyGrid, "/robot_bad/map", QoSProfile(
        depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE))
    try:
        for k in itertools.count():
            msg = OccupancyGrid()
            msg.info.width, msg.info.height, msg.info.resolution = 100, 80, 0.05
            msg.data = array.array("b", bytes(8000 if k % 2 else 5000))  # 5000: wrong length
            if k % 2:
                msg.info.resolution = float("nan")
            pub.publish(msg)
            time.sleep(0.3)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
""")


SEQUENCE_PUBLISHER = textwrap.dedent("""
    # python -c SCRIPT ROBOT=MAP@SECONDS ...: publish each MAP (a map YAML, or "unknown" for an
    # all-unknown 200 x 200 grid, "free" for an all-free one, "short" for a free one whose data
    # lacks 7 cells, or "none": the topic only) latched
    # on /ROBOT/map, SECONDS
    # after the start, in that order
    import sys, time
    import numpy as np
    import rclpy
    import fusionkit as fk
    from fusionkit.ros2._convert import fill_msg
    from nav_msgs.msg import OccupancyGrid
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    rclpy.init()
    node = rclpy.create_node("sequence")
    qos = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)
    steps = []
    for arg in sys.argv[1:]:
        robot, rest = arg.split("=", 1)
        path, at = rest.rsplit("@", 1)
        grid = (fk.OccupancyGrid(np.full((200, 200), -1 if path == "unknown" else 0, np.int8), 0.1,
                                 (0.0, 0.0, 0.0), robot) if path in ("unknown", "free", "short")
                else None if path == "none" else fk.load_map(path))
        steps.append((float(at), robot, grid, path == "short"))
    pubs, t0 = {}, time.monotonic()
    try:
        for at, robot, grid, short in sorted(steps, key=lambda s: s[0]):
            time.sleep(max(0.0, t0 + at - time.monotonic()))
            if robot not in pubs:
                pubs[robot] = node.create_publisher(OccupancyGrid, f"/{robot}/map", qos)
            if grid is None:
                continue
            msg = OccupancyGrid()
            fill_msg(msg, grid, f"{robot}/map", node.get_clock().now().to_msg())
            if short:
                msg.data = msg.data[:-7]
            pubs[robot].publish(msg)
            print("published", robot, at, flush=True)
        while True:
            time.sleep(0.2)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
""")


class Processes:
    """Processes started for one test, each stopped by its handle (SIGINT, then SIGKILL)."""

    def __init__(self, tmp_path):
        self.tmp = tmp_path
        self.env = {**os.environ,
                    # isolation from other ROS graphs on this machine, not a computation: any
                    # free domain will do
                    "ROS_DOMAIN_ID": str(random.SystemRandom().randint(1, 101)),
                    "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
                    "ROS_LOG_DIR": str(tmp_path / "roslog"),
                    "PYTHONUNBUFFERED": "1"}
        self.procs: dict = {}
        self.codes: dict = {}
        self.killed = False
        self.shm_before = set(Path("/dev/shm").glob("fastdds_*"))

    def start(self, name, argv):
        out = open(self.tmp / f"{name}.log", "w")
        self.procs[name] = subprocess.Popen(argv, stdout=out, stderr=subprocess.STDOUT,
                                            env=self.env, cwd=self.tmp)
        out.close()
        return self.procs[name]

    def log(self, name) -> str:
        return (self.tmp / f"{name}.log").read_text()

    def stop(self, name, timeout=20.0) -> int:
        p = self.procs.pop(name)
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
            try:
                p.wait(timeout)
            except subprocess.TimeoutExpired:
                self.killed = True
                p.kill()
                p.wait(10)
        self.codes[name] = p.returncode
        return p.returncode

    def close(self):
        for name in list(self.procs):
            try:
                self.stop(name)
            except Exception:   # every other process is stopped all the same
                self.killed = True
        if self.killed:
            # Fast DDS removes its shared-memory files on a clean exit; after a kill, remove
            # the new ones that no running process maps any more
            mapped = " ".join(_maps(pid) for pid in os.listdir("/proc") if pid.isdigit())
            for f in set(Path("/dev/shm").glob("fastdds_*")) - self.shm_before:
                if str(f) not in mapped:
                    f.unlink(missing_ok=True)


def _maps(pid: str) -> str:
    try:
        return Path(f"/proc/{pid}/maps").read_text(errors="replace")
    except OSError:
        return ""


@pytest.fixture
def procs(tmp_path):
    p = Processes(tmp_path)
    yield p
    p.close()


@pytest.fixture(scope="module")
def run3(tmp_path_factory):
    sim = simulate(fk.default_world(), SimulationConfig(robots=3, poses=1500, seed=1))
    out = tmp_path_factory.mktemp("ros2") / "run3"
    write_run(sim, out)
    return out


def _records(path: Path, kind: str) -> list:
    if not path.is_file():
        return []
    out = []
    for line in path.read_text().splitlines():
        try:
            d = json.loads(line)
        except ValueError:  # a line being written
            continue
        if d["kind"] == kind:
            out.append(d)
    return out


def _probe(procs, out: Path, *robots: str, name: str = "probe"):
    """Start a listener writing the merged map, the status and the robots' transforms to
    ``out`` (JSON lines)."""
    return procs.start(name, [sys.executable, str(HERE / "_ros2_probe.py"), str(out), *robots])


def _wait(condition, timeout, procs, what):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = condition()
        if value:
            return value
        for name, p in procs.procs.items():
            if p.poll() is not None:
                pytest.fail(f"{name} exited with {p.returncode} while waiting for {what}:\n"
                            f"{procs.log(name)[-3000:]}")
        time.sleep(0.25)
    pytest.fail(f"timed out after {timeout} s waiting for {what}; node log:\n"
                f"{procs.log('node')[-3000:] if (procs.tmp / 'node.log').exists() else ''}")


def test_node_merges_a_played_run_holds_transforms_and_survives_bad_input(procs, run3, tmp_path):
    steps = 6
    probe_out = tmp_path / "probe.jsonl"
    _probe(procs, probe_out, "robot_1", "robot_2", "robot_3", "robot_bad")
    procs.start("node", MERGE_NODE + ["--ros-args", "-p", "discovery_rate:=2.0",
                                      "-p", "estimation_rate:=1.0"])
    procs.start("bad", [sys.executable, "-c", BAD_PUBLISHER])
    procs.start("play", FUSIONKIT + ["ros2", "play", str(run3), "--duration", "30",
                                     "--steps", str(steps)])

    # the malformed robot is refused, once per reason, and its topic vanishing is noticed
    _wait(lambda: "/robot_bad: map refused: data holds 5000" in procs.log("node"), 60, procs,
          "the malformed map to be refused")
    _wait(lambda: "/robot_bad: map refused: resolution nan" in procs.log("node"), 30, procs,
          "the NaN resolution to be refused")
    procs.stop("bad")
    _wait(lambda: "/robot_bad/map has no publisher any more" in procs.log("node"), 30, procs,
          "the vanished topic to be noticed")

    last_maps = {n: fk.load_map(run3 / f"{n}.yaml") for n in ("robot_1", "robot_2", "robot_3")}

    def fused_last_maps():
        """The newest status and merged map once that map is the robots' last maps fused with
        the status's transforms (an estimation made while the last maps came in is not)."""
        sts, maps = _records(probe_out, "status"), _records(probe_out, "map")
        if not sts or not maps:
            return None
        st = sts[-1]["status"]
        robots = st["robots"]
        if not all(robots.get(f"/{n}", {}).get("updates") == steps and robots[f"/{n}"]["placed"]
                   for n in last_maps):
            return None
        ref = st["reference"].strip("/")
        names = [ref] + sorted(set(last_maps) - {ref})
        fused = fk.fuse_maps([last_maps[n] for n in names],
                             [fk.Transform2D.from_dict(robots[f"/{n}"]["transform"])
                              for n in names]).grid
        same = (maps[-1]["known"] == pytest.approx(int(fused.known_mask().sum()), rel=0.01)
                and maps[-1]["occupied"] == pytest.approx(int(fused.occupied_mask().sum()), rel=0.01))
        return same and (st, maps[-1])

    # the merged map arrives: the three last maps fused with the published transforms
    status, merged = _wait(fused_last_maps, 120, procs,
                           "the merged map of the robots' last maps with the held transforms")
    assert procs.procs["node"].poll() is None, "the node stopped"
    assert procs.stop("play") == 0
    assert procs.stop("node") == 0, procs.log("node")[-3000:]
    procs.stop("probe")
    node_log = procs.log("node")
    assert "Traceback" not in node_log

    # logged once per reason, that robot skipped
    assert node_log.count("/robot_bad: map refused: data holds 5000") == 1
    assert node_log.count("/robot_bad: map refused: resolution nan") == 1
    assert status["robots"]["/robot_bad"]["placed"] is False
    assert status["robots"]["/robot_bad"]["map"] is None

    truth = {r["name"]: fk.Transform2D.from_dict(r["transform"])
             for r in json.loads((run3 / "truth.json").read_text())["robots"]}
    reference = status["reference"].strip("/")   # the first robot whose map arrived
    assert reference in truth

    # the merged map is in the world frame and covers what the last maps cover with the true
    # transforms
    assert merged["frame"] == "world"
    names = [reference] + sorted(set(truth) - {reference})
    oracle = fk.fuse_maps([last_maps[n] for n in names],
                          [truth[reference].inverse @ truth[n] for n in names]).grid
    assert merged["known"] == pytest.approx(int(oracle.known_mask().sum()), rel=0.02)

    # every published transform matches the truth within 2 cells and 1 degree
    poses = _records(probe_out, "pose")
    for name in ("robot_1", "robot_2", "robot_3"):
        mine = [fk.Transform2D(p["x"], p["y"], p["theta"]) for p in poses if p["robot"] == name]
        assert mine, f"no transform published for {name}"
        expected = truth[reference].inverse @ truth[name]
        for t in mine:
            dist, ang = t.error_to(expected)
            assert dist <= 2 * 0.1 and ang <= 0.0175, (name, t, expected)
        assert all(p["frame"] == "world" for p in poses if p["robot"] == name)

    # placed once, the placement stays while the map grows: refined (a few cells at most), never
    # switched to another
    for name in {"/robot_1", "/robot_2", "/robot_3"} - {status["reference"]}:
        seen = [(s["status"]["robots"][name]["updates"], s["status"]["robots"][name]["transform"])
                for s in _records(probe_out, "status")
                if s["status"]["robots"].get(name, {}).get("placed")]
        assert seen, f"{name} was never placed"
        assert seen[0][0] < steps, f"{name} was placed only on its last map; nothing to hold"
        first = fk.Transform2D.from_dict(seen[0][1])
        for _, t in seen:
            dist, ang = fk.Transform2D.from_dict(t).error_to(first)
            assert dist <= 6 * 0.1 and ang <= math.radians(2.0), (name, t, seen[0][1])
        assert "switched" not in node_log


@pytest.mark.parametrize("first", ["unknown", "free"])
def test_an_empty_first_map_is_not_the_reference_and_a_pending_switch_is_decided(procs, run3,
                                                                               tmp_path, first):
    """Two ways the node once stood still. A SLAM node's first map is often all unknown: taken
    as the reference (or one of free space without a wall), nothing merged until that robot
    mapped something. A robot placed from a
    wrong map (here robot_2's, published under robot_3) then sending its own map once kept the
    wrong transform for good: the better estimate needed a second estimation, and maps that stop
    changing were never estimated again; then it kept the wrong one until a second estimation
    confirmed the better one, though the wrong one no longer fitted robot_3's map at all."""
    probe_out = tmp_path / "probe.jsonl"
    _probe(procs, probe_out, "robot_1", "robot_2", "robot_3")
    procs.start("node", MERGE_NODE + ["--ros-args", "-p", "discovery_rate:=2.0",
                                      "-p", "estimation_rate:=1.0"])
    # robot_3's wrong map comes after robot_2's (sent at once, either could be the reference),
    # and its own map long enough after it to be placed from the wrong one first
    procs.start("pub", [sys.executable, "-c", SEQUENCE_PUBLISHER, f"robot_1={first}@0",
                        f"robot_2={run3 / 'robot_2.yaml'}@2", f"robot_3={run3 / 'robot_2.yaml'}@4",
                        f"robot_1={run3 / 'robot_1.yaml'}@6", f"robot_3={run3 / 'robot_3.yaml'}@14"])
    truth = {r["name"]: fk.Transform2D.from_dict(r["transform"])
             for r in json.loads((run3 / "truth.json").read_text())["robots"]}

    def settled():
        sts = [s["status"] for s in _records(probe_out, "status")]
        last = sts[-1] if sts else None
        if not last or last["robots"].get("/robot_3", {}).get("updates") != 2:
            return None
        placed = all(last["robots"].get(f"/robot_{i}", {}).get("placed") for i in (1, 2, 3))
        t3 = last["robots"]["/robot_3"]["transform"]
        right = t3 and fk.Transform2D.from_dict(t3).error_to(
            truth["robot_2"].inverse @ truth["robot_3"])[0] <= 0.2
        return placed and right and last

    status = _wait(settled, 150, procs, "every robot placed, robot_3 where its own map lies")
    assert procs.stop("pub") == 0 and procs.stop("node") == 0
    log = procs.log("node")
    assert status["reference"] == "/robot_2"              # the first map with a known cell
    if first == "unknown":  # while robot_1's map held no known cell, its reason was empty
        early = [s["status"]["robots"]["/robot_1"] for s in _records(probe_out, "status")
                 if s["status"]["robots"].get("/robot_1", {}).get("updates") == 1]
        assert early and all("no known cell" in r["reason"] for r in early), \
            [(r["last_decision"], r["reason"]) for r in early]
    # the wrong transform no longer fits robot_3's own map: it is not kept until a better one
    # is confirmed, the new estimate places robot_3 at once
    assert "/robot_3: placed" in log and "(anew, as its placement no longer fits" in log
    assert "Traceback" not in log and "ERROR" not in log
    for name in ("robot_1", "robot_3"):
        dist, ang = fk.Transform2D.from_dict(status["robots"][f"/{name}"]["transform"]).error_to(
            truth["robot_2"].inverse @ truth[name])
        assert dist <= 2 * 0.1 and ang <= math.radians(1.0), (name, dist, ang)


def test_known_init_poses_from_a_map_merge_params_file(procs, run3, tmp_path):
    params = tmp_path / "params.yaml"
    params.write_text(textwrap.dedent("""\
        map_merge:
          ros__parameters:
            merging_rate: 4.0
            discovery_rate: 2.0
            known_init_poses: true
            world_frame: site
            /robot_1/map_merge/init_pose_x: 0.0
            /robot_1/map_merge/init_pose_y: 0.0
            /robot_1/map_merge/init_pose_z: 0.0
            /robot_1/map_merge/init_pose_yaw: 0.0
            /robot_2/map_merge/init_pose_x: -3.0
            /robot_2/map_merge/init_pose_y: 1.0
            /robot_2/map_merge/init_pose_z: 0.0
            /robot_2/map_merge/init_pose_yaw: 1.5
            /robot_3/map_merge/init_pose_x: 2.0
        """))
    probe_out = tmp_path / "probe.jsonl"
    _probe(procs, probe_out, "robot_1", "robot_2", "robot_3")
    procs.start("node", FUSIONKIT + ["ros2", "merge-node", "--params-file", str(params)])
    procs.start("play", FUSIONKIT + ["ros2", "play", str(run3), "--duration", "0", "--steps", "1"])
    _wait(lambda: {p["robot"] for p in _records(probe_out, "pose")} >= {"robot_1", "robot_2"}
          and _records(probe_out, "map"), 60, procs, "the known poses and the merged map")
    # robot_3's pose is half given: as map_merge, that robot is skipped, not the node stopped
    _wait(lambda: "/robot_3: initial pose incomplete: give /robot_3/map_merge/init_pose_y, "
                  "/robot_3/map_merge/init_pose_yaw too" in procs.log("node"), 30, procs,
          "robot_3 to be skipped")

    def skipped():
        sts = [s["status"] for s in _records(probe_out, "status")]
        return next((s for s in reversed(sts) if "/robot_3" in s["robots"]), None)

    status = _wait(skipped, 30, procs, "robot_3 in the status")
    assert status["robots"]["/robot_3"]["last_decision"] == "skipped"
    assert not status["robots"]["/robot_3"]["placed"]
    assert "initial pose incomplete" in status["robots"]["/robot_3"]["reason"]
    assert procs.stop("node") == 0
    assert procs.log("node").count("initial pose incomplete") == 1   # at start, not again when found
    poses = {p["robot"]: p for p in _records(probe_out, "pose")}
    assert (poses["robot_2"]["x"], poses["robot_2"]["y"]) == (-3.0, 1.0)
    assert poses["robot_2"]["theta"] == pytest.approx(1.5)
    assert poses["robot_2"]["frame"] == "site" and "robot_3" not in poses
    assert _records(probe_out, "map")[-1]["frame"] == "site"


@pytest.mark.parametrize("argv, message", [
    (["merge-node", "--ros-args", "-p", "merging_rate:=fast"], "parameter merging_rate: expected a number"),
    (["merge-node", "--ros-args", "-p", "method:=magic"], "parameter method: 'magic' is not a method"),
    (["merge-node", "--params-file", "missing.yaml"], "missing.yaml: parameter file not found"),
    (["merge-node", "--params-file", "broken.yaml"], "broken.yaml: not valid YAML at line 4"),
    (["merge-node", "--ros-args", "--params-file", "broken.yaml"], "broken.yaml: not valid YAML"),
    (["merge-node", "--params-file", "text.yaml"], "this one holds a text"),
    (["merge-node", "--params-file", "alias.yaml"], "uses YAML aliases"),
    (["merge-node", "--params-file", "."], ".: is a folder, not a parameter file"),
    (["merge-node", "--ros-args", "-p"], "ROS arguments '--ros-args -p' not understood"),
    (["play", "nowhere"], "nowhere: not a directory"),
])
def test_bad_input_is_one_line_and_exit_2(procs, argv, message):
    (procs.tmp / "broken.yaml").write_text("map_merge:\n  ros__parameters:\n    merging_rate: [1,\n")
    (procs.tmp / "text.yaml").write_text("just a string\n")  # read by rcl as no parameters at all
    (procs.tmp / "alias.yaml").write_text("a: &x 1\nmap_merge:\n  ros__parameters:\n"
                                          "    merging_rate: *x\n")
    p = procs.start("cmd", FUSIONKIT + ["ros2", *argv])
    assert p.wait(60) == 2
    out = procs.log("cmd").strip().splitlines()
    assert len(out) == 1 and message in out[0], out
    assert " at /" not in out[0]  # no C source place of rcl's


@pytest.mark.parametrize("argv", [["merge-node"], ["play", "RUN", "--duration", "20"]])
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_stopped_while_it_starts_a_ros2_command_ends_with_exit_0(procs, run3, argv, sig):
    """The ROS 2 commands run until stopped and write nothing: a signal that comes while they
    start up (importing ROS, building a run's map steps) ends them as one that comes later."""
    argv = [str(run3) if a == "RUN" else a for a in argv]
    p = procs.start("cmd", FUSIONKIT + ["ros2", *argv])

    def handlers_in_place():   # Python never catches SIGTERM itself: the command's handler does
        status = Path(f"/proc/{p.pid}/status").read_text()
        caught = re.search(r"^SigCgt:\s*([0-9a-f]+)", status, re.M)
        return caught and (int(caught[1], 16) >> (signal.SIGTERM - 1)) & 1

    _wait(handlers_in_place, 30, procs, "the command's signal handlers")
    assert p.poll() is None
    p.send_signal(sig)
    assert p.wait(60) == 0, procs.log("cmd")
    assert "Traceback" not in procs.log("cmd")


def test_robots_already_publishing_are_found_within_seconds_at_the_default_discovery_rate(
        procs, run3):
    """The discovery made as the node starts finds no robot (the ROS graph is not known to it
    yet), and the next one came a whole discovery period later: 20 s at the default rate."""
    procs.start("play", FUSIONKIT + ["ros2", "play", str(run3), "--duration", "0", "--steps", "1"])
    _wait(lambda: "last maps published" in procs.log("play"), 60, procs, "the maps to be published")
    procs.start("node", MERGE_NODE)
    _wait(lambda: "map merging started" in procs.log("node"), 60, procs, "the node to start")
    started = time.monotonic()
    _wait(lambda: all(f"/robot_{k}: subscribed to /robot_{k}/map" in procs.log("node")
                      for k in (1, 2, 3)), 15, procs, "the three robots to be found")
    assert time.monotonic() - started < 15
    assert procs.stop("node") == 0 and procs.stop("play") == 0


def test_the_status_is_published_while_the_reference_robot_is_missing(procs, run3, tmp_path):
    """With ``reference_robot`` naming a robot that never comes, nothing can be placed; the
    status still says which robots are there and that none is placed."""
    probe_out = tmp_path / "probe.jsonl"
    _probe(procs, probe_out, "robot_1", "robot_2", "robot_3")
    procs.start("node", MERGE_NODE + ["--ros-args", "-p", "discovery_rate:=2.0",
                                      "-p", "reference_robot:=/nobody"])
    procs.start("play", FUSIONKIT + ["ros2", "play", str(run3), "--duration", "10", "--steps", "2"])

    def waiting():
        sts = [s["status"] for s in _records(probe_out, "status")]
        return next((s for s in sts if len(s["robots"]) == 3), None)

    status = _wait(waiting, 90, procs, "a status naming the three robots")
    assert status["reference"] == "/nobody"
    assert not any(r["placed"] for r in status["robots"].values())
    _wait(lambda: "waiting for the reference robot /nobody's map" in procs.log("node"), 60, procs,
          "the node to say what it waits for")

    def with_maps():
        sts = [s["status"] for s in _records(probe_out, "status")]
        return next((s for s in sts if len(s["robots"]) == 3
                     and all(r["map"] for r in s["robots"].values())), None)

    # each robot's status says so too (its reason was empty)
    status = _wait(with_maps, 60, procs, "a status with the three robots' maps")
    assert all(r["reason"] == "waiting for the reference robot /nobody's map with a wall"
               for r in status["robots"].values()), status
    assert procs.stop("play") == 0 and procs.stop("node") == 0


def test_a_parameter_the_node_does_not_know_is_said_once_and_ignored(procs):
    """As map_merge, the node ignores a parameter it does not know; a typo (merging_rte) is
    said in one WARN line. ROS's own parameters (use_sim_time) are not warned about."""
    procs.start("node", MERGE_NODE + ["--ros-args", "-p", "merging_rte:=2.0",
                                      "-p", "use_sim_time:=false"])
    _wait(lambda: "map merging started" in procs.log("node"), 60, procs, "the node to start")
    assert procs.stop("node") == 0
    log = procs.log("node")
    assert log.count("parameter merging_rte is not one of this node's; ignored") == 1
    assert "use_sim_time" not in log


@pytest.mark.parametrize("sent", ["none", "short"])
def test_a_reference_robot_whose_map_has_not_come_is_not_said_placed(procs, run3, tmp_path, sent):
    """The status said the reference robot was placed (confidence 1) while no map of it had
    arrived, so nothing of it was in the merged map. A map refused (data short of its size)
    was said to hold no known cell."""
    probe_out = tmp_path / "probe.jsonl"
    _probe(procs, probe_out, "robot_1", "robot_2")
    procs.start("node", MERGE_NODE + ["--ros-args", "-p", "discovery_rate:=2.0",
                                      "-p", "reference_robot:=/robot_1"])
    procs.start("pub", [sys.executable, "-c", SEQUENCE_PUBLISHER, f"robot_1={sent}@0",
                        f"robot_2={run3 / 'robot_2.yaml'}@0"])

    def both():
        sts = [s["status"] for s in _records(probe_out, "status")]
        # robot_1's short map may be refused just after robot_2's map is shown: wait for that too
        return next((s for s in reversed(sts) if {"/robot_1", "/robot_2"} <= set(s["robots"])
                     and s["robots"]["/robot_2"]["map"]
                     and (sent == "none" or s["robots"]["/robot_1"]["problem"])), None)

    status = _wait(both, 90, procs, "a status naming both robots")
    time.sleep(1.0)   # a transform of robot_1 would have reached the probe by now
    assert procs.stop("pub") == 0 and procs.stop("node") == 0
    r1 = status["robots"]["/robot_1"]
    assert r1["placed"] is False and r1["map"] is None
    # nor given a confidence or a transform (its identity pose was latched at subscription)
    assert r1["confidence"] is None and r1["transform"] is None, r1
    assert [p for p in _records(probe_out, "pose") if p["robot"] == "robot_1"] == []
    if sent == "none":
        assert r1["reason"] == "no valid map received yet" and r1["problem"] is None
    else:
        assert r1["problem"] and "width x height" in r1["problem"], r1
        assert r1["reason"] == f"no valid map received yet ({r1['problem']})", r1


def test_a_map_that_changes_nothing_merged_does_not_send_the_merged_map_again(procs, run3,
                                                                              tmp_path):
    """Every map message of a robot not yet placed sent the same merged map again (at start-up,
    twice): a subscriber such as a navigation stack redoes its work for nothing."""
    probe_out = tmp_path / "probe.jsonl"
    _probe(procs, probe_out, "robot_1", "robot_2")
    procs.start("node", MERGE_NODE + ["--ros-args", "-p", "discovery_rate:=2.0",
                                      "-p", "estimation_rate:=2.0"])
    procs.start("pub", [sys.executable, "-c", SEQUENCE_PUBLISHER,
                        f"robot_1={run3 / 'robot_1.yaml'}@0", "robot_2=none@0", "robot_2=unknown@3",
                        "robot_2=unknown@4", "robot_2=unknown@5"])

    def robot_2_seen_thrice():
        sts = [s["status"] for s in _records(probe_out, "status")]
        return any(s["robots"].get("/robot_2", {}).get("updates") == 3 for s in sts)

    _wait(robot_2_seen_thrice, 90, procs, "the third map of robot_2")
    time.sleep(2.0)   # eight merging periods, four estimation periods
    assert procs.stop("pub") == 0 and procs.stop("node") == 0
    maps = _records(probe_out, "map")
    assert len(maps) == 1, maps
    assert maps[0]["occupied"] == int(fk.load_map(run3 / "robot_1.yaml").occupied_mask().sum())


def test_a_dropped_robot_leaves_no_transform_for_a_subscriber_that_comes_later(procs, run3,
                                                                               tmp_path):
    """A robot dropped (its SLAM restarted in a new frame, with too small a map to be placed
    again) kept its last pose latched on its transform topic: a navigation stack started
    later took that transform for a placement the node no longer held."""
    g2 = fk.load_map(run3 / "robot_2.yaml")
    rows, cols = g2.occupied_mask().nonzero()
    r0, c0 = int(rows[rows.size // 2]) - 20, int(cols[rows.size // 2]) - 20
    # a 4 x 4 m window of robot_2's map, turned 90 degrees: a restart in a new frame
    corner = fk.OccupancyGrid(g2.data[r0:r0 + 40, c0:c0 + 40][::-1].T.copy(), g2.resolution,
                              (0.0, 0.0, 0.0), "robot_2")
    assert corner.occupied_mask().any()
    fk.save_map(corner, tmp_path / "corner.yaml")
    probe_out = tmp_path / "probe.jsonl"
    _probe(procs, probe_out, "robot_1", "robot_2")
    # robot_1 is named the reference: both maps come at once, and the first to arrive would be
    procs.start("node", MERGE_NODE + ["--ros-args", "-p", "discovery_rate:=2.0",
                                      "-p", "estimation_rate:=1.0",
                                      "-p", "reference_robot:=/robot_1"])
    procs.start("pub", [sys.executable, "-c", SEQUENCE_PUBLISHER,
                        f"robot_1={run3 / 'robot_1.yaml'}@0", f"robot_2={run3 / 'robot_2.yaml'}@0",
                        f"robot_2={tmp_path / 'corner.yaml'}@12"])

    def robot_2_is(placed, updates):
        def check():
            sts = [s["status"] for s in _records(probe_out, "status")]
            r2 = sts[-1]["robots"].get("/robot_2", {}) if sts else {}
            return r2.get("updates") == updates and r2.get("placed") is placed and r2
        return check

    _wait(lambda: robot_2_is(True, 1)() and any(p["robot"] == "robot_2"
                                                for p in _records(probe_out, "pose")),
          90, procs, "robot_2 placed and its transform sent")
    dropped = _wait(robot_2_is(False, 2), 90, procs, "robot_2 dropped after its restart")
    assert dropped["last_decision"] == "dropped", dropped
    late_out = tmp_path / "late.jsonl"
    _probe(procs, late_out, "robot_1", "robot_2", name="late")
    # the reference's pose comes to the late subscriber; robot_2's does not
    _wait(lambda: any(p["robot"] == "robot_1" for p in _records(late_out, "pose")), 30, procs,
          "the reference robot's transform at the late subscriber")
    time.sleep(3.0)
    assert [p for p in _records(late_out, "pose") if p["robot"] == "robot_2"] == []
    assert procs.stop("late") == 0 and procs.stop("pub") == 0 and procs.stop("node") == 0
    log = procs.log("node")
    assert "/robot_2: dropped" in log and "Traceback" not in log and "ERROR" not in log


def test_a_merged_map_topic_a_robot_publishes_on_is_said(procs, run3):
    """merged_map_topic:=/robot_1/map was taken silently: robot_1 dropped from the merge, and
    merged maps published among its own."""
    procs.start("node", MERGE_NODE + ["--ros-args", "-p", "discovery_rate:=2.0",
                                      "-p", "merged_map_topic:=/robot_1/map"])
    procs.start("pub", [sys.executable, "-c", SEQUENCE_PUBLISHER, f"robot_1={run3 / 'robot_1.yaml'}@0",
                        f"robot_2={run3 / 'robot_2.yaml'}@0"])
    said = "/robot_1/map, the merged map's topic, has another publisher"
    _wait(lambda: said in procs.log("node"), 60, procs, "the shared topic to be said")
    assert procs.stop("pub") == 0 and procs.stop("node") == 0
    log = procs.log("node")
    assert log.count(said) == 1 and "choose another merged_map_topic" in log and "Traceback" not in log


def test_a_robot_map_topic_of_two_levels_finds_its_robots(procs, run3):
    """robot_map_topic:=slam/map found no robot (the robot was taken as the topic's parent,
    /robot_1/slam, whose slam/map is not the topic): nothing was ever merged, without a word."""
    procs.start("play", FUSIONKIT + ["ros2", "play", str(run3), "--duration", "0", "--steps", "1",
                                     "--topic", "slam/map"])
    _wait(lambda: "last maps published" in procs.log("play"), 60, procs, "the maps to be published")
    procs.start("node", MERGE_NODE + ["--ros-args", "-p", "discovery_rate:=2.0",
                                      "-p", "robot_map_topic:=slam/map"])
    _wait(lambda: all(f"/robot_{k}: subscribed to /robot_{k}/slam/map" in procs.log("node")
                      for k in (1, 2, 3)), 60, procs, "the three robots to be found")
    assert procs.stop("node") == 0 and procs.stop("play") == 0
