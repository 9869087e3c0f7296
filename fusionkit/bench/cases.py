"""Case making: the worlds (ground-truth maps, and real laser logs) and the seeded cases drawn
from them (``explore``: simulated robots; ``crop``: turned and shifted windows; ``log``: a log
split into sessions).
"""

from __future__ import annotations

import math
import os
import zlib
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Sequence

import numpy as np

from .._validate import names
from ..errors import FusionkitError, InputError
from ..grid import OCCUPIED, OccupancyGrid
from ..io_carmen import NO_RETURN_FREE, RESOLUTION, SPLIT_OVERLAP
from ..resample import canvas_for, resample
from ..transform import Transform2D
from .config import MIN_MAP_WALLS, MIN_WORLD_OCCUPIED, BenchConfig

__all__ = ["WorldSpec", "CaseSpec", "Case", "find_worlds", "find_logs", "plan_cases", "make_case",
           "LOG_SPLIT"]

#: How a log is cut into sessions and mapped (``fusionkit import carmen --split K``'s defaults):
#: consecutive sessions share this fraction of their length; cells of this size (m); a beam
#: without a return clears nothing
LOG_SPLIT = {"overlap": SPLIT_OVERLAP, "resolution": RESOLUTION, "no_return_free": NO_RETURN_FREE}


@dataclass(frozen=True)
class WorldSpec:
    """A ground-truth map: a map file (``path``) or a built-in world (``builtin`` name); or a
    CARMEN laser log (``log``), whose world is the map of the whole log."""

    name: str
    path: str | None = None
    builtin: str | None = None
    log: str | None = None


#: Worlds handed to this process with the cases (:func:`given_worlds`), by spec
_GIVEN: dict = {}


def given_worlds(worlds: dict) -> None:
    """Have :func:`load_world` answer the specs of ``worlds`` (``{WorldSpec: grid}``, and
    :func:`load_log` ``{WorldSpec: ScanLog}`` for logs) with what is given: a worker on another
    machine need not hold the map or log files at the same path."""
    global _GIVEN
    _GIVEN = worlds


def load_world(spec: WorldSpec) -> OccupancyGrid:
    """The world's grid in its three states (cached per process; a world handed over by
    :func:`given_worlds` is not read again)."""
    given = _GIVEN.get(spec) if spec.log is None else None
    return given if given is not None else _load_world(spec)


def load_log(spec: WorldSpec):
    """The scans of a log world (a :class:`~fusionkit.scanlog.ScanLog` in the log's frame; cached
    per process; a log handed over by :func:`given_worlds` is not read again)."""
    given = _GIVEN.get(spec)
    return given if given is not None else _load_log(spec.log)


@lru_cache(maxsize=64)
def _load_log(path: str):
    from ..io_carmen import read_carmen
    return read_carmen(path).scans


def _log_mapping():
    from ..io_carmen import mapping_config
    return mapping_config(LOG_SPLIT["resolution"], LOG_SPLIT["no_return_free"])


def _log_grid(scans, name: str) -> OccupancyGrid:
    from ..mapping import build_grid
    return build_grid(scans, _log_mapping(), name=name)


@lru_cache(maxsize=32)
def _load_world(spec: WorldSpec) -> OccupancyGrid:
    if spec.log is not None:
        g = _log_grid(load_log(spec), spec.name)
    elif spec.builtin is not None:
        from ..worlds import make_world
        g = make_world(spec.builtin, 0)
    else:
        from ..mapio import load_map
        g = load_map(spec.path)
    return g.with_data(g.trinary(), name=spec.name)


def _usable(g: OccupancyGrid) -> str:
    """Why a world cannot be used ("" when it can)."""
    occ = int(g.occupied_mask().sum())
    if occ < MIN_WORLD_OCCUPIED:
        return (f"only {occ} occupied cell{'' if occ == 1 else 's'}, needs {MIN_WORLD_OCCUPIED}"
                f"; walls drawn in grey may fall short of the map's occupied_thresh")
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
    from ..worlds import WORLDS
    worlds, skipped = [], []
    seen = set()
    folders, builtin = names(folders), names(builtin)
    for folder in folders:
        d = Path(folder)
        if not d.is_dir():
            raise InputError(f"{d}: is a file, not a folder of ground-truth maps" if d.is_file() else
                             f"{d}: is not a folder; give a folder of ground-truth maps" if d.exists()
                             else f"{d}: no such folder of ground-truth maps")
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


def find_logs(paths: Sequence[str | os.PathLike], taken: Sequence[str] = ()) -> tuple[list, list]:
    """The CARMEN logs among ``paths`` (files, or folders whose ``*.log`` files are taken,
    sorted), each read once to check it; a log given twice (by two paths, or in a folder given
    too) is taken once. Returns ``(worlds, skipped)`` as :func:`find_worlds` does: a
    :class:`WorldSpec` per readable log, named by its file name up to the first dot
    (``intel.gfs.log`` -> ``intel``; ``intel (log)`` when a world of ``taken`` or another log
    has that name), and ``(name, reason)`` for the logs of a folder that cannot be used (not a
    CARMEN log, fewer than 20 scans, or a map of the whole log that would not do as a world of
    :func:`find_worlds`).

    Raises
    ------
    InputError
        A path that does not exist or is no file nor folder, a folder without a ``*.log``
        file, or a log named on its own that cannot be used (one line naming it).
    """
    files = []
    for p in map(Path, paths):
        if p.is_dir():
            found = sorted(p.glob("*.log"))
            if not found:
                raise InputError(f"{p}: the folder holds no CARMEN log (*.log); give log files or "
                                 f"a folder of them")
            files += [(f, False) for f in found]
        elif p.is_file():
            files.append((p, True))
        elif p.exists():
            raise InputError(f"{p}: is not a regular file; give a CARMEN log file or a folder of them")
        else:
            raise InputError(f"{p}: no such CARMEN log or folder of logs")
    unique: dict = {}
    for f, named in files:
        first, was = unique.get(os.path.realpath(f), (f, False))
        unique[os.path.realpath(f)] = (first, was or named)
    worlds, skipped, seen = [], [], set(taken)
    for f, named in unique.values():
        name = base = f.name.split(".")[0] or f.name
        n = 1
        while name in seen:
            name = f"{base} (log)" if n == 1 else f"{base} (log {n})"
            n += 1
        spec = WorldSpec(name, log=str(f))
        try:
            scans = load_log(spec)
            # the map of the whole log is the world: as usable as a world of maps must be
            why = (f"only {scans.n_scans} scans, needs 20" if scans.n_scans < 20
                   else _usable(load_world(spec)))
        except FusionkitError as exc:
            why = str(exc)
        if why and named:
            raise InputError(why if why.startswith(str(f)) else f"{f}: {why}")
        if why:
            skipped.append((name, why))
            continue
        worlds.append(spec)
        seen.add(name)
    return worlds, skipped


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
    """The suite: ``config.cases`` cases of the maps, case ``i`` taking map world ``i mod W``,
    mode ``(i // W) mod M`` and K ``(i + i // (W M)) mod R`` (so every world meets every mode
    and K as the suite grows); then every log world split into each K of ``config.robots``, one
    case each (mode ``log``). A map case's seed is drawn from the suite's seed and its index, a
    log case's from the suite's seed, the log's name and K."""
    maps = [w for w in worlds if w.log is None]
    logs = [w for w in worlds if w.log is not None]
    W, M, R = len(maps), len(config.modes), len(config.robots)
    todo = [(maps[i % W], config.modes[(i // W) % M], config.robots[(i + i // (W * M)) % R],
             (config.seed, i)) for i in range(config.cases if maps else 0)]
    # a log case's seed is drawn from the log's name and K: the same whatever else the suite holds
    todo += [(w, "log", k, (config.seed, zlib.crc32(w.name.encode()), k, 1))
             for w in logs for k in config.robots]
    if not todo:
        raise InputError("no case to run: give --cases 1 or more with a world to draw them from, "
                         "or logs to split (--logs)")
    return [CaseSpec(i, w, mode, k, int(np.random.SeedSequence(list(key)).generate_state(1)[0] % 2**31))
            for i, (w, mode, k, key) in enumerate(todo)]


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
    from ..simulate import LidarConfig, MotionConfig, SimulationConfig, simulate
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


def _log_case(spec: CaseSpec, world: OccupancyGrid, config: BenchConfig) -> Case:
    """The log cut into K sessions, each mapped in its own start frame with its recorded scans,
    as ``fusionkit import carmen --split K`` writes them; the truth is where each session's
    first pose lies in the log's frame (the world's)."""
    from ..io_carmen import session_maps
    _, scans, grids, truth = zip(*session_maps(load_log(spec.world), spec.robots,
                                               LOG_SPLIT["overlap"], _log_mapping()))
    masks = [resample(g, t, world).known_mask() & world.known_mask() for g, t in zip(grids, truth)]
    ov = _overlaps(masks)
    return Case(spec, world, grids, scans, truth, ov, _linked(ov, config.min_overlap, grids))


def make_case(spec: CaseSpec, config: BenchConfig) -> Case:
    """Build the maps, scans and truth of one case."""
    world = load_world(spec.world)
    if spec.mode == "log":
        return _log_case(spec, world, config)
    if spec.mode == "crop":
        return _crop_case(spec, world, config)
    return _explore_case(spec, world, config)
