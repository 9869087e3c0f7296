"""Time per pair of the merging methods on the same cases, on one thread and on every core, and
where the consensus method spends its time.

    python benchmarks/bench_methods.py [--cases 48] [--step 4] [--seed 0]
                                       [--methods consensus map-merge ...]

The cases are those of ``fusionkit bench`` over maps/ and ../shared/maps/real when it stands
beside the repository, else maps/real (every ``--step``-th of the suite's first ``cases * step``, so
that worlds, modes and K = 2..5 all come up); every method merges each case through
:func:`fusionkit.pipeline.merge` in this one process, so the figures include what all methods
share (fusing the maps). A method runs twice: on one thread (OpenCV's and numba's thread pools
set to one thread, the consensus method's pairs one after another), and on every core (the
pools at their defaults, the consensus method with ``threads=0``: one thread per core). Time per pair is a merge's wall time over K - 1. Prints, per method and run, the
median time per pair (all cases, explorations, crops), the mean, the median of its ratio to
map-merge's on the same case, and the pairs placed within 2 degrees and 3 cells; then the
consensus method's mean time per stage.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import time
from pathlib import Path

import cv2
import numba
import numpy as np

from fusionkit.bench import BenchConfig, find_worlds, make_case, plan_cases
from fusionkit.methods.consensus import ConsensusConfig
from fusionkit.pipeline import MergeConfig, merge

METHODS = ("consensus", "map-merge", "fourier-mellin")


def _placed(res, case) -> int:
    n = 0
    ref = case.truth[0]
    for j in range(1, len(case.grids)):
        t = res.transforms[j]
        if t is None or not case.linked[j]:
            continue
        truth = ref.inverse @ case.truth[j]
        r, c = np.nonzero(case.grids[j].known_mask())
        centre = case.grids[j].cell_to_world(r.mean(), c.mean())
        d = float(np.hypot(*(t(centre) - truth(centre)))) / case.world.resolution
        n += d < 3 and math.degrees(t.error_to(truth)[1]) < 2
    return n


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=48, help="number of cases (default 48)")
    ap.add_argument("--step", type=int, default=4, help="take every STEP-th case of the suite (default 4)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the suite (default 0)")
    ap.add_argument("--methods", nargs="+", default=list(METHODS),
                    help=f"methods (default: {' '.join(METHODS)}); map-merge is always run")
    args = ap.parse_args()
    methods = list(dict.fromkeys(["map-merge", *args.methods]))
    root = Path(__file__).resolve().parents[1]
    shared = root.parent / "shared" / "maps" / "real"
    folders = [root / "maps", shared if shared.is_dir() else root / "maps" / "real"]
    worlds, _ = find_worlds(folders, ())
    cfg = BenchConfig(methods=tuple(methods), cases=args.cases * args.step, seed=args.seed)
    specs = plan_cases(worlds, cfg)[::args.step][:args.cases]
    cases = [(s, make_case(s, cfg)) for s in specs]
    runs = [(m, threads) for m in methods for threads in (1, 0)]

    def config(m, threads, seed):
        return MergeConfig(method=m, seed=seed, consensus=ConsensusConfig(threads=threads))

    def set_threads(threads):
        n = threads or os.cpu_count() or 1
        cv2.setNumThreads(n)
        numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))

    s0, c0 = cases[0]
    for m, threads in runs:                    # compile and warm up outside the timing
        merge(list(c0.grids), scans=list(c0.scans) if c0.scans[0] is not None else None,
              config=config(m, threads, 0))
    per = {r: [] for r in runs}
    placed = {r: 0 for r in runs}
    stages: dict = {}
    pairs = 0
    for spec, case in cases:
        scans = list(case.scans) if any(s is not None for s in case.scans) else None
        pairs += sum(case.linked[1:])
        for m, threads in runs:
            set_threads(threads)
            t0 = time.perf_counter()
            res = merge(list(case.grids), scans=scans, config=config(m, threads, spec.seed % 10_000))
            per[(m, threads)].append((time.perf_counter() - t0) / (spec.robots - 1))
            placed[(m, threads)] += _placed(res, case)
            if m == "consensus" and threads == 1:
                for k, v in res.seconds.items():
                    stages.setdefault(k, []).append(v / (spec.robots - 1))
    set_threads(0)
    modes = [s.mode for s, _ in cases]
    print(f"{len(cases)} cases ({modes.count('explore')} explorations, {modes.count('crop')} crops; "
          f"{pairs} linked pairs) from {len(worlds)} worlds, seed {args.seed}, on {os.cpu_count()} cores")
    print(f"{'method':<16} {'threads':<8} {'median s/pair':>13} {'explore':>8} {'crop':>8} "
          f"{'mean':>7} {'x map-merge':>11} {'placed':>8}")
    for m, threads in runs:
        v = per[(m, threads)]
        mm = per[("map-merge", threads)]
        ex = [x for x, md in zip(v, modes) if md == "explore"] or [math.nan]
        cr = [x for x, md in zip(v, modes) if md == "crop"] or [math.nan]
        ratio = statistics.median(a / b for a, b in zip(v, mm) if b > 0)
        print(f"{m:<16} {'one' if threads == 1 else 'all':<8} {statistics.median(v):13.4f} "
              f"{statistics.median(ex):8.4f} {statistics.median(cr):8.4f} {statistics.mean(v):7.4f} "
              f"{ratio:11.2f} {placed[(m, threads)]:>4}/{pairs}")
    print("consensus on one thread, mean s per pair by stage: " + ", ".join(
        f"{k} {statistics.mean(v):.4f}" for k, v in stages.items()))


if __name__ == "__main__":
    main()
