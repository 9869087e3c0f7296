"""The merge node's parameters: multirobot_map_merge's, with its names and defaults, plus
fusionkit's own. Values come from ROS 2 parameters (``--ros-args -p NAME:=VALUE``,
``--params-file FILE.yaml``) and are checked here, one clear line per mistake.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

from .. import InputError, Transform2D

__all__ = ["NodeSettings", "PARAMETERS", "INIT_POSE", "init_poses_from", "settings_from",
           "unknown_parameter"]

#: name -> (default, kind, help). The first block are multirobot_map_merge's (same defaults).
PARAMETERS: dict = {
    "robot_map_topic": ("map", "str", "name of each robot's map topic, relative to its namespace"),
    "robot_map_updates_topic": ("map_updates", "str",
                                "accepted for launch files; partial updates are not read (full maps are)"),
    "robot_namespace": ("", "str", "only map topics whose name contains this text are robots"),
    "merged_map_topic": ("map", "str", "topic of the merged map (latched)"),
    "world_frame": ("world", "str", "frame_id of the merged map and of the published transforms"),
    "known_init_poses": (False, "bool",
                         "take each robot's transform from /<robot>/map_merge/init_pose_{x,y,z,yaw} "
                         "instead of estimating it"),
    "merging_rate": (4.0, "rate", "most merged maps published per second (Hz)"),
    "discovery_rate": (0.05, "rate", "robot discoveries per second (Hz)"),
    "estimation_rate": (0.5, "rate", "transform estimations per second (Hz)"),
    "estimation_confidence": (1.0, "float",
                              "accepted for launch files (it is OpenCV's matcher threshold there); "
                              "fusionkit's threshold is min_confidence"),
    # fusionkit's own
    "method": ("consensus", "str", "fusionkit merging method (consensus, spectral-pso, map-merge, ...)"),
    "min_confidence": (0.5, "unit",
                       "least confidence (0-1) for a robot to be placed; the method refuses "
                       "placements it is unsure of on top of this"),
    "switch_margin": (0.05, "unit",
                      "how much better (0-1 overlap score on the current maps) a new estimate must "
                      "be than the accepted one to replace it"),
    "switch_confirmations": (2, "count", "successive estimations that must agree before an accepted "
                                         "transform is replaced"),
    "reference_robot": ("", "str", "robot whose map frame is the merged frame (default: the first "
                                   "robot whose valid map with a wall arrives)"),
    "seed": (0, "count", "seed of every random step of the estimation"),
    "max_map_cells": (16_000_000, "count", "larger maps are refused (logged once, robot skipped)"),
}

#: The known initial pose parameters of a robot, as multirobot_map_merge names them.
INIT_POSE = re.compile(r"^/?(?P<robot>.+)/map_merge/init_pose_(?P<axis>x|y|z|yaw)$")


@dataclass(frozen=True)
class NodeSettings:
    """Every setting of the merge node (see :data:`PARAMETERS` for what each means)."""

    robot_map_topic: str = "map"
    robot_map_updates_topic: str = "map_updates"
    robot_namespace: str = ""
    merged_map_topic: str = "map"
    world_frame: str = "world"
    known_init_poses: bool = False
    merging_rate: float = 4.0
    discovery_rate: float = 0.05
    estimation_rate: float = 0.5
    estimation_confidence: float = 1.0
    method: str = "consensus"
    min_confidence: float = 0.5
    switch_margin: float = 0.05
    switch_confirmations: int = 2
    reference_robot: str = ""
    seed: int = 0
    max_map_cells: int = 16_000_000
    init_poses: dict = field(default_factory=dict)
    #: robots with some but not all of x, y and yaw: what to add (skipped, as map_merge does)
    partial_init_poses: dict = field(default_factory=dict)

    def __post_init__(self):
        from .. import METHODS
        if self.method not in METHODS:
            raise InputError(f"parameter method: {self.method!r} is not a method; choose one of "
                             f"{', '.join(METHODS)}")
        if not self.robot_map_topic.strip("/"):
            raise InputError("parameter robot_map_topic: give a topic name such as 'map'")
        if not self.merged_map_topic.strip("/"):
            raise InputError("parameter merged_map_topic: give a topic name such as 'map'")
        from ._names import check_topic
        for name in ("robot_map_topic", "robot_map_updates_topic", "merged_map_topic"):
            check_topic(f"parameter {name}", getattr(self, name))
        if not self.world_frame:
            raise InputError("parameter world_frame: give a frame name such as 'world'")
        for name in ("merging_rate", "discovery_rate", "estimation_rate"):
            # as map_merge's files for known poses give it, estimation_rate 0: no estimation
            if getattr(self, name) == 0 and not (name == "estimation_rate" and self.known_init_poses):
                raise _bad_rate(name, getattr(self, name))
        if self.switch_confirmations < 1:
            raise InputError("parameter switch_confirmations: must be >= 1")
        if self.max_map_cells < 1:
            raise InputError("parameter max_map_cells: must be >= 1")
        if self.reference_robot:
            if not self.reference_robot.strip("/"):
                raise InputError(f"parameter reference_robot: give a robot's namespace such as "
                                 f"/robot_1, got {self.reference_robot!r}")
            object.__setattr__(self, "reference_robot", "/" + self.reference_robot.strip("/"))


#: The least rate (Hz) of a timer of the node
MIN_RATE = 1e-6


def _bad_rate(name: str, value) -> InputError:
    # a rarer rate overflows the timers (about 11.6 days between two rounds at the least)
    return InputError(f"parameter {name}: expected a rate in Hz, from {MIN_RATE:g} to 1000, "
                      f"got {value!r}")


def _coerce(name: str, value, kind: str):
    """``value`` as the parameter's kind, or an InputError saying what to give."""
    if kind == "str":
        if not isinstance(value, str):
            raise InputError(f"parameter {name}: expected text, got {value!r}")
        return value
    if kind == "bool":
        if isinstance(value, bool):
            return value
        if isinstance(value, str) and value.lower() in ("true", "false"):
            return value.lower() == "true"
        raise InputError(f"parameter {name}: expected true or false, got {value!r}")
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"parameter {name}: expected a number, got {value!r}")
    if kind == "count":
        whole = isinstance(value, int) or (math.isfinite(value) and value == int(value))
        if not whole or not 0 <= value <= 2**63 - 1:
            raise InputError(f"parameter {name}: expected a whole number from 0 to 2^63 - 1, "
                             f"got {value!r}")
        return int(value)
    v = float(value)
    if not math.isfinite(v):
        raise InputError(f"parameter {name}: expected a finite number, got {value!r}")
    if kind == "rate" and not (v == 0 or MIN_RATE <= v <= 1000.0):   # 0: NodeSettings decides
        raise _bad_rate(name, value)
    if kind == "unit" and not 0.0 <= v <= 1.0:
        raise InputError(f"parameter {name}: expected a number between 0 and 1, got {value!r}")
    return v


def init_poses_from(values: dict) -> tuple[dict, dict]:
    """``{"/robot1": Transform2D, ...}`` from the ``/<robot>/map_merge/init_pose_*`` parameters
    (a robot needs x, y and yaw; z is read and ignored, maps being planar), and for each robot
    given only some of them, what to add (such a robot is skipped, as map_merge skips it)."""
    axes: dict = {}
    for name, value in values.items():
        m = INIT_POSE.match(name)
        if m is None:
            continue
        robot = "/" + m["robot"].strip("/")
        axes.setdefault(robot, {})[m["axis"]] = _coerce(name, value, "float")
    poses, partial = {}, {}
    for robot, a in axes.items():
        missing = [k for k in ("x", "y", "yaw") if k not in a]
        if missing:
            partial[robot] = (f"give {', '.join(f'{robot}/map_merge/init_pose_{k}' for k in missing)} "
                              f"too (x, y and yaw make a known initial pose)")
            continue
        poses[robot] = Transform2D(a["x"], a["y"], a["yaw"])
    return poses, partial


def settings_from(values: dict) -> NodeSettings:
    """Settings from parameter values (``name -> value``; missing names take their defaults)."""
    kw = {}
    for name, (default, kind, _help) in PARAMETERS.items():
        if name in values and values[name] is not None:
            kw[name] = _coerce(name, values[name], kind)
    if kw.get("known_init_poses", PARAMETERS["known_init_poses"][0]):
        kw["init_poses"], kw["partial_init_poses"] = init_poses_from(values)
    # else, as map_merge, initial poses are not read (a half-given one is no error)
    return NodeSettings(**kw)


#: an initial pose written nested in a parameters file (``robot_3: map_merge: init_pose_x:``)
_NESTED_INIT_POSE = re.compile(r"^(?P<robot>.+)\.map_merge\.init_pose_(?P<axis>x|y|z|yaw)$")


def unknown_parameter(name: str) -> str:
    """The warning for a parameter the node does not know (it is ignored, as map_merge does)."""
    m = _NESTED_INIT_POSE.match(name)
    if m:
        return (f"parameter {name} is not one of this node's; ignored (an initial pose is "
                f"written flat, as map_merge's params.yaml does: "
                f"/{m['robot'].lstrip('/').replace('.', '/')}/map_merge/init_pose_{m['axis']}: VALUE)")
    return (f"parameter {name} is not one of this node's; ignored (the parameters: fusionkit "
            f"ros2 merge-node --help)")
