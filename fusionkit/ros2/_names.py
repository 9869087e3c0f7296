"""ROS graph names as multirobot_map_merge reads them: a robot is the namespace of its map topic."""

from __future__ import annotations

__all__ = ["robot_of", "is_robot_map_topic", "robot_slug", "MAP_TYPE", "check_topic"]

#: The one message type read as a robot map.
MAP_TYPE = "nav_msgs/msg/OccupancyGrid"


def robot_of(topic: str, robot_map_topic: str) -> str | None:
    """The robot whose map ``topic`` is, ``<robot>/<robot_map_topic>``, or None
    (``"/robot1/slam/map"``, ``"slam/map"`` -> ``"/robot1"``; map_merge takes the topic's parent
    namespace, so that a robot_map_topic of two levels matched no topic)."""
    suffix = "/" + robot_map_topic.strip("/")
    if not topic.endswith(suffix):
        return None
    return topic[:-len(suffix)] or "/"


def is_robot_map_topic(topic: str, types, *, robot_map_topic: str, robot_namespace: str,
                       merged_topic: str) -> bool:
    """Whether ``topic`` is a robot's map: ``<namespace>/<robot_map_topic>`` of type
    OccupancyGrid, containing ``robot_namespace``, and not the merged map itself."""
    return (MAP_TYPE in types and topic != merged_topic and robot_namespace in topic
            and robot_of(topic, robot_map_topic) is not None)


def robot_slug(robot: str) -> str:
    """A robot name usable inside a topic name (``"/robot1"`` -> ``"robot1"``)."""
    return robot.strip("/") or "root"


def check_topic(what: str, name: str) -> None:
    """Raise an InputError naming ``what`` when ``name`` (absolute, or relative to a namespace)
    is not a valid ROS 2 topic name; nothing to check without rclpy."""
    from .. import InputError
    try:
        from rclpy.validate_topic_name import validate_topic_name
    except ImportError:
        return
    try:
        validate_topic_name(name if name.startswith("/") else "/" + name)
    except Exception as exc:  # noqa: BLE001 - rclpy's InvalidTopicNameException and its kin
        why = str(exc).split("\n", 1)[0].replace("Invalid topic name: ", "").rstrip(":")
        raise InputError(f"{what}: {name!r} is not a ROS 2 topic name ({why})") from None
