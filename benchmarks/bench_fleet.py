"""Large fleets: merge time and pairs estimated, every pair vs candidate pairs.

For each fleet size K, K robots explore one simulated cave whose area grows with K (so that a
robot overlaps about as many others whatever K), each robot's map and scans in its own frame.
The default method merges the fleet twice: with every pair estimated (``candidates=0``) and with
candidate pairs (the default). Printed per K and mode: merge wall time (prepare, pairs, graph,
fuse included), pairs estimated, maps placed, wrong placements (rotation error >= 2 deg or
known-cell centroid >= 3 cells from the truth), the CPU time of this process during the merge,
and the peak resident memory of this process so far (a fleet simulated in this run counts).
Then, for each K where both ran, whether every map the exhaustive merge placed correctly is
placed correctly with candidates too.

Fleets are simulated in batches of at most 50 robots (each batch its own seed) and cached in
``--cache`` (``.npz`` per fleet) so that a second run does not simulate again.

Run (the machine's cores may be shared: compare ratios within one run)::

    NUMBA_THREADING_LAYER=threadsafe .venv/bin/python benchmarks/bench_fleet.py \
        [--k 5 10 20 50 100] [--exhaustive-max 50] [--top 4 6] [--workers N --backend dask]

With ``--backend dask`` the peak resident memory of each worker is printed too (each holds the
fleet's prepared maps once, scattered to it, whatever the number of pair tasks).
"""

from __future__ import annotations

import argparse
import math
import resource
import sys
import time
from pathlib import Path

import numpy as np

from fusionkit.methods.consensus import ConsensusConfig
from fusionkit.executor import make_executor, using
from fusionkit.grid import OccupancyGrid
from fusionkit.pipeline import MergeConfig, merge
from fusionkit.resample import canvas_for, resample
from fusionkit.scanlog import ScanLog
from fusionkit.simulate import SimulationConfig, simulate
from fusionkit.transform import Transform2D
from fusionkit.worlds import make_world

#: World area per robot (m^2); the cave is 4:3.
AREA_PER_ROBOT = 500.0


def world_for(k: int, area_per_robot: float) -> tuple[float, float]:
    area = max(k * area_per_robot, 40.0 * 30.0)
    w = math.sqrt(area * 4 / 3)
    return (round(w, 1), round(w * 3 / 4, 1))


def make_fleet(k: int, poses: int, seed: int, area_per_robot: float, cache: Path):
    """Grids, scans and true transforms (own frame -> world) of ``k`` robots."""
    size = world_for(k, area_per_robot)
    path = cache / f"fleet_k{k}_p{poses}_s{seed}_a{area_per_robot:g}.npz"
    if path.exists():
        z = np.load(path, allow_pickle=False)
        grids, scans, truth = [], [], []
        for r in range(k):
            grids.append(OccupancyGrid(z[f"data{r}"], float(z["res"]), tuple(z[f"origin{r}"]),
                                       name=f"robot_{r + 1}"))
            scans.append(ScanLog(z[f"poses{r}"], z[f"ranges{r}"], float(z["amin"]), float(z["ainc"]),
                                 float(z["rmax"])))
            truth.append(Transform2D(*z[f"truth{r}"]))
        return grids, scans, truth, size
    world = make_world("cave", seed=seed, size=size)
    grids, scans, truth = [], [], []
    left, batch = k, 0
    while left:
        n = min(left, 50)
        sim = simulate(world, SimulationConfig(robots=n, poses=poses, seed=seed * 1000 + batch))
        for r in sim.robots:
            grids.append(r.grid)
            scans.append(r.scans)
            truth.append(r.transform)
        left -= n
        batch += 1
    payload = {"res": grids[0].resolution}
    s0 = scans[0]
    payload.update(amin=s0.angle_min, ainc=s0.angle_increment, rmax=s0.range_max)
    for r, (g, s, t) in enumerate(zip(grids, scans, truth)):
        payload[f"data{r}"] = g.data
        payload[f"origin{r}"] = np.array(g.origin, float)
        payload[f"poses{r}"] = s.poses
        payload[f"ranges{r}"] = s.ranges
        payload[f"truth{r}"] = np.array([t.x, t.y, t.theta])
    cache.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    np.savez(tmp, **payload)
    tmp.replace(path)
    grids = [OccupancyGrid(g.data, g.resolution, g.origin, name=f"robot_{r + 1}")
             for r, g in enumerate(grids)]
    return grids, scans, truth, size


def centroid(g: OccupancyGrid) -> np.ndarray:
    r, c = np.nonzero(g.known_mask())
    return g.cell_to_world(r.mean(), c.mean())


def score(grids, truth, transforms) -> list[str]:
    """Per map: ``"ok"``, ``"wrong"`` or ``"left"`` (not placed)."""
    rel = [truth[0].inverse @ t for t in truth]
    res = grids[0].resolution
    out = []
    for k, t in enumerate(transforms):
        if t is None:
            out.append("left")
            continue
        p = centroid(grids[k])
        d = float(np.hypot(*(t(p) - rel[k](p)))) / res
        rot = math.degrees(t.error_to(rel[k])[1])
        out.append("ok" if rot < 2.0 and d < 3.0 else "wrong")
    return out


def best_overlap(grids, truth, m: int) -> float:
    """Largest share of map ``m``'s known cells (in the world) that another map also knows."""
    canvas = canvas_for([grids[m]], [truth[m]], grids[m].resolution)
    mine = resample(grids[m], truth[m], canvas).known_mask()
    total = max(int(mine.sum()), 1)
    best = 0.0
    for k, (g, t) in enumerate(zip(grids, truth)):
        if k != m:
            best = max(best, float((resample(g, t, canvas).known_mask() & mine).sum()) / total)
    return best


def peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def worker_peaks(ex) -> str:
    """Peak resident memory of each Dask worker process (MB), or "" on other back ends."""
    client = getattr(ex, "client", None)
    if client is None:
        return ""
    peaks = client.run(peak_mb)
    return "; workers' peak MB: " + ", ".join(f"{v:.0f}" for v in peaks.values())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--k", nargs="+", type=int, default=[5, 10, 20, 50, 100])
    ap.add_argument("--poses", type=int, default=1500)
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--area-per-robot", type=float, default=AREA_PER_ROBOT)
    ap.add_argument("--exhaustive-max", type=int, default=50,
                    help="run the every-pair merge only up to this K (default 50)")
    ap.add_argument("--top", type=int, nargs="+", default=[ConsensusConfig().candidates],
                    help="candidates per map, one merge per value (default: the method's)")
    ap.add_argument("--backend", default=None, choices=("inprocess", "processes", "dask"))
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--cache", default="/tmp/fusionkit_fleets")
    args = ap.parse_args(argv)
    cache = Path(args.cache)
    print(f"{'K':>4} {'mode':<11} {'seconds':>8} {'CPU s':>7} {'pairs':>6} {'placed':>6} {'wrong':>5} "
          f"{'peak MB':>8}  world")
    rows = {}
    with make_executor(args.backend, workers=args.workers) as ex, using(ex):
        if args.backend is not None:
            print(f"# {ex.describe()}")
        for k in args.k:
            t0 = time.perf_counter()
            grids, scans, truth, size = make_fleet(k, args.poses, args.seed, args.area_per_robot, cache)
            sim_s = time.perf_counter() - t0
            modes = [(f"top {top}", top) for top in args.top]
            if k <= args.exhaustive_max:
                modes.insert(0, ("every-pair", 0))
            for mode, top in modes:
                cfg = MergeConfig(seed=0, consensus=ConsensusConfig(candidates=top))
                t0, c0 = time.perf_counter(), time.process_time()
                res = merge(grids, scans=scans, config=cfg)
                secs, cpu = time.perf_counter() - t0, time.process_time() - c0
                status = score(grids, truth, res.transforms)
                rows[(k, mode)] = (secs, status, res)
                print(f"{k:>4} {mode:<11} {secs:8.1f} {cpu:7.1f} {len(res.steps):>6} {status.count('ok') + status.count('wrong'):>6} "
                      f"{status.count('wrong'):>5} {peak_mb():8.0f}  cave {size[0]:g}x{size[1]:g} m "
                      f"(fleet made in {sim_s:.0f} s); " + ", ".join(f"{s} {v:.1f}" for s, v in res.seconds.items())
                      + worker_peaks(ex), flush=True)
                left = [m for m, st in enumerate(status) if st == "left"]
                if left:
                    print(f"{k:>4} left out: " + ", ".join(
                        f"robot_{m + 1} (largest true overlap with another map {best_overlap(grids, truth, m):.2f})"
                        for m in left), flush=True)
            for top in args.top if (k, "every-pair") in rows else ():
                ex_ok = {m for m, s in enumerate(rows[(k, "every-pair")][1]) if s == "ok"}
                ca_ok = {m for m, s in enumerate(rows[(k, f"top {top}")][1]) if s == "ok"}
                lost = sorted(ex_ok - ca_ok)
                print(f"{k:>4} top {top}: same correct placements as every-pair: "
                      f"{'yes' if ex_ok == ca_ok else 'no'}; lost: {lost or 'none'}; "
                      f"gained: {sorted(ca_ok - ex_ok) or 'none'}", flush=True)
    for top in args.top:
        ks = [k for k in args.k if (k, f"top {top}") in rows]
        for a, b in zip(ks, ks[1:]):
            ra, rb = rows[(a, f"top {top}")], rows[(b, f"top {top}")]
            print(f"top {top}: K {a} -> {b}: time x{rb[0] / ra[0]:.2f}, pairs x"
                  f"{len(rb[2].steps) / len(ra[2].steps):.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
