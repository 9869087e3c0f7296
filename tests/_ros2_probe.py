"""A ROS 2 listener for the node tests, run as its own process.

``python _ros2_probe.py OUT.jsonl ROBOT [ROBOT ...]`` appends one JSON line per message
received on ``/map`` (the merged map: its size, resolution, origin and the counts of its
cells), ``/map_merge/status`` and ``/map_merge/<ROBOT>/transform``, until SIGINT or SIGTERM.
"""

import json
import math
import sys
import time

import numpy as np
import rclpy
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import OccupancyGrid
from rclpy.executors import ExternalShutdownException
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String


def main(out_path, robots):
    rclpy.init(args=["probe"])
    node = rclpy.create_node("fusionkit_probe")
    qos = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)
    out = open(out_path, "a", buffering=1)

    def write(kind, **kw):
        out.write(json.dumps({"kind": kind, "t": time.time(), **kw}) + "\n")

    def on_map(msg):
        data = np.frombuffer(msg.data, np.int8)
        write("map", width=msg.info.width, height=msg.info.height, frame=msg.header.frame_id,
              resolution=msg.info.resolution, occupied=int((data == 100).sum()),
              known=int((data >= 0).sum()))

    def on_pose(msg, robot):
        q = msg.pose.orientation
        write("pose", robot=robot, frame=msg.header.frame_id, x=msg.pose.position.x,
              y=msg.pose.position.y,
              theta=math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z)))

    node.create_subscription(OccupancyGrid, "/map", on_map, qos)
    node.create_subscription(String, "/map_merge/status",
                             lambda m: write("status", status=json.loads(m.data)), qos)
    for r in robots:
        node.create_subscription(PoseStamped, f"/map_merge/{r}/transform",
                                 lambda m, _r=r: on_pose(m, _r), qos)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        out.close()
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2:])
