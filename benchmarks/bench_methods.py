"""Time per pair of every merging method on the same crop pairs, and where the consensus
method spends its time.

    python benchmarks/bench_methods.py [--pairs 20] [--seed 0]

Each pair is two overlapping, turned windows of a map of maps/real (or the built-in worlds);
every method places the second in the first through :func:`fusionkit.pipeline.merge`, so the
figures include what all methods share (fusing the two maps). Prints the median and the 90th
percentile wall time per method, the consensus method's median time per stage, and how many
pairs each method placed within 2 degrees and 3 cells.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from fusionkit.bench import BenchConfig, find_worlds, make_case, plan_cases
from fusionkit.pipeline import MergeConfig, merge

METHODS = ("consensus", "map-merge", "hough-spectrum", "fourier-mellin", "spectral-pso")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=20, help="number of crop pairs (default 20)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the pairs (default 0)")
    args = ap.parse_args()
    root = Path(__file__).resolve().parents[1]
    folders = [p for p in (root / "maps", root / "maps" / "real") if p.is_dir()]
    worlds, _ = find_worlds(folders, ("office", "warehouse", "cave"))
    cfg = BenchConfig(methods=METHODS, modes=("crop",), robots=(2,), cases=args.pairs, seed=args.seed)
    cases = [make_case(s, cfg) for s in plan_cases(worlds, cfg)]
    # one warm-up merge per method so that JIT compilation is not timed
    for m in METHODS:
        merge(list(cases[0].grids), config=MergeConfig(method=m))
    times = {m: [] for m in METHODS}
    placed = {m: 0 for m in METHODS}
    stages: dict = {}
    for case in cases:
        truth = case.truth[0].inverse @ case.truth[1]
        r, c = np.nonzero(case.grids[1].known_mask())
        centre = case.grids[1].cell_to_world(r.mean(), c.mean())
        for m in METHODS:
            t0 = time.perf_counter()
            res = merge(list(case.grids), config=MergeConfig(method=m))
            times[m].append(time.perf_counter() - t0)
            t = res.placements[1].transform
            if t is not None:
                d = float(np.hypot(*(t(centre) - truth(centre)))) / case.world.resolution
                if d < 3 and np.degrees(t.error_to(truth)[1]) < 2:
                    placed[m] += 1
            if m == "consensus":
                for k, v in res.seconds.items():
                    stages.setdefault(k, []).append(v)
    print(f"{len(cases)} crop pairs (K = 2) from {len(worlds)} worlds, seed {args.seed}")
    print(f"{'method':<16} {'median s':>9} {'p90 s':>8} {'placed':>7}")
    for m in METHODS:
        v = sorted(times[m])
        print(f"{m:<16} {statistics.median(v):9.3f} {v[int(0.9 * (len(v) - 1))]:8.3f} "
              f"{placed[m]:>4}/{len(cases)}")
    print("consensus stages (median s): " + ", ".join(
        f"{k} {statistics.median(v):.3f}" for k, v in stages.items()))


if __name__ == "__main__":
    main()
