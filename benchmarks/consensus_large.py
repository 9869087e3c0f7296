"""Time per pair of the consensus method against map-merge on the largest real floors.

    python benchmarks/consensus_large.py [--maps 6] [--pairs 2] [--seed 5] [--fraction 0.7]
        [--record FILE] [--profile FILE]

The ``--maps`` largest maps (by cells) of ../shared/maps/real when it stands beside the
repository (else maps/real), at their native resolution. From each, ``--pairs`` pairs of
windows are cut: each window ``--fraction`` of the known area's height and width (not clipped
to the bench's 600 cells), the second one shifted from the first by a random part of the rest,
both turned by a random angle into frames of their own (so up to 2000 x 2000 cells). Both methods
merge each pair in turn in one process, one thread each. Prints, per method, the pairs placed
right (within 2 degrees and 3 cells of the truth), wrong and refused, the median time per pair
and the ratio of the medians; ``--record`` writes what each method decided per pair (JSON).
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
from fusionkit.bench.cases import find_worlds, load_world
from fusionkit.grid import OccupancyGrid
from fusionkit.methods.consensus import ConsensusConfig, prepare_maps, refine_pso
from fusionkit.pipeline import MergeConfig, merge
from fusionkit.resample import canvas_for, resample
from fusionkit.transform import Transform2D


def _window(world: OccupancyGrid, r0: int, c0: int, h: int, w: int, theta: float, name: str):
    """The window ``[r0:r0+h, c0:c0+w]`` of ``world`` in a frame of its own turned by
    ``theta``: the grid and its transform into the world's frame."""
    cells = world.data[r0:r0 + h, c0:c0 + w]
    corner = world.cell_to_world(r0 - 0.5, c0 - 0.5)
    win = OccupancyGrid(np.ascontiguousarray(cells), world.resolution,
                        (float(corner[0]), float(corner[1]), world.origin[2]))
    centre = world.cell_to_world(r0 + h / 2 - 0.5, c0 + w / 2 - 0.5)
    own_to_world = Transform2D(float(centre[0]), float(centre[1]), theta)
    g = resample(win, own_to_world.inverse, canvas_for([win], [own_to_world.inverse],
                                                       world.resolution))
    return g.with_data(g.data, name=name), own_to_world


def make_pair(world: OccupancyGrid, fraction: float, rng: np.random.Generator):
    """Two overlapping windows of ``world`` (see the module's description)."""
    r, c = np.nonzero(world.known_mask())
    r_lo, c_lo = int(r.min()), int(c.min())
    kh, kw = int(r.max()) - r_lo + 1, int(c.max()) - c_lo + 1
    h, w = max(1, int(round(fraction * kh))), max(1, int(round(fraction * kw)))
    # the first window in one corner of the known area, the second towards the opposite one
    sr, sc = int(rng.choice([-1, 1])), int(rng.choice([-1, 1]))
    off = rng.uniform(0.5, 1.0, 2)
    r1 = r_lo if sr > 0 else r_lo + kh - h
    c1 = c_lo if sc > 0 else c_lo + kw - w
    r2 = int(r1 + sr * round(off[0] * (kh - h)))
    c2 = int(c1 + sc * round(off[1] * (kw - w)))
    g1, t1 = _window(world, r1, c1, h, w, float(rng.uniform(-math.pi, math.pi)), "part_1")
    g2, t2 = _window(world, r2, c2, h, w, float(rng.uniform(-math.pi, math.pi)), "part_2")
    return (g1, g2), (t1, t2)


def _right(grids, truth, t, resolution) -> str:
    if t is None:
        return "refused"
    rel = truth[0].inverse @ truth[1]
    r, c = np.nonzero(grids[1].known_mask())
    centre = grids[1].cell_to_world(r.mean(), c.mean())
    d = float(np.hypot(*(t(centre) - rel(centre)))) / resolution
    return "right" if d < 3 and math.degrees(t.error_to(rel)[1]) < 2 else "wrong"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--maps", type=int, default=6, help="the largest maps used (default 6)")
    ap.add_argument("--pairs", type=int, default=2, help="pairs cut from each map (default 2)")
    ap.add_argument("--seed", type=int, default=5, help="seed of the windows (default 5)")
    ap.add_argument("--fraction", type=float, default=0.7,
                    help="window side over the known area's side (default 0.7)")
    ap.add_argument("--record", default="", metavar="FILE",
                    help="write what each method decided on each pair to FILE (JSON)")
    ap.add_argument("--profile", default="", metavar="FILE",
                    help="profile the consensus merges into FILE (cProfile statistics)")
    args = ap.parse_args()
    if args.maps < 1 or args.pairs < 1 or not 0.2 <= args.fraction <= 0.95:
        ap.error("--maps and --pairs are >= 1, --fraction is in [0.2, 0.95]")
    root = Path(__file__).resolve().parents[1]
    shared = root.parent / "shared" / "maps" / "real"
    worlds, _ = find_worlds([shared if shared.is_dir() else root / "maps" / "real"])
    grids = [(w, load_world(w)) for w in worlds]
    grids.sort(key=lambda wg: -wg[1].rows * wg[1].cols)
    cv2.setNumThreads(1)
    numba.set_num_threads(1)
    methods = {"consensus": MergeConfig(consensus=ConsensusConfig(threads=1)),
               "map-merge": MergeConfig(method="map-merge")}
    runs = {m: {"right": 0, "wrong": 0, "refused": 0, "t": []} for m in methods}
    record = []
    prof = cProfile.Profile() if args.profile else None
    warm = False
    for k, (spec, world) in enumerate(grids[: args.maps]):
        for p in range(args.pairs):
            rng = np.random.default_rng([args.seed, k, p])
            pair, truth = make_pair(world, args.fraction, rng)
            if not warm:  # compile every kernel before anything is timed
                for cfg in methods.values():
                    merge(list(pair), config=cfg)
                # the swarm polish runs only on pairs with contenders: compile it here too
                a, b = prepare_maps(list(pair)[:2])
                refine_pso(a.points, b.refine_points, Transform2D(), a.resolution, seed=0)
                warm = True
            entry = {"world": spec.name, "pair": p,
                     "shape": [list(g.data.shape) for g in pair]}
            for m, cfg in methods.items():
                if prof is not None and m == "consensus":
                    prof.enable()
                t0 = time.perf_counter()
                res = merge(list(pair), config=cfg)
                seconds = time.perf_counter() - t0 - res.seconds.get("confidence", 0.0)
                if prof is not None and m == "consensus":
                    prof.disable()
                t = res.placements[1].transform
                verdict = _right(pair, truth, t, world.resolution)
                runs[m][verdict] += 1
                runs[m]["t"].append(seconds)
                entry[m] = {"verdict": verdict, "seconds": round(seconds, 3),
                            "transform": None if t is None else [t.x, t.y, t.theta],
                            "confidence": float(res.placements[1].confidence),
                            "reason": res.placements[1].reason}
            record.append(entry)
            print(f"{spec.name:<28} {p} {entry['shape'][0]} {entry['shape'][1]}  " + "  ".join(
                f"{m} {entry[m]['verdict']} {entry[m]['seconds']:.2f} s" for m in methods),
                flush=True)
    if args.record:
        write_text_atomic(args.record, json.dumps(record, indent=1))
    if prof is not None:
        prof.dump_stats(args.profile)
    base = statistics.median(runs["map-merge"]["t"])
    print(f"{args.maps} largest maps x {args.pairs} pairs, windows {args.fraction} of the known "
          f"area, seed {args.seed}")
    for m, st in runs.items():
        med = statistics.median(st["t"])
        print(f"{m:<10} right {st['right']:>3} wrong {st['wrong']:>3} refused {st['refused']:>3}  "
              f"median {med:.3f} s / pair  x map-merge {med / max(base, 1e-9):.2f}  "
              f"total {sum(st['t']):.1f} s")


if __name__ == "__main__":
    main()
