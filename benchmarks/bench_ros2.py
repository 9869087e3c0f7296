"""The live merge node under load: update latency and idle CPU, for 3 and 10 robots.

For each robot count, a seeded simulated run's maps are published (latched, from this
process) to a ``fusionkit ros2 merge-node`` started as its own process; once the node has
placed the robots:

* **idle CPU**: the node's CPU time (user + system, from ``/proc``) over ``--idle`` seconds in
  which nothing changes, as a share of one core;
* **latency**: the last robot's map is updated (one cell changed) ``--updates`` times, 1.5 s
  apart; each latency is the time from that publish to the arrival here of the next merged map.
  The baseline, measured in this same script, is the work the node cannot avoid for one update:
  ``fusionkit.fuse_maps`` of the same maps with the node's transforms plus filling the message
  (median of 10); the second baseline is the node's own time for that work, from its status
  (``last_merge_seconds``), so ``latency_over_node_merge`` is what the transport and the
  scheduling add to the work itself.

Everything talks over loopback only (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, a random
``ROS_DOMAIN_ID``); the node is stopped with SIGINT by its handle.

Run::

    NUMBA_CACHE_DIR=/tmp/fk_numba_cache .venv/bin/python benchmarks/bench_ros2.py [--robots 3 10]
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import statistics
import subprocess
import sys
import time

import numpy as np

import fusionkit as fk


def _cpu_seconds(pid: int) -> float:
    fields = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def bench(n_robots: int, *, poses: int, seed: int, updates: int, idle: float, timeout: float) -> dict:
    import rclpy
    from nav_msgs.msg import OccupancyGrid as GridMsg
    from std_msgs.msg import String

    from fusionkit.ros2._convert import fill_msg
    from fusionkit.ros2.node import latched_qos

    sim = fk.simulate(fk.default_world(), fk.SimulationConfig(robots=n_robots, poses=poses, seed=seed))
    grids = [r.grid for r in sim.robots]
    names = [r.name for r in sim.robots]
    node_proc = subprocess.Popen(
        [sys.executable, "-m", "fusionkit.ros2", "merge-node", "--ros-args",
         "-p", "discovery_rate:=2.0"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
        text=True)
    node = rclpy.create_node(f"bench_{n_robots}")
    got: dict = {"maps": [], "status": None}
    node.create_subscription(GridMsg, "/map", lambda m: got["maps"].append(time.time()), latched_qos())
    node.create_subscription(String, "/map_merge/status",
                             lambda m: got.__setitem__("status", json.loads(m.data)), latched_qos())
    pubs = [node.create_publisher(GridMsg, f"/{n}/map", latched_qos()) for n in names]

    def publish(k, grid):
        msg = GridMsg()
        fill_msg(msg, grid, f"{names[k]}/map", node.get_clock().now().to_msg())
        pubs[k].publish(msg)

    def spin_until(cond, limit):
        end = time.monotonic() + limit
        while time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.05)
            if cond():
                return True
        return False

    def placed():
        st = got["status"]
        return 0 if not st else sum(bool(r["placed"]) for r in st["robots"].values())

    try:
        for k, g in enumerate(grids):
            publish(k, g)
        t_start = time.monotonic()
        spin_until(lambda: placed() == n_robots, timeout)
        t_placed = time.monotonic() - t_start
        n_placed = placed()
        spin_until(lambda: False, 3.0)  # let the last estimation and composition finish

        c0, w0 = _cpu_seconds(node_proc.pid), time.monotonic()
        spin_until(lambda: False, idle)
        idle_share = (_cpu_seconds(node_proc.pid) - c0) / (time.monotonic() - w0)

        latencies, inside = [], []
        last = grids[-1]
        for i in range(updates):
            data = np.array(last.data)
            r, c = np.argwhere(data == fk.FREE)[i]
            data[r, c] = fk.OCCUPIED if i % 2 == 0 else fk.FREE
            n_before = len(got["maps"])
            t0 = time.time()
            publish(n_robots - 1, last.with_data(data))
            if spin_until(lambda: len(got["maps"]) > n_before, 30.0):
                latencies.append(got["maps"][n_before] - t0)
            spin_until(lambda: False, 1.5)
            inside.append(got["status"]["last_merge_seconds"])

        # the baseline: fusing the same maps with the node's transforms and filling the message
        st = got["status"]["robots"]
        held = [(g, fk.Transform2D.from_dict(st[f"/{n}"]["transform"]))
                for g, n in zip(grids, names) if st.get(f"/{n}", {}).get("placed")]
        base = []
        for _ in range(10):
            t0 = time.perf_counter()
            fused = fk.fuse_maps([g for g, _ in held], [t for _, t in held]).grid
            fill_msg(GridMsg(), fused, "world", node.get_clock().now().to_msg())
            base.append(time.perf_counter() - t0)
    finally:
        node_proc.send_signal(signal.SIGINT)
        try:
            rc = node_proc.wait(30)
        except subprocess.TimeoutExpired:
            node_proc.kill()
            rc = node_proc.wait(10)
        node.destroy_node()
    return {"robots": n_robots, "placed": n_placed, "seconds_to_place": round(t_placed, 2),
            "merged_cells": int(fused.data.size), "idle_cpu_share": round(idle_share, 4),
            "latency_median_s": round(statistics.median(latencies), 4) if latencies else None,
            "latency_max_s": round(max(latencies), 4) if latencies else None,
            "baseline_median_s": round(statistics.median(base), 4),
            "node_merge_median_s": statistics.median(inside) if inside else None,
            "latency_over_node_merge": round(statistics.median(latencies) / statistics.median(inside), 2)
            if latencies and inside else None,
            "latency_over_baseline": round(statistics.median(latencies) / statistics.median(base), 1)
            if latencies else None,
            "updates_answered": len(latencies), "node_exit": rc,
            "load_average": os.getloadavg()[0]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robots", type=int, nargs="+", default=[3, 10])
    ap.add_argument("--poses", type=int, default=1500)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--updates", type=int, default=10)
    ap.add_argument("--idle", type=float, default=20.0)
    ap.add_argument("--timeout", type=float, default=300.0, help="seconds to wait for placement")
    args = ap.parse_args(argv)
    os.environ.setdefault("ROS_DOMAIN_ID", str(random.SystemRandom().randint(1, 101)))
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    import rclpy
    rclpy.init()
    try:
        for n in args.robots:
            res = bench(n, poses=args.poses, seed=args.seed, updates=args.updates,
                        idle=args.idle, timeout=args.timeout)
            print(json.dumps(res), flush=True)
    finally:
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
