"""fusionkit in a running ROS 2 system.

* :func:`run_merge_node` (``fusionkit ros2 merge-node``, ``python -m fusionkit.ros2
  merge-node``): a drop-in for the ``multirobot_map_merge`` node, with its parameters and
  defaults (:mod:`._params`), that never flips a merge back and forth (:mod:`._tracker`), says
  how sure it is, and refuses a wrong merge;
* :func:`run_play` (``fusionkit ros2 play RUN_DIR``): a recorded run's robot maps as live,
  growing map topics (:mod:`.play`).

Needs the ``ros2`` extra (``pip install -e ".[ros2]"``): ROS 2 as wheels, no ROS installation.
Nothing here imports ``rclpy`` until a node starts.
"""

from __future__ import annotations

__all__ = ["run_merge_node", "run_play"]


def run_merge_node(ros_args=(), params_files=(), *, name: str = "map_merge") -> int:
    """Run the merge node until Ctrl-C or SIGTERM; returns the exit status (0).

    Parameters
    ----------
    ros_args : sequence of str
        What follows ``--ros-args`` (``-p NAME:=VALUE``, ``-r`` remappings, ...).
    params_files : sequence of path
        ROS 2 parameter files (the node is named ``map_merge``, as multirobot_map_merge's is,
        so its parameter files apply unchanged).

    Raises
    ------
    InputError
        ROS 2 not installed, bad arguments, a parameter with a bad value.
    """
    from ._runtime import _params_files, ros_argv, ros_context, unapplied_params_files
    from .node import MergeNode, read_settings

    argv = ros_argv("fusionkit-merge-node", ros_args, params_files)
    with ros_context(argv) as rclpy:
        from rclpy.node import Node

        node = Node(name, allow_undeclared_parameters=True,
                    automatically_declare_parameters_from_overrides=True)
        name = node.get_fully_qualified_name()
        for f in unapplied_params_files(_params_files(argv), name):
            node.get_logger().warn(f"{f}: no section for this node ({name}: ros__parameters: "
                                   f"...); none of its parameters is applied")
        merger = None
        try:
            merger = MergeNode(node, read_settings(node))
            rclpy.spin(node)
        finally:
            if merger is not None:
                merger.close()
            node.destroy_node()
    return 0


def run_play(run_dir, *, duration: float = 30.0, steps: int = 10, topic: str = "map",
             hold: float | None = None, ros_args=(), log=print) -> int:
    """Play a run directory's robot maps as growing ``/<robot>/<topic>`` topics (see
    :func:`fusionkit.ros2.play.play`)."""
    from .play import play
    return play(run_dir, duration=duration, steps=steps, topic=topic, hold=hold,
                ros_args=ros_args, log=log)
