"""Leave-one-world-out choice of the consensus test's one calibrated constant, and its
out-of-sample result.

    python benchmarks/calibrate_consensus.py [--maps DIR] [--pairs 36] [--seed 1] [--out FILE]
                                             [--from FILE]

Pairs are drawn from the real maps of ``--maps`` (default ../shared/maps/real; maps at 0.05 m
cells, so that two of them can be paired without resampling): *positives* are two overlapping
windows of one map (160-320 cells square, at least 30 % shared, the second turned and moved,
:func:`fusionkit.methods.peers.crop_pair`), *negatives* a window of one map and a window of another
building, where every placement is wrong. The consensus method estimates each pair
(:func:`fusionkit.methods.consensus.estimate_pair`, default settings) and the inputs of its test are
recorded.

The constant is ``ConsensusConfig.calibration``: decades added to the null model's count of
false alarms. For each world in turn it is chosen on the pairs of all the other worlds (the
least offset, in quarter decades and possibly below zero, at which none of their negatives
would be merged, plus ``--margin`` decades, 1 by default, as the shipped constant was chosen) and measured on the
pairs of the world left out: positives placed right (passing the test, not ambiguous, at the
truth), positives placed wrong, negatives merged. Whether a pair is ambiguous is read from the
run at the default offset, as the rival test is not run again at each offset. Two maps of one
building (two runs in the Yujin office, the RoboCup arena mapped by two SLAM systems) are one
world: never paired as a negative, left out together. A negative belongs to both of its worlds
and is judged once with each left out. Prints the per-world table and the totals. ``--from``
re-reads recorded pairs.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parents[1]
EPS = 0.01
#: maps of one building under two names
BUILDING = {"yujin_office_run1": "yujin_office", "yujin_office_run2": "yujin_office",
            "robocup17_nagoya_gmapping": "robocup17_nagoya", "robocup17_nagoya_srrg": "robocup17_nagoya"}


def draw_pairs(maps_dir: Path, count: int, seed: int) -> list[dict]:
    from fusionkit.methods.peers import crop_pair, placement_error
    from fusionkit.methods.consensus import ConsensusConfig, estimate_pair, prepare_maps
    from lowo import best_cross_wall
    from fusionkit.errors import FusionkitError
    from fusionkit.mapio import load_map
    cfg = ConsensusConfig()
    maps = {}
    for y in sorted(maps_dir.glob("*.yaml")):
        g = load_map(y)
        if abs(g.resolution - 0.05) < 1e-9 and min(g.rows, g.cols) > 330 and g.occupied_mask().sum() > 2000:
            maps[y.stem] = g
    names = sorted(maps)
    rng = np.random.default_rng(seed)
    rows = []
    for kind in ("pos", "neg"):
        for it in range(count):
            n1 = names[it % len(names)]
            try:
                c = crop_pair(maps[n1], rng, size=int(rng.integers(160, 320)), min_overlap=0.3)
                if kind == "neg":
                    others = [n for n in names if BUILDING.get(n, n) != BUILDING.get(n1, n1)]
                    n2 = others[int(rng.integers(len(others)))]
                    c2 = crop_pair(maps[n2], rng, size=int(rng.integers(160, 320)), min_overlap=0.3)
            except FusionkitError:
                continue
            a, b = c.a, (c.b if kind == "pos" else c2.b)
            pr = estimate_pair(a, b, config=cfg).diagnostics["pair"]
            if pr.best is None or pr.null is None:
                continue
            ia, ib = prepare_maps([a, b], config=cfg)
            right = None
            if kind == "pos":
                d, r = placement_error(pr.best.transform, c.truth, b)
                right = bool(d < 3 * a.resolution and r < math.radians(2))
            rows.append({"kind": kind, "world": BUILDING.get(n1, n1),
                         "other": BUILDING.get(n2, n2) if kind == "neg" else None,
                         "right": right, "ambiguous": bool(pr.ambiguous),
                         "log10_nfa_model": pr.diagnostics["log10_nfa"] - cfg.calibration,
                         "score": pr.best.check.score,
                         "cross_wall_m": best_cross_wall(pr, ia, ib),
                         "best_transform": [pr.best.transform.x, pr.best.transform.y,
                                            pr.best.transform.theta]})
            print(json.dumps(rows[-1]), flush=True)
    return rows


def refused_anyway(row: dict) -> bool:
    """Refused at every offset: a rival nearly as good (ambiguous), or walls that all run one
    way (``lowo.slides``; rows recorded before that check have no measure)."""
    from lowo import slides
    return row["ambiguous"] or slides(row)


def merged(row: dict, offset: float) -> bool:
    return row["log10_nfa_model"] + offset <= math.log10(EPS) and not refused_anyway(row)


def least_offset(rows: list[dict], margin: float) -> float:
    """The least offset (quarter decades, from -20: below 0 the model counts more false alarms
    than occur) at which none of the negatives ``rows`` is merged, plus ``margin``."""
    worst = min((r["log10_nfa_model"] for r in rows if not refused_anyway(r)), default=math.inf)
    least = math.ceil((math.log10(EPS) - worst) * 4 + 1e-9) / 4 if math.isfinite(worst) else -20.0
    return max(least, -20.0) + margin


def leave_one_world_out(rows: list[dict], margin: float = 1.0) -> None:
    worlds = sorted({r["world"] for r in rows} | {r["other"] for r in rows if r["other"]})
    total = {"positives": 0, "right": 0, "wrong": 0, "negatives": 0, "negatives passing": 0}
    print("| world left out | offset chosen | positives placed right | placed wrong | negatives passing |")
    print("|---|---|---|---|---|")
    for w in worlds:
        train = [r for r in rows if r["kind"] == "neg" and w not in (r["world"], r["other"])]
        offset = least_offset(train, margin)
        pos = [r for r in rows if r["kind"] == "pos" and r["world"] == w]
        neg = [r for r in rows if r["kind"] == "neg" and w in (r["world"], r["other"])]
        right = sum(merged(r, offset) and r["right"] for r in pos)
        wrong = sum(merged(r, offset) and not r["right"] for r in pos)
        nm = sum(merged(r, offset) for r in neg)
        total["positives"] += len(pos)
        total["right"] += right
        total["wrong"] += wrong
        total["negatives"] += len(neg)
        total["negatives passing"] += nm
        print(f"| {w} | {offset:.2f} | {right}/{len(pos)} | {wrong} | {nm}/{len(neg)} |")
    print()
    print("out of sample (each world judged with the offset chosen without it):", total)
    allw = least_offset([r for r in rows if r["kind"] == "neg"], margin)
    print(f"offset chosen on every world: {allw:.2f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--maps", default=str(HERE.parent / "shared" / "maps" / "real"))
    ap.add_argument("--pairs", type=int, default=36, help="positives and negatives each")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default=None, help="record the pairs (JSON) here")
    ap.add_argument("--from", dest="source", default=None, help="re-read recorded pairs")
    ap.add_argument("--margin", type=float, default=1.0,
                    help="decades added to the least offset that merges no negative (default 1)")
    args = ap.parse_args(argv)
    if args.source:
        rows = json.loads(Path(args.source).read_text())
    else:
        rows = draw_pairs(Path(args.maps), args.pairs, args.seed)
        if args.out:
            Path(args.out).write_text(json.dumps(rows, indent=1))
    leave_one_world_out(rows, args.margin)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
