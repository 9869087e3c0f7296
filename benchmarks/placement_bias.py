"""How far within the cell the consensus method lays a map, with and without its last polish.

    python benchmarks/placement_bias.py [--cases 32] [--seed 5] [--maps DIR]

Crop cases of ``fusionkit bench`` (K = 2, each window turned by a random angle) over the real
floors of ``--maps`` (../shared/maps/real beside the repository, else maps/real). For each
pair, the error is measured in cells along the first map's axes at the moving map's known
centre:

1. ICP started at the true placement: the search's refinement (walls paired from the centre
   of the cell each point falls in) and the polish (walls paired from the points themselves),
   both from the truth: what each converges to when the search has done its part perfectly;
2. the whole pair estimate (``estimate_pair``), polish on and off, in the same process, in turn:
   the decisions (must be the same), the errors of the placements taken, the time per pair, and
   the time the polish itself took (its share of the shipped estimates' time).
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import importlib

import numpy as np

from fusionkit.bench import BenchConfig, find_worlds, make_case, plan_cases
from fusionkit.methods.consensus import ConsensusConfig, estimate_pair, prepare_maps
from fusionkit.methods.consensus._polish import polish
from fusionkit.methods.consensus._verify import refine_icp

pair_module = importlib.import_module("fusionkit.methods.consensus._pair")


def _error(case, t) -> np.ndarray:
    truth = case.truth[0].inverse @ case.truth[1]
    b = case.grids[1]
    r, c = np.nonzero(b.known_mask())
    centre = b.cell_to_world(r.mean(), c.mean())
    return (t(centre) - truth(centre)) / b.resolution


def _line(name: str, e: np.ndarray) -> str:
    if len(e) == 0:
        return f"{name:34s} no pair"
    d = np.hypot(e[:, 0], e[:, 1])
    return (f"{name:34s} {len(e):5d}  {e[:, 0].mean():+7.3f} {e[:, 1].mean():+7.3f}  "
            f"{np.median(d):7.3f} {np.percentile(d, 95):7.3f} {d.max():7.3f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=32, help="number of pairs (default 32)")
    ap.add_argument("--seed", type=int, default=5, help="seed of the case draw (default 5)")
    ap.add_argument("--maps", default=None, help="folder of real floors (YAML + image)")
    args = ap.parse_args()
    root = Path(__file__).resolve().parents[1]
    shared = root.parent / "shared" / "maps" / "real"
    folder = Path(args.maps) if args.maps else (shared if shared.is_dir() else root / "maps" / "real")
    worlds, _ = find_worlds([folder], ())
    cfg = BenchConfig(methods=("consensus",), cases=args.cases, seed=args.seed, modes=("crop",),
                      robots=(2,))
    from_truth = {"search ICP from the truth": [], "polish from the truth": []}
    whole = {True: [], False: []}
    seconds = {True: [], False: []}
    same = 0
    cases = [make_case(spec, cfg) for spec in plan_cases(worlds, cfg)]
    estimate_pair(*cases[0].grids)                 # compile every kernel before timing
    own = [0.0]

    def timed_polish(*a, **k):
        t0 = time.perf_counter()
        out = polish(*a, **k)
        own[0] += time.perf_counter() - t0
        return out

    pair_module.polish = timed_polish              # the estimate's own calls, timed
    for case in cases:
        a, b = prepare_maps(list(case.grids))
        truth = case.truth[0].inverse @ case.truth[1]
        from_truth["search ICP from the truth"].append(_error(case, refine_icp(a, b.refine_points, truth)))
        from_truth["polish from the truth"].append(_error(case, polish(a, b, truth)))
        decided = {}
        # in turn, so that neither setting always runs on caches the other warmed
        for on in ((False, True) if len(seconds[True]) % 2 else (True, False)):
            t0 = time.perf_counter()
            est = estimate_pair(*case.grids, config=ConsensusConfig(polish=on))
            seconds[on].append(time.perf_counter() - t0)
            decided[on] = est.accepted
            if est.accepted:
                whole[on].append(_error(case, est.transform))
        same += decided[True] == decided[False]
    print(f"{len(cases)} crop pairs of {folder}, seed {args.seed}; error in cells along the "
          "first map's axes at the moving map's known centre")
    print(f"{'':34s} {'pairs':>5s}  {'mean x':>7s} {'mean y':>7s}  {'median':>7s} {'95th':>7s} {'max':>7s}")
    for name, e in from_truth.items():
        print(_line(name, np.array(e)))
    print(_line("estimate, polish off", np.array(whole[False])))
    print(_line("estimate, polish on (shipped)", np.array(whole[True])))
    print(f"same decision on {same} of {len(cases)} pairs; median time per pair "
          f"{statistics.median(seconds[False]):.3f} s off, {statistics.median(seconds[True]):.3f} s "
          f"on (x{statistics.median(seconds[True]) / statistics.median(seconds[False]):.3f}); "
          f"the polish itself {own[0]:.3f} s of {sum(seconds[True]):.2f} s "
          f"({100 * own[0] / sum(seconds[True]):.1f} %)")


if __name__ == "__main__":
    main()
