"""What each part of the consensus method is worth: the same cases with one part switched off.

    python benchmarks/consensus_parts.py [--cases 88] [--seed 3]

The cases are those of ``fusionkit bench`` (seed ``--seed``) over maps/ and
../shared/maps/real when it stands beside the repository, else maps/real. Each variant of
:class:`fusionkit.methods.consensus.ConsensusConfig` merges every case in this one process (one thread,
so that times compare); a pair is placed right within 2 degrees and 3 cells of the truth, as in
``fusionkit bench``. Prints, per mode and variant, the pairs placed right, wrong and refused,
the median centroid error of the right ones (cells) and the median time per pair.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
from pathlib import Path

import cv2
import numba
import numpy as np

from fusionkit.bench import BenchConfig, find_worlds, make_case, plan_cases
from fusionkit.methods.consensus import ConsensusConfig
from fusionkit.pipeline import MergeConfig, merge

VARIANTS = {
    "as shipped": {},
    "no alias search (alias_peaks=0)": {"alias_peaks": 0},
    "no swarm polish (pso_refine=False)": {"pso_refine": False},
    "no exhaustive fall-back (fallback=False)": {"fallback": False},
    "no pose graph (pose_graph=False)": {"pose_graph": False},
    "grids alone (use_scans=False)": {"use_scans": False},
    "with virtual scans (virtual_scans=True)": {"virtual_scans": True},
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=88, help="number of cases (default 88)")
    ap.add_argument("--seed", type=int, default=3, help="seed of the suite (default 3)")
    args = ap.parse_args()
    root = Path(__file__).resolve().parents[1]
    shared = root.parent / "shared" / "maps" / "real"
    worlds, _ = find_worlds([root / "maps", shared if shared.is_dir() else root / "maps" / "real"], ())
    cfg = BenchConfig(methods=("consensus",), cases=args.cases, seed=args.seed)
    cases = [(s, make_case(s, cfg)) for s in plan_cases(worlds, cfg)]
    cv2.setNumThreads(1)
    numba.set_num_threads(1)
    stats = {(m, v): {"right": 0, "wrong": 0, "refused": 0, "err": [], "t": []}
             for m in ("explore", "crop") for v in VARIANTS}
    s0, c0 = cases[0]
    merge(list(c0.grids), config=MergeConfig(consensus=ConsensusConfig(threads=1)))
    for spec, case in cases:
        scans = list(case.scans) if any(s is not None for s in case.scans) else None
        ref = case.truth[0]
        for name, over in VARIANTS.items():
            st = stats[(spec.mode, name)]
            config = MergeConfig(seed=spec.seed % 10_000, consensus=ConsensusConfig(threads=1, **over))
            t0 = time.perf_counter()
            res = merge(list(case.grids), scans=scans, config=config)
            st["t"].append((time.perf_counter() - t0) / (spec.robots - 1))
            for j in range(1, spec.robots):
                if not case.linked[j]:
                    continue
                t = res.transforms[j]
                if t is None:
                    st["refused"] += 1
                    continue
                truth = ref.inverse @ case.truth[j]
                r, c = np.nonzero(case.grids[j].known_mask())
                centre = case.grids[j].cell_to_world(r.mean(), c.mean())
                d = float(np.hypot(*(t(centre) - truth(centre)))) / case.world.resolution
                if d < 3 and math.degrees(t.error_to(truth)[1]) < 2:
                    st["right"] += 1
                    st["err"].append(d)
                else:
                    st["wrong"] += 1
    modes = [s.mode for s, _ in cases]
    print(f"{len(cases)} cases ({modes.count('explore')} explorations, {modes.count('crop')} crops) "
          f"from {len(worlds)} worlds, seed {args.seed}")
    print(f"{'mode':<8} {'variant':<42} {'pairs':>5} {'right':>6} {'wrong':>6} {'refused':>8} "
          f"{'err (cells)':>11} {'s / pair':>9}")
    for (mode, name), st in stats.items():
        if not st["t"]:
            continue
        pairs = st["right"] + st["wrong"] + st["refused"]
        err = f"{statistics.median(st['err']):.2f}" if st["err"] else "-"
        print(f"{mode:<8} {name:<42} {pairs:>5} {st['right']:>6} {st['wrong']:>6} {st['refused']:>8} "
              f"{err:>11} {statistics.median(st['t']):9.3f}")


if __name__ == "__main__":
    main()
