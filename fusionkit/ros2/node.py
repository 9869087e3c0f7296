"""The live merge node: a drop-in for multirobot_map_merge.

It discovers robots by their map topics (``/<robot>/map``), subscribes to them latched,
estimates the robots' transforms in a worker thread at ``estimation_rate`` with
:func:`fusionkit.merge`, keeps each accepted transform until a confidently better one comes
(:mod:`._tracker`), and publishes the merged map latched at most ``merging_rate`` times a second.

Published, besides the merged map (``merged_map_topic``, frame ``world_frame``):

* ``~/<robot>/transform`` (``geometry_msgs/msg/PoseStamped``, latched): where the robot's map
  frame lies in the merged frame, e.g. ``/map_merge/robot1/transform``;
* ``~/status`` (``std_msgs/msg/String``, latched): JSON of each robot's state and transform;
* ``/tf_static`` (``world_frame`` -> ``<robot>/map``) when ``tf2_ros`` can be imported.
"""

from __future__ import annotations

import json
import math
import threading
import time

from .. import FusionkitError, MergeCancelled
from ._convert import BadMap, fill_msg, fill_pose, grid_from_msg
from ._names import is_robot_map_topic, robot_of, robot_slug
from ._params import INIT_POSE, PARAMETERS, NodeSettings, settings_from, unknown_parameter
from ._robots import Robot, estimate_round
from ._tracker import Tracker

__all__ = ["MergeNode", "latched_qos", "read_settings"]


def latched_qos():
    """The QoS of a ROS 1 latched topic: keep the last message for late subscribers."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    return QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL,
                      reliability=ReliabilityPolicy.RELIABLE)


def read_settings(node) -> NodeSettings:
    """The node's parameters as :class:`NodeSettings` (declaring the missing ones with their
    defaults, so ``ros2 param`` users see them all)."""
    for name, (default, _kind, _help) in PARAMETERS.items():
        if not node.has_parameter(name):
            node.declare_parameter(name, default)
    values = {name: p.value for name, p in node.get_parameters_by_prefix("").items()}
    settings = settings_from(values)
    # as map_merge, a parameter it does not know is ignored; unlike it, a typo is said
    for name in sorted(values):
        if name not in PARAMETERS and not INIT_POSE.match(name) and name not in ROS_OWN \
                and not name.startswith("qos_overrides."):
            node.get_logger().warn(unknown_parameter(name))
    return settings


#: Parameters every ROS 2 node has
ROS_OWN = frozenset({"use_sim_time", "start_type_description_service", "start_parameter_services"})


class MergeNode:
    """The merge node around an ``rclpy`` node (``self.node``); :meth:`close` stops it."""

    def __init__(self, node, settings: NodeSettings):
        from geometry_msgs.msg import PoseStamped
        from nav_msgs.msg import OccupancyGrid as GridMsg
        from std_msgs.msg import String

        self.node, self.s = node, settings
        self.log = node.get_logger()
        self._GridMsg, self._Pose, self._String = GridMsg, PoseStamped, String
        self._lock = threading.Lock()
        self._pose_lock = threading.Lock()   # a robot's transform publisher, replaced when dropped
        self._stop = threading.Event()
        self._wake_compose = threading.Event()
        self.robots: dict[str, Robot] = {}
        self.reference = settings.reference_robot or None
        self.tracker = Tracker(min_confidence=settings.min_confidence,
                               switch_margin=settings.switch_margin,
                               switch_confirmations=settings.switch_confirmations)
        self.estimations = 0
        self.last_estimation_s = None
        self.estimate_error = ""   # why the last estimation failed (none: "")
        self.last_merge_s = None     # seconds to fuse and publish the last merged map
        self._map_version = 0       # bumped by every accepted map message
        self._held_version = 0      # bumped by every change of a held transform
        self._warned: set = set()
        self.skipped: dict[str, tuple[str, str]] = {}   # robots left out at discovery: (topic, why)
        self.merged_pub = node.create_publisher(GridMsg, settings.merged_map_topic, latched_qos())
        self.merged_topic = self.merged_pub.topic_name
        self.status_pub = node.create_publisher(String, "~/status", latched_qos())
        self.tf = None
        try:  # tf2 is not on the package index: /tf_static only where a ROS install has it
            from tf2_ros import StaticTransformBroadcaster
            self.tf = StaticTransformBroadcaster(node)
        except Exception:  # noqa: BLE001 - absent or broken tf2: the topics say it all
            self.tf = None
        mode = ("known initial poses" if settings.known_init_poses else
                f"method {settings.method}, estimation every {f'{1 / settings.estimation_rate:.3f}'.rstrip('0').rstrip('.')} s")
        self.log.info(f"map merging started: robots' '{settings.robot_map_topic}' topics into "
                      f"{self.merged_topic} (frame {settings.world_frame}), {mode}")
        for robot, what in sorted(settings.partial_init_poses.items()):   # said once, here
            self._once(("nopose", robot), f"{robot}: initial pose incomplete: {what}; robot skipped")
        self._discover()
        node.create_timer(1.0 / settings.discovery_rate, self._guard(self._discover))
        # at start the ROS graph is not yet known to this node (the discovery above finds no
        # robot): look again every second for the first EARLY_DISCOVERIES seconds, so that
        # robots already publishing are not waited for a whole discovery period (20 s)
        self._early_left = EARLY_DISCOVERIES if settings.discovery_rate < 1.0 else 0
        self._early = node.create_timer(1.0, self._guard(self._early_discover)) \
            if self._early_left else None
        self._threads = [threading.Thread(target=self._compose_loop, name="compose", daemon=True)]
        if not settings.known_init_poses:
            self._threads.append(threading.Thread(target=self._estimate_loop, name="estimate",
                                                  daemon=True))
        for t in self._threads:
            t.start()

    # -- helpers ----------------------------------------------------------------------------
    def _once(self, key, text: str, level: str = "warning") -> None:
        """Log ``text`` the first time ``key`` is seen (rclpy wants one severity per call site)."""
        if key in self._warned:
            return
        self._warned.add(key)
        if level == "info":
            self.log.info(text)
        elif level == "error":
            self.log.error(text)
        else:
            self.log.warning(text)

    def _guard(self, fn):
        """An executor callback that logs an unexpected error once instead of raising it."""
        def run(*a):
            try:
                fn(*a)
            except Exception as exc:  # noqa: BLE001 - the node must go on
                if self._alive():
                    self._once(("error", fn.__name__, type(exc).__name__),
                               f"{fn.__name__}: {type(exc).__name__}: {exc}", "error")
        return run

    def _alive(self) -> bool:
        """Whether the node still runs: not closed, and ROS not shut down (Ctrl-C or SIGTERM
        shut ROS down before the worker threads hear of it; what fails to publish then is not
        an error to report, and logging it would fail too)."""
        if self._stop.is_set():
            return False
        try:
            return bool(self.node.context.ok())
        except Exception:  # noqa: BLE001 - a destroyed context is not running
            return False

    def _stamp(self):
        return self.node.get_clock().now().to_msg()

    # -- discovery and subscriptions (executor thread) ----------------------------------------
    def _early_discover(self) -> None:
        self._early_left -= 1
        if self._early_left <= 0 and self._early is not None:
            self._early.cancel()
        self._discover()

    def _discover(self) -> None:
        s = self.s
        seen = set()
        if self.node.count_publishers(self.merged_topic) > 1:   # a robot's map topic, say
            self._once(("shared",), f"{self.merged_topic}, the merged map's topic, has another publisher: a "
                                    f"robot's map there is not merged; choose another merged_map_topic")
        for topic, types in self.node.get_topic_names_and_types():
            if not is_robot_map_topic(topic, types, robot_map_topic=s.robot_map_topic,
                                      robot_namespace=s.robot_namespace,
                                      merged_topic=self.merged_topic):
                continue
            name = robot_of(topic, s.robot_map_topic)
            seen.add(name)
            if name in self.robots:
                continue
            if s.known_init_poses and name not in s.init_poses:
                why = (f"initial pose incomplete: {s.partial_init_poses[name]}"
                       if name in s.partial_init_poses else
                       f"no known initial pose: set {name}/map_merge/init_pose_x, _y, _yaw, or "
                       f"set known_init_poses to false")
                self._once(("nopose", name), f"{name}: {why}; robot skipped")
                if name not in self.skipped:
                    with self._lock:
                        self.skipped[name] = (topic, why)
                    self._publish_status()
                continue
            self._add_robot(name, topic)
        changed = False
        for name, r in self.robots.items():
            gone = name not in seen or self.node.count_publishers(r.topic) == 0
            if gone and not r.vanished:
                kept = "its last map stays in the merge" if r.grid is not None else "it had no valid map"
                self.log.warning(f"{name}: {r.topic} has no publisher any more; {kept}")
            elif r.vanished and not gone:
                self.log.info(f"{name}: {r.topic} is published again")
            changed |= r.vanished != gone
            r.vanished = gone
        if changed:
            self._publish_status()

    def _add_robot(self, name: str, topic: str) -> None:
        r = Robot(name, topic)
        r.pose_topic = f"~/{robot_slug(name)}/transform"
        r.pose_pub = self.node.create_publisher(self._Pose, r.pose_topic, latched_qos())
        with self._lock:
            self.robots[name] = r
            if self.s.known_init_poses:
                self.tracker.fix(name, self.s.init_poses[name])
                r.last_action = "known initial pose"
            elif name == self.reference:
                self.tracker.fix(name, _identity())
                r.last_action = "reference"

        def on_map(msg, _r=r):
            self._on_map(_r, msg)

        r.sub = self.node.create_subscription(self._GridMsg, topic, self._guard(on_map),
                                              latched_qos())
        role = " (reference: its map frame is the merged frame)" if name == self.reference else ""
        self.log.info(f"{name}: subscribed to {topic}{role}")

    def _on_map(self, r: Robot, msg) -> None:
        try:
            grid = grid_from_msg(msg, name=r.name, max_cells=self.s.max_map_cells)
        except BadMap as exc:
            kept = ("its last valid map stays in the merge" if r.grid is not None else
                    "the robot is skipped")
            self._once(("bad", r.name, str(exc)), f"{r.name}: map refused: {exc}; {kept} until "
                                                  f"a valid map arrives")
            changed = r.problem != str(exc)
            r.problem = str(exc)
            if changed:
                self._publish_status()
            return
        if r.problem:
            self.log.info(f"{r.name}: valid map again")
        known = bool(grid.known_mask().any())
        walls = known and bool(grid.occupied_mask().any())
        with self._lock:
            # the first map with a wall: an empty or wall-less map (a SLAM node's first) gives
            # nothing to place the others by
            if self.reference is None and not self.s.known_init_poses and walls:
                # the first robot with a valid map: its map frame is the merged frame
                self.reference = r.name
                self.tracker.fix(r.name, _identity())
                r.last_action = "reference"
                self.log.info(f"{r.name}: reference robot (its map frame is the merged frame)")
            r.problem = ""
            r.known, r.walls = known, walls
            r.grid = grid
            if not r.pose_sent and self.tracker.held(r.name) is not None:   # the reference, or
                self._publish_pose(r)   # a known initial pose: placed once its first map came
            r.received = time.monotonic()
            r.updates += 1
            self._map_version += 1
        self._wake_compose.set()

    # -- publishing (worker threads) ----------------------------------------------------------
    def _publish_pose(self, r: Robot) -> None:
        with self._pose_lock:
            self._publish_pose_locked(r)

    def _publish_pose_locked(self, r: Robot) -> None:
        held = self.tracker.held(r.name)
        if r.pose_pub is None:
            return
        if held is None:
            if r.pose_sent:
                # dropped: a latched pose cannot be taken back, but its publisher can; a
                # subscriber that joins later gets no transform for a robot not placed
                self.node.destroy_publisher(r.pose_pub)
                r.pose_pub = self.node.create_publisher(self._Pose, r.pose_topic, latched_qos())
                r.pose_sent = False
            return
        msg = self._Pose()
        msg.header.frame_id = self.s.world_frame
        msg.header.stamp = self._stamp()
        fill_pose(msg.pose, held[0])
        r.pose_pub.publish(msg)
        r.pose_sent = True
        if self.tf is not None:
            from geometry_msgs.msg import TransformStamped
            t = TransformStamped()
            t.header = msg.header
            t.child_frame_id = f"{robot_slug(r.name)}/map"
            t.transform.translation.x, t.transform.translation.y = msg.pose.position.x, msg.pose.position.y
            t.transform.rotation = msg.pose.orientation
            self.tf.sendTransform(t)

    def status(self) -> dict:
        """What the node knows, as published on ``~/status``."""
        robots = {}
        with self._lock:
            items = list(self.robots.items())
            skipped = dict(self.skipped)
            ref = self.robots.get(self.reference) if self.reference else None
            # a named reference robot not yet heard of (or without a wall): nothing is placed
            no_ref = (self.reference is not None and not self.s.known_init_poses
                      and (ref is None or not ref.walls))
            failed = self.estimate_error
        for name, r in items:
            held = self.tracker.held(name)
            waiting = r.grid is None   # its place may be known (the reference), its map is not
            why = (f"no valid map received yet{f' ({r.problem})' if r.problem else ''}" if waiting else
                   r.last_why or (f"waiting for the reference robot {self.reference}'s map with a "
                                  f"wall" if no_ref and held is None else
                                  "its map holds no known cell yet" if not r.known else
                                  f"the last estimation failed: {failed}" if failed and held is None
                                  else ""))
            robots[name] = {
                "topic": r.topic, "placed": held is not None and not waiting,
                "transform": None if held is None or waiting else held[0].as_dict(4),
                "confidence": None if held is None or waiting else round(held[1], 4),
                "last_decision": r.last_action,
                "reason": why,
                "map": None if r.grid is None else {"width": r.grid.cols, "height": r.grid.rows,
                                                    "resolution": r.grid.resolution},
                "updates": r.updates, "problem": r.problem or None, "vanished": r.vanished}
        for name, (topic, why) in skipped.items():
            robots[name] = {"topic": topic, "placed": False, "transform": None, "confidence": None,
                            "last_decision": "skipped", "reason": why, "map": None, "updates": 0,
                            "problem": None, "vanished": False}
        return {"reference": self.reference, "world_frame": self.s.world_frame,
                "method": "known_init_poses" if self.s.known_init_poses else self.s.method,
                "estimations": self.estimations, "last_estimation_seconds": self.last_estimation_s,
                "last_merge_seconds": self.last_merge_s,
                "robots": robots}

    def _publish_status(self) -> None:
        self.status_pub.publish(self._String(data=json.dumps(self.status(), sort_keys=True)))

    def _shown(self, name: str, r: Robot):
        """The map of robot ``name`` that the merged map shows (call with the lock held): the
        reference's and, with known initial poses, every robot's latest map with a known cell;
        else the map its held transform was last judged on by an estimation (a new map at the
        old transform, before it is judged, could lay a restarted robot's map across the
        others')."""
        if name == self.reference or self.s.known_init_poses:
            return r.grid if r.grid is not None and r.known else None
        return r.judged

    def _compose_loop(self) -> None:
        period = 1.0 / self.s.merging_rate
        done = (-1, -1)
        last = -math.inf
        # the maps and transforms of the merged map last published: a map of a robot not yet
        # placed changes the version but not the merged map, which is not sent again
        sent: list = []
        while not self._stop.is_set():
            self._wake_compose.wait(timeout=1.0)
            self._wake_compose.clear()
            if self._stop.is_set():
                break
            with self._lock:
                version = (self._map_version, self._held_version)
            if version == done:
                continue
            wait = last + period - time.monotonic()
            if wait > 0 and self._stop.wait(wait):
                break
            try:
                with self._lock:
                    version = (self._map_version, self._held_version)
                    placed = [(g, h) for n, r in self.robots.items()
                              if (g := self._shown(n, r)) is not None
                              and (h := self.tracker.held(n)) is not None]
                    first = self.reference
                    ref_grid = self.robots[first].grid if first in self.robots else None
                if not placed:
                    done = version
                    self._publish_status()
                    continue
                if ref_grid is not None:  # the reference first: its resolution is the merged one
                    placed.sort(key=lambda gh: gh[0] is not ref_grid)
                if len(placed) == len(sent) and all(
                        g is g0 and h[0] == h0[0] for (g, h), (g0, h0) in zip(placed, sent)):
                    done = version
                    self._publish_status()
                    continue
                import fusionkit as fk
                t0 = time.perf_counter()
                fused = fk.fuse_maps([g for g, _ in placed], [h[0] for _, h in placed]).grid
                msg = self._GridMsg()
                fill_msg(msg, fused, self.s.world_frame, self._stamp())
                self.merged_pub.publish(msg)
                sent = placed
                self.last_merge_s = round(time.perf_counter() - t0, 4)
                last, done = time.monotonic(), version
                self._publish_status()
            except Exception as exc:  # noqa: BLE001 - log once, go on
                if not self._alive():
                    break
                self._once(("compose", type(exc).__name__), f"merged map not composed: {exc}", "error")
                done = version

    def _estimate_loop(self) -> None:
        while not self._stop.is_set():
            try:
                self._estimate_forever()
            except Exception as exc:  # noqa: BLE001 - log once, start over
                if not self._alive():
                    break
                self._once(("estimate-loop", type(exc).__name__),
                           f"estimation stopped by {type(exc).__name__}: {exc}; restarting", "error")
                self._stop.wait(1.0)

    def _estimate_forever(self) -> None:
        period = 1.0 / self.s.estimation_rate
        done = -1
        while not self._stop.wait(period if done >= 0 else 0.5):
            with self._lock:
                version = self._map_version
                ref = self.reference
                snapshot = [(n, r.grid) for n, r in self.robots.items() if r.grid is not None]
                ref_bare = ref in dict(snapshot) and not self.robots[ref].walls
            if ref_bare:
                # a named reference whose map holds no wall yet: nothing can be placed by it
                self._once(("nowall", ref), f"waiting for the reference robot {ref}'s map "
                           f"to show a wall (reference_robot)", "info")
                if version != done:
                    self._publish_status()
                    done = version
                continue
            # a switch waiting for its confirmations is estimated again on unchanged maps: a
            # robot whose map stopped growing must not keep a transform found worse
            if (version == done and not self.tracker.pending()) or ref not in dict(snapshot) \
                    or len(snapshot) < 2:
                if ref is not None and snapshot and ref not in dict(snapshot):
                    self._once(("noref", ref), f"waiting for the reference robot {ref}'s map", "info")
                if version != done:  # say what is known (the robots, none placed yet) meanwhile
                    self._publish_status()
                    done = version
                continue
            t0 = time.perf_counter()
            try:
                decisions = estimate_round(snapshot, ref, self.s, self.tracker,
                                           cancel=self._stop.is_set)
            except MergeCancelled:
                break
            except Exception as exc:  # noqa: BLE001 - log once, go on
                if not self._alive():
                    break
                said = isinstance(exc, FusionkitError)   # bad input, said in its own words
                self.estimate_error = str(exc) if said else f"{type(exc).__name__}: {exc}"
                self._once(("estimate", str(exc) if said else type(exc).__name__),
                           f"estimation failed: {self.estimate_error}", "warning" if said else "error")
                done = version
                self._publish_status()
                continue
            if not self._alive():
                break
            self.last_estimation_s = round(time.perf_counter() - t0, 3)
            self.estimations += 1
            self.estimate_error = ""
            done = version
            changed = False
            grids = dict(snapshot)
            for d in decisions:
                r = self.robots[d.robot]
                moved = d.action in ("placed", "switched", "refined", "dropped")
                with self._lock:
                    # the map the held transform was just judged on: the merged map shows it
                    judged = grids[d.robot] if d.transform is not None else None
                    if judged is not r.judged:
                        r.judged = judged
                        changed = True
                if (d.action, d.why) != (r.last_action, r.last_why) or moved:
                    self.log.info(d.line())
                else:
                    self.log.debug(d.line())
                r.last_action, r.last_why = d.action, d.why
                if moved:
                    changed = True
                    self._publish_pose(r)
            if changed:
                with self._lock:
                    self._held_version += 1
                self._wake_compose.set()
            else:
                self._publish_status()

    def close(self, timeout: float = 5.0) -> None:
        """Stop the worker threads (a running estimation is cancelled)."""
        self._stop.set()
        self._wake_compose.set()
        for t in self._threads:
            t.join(timeout)


#: Discoveries made once a second after start, before the discovery_rate timer takes over
EARLY_DISCOVERIES = 10


def _identity():
    from .. import Transform2D
    return Transform2D.identity()
