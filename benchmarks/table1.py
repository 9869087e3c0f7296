"""Reproduce the paper's Table 1, then measure placement over seeds and worlds, and speed.

    python benchmarks/table1.py                 # the default scenario + 10 seeds x 3 worlds
    python benchmarks/table1.py --seeds 3       # quicker

Prints: (1) Table 1 for the default scenario (office, 5 robots x 5000 poses) beside the paper's
numbers and the oracle (fusion with the true transforms); (2) over seeds and the shipped worlds,
how many maps were placed within 2 deg and 3 cells of the truth, how many were wrongly placed
(merged outside those bounds) and how many were left out, with merge times; (3) the speed of the
jitted eq. 3 objective against a plain-numpy objective in the same process.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

from fusionkit.alignment import dedupe_points, make_field, mask_points, mse_cost, mse_cost_numpy
from fusionkit.fusion import fuse_maps
from fusionkit.mapio import load_map
from fusionkit.metrics import format_table1, table1, transform_errors
from fusionkit.pipeline import MergeConfig, merge
from fusionkit.simulate import SimulationConfig, simulate
from fusionkit.worlds import default_world


def run_case(world, robots, poses, sim_seed, merge_seed=0):
    sim = simulate(world, SimulationConfig(robots=robots, poses=poses, seed=sim_seed))
    grids, scans = [r.grid for r in sim.robots], [r.scans for r in sim.robots]
    t0 = time.perf_counter()
    res = merge(grids, scans=scans, config=MergeConfig(method="spectral-pso", seed=merge_seed))
    seconds = time.perf_counter() - t0
    ref = sim.robots[0].transform
    truth = [ref.inverse @ r.transform for r in sim.robots]
    return sim, res, truth, seconds


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=10, help="simulation seeds per world (default 10)")
    ap.add_argument("--robots", type=int, default=5)
    ap.add_argument("--poses", type=int, default=5000)
    args = ap.parse_args(argv)

    # warm the JIT caches so timings measure the work, not compilation
    run_case(default_world(), 2, 300, 99)

    print("== Table 1: office, 5 robots x 5000 poses, simulation seed 7 (as `fusionkit run`) ==")
    world = default_world()
    sim, res, truth, seconds = run_case(world, args.robots, args.poses, 7)
    order = list(res.order)
    rows = table1(res.fused.steps, world, sim.robots[0].transform)
    oracle = fuse_maps([r.grid for r in sim.robots], truth, order=order, keep_steps=True)
    orows = table1(oracle.steps, world, sim.robots[0].transform)
    print(format_table1(rows, paper=True, oracle=orows))
    grids, scans = [r.grid for r in sim.robots], [r.scans for r in sim.robots]
    warm = []
    for _ in range(3):
        t0 = time.perf_counter()
        again = merge(grids, scans=scans, config=MergeConfig(method="spectral-pso", seed=0))
        warm.append(time.perf_counter() - t0)
    print(f"merge of {args.robots} maps (simulation excluded): first call in this process "
          f"{seconds:.2f} s, then {', '.join(f'{t:.2f}' for t in warm)} s; stages of the last: "
          + ", ".join(f"{k} {v:.2f}" for k, v in again.seconds.items()))

    print(f"\n== Placement over {args.seeds} seeds x shipped worlds ({args.robots} robots x {args.poses} poses) ==")
    worlds = {p.stem: load_map(p) for p in sorted((ROOT / "maps").glob("*.yaml"))}
    print(f"{'world':<10} {'maps':>5} {'correct':>8} {'wrong':>6} {'left out':>9} {'med err (cells)':>16} "
          f"{'med err (deg)':>14} {'med merge s':>12}")
    totals = np.zeros(4, int)
    for name, w in worlds.items():
        n = ok = wrong = out = 0
        errs_c, errs_d, times = [], [], []
        for s in range(args.seeds):
            sim, res, truth, seconds = run_case(w, args.robots, args.poses, 1000 + s)
            times.append(seconds)
            for p in res.placements[1:]:
                n += 1
                if not p.merged:
                    out += 1
                    continue
                e = transform_errors(p.transform, truth[p.index], w.resolution)
                errs_c.append(e.translation_cells)
                errs_d.append(e.rotation_deg)
                if e.rotation_deg < 2 and e.translation_cells < 3:
                    ok += 1
                else:
                    wrong += 1
            print(f"  {name} seed {1000 + s}: {sum(p.merged for p in res.placements) - 1}/{args.robots - 1} "
                  f"merged, {seconds:.2f} s", file=sys.stderr)
        totals += (n, ok, wrong, out)
        med = lambda v: f"{statistics.median(v):.2f}" if v else "-"
        print(f"{name:<10} {n:>5} {ok:>8} {wrong:>6} {out:>9} {med(errs_c):>16} {med(errs_d):>14} "
              f"{statistics.median(times):>12.2f}")
    n, ok, wrong, out = totals
    print(f"{'all':<10} {n:>5} {ok:>8} {wrong:>6} {out:>9}   correct {100 * ok / n:.1f}%, "
          f"wrong {100 * wrong / n:.1f}%, left out {100 * out / n:.1f}%")

    print("\n== eq. 3 objective: jitted kernel vs plain numpy, same masks, same particles ==")
    a, b = sim.robots[0].scans, sim.robots[1].scans
    ref_pts = mask_points(a, np.arange(0, a.n_scans, 25))
    mov = dedupe_points(mask_points(b, np.arange(0, b.n_scans, 25)), w.resolution)
    fld = make_field(ref_pts, w.resolution)
    rng = np.random.default_rng(0)
    P = rng.uniform([-10, -10, -math.pi], [10, 10, math.pi], (40, 3))
    mse_cost(fld, mov, P)
    reps = 50
    t0 = time.perf_counter()
    for _ in range(reps):
        mse_cost(fld, mov, P)
    t_jit = (time.perf_counter() - t0) / reps
    t0 = time.perf_counter()
    mse_cost_numpy(fld, mov, P)
    t_np = time.perf_counter() - t0
    print(f"40 particles x {len(mov)} mask cells on a {fld.values.shape[1]}x{fld.values.shape[0]} raster: "
          f"jitted {1e3 * t_jit:.2f} ms, numpy {1e3 * t_np:.1f} ms per swarm evaluation "
          f"-> {t_np / t_jit:.0f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
