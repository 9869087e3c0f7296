"""``fusionkit run``: the main job on a scenario: simulate, merge, evaluate (Table 1)."""

from __future__ import annotations

import json
import math
import textwrap
import time

from ._common import Progress, add_merge_options, int_range, merge_config_from_args


#: What the columns of Table 1 mean (docs/formats.md gives the exact definitions).
COLUMNS = (
    "Compl  completeness: % of the world's known cells that the fused map knows",
    "Acc    accuracy: % of the world's known cells the fused map has in the right state "
    "(free or wall)",
    "Prec   precision: % of the fused map's wall cells that are walls in the world, cell-exact",
    "Eff    efficiency: Compl x Prec / 100",
    "Prec1  precision with one cell of tolerance: a wall cell next to a true wall counts",
)

#: Why the first row differs from the paper's.
M1_NOTE = (
    "Row M1 is the first map of the fusion order alone, before any fusion, placed in the world "
    "by its transform into the reference's frame: it measures how much of the world that robot "
    "explored and how its map draws walls, and, beside the oracle's M1, how well that one map "
    "was placed (when it is not the reference). The paper's "
    "world and trajectories are not published, so its M1 (one robot's map that already "
    "covers 80 % of its building) cannot be matched; compare fusionkit with the oracle columns "
    "instead: the same maps fused with the true transforms, the best any method can do."
)


def register(sub) -> None:
    p = sub.add_parser(
        "run", help="simulate the default scenario, merge the robots' maps and print Table 1",
        description="The paper's experiment end to end: simulate N robots exploring a world "
                    "(default: the office, 5 robots x 5000 poses), write their maps, merge them "
                    "and print the paper's Table 1 (completeness, accuracy, precision, "
                    "efficiency of M1, M1,2, ...) beside the paper's own numbers and the oracle "
                    "(fusion with the true transforms). It merges with the paper's method "
                    "(spectral-pso) unless --method says otherwise; fusionkit merge defaults "
                    "to consensus. File formats: docs/formats.md.")
    p.add_argument("--out", default="runs/default", metavar="DIR",
                   help="run directory: robot maps, truth.json, merged.yaml, report (default runs/default)")
    p.add_argument("--world", metavar="W.yaml", help="world map (default: the built-in office)")
    p.add_argument("--robots", type=int_range(2, 64), default=5, help="number of robots (default 5)")
    p.add_argument("--poses", type=int_range(10, 1_000_000), default=5000,
                   help="poses per robot (default 5000)")
    # --seed is the simulation's seed, as in `fusionkit simulate`; the merge's is --merge-seed.
    # (--sim-seed, its older name, still works.)
    add_merge_options(p, method="spectral-pso", seed_flag="--merge-seed")
    p.add_argument("--seed", "--sim-seed", dest="sim_seed", type=int_range(0, 2**63 - 1), default=7,
                   metavar="S", help="seed of the simulation: starts, motion, range noise, drift "
                                     "(default 7; --sim-seed is the same)")
    p.set_defaults(func=run)


def fusion_order_line(result, names) -> str:
    """The order the maps were fused in, on one line."""
    order = list(result.order)
    if not order:
        return "fusion order: (no map placed)"
    anchor = {b: a for a, b in result.fusion_order}
    steps = [names[order[0]]]
    for k in order[1:]:
        steps.append(f"{names[k]} (onto {names[anchor[k]]})" if k in anchor else names[k])
    return "fusion order: " + ", ".join(steps) + "; Table 1 row M1,..,k = its first k maps"


def format_run(result, names, errors) -> str:
    """Each map's placement and its error against the truth, as a table."""
    lines = [f"{'map':<12} {'merged':<6} {'conf':>5} {'x (m)':>8} {'y (m)':>8} {'theta (deg)':>11} "
             f"{'error (m)':>9} {'(cells)':>7} {'error (deg)':>11}"]
    for p in result.placements:
        e = errors[p.index]
        if p.transform is None:
            lines.append(f"{names[p.index]:<12} {'no':<6} {p.confidence:5.2f} {'-':>8} {'-':>8} "
                         f"{'-':>11} {'-':>9} {'-':>7} {'-':>11}  {p.reason}")
            continue
        t = p.transform
        lines.append(f"{names[p.index]:<12} {'yes' if p.merged else 'no':<6} {p.confidence:5.2f} "
                     f"{t.x:8.2f} {t.y:8.2f} {math.degrees(t.theta):11.1f} "
                     f"{e.translation_m:9.2f} {e.translation_cells:7.1f} {e.rotation_deg:11.2f}")
    return "\n".join(lines)


def run(args) -> int:
    from ..fusion import fuse_maps
    from ..mapio import group_map_files, load_map, save_maps
    from ..metrics import format_table1, table1, table1_label, transform_errors
    from ..pipeline import merge
    from ..sim_output import check_run_dir
    from ..simulate import SimulationConfig, simulate, write_run
    from ..worlds import default_world

    out = check_run_dir(args.out)  # before any work
    world = load_map(args.world) if args.world else default_world()
    sim_cfg = SimulationConfig(robots=args.robots, poses=args.poses, seed=args.sim_seed)
    t0 = time.perf_counter()
    progress = Progress("simulating")
    sim = simulate(world, sim_cfg, progress=progress)
    progress.close()
    merged_path = out / "merged.yaml"
    # The merged set of an earlier run goes with its robots (until this run's merge replaces it).
    write_run(sim, out, world_path=args.world,
              stale=[merged_path, merged_path.with_suffix(".pgm"), out / "merged.report.json",
                     *group_map_files(merged_path)])
    t_sim = time.perf_counter() - t0
    files = [f"robot_{k + 1}.yaml" for k in range(args.robots)]
    names = [f.removesuffix(".yaml") for f in files]
    inputs = [str(out / n) for n in files]
    config = merge_config_from_args(args)
    progress = Progress("merging")

    def callback(ev):
        progress(ev.step, max(ev.total, 1), f"{ev.stage} {ev.label}")

    result = merge(inputs, config=config, callback=callback)
    progress.close()
    save_maps([(result.grid, merged_path)],
              (out / "merged.report.json",
               json.dumps(result.report(inputs, output=str(merged_path)), indent=2) + "\n"),
              inputs=inputs, remove=group_map_files(merged_path))

    # Table 1: the fused map after each step, placed in the world by the reference's true pose
    ref_true = sim.robots[config.reference].transform
    rows = table1(result.fused.steps, world, ref_true)
    oracle_tf = [ref_true.inverse @ r.transform for r in sim.robots]
    order = list(result.order)
    # the maps the merge left out are fused last by the oracle: the rows that need them are
    # blank on fusionkit's side only
    left = [k for k in range(len(sim.robots)) if k not in order]
    oracle = fuse_maps([r.grid for r in sim.robots], oracle_tf, order=order + left, keep_steps=True)
    oracle_rows = table1(oracle.steps, world, ref_true)
    errors = [None if p.transform is None else
              transform_errors(p.transform, oracle_tf[p.index], world.resolution)
              for p in result.placements]
    where = args.world or "the built-in office"
    print(f"simulated {args.robots} robots x {args.poses} poses in {where} (seed {args.sim_seed}) "
          f"in {t_sim:.1f} s -> {out}/")
    print(f"merged with {result.config.method} (merge seed {result.config.seed}) in "
          f"{result.seconds.get('total', 0.0):.1f} s; transforms into {names[config.reference]}'s "
          f"frame, errors against the truth:")
    print(format_run(result, names, errors))
    print()
    print(fusion_order_line(result, names))
    print(format_table1(rows, paper=True, oracle=oracle_rows))
    if left:
        blank = [table1_label(k) for k in range(len(rows), len(oracle_rows))]
        print(f"{', '.join(names[k] for k in left)} left out by the merge: the oracle fuses "
              f"{'them' if len(left) > 1 else 'it'} last, and fusionkit's cells of row"
              f"{f's {blank[0]} to {blank[-1]}' if len(blank) > 1 else f' {blank[0]}'} are blank")
    print("\nAll columns in percent, measured on the world's cells (docs/formats.md, metrics):")
    for line in COLUMNS:
        print(f"  {line}")
    print()
    print(textwrap.fill(M1_NOTE, width=100))
    print(f"\nfused map: {merged_path}; evaluate it with: fusionkit evaluate {merged_path} "
          f"--truth {out / 'truth.json'}")
    return 0 if result.all_merged else 3
