"""Running: one case through every method (:func:`run_case`) and every case of a suite
(:func:`run_bench`, in this process or in a pool of processes, gathered in case order).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from ..errors import FusionkitError, InputError
from ..executor import Executor, InProcess, LocalProcesses
from ..grid import OccupancyGrid
from ..transform import Transform2D
from .cases import CaseSpec, WorldSpec, given_worlds, load_log, load_world, make_case, plan_cases
from .config import BenchConfig

__all__ = ["run_case", "BenchResult", "run_bench"]


def _centroid(g: OccupancyGrid) -> np.ndarray:
    r, c = np.nonzero(g.known_mask())
    if r.size == 0:
        return g.cell_to_world(g.rows / 2 - 0.5, g.cols / 2 - 0.5)
    return g.cell_to_world(r.mean(), c.mean())


def _grid_payload(g: OccupancyGrid) -> dict:
    return {"data": np.asarray(g.data), "resolution": g.resolution, "origin": g.origin}


def run_case(spec: CaseSpec, config: BenchConfig, keep_grids: bool = False) -> dict:
    """Build one case and run every method on it; a plain dict of figures (and, with
    ``keep_grids``, the fused grids for pictures)."""
    from ..fusion import fuse_maps
    from ..metrics import evaluate_map
    from ..pipeline import MergeConfig, merge

    t0 = time.perf_counter()
    case = make_case(spec, config)
    build_s = time.perf_counter() - t0
    k = spec.robots
    res = case.world.resolution
    ref_true = case.truth[0]
    rel_truth = [ref_true.inverse @ t for t in case.truth]
    oracle = fuse_maps(list(case.grids), rel_truth).grid
    oracle_m = evaluate_map(oracle, case.world, ref_true)
    out = {"index": spec.index, "world": spec.world.name, "mode": spec.mode, "robots": k,
           "seed": spec.seed, "build_seconds": round(build_s, 3),
           "overlap": [[round(float(v), 4) for v in row] for row in case.overlap],
           "linked": list(case.linked),
           "oracle": oracle_m.as_dict(2), "methods": {}}
    grids_out = {"world": _grid_payload(case.world), "truth": [t.as_dict() for t in case.truth],
                 "ref_true": ref_true.as_dict(), "fused": {}} if keep_grids else None
    scans = list(case.scans) if any(s is not None for s in case.scans) else None
    for method in config.methods:
        rec = {"maps": [], "error": ""}
        try:
            t1 = time.perf_counter()
            result = merge(list(case.grids), scans=scans,
                           config=MergeConfig(method=method, seed=spec.seed % 10_000))
            # a peer's confidence on the common scale is the consensus test's, not its own work
            seconds = time.perf_counter() - t1 - result.seconds.get("confidence", 0.0)
            transforms = result.transforms
            fused = result.grid
        except FusionkitError as exc:
            seconds = 0.0
            transforms = [Transform2D.identity()] + [None] * (k - 1)
            fused = case.grids[0]
            rec["error"] = str(exc)
        for j in range(1, k):
            ov = max(float(case.overlap[j, i]) for i in range(k) if i != j)
            entry = {"map": j, "overlap": round(ov, 4), "linked": bool(case.linked[j])}
            t = transforms[j]
            if t is None:
                entry.update(status="refused", rot_err_deg=None, trans_err_cells=None)
            else:
                p = _centroid(case.grids[j])
                d = float(np.hypot(*(t(p) - rel_truth[j](p)))) / res
                rot = math.degrees(t.error_to(rel_truth[j])[1])
                ok = rot < config.max_rotation_deg and d < config.max_cells
                entry.update(status="success" if ok else "wrong", rot_err_deg=round(rot, 4),
                             trans_err_cells=round(d, 3))
            rec["maps"].append(entry)
        rec["seconds"] = round(seconds, 4)
        rec["seconds_per_pair"] = round(seconds / (k - 1), 4)
        try:
            rec["table1"] = evaluate_map(fused, case.world, ref_true).as_dict(2)
        except FusionkitError:
            rec["table1"] = None
        out["methods"][method] = rec
        if grids_out is not None:
            grids_out["fused"][method] = _grid_payload(fused)
    if grids_out is not None:
        out["_grids"] = grids_out
    return out


def _run_one(shared, task):
    config, worlds = shared
    given_worlds(worlds)
    spec, keep = task
    return run_case(spec, config, keep_grids=keep)


@dataclass(frozen=True, eq=False)
class BenchResult:
    """Everything a bench run produced: its settings, the worlds, and one record per case."""

    config: BenchConfig
    worlds: tuple
    skipped: tuple
    cases: tuple
    showcase: dict | None = None
    seconds: float = 0.0
    command: str = ""


def run_bench(worlds: Sequence[WorldSpec], config: BenchConfig, *, jobs: int = 1,
              skipped: Sequence = (), command: str = "",
              progress: Callable[[int, int, str], None] | None = None,
              executor: Executor | None = None) -> BenchResult:
    """Run the suite on ``executor`` (default: ``jobs`` local processes, or this process for
    one; each worker process runs every method on one thread). Results do not depend on where
    the cases run; timings do."""
    if jobs < 1:
        raise InputError(f"jobs must be >= 1, got {jobs}")
    t0 = time.perf_counter()
    specs = plan_cases(worlds, config)
    show = next((s.index for s in specs if s.robots >= 3), specs[0].index)
    tasks = [(s, s.index == show) for s in specs]
    ex = executor if executor is not None else InProcess() if jobs == 1 else LocalProcesses(jobs)

    def tick(done, total):
        if progress is not None:
            progress(done, total, "")

    # each case is built from its own seed where it runs; records come back in case order
    # the worlds read from files go with the cases: a worker elsewhere (a Dask cluster) has
    # neither the files nor the folder their paths are relative to
    worlds_used = {s.world: load_world(s.world) for s in specs if s.world.path is not None}
    worlds_used.update({s.world: load_log(s.world) for s in specs if s.world.log is not None})
    records = ex.map(_run_one, tasks, shared=(config, worlds_used), progress=tick)
    showcase = records[show].pop("_grids", None)
    if showcase is not None:
        showcase["index"] = show
    return BenchResult(config, tuple(worlds), tuple(skipped), tuple(records), showcase,
                       time.perf_counter() - t0, command)
