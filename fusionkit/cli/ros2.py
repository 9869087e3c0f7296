"""``fusionkit ros2``: the live merge node (a drop-in for multirobot_map_merge) and a player
that publishes a recorded run's robot maps as growing topics."""

from __future__ import annotations

import argparse

from ._common import float_range, int_range, paragraphs

__all__ = ["register"]


def register(sub) -> None:
    p = sub.add_parser(
        "ros2", help="ROS 2: a live merge node (drop-in for multirobot_map_merge), a run player",
        description="fusionkit inside a running ROS 2 system (needs the ros2 extra: "
                    "pip install -e \".[ros2]\").")
    kinds = p.add_subparsers(dest="ros2_command", metavar="COMMAND", required=True)

    m = kinds.add_parser(
        "merge-node", help="merge the robots' map topics into one latched map topic, live",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=paragraphs(
            "A ROS 2 node named map_merge with multirobot_map_merge's parameters and defaults "
            "(robot_map_topic, robot_namespace, merged_map_topic, world_frame, known_init_poses "
            "with /<robot>/map_merge/init_pose_{x,y,z,yaw}, merging_rate, discovery_rate, "
            "estimation_rate, estimation_confidence) plus fusionkit's own (method, "
            "min_confidence, switch_margin, switch_confirmations, reference_robot, seed, "
            "max_map_cells), set as ROS 2 users set them: --ros-args -p NAME:=VALUE, "
            "--params-file FILE.yaml.",
            "It discovers robots by their map topics, estimates their transforms in a worker "
            "thread, keeps each accepted transform until a confidently better one comes (and "
            "only while it still fits the current maps), and "
            "publishes the merged map (latched), each robot's transform on "
            "/map_merge/<robot>/transform (geometry_msgs/PoseStamped) and a JSON status on "
            "/map_merge/status (std_msgs/String). Ctrl-C stops it. Exit status: 0 stopped, "
            "2 bad input."),
        epilog=_parameters_help() + "\n\nexample: fusionkit ros2 merge-node --ros-args "
               "-p discovery_rate:=1.0 -p estimation_rate:=0.5")
    m.add_argument("--params-file", action="append", default=[], metavar="FILE.yaml",
                   help="ROS 2 parameter file (map_merge: ros__parameters: ...); may be repeated")
    m.add_argument("--ros-args", nargs=argparse.REMAINDER, default=[], metavar="ARG",
                   help="ROS arguments, to the end of the line (-p NAME:=VALUE, --params-file F, "
                        "-r FROM:=TO, --log-level LEVEL)")
    m.set_defaults(func=_merge_node)

    pl = kinds.add_parser(
        "play", help="publish a run's robot maps as live topics, growing along the recorded poses",
        description="Publish each robot of RUN_DIR (a 'fusionkit simulate' run, or maps written by "
                    "'fusionkit import') on /<robot>/map, latched, growing over time: step i of "
                    "--steps is the map built from the first i/steps of its recorded poses, the "
                    "last step the map file itself. The maps stay published until Ctrl-C (or "
                    "--hold seconds). Exit status: 0 done, 2 bad input.")
    pl.add_argument("run_dir", metavar="RUN_DIR", help="directory of robot maps with their scans")
    pl.add_argument("--duration", type=float_range(0.0, 86400.0), default=30.0, metavar="S",
                    help="seconds from the first map to the last (default: %(default)s)")
    pl.add_argument("--steps", type=int_range(1, 10_000), default=10, metavar="N",
                    help="map updates per robot (default: %(default)s)")
    pl.add_argument("--topic", default="map", metavar="NAME",
                    help="map topic in each robot's namespace: /robot_1/NAME, also when NAME "
                         "starts with / (default: %(default)s)")
    pl.add_argument("--hold", type=float_range(0.0, 86400.0), default=None, metavar="S",
                    help="seconds to keep publishing after the last step (default: until Ctrl-C)")
    pl.add_argument("--ros-args", nargs=argparse.REMAINDER, default=[], metavar="ARG",
                    help="ROS arguments, to the end of the line")
    pl.set_defaults(func=_play)


def _parameters_help() -> str:
    """The node's parameters, each with its default and meaning, for ``--help``."""
    import textwrap

    from ..ros2._params import PARAMETERS

    lines = ["parameters (-p NAME:=VALUE; default, meaning):"]
    for name, (default, _kind, meaning) in PARAMETERS.items():
        shown = str(default).lower() if isinstance(default, bool) else repr(default) \
            if isinstance(default, str) else f"{default:g}" if isinstance(default, float) else default
        lines += textwrap.wrap(f"{name} ({shown}): {meaning}", width=88, initial_indent="  ",
                               subsequent_indent="      ")
    lines += textwrap.wrap("/<robot>/map_merge/init_pose_x, _y, _z, _yaw: a robot's known "
                           "initial pose, read with known_init_poses true (_z is ignored)",
                           width=88, initial_indent="  ", subsequent_indent="      ")
    return "\n".join(lines)


def _merge_node(args) -> int:
    from ..ros2 import run_merge_node
    return run_merge_node(args.ros_args, args.params_file)


def _play(args) -> int:
    from ..ros2 import run_play
    return run_play(args.run_dir, duration=args.duration, steps=args.steps, topic=args.topic,
                    hold=args.hold, ros_args=args.ros_args,
                    log=lambda text: print(f"fusionkit ros2 play: {text}", flush=True))
