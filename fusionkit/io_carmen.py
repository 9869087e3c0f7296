"""CARMEN laser logs turned into fusionkit robot logs and maps (CONTRACTS sections 3 and 5).

Reading the log is :mod:`fusionkit.carmen_read` (:func:`read_carmen`, re-exported here, with
the format's notes). Here: poses re-expressed in the frame of the first scan (that robot's own
map frame: the first pose becomes ``(0, 0, 0)``), a log cut into overlapping sessions, and the
files written (each robot's files as one set, a split as one set with ``truth.json`` last).
"""

from __future__ import annotations

from numbers import Integral

import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from ._atomic import (_journal_path, check_not_input, check_out_dir, hidden_copies, made_out_dir,
                      recover_set, write_set)
from .carmen_read import (NO_RETURN_BAND, CarmenConfig, CarmenLog, CarmenStats,  # noqa: F401
                          flaser_geometry, read_carmen)
from ._validate import number
from .errors import InputError
from .grid import OccupancyGrid
from .mapping import MappingConfig, build_grid
from .scanlog import ScanLog, encode_scans, scans_path_for
from .transform import Transform2D

__all__ = [
    "CarmenConfig", "CarmenStats", "CarmenLog", "ImportedMap", "CarmenImport", "read_carmen",
    "flaser_geometry", "to_own_frame", "split_sessions", "session_maps", "path_length",
    "write_robot_files", "import_carmen", "SPLIT_OVERLAP", "RESOLUTION", "NO_RETURN_FREE",
]

ProgressFn = Callable[[int, int, str], None]

_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")


@dataclass(frozen=True)
class ImportedMap:
    """One robot (or world) written by an import.

    Attributes
    ----------
    name : str
        File stem (``NAME.yaml``, ``NAME.pgm``, ``NAME.scans.npz``).
    scans : int
        Scans in the log.
    transform : Transform2D
        From this robot's map frame into the source log's frame (CONTRACTS section 4).
    path_length_m : float
        Length of the pose trajectory (m).
    shape : tuple[int, int]
        Grid size (rows, cols).
    occupied, free : int
        Cell counts of the built map.
    files : tuple[Path, ...]
        Files written.
    """

    name: str
    scans: int
    transform: Transform2D
    path_length_m: float
    shape: tuple[int, int]
    occupied: int
    free: int
    files: tuple[Path, ...]


@dataclass(frozen=True)
class CarmenImport:
    """Result of :func:`import_carmen`.

    Attributes
    ----------
    stats : CarmenStats
        What reading the log found.
    range_max : float
        ``range_max`` of the written scan logs (m).
    robots : tuple[ImportedMap, ...]
        One entry, or ``robot_1 .. robot_K`` after a split.
    world : ImportedMap or None
        The whole log's map in the log frame (written only with a split).
    truth : Path or None
        ``truth.json`` (written only with a split).
    files : tuple[Path, ...]
        Every file written.
    removed : tuple[Path, ...]
        Files of an earlier run in the folder that ``overwrite`` removed with the same write:
        its sessions the new split does not have, and the merges of its maps.
    """

    stats: CarmenStats
    range_max: float
    robots: tuple[ImportedMap, ...]
    world: ImportedMap | None
    truth: Path | None
    files: tuple[Path, ...] = field(default=())
    removed: tuple[Path, ...] = field(default=())


# -- frames and sessions --------------------------------------------------------------------------

def to_own_frame(log: ScanLog) -> tuple[ScanLog, Transform2D]:
    """Re-express ``log`` in the frame of its first pose.

    Returns
    -------
    own : ScanLog
        Same ranges; poses with the first at ``(0, 0, 0)``.
    transform : Transform2D
        From the new frame into ``log``'s frame (the first pose as a transform), so that
        ``transform.apply_pose(own.poses) == log.poses``.
    """
    t = Transform2D(*log.poses[0])
    own = ScanLog(t.inverse.apply_pose(log.poses), log.ranges, log.angle_min,
                  log.angle_increment, log.range_max)
    return own, t


def path_length(poses) -> float:
    """Length (m) of the polyline through the ``(N, 3)`` poses' positions."""
    p = np.asarray(poses, dtype=float)
    if len(p) < 2:
        return 0.0
    return float(np.hypot(*np.diff(p[:, :2], axis=0).T).sum())


#: Defaults of an import: the share of a session's length the next one shares, the cell size
#: (m), and how far (m) a beam without a return clears free space
SPLIT_OVERLAP, RESOLUTION, NO_RETURN_FREE = 0.3, 0.05, 0.0


def session_maps(log: ScanLog, k: int, overlap: float, mcfg: MappingConfig):
    """The ``k`` sessions of ``log`` (:func:`split_sessions`), each in the frame of its first
    pose and mapped: ``(name, own scans, grid, own frame -> log frame)`` per session, in order
    (``robot_1`` ... ``robot_k``)."""
    for i, (a, b) in enumerate(split_sessions(log.n_scans, k, overlap)):
        own, t = to_own_frame(log.subset(slice(a, b)))
        yield f"robot_{i + 1}", own, build_grid(own, mcfg, name=f"robot_{i + 1}"), t


def split_sessions(n_scans: int, k: int, overlap: float) -> tuple[tuple[int, int], ...]:
    """Cut ``n_scans`` consecutive scans into ``k`` stretches sharing ``overlap`` of their length.

    Each stretch has length ``L = n / ((k - 1)(1 - overlap) + 1)`` and starts ``L (1 - overlap)``
    after the previous one; the first starts at scan 0 and the last ends at the last scan.

    Returns
    -------
    tuple of (start, stop)
        Half-open scan index ranges, in time order.
    """
    if k < 1:
        raise InputError(f"the number of sessions must be >= 1, got {k}")
    if not 0.0 <= overlap < 1.0:
        raise InputError(f"overlap must be a fraction in [0, 1), got {overlap}")
    length = n_scans / ((k - 1) * (1.0 - overlap) + 1.0)
    step = length * (1.0 - overlap)
    out = []
    for i in range(k):
        start = int(round(i * step))
        stop = n_scans if i == k - 1 else min(n_scans, int(round(i * step + length)))
        out.append((start, stop))
    if min(b - a for a, b in out) < 2:
        raise InputError(f"{n_scans} scans are too few to cut into {k} sessions; "
                         f"use fewer sessions")
    return tuple(out)


# -- writing --------------------------------------------------------------------------------------

def _outputs_for(out_dir: Path, name: str) -> tuple[Path, Path, Path]:
    yaml_path = out_dir / f"{name}.yaml"
    return yaml_path, yaml_path.with_suffix(".pgm"), scans_path_for(yaml_path)


def check_outputs(paths, inputs, *, overwrite: bool) -> None:
    """Refuse to write over an input, or over an existing file unless ``overwrite``: files of
    an import killed while it put them in place are not existing ones (that import is finished
    or undone first, as the next write would)."""
    check_not_input(paths, inputs)
    paths = [Path(p) for p in paths]
    names = "|".join(re.escape(p.name) for p in paths)
    for p in paths:
        if _journal_path(p).is_file():
            recover_set(p, hidden_copies(names), paths)
    if not overwrite:
        existing = [str(p) for p in paths if p.exists()]
        if existing:
            more = f" and {len(existing) - 1} more" if len(existing) > 1 else ""
            raise InputError(f"{existing[0]}{more} already exist{'s' if not more else ''}; "
                             f"choose another output "
                             f"directory or allow overwriting (--force; overwrite=True from Python)")


def _robot_files(out_dir, name: str, log: ScanLog, grid: OccupancyGrid,
                 transform: Transform2D) -> tuple[ImportedMap, list]:
    """What :func:`write_robot_files` writes, as ``(result, [(path, bytes), ...])`` with the
    map's YAML last."""
    from .mapio import encode_map

    yaml_path, pgm_path, npz_path = _outputs_for(Path(out_dir), name)
    image, pixels, text = encode_map(grid, yaml_path)
    counts = grid.counts()
    robot = ImportedMap(name=name, scans=log.n_scans, transform=transform,
                        path_length_m=path_length(log.poses), shape=tuple(grid.shape),
                        occupied=counts["occupied"], free=counts["free"],
                        files=(npz_path, yaml_path, pgm_path))
    return robot, [(npz_path, encode_scans(log)), (image, pixels), (yaml_path, text)]


def write_robot_files(out_dir, name: str, log: ScanLog, grid: OccupancyGrid,
                      transform: Transform2D) -> ImportedMap:
    """Write ``NAME.scans.npz``, ``NAME.pgm`` and ``NAME.yaml`` as one set (the YAML is the
    commit point: on any failure or interrupt the three files are left as they were)."""
    robot, files = _robot_files(out_dir, name, log, grid, transform)
    write_set(files[:-1], files[-1])
    return robot


def mapping_config(resolution: float, no_return_free: float) -> MappingConfig:
    """The mapping settings of an import: ``resolution`` (m) and how far (m) a no-return beam
    clears free space (``0``: not at all; a dazzled scanner also reports no return)."""
    if not (math.isfinite(no_return_free) and no_return_free >= 0):
        raise InputError(f"no-return free range must be >= 0 m, got {no_return_free}")
    return MappingConfig(resolution=resolution, max_free_range=float(no_return_free))


def default_name(path) -> str:
    """A map name from a log path: the file name up to its first dot (``intel.gfs.log`` ->
    ``intel``)."""
    stem = Path(path).name.split(".")[0]
    return stem if stem and _NAME_RE.match(stem) else "robot"


def check_name(name: str) -> str:
    if not _NAME_RE.match(name or ""):
        raise InputError(f"map name {name!r} must start with a letter or digit and hold only "
                         f"letters, digits, '_', '-' or '.'")
    return name


def import_carmen(path, out_dir, *, name: str | None = None, split: int | None = None,
                  overlap: float = SPLIT_OVERLAP, resolution: float = RESOLUTION,
                  no_return_free: float = NO_RETURN_FREE,
                  config: CarmenConfig = CarmenConfig(), overwrite: bool = False,
                  progress: ProgressFn | None = None) -> CarmenImport:
    """Convert a CARMEN log into fusionkit robot logs and maps.

    Without ``split`` it writes ``NAME.scans.npz``, ``NAME.yaml`` and ``NAME.pgm`` in
    ``out_dir``, the poses in the frame of the first scan. With ``split=K`` it cuts the log
    into ``K`` consecutive sessions sharing ``overlap`` of their length and writes each as
    ``robot_k`` in its own start frame, plus ``world.yaml``/``.pgm`` (the whole log in the
    log's frame) and ``truth.json`` (CONTRACTS section 5; each robot's transform maps its frame
    into the world map's frame).

    Parameters
    ----------
    path : path-like
        CARMEN log.
    out_dir : path-like
        Output directory (created if missing).
    name : str, optional
        File stem without a split (default: the log's name up to its first dot).
    split : int, optional
        Number of sessions (>= 2 to split).
    overlap : float
        Fraction of a session shared with the next one, in ``[0, 0.9]``.
    resolution : float
        Map cell size (m).
    no_return_free : float
        Distance (m) a no-return beam marks free when building the maps (``0``: none).
    config : CarmenConfig
        Range interpretation.
    overwrite : bool
        Replace existing output files (an input is never replaced).
    progress : callable, optional
        ``progress(done, total, label)`` after each map is built and written.

    Raises
    ------
    InputError
        Unreadable or empty log, bad option values, or outputs that already exist.
    """
    if split is not None and (isinstance(split, bool) or not isinstance(split, Integral) or split < 1):
        raise InputError(f"split (--split) must be a whole number >= 1 of sessions, got {split!r}")
    overlap = number(overlap, "overlap")
    resolution = number(resolution, "resolution")
    no_return_free = number(no_return_free, "no_return_free")
    if not 0.0 <= overlap <= 0.9:
        raise InputError(f"overlap must be between 0 and 0.9, got {overlap}")
    if split is not None and split > 1 and name is not None:
        raise InputError("a split writes robot_1 .. robot_K; leave out the map name")
    mcfg = mapping_config(resolution, no_return_free)
    out_dir = check_out_dir(out_dir)
    carmen = read_carmen(path, config)
    log = carmen.scans
    split = split or 1

    if split == 1:
        nm = check_name(default_name(path) if name is None else name)
        outputs = list(_outputs_for(out_dir, nm))
        check_outputs(outputs, [path], overwrite=overwrite)
        own, t = to_own_frame(log)
        grid = build_grid(own, mcfg, name=nm)
        with made_out_dir(out_dir):
            robot = write_robot_files(out_dir, nm, own, grid, t)
        if progress:
            progress(1, 1, nm)
        return CarmenImport(carmen.stats, log.range_max, (robot,), None, None, robot.files)

    sessions = split_sessions(log.n_scans, split, overlap)
    names = [f"robot_{i + 1}" for i in range(split)]
    outputs = [p for nm in names for p in _outputs_for(out_dir, nm)]
    world_yaml = out_dir / "world.yaml"
    truth_path = out_dir / "truth.json"
    outputs += [world_yaml, world_yaml.with_suffix(".pgm"), truth_path]
    check_outputs(outputs, [path], overwrite=overwrite)

    total = split + 1
    world_grid = build_grid(log, mcfg, name="world")
    built = []
    for i, session in enumerate(session_maps(log, split, overlap, mcfg)):
        built.append(session)
        if progress:
            progress(i + 1, total, session[0])

    from .mapio import encode_map

    robots, files = [], []
    for nm, own, g, t in built:
        robot, payloads = _robot_files(out_dir, nm, own, g, t)
        robots.append(robot)
        files += payloads
    robots = tuple(robots)
    image, pixels, text = encode_map(world_grid, world_yaml)
    files += [(image, pixels), (world_yaml, text)]
    wc = world_grid.counts()
    world = ImportedMap("world", log.n_scans, Transform2D.identity(), path_length(log.poses),
                        tuple(world_grid.shape), wc["occupied"], wc["free"],
                        (world_yaml, world_yaml.with_suffix(".pgm")))
    truth = {
        "world": world_yaml.name,
        "seed": None,
        "source": str(path),
        "sessions": [{"name": nm, "first_scan": a, "last_scan": b - 1}
                     for nm, (a, b) in zip(names, sessions)],
        "robots": [{"name": r.name, "transform": r.transform.as_dict(digits=None),
                    "poses": r.scans, "path_length_m": round(r.path_length_m, 3)}
                   for r in robots],
    }
    # One set: images before the YAMLs naming them (YAMLs taken away first), truth.json last.
    files.sort(key=lambda f: f[0].suffix == ".yaml")
    # an earlier run in the folder (imported or simulated), replaced with --force: its sessions
    # the new one does not have, and the merges of its maps, go with the same commit (left,
    # they were merged with the new sessions, and scored against the new truth)
    from .sim_output import replaced_run_files

    stale = replaced_run_files(out_dir, [q for q, _ in files] + [truth_path], [path]) \
        if overwrite else []
    with made_out_dir(out_dir):
        write_set(files + [(q, None) for q in stale],
                  (truth_path, (json.dumps(truth, indent=2) + "\n").encode("utf-8")),
                  hide_first=[p for p, _ in files if p.suffix == ".yaml"])
    if progress:
        progress(total, total, "world")
    files = tuple(p for r in robots for p in r.files) + world.files + (truth_path,)
    return CarmenImport(carmen.stats, log.range_max, robots, world, truth_path, files, tuple(stale))
