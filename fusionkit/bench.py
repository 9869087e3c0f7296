"""A benchmark suite: every method on the same seeded cases, scored against the truth.

Cases
-----
Each case is made from one ground-truth map (a *world*) and a seed, in one of two modes:

``explore``
    ``K`` simulated robots explore the world (:func:`fusionkit.simulate.simulate`); each brings
    its own map and scans, in its own frame (CONTRACTS section 5).
``crop``
    ``K`` overlapping square windows are cut from the world, each turned by a random angle,
    shifted by a random offset and resampled into a frame of its own: the classic map-merging
    benchmark. These maps come without scans.

The *overlap* of two maps is the share of the smaller one's known cells (in the world) that the
other also knows. Cases are drawn so that every map overlaps another one by at least
``min_overlap`` and all are linked to the reference (the first map) by such overlaps; when a
simulation cannot give that in a few tries, the maps left unlinked are scored apart (refusing
them is right). A map with fewer than ``MIN_MAP_WALLS`` occupied cells (a robot that saw no wall
in range, as on an open campus) holds nothing to place it by: it links nothing and is scored
apart too.

Scoring
-------
Every non-reference map of a case is one *pair* (the map and the reference frame). A merged map
is a **success** when its rotation error is below ``max_rotation_deg`` and the known-cell centroid
of the map lands within ``max_cells`` cells of where the true transform puts it; merged outside
those bounds it is a **wrong merge**; not merged it is a **refusal**. The fused map of each case is
scored with the paper's Table 1 metrics (CONTRACTS section 7) against the world, placed by the
reference's true transform, beside the oracle (the fusion with the true transforms). Time per
pair is a merge's wall time over ``K - 1``.

Cases are independent: each is built from its own seed inside whichever process runs it, and
results are gathered in case order, so the figures do not depend on ``jobs`` (wall times do).
"""

from __future__ import annotations

import json
import math
import os
import statistics
import time
from dataclasses import asdict, dataclass
from functools import lru_cache
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from ._atomic import atomic_path, write_text_atomic
from .errors import FusionkitError, InputError
from .executor import Executor, InProcess, LocalProcesses
from .grid import OCCUPIED, OccupancyGrid
from .resample import canvas_for, resample
from .transform import Transform2D

__all__ = ["BenchConfig", "WorldSpec", "CaseSpec", "Case", "find_worlds", "plan_cases", "make_case",
           "run_case", "BenchResult", "run_bench", "summarize", "format_markdown", "write_outputs",
           "MODES", "DEFAULT_METHODS", "OVERLAP_BINS"]

MODES = ("explore", "crop")
#: Methods compared by default: fusionkit's two and the classic peers (map-merge with its chaining
#: corrected and as shipped).
DEFAULT_METHODS = ("consensus", "spectral-pso", "map-merge", "map-merge-shipped", "hough-spectrum",
                   "fourier-mellin")
#: Overlap bins of the breakdown (lower edges).
OVERLAP_BINS = (0.0, 0.15, 0.3, 0.5)
#: Fewest occupied cells for a map to be used as a world.
MIN_WORLD_OCCUPIED = 1000
#: Fewest occupied cells for a case's map to count as placeable (linked).
MIN_MAP_WALLS = 20


@dataclass(frozen=True)
class BenchConfig:
    """What the suite contains and how it is scored.

    Attributes
    ----------
    methods : tuple of str
        Method names (:data:`fusionkit.pipeline.METHODS`).
    modes : tuple of str
        ``"explore"`` and/or ``"crop"``.
    robots : tuple of int
        Numbers of maps per case (2 to 5), cycled over the cases.
    cases : int
        Number of cases.
    min_overlap : float
        Least overlap (0..1) linking each map to another.
    max_overlap : float
        Largest overlap of a crop with the window it was drawn beside (0..1).
    poses : int
        Poses per simulated robot (explore).
    range_noise : float
        LIDAR range noise, standard deviation (m) (explore).
    drift : float
        Odometry translation drift (m per square-root metre travelled) (explore).
    drift_theta : float
        Odometry heading drift (rad per square-root metre travelled) (explore).
    cell_noise : float
        Fraction of each crop's wall cells moved to a random neighbouring cell (crop).
    crop_fraction : float
        Side of the crop windows as a fraction of the shorter side of the world's known area.
    max_rotation_deg, max_cells : float
        Success bounds: rotation error (degrees) and centroid displacement (cells).
    seed : int
        Seed of the whole suite.
    """

    methods: tuple = DEFAULT_METHODS
    modes: tuple = MODES
    robots: tuple = (2, 3, 4, 5)
    cases: int = 20
    min_overlap: float = 0.15
    max_overlap: float = 0.85
    poses: int = 1500
    range_noise: float = 0.01
    drift: float = 0.0
    drift_theta: float = 0.0
    cell_noise: float = 0.0
    crop_fraction: float = 0.55
    max_rotation_deg: float = 2.0
    max_cells: float = 3.0
    seed: int = 0

    def __post_init__(self):
        from .pipeline import METHODS
        object.__setattr__(self, "methods", tuple(self.methods))
        object.__setattr__(self, "modes", tuple(self.modes))
        object.__setattr__(self, "robots", tuple(int(k) for k in self.robots))
        if not self.methods:
            raise InputError("give at least one method to benchmark")
        for m in self.methods:
            if m not in METHODS:
                raise InputError(f"unknown method {m!r}; choose from {', '.join(METHODS)}")
        if len(set(self.methods)) != len(self.methods):
            raise InputError("a method is listed twice; list each once")
        if not self.modes or any(m not in MODES for m in self.modes):
            raise InputError(f"modes must be among {', '.join(MODES)}, got {', '.join(self.modes) or 'none'}")
        if not self.robots or any(not 2 <= k <= 5 for k in self.robots):
            raise InputError(f"robots per case must be between 2 and 5, got {self.robots}")
        if self.cases < 1:
            raise InputError(f"cases must be >= 1, got {self.cases}")
        if not 0.0 < self.min_overlap < self.max_overlap <= 1.0:
            raise InputError(f"overlaps must satisfy 0 < min ({self.min_overlap}) < max "
                             f"({self.max_overlap}) <= 1")
        if self.poses < 100:
            raise InputError(f"poses per robot must be >= 100, got {self.poses}")
        for name in ("range_noise", "drift", "drift_theta", "cell_noise"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise InputError(f"{name.replace('_', ' ')} must be >= 0, got {v}")
        if self.cell_noise > 0.5:
            raise InputError(f"cell noise is a fraction of wall cells, at most 0.5, got {self.cell_noise}")
        if not 0.1 <= self.crop_fraction <= 1.0:
            raise InputError(f"crop fraction must be in [0.1, 1], got {self.crop_fraction}")
        if self.max_rotation_deg <= 0 or self.max_cells <= 0:
            raise InputError("success bounds must be > 0")


# -- worlds ---------------------------------------------------------------------------------------

@dataclass(frozen=True)
class WorldSpec:
    """A ground-truth map: a map file (``path``) or a built-in world (``builtin`` name)."""

    name: str
    path: str | None = None
    builtin: str | None = None


@lru_cache(maxsize=32)
def load_world(spec: WorldSpec) -> OccupancyGrid:
    """The world's grid in its three states (cached per process)."""
    if spec.builtin is not None:
        from .worlds import make_world
        g = make_world(spec.builtin, 0)
    else:
        from .mapio import load_map
        g = load_map(spec.path)
    return g.with_data(g.trinary(), name=spec.name)


def _usable(g: OccupancyGrid) -> str:
    """Why a world cannot be used ("" when it can)."""
    occ = int(g.occupied_mask().sum())
    if occ < MIN_WORLD_OCCUPIED:
        return f"only {occ} occupied cells, needs {MIN_WORLD_OCCUPIED}"
    if int(g.free_mask().sum()) < 20 * MIN_WORLD_OCCUPIED:
        return "too little free space"
    r, c = np.nonzero(g.known_mask())
    if min(r.max() - r.min(), c.max() - c.min()) < 150:
        return "its known area is narrower than 150 cells"
    return ""


def find_worlds(folders: Sequence[str | os.PathLike] = (), builtin: Sequence[str] = ()) -> tuple[list, list]:
    """Usable worlds in ``folders`` (their ``*.yaml`` maps, sorted) and the built-in worlds named.

    Returns ``(worlds, skipped)``: a list of :class:`WorldSpec` and a list of
    ``(name, reason)`` for maps that could not be used.

    Raises
    ------
    InputError
        A folder that does not exist, or no usable world at all.
    """
    from .worlds import WORLDS
    worlds, skipped = [], []
    seen = set()
    for folder in folders:
        d = Path(folder)
        if not d.is_dir():
            raise InputError(f"{d}: no such folder of ground-truth maps")
        for p in sorted(d.glob("*.yaml")):
            name = p.stem
            if name in seen:
                name = f"{d.name}/{p.stem}"
            spec = WorldSpec(name, path=str(p))
            try:
                why = _usable(load_world(spec))
            except FusionkitError as exc:
                why = str(exc)
            if why:
                skipped.append((name, why))
            else:
                worlds.append(spec)
                seen.add(name)
    for b in builtin:
        if b not in WORLDS:
            raise InputError(f"unknown built-in world {b!r}; choose from {', '.join(WORLDS)}")
        if b not in seen:
            worlds.append(WorldSpec(b, builtin=b))
            seen.add(b)
    if not worlds:
        where = ", ".join(str(f) for f in folders) or "(no folder given)"
        detail = "; ".join(f"{n}: {w}" for n, w in skipped[:5])
        raise InputError(f"{where}: no usable ground-truth map (map_server YAML with at least "
                         f"{MIN_WORLD_OCCUPIED} occupied cells)" + (f"; {detail}" if detail else ""))
    return worlds, skipped


# -- cases ----------------------------------------------------------------------------------------

@dataclass(frozen=True)
class CaseSpec:
    """What to build: case ``index`` on ``world`` in ``mode`` with ``robots`` maps."""

    index: int
    world: WorldSpec
    mode: str
    robots: int
    seed: int


@dataclass(frozen=True, eq=False)
class Case:
    """A built case.

    Attributes
    ----------
    spec : CaseSpec
    world : OccupancyGrid
        The ground truth.
    grids : tuple of OccupancyGrid
        The maps, each in its own frame.
    scans : tuple of (ScanLog or None)
    truth : tuple of Transform2D
        Per map, its frame -> the world frame.
    overlap : (K, K) ndarray
        Overlap of every two maps (1 on the diagonal).
    linked : tuple of bool
        Per map, whether overlaps of at least ``min_overlap`` between maps that hold walls
        link it to the reference.
    """

    spec: CaseSpec
    world: OccupancyGrid
    grids: tuple
    scans: tuple
    truth: tuple
    overlap: np.ndarray
    linked: tuple


def plan_cases(worlds: Sequence[WorldSpec], config: BenchConfig) -> list[CaseSpec]:
    """The suite: case ``i`` takes world ``i mod W``, mode ``(i // W) mod M`` and K
    ``(i + i // (W M)) mod R`` (so every world meets every mode and K as the suite grows), and a
    seed drawn from the suite's seed and ``i``."""
    W, M, R = len(worlds), len(config.modes), len(config.robots)
    out = []
    for i in range(config.cases):
        out.append(CaseSpec(i, worlds[i % W], config.modes[(i // W) % M],
                            config.robots[(i + i // (W * M)) % R],
                            int(np.random.SeedSequence([config.seed, i]).generate_state(1)[0] % 2**31)))
    return out


def _overlaps(masks: list) -> np.ndarray:
    k = len(masks)
    sizes = [max(int(m.sum()), 1) for m in masks]
    ov = np.eye(k)
    for i in range(k):
        for j in range(i + 1, k):
            ov[i, j] = ov[j, i] = int((masks[i] & masks[j]).sum()) / min(sizes[i], sizes[j])
    return ov


def _linked(ov: np.ndarray, min_overlap: float, grids=None, reference: int = 0) -> tuple:
    k = ov.shape[0]
    walls = [True] * k if grids is None else [int(g.occupied_mask().sum()) >= MIN_MAP_WALLS
                                               for g in grids]
    seen = {reference} if walls[reference] else set()
    stack = list(seen)
    while stack:
        i = stack.pop()
        for j in range(k):
            if j not in seen and walls[j] and ov[i, j] >= min_overlap:
                seen.add(j)
                stack.append(j)
    return tuple(i in seen for i in range(k))


def _move_walls(data: np.ndarray, fraction: float, rng: np.random.Generator) -> np.ndarray:
    """Move ``fraction`` of the occupied cells to a random 8-neighbour that is free."""
    out = data.copy()
    r, c = np.nonzero(out == OCCUPIED)
    if fraction <= 0 or r.size == 0:
        return out
    pick = rng.choice(r.size, size=int(round(fraction * r.size)), replace=False)
    dr = rng.integers(-1, 2, pick.size)
    dc = rng.integers(-1, 2, pick.size)
    nr = np.clip(r[pick] + dr, 0, out.shape[0] - 1)
    nc = np.clip(c[pick] + dc, 0, out.shape[1] - 1)
    ok = out[nr, nc] == 0
    out[r[pick][ok], c[pick][ok]] = 0
    out[nr[ok], nc[ok]] = OCCUPIED
    return out


def _draw(rng: np.random.Generator, lo: int, hi: int, top: int) -> int:
    """A whole number in ``[lo, hi]`` clipped to ``[0, top]`` (``lo`` when the range is empty)."""
    lo, hi = min(max(int(lo), 0), top), min(max(int(hi), 0), top)
    return int(rng.integers(lo, max(hi, lo) + 1))


def _crop_case(spec: CaseSpec, world: OccupancyGrid, config: BenchConfig) -> Case:
    rng = np.random.default_rng(spec.seed)
    data = world.data
    known = data >= 0
    r, c = np.nonzero(known)
    kh, kw = r.max() - r.min() + 1, c.max() - c.min() + 1
    side = int(np.clip(round(config.crop_fraction * min(kh, kw)), 120, 600))
    side = min(side, world.rows, world.cols)
    min_occ = max(200, int(0.004 * side * side))
    k = spec.robots

    def window_mask(r0, c0):
        m = np.zeros(known.shape, bool)
        m[r0:r0 + side, c0:c0 + side] = True
        return m & known

    def usable(r0, c0):
        w = data[r0:r0 + side, c0:c0 + side]
        return int((w == OCCUPIED).sum()) >= min_occ and int((w >= 0).sum()) >= 0.15 * side * side

    for _ in range(20):
        wins, masks = [], []
        for _ in range(400):
            if not wins:
                r0 = _draw(rng, r.min() - side // 4, r.max() - 3 * side // 4, world.rows - side)
                c0 = _draw(rng, c.min() - side // 4, c.max() - 3 * side // 4, world.cols - side)
                if usable(r0, c0):
                    wins.append((r0, c0))
                    masks.append(window_mask(r0, c0))
                continue
            pr, pc = wins[int(rng.integers(len(wins)))]
            span = int(side * (1 - config.min_overlap))
            r0 = int(np.clip(pr + rng.integers(-span, span + 1), 0, world.rows - side))
            c0 = int(np.clip(pc + rng.integers(-span, span + 1), 0, world.cols - side))
            if (r0, c0) in wins or not usable(r0, c0):
                continue
            m = window_mask(r0, c0)
            parent = masks[wins.index((pr, pc))]
            ov = int((m & parent).sum()) / max(1, min(int(m.sum()), int(parent.sum())))
            if not config.min_overlap <= ov <= config.max_overlap:
                continue
            wins.append((r0, c0))
            masks.append(m)
            if len(wins) == k:
                break
        if len(wins) == k:
            break
    else:
        raise InputError(f"{spec.world.name}: could not cut {k} overlapping windows of {side} cells "
                         f"with enough walls; use a larger map or fewer robots")
    grids, truth = [], []
    for n, (r0, c0) in enumerate(wins):
        cells = _move_walls(data[r0:r0 + side, c0:c0 + side], config.cell_noise, rng)
        corner = world.cell_to_world(r0 - 0.5, c0 - 0.5)
        win = OccupancyGrid(cells, world.resolution, (float(corner[0]), float(corner[1]), world.origin[2]))
        theta = float(rng.uniform(-math.pi, math.pi))
        centre = world.cell_to_world(r0 + side / 2 - 0.5, c0 + side / 2 - 0.5)
        off = rng.uniform(-5.0, 5.0, 2)
        # own frame: the window's centre near (off), turned by theta
        own_to_world = Transform2D(float(centre[0]), float(centre[1]), theta) @ Transform2D(
            float(-off[0]), float(-off[1]), 0.0)
        canvas = canvas_for([win], [own_to_world.inverse], world.resolution)
        g = resample(win, own_to_world.inverse, canvas)
        grids.append(g.with_data(g.data, name=f"crop_{n + 1}"))
        truth.append(own_to_world)
    ov = _overlaps(masks)
    return Case(spec, world, tuple(grids), tuple([None] * k), tuple(truth), ov,
                _linked(ov, config.min_overlap, grids))


def _explore_case(spec: CaseSpec, world: OccupancyGrid, config: BenchConfig) -> Case:
    from .simulate import LidarConfig, MotionConfig, SimulationConfig, simulate
    best = None
    for attempt in range(4):
        cfg = SimulationConfig(robots=spec.robots, poses=config.poses, seed=spec.seed + 7919 * attempt,
                               lidar=LidarConfig(range_noise=config.range_noise),
                               motion=MotionConfig(drift_xy=config.drift, drift_theta=config.drift_theta))
        sim = simulate(world, cfg)
        masks = [resample(r.grid, r.transform, world).known_mask() & world.known_mask()
                 for r in sim.robots]
        ov = _overlaps(masks)
        linked = _linked(ov, config.min_overlap, [r.grid for r in sim.robots])
        if best is None or sum(linked) > sum(best[2]):
            best = (sim, ov, linked)
        if all(linked):
            break
    sim, ov, linked = best
    return Case(spec, world, tuple(r.grid for r in sim.robots), tuple(r.scans for r in sim.robots),
                tuple(r.transform for r in sim.robots), ov, linked)


def make_case(spec: CaseSpec, config: BenchConfig) -> Case:
    """Build the maps, scans and truth of one case."""
    world = load_world(spec.world)
    if spec.mode == "crop":
        return _crop_case(spec, world, config)
    return _explore_case(spec, world, config)


# -- running --------------------------------------------------------------------------------------

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
    from .fusion import fuse_maps
    from .metrics import evaluate_map
    from .pipeline import MergeConfig, merge

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
            seconds = time.perf_counter() - t1
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


def _run_one(config, task):
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
    records = ex.map(_run_one, tasks, shared=config, progress=tick)
    showcase = records[show].pop("_grids", None)
    if showcase is not None:
        showcase["index"] = show
    return BenchResult(config, tuple(worlds), tuple(skipped), tuple(records), showcase,
                       time.perf_counter() - t0, command)


# -- summaries ------------------------------------------------------------------------------------

def _median(values) -> float | None:
    v = [x for x in values if x is not None]
    return round(float(statistics.median(v)), 4) if v else None


def _bin_label(ov: float) -> str:
    edges = list(OVERLAP_BINS) + [1.0001]
    for lo, hi in zip(edges[:-1], edges[1:]):
        if lo <= ov < hi:
            return f"{lo:.2f}-{min(hi, 1.0):.2f}"
    return "?"


def _tally(entries) -> dict:
    linked = [e for e in entries if e["linked"]]
    n = len(linked)
    succ = sum(e["status"] == "success" for e in linked)
    wrong = sum(e["status"] == "wrong" for e in entries)
    refused = sum(e["status"] == "refused" for e in linked)
    return {"pairs": n, "success": succ, "wrong": wrong, "refused": refused,
            "success_rate": round(100.0 * succ / n, 1) if n else None,
            "unlinked": len(entries) - n,
            "unlinked_refused": sum(e["status"] == "refused" for e in entries if not e["linked"])}


def summarize(result: BenchResult) -> dict:
    """Per-method totals and the breakdowns by world, mode, K and overlap."""
    methods = result.config.methods
    summary = {"methods": {}, "by": {"world": {}, "mode": {}, "robots": {}, "overlap": {}}}
    for m in methods:
        entries, times, t1, errs = [], [], [], 0
        for rec in result.cases:
            r = rec["methods"][m]
            for e in r["maps"]:
                entries.append(dict(e, world=rec["world"], mode=rec["mode"], robots=rec["robots"]))
            times.append(r["seconds_per_pair"])
            if r["table1"] is not None:
                t1.append(r["table1"])
            errs += bool(r["error"])
        tally = _tally(entries)
        merged = [e for e in entries if e["status"] != "refused"]
        tally.update(
            median_rot_err_deg=_median(e["rot_err_deg"] for e in merged),
            median_trans_err_cells=_median(e["trans_err_cells"] for e in merged),
            median_rot_err_success_deg=_median(e["rot_err_deg"] for e in merged if e["status"] == "success"),
            median_trans_err_success_cells=_median(e["trans_err_cells"] for e in merged
                                                   if e["status"] == "success"),
            median_seconds_per_pair=_median(times),
            errors=errs,
            table1={k: _median(t[k] for t in t1) for k in ("completeness", "accuracy", "precision",
                                                            "efficiency", "precision_tol1")})
        summary["methods"][m] = tally
        for key, fn in (("world", lambda e: e["world"]), ("mode", lambda e: e["mode"]),
                        ("robots", lambda e: f"K={e['robots']}"),
                        ("overlap", lambda e: _bin_label(e["overlap"]))):
            groups: dict = {}
            for e in entries:
                groups.setdefault(fn(e), []).append(e)
            for g, es in sorted(groups.items()):
                summary["by"][key].setdefault(g, {})[m] = _tally(es)
    oracle = [rec["oracle"] for rec in result.cases]
    summary["oracle_table1"] = {k: _median(t[k] for t in oracle) for k in (
        "completeness", "accuracy", "precision", "efficiency", "precision_tol1")}
    return summary


def _fmt(v, suffix="") -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.2f}{suffix}" if abs(v) < 100 else f"{v:.1f}{suffix}"
    return f"{v}{suffix}"


def _pct(v) -> str:
    return "-" if v is None else f"{v:.1f}%"


def format_table(result: BenchResult, summary: dict | None = None) -> str:
    """The main per-method table (markdown)."""
    s = summary or summarize(result)
    head = ("| method | pairs | success | wrong merges | refusals | median rot err (deg) | "
            "median trans err (cells) | Compl | Acc | Prec | Eff | median s / pair |")
    lines = [head, "|" + "---|" * 12]
    for m, t in s["methods"].items():
        t1 = t["table1"]
        lines.append(
            f"| {m} | {t['pairs']} | {t['success']} ({_pct(t['success_rate'])}) | {t['wrong']} | "
            f"{t['refused']} | {_fmt(t['median_rot_err_deg'])} | {_fmt(t['median_trans_err_cells'])} | "
            f"{_fmt(t1['completeness'])} | {_fmt(t1['accuracy'])} | {_fmt(t1['precision'])} | "
            f"{_fmt(t1['efficiency'])} | {_fmt(t['median_seconds_per_pair'])} |")
    o = s["oracle_table1"]
    lines.append(f"| oracle (true transforms) | | | | | | | {_fmt(o['completeness'])} | "
                 f"{_fmt(o['accuracy'])} | {_fmt(o['precision'])} | {_fmt(o['efficiency'])} | |")
    return "\n".join(lines)


def format_markdown(result: BenchResult, summary: dict | None = None) -> str:
    """The whole report: settings, main table, breakdowns, unlinked maps."""
    s = summary or summarize(result)
    cfg = result.config
    modes = {}
    for rec in result.cases:
        modes[rec["mode"]] = modes.get(rec["mode"], 0) + 1
    lines = [
        "# fusionkit bench",
        "",
        f"{len(result.cases)} cases ({', '.join(f'{n} {m}' for m, n in modes.items())}) on "
        f"{len(result.worlds)} worlds ({', '.join(w.name for w in result.worlds)}); K = "
        f"{', '.join(str(k) for k in cfg.robots)} maps per case; pair overlap >= {cfg.min_overlap:g}; "
        f"seed {cfg.seed}; wall time {result.seconds:.0f} s.",
        "",
    ]
    if result.command:
        lines += ["Command:", "", "```", result.command, "```", ""]
    if result.skipped:
        lines += ["Maps not used: " + "; ".join(f"{n} ({w})" for n, w in result.skipped) + ".", ""]
    lines += [
        f"A pair is a non-reference map of a case. Success: merged with rotation error < "
        f"{cfg.max_rotation_deg:g} deg and its known-cell centroid < {cfg.max_cells:g} cells from "
        f"the truth; wrong merge: merged outside those bounds; refusal: not merged. Median errors "
        f"over merged pairs; Table 1 metrics (%) are medians over cases of the fused map against "
        f"the world; time is a merge's wall time over K - 1.",
        "",
        format_table(result, s),
        "",
    ]
    for key, title in (("mode", "By mode"), ("robots", "By number of maps"),
                       ("overlap", "By overlap of the pair"), ("world", "By world")):
        lines += [f"## {title}", "",
                  "| " + key + " | " + " | ".join(cfg.methods) + " |",
                  "|---|" + "---|" * len(cfg.methods)]
        for g, per in s["by"][key].items():
            cells = []
            for m in cfg.methods:
                t = per.get(m)
                if t is None or t["pairs"] == 0:
                    cells.append("-")
                else:
                    cells.append(f"{t['success']}/{t['pairs']} ({_pct(t['success_rate'])}), "
                                 f"{t['wrong']} wrong")
            if any(c != "-" for c in cells):
                lines.append(f"| {g} | " + " | ".join(cells) + " |")
        lines.append("")
    unl = {m: (t["unlinked"], t["unlinked_refused"]) for m, t in s["methods"].items()}
    if any(u for u, _ in unl.values()):
        lines += ["Maps that no overlap >= the minimum links to the reference, or that hold no walls "
                  "(right answer: refuse): "
                  + ", ".join(f"{m} refused {r} of {u}" for m, (u, r) in unl.items()) + ".", ""]
    errs = {m: t["errors"] for m, t in s["methods"].items() if t["errors"]}
    if errs:
        lines += ["Merges that raised an error (counted as refusals): "
                  + ", ".join(f"{m} {n}" for m, n in errs.items()) + ".", ""]
    return "\n".join(lines)


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o).__name__)


def _render(path: Path, showcase: dict, method: str, record: dict) -> None:
    """One picture of the showcase case for ``method``: its fused map placed in the world by
    the reference's true transform, over the world's walls."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap

    w = showcase["world"]
    world = OccupancyGrid(w["data"], w["resolution"], tuple(w["origin"]))
    f = showcase["fused"][method]
    fused = OccupancyGrid(f["data"], f["resolution"], tuple(f["origin"]))
    placed = resample(fused, Transform2D.from_dict(showcase["ref_true"]), world).data
    img = np.zeros(world.shape, np.int8)                # 0 unknown in both
    img[world.data >= 0] = 1                            # world known
    img[placed == 0] = 2                                # fused free
    img[world.data >= 50] = 3                           # world walls
    img[placed >= 50] = 4                               # fused walls
    img[(placed >= 50) & (world.data >= 50)] = 5        # fused walls on world walls
    known = np.nonzero((world.data >= 0) | (placed >= 0))
    r0, r1 = known[0].min(), known[0].max() + 1
    c0, c1 = known[1].min(), known[1].max() + 1
    cmap = ListedColormap(["#d0d0d0", "#f4f4f4", "#ffffff", "#9ab0d8", "#d62728", "#1a1a1a"])
    fig, ax = plt.subplots(figsize=(7, 7 * (r1 - r0) / max(c1 - c0, 1) + 0.8))
    ax.imshow(img[r0:r1, c0:c1], origin="lower", cmap=cmap, vmin=-0.5, vmax=5.5, interpolation="nearest")
    st = [f"map {e['map'] + 1} {e['status']}" for e in record["maps"]]
    ax.set_title(f"{method}: case {showcase['index']} ({record.get('world', '')}; the same case for "
                 f"every method)\n{', '.join(st)}\nblack: walls on the truth, red: walls off "
                 f"the truth, blue: truth walls not mapped", fontsize=9)
    ax.set_xticks([])
    ax.set_yticks([])
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=90)
    plt.close(fig)


def write_outputs(result: BenchResult, out_dir: str | os.PathLike, summary: dict | None = None) -> list[Path]:
    """Write ``bench.md``, ``bench.json`` and ``bench_<method>.png`` into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    s = summary or summarize(result)
    paths = [out / "bench.md", out / "bench.json"]
    write_text_atomic(paths[0], format_markdown(result, s) + "\n")
    doc = {"config": asdict(result.config), "command": result.command,
           "worlds": [asdict(w) for w in result.worlds], "skipped": [list(x) for x in result.skipped],
           "seconds": round(result.seconds, 2), "summary": s, "cases": list(result.cases)}
    write_text_atomic(paths[1], json.dumps(doc, indent=1, default=_json_default) + "\n")
    if result.showcase is not None:
        rec = dict(result.cases[result.showcase["index"]])
        for m in result.config.methods:
            p = out / f"bench_{m}.png"
            _render(p, result.showcase, m, dict(rec["methods"][m], world=rec["world"]))
            paths.append(p)
    return paths
