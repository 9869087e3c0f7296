"""ROS graph names as multirobot_map_merge reads them: a robot is the namespace of its map topic."""

from __future__ import annotations

__all__ = ["parent_namespace", "append", "is_robot_map_topic", "robot_slug", "MAP_TYPE"]

#: The one message type read as a robot map.
MAP_TYPE = "nav_msgs/msg/OccupancyGrid"


def parent_namespace(name: str) -> str:
    """``"/robot1/map"`` -> ``"/robot1"``; ``"/map"`` -> ``"/"``."""
    head = name.rstrip("/").rsplit("/", 1)[0]
    return head or "/"


def append(ns: str, name: str) -> str:
    """``ns`` joined with a relative ``name`` (``"/robot1"``, ``"map"`` -> ``"/robot1/map"``)."""
    name = name.strip("/")
    return ns + name if ns.endswith("/") else f"{ns}/{name}"


def is_robot_map_topic(topic: str, types, *, robot_map_topic: str, robot_namespace: str,
                       merged_topic: str) -> bool:
    """Whether ``topic`` is a robot's map: ``<namespace>/<robot_map_topic>`` of type
    OccupancyGrid, containing ``robot_namespace``, and not the merged map itself."""
    return (MAP_TYPE in types and topic != merged_topic and robot_namespace in topic
            and append(parent_namespace(topic), robot_map_topic) == topic)


def robot_slug(robot: str) -> str:
    """A robot name usable inside a topic name (``"/robot1"`` -> ``"robot1"``)."""
    return robot.strip("/") or "root"
