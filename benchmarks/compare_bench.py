"""Are two ``fusionkit bench`` runs the same, timings aside? And how do their wall times compare?

Used to check that the cases give the same results on every back end::

    fusionkit bench --worlds cave office --cases 8 --out /tmp/b_local
    fusionkit bench --worlds cave office --cases 8 --backend dask --workers 2 --out /tmp/b_dask
    .venv/bin/python benchmarks/compare_bench.py /tmp/b_local/bench.json /tmp/b_dask/bench.json

Prints whether every case's figures (placements, errors, Table 1 metrics, summary) agree
exactly once wall times are removed, whether the summary tables do, the first ten differences,
and the ratio of the two runs' wall times. Exit status 0 when identical, 1 otherwise.
"""

from __future__ import annotations

import argparse
import json
import sys

TIMES = ("build_seconds", "seconds", "seconds_per_pair")


def strip(doc: dict) -> dict:
    """The run without its wall times (and without its command line)."""
    def clean(x):
        if isinstance(x, dict):
            return {k: clean(v) for k, v in x.items() if k not in TIMES and "seconds" not in k}
        if isinstance(x, list):
            return [clean(v) for v in x]
        return x
    return {"cases": clean(doc["cases"]), "summary": clean(doc["summary"]), "config": doc["config"]}


def differences(a, b, path="") -> list[str]:
    """Every place where ``a`` and ``b`` differ, as ``path: value vs value``."""
    if type(a) is not type(b):
        return [f"{path}: {a!r} vs {b!r}"]
    if isinstance(a, dict):
        out = []
        for k in sorted(set(a) | set(b)):
            if k not in a or k not in b:
                out.append(f"{path}/{k}: only in one run")
            else:
                out += differences(a[k], b[k], f"{path}/{k}")
        return out
    if isinstance(a, list):
        if len(a) != len(b):
            return [f"{path}: {len(a)} vs {len(b)} items"]
        return [d for n, (x, y) in enumerate(zip(a, b)) for d in differences(x, y, f"{path}[{n}]")]
    return [] if a == b else [f"{path}: {a!r} vs {b!r}"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("first", metavar="A/bench.json")
    ap.add_argument("second", metavar="B/bench.json")
    args = ap.parse_args(argv)
    a, b = (json.load(open(p)) for p in (args.first, args.second))
    sa, sb = strip(a), strip(b)
    diffs = differences(sa, sb)
    print(f"cases: {len(a['cases'])} vs {len(b['cases'])}; identical (timings aside): "
          f"{'yes' if not diffs else f'no, {len(diffs)} values differ'}; summary tables identical: "
          f"{'yes' if sa['summary'] == sb['summary'] else 'no'}")
    for d in diffs[:10]:
        print("  " + d)
    print(f"wall time: {a['seconds']:.1f} s vs {b['seconds']:.1f} s; "
          f"second / first = {b['seconds'] / a['seconds']:.2f}")
    return 0 if not diffs else 1


if __name__ == "__main__":
    sys.exit(main())
