"""``fusionkit bench``: every method on the same seeded cases, scored against the truth."""

from __future__ import annotations

import shlex
import sys
from pathlib import Path

from ..errors import InputError
from ._common import float_range, int_range
from ._executor import add_executor_options, executor_from_args


def register(sub) -> None:
    from ..bench import DEFAULT_METHODS, MODES, BenchConfig
    from ..pipeline import METHODS
    from ..worlds import WORLDS
    d = BenchConfig()
    p = sub.add_parser(
        "bench", help="compare merging methods on seeded cases made from ground-truth maps",
        description="Make seeded cases from a folder of ground-truth maps (ROS map_server YAML) "
                    "and run every method on the same cases: 'explore' cases are simulated robots "
                    "exploring a map (own-frame maps with scans), 'crop' cases are overlapping "
                    "windows of a map, each turned and shifted at random (no scans); with --logs, "
                    "'log' cases are real laser logs split into sessions. A pair (a "
                    "non-reference map of a case) is a success when merged with a rotation error "
                    "below --max-rotation and its centroid within --max-cells of the truth, a wrong "
                    "merge when merged outside those bounds, a refusal when not merged. Prints the "
                    "table and writes OUT/bench.md, OUT/bench.json and OUT/bench_METHOD.png (one "
                    "case per method). Results do not depend on --jobs or on the back end; timings do.")
    p.add_argument("folders", nargs="*", metavar="DIR",
                   help="folders of ground-truth maps (*.yaml); default: maps and maps/real, plus "
                        "the built-in worlds not already found there (none when --worlds names "
                        "worlds)")
    p.add_argument("--worlds", nargs="*", choices=list(WORLDS), default=None, metavar="NAME",
                   help=f"built-in worlds to bench ({', '.join(WORLDS)}): beside the folders "
                        f"given, or alone when none is; default: all of them when no folder is "
                        f"given, none otherwise")
    p.add_argument("--logs", nargs="+", default=[], metavar="LOG",
                   help="CARMEN laser logs (files, or folders of *.log) to add as 'log' cases: each "
                        "log split into K sessions for every K of --robots (one case each, beside "
                        "the --cases drawn from the maps), the sessions' maps with their recorded "
                        "scans, as 'fusionkit import carmen --split K' writes them; the truth is "
                        "the log's poses, so give SLAM-corrected logs (such as the *.gfs.log of "
                        "Radish). The options of explore and crop cases do not apply to them. With "
                        "--cases 0, the logs alone. Give folders of maps before --logs")
    p.add_argument("--methods", nargs="+", choices=METHODS, default=list(DEFAULT_METHODS), metavar="M",
                   help=f"methods to compare (default: {' '.join(DEFAULT_METHODS)}"
                        f"{''.join(f'; also {m}' for m in METHODS if m not in DEFAULT_METHODS)})")
    p.add_argument("--modes", nargs="+", choices=MODES, default=list(d.modes),
                   help=f"kinds of case (default: {' '.join(d.modes)})")
    p.add_argument("--cases", type=int_range(0, 100000), default=d.cases,
                   help=f"number of cases drawn from the maps (default {d.cases}); the worlds are cycled, then the "
                        f"modes (one mode per round of worlds, so fewer cases than worlds are all "
                        f"of the first mode), and K")
    p.add_argument("--robots", nargs="+", type=int_range(2, 5), default=list(d.robots), metavar="K",
                   help=f"maps per case, cycled (default: {' '.join(map(str, d.robots))})")
    p.add_argument("--min-overlap", type=float_range(0, 1, lo_open=True), default=d.min_overlap,
                   help=f"least overlap (fraction of the smaller map's known cells) linking each map "
                        f"to another (default {d.min_overlap})")
    p.add_argument("--max-overlap", type=float_range(0, 1, lo_open=True), default=d.max_overlap,
                   help=f"largest overlap of a crop with the window it is drawn beside "
                        f"(default {d.max_overlap})")
    p.add_argument("--poses", type=int_range(100, 1_000_000), default=d.poses,
                   help=f"poses per simulated robot (explore; default {d.poses})")
    p.add_argument("--range-noise", type=float_range(0, 1), default=d.range_noise,
                   help=f"LIDAR range noise, standard deviation in m (explore; default {d.range_noise})")
    p.add_argument("--drift", type=float_range(0, 1), default=d.drift,
                   help=f"odometry translation drift in m per square-root metre travelled "
                        f"(explore; default {d.drift})")
    p.add_argument("--drift-theta", type=float_range(0, 1), default=d.drift_theta,
                   help=f"odometry heading drift in rad per square-root metre travelled "
                        f"(explore; default {d.drift_theta})")
    p.add_argument("--cell-noise", type=float_range(0, 0.5), default=d.cell_noise,
                   help=f"fraction of each crop's wall cells moved to a neighbouring cell "
                        f"(crop; default {d.cell_noise})")
    p.add_argument("--crop-fraction", type=float_range(0.1, 1), default=d.crop_fraction,
                   help=f"side of a crop as a fraction of the shorter side of the map's known area "
                        f"(crop; default {d.crop_fraction})")
    p.add_argument("--max-rotation", type=float_range(0, 180, lo_open=True), default=d.max_rotation_deg,
                   help=f"success bound on the rotation error, degrees (default {d.max_rotation_deg})")
    p.add_argument("--max-cells", type=float_range(0, 1e6, lo_open=True), default=d.max_cells,
                   help=f"success bound on the centroid displacement, cells (default {d.max_cells})")
    p.add_argument("--seed", type=int_range(0, 2**63 - 1), default=d.seed, help=f"seed of the suite (default {d.seed})")
    p.add_argument("--jobs", type=int_range(1, 64), default=1,
                   help="cases run in this many processes at once (default 1; the same as "
                        "--workers); with more than one, every method runs on one thread (with "
                        "one, a method may use every core, as OpenCV does for map-merge)")
    add_executor_options(p, what="cases")
    p.add_argument("--out", default="bench", metavar="DIR",
                   help="output folder, created if missing (default: bench)")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")
    p.set_defaults(func=run)


def run(args) -> int:
    from .._atomic import check_not_input, check_out_dir
    from ..bench import (BenchConfig, find_logs, find_worlds, format_table, run_bench, summarize,
                         write_outputs)
    from ..bench.report import output_files
    from ..labels import count
    from ..progress import ProgressBar

    folders = list(args.folders)
    builtin = args.worlds
    defaulted = not folders and not builtin   # `--worlds office` alone benches the office alone
    if defaulted:
        folders = [f for f in ("maps", "maps/real") if Path(f).is_dir()]
        if builtin is None:
            from ..worlds import WORLDS
            builtin = list(WORLDS)
    builtin = builtin or []
    if defaulted and not folders and not builtin and args.cases > 0:   # `--worlds` naming none
        raise InputError("--worlds names no world and no folder of maps is given (no ./maps here): "
                         "name built-in worlds after --worlds, or give folders of maps")
    config = BenchConfig(methods=tuple(args.methods), modes=tuple(args.modes), robots=tuple(args.robots),
                         cases=args.cases, min_overlap=args.min_overlap, max_overlap=args.max_overlap,
                         poses=args.poses, range_noise=args.range_noise, drift=args.drift,
                         drift_theta=args.drift_theta, cell_noise=args.cell_noise,
                         crop_fraction=args.crop_fraction, max_rotation_deg=args.max_rotation,
                         max_cells=args.max_cells, seed=args.seed)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: exists and is not a folder; choose another --out")
    check_out_dir(out)   # before the cases are run, not when their tables are written
    if args.cases == 0 and not args.logs:
        raise InputError("--cases 0 leaves no case to run: give --cases 1 or more, or logs to split "
                         "(--logs)")
    if args.cases == 0 and (args.folders or args.worlds):
        raise InputError("--cases 0 draws no case from the maps: leave out the folders of maps and "
                         "--worlds, or give --cases 1 or more")
    for p in map(Path, args.logs):
        if p.is_dir() and not any(p.glob("*.log")) and any(p.glob("*.yaml")):
            raise InputError(f"{p}: a folder of maps given among --logs; give the folders of maps "
                             f"before --logs")
    use_maps = args.cases > 0
    worlds, skipped = find_worlds(folders, builtin) if use_maps else ([], [])
    logs, more = find_logs(args.logs, taken=[w.name for w in worlds])
    if args.logs and not logs:
        raise InputError("no usable CARMEN log among --logs: " + "; ".join(f"{n}: {w}" for n, w in more))
    worlds += logs
    skipped += more
    # every file the bench reads, used or not: no output may replace one, and no input is
    # taken for the picture of a method this run does not have
    inputs = _inputs(folders if use_maps else [], logs)
    check_not_input(output_files(out, config.methods), inputs)
    progress = ProgressBar("bench", unit="cases", enabled=False if args.quiet else None)
    command = "fusionkit bench " + " ".join(shlex.quote(a) for a in sys.argv[2:]) \
        if len(sys.argv) > 1 and sys.argv[1] == "bench" else ""
    with executor_from_args(args, jobs=args.jobs) as executor:
        if defaulted and use_maps and not args.quiet:
            # the default folders are relative to where the command runs: say what was found
            # (once the options are known good: an error is then the only line)
            print("no folder given: the maps of " + " and ".join(f"./{f}" for f in folders)
                  + (", and the built-in worlds" if builtin else "") if folders else
                  "no folder given, and no ./maps or ./maps/real here: the built-in worlds only "
                  "(give folders of maps to bench on them)", flush=True)
        if not args.quiet and executor.name != "inprocess":
            progress.note(executor.describe())
        result = run_bench(worlds, config, skipped=skipped, command=command, executor=executor,
                           progress=lambda done, total, label: progress(done, total, label))
        progress.close()
    summary = summarize(result)
    paths = write_outputs(result, out, summary, inputs=inputs)
    if not args.quiet:
        if skipped:
            print("not used: " + "; ".join(f"{n} ({w})" for n, w in skipped))
        used = len({c["world"] for c in result.cases})
        print(f"{count(len(result.cases), 'case')} on {used} of {count(len(worlds), 'world')} in "
              f"{result.seconds:.0f} s")
        print(format_table(result, summary))
        print("wrote " + ", ".join(str(p) for p in paths))
    return 0


def _inputs(folders, logs) -> list[Path]:
    """The files a bench reads: every map YAML of ``folders`` and the image it names, and the
    logs (:class:`~fusionkit.bench.WorldSpec` of ``logs``)."""
    from ..mapio import _protected

    maps = [p for f in folders for p in sorted(Path(f).glob("*.yaml"))]
    return _protected(maps) + [Path(w.log) for w in logs]
