"""Success rate and speed of the three classic map-merging peers on crops of real maps.

For each trial a map is drawn from the real maps, two windows sharing at least half their area
are cut from it and the second is moved into a frame of its own (``crop_pair``); a peer
succeeds when its estimate puts the second window's known cells within ``--cells`` cells
(centroid) and ``--degrees`` degrees of the truth. Each trial also pairs the first window with
a window of another map (or a cave), which no peer should accept.

Run:  .venv/bin/python benchmarks/baselines_bench.py [--pairs 20] [--seed 0] [--size 240]
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
from pathlib import Path

import numpy as np

from fusionkit.methods.peers import ESTIMATORS, crop_pair, placement_error
from fusionkit.mapio import load_map
from fusionkit.worlds import make_cave

REPO = Path(__file__).resolve().parents[1]
MAPS = ("intel_lab", "uos_avz_floor5", "mit_stata_basement", "yujin_office_run1",
        "utexas_gdc_floor3", "gatech_ilab", "belgioioso_castle")


def find_map(name: str) -> Path | None:
    for d in (REPO / "maps" / "real", REPO.parent / "shared" / "maps" / "real"):
        if (d / f"{name}.yaml").is_file():
            return d / f"{name}.yaml"
    return None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=20, help="number of crop pairs (default 20)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the crops and motions (default 0)")
    ap.add_argument("--size", type=int, default=240, help="window side in cells (default 240; "
                    "smaller maps use the largest that fits)")
    ap.add_argument("--degrees", type=float, default=2.0, help="rotation tolerance (deg, default 2)")
    ap.add_argument("--cells", type=float, default=3.0, help="displacement tolerance (cells, default 3)")
    ap.add_argument("--maps", nargs="*", default=list(MAPS), help="map names under maps/real")
    args = ap.parse_args(argv)

    found = {n: find_map(n) for n in args.maps}
    missing = [n for n, p in found.items() if p is None]
    if missing:
        print(f"not found, left out: {', '.join(missing)}")
    args.maps = [n for n in args.maps if found[n] is not None]
    if not args.maps:
        sys.exit("no real maps found under maps/real or ../shared/maps/real")
    grids = {n: load_map(found[n]) for n in args.maps}
    rng = np.random.default_rng(args.seed)
    rows = {m: {"ok": 0, "acc": 0, "acc_wrong": 0, "false_acc": 0, "t": [], "conf_ok": [],
                "conf_false": []} for m in ESTIMATORS}
    per_map = {m: {} for m in ESTIMATORS}
    for k in range(args.pairs):
        name = args.maps[k % len(args.maps)]
        g = grids[name]
        size = min(args.size, min(g.shape) - 20)
        case = crop_pair(g, rng, size=size)
        others = [n for n in args.maps if n != name]
        if k % 3 == 2 or not others:
            other = make_cave(seed=int(rng.integers(1 << 30)), size=(max(12.0, size * g.resolution),) * 2,
                              resolution=g.resolution)
        else:
            og = grids[others[int(rng.integers(len(others)))]]
            other = crop_pair(og, rng, size=min(args.size, min(og.shape) - 20)).b
        line = [f"{k:3d} {name:20s} ov={case.overlap:.2f} rot={math.degrees(case.truth.theta):7.1f}"]
        for m, fn in ESTIMATORS.items():
            est = fn(case.a, case.b)
            r = rows[m]
            r["t"].append(est.seconds)
            ok = False
            if est.transform is not None:
                d, rot = placement_error(est.transform, case.truth, case.b)
                ok = rot <= math.radians(args.degrees) and d <= args.cells * case.a.resolution
            r["ok"] += ok
            r["acc"] += est.accepted
            r["acc_wrong"] += est.accepted and not ok
            if ok:
                r["conf_ok"].append(est.confidence)
            s = per_map[m].setdefault(name, [0, 0])
            s[0] += ok
            s[1] += 1
            false = fn(case.a, other)
            r["t"].append(false.seconds)
            r["false_acc"] += false.accepted
            r["conf_false"].append(false.confidence)
            line.append(f"{m}:{'ok' if ok else '--'}{'+' if est.accepted else ' '}")
        print(" ".join(line), flush=True)

    n = args.pairs
    print(f"\n{n} crop pairs (>= 50% overlap, random rotation), success = within "
          f"{args.degrees:g} deg and {args.cells:g} cells; {n} unrelated pairs")
    print(f"{'method':16s} {'success':>9s} {'accepted':>9s} {'acc.wrong':>9s} {'false acc':>9s} "
          f"{'s/estim.':>8s}  score(correct) min/median  score(unrelated) median/max")
    for m, r in rows.items():
        co, cf = r["conf_ok"], r["conf_false"]
        print(f"{m:16s} {r['ok']:4d}/{n:<4d} {r['acc']:4d}/{n:<4d} {r['acc_wrong']:4d}/{n:<4d} "
              f"{r['false_acc']:4d}/{n:<4d} {statistics.mean(r['t']):8.3f}  "
              f"{(min(co) if co else float('nan')):.3f}/{(statistics.median(co) if co else float('nan')):.3f}"
              f"              {statistics.median(cf):.3f}/{max(cf):.3f}")
    print("\nsuccess per map:")
    for m, d in per_map.items():
        print(f"  {m:16s} " + "  ".join(f"{name}:{s[0]}/{s[1]}" for name, s in d.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
