"""The maps a merge is given: loaded from files, each once, brought to the reference's cell
size, and the words for a map no method can place."""

from __future__ import annotations

import math
import os
from typing import Sequence

import numpy as np

from .errors import InputError
from .grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from .mapping import MAX_CELLS
from .resample import canvas_for, resample, transformed_bounds
from .scanlog import ScanLog, load_scans, scans_path_for
from .transform import Transform2D

__all__ = ["load_inputs", "scans_misfit", "check_scans", "scans_labels"]


def load_inputs(paths: Sequence[str | os.PathLike]) -> tuple[list[OccupancyGrid], list[ScanLog | None]]:
    """Load maps (ROS map_server YAML) and, where ``NAME.scans.npz`` stands beside, their scans."""
    from .mapio import load_map

    _once(paths)
    grids, scans = [], []
    for p in paths:
        grids.append(load_map(p))
        sp = scans_path_for(p)
        try:
            scans.append(load_scans(sp) if sp.is_file() else None)
        except InputError as e:   # the scans are optional: say the other way out too
            raise InputError(f"{e}; or move it away from {os.path.basename(p)}: a map without "
                             f"scans is placed by its walls") from None
    return grids, scans


def _once(paths) -> None:
    """Refuse a map file given twice (by one path or two: a link, ``a/../a``): a map merged
    with itself is placed on itself, and the report would list one input twice."""
    seen: dict = {}
    for k, p in enumerate(paths):
        try:
            st = os.stat(p)
        except OSError:
            continue  # the loader says what is wrong with it
        first = seen.setdefault((st.st_dev, st.st_ino), k)
        if first != k:
            same = "" if os.fspath(paths[first]) == os.fspath(p) else f" (as {paths[first]})"
            raise InputError(f"{p}: the same map file is given twice{same}, as maps {first + 1} "
                             f"and {k + 1}; give each map once")
    # two YAML files naming one image are one map (merged with itself, it is placed on itself)
    from .mapio import _protected

    images: dict = {}
    for k, p in enumerate(paths):
        for image in _protected([p])[1:]:
            try:
                st = os.stat(image)
            except OSError:
                continue
            first = images.setdefault((st.st_dev, st.st_ino), k)
            if first != k:
                raise InputError(f"{paths[first]} and {p} (maps {first + 1} and {k + 1}) name "
                                 f"the same image {image}: they are one map; give it once")


def _same_resolution(grids: list[OccupancyGrid], ref: int) -> list[OccupancyGrid]:
    """Resample every grid to the reference's resolution (nearest neighbour)."""
    res = grids[ref].resolution
    out = []
    for g in grids:
        if abs(g.resolution - res) <= 1e-9 * res and g.data.size:
            out.append(g)
            continue
        if not g.known_mask().any():
            # nothing to resample (and no extent worth cells), or no cell at all (an empty image
            # crashed OpenCV's morphology in the consensus method): one unknown cell at the
            # reference's cell size, which the method refuses with its reason
            out.append(OccupancyGrid(np.full((1, 1), UNKNOWN, np.int8), res, g.origin, g.name))
            continue
        x0, y0, x1, y1 = transformed_bounds(g, Transform2D.identity())
        rows, cols = math.ceil((y1 - y0) / res), math.ceil((x1 - x0) / res)
        if rows * cols > MAX_CELLS:
            raise InputError(f"{g.name or 'a map'}: at the reference map's {res:g} m cells this "
                             f"map of {g.resolution:g} m cells would be {rows} x {cols} cells, more "
                             f"than the {MAX_CELLS} fusionkit can hold; choose a coarser map as "
                             "the reference, or crop this one")
        canvas = canvas_for([g], [Transform2D.identity()], res, margin_cells=0)
        moved = resample(g, Transform2D.identity(), canvas)
        if g.resolution < res:
            moved = _keep_walls(g, moved)
        out.append(moved)
    return out


#: The finest cell size the default method compares maps at, as a share of the reference's:
#: half (the reference's map 4 times the cells). Finer still, the maps are compared at the
#: reference's cell size: a 0.25 m campus as the reference of a 0.03 m window, at the window's
#: cells (69 times as many), took 22 s and 6.1 GB instead of 2.2 s and 0.3 GB.
FINEST_SHARE = 0.5


def _compared(originals: list[OccupancyGrid], at_reference: list[OccupancyGrid],
              ref: int) -> list[OccupancyGrid]:
    """The maps as the default method compares them: at the finest cell size of the maps with
    walls, down to half the reference's, so that no map loses detail and the decision depends
    less on which map is the reference (a small window of a 0.05 m map, brought to the cells of
    a 0.1 m reference, kept too few walls and was refused, where with the window as the
    reference the two were merged). ``at_reference`` (the maps at the reference's cell size,
    which they are fused at) is given back when that is the finest, when the finest is under
    half of it, or when the maps at the finest would be more cells than fusionkit holds."""
    usable = [k for k, g in enumerate(originals) if g.occupied_mask().any()]
    finest = min(usable, key=lambda k: originals[k].resolution, default=ref)
    res, ref_res = originals[finest].resolution, originals[ref].resolution
    if res >= ref_res * (1 - 1e-9) or res < FINEST_SHARE * ref_res * (1 - 1e-9):
        return at_reference
    try:
        return _same_resolution(originals, finest)
    except InputError:
        return at_reference


def _keep_walls(fine: OccupancyGrid, sampled: OccupancyGrid) -> OccupancyGrid:
    """``sampled`` (``fine`` at coarser cells, each the fine cell under its centre) with every
    coarse cell that holds a fine wall cell occupied, and every one that holds a known cell
    known: a wall one fine cell thick fell between the centres and broke up, so that a map
    finer than the reference was refused where, given first, it was placed."""
    tri = fine.trinary()
    r, c = np.nonzero(tri != UNKNOWN)
    rows, cols = sampled.world_to_cell(fine.cell_to_world(r, c))
    ri, ci = np.floor(rows).astype(np.int64), np.floor(cols).astype(np.int64)
    inside = (ri >= 0) & (ri < sampled.rows) & (ci >= 0) & (ci < sampled.cols)
    rank = np.zeros(sampled.shape, np.int8)            # 0 unknown, 1 free, 2 wall
    np.maximum.at(rank, (ri[inside], ci[inside]), np.where(tri[r, c] == OCCUPIED, 2, 1)[inside])
    data = np.array(sampled.data)
    data[(rank == 1) & (data == UNKNOWN)] = FREE
    data[rank == 2] = OCCUPIED
    return OccupancyGrid(data, sampled.resolution, sampled.origin, sampled.name)


def _unusable(grid: OccupancyGrid) -> str:
    """Why no method can place ``grid`` (the same words whatever the method), or ``""``."""
    if not grid.known_mask().any():
        return "it holds no known cell (all unknown): nothing to place it by"
    if not grid.occupied_mask().any():
        return "it holds no wall (occupied cell) to place it by"
    return ""


#: Scans are refused as another map's when fewer of their end points on the map's known cells
#: fall on or beside its walls than this share and than SCAN_FIT_LIFT times chance. A map's own
#: scans: 68-100 % and 6-37 times chance (the four real logs split into three sessions each, the
#: simulated demo run); another session's or robot's: 1-32 % and 0.3-2.7 times chance.
SCAN_FIT_SHARE = 0.4
SCAN_FIT_LIFT = 3.0


def scans_misfit(grid: OccupancyGrid, log: ScanLog, *, scans: int = 200) -> str:
    """Why ``log`` cannot be ``grid``'s own scans (its end points miss the map's walls), or ""."""
    from scipy.ndimage import binary_dilation

    known = grid.known_mask()
    if log.n_scans == 0 or not known.any() or not grid.occupied_mask().any():
        return ""                      # nothing to judge them by: the map's own reason is said
    idx = np.unique(np.linspace(0, log.n_scans - 1, min(scans, log.n_scans)).round().astype(np.int64))
    pts = log.endpoints(idx)
    if len(pts) == 0:
        return ""                      # no beam returned: nothing to judge them by
    rows, cols = grid.world_to_cell(pts)
    r, c = np.floor(rows).astype(np.int64), np.floor(cols).astype(np.int64)
    inside = (r >= 0) & (r < grid.rows) & (c >= 0) & (c < grid.cols)
    r, c = r[inside], c[inside]
    on_known = known[r, c]
    near_wall = binary_dilation(grid.occupied_mask(), np.ones((3, 3), bool))
    if on_known.sum() < 50:
        return (f"{int(on_known.sum())} of its {len(pts)} scan end points (of {len(idx)} scans) "
                f"fall on the map's known cells")
    share = float(near_wall[r, c][on_known].mean())
    chance = float(near_wall[known].mean())
    if share >= SCAN_FIT_SHARE or share >= SCAN_FIT_LIFT * chance:
        return ""
    return (f"{100 * share:.0f}% of its scan end points on the map's known cells fall on or "
            f"beside a wall, where {100 * chance:.0f}% would by chance")


def scans_labels(paths) -> list[str]:
    """How an error names the scan log of each map file: its path and its map's."""
    return [f"{scans_path_for(p)} (the scans of {os.fspath(p)})" for p in paths]


def check_scans(grids, scans, labels) -> None:
    """Refuse, naming it by ``labels``, a scan log that is not its map's own
    (:func:`scans_misfit`)."""
    for grid, log, label in zip(grids, scans, labels):
        why = scans_misfit(grid, log) if log is not None else ""
        if why:   # another robot's scans, or scans of another frame, used without a word
            raise InputError(f"{label}: {why}: these are not this map's scans; give its own, or "
                             f"none (a map without scans is placed by its walls)")
