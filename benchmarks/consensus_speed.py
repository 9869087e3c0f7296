"""Time per pair of the consensus method against map-merge, on the same cases in one process.

    python benchmarks/consensus_speed.py [--cases 20] [--seed 5] [--modes crop]
        [--drift 0.0] [--drift-theta 0.0] [--worlds NAME ...] [--robots 2 3 4 5]
        [--shipped] [--record FILE] [--profile FILE]

The cases are those of ``fusionkit bench`` (seed ``--seed``) over ../shared/maps/real when it
stands beside the repository (else maps/real) and the built-in office and warehouse. Every
variant below and map-merge merge each case in turn, one thread each, so that their times
compare; a pair is placed right within 2 degrees and 3 cells of the truth. Prints, per
variant, the pairs placed right, wrong and refused, the median time per pair, the median of
the per-case ratio to map-merge's time, the ratio of the medians, and the median share of the
time spent by the fall-back search, and the sum of the times per pair.

``--shipped`` times only the shipped settings against map-merge. ``--record FILE`` writes what
every variant decided on every case (each map merged or not, its transform, confidence, group
and reason) as JSON, for :mod:`compare_decisions` to set two runs side by side.
``--profile FILE`` profiles the shipped variant's merges (``cProfile`` statistics in FILE).
"""

from __future__ import annotations

import argparse
import cProfile
import json
import math
import statistics
import time
from pathlib import Path

import cv2
import numba
import numpy as np

from fusionkit._atomic import write_text_atomic
from fusionkit.bench import BenchConfig, find_worlds, make_case, plan_cases
from fusionkit.errors import InputError
from fusionkit.methods.consensus import ConsensusConfig, prepare_maps, refine_pso
from fusionkit.pipeline import MergeConfig, merge
from fusionkit.transform import Transform2D

SHIPPED = "consensus, as shipped"

VARIANTS = {
    "consensus, full null and fall-back": {"null_margin": math.inf, "fallback_rotations": 0},
    "consensus, sequential null": {"fallback_rotations": 0},
    SHIPPED: {},
    "consensus, null ICP wide gates on 300 points": {"null_wide_points": 300},
}


def _score(case, spec, transforms, st) -> None:
    ref = case.truth[0]
    for j in range(1, spec.robots):
        if not case.linked[j]:
            continue
        t = transforms[j]
        if t is None:
            st["refused"] += 1
            continue
        truth = ref.inverse @ case.truth[j]
        r, c = np.nonzero(case.grids[j].known_mask())
        centre = case.grids[j].cell_to_world(r.mean(), c.mean())
        d = float(np.hypot(*(t(centre) - truth(centre)))) / case.world.resolution
        ok = d < 3 and math.degrees(t.error_to(truth)[1]) < 2
        st["right" if ok else "wrong"] += 1


def decisions(res) -> list:
    """What a merge decided for each map, in a form that compares across runs."""
    def tf(t):
        return None if t is None else [float(t.x), float(t.y), float(t.theta)]
    return [{"merged": bool(p.merged), "transform": tf(p.transform),
             "confidence": float(p.confidence), "group": p.group,
             "group_transform": tf(p.group_transform), "reason": p.reason}
            for p in res.placements]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=20, help="number of cases (default 20)")
    ap.add_argument("--seed", type=int, default=5, help="seed of the suite (default 5)")
    ap.add_argument("--modes", nargs="+", default=["crop"], choices=["crop", "explore"])
    ap.add_argument("--drift", type=float, default=0.0, help="odometry drift, m per sqrt(m)")
    ap.add_argument("--drift-theta", type=float, default=0.0, help="heading drift, rad per sqrt(m)")
    ap.add_argument("--try", dest="trial", default="", metavar="JSON",
                    help='settings of one more variant, e.g. \'{"coarse_points": 400}\'')
    ap.add_argument("--worlds", nargs="+", default=[], metavar="NAME",
                    help="only these worlds (map names without .yaml, office, warehouse)")
    ap.add_argument("--robots", nargs="+", type=int, default=[2, 3, 4, 5],
                    help="maps per case, in turn (default 2 3 4 5)")
    ap.add_argument("--shipped", action="store_true",
                    help="time only the shipped settings against map-merge")
    ap.add_argument("--record", default="", metavar="FILE",
                    help="write every variant's decisions on every case to FILE (JSON)")
    ap.add_argument("--profile", default="", metavar="FILE",
                    help="profile the shipped variant's merges into FILE (cProfile statistics)")
    args = ap.parse_args()
    if args.shipped:
        for name in list(VARIANTS):
            if name != SHIPPED:
                del VARIANTS[name]
    if args.trial:
        VARIANTS[f"consensus, {args.trial}"] = json.loads(args.trial)
    root = Path(__file__).resolve().parents[1]
    shared = root.parent / "shared" / "maps" / "real"
    worlds, _ = find_worlds([shared if shared.is_dir() else root / "maps" / "real"],
                            ("office", "warehouse"))
    if args.worlds:
        unknown = sorted(set(args.worlds) - {w.name for w in worlds})
        if unknown:
            ap.error(f"no world named {', '.join(unknown)}; the worlds are "
                     f"{', '.join(w.name for w in worlds)}")
        worlds = [w for w in worlds if w.name in args.worlds]
    try:
        cfg = BenchConfig(methods=("consensus",), cases=args.cases, seed=args.seed,
                          modes=tuple(args.modes), drift=args.drift,
                          drift_theta=args.drift_theta, robots=tuple(args.robots))
    except InputError as exc:
        ap.error(str(exc))
    cv2.setNumThreads(1)
    numba.set_num_threads(1)
    runs = {v: {"right": 0, "wrong": 0, "refused": 0, "t": [], "fb": []} for v in VARIANTS}
    runs["map-merge"] = {"right": 0, "wrong": 0, "refused": 0, "t": [], "fb": []}
    warm = None
    record = []
    prof = cProfile.Profile() if args.profile else None
    for spec in plan_cases(worlds, cfg):
        case = make_case(spec, cfg)
        scans = list(case.scans) if any(s is not None for s in case.scans) else None
        if warm is None:  # compile every kernel before anything is timed
            for m in ("consensus", "map-merge"):
                merge(list(case.grids), scans=scans, config=MergeConfig(method=m))
            # the swarm polish runs only on pairs with contenders: compile it here too
            a, b = prepare_maps(list(case.grids)[:2])
            refine_pso(a.points, b.refine_points, Transform2D(), a.resolution, seed=0)
            warm = True
        for name, st in runs.items():
            if name == "map-merge":
                config = MergeConfig(method="map-merge", seed=spec.seed % 10_000)
            else:
                config = MergeConfig(seed=spec.seed % 10_000,
                                     consensus=ConsensusConfig(threads=1, **VARIANTS[name]))
            if prof is not None and name == SHIPPED:
                prof.enable()
            t0 = time.perf_counter()
            res = merge(list(case.grids), scans=scans, config=config)
            seconds = time.perf_counter() - t0 - res.seconds.get("confidence", 0.0)
            if prof is not None and name == SHIPPED:
                prof.disable()
            record.append({"case": spec.index, "world": spec.world.name, "mode": spec.mode,
                           "variant": name, "maps": decisions(res)})
            st["t"].append(seconds / (spec.robots - 1))
            st["fb"].append(res.seconds.get("fallback", 0.0) / max(seconds, 1e-9))
            _score(case, spec, res.transforms, st)
    if args.record:
        write_text_atomic(args.record, json.dumps(record, indent=1))
    if prof is not None:
        prof.dump_stats(args.profile)
    base = runs["map-merge"]["t"]
    print(f"{args.cases} cases, modes {' '.join(args.modes)}, seed {args.seed}, "
          f"drift {args.drift} m and {args.drift_theta} rad per sqrt(m)")
    print(f"{'method':<44} {'right':>6} {'wrong':>6} {'refused':>8} {'s / pair':>9} "
          f"{'x map-merge':>12} {'ratio of medians':>17} {'fall-back':>10} {'total s':>8}")
    for name, st in runs.items():
        ratio = statistics.median(a / max(b, 1e-9) for a, b in zip(st["t"], base))
        rom = statistics.median(st["t"]) / max(statistics.median(base), 1e-9)
        print(f"{name:<44} {st['right']:>6} {st['wrong']:>6} {st['refused']:>8} "
              f"{statistics.median(st['t']):9.3f} {ratio:12.2f} {rom:17.2f} "
              f"{100 * statistics.median(st['fb']):9.0f}% {sum(st['t']):8.2f}")


if __name__ == "__main__":
    main()
