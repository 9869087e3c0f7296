"""Does an unknown margin around a map change the consensus decision, and what does searching a
map on its known cells only cost? Pairs of windows of real floors, each merged as it is and with
its reference map padded by ``--pads`` unknown cells on every side (the same map in the same
frame, as map_saver writes a 4000 x 4000 grid), once as shipped (the map cut to its known cells
and a margin, :func:`fusionkit.methods.consensus._index._trimmed`) and once searched on its whole
grid (the code before), in the same process::

    python benchmarks/unknown_margin.py --maps ../shared/maps/real --pairs 2 --pads 0 1000 2000

Prints, per pad and per way, the pairs placed within 3 cells of the truth / elsewhere / refused,
and the median seconds per pair.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(HERE))

import fusionkit.methods.consensus._index as index_module  # noqa: E402
from fusionkit.grid import UNKNOWN, OccupancyGrid  # noqa: E402
from fusionkit.mapio import load_map  # noqa: E402
from fusionkit.methods.consensus import estimate_pair  # noqa: E402
from fusionkit.methods.peers import crop_pair, placement_error  # noqa: E402

SHIPPED = index_module._trimmed


def padded(grid: OccupancyGrid, cells: int) -> OccupancyGrid:
    """``grid`` with ``cells`` unknown cells on every side, in the same frame."""
    if cells == 0:
        return grid
    x, y, yaw = grid.origin
    c, s, d = math.cos(yaw), math.sin(yaw), cells * grid.resolution
    return OccupancyGrid(np.pad(grid.data, cells, constant_values=UNKNOWN), grid.resolution,
                         (x - c * d + s * d, y - s * d - c * d, yaw))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--maps", default=str(HERE.parent / "shared" / "maps" / "real"))
    ap.add_argument("--pairs", type=int, default=2, help="window pairs per floor")
    ap.add_argument("--pads", type=int, nargs="+", default=[0, 1000, 2000])
    ap.add_argument("--seed", type=int, default=5)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    cases = []
    for f in sorted(Path(args.maps).glob("*.yaml")):
        g = load_map(f)
        for _ in range(args.pairs):
            try:
                cases.append(crop_pair(g, rng, size=200, min_overlap=0.4))
            except Exception:   # noqa: BLE001 - a floor with no such window: none drawn there
                pass
    print(f"{len(cases)} pairs of windows of {args.maps}")
    print("| pad (cells) | way | right / wrong / refused | median s per pair |")
    print("|---|---|---|---|")
    for pad in args.pads:
        for name, trim in (("known cells (shipped)", SHIPPED), ("whole grid (before)", lambda g: g)):
            index_module._trimmed = trim
            counts, secs = [0, 0, 0], []
            for c in cases:
                a = padded(c.a, pad)
                t0 = time.perf_counter()
                r = estimate_pair(a, c.b)
                secs.append(time.perf_counter() - t0)
                if not r.accepted:
                    counts[2] += 1
                else:
                    d, th = placement_error(r.transform, c.truth, c.b)
                    counts[0 if d < 3 * c.a.resolution and th < math.radians(2) else 1] += 1
            index_module._trimmed = SHIPPED
            print(f"| {pad} | {name} | {counts[0]} / {counts[1]} / {counts[2]} | "
                  f"{float(np.median(secs)):.3f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
