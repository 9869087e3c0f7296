"""Speed of the simulator on the paper's default scenario (5 robots x 5000 poses x 360 beams).

Prints:

* the wall time of ``simulate`` after JIT warm-up, with the time of its ray casting alone;
* the numba ray caster against a plain-numpy reference (the slab method of
  ``tests/naive_simulate.py``) on a subset of the poses, per scan;
* the start-up time of a fresh process that imports fusionkit and simulates a tiny case with
  the JIT cache warm (``cache=True``);
* how much of the world the robots' maps cover.

Run::

    NUMBA_CACHE_DIR=/tmp/fk_numba_cache .venv/bin/python benchmarks/bench_simulate.py [--ref-poses 200]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

from fusionkit.simulate import LidarConfig, SimulationConfig, cast_scans, simulate  # noqa: E402
from fusionkit.worlds import default_world, make_world  # noqa: E402
from naive_simulate import slab_ranges  # noqa: E402

_CHILD = """
import time
t0 = time.perf_counter()
from fusionkit.simulate import SimulationConfig, simulate
from fusionkit.worlds import default_world
t1 = time.perf_counter()
simulate(default_world(), SimulationConfig(robots=2, poses=50, seed=1))
t2 = time.perf_counter()
print(f"{t1 - t0:.3f} {t2 - t1:.3f}")
"""


def best_of(fn, repeat):
    times = []
    out = None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return min(times), out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ref-poses", type=int, default=200, help="poses for the numpy reference (default 200)")
    ap.add_argument("--repeat", type=int, default=3, help="timed repetitions, best kept (default 3)")
    args = ap.parse_args()

    print(f"cores: {os.cpu_count()}, NUMBA_CACHE_DIR={os.environ.get('NUMBA_CACHE_DIR', '(default)')}")
    world = default_world()
    config = SimulationConfig()  # 5 robots x 5000 poses x 360 beams, seed 0
    t = time.perf_counter()
    simulate(world, SimulationConfig(robots=2, poses=20))
    print(f"warm-up (JIT compile or cache load): {time.perf_counter() - t:.2f} s")

    t_sim, sim = best_of(lambda: simulate(world, config), args.repeat)
    n_scans = config.robots * config.poses
    print(f"\nsimulate, {config.robots} robots x {config.poses} poses x {config.lidar.beams} beams: "
          f"{t_sim:.2f} s (best of {args.repeat}; {1e6 * t_sim / n_scans:.0f} us per scan, "
          f"walk + cast + noise + maps)")

    poses = np.concatenate([r.trajectory for r in sim.robots])
    lidar = LidarConfig(range_noise=0.0)
    t_cast, ranges = best_of(lambda: cast_scans(world, poses, lidar), args.repeat)
    print(f"  ray casting alone (numba, {len(poses)} scans): {t_cast:.2f} s = "
          f"{1e6 * t_cast / len(poses):.1f} us per scan")

    sub = poses[:: max(1, len(poses) // args.ref_poses)][: args.ref_poses]
    t_ref = time.perf_counter()
    ref = slab_ranges(world, sub, lidar.angles, lidar.max_range)
    t_ref = time.perf_counter() - t_ref
    t_fast, fast = best_of(lambda: cast_scans(world, sub, lidar), args.repeat)
    fin = np.isfinite(ref)
    agree = np.array_equal(np.isinf(fast), np.isinf(ref)) and np.allclose(fast[fin], ref[fin], atol=2e-5)
    per_ref = t_ref / len(sub)
    per_fast = t_cast / len(poses)
    print(f"  numpy reference (slab method) on {len(sub)} scans: {t_ref:.2f} s = "
          f"{1e3 * per_ref:.2f} ms per scan -> numba is {per_ref / per_fast:.0f}x faster per scan "
          f"(results agree: {agree})")

    cov = sim.coverage()
    print("\ncoverage of the world's known cells (true transforms):")
    for r, c in zip(sim.robots, cov.per_robot):
        print(f"  {r.name}: {100 * c:5.1f}%  path {r.path_length:6.1f} m")
    print(f"  all {len(sim.robots)} maps: {100 * cov.combined:.1f}%")
    for kind in ("warehouse", "cave"):
        s = simulate(make_world(kind), config)
        c = s.coverage()
        print(f"  {kind}: per robot {', '.join(f'{100 * v:.1f}' for v in c.per_robot)}%; "
              f"all {100 * c.combined:.1f}%")

    env = dict(os.environ)
    times = []
    for _ in range(3):
        t = time.perf_counter()
        out = subprocess.run([sys.executable, "-c", _CHILD], capture_output=True, text=True, env=env,
                             check=True)
        wall = time.perf_counter() - t
        imp, run = (float(v) for v in out.stdout.split())
        times.append((wall, imp, run))
    wall, imp, run = min(times)
    print(f"\nsecond process (warm JIT cache): {wall:.2f} s in all, of which import {imp:.2f} s and "
          f"a 2 robots x 50 poses simulation {run:.2f} s (best of 3)")


if __name__ == "__main__":
    main()
