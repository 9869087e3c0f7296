"""Did two runs decide the same? Compares the records of ``consensus_speed.py --record`` (or
``consensus_large.py --record``) made before and after a change::

    python benchmarks/consensus_speed.py --shipped --record /tmp/before.json   # old code
    python benchmarks/consensus_speed.py --shipped --record /tmp/after.json    # new code
    python benchmarks/compare_decisions.py /tmp/before.json /tmp/after.json

Prints every map whose decision differs (merged or not, group, reason) and the largest change
of a placement (m and rad); exit status 0 when every decision and placement is the same
(placements within ``--tolerance``, default 0: bit for bit), 1 otherwise.
"""

from __future__ import annotations

import argparse
import json
import sys


def _maps(entry: dict) -> list:
    """The per-map decisions of one record entry (both record formats)."""
    if "maps" in entry:
        return entry["maps"]
    return [{"method": m, **entry[m]} for m in ("consensus", "map-merge") if m in entry]


def _key(entry: dict) -> tuple:
    return tuple(entry.get(k) for k in ("case", "world", "mode", "variant", "pair"))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before")
    ap.add_argument("after")
    ap.add_argument("--tolerance", type=float, default=0.0,
                    help="largest change of a placement (m or rad) counted as the same")
    args = ap.parse_args()
    try:
        runs = [json.load(open(p)) for p in (args.before, args.after)]
    except (OSError, ValueError) as exc:
        print(f"error: cannot read a record ({exc}); give two files written by --record",
              file=sys.stderr)
        return 2
    before, after = ({_key(e): e for e in run} for run in runs)
    differ, worst, compared = 0, 0.0, 0
    for key in sorted(set(before) | set(after), key=str):
        if key not in before or key not in after:
            print(f"{key}: only in {'after' if key not in before else 'before'}")
            differ += 1
            continue
        for k, (m0, m1) in enumerate(zip(_maps(before[key]), _maps(after[key]))):
            compared += 1
            t0 = m0.get("transform")
            t1 = m1.get("transform")
            what = [f for f in ("merged", "verdict", "group", "reason")
                    if m0.get(f) != m1.get(f)]
            if (t0 is None) != (t1 is None):
                what.append("transform")
            elif t0 is not None:
                d = max(abs(x - y) for x, y in zip(t0, t1))
                worst = max(worst, d)
                if d > args.tolerance:
                    what.append(f"transform by {d:.3g}")
            if what:
                differ += 1
                print(f"{key} map {k}: {', '.join(what)}: {m0} -> {m1}")
    print(f"{compared} decisions compared, {differ} differ; largest change of a placement "
          f"{worst:.3g} (m or rad)")
    return 0 if differ == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
