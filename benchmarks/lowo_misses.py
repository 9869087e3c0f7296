"""Why the consensus method refuses resolvable pairs of leave-one-world-out draws, and how many of
them a search that always found the truth would place.

    python benchmarks/lowo_misses.py --record benchmarks/records/lattice/lowo_seed7.json [RECORD ...]

For each record of ``benchmarks/lowo.py``, every resolvable positive its first search refused is
rebuilt (the record's seed and sizes, checked against the record) and classed by the reason it
was refused (a rival placement, not distinguishable from chance, misses too much, contradicted,
slides) and by whether the best placement the search found was right. Each is then estimated
again with the truth given as one more start (``estimate_pair(..., priors=[truth])``, shipped
settings, the first search alone as in the record): a pair placed then is one the search lost;
one still refused is refused by the test, whatever a search finds. Prints a Markdown table.
"""

from __future__ import annotations

import argparse
import collections
import json
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import lowo as L  # noqa: E402

#: the refusal classes, by the start of the reason the method gives
CLASSES = (("ambiguous", "rival"), ("best placement is not distinguishable", "chance"),
           ("best placement misses too much", "misses"), ("best placement is contradicted", "contradicted"),
           ("the placement may slide", "slides"))


def refusal(reason: str) -> str:
    """The class of a refusal reason (``"other"`` when none fits)."""
    return next((name for head, name in CLASSES if reason.startswith(head)), "other")


def misses(record: dict) -> list[dict]:
    """The resolvable positives of ``record`` whose first search the shipped decision refuses."""
    from fusionkit.methods.consensus import ConsensusConfig
    cfg = ConsensusConfig()
    return [r for r in record["pairs"] if r["kind"] == "pos" and r.get("resolvable")
            and not L.merged(r, cfg.calibration, record["max_false_merge"])]


def oracle(p: dict) -> tuple[str, str]:
    """``(outcome, class)`` of the first search of pair ``p`` given its truth as a start:
    ``outcome`` "right", "wrong" or "refused", ``class`` the refusal's (empty when placed)."""
    from fusionkit.methods.consensus import estimate_pair
    pr = estimate_pair(p["a"], p["b"], scans_a=p["scans_a"], scans_b=p["scans_b"],
                       seed=p["case_seed"] % 10_000, priors=[p["truth"]]).diagnostics["pair"]
    if not pr.accepted:
        return "refused", refusal(pr.reason)
    return L._outcome(pr.transform, p["truth"], p["b"]), ""


def run(record: dict, maps: str, logs: str) -> list[dict]:
    """One row per refused resolvable positive of ``record``: family, world, the record's class
    and best outcome, and the oracle's outcome and class."""
    from fusionkit.bench import find_worlds
    todo = {(r["family"], r["source"], r["case_seed"]): r for r in misses(record)}
    if not todo:
        return []
    st = dict(record["settings"], families=sorted({k[0] for k in todo}, key=L.FAMILIES.index))
    real, _ = find_worlds([maps])
    builtin, _ = find_worlds([], ["office", "warehouse"])
    rows, skipped = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for fam, p in L.draw_pairs(st, real, builtin, Path(logs), Path(tmp), skipped):
            r = todo.pop((fam, p["source"], p["case_seed"]), None)
            if r is None or p["truth"] is None:
                continue
            if [list(p["a"].data.shape), list(p["b"].data.shape)] != [r["shape_a"], r["shape_b"]]:
                raise SystemExit(f"lowo_misses: {p['source']} is not the pair of the record: give the "
                                 "maps and logs the record was made with")
            outcome, cls = oracle(p)
            rows.append({"family": fam, "world": r["world"], "source": p["source"],
                         "class": refusal(r["consensus"]["reason"]), "best": r["consensus"]["best"],
                         "oracle": outcome, "oracle_class": cls})
            print(f"{fam:10} {p['source'][:40]:40} {rows[-1]['class']:12} best {rows[-1]['best']:7} "
                  f"with the truth as a start: {outcome} {cls}", file=sys.stderr, flush=True)
    if todo:
        raise SystemExit(f"lowo_misses: {len(todo)} pairs of the record were not drawn again "
                         "(other maps, logs or code?)")
    return rows


def table(rows: list[dict]) -> str:
    """Markdown: per refusal class and best outcome, how many pairs, and what the oracle did."""
    groups = collections.defaultdict(list)
    for r in rows:
        groups[(r["class"], r["best"])].append(r)
    lines = ["| refused as | best found | pairs | with the truth as a start: placed right | still refused, as |",
             "|---|---|---|---|---|"]
    for (cls, best), rs in sorted(groups.items(), key=lambda kv: -len(kv[1])):
        still = collections.Counter(r["oracle_class"] for r in rs if r["oracle"] == "refused")
        wrong = sum(r["oracle"] == "wrong" for r in rs)
        lines.append(f"| {cls} | {best} | {len(rs)} | {sum(r['oracle'] == 'right' for r in rs)}"
                     f"{f' ({wrong} placed wrong)' if wrong else ''} | "
                     f"{', '.join(f'{k} {v}' for k, v in still.most_common()) or '-'} |")
    right = sum(r["oracle"] == "right" for r in rows)
    lines += ["", f"{len(rows)} refused resolvable pairs; with the truth as a start {right} placed right."]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--record", nargs="+", required=True, help="records of benchmarks/lowo.py --out")
    ap.add_argument("--maps", default=str(L.HERE.parent / "shared" / "maps" / "real"))
    ap.add_argument("--logs", default=str(L.HERE.parent / "shared" / "logs" / "real"))
    args = ap.parse_args(argv)
    rows = []
    for f in args.record:
        try:
            record = json.loads(Path(f).read_text())
            record["settings"], record["pairs"]
        except (OSError, ValueError, KeyError, TypeError) as exc:
            print(f"lowo_misses: {f}: not a record of benchmarks/lowo.py ({exc})", file=sys.stderr)
            return 2
        rows += run(record, args.maps, args.logs)
    print(table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
