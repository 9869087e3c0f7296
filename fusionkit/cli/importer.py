"""``fusionkit import``: real robot logs (CARMEN, ROS bags) to fusionkit robot logs and maps."""

from __future__ import annotations

import argparse
import math
import textwrap
import time

from ..io_carmen import NO_RETURN_FREE, RESOLUTION, SPLIT_OVERLAP, CarmenConfig, import_carmen
from ..io_rosbag import PoseSource, import_rosbag
from ._common import Progress, float_range, int_range

__all__ = ["register", "run_carmen", "run_rosbag"]


def _paragraphs(*paras: str) -> str:
    """Help text of several paragraphs, each wrapped to 88 columns."""
    return "\n\n".join(textwrap.fill(p, 88) for p in paras)

_RES_HELP = "map cell size in metres (default: %(default)s)"


def register(sub) -> None:
    p = sub.add_parser(
        "import", help="convert a real robot log (CARMEN, ROS bag) into robot logs and maps",
        description="Convert a real robot's laser log into NAME.scans.npz (see docs/formats.md) "
                    "plus the map built from it (NAME.yaml + NAME.pgm), the poses in the "
                    "frame of the first scan. Exit status: 0 done, 2 bad input.")
    kinds = p.add_subparsers(dest="kind", metavar="KIND", required=True)

    c = kinds.add_parser(
        "carmen", help="a CARMEN log (FLASER / ROBOTLASER1 records)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=_paragraphs(
            "Read the FLASER and ROBOTLASER1 records of a CARMEN log (others, such as ODOM, "
            "NEFF, PARAM and comments, are skipped and counted) and write NAME.scans.npz, "
            "NAME.yaml and NAME.pgm in DIR, the poses in the frame of the first scan.",
            "FLASER beams cover 180 degrees counter-clockwise from -90 degrees: an even count n "
            "in steps of 180/n degrees (180 beams: -90..+89), an odd count from -90 to +90 "
            "inclusive (181 beams). The scanner's maximum reading (the largest value when it "
            "repeats, e.g. 81.83 or 32.767 m; under a single stray reading, the most frequent "
            "one near the top, e.g. 51.15 m) and error codes within 0.1% below it mean no "
            "return and are stored as inf, as are readings at or beyond --max-range; the scan "
            "log's range_max is --max-range, else the largest other reading capped at 40 m. "
            "Scans are sorted by timestamp (equal "
            "timestamps keep the file order).",
            "--split K cuts the log into K consecutive sessions sharing --overlap of their "
            "length, written as robot_1..robot_K, each in its own start frame, with "
            "world.yaml/.pgm (the whole log in the log's frame) and truth.json (each robot's "
            "transform into the world frame), as 'fusionkit simulate' writes them. "
            "Exit status: 0 done, 2 bad input."))
    c.add_argument("log", metavar="LOG", help="the CARMEN log file")
    c.add_argument("--out", required=True, metavar="DIR",
                   help="output directory (created if missing)")
    c.add_argument("--name", metavar="NAME",
                   help="file stem of the outputs (default: the log's file name up to its "
                        "first dot, e.g. intel for intel.gfs.log); not allowed with --split")
    c.add_argument("--split", type=int_range(2, 100), metavar="K",
                   help="cut the log into K >= 2 overlapping sessions robot_1..robot_K "
                        "(default: no split, one map named after the log)")
    c.add_argument("--overlap", type=float_range(0.0, 0.9), default=SPLIT_OVERLAP, metavar="F",
                   help="with --split: fraction of each session shared with the next, "
                        "0..0.9 (default: %(default)s)")
    c.add_argument("--resolution", type=float_range(0.0, 10.0, lo_open=True), default=RESOLUTION,
                   metavar="M", help=_RES_HELP)
    c.add_argument("--max-range", type=float_range(0.0, 1000.0, lo_open=True), metavar="M",
                   help="usable sensor range in metres: readings at or beyond it mean no return, "
                        "as does the scanner's no-return value found in the log (default: the "
                        "largest other reading, at most 40 m)")
    c.add_argument("--no-return-free", type=float_range(0.0, 1000.0), default=NO_RETURN_FREE, metavar="M",
                   help="distance in metres a no-return beam marks free space in the maps "
                        "(default: %(default)s: none, since a scanner also reports no return "
                        "when dazzled)")
    c.add_argument("--force", action="store_true",
                   help="replace output files that already exist; over an earlier run (its "
                        "truth.json) also remove its sessions beyond K and the merges of its maps "
                        "that stand in the folder, and say which files went (an input is never "
                        "replaced)")
    c.add_argument("--quiet", action="store_true", help="print nothing on success")
    c.set_defaults(func=run_carmen)

    b = kinds.add_parser(
        "rosbag", help="a ROS 1 .bag or ROS 2 bag directory (LaserScan + odometry or tf)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=_paragraphs(
            "Read the sensor_msgs/LaserScan messages of --scan-topic from a ROS 1 .bag file or "
            "a ROS 2 bag directory (.db3 or .mcap) and pair each with the sensor pose at its "
            "stamp, from --odom-topic (nav_msgs/Odometry, PoseStamped or "
            "PoseWithCovarianceStamped; a fixed laser mounting on /tf_static is applied) or "
            "from the transform tree (--tf: the pose of the scan's frame, else of "
            "--base-frame, in --fixed-frame).",
            "Poses are interpolated between the bracketing samples (x, y linearly, the heading "
            "along the shorter arc); scans outside the poses' time span are dropped and "
            "counted. Messages are sorted by header stamp. NaN readings and readings below "
            "range_min become inf (no return).",
            "Writes NAME.scans.npz, NAME.yaml and NAME.pgm in DIR. Exit status: 0 done, "
            "2 bad input."))
    b.add_argument("bag", metavar="BAG", help="ROS 1 .bag file or ROS 2 bag directory")
    b.add_argument("--scan-topic", required=True, metavar="TOPIC",
                   help="the sensor_msgs/LaserScan topic, e.g. /scan")
    src = b.add_mutually_exclusive_group(required=True)
    src.add_argument("--odom-topic", metavar="TOPIC",
                     help="take poses from this odometry/pose topic, e.g. /odom")
    src.add_argument("--tf", action="store_true",
                     help="take poses from /tf and /tf_static")
    b.add_argument("--fixed-frame", default="odom", metavar="FRAME",
                   help="with --tf: the frame poses are expressed in (default: %(default)s)")
    b.add_argument("--base-frame", default="base_link", metavar="FRAME",
                   help="the robot frame used when the scan's frame is not in the transform "
                        "tree; for PoseStamped poses, the frame they locate "
                        "(default: %(default)s)")
    b.add_argument("--out", required=True, metavar="DIR",
                   help="output directory (created if missing)")
    b.add_argument("--name", metavar="NAME",
                   help="file stem of the outputs (default: the bag's name up to its first dot)")
    b.add_argument("--resolution", type=float_range(0.0, 10.0, lo_open=True), default=0.05,
                   metavar="M", help=_RES_HELP)
    b.add_argument("--no-return-free", type=float_range(0.0, 1000.0), metavar="M",
                   help="distance in metres a no-return beam marks free space in the map "
                        "(default: the scans' range_max)")
    b.add_argument("--keep-frame", action="store_true",
                   help="keep the poses in the bag's pose frame instead of the frame of the "
                        "first scan")
    b.add_argument("--force", action="store_true",
                   help="replace output files that already exist (an input is never replaced)")
    b.add_argument("--quiet", action="store_true", help="print nothing on success")
    b.set_defaults(func=run_rosbag)


def _skipped(skipped) -> str:
    return ", ".join(f"{k} {v}" for k, v in skipped.items()) or "none"


def run_carmen(args) -> int:
    t0 = time.perf_counter()
    progress = Progress("import", enabled=False if args.quiet else None)
    try:
        res = import_carmen(
            args.log, args.out, name=args.name, split=args.split, overlap=args.overlap,
            resolution=args.resolution, no_return_free=args.no_return_free,
            config=CarmenConfig(max_range=args.max_range), overwrite=args.force,
            progress=progress)
    finally:
        progress.close()
    if args.quiet:
        return 0
    s = res.stats
    nr = f"{s.no_return_value:g} m" if s.no_return_value is not None else "none found"
    print(f"{args.log}: {s.records} records, {s.scans} {s.kind} scans kept; skipped: "
          f"{_skipped(s.skipped)}")
    print(f"  no-return value {nr} ({s.no_return_readings} readings set to inf), range_max "
          f"{res.range_max:g} m, {s.out_of_order} scans out of time order (sorted)")
    for r in res.robots:
        print(f"  {r.name}: {r.scans} scans, {r.path_length_m:.1f} m path, map "
              f"{r.shape[1]} x {r.shape[0]} cells, {r.occupied} occupied, {r.free} free; "
              f"its frame in the log's: x {r.transform.x:.3f} m, y {r.transform.y:.3f} m, "
              f"theta {math.degrees(r.transform.theta):.2f} deg")
    if res.world is not None:
        w = res.world
        print(f"  world: map {w.shape[1]} x {w.shape[0]} cells, {w.occupied} occupied; "
              f"truth in {res.truth}")
    print(f"wrote {len(res.files)} files to {args.out} in {time.perf_counter() - t0:.1f} s")
    if res.removed:   # said as simulate says it
        print(f"removed the earlier run's files: {', '.join(p.name for p in res.removed)}")
    return 0


def run_rosbag(args) -> int:
    t0 = time.perf_counter()
    source = PoseSource(odom_topic=args.odom_topic, use_tf=args.tf,
                        fixed_frame=args.fixed_frame, base_frame=args.base_frame)
    progress = Progress("import", enabled=False if args.quiet else None)
    try:
        res = import_rosbag(args.bag, args.out, scan_topic=args.scan_topic, poses=source,
                            name=args.name, resolution=args.resolution,
                            no_return_free=args.no_return_free, keep_frame=args.keep_frame,
                            overwrite=args.force, progress=progress)
    finally:
        progress.close()
    if args.quiet:
        return 0
    s, r = res.stats, res.robot
    print(f"{args.bag}: {s.scan_messages} scans on {args.scan_topic}, "
          f"{s.pose_messages or s.tf_messages} pose messages; kept {s.scans} scans "
          f"(dropped {s.outside_pose_span} outside the poses' time span, {s.other_geometry} "
          f"of another beam geometry)")
    print(f"  poses of {s.sensor_frame} in {s.pose_frame}; {s.invalid_readings} invalid readings "
          f"set to inf; out of order: {s.out_of_order_scans} scans, {s.out_of_order_poses} poses "
          f"(sorted)")
    if s.stamps_from_bag:
        print(f"  header stamps all zero on {', '.join(s.stamps_from_bag)}: used record times")
    print(f"  {r.name}: {r.scans} scans, {r.path_length_m:.1f} m path, map {r.shape[1]} x "
          f"{r.shape[0]} cells, {r.occupied} occupied, {r.free} free")
    print(f"wrote {len(res.files)} files to {args.out} in {time.perf_counter() - t0:.1f} s")
    return 0
