"""Ground-truth worlds for the simulator: an office, a warehouse and a cave.

Each generator is seeded and returns a trinary :class:`~fusionkit.grid.OccupancyGrid`: walls
occupied, the space inside free, everything a robot can never see (outside the building, inside
shelves and rock) unknown. Every free cell is reachable from every other (doors are open).

The office reproduces the kind of building the paper simulates (its Fig. 2): a rectangular
floor of many similar rooms along corridors, the repetitive structure that makes map fusion
hard, with a few distinctive places (a hall with pillars, furniture in some rooms).

The worlds are drawn as a *solid* mask (walls, rock, shelf bodies, outside) in metres and
rasterised at the requested resolution; the solid cells that face free space (within the wall
thickness, 0.2 m) become occupied, deeper solid cells unknown.

Regenerate the default map files with::

    python -m fusionkit.worlds --out maps
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from ..errors import InputError
from ..grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from ..mapping import MAX_CELLS

__all__ = ["make_office", "make_warehouse", "make_cave", "make_world", "WORLDS",
           "DEFAULT_SIZE", "DEFAULT_RESOLUTION", "default_world"]

#: Default world size ``(width, height)`` in metres (the paper's building is about 40 x 30 m).
DEFAULT_SIZE = (40.0, 30.0)
#: Default cell size (m).
DEFAULT_RESOLUTION = 0.1
#: Thickness of walls and of the visible skin of shelves and rock (m).
WALL = 0.2
#: Unknown margin around the building (m).
MARGIN = 0.5

_MIN_SIZE = {"office": (16.0, 14.0), "warehouse": (16.0, 14.0), "cave": (10.0, 10.0)}


# ---------------------------------------------------------------------------------------------
# Rasterising helpers
# ---------------------------------------------------------------------------------------------
class _Canvas:
    """A boolean *solid* raster drawn in metres (x right, y up, origin at the lower-left corner)."""

    def __init__(self, size, resolution):
        self.res = float(resolution)
        self.width, self.height = float(size[0]), float(size[1])
        self.cols = int(round(self.width / self.res))
        self.rows = int(round(self.height / self.res))
        self.solid = np.ones((self.rows, self.cols), bool)

    def _span(self, a, b, n):
        # cells whose centres lie in [a, b); at least one cell when a < b
        lo = int(math.ceil(a / self.res - 0.5))
        hi = int(math.ceil(b / self.res - 0.5))
        if hi <= lo and b > a:
            hi = lo + 1
        return max(lo, 0), min(hi, n)

    def rect(self, x0, y0, x1, y1, solid: bool) -> None:
        """Set the axis-aligned rectangle ``[x0, x1) x [y0, y1)`` (m) solid or free."""
        c0, c1 = self._span(min(x0, x1), max(x0, x1), self.cols)
        r0, r1 = self._span(min(y0, y1), max(y0, y1), self.rows)
        self.solid[r0:r1, c0:c1] = solid

    def carve(self, x0, y0, x1, y1) -> None:
        self.rect(x0, y0, x1, y1, False)

    def fill(self, x0, y0, x1, y1) -> None:
        self.rect(x0, y0, x1, y1, True)


def _finish(solid: np.ndarray, resolution: float, name: str) -> OccupancyGrid:
    """Keep the largest free region; solid cells within the wall thickness of it are occupied,
    the rest unknown."""
    free = ~solid
    free[0, :] = free[-1, :] = False
    free[:, 0] = free[:, -1] = False
    labels, n = ndimage.label(free)  # 4-connected free regions
    if n == 0:
        raise InputError(f"the {name} world has no free space at this size and resolution; "
                         f"use a larger size or a finer resolution")
    sizes = np.bincount(labels.ravel())
    sizes[0] = 0
    free = labels == int(np.argmax(sizes))
    thick = max(1, int(round(WALL / resolution)))
    near = ndimage.binary_dilation(free, structure=np.ones((3, 3), bool), iterations=thick)
    data = np.full(solid.shape, UNKNOWN, np.int8)
    data[near & ~free] = OCCUPIED
    data[free] = FREE
    return OccupancyGrid(data, resolution, (0.0, 0.0, 0.0), name)


def _check(kind: str, size, resolution) -> tuple[tuple[float, float], float]:
    try:
        w, h = (float(v) for v in size)
    except (TypeError, ValueError):
        raise InputError(f"world size must be two numbers (width, height) in metres, got {size!r}") from None
    try:
        res = float(resolution)
    except (TypeError, ValueError):
        raise InputError(f"world resolution must be a number of metres per cell, got {resolution!r}") from None
    if not (math.isfinite(res) and 0.01 <= res <= 0.5):
        raise InputError(f"world resolution {resolution!r} m is out of range; use 0.01 to 0.5 m per cell")
    mw, mh = _MIN_SIZE[kind]
    if not (math.isfinite(w) and math.isfinite(h)) or w < mw or h < mh:
        raise InputError(f"a {kind} world must be at least {mw:g} x {mh:g} m, got {w:g} x {h:g} m; "
                         f"give a larger size")
    if (w / res) * (h / res) > MAX_CELLS:
        raise InputError(f"a {w:g} x {h:g} m world at {res:g} m per cell has more than {MAX_CELLS} "
                         f"cells; use a smaller size or a coarser resolution")
    return (w, h), res


def _rng(seed) -> np.random.Generator:
    if isinstance(seed, np.random.Generator):
        return seed
    # 2.7 was taken as 2 and "1" as 1: a seed is a whole number, as the simulation's is
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)):
        raise InputError(f"world seed must be a whole number >= 0 or a numpy Generator, "
                         f"got {seed!r}")
    if seed < 0:
        raise InputError(f"world seed must be >= 0, got {seed}")
    return np.random.default_rng(int(seed))


def _split(rng, length: float, lo: float, hi: float) -> list[float]:
    """Widths in ``[lo, hi]`` (m) that add up to ``length`` (the last absorbs the remainder)."""
    widths = []
    left = length
    while left > hi:
        w = float(rng.uniform(lo, hi))
        if left - w < lo:  # avoid a sliver at the end
            w = left / 2 if left / 2 >= lo else left
        widths.append(w)
        left -= w
    if left > 0:
        if widths and left < 0.6 * lo:
            widths[-1] += left
        else:
            widths.append(left)
    return widths


# ---------------------------------------------------------------------------------------------
# Office
# ---------------------------------------------------------------------------------------------
def make_office(seed: int = 0, size=DEFAULT_SIZE, resolution: float = DEFAULT_RESOLUTION) -> OccupancyGrid:
    """An office floor: rooms of similar size along two corridors joined at both ends.

    The floor has, from bottom to top, a row of rooms, a corridor, a double row of rooms (back
    to back), a second corridor and another row of rooms; short corridors at both ends close the
    loop. Every room has a door (0.9-1.2 m) to its corridor, some also a door to a neighbour.
    One room of the double row is a larger hall with pillars, and some rooms hold a table.

    Parameters
    ----------
    seed : int
        Seed of the layout (room widths, door places, furniture).
    size : (width, height)
        Extent of the grid (m); the building fills it but for a 0.5 m unknown margin.
    resolution : float
        Cell size (m).

    Returns
    -------
    OccupancyGrid
        Trinary grid, origin ``(0, 0, 0)``, name ``"office"``.

    Raises
    ------
    InputError
        Size below 16 x 14 m, resolution outside 0.01-0.5 m or a negative seed.
    """
    (W, H), res = _check("office", size, resolution)
    rng = _rng(seed)
    cv = _Canvas((W, H), res)
    w = WALL
    x0, x1 = MARGIN + w, W - MARGIN - w
    y0, y1 = MARGIN + w, H - MARGIN - w
    inner_h = y1 - y0
    corr = float(rng.uniform(1.8, 2.4))
    # band heights: rooms | corridor | rooms | rooms | corridor | rooms, walls between them
    avail = inner_h - 2 * corr - 5 * w
    outer = avail * float(rng.uniform(0.22, 0.26))
    outer2 = avail * float(rng.uniform(0.22, 0.26))
    mid = (avail - outer - outer2 - w) / 2  # back-to-back rooms share one wall
    yb = [y0]
    for hgt in (outer, corr, mid, mid, corr, outer2):
        yb.append(yb[-1] + hgt + w)
    # band k spans [yb[k], yb[k+1] - w)
    band = [(yb[k], yb[k + 1] - w) for k in range(6)]
    side = corr  # width of the end corridors that join the two corridors
    room_lo, room_hi = 3.2, 4.8
    door_lo, door_hi = 0.9, 1.2

    # corridors
    for k in (1, 4):
        cv.carve(x0, band[k][0], x1, band[k][1])
    for xa in (x0, x1 - side):
        cv.carve(xa, band[1][0], xa + side, band[4][1])

    def rooms_in(ya, yb_, xa, xb, door_side):
        """Rooms side by side in ``[xa, xb) x [ya, yb_)``; doors on the ``door_side`` wall
        (``"down"`` or ``"up"``)."""
        xs = [xa]
        for wd in _split(rng, xb - xa + w, room_lo + w, room_hi + w):
            xs.append(xs[-1] + wd)
        xs[-1] = xb + w
        spans = [(xs[i], xs[i + 1] - w) for i in range(len(xs) - 1)]
        for (ra, rb) in spans:
            cv.carve(ra, ya, rb, yb_)
            dw = float(rng.uniform(door_lo, door_hi))
            dx = float(rng.uniform(ra + 0.3, max(ra + 0.3, rb - 0.3 - dw)))
            if door_side == "down":
                cv.carve(dx, ya - w - 0.05, dx + dw, ya + 0.05)
            else:
                cv.carve(dx, yb_ - 0.05, dx + dw, yb_ + w + 0.05)
        # some neighbours share a door
        for i in range(len(spans) - 1):
            if rng.random() < 0.3:
                dw = float(rng.uniform(door_lo, door_hi))
                dy = float(rng.uniform(ya + 0.4, max(ya + 0.4, yb_ - 0.4 - dw)))
                xw = spans[i][1]
                cv.carve(xw - 0.05, dy, xw + w + 0.05, dy + dw)
        return spans

    all_rooms = []
    all_rooms += [(s, band[0]) for s in rooms_in(band[0][0], band[0][1], x0, x1, "up")]
    mx0, mx1 = x0 + side + w, x1 - side - w
    low = rooms_in(band[2][0], band[2][1], mx0, mx1, "down")
    all_rooms += [(s, band[2]) for s in low]
    high = rooms_in(band[3][0], band[3][1], mx0, mx1, "up")
    all_rooms += [(s, band[3]) for s in high]
    all_rooms += [(s, band[5]) for s in rooms_in(band[5][0], band[5][1], x0, x1, "down")]

    # a hall: open the wall between two back-to-back rows over a stretch and add pillars
    hall = None
    if len(low) >= 3:
        i = int(rng.integers(0, len(low) - 1))
        ha, hb = low[i][0], low[min(i + 1, len(low) - 1)][1]
        cv.carve(ha, band[2][0], hb, band[3][1])
        # the hall gets its own door on each corridor (the carved rooms' doors are kept)
        hall = (ha, band[2][0], hb, band[3][1])
        ps = 0.4
        cx = (ha + hb) / 2
        cy = (band[2][0] + band[3][1]) / 2
        for ox in (-1, 1):
            for oy in (-1, 1):
                px = cx + ox * (hb - ha) / 4
                py = cy + oy * (band[3][1] - band[2][0]) / 4
                cv.fill(px - ps / 2, py - ps / 2, px + ps / 2, py + ps / 2)

    # tables in some rooms, at least 1 m from every wall
    for (ra, rb), (ya, yb_) in all_rooms:
        if hall is not None and ra >= hall[0] - 1e-9 and rb <= hall[2] + 1e-9 and ya >= hall[1] - 1e-9:
            continue
        if rng.random() < 0.45:
            tw = min(float(rng.uniform(0.8, 1.6)), rb - ra - 2.2)
            th = min(float(rng.uniform(0.6, 0.9)), yb_ - ya - 2.2)
            if tw >= 0.4 and th >= 0.4:
                tx = float(rng.uniform(ra + 1.0, rb - 1.0 - tw))
                ty = float(rng.uniform(ya + 1.0, yb_ - 1.0 - th))
                cv.fill(tx, ty, tx + tw, ty + th)
    return _finish(cv.solid, res, "office")


# ---------------------------------------------------------------------------------------------
# Warehouse
# ---------------------------------------------------------------------------------------------
def make_warehouse(seed: int = 0, size=DEFAULT_SIZE, resolution: float = DEFAULT_RESOLUTION) -> OccupancyGrid:
    """A warehouse hall: blocks of long shelf rows with aisles, a loading area with pallets
    and pillars, and a small office in one corner.

    Parameters
    ----------
    seed : int
        Seed of the layout.
    size : (width, height)
        Extent of the grid (m).
    resolution : float
        Cell size (m).

    Returns
    -------
    OccupancyGrid
        Trinary grid, origin ``(0, 0, 0)``, name ``"warehouse"``; shelves are solid (their
        faces occupied, their inside unknown).

    Raises
    ------
    InputError
        Size below 16 x 14 m, resolution outside 0.01-0.5 m or a negative seed.
    """
    (W, H), res = _check("warehouse", size, resolution)
    rng = _rng(seed)
    cv = _Canvas((W, H), res)
    w = WALL
    x0, x1 = MARGIN + w, W - MARGIN - w
    y0, y1 = MARGIN + w, H - MARGIN - w
    cv.carve(x0, y0, x1, y1)

    dock = float(rng.uniform(4.5, 6.0))  # open loading area along the bottom wall
    office_w = min(7.0, max(5.0, (x1 - x0) * 0.25))
    office_h = min(dock - 0.5, 4.0)
    # small office in the lower-left corner: two rooms with doors to the hall
    ox1 = x0 + office_w
    oy1 = y0 + office_h
    cv.fill(ox1, y0, ox1 + w, oy1 + w)
    cv.fill(x0, oy1, ox1 + w, oy1 + w)
    mid = x0 + office_w / 2
    cv.fill(mid, y0, mid + w, oy1)
    for ra, rb in ((x0, mid), (mid + w, ox1)):
        dw = float(rng.uniform(0.9, 1.2))
        dx = float(rng.uniform(ra + 0.3, max(ra + 0.3, rb - 0.3 - dw)))
        cv.carve(dx, oy1 - 0.05, dx + dw, oy1 + w + 0.05)
    # pallets and pillars in the loading area (right of the office)
    px = ox1 + 1.5
    while px < x1 - 1.5:
        if rng.random() < 0.5:
            pw, ph = float(rng.uniform(0.8, 1.2)), float(rng.uniform(0.8, 1.2))
            py = float(rng.uniform(y0 + 0.9, y0 + dock - 1.0 - ph))
            cv.fill(px, py, px + pw, py + ph)
        px += float(rng.uniform(2.5, 4.0))

    # shelf blocks above the loading area
    sy0 = y0 + dock
    sy1 = y1 - float(rng.uniform(1.8, 2.4))  # top aisle
    n_blocks = max(1, int(round((x1 - x0) / 13.0)))
    cross = float(rng.uniform(2.2, 2.8))  # cross aisle width
    side = float(rng.uniform(1.8, 2.4))  # aisle along the side walls
    block_w = ((x1 - x0) - 2 * side - (n_blocks - 1) * cross) / n_blocks
    for b in range(n_blocks):
        bx0 = x0 + side + b * (block_w + cross)
        y = sy0
        while True:
            depth = float(rng.choice([1.0, 1.2]))  # single or double shelf
            if y + depth > sy1:
                break
            # a shelf row, sometimes broken by a gap
            if rng.random() < 0.3 and block_w > 6.0:
                g = float(rng.uniform(bx0 + 2.0, bx0 + block_w - 3.5))
                gw = float(rng.uniform(1.2, 1.6))
                cv.fill(bx0, y, g, y + depth)
                cv.fill(g + gw, y, bx0 + block_w, y + depth)
            else:
                shorten = float(rng.uniform(0.0, 1.5)) if rng.random() < 0.4 else 0.0
                if rng.random() < 0.5:
                    cv.fill(bx0 + shorten, y, bx0 + block_w, y + depth)
                else:
                    cv.fill(bx0, y, bx0 + block_w - shorten, y + depth)
            y += depth + float(rng.uniform(2.0, 2.6))
    # pillars along the top aisle
    px = x0 + float(rng.uniform(4.0, 8.0))
    while px < x1 - 2.0:
        cv.fill(px, y1 - 0.5, px + 0.4, y1)
        px += 8.0
    return _finish(cv.solid, res, "warehouse")


# ---------------------------------------------------------------------------------------------
# Cave
# ---------------------------------------------------------------------------------------------
def make_cave(seed: int = 0, size=DEFAULT_SIZE, resolution: float = DEFAULT_RESOLUTION) -> OccupancyGrid:
    """An irregular cave: a cellular automaton on a 1 m lattice, smoothly upsampled and
    roughened, keeping one connected free region.

    Parameters
    ----------
    seed : int
        Seed of the cave.
    size : (width, height)
        Extent of the grid (m).
    resolution : float
        Cell size (m).

    Returns
    -------
    OccupancyGrid
        Trinary grid, origin ``(0, 0, 0)``, name ``"cave"``; the rock's surface is occupied,
        its inside unknown.

    Raises
    ------
    InputError
        Size below 10 x 10 m, resolution outside 0.01-0.5 m or a negative seed.
    """
    (W, H), res = _check("cave", size, resolution)
    rng = _rng(seed)
    lat = 1.0  # lattice spacing of the automaton (m)
    nx, ny = max(6, int(round(W / lat))), max(6, int(round(H / lat)))
    best = None
    for _attempt in range(8):
        rock = rng.random((ny, nx)) < 0.45
        rock[:2, :] = rock[-2:, :] = True
        rock[:, :2] = rock[:, -2:] = True
        k = np.ones((3, 3), int)
        for _ in range(5):  # rock where at least 5 of the 9 cells around are rock
            rock = ndimage.convolve(rock.astype(int), k, mode="constant", cval=1) >= 5
            rock[0, :] = rock[-1, :] = True
            rock[:, 0] = rock[:, -1] = True
        lab, n = ndimage.label(~rock)
        if n == 0:
            continue
        sizes = np.bincount(lab.ravel())
        sizes[0] = 0
        frac = sizes.max() / rock.size
        if best is None or frac > best[0]:
            best = (frac, lab == int(np.argmax(sizes)))
        if frac >= 0.35:
            break
    coarse = (~best[1]).astype(float)  # 1 rock, 0 open
    # smooth upsampling to the fine grid, plus fine-scale roughness of the walls
    cols, rows = int(round(W / res)), int(round(H / res))
    yy = (np.arange(rows) + 0.5) * res / lat - 0.5
    xx = (np.arange(cols) + 0.5) * res / lat - 0.5
    field = ndimage.map_coordinates(coarse, np.meshgrid(yy, xx, indexing="ij"), order=3, mode="nearest")
    sigma = 0.3 / res
    noise = ndimage.gaussian_filter(rng.standard_normal((rows, cols)), sigma)
    noise /= max(float(noise.std()), 1e-12)
    field = field + 0.12 * noise
    solid = field > 0.5
    # a narrow band at the grid edge is always rock
    edge = max(1, int(round(MARGIN / res)))
    solid[:edge, :] = solid[-edge:, :] = True
    solid[:, :edge] = solid[:, -edge:] = True
    # open the fine grid the same way as the lattice: remove specks smaller than 0.3 m
    specks = ndimage.binary_opening(~solid, structure=np.ones((3, 3), bool),
                                    iterations=max(1, int(round(0.15 / res))))
    solid = ~specks
    return _finish(solid, res, "cave")


# ---------------------------------------------------------------------------------------------
# Registry
# ---------------------------------------------------------------------------------------------
#: World generators by name.
WORLDS = {"office": make_office, "warehouse": make_warehouse, "cave": make_cave}


def make_world(name: str, seed: int = 0, size=DEFAULT_SIZE, resolution: float = DEFAULT_RESOLUTION) -> OccupancyGrid:
    """Generate the world called ``name`` (one of :data:`WORLDS`).

    Raises
    ------
    InputError
        Unknown name, or a bad seed, size or resolution.
    """
    try:
        gen = WORLDS[str(name).lower()]
    except KeyError:
        raise InputError(f"unknown world kind {name!r}; use one of {', '.join(WORLDS)}") from None
    return gen(seed, DEFAULT_SIZE if size is None else size, resolution)


def default_world() -> OccupancyGrid:
    """The default world of ``fusionkit simulate``: the office with seed 0 at the default size
    and resolution (the same grid as ``maps/office.yaml``)."""
    return make_office(0, DEFAULT_SIZE, DEFAULT_RESOLUTION)
