"""``fusionkit ros2 play``: a recorded run's robot maps as live ROS 2 topics.

Each robot of a run directory (``fusionkit simulate`` output, or maps written by ``fusionkit
import``: ``NAME.yaml`` with ``NAME.scans.npz`` beside it) publishes ``/<NAME>/map``, latched,
growing over time: step ``i`` of ``steps`` is the map built from the first ``i / steps`` of the
robot's recorded poses, the last step is the map file itself. Maps therefore grow, change size
and move their origin, as a SLAM robot's do.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

from .. import InputError

__all__ = ["PlayRobot", "find_robots", "growth_steps"]


@dataclass(frozen=True)
class PlayRobot:
    """A robot to play: its name (the topic namespace), map file and scan log file (or None)."""

    name: str
    map_path: Path
    scans_path: Path | None


def find_robots(run_dir) -> list[PlayRobot]:
    """The robots of a run directory: those listed in its ``truth.json`` when it has one (one
    without a ``.scans.npz`` is played as its whole map at once), else every map with a
    ``.scans.npz`` beside it.

    Raises
    ------
    InputError
        Not a directory, or no robot map in it.
    """
    from .. import scans_path_for

    run = Path(run_dir)
    if not run.is_dir():
        raise InputError(f"{run}: not a directory; give a run directory written by "
                         f"'fusionkit simulate' or 'fusionkit import'")
    truth = run / "truth.json"
    if truth.is_file():
        try:
            names = [r["name"] for r in json.loads(truth.read_text())["robots"]]
        except (ValueError, KeyError, TypeError) as exc:
            raise InputError(f"{truth}: not a run's truth.json ({exc})") from None
        maps = [run / f"{n}.yaml" for n in names]
    else:
        maps = sorted(p for p in run.glob("*.yaml") if scans_path_for(p).is_file())
    if not maps:
        raise InputError(f"{run}: no robot map (NAME.yaml with NAME.scans.npz beside it) found")
    robots = []
    for m in maps:
        if not m.is_file():
            raise InputError(f"{m}: listed in truth.json but missing")
        sp = scans_path_for(m)
        robots.append(PlayRobot(m.stem, m, sp if sp.is_file() else None))
    return robots


def growth_steps(robot: PlayRobot, steps: int) -> list:
    """The robot's map at each of ``steps`` steps (OccupancyGrid list, the last the map file)."""
    import fusionkit as fk

    final = fk.load_map(robot.map_path)
    if robot.scans_path is None or steps <= 1:
        return [final]
    log = fk.load_scans(robot.scans_path)
    cfg = fk.MappingConfig(resolution=final.resolution)
    grids = []
    for i in range(1, steps):
        n = max(2, math.ceil(log.n_scans * i / steps))
        grids.append(fk.build_grid(log.subset(slice(0, n)), cfg, name=robot.name))
    return grids + [final]


def play(run_dir, *, duration: float, steps: int, topic: str = "map", hold: float | None = None,
         ros_args=(), log=print) -> int:
    """Publish every robot's growing map; returns the exit status.

    Parameters
    ----------
    duration : float
        Seconds from the first step to the last.
    steps : int
        Map updates per robot.
    topic : str
        Map topic name in each robot's namespace.
    hold : float or None
        Seconds to keep the last maps published after the last step (None: until Ctrl-C).
    """
    robots = find_robots(run_dir)
    if not (duration >= 0 and math.isfinite(duration)) or steps < 1:
        raise InputError("--duration must be >= 0 s and --steps >= 1")
    from ._names import check_topic
    from ._runtime import ros_context
    check_topic("--topic", topic)
    for r in robots:
        check_topic(f"{r.name}.yaml (its name is the robot's topic namespace)", f"/{r.name}/{topic.strip('/')}")

    from ..labels import count
    # the ROS arguments are checked (and refused) before the maps are built
    with ros_context(["fusionkit-play", "--ros-args", *ros_args]) as rclpy:
        log(f"building {count(steps, 'map step')} for each of {count(len(robots), 'robot')}")
        plans = [(r, growth_steps(r, steps)) for r in robots]
        from nav_msgs.msg import OccupancyGrid as GridMsg

        from ._convert import fill_msg
        from .node import latched_qos

        node = rclpy.create_node("fusionkit_play")
        try:
            pubs = [node.create_publisher(GridMsg, f"/{r.name}/{topic.strip('/')}", latched_qos())
                    for r, _ in plans]
            log(f"playing {count(len(plans), 'robot')} ({', '.join(r.name for r, _ in plans)}) from "
                f"{run_dir}: {count(steps, 'step')} over {duration:g} s")
            t0 = time.monotonic()
            for i in range(steps):
                wait = t0 + (duration * i / max(1, steps - 1)) - time.monotonic()
                if wait > 0:
                    time.sleep(wait)
                for pub, (r, grids) in zip(pubs, plans):
                    if i >= len(grids):  # a map without scans is published once, whole
                        continue
                    g = grids[i]
                    msg = GridMsg()
                    fill_msg(msg, g, f"{r.name}/map", node.get_clock().now().to_msg())
                    pub.publish(msg)
                log(f"step {i + 1}/{steps} published")
            log("last maps published; holding them " +
                ("until Ctrl-C" if hold is None else f"for {hold:g} s"))
            end = math.inf if hold is None else time.monotonic() + hold
            while time.monotonic() < end and rclpy.ok():
                time.sleep(min(0.2, max(0.0, end - time.monotonic())))
        finally:
            node.destroy_node()
    return 0
