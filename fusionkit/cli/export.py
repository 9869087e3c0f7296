"""``fusionkit export``: a simulated run written as a ROS bag."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from ..errors import InputError
from ..io_rosbag import export_rosbag
from ._common import Progress, float_range, paragraphs

__all__ = ["register", "run_rosbag"]


def register(sub) -> None:
    p = sub.add_parser(
        "export", help="write a simulated run as a ROS bag",
        description="Write fusionkit data in other tools' formats. Exit status: 0 done, "
                    "2 bad input.")
    kinds = p.add_subparsers(dest="kind", metavar="KIND", required=True)
    b = kinds.add_parser(
        "rosbag", help="a run directory (NAME.scans.npz + NAME.yaml per robot) as a ROS bag",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=paragraphs(
            "Write every robot of RUN_DIR (NAME.scans.npz, and NAME.yaml when present) as a "
            "ROS bag: per robot /NAME/scan (sensor_msgs/LaserScan, frame NAME/laser), "
            "/NAME/odom (nav_msgs/Odometry: the laser's pose in NAME/map, zero twist), "
            "/NAME/map (nav_msgs/OccupancyGrid, once, latched) and the same pose on /tf.",
            "Scan i of every robot is stamped START + i / RATE seconds. The bag is written "
            "under a temporary name and renamed when complete; an existing output is never "
            "replaced. Exit status: 0 done, 2 bad input."))
    b.add_argument("run_dir", metavar="RUN_DIR", help="directory of a simulated run")
    b.add_argument("--out", metavar="BAG",
                   help="output bag: a .bag file for ros1, a directory for ros2 (default: "
                        "RUN_DIR.bag or RUN_DIR_bag beside the run directory)")
    b.add_argument("--format", dest="fmt", choices=("ros2", "ros1"), default=None,
                   help="bag format (default: ros1 when --out ends in .bag, else ros2)")
    b.add_argument("--storage", choices=("sqlite3", "mcap"), default=None,
                   help="ROS 2 storage plugin (default: sqlite3)")
    b.add_argument("--rate", type=float_range(0.0, 10000.0, lo_open=True), default=10.0,
                   metavar="HZ", help="scans per second per robot (default: %(default)s Hz)")
    b.add_argument("--start", type=float_range(0.0, 2.0 ** 31), default=1.0, metavar="S",
                   help="stamp of the first scan in seconds (default: %(default)s s)")
    b.add_argument("--quiet", action="store_true", help="print nothing on success")
    b.set_defaults(func=run_rosbag)


def run_rosbag(args) -> int:
    t0 = time.perf_counter()
    fmt = args.fmt or ("ros1" if args.out and str(args.out).endswith(".bag") else "ros2")
    if fmt == "ros1" and args.storage is not None:
        raise InputError(f"--storage {args.storage} is for ROS 2 bags, and this one is ROS 1 "
                         f"({'--format ros1' if args.fmt else 'the output ends in .bag'}); drop "
                         f"--storage, or give a ROS 2 bag's directory name")
    left = _robots_without_scans(Path(args.run_dir))   # read before any output is written
    progress = Progress("export", enabled=False if args.quiet else None)
    try:
        res = export_rosbag(args.run_dir, args.out, fmt=fmt, storage=args.storage or "sqlite3",
                            rate=args.rate, start_s=args.start, progress=progress)
    finally:
        progress.close()
    if args.quiet:
        return 0
    for r in res.robots:
        maps = f", {r.map_topic}" if r.map_topic else " (no map beside the scans)"
        print(f"  {r.name}: {r.scans} scans on {r.scan_topic}, {r.odom_topic}{maps}")
    if left:
        print(f"  not in the bag, no scan log beside their maps: {', '.join(left)}")
    print(f"wrote {res.path} ({res.format}, {res.storage}): {res.messages} messages over "
          f"{res.duration_s:.1f} s in {time.perf_counter() - t0:.1f} s")
    return 0


def _robots_without_scans(run_dir: Path) -> list[str]:
    """The robots the run's truth.json names that have no ``NAME.scans.npz`` (left out of the
    bag, which holds scans)."""
    from .._inputs import read_json
    truth = run_dir / "truth.json"
    try:   # as every input is read: a regular file, of a bounded size (a FIFO hung the export)
        robots = read_json(truth, "ground truth")["robots"] if truth.exists() else []
        names = [str(r["name"]) for r in robots]
    except (InputError, OSError, KeyError, TypeError):
        return []
    return [n for n in names if not (run_dir / f"{n}.scans.npz").is_file()]
