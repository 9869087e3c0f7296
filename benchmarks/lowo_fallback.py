"""The exhaustive fall-back of the consensus method on the pairs of a leave-one-world-out draw
that the first search refused, and the choice of its calibration.

    python benchmarks/lowo_fallback.py --record benchmarks/records/lowo_seed1.json --out fb1.json
    python benchmarks/lowo_fallback.py --from fb1.json fb2.json ...

``benchmarks/lowo.py`` estimates each pair with the first search alone
(:func:`fusionkit.methods.consensus.estimate_pair`). A merge (:func:`fusionkit.pipeline.merge`)
searches the pairs of a map it left out again, exhaustively (``ConsensusConfig.fallback``): every
rotation at 2 degrees, three times the starts. ``--record`` rebuilds the pairs of the draw that
record was made from (same seed and default sizes, checked pair by pair against the record),
and merges each pair the first search refuses with the shipped settings (the record's inputs of
the decision judged with the shipped ``calibration`` and ``cross_wall``) as :func:`fusionkit.pipeline.merge` would
(:func:`fusionkit.methods.consensus.estimate_maps`, K = 2, shipped settings but
``fallback_calibration`` = 0, so that the record holds the model's count before it), and records
what the fall-back found: the model's count of false alarms without the offsets, its rivals,
whether its best placement is right.

``--from`` tables one or more such records: what the fall-back places and merges at the
shipped ``fallback_calibration``, and the offset the calibration's rule chooses for it (the
least, in quarter decades, at which no pair of two buildings is merged, plus one decade), on
every draw given and per world left out.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import lowo as L  # noqa: E402


def run(record: dict, st: dict, maps: str, logs: str, out: Path | None) -> list[dict]:
    from fusionkit.bench import find_worlds
    from fusionkit.methods.consensus import ConsensusConfig, estimate_maps
    real, _ = find_worlds([maps])
    builtin, _ = find_worlds([], ["office", "warehouse"])
    cfg = ConsensusConfig(fallback_calibration=0.0)
    cal, eps = cfg.calibration, record["max_false_merge"]
    rec = record["pairs"]
    res, k, skipped = [], 0, []
    with tempfile.TemporaryDirectory() as tmp:
        for fam, p in L.draw_pairs(st, real, builtin, Path(logs), Path(tmp), skipped):
            r = rec[k]
            k += 1
            if r["source"] != p["source"] or r["case_seed"] != p["case_seed"]:
                raise SystemExit(f"lowo_fallback: pair {k - 1} is {p['source']!r}, the record's is "
                                 f"{r['source']!r}: give the maps, logs and sizes the record was made with")
            if L.merged(r, cal, eps):
                continue                               # the first search's decision as shipped now
            t0 = time.perf_counter()
            mr = estimate_maps([p["a"], p["b"]], [p["scans_a"], p["scans_b"]], config=cfg,
                               seed=p["case_seed"] % 10_000)
            pr = mr.pairs[(0, 1)]
            lg = pr.diagnostics.get("log10_nfa", math.inf)
            best = pr.best.transform if pr.best is not None else None
            truth = p["truth"]
            res.append({"index": k - 1, "family": fam, "kind": r["kind"], "source": p["source"],
                        "world": r["world"], "other": r.get("other"), "resolvable": r.get("resolvable"),
                        "first_model": r["consensus"]["log10_nfa_model"],
                        "model": (lg - cfg.calibration) if math.isfinite(lg) else None,
                        "rivals": int(pr.diagnostics.get("rivals", int(pr.ambiguous))),
                        "cross_wall_m": L.best_cross_wall(pr, *mr.indexes),
                        "best_transform": None if best is None else [best.x, best.y, best.theta],
                        "best": "refused" if best is None else ("wrong" if truth is None
                                                                else L._outcome(best, truth, p["b"])),
                        "seconds": round(time.perf_counter() - t0, 3),
                        "fallback_seconds": round(mr.seconds.get("fallback", 0.0), 3)})
            print(f"{fam:10} {r['kind']} {p['source'][:48]:48} first {r['consensus']['log10_nfa_model']!s:.7} "
                  f"fall-back {res[-1]['model']!s:.7} best {res[-1]['best']}", file=sys.stderr, flush=True)
            if out:
                from fusionkit._atomic import write_text_atomic
                write_text_atomic(out, json.dumps({"settings": st, "eps": record["max_false_merge"],
                                                   "calibration": cfg.calibration, "pairs": res}, indent=1))
    return res


def merged(r: dict, calibration: float, extra: float, eps: float) -> bool:
    return (r["model"] is not None and r["model"] + calibration + extra <= math.log10(eps)
            and not r["rivals"] and not L.slides(r))


def choose(rows: list[dict], calibration: float, eps: float, margin: float = L.MARGIN) -> float:
    """The least offset >= 0 at which none of ``rows`` is merged, plus ``margin``."""
    return L.least_offset(lambda c: any(merged(r, calibration, c, eps) for r in rows), margin, least=0.0)


def tables(draws: dict) -> str:
    from fusionkit.methods.consensus import ConsensusConfig
    shipped = ConsensusConfig().fallback_calibration
    any_d = next(iter(draws.values()))
    eps, cal = any_d["eps"], any_d["calibration"]
    rows = [dict(r, draw=n) for n, d in draws.items() for r in d["pairs"]]
    negs = [r for r in rows if r["kind"] == "neg" and r["family"] != "apart"]
    worlds = sorted({r[k] for r in rows for k in ("world", "other") if r.get(k)})
    offs = {w: choose([r for r in negs if w not in (r["world"], r["other"])], cal, eps) for w in worlds}
    ins = choose(negs, cal, eps)
    lines = [f"Pairs the first search refused, searched again by the fall-back (calibration {cal:g}; "
             f"fallback_calibration as shipped {shipped:g}, chosen by the rule on these draws {ins:g}):", "",
             "| draw | refused pairs | positives placed right at 0 / as shipped / out of sample | placed wrong at 0 / as shipped "
             "| pairs of two buildings merged at 0 / as shipped / judgements out of sample | `apart` merged at 0 / as shipped "
             "| median s of the fall-back |", "|---|---|---|---|---|---|---|"]
    for n, d in draws.items():
        rs = d["pairs"]
        pos = [r for r in rs if r["kind"] == "pos"]
        ng = [r for r in rs if r["kind"] == "neg" and r["family"] != "apart"]
        ap = [r for r in rs if r["family"] == "apart"]
        jud = L._judgements(ng)
        fs = sorted(r["fallback_seconds"] for r in rs)

        def right(r, c):
            return merged(r, cal, c, eps) and r["best"] == "right"
        lines.append(
            f"| {n} | {len(rs)} | {sum(right(r, 0) for r in pos)} / {sum(right(r, shipped) for r in pos)} / "
            f"{sum(right(r, offs[r['world']]) for r in pos)} | "
            f"{sum(merged(r, cal, 0, eps) and r['best'] != 'right' for r in pos)} / "
            f"{sum(merged(r, cal, shipped, eps) and r['best'] != 'right' for r in pos)} | "
            f"{sum(merged(r, cal, 0, eps) for r in ng)} / {sum(merged(r, cal, shipped, eps) for r in ng)} / "
            f"{sum(merged(r, cal, offs[w], eps) for r, w in jud)} of {len(jud)} | "
            f"{sum(merged(r, cal, 0, eps) for r in ap)} / {sum(merged(r, cal, shipped, eps) for r in ap)} | "
            f"{fs[len(fs) // 2] if fs else 0:.2f} |")
    hit = [r for r in rows if merged(r, cal, 0, eps)]
    if hit:
        lines += ["", "Placed by the fall-back at 0: " + "; ".join(
            f"{r['draw']}: {r['source']} ({r['family']}, {r['kind']}, {r['best']}; first search "
            f"10^{r['first_model']:.1f}, fall-back 10^{r['model']:.1f} by the model)" for r in hit)]
    moved = [f"{w} {o:g}" for w, o in sorted(offs.items()) if o != ins]
    lines += ["", f"Offset chosen per world left out: {', '.join(moved) or 'none other'}; every other world {ins:g}."]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--record", default=None, help="a record of benchmarks/lowo.py --out")
    ap.add_argument("--maps", default=None, help="default: the record's")
    ap.add_argument("--logs", default=None, help="default: the record's")
    ap.add_argument("--out", default=None, help="write what the fall-back found here (JSON)")
    ap.add_argument("--from", dest="source", nargs="+", default=None, help="table records of --out")
    args = ap.parse_args(argv)
    try:
        if args.source:
            draws = {Path(f).stem: json.loads(Path(f).read_text()) for f in args.source}
            print(tables(draws))
            return 0
        if not args.record:
            print("lowo_fallback: give --record (a record of benchmarks/lowo.py) or --from", file=sys.stderr)
            return 2
        record = json.loads(Path(args.record).read_text())
        st = dict(record["settings"])
    except (OSError, ValueError, KeyError, TypeError, StopIteration) as exc:
        print(f"lowo_fallback: not a record this script reads ({exc}); give one", file=sys.stderr)
        return 2
    if st.get("quick"):
        print("lowo_fallback: the record is of a --quick run; give one of default sizes", file=sys.stderr)
        return 2
    res = run(record, st, args.maps or st["maps"], args.logs or st["logs"], Path(args.out) if args.out else None)
    from fusionkit.methods.consensus import ConsensusConfig
    print(tables({Path(args.record).stem: {"settings": st, "eps": record["max_false_merge"],
                                           "calibration": ConsensusConfig().calibration, "pairs": res}}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
