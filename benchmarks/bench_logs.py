"""Real laser logs split into sessions: every method on the same imports, scored on the truth.

    python benchmarks/bench_logs.py [--logs DIR] [--splits 2 3 4] [--methods consensus map-merge]
                                    [--out DIR]

Each CARMEN log of ``--logs`` (default ../shared/logs/real) is imported with
``fusionkit import carmen --split K`` for every K of ``--splits`` (consecutive sessions sharing
30 % of their length, each mapped in its own start frame, truth.json beside), and the K maps
(with their recorded scans) are merged by every method through :func:`fusionkit.pipeline.merge`
in this one process. A map other than the first is one pair: placed within 2 degrees and 3 cells
of its true place (at its known area's centroid) is a success, placed elsewhere a wrong merge,
left out a refusal. Prints a table per method and per log, and the median time per pair
(a merge's wall time over K - 1, without the common-scale confidence a peer's report gets).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from fusionkit.io_carmen import import_carmen
from fusionkit.pipeline import MergeConfig, load_inputs, merge
from fusionkit.transform import Transform2D

HERE = Path(__file__).resolve().parents[1]


def _centroid(g) -> np.ndarray:
    r, c = np.nonzero(g.known_mask())
    return g.cell_to_world(np.array([r.mean()]), np.array([c.mean()]))[0]


def score(transform, truth_ref: Transform2D, truth_k: Transform2D, grid) -> str:
    """``"right"``, ``"wrong"`` or ``"refused"`` for one map's placement in the reference frame."""
    if transform is None:
        return "refused"
    true = truth_ref.inverse @ truth_k
    p = _centroid(grid)
    d = float(np.hypot(*(transform(p[None])[0] - true(p[None])[0])))
    rot = abs(math.remainder(transform.theta - true.theta, 2 * math.pi))
    return "right" if d <= 3 * grid.resolution and rot <= math.radians(2.0) else "wrong"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--logs", default=str(HERE.parent / "shared" / "logs" / "real"))
    ap.add_argument("--splits", nargs="+", type=int, default=[2, 3, 4])
    ap.add_argument("--methods", nargs="+", default=["consensus", "map-merge"])
    ap.add_argument("--out", default=None, help="write the per-pair records (JSON) here")
    args = ap.parse_args(argv)
    logs = sorted(Path(args.logs).glob("*.log"))
    records = []
    with tempfile.TemporaryDirectory() as tmp:
        for log in logs:
            for k in args.splits:
                d = Path(tmp) / f"{log.name.split('.')[0]}{k}"
                import_carmen(log, d, split=k)
                truth = json.loads((d / "truth.json").read_text())
                t_true = [Transform2D(**r["transform"]) for r in truth["robots"]]
                inputs = [str(d / f"robot_{i + 1}.yaml") for i in range(k)]
                grids, scans = load_inputs(inputs)
                for method in args.methods:
                    t0 = time.perf_counter()
                    res = merge(grids, scans=scans, config=MergeConfig(method=method))
                    sec = time.perf_counter() - t0 - res.seconds.get("confidence", 0.0)
                    for i in range(1, k):
                        p = res.placements[i]
                        records.append({"log": log.name.split(".")[0], "k": k, "map": i + 1,
                                        "method": method, "outcome": score(p.transform, t_true[0], t_true[i], grids[i]),
                                        "confidence": round(p.confidence, 4), "group": p.group,
                                        "reason": p.reason, "seconds_per_pair": sec / (k - 1)})
                    print(f"{log.name} K={k} {method:15} "
                          + " ".join(r["outcome"] for r in records[-(k - 1):]), flush=True)
    print()
    print("| method | pairs | right | wrong | refused | median s/pair |")
    print("|---|---|---|---|---|---|")
    for m in args.methods:
        rs = [r for r in records if r["method"] == m]
        n = len(rs)
        right = sum(r["outcome"] == "right" for r in rs)
        wrong = sum(r["outcome"] == "wrong" for r in rs)
        print(f"| {m} | {n} | {right} ({100 * right / max(n, 1):.1f}%) | {wrong} | {n - right - wrong} | "
              f"{statistics.median(r['seconds_per_pair'] for r in rs):.2f} |")
    print()
    print("| log | " + " | ".join(args.methods) + " |")
    print("|---|" + "---|" * len(args.methods))
    for name in sorted({r["log"] for r in records}):
        cells = []
        for m in args.methods:
            rs = [r for r in records if r["method"] == m and r["log"] == name]
            cells.append(f"{sum(r['outcome'] == 'right' for r in rs)}/{len(rs)}"
                         + (f" ({sum(r['outcome'] == 'wrong' for r in rs)} wrong)"
                            if any(r["outcome"] == "wrong" for r in rs) else ""))
        print(f"| {name} | " + " | ".join(cells) + " |")
    if args.out:
        Path(args.out).write_text(json.dumps(records, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
