"""``fusionkit run``: the main job on a scenario: simulate, merge, evaluate (Table 1)."""

from __future__ import annotations

import json
import time

from ._common import Progress, add_merge_options, int_range, merge_config_from_args


def register(sub) -> None:
    p = sub.add_parser(
        "run", help="simulate the default scenario, merge the robots' maps and print Table 1",
        description="The paper's experiment end to end: simulate N robots exploring a world "
                    "(default: the office, 5 robots x 5000 poses), write their maps, merge them "
                    "and print the paper's Table 1 (completeness, accuracy, precision, "
                    "efficiency of M1, M1,2, ...) beside the paper's own numbers and the oracle "
                    "(fusion with the true transforms). It merges with the paper's method "
                    "(spectral-pso) unless --method says otherwise; fusionkit merge defaults "
                    "to consensus.")
    p.add_argument("--out", default="runs/default", metavar="DIR",
                   help="run directory: robot maps, truth.json, merged.yaml, report (default runs/default)")
    p.add_argument("--world", metavar="W.yaml", help="world map (default: the built-in office)")
    p.add_argument("--robots", type=int_range(2, 64), default=5, help="number of robots (default 5)")
    p.add_argument("--poses", type=int_range(10, 1_000_000), default=5000,
                   help="poses per robot (default 5000)")
    p.add_argument("--sim-seed", type=int, default=7, help="seed of the simulation (default 7)")
    add_merge_options(p, method="spectral-pso")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..mapio import group_map_files, load_map, save_maps
    from ..metrics import format_table1, table1, transform_errors
    from ..pipeline import merge
    from ..sim_output import check_run_dir
    from ..simulate import SimulationConfig, simulate, write_run
    from ..worlds import default_world
    from .merge import format_placements

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
    names = [f"robot_{k + 1}.yaml" for k in range(args.robots)]
    inputs = [str(out / n) for n in names]
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
    truth_tf = [r.transform for r in sim.robots]
    oracle_tf = [ref_true.inverse @ t for t in truth_tf]
    from ..fusion import fuse_maps
    order = list(result.order)
    oracle = fuse_maps([r.grid for r in sim.robots], oracle_tf, order=order, keep_steps=True)
    oracle_rows = table1(oracle.steps, world, ref_true)
    print(f"simulated {args.robots} robots x {args.poses} poses in {t_sim:.1f} s -> {out}/")
    print(format_placements(result, names))
    for p in result.placements:
        if p.transform is not None:
            e = transform_errors(p.transform, oracle_tf[p.index], world.resolution)
            print(f"  {names[p.index]}: error {e.translation_m:.2f} m ({e.translation_cells:.1f} cells), "
                  f"{e.rotation_deg:.2f} deg")
    print()
    print("fusion order: " + " -> ".join(names[k].removesuffix(".yaml") for k in order)
          + "  (row M1,..,k: the first k maps of this order)")
    print(format_table1(rows, paper=True, oracle=oracle_rows))
    print(f"\nfused map: {merged_path}; evaluate it with: fusionkit evaluate {merged_path} "
          f"--truth {out / 'truth.json'}")
    return 0 if result.all_merged else 3

