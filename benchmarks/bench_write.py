"""Cost of crash-safe output: a merged map set written by ``save_maps`` against plain writes.

``save_maps`` locks the folder, stages every file under a temporary name, flushes each to disk
(``fsync``), keeps an undo journal and backups, and renames the files in a safe order with the
report last. The baseline writes the same bytes (image, YAML, report) straight to their final
names with no flush. Both run in this process, alternately, over an earlier output (so the
set writer also has backups to make and drop); the ratio is what the promise costs.

Run::

    .venv/bin/python benchmarks/bench_write.py [--size 6000] [--repeat 5]
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from fusionkit.grid import OccupancyGrid
from fusionkit.mapio import encode_map, save_maps


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", type=int, default=6000, help="map side in cells (default 6000)")
    ap.add_argument("--repeat", type=int, default=5, help="timed writes of each kind (default 5)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the random map (default 0)")
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    data = rng.choice(np.array([-1, 0, 100], np.int8), size=(args.size, args.size), p=[0.5, 0.4, 0.1])
    grid = OccupancyGrid(data, 0.05, (0.0, 0.0, 0.0))
    report = json.dumps({"method": "bench", "maps": []}, indent=2) + "\n"
    safe, plain = [], []
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "merged.yaml"
        rep = Path(tmp) / "merged.report.json"
        save_maps([(grid, out)], (rep, report))  # an earlier output to replace
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            save_maps([(grid, out)], (rep, report))
            safe.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            image, pixels, text = encode_map(grid, out)
            image.write_bytes(pixels)
            out.write_bytes(text)
            rep.write_text(report)
            plain.append(time.perf_counter() - t0)
    s, p = statistics.median(safe), statistics.median(plain)
    print(f"{args.size} x {args.size} map ({args.size ** 2 / 1e6:.0f} MB image), median of {args.repeat}:")
    print(f"  save_maps (locked, fsync, journal, report last): {s:.3f} s")
    print(f"  plain writes of the same bytes:                  {p:.3f} s")
    print(f"  ratio: {s / p:.2f}x")


if __name__ == "__main__":
    main()
