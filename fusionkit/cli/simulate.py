"""``fusionkit simulate``: robots explore a world and record maps and scans (docs/formats.md)."""

from __future__ import annotations

import time
from pathlib import Path

from ._common import Progress, float_range, int_range

_DEFAULT_WORLD_NOTE = ("without --world or --world-kind: the built-in office (seed 0, 40 x 30 m at "
                       "0.1 m, the same map as maps/office.yaml)")


def register(sub) -> None:
    from ..simulate import MOTION_MODES, LidarConfig, MotionConfig
    from ..worlds import WORLDS

    lid, mot = LidarConfig(), MotionConfig()
    p = sub.add_parser(
        "simulate", help="simulate robots exploring a world; write their maps, scans and truth.json",
        description="Simulate N robots that each start at a random free place of a ground-truth "
                    "world and move about it, recording every pose and a 2-D LIDAR scan, as in the "
                    "paper's Section 4. Each robot's map (robot_k.yaml + .pgm) and scan log "
                    "(robot_k.scans.npz) are in its OWN frame, origin at its start pose. "
                    "truth.json holds each map's true transform into the world frame, for "
                    "evaluation only; the world itself is copied to world.yaml + world.pgm. "
                    f"World: {_DEFAULT_WORLD_NOTE}. File formats: docs/formats.md.",
        )
    w = p.add_mutually_exclusive_group()
    w.add_argument("--world", metavar="W.yaml", default=None,
                   help="ground-truth world as a ROS map_server map (occupied cells return beams, "
                        "free and unknown cells let them pass, robots drive in free cells)")
    w.add_argument("--world-kind", choices=list(WORLDS), default=None,
                   help="generate a world of this kind instead of loading one (default: office)")
    p.add_argument("--world-seed", type=int_range(0, 2**31 - 1), default=None, metavar="N",
                   help="layout seed of a generated world (default: 0)")
    p.add_argument("--world-size", type=float_range(10.0, 2000.0), nargs=2, metavar=("W", "H"),
                   default=None, help="width and height (m) of a generated world (default: 40 30)")
    p.add_argument("--resolution", type=float_range(0.01, 0.5), default=None, metavar="M",
                   help="cell size (m) of a generated world and of the robots' maps "
                        "(default: 0.1 for a generated world, the world map's for --world)")
    p.add_argument("--robots", type=int_range(1, 64), default=5, metavar="N", help="number of robots (default: %(default)s)")
    p.add_argument("--poses", type=int_range(10, 1_000_000), default=5000, metavar="P",
                   help="poses (and scans) recorded per robot (default: %(default)s)")
    p.add_argument("--seed", type=int_range(0, 2**63 - 1), default=0, metavar="S",
                   help="seed of the simulation: starts, motion, range noise, drift; the world's "
                        "layout has its own, --world-seed (default: %(default)s)")
    g = p.add_argument_group("LIDAR")
    g.add_argument("--beams", type=int_range(2, 10_000), default=lid.beams, metavar="B",
                   help="beams per scan (default: %(default)s)")
    g.add_argument("--fov", type=float_range(0.0, 360.0, lo_open=True), default=lid.fov_deg,
                   metavar="DEG", help="field of view (degrees), centred on the heading (default: %(default)s)")
    g.add_argument("--max-range", type=float_range(0.0, 1000.0, lo_open=True), default=lid.max_range,
                   metavar="M", help="sensor range (m); farther walls give no return (inf) (default: %(default)s)")
    g.add_argument("--range-noise", type=float_range(0.0, 100.0), default=lid.range_noise, metavar="M",
                   help="standard deviation of the gaussian range noise (m) (default: %(default)s)")
    g = p.add_argument_group("motion and odometry")
    g.add_argument("--motion", choices=MOTION_MODES, default=mot.mode,
                   help="waypoint: drive to random goals along shortest paths (explores the whole "
                        "world); wander: smooth random walk that turns away from walls (default: %(default)s)")
    g.add_argument("--speed", type=float_range(0.0, 10.0, lo_open=True), default=mot.speed,
                   metavar="M/S", help="forward speed (m/s) (default: %(default)s)")
    g.add_argument("--scan-period", type=float_range(0.0, 10.0, lo_open=True), default=mot.scan_period,
                   metavar="S", help="time between two poses (s); a step is speed x scan period (default: %(default)s)")
    g.add_argument("--clearance", type=float_range(0.0, 10.0), default=mot.clearance, metavar="M",
                   help="least distance (m) the robots keep from occupied and unknown cells (default: %(default)s)")
    g.add_argument("--drift-xy", type=float_range(0.0, 1.0), default=mot.drift_xy, metavar="M",
                   help="odometry position error (m) per square-root metre travelled (0: perfect "
                        "odometry) (default: %(default)s)")
    g.add_argument("--drift-theta", type=float_range(0.0, 1.0), default=mot.drift_theta, metavar="RAD",
                   help="odometry heading error (rad) per square-root metre travelled (default: %(default)s)")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="run directory; must be new, empty, or hold an earlier run (its truth.json), "
                        "which is replaced, with the merges of its maps that stand in the folder")
    p.add_argument("--quiet", action="store_true", help="print nothing on success")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..errors import InputError
    from ..mapio import load_map
    from ..mapping import MappingConfig
    from ..sim_output import check_run_dir
    from ..simulate import LidarConfig, MotionConfig, SimulationConfig, simulate, write_run
    from ..worlds import DEFAULT_RESOLUTION, DEFAULT_SIZE, default_world, make_world

    t0 = time.perf_counter()
    check_run_dir(args.out)  # before any work: a file, a read-only or a foreign folder
    lidar = LidarConfig(beams=args.beams, fov_deg=args.fov, max_range=args.max_range,
                        range_noise=args.range_noise)
    motion = MotionConfig(mode=args.motion, speed=args.speed, scan_period=args.scan_period,
                          clearance=args.clearance, start_clearance=max(MotionConfig().start_clearance,
                                                                        args.clearance),
                          drift_xy=args.drift_xy, drift_theta=args.drift_theta)
    if args.world is not None:
        for flag, value in (("--world-size", args.world_size), ("--world-seed", args.world_seed)):
            if value is not None:   # --world-seed was ignored without a word
                raise InputError(f"{flag} applies to generated worlds only; leave it out with --world")
        world = load_map(args.world)
        source = args.world
    elif args.world_kind is None and args.world_size is None and args.resolution is None \
            and not args.world_seed:
        world = default_world()
        source = "office (built in, layout seed 0)"
    else:
        kind, layout = args.world_kind or "office", args.world_seed or 0
        world = make_world(kind, layout, args.world_size or DEFAULT_SIZE,
                           args.resolution or DEFAULT_RESOLUTION)
        source = f"{kind} (generated, layout seed {layout})"
    mapping = MappingConfig(resolution=args.resolution or world.resolution)
    config = SimulationConfig(robots=args.robots, poses=args.poses, lidar=lidar, motion=motion,
                              mapping=mapping, seed=args.seed)
    progress = Progress("simulating", enabled=None if not args.quiet else False)
    sim = simulate(world, config, progress=progress)
    progress.close()
    # what the write takes away of an earlier run: the robots this run has not, their merges
    out = Path(args.out)
    before = {p.name for p in out.iterdir() if p.is_file()} if out.is_dir() else set()
    truth = write_run(sim, args.out, world_path=args.world)
    seconds = time.perf_counter() - t0
    removed = sorted(before - {p.name for p in out.iterdir() if p.is_file()})
    if not args.quiet:
        print(format_summary(sim, source))
        print(f"wrote {len(sim.robots)} robot maps, scans and {truth} in {seconds:.1f} s")
        if removed:
            shown = ", ".join(removed[:12]) + (f" and {len(removed) - 12} more" if len(removed) > 12 else "")
            print(f"removed the earlier run's files that this one makes wrong: {shown}")
    return 0


def format_summary(sim, source: str) -> str:
    """A table of what each robot recorded, for the terminal."""
    w = sim.world
    cov = sim.coverage()
    lines = [f"world: {source}: {w.cols} x {w.rows} cells at {w.resolution:g} m "
             f"({w.cols * w.resolution:g} x {w.rows * w.resolution:g} m)",
             f"robots: simulation seed {sim.config.seed} (starts, motion, range noise, drift; "
             f"--world-seed sets the world's layout)",
             f"{'robot':<10} {'poses':>7} {'path (m)':>9} {'map (cells)':>12} {'map (m)':>13} "
             f"{'known cells':>11} {'covers':>7}"]
    for r, c in zip(sim.robots, cov.per_robot):
        g = r.grid
        lines.append(f"{r.name:<10} {r.scans.n_scans:>7} {r.path_length:>9.1f} "
                     f"{f'{g.cols}x{g.rows}':>12} "
                     f"{f'{g.cols * g.resolution:.1f}x{g.rows * g.resolution:.1f}':>13} "
                     f"{int(g.known_mask().sum()):>11} {100 * c:>6.1f}%")
    lines.append(f"all maps together cover {100 * cov.combined:.1f}% of the world's known cells")
    return "\n".join(lines)
