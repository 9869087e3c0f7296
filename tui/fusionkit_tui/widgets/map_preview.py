"""An occupancy grid drawn in the terminal with half-block characters.

Each character cell shows two map pixels, one above the other: ``▀`` with the upper pixel as
the foreground colour and the lower one as the background. The map is shrunk to fit the widget
(keeping its aspect ratio); a pixel covering several cells shows the "strongest" of them
(occupied over free over unknown), so thin walls survive the shrinking. North (+y) is up.

Without colour (``NO_COLOR`` set) the states are drawn with distinct characters instead:
``█ ▀ ▄`` for walls, ``░`` for free space and a blank for unknown.
"""

from __future__ import annotations

import textwrap

import numpy as np
from rich.color import Color
from rich.segment import Segment
from rich.style import Style
from textual.strip import Strip
from textual.widget import Widget

from fusionkit.grid import OccupancyGrid

__all__ = ["MapPreview", "downsample", "preview_strips", "robot_colour", "shade", "ROBOT_COLOURS", "STATE_COLOURS",
           "UNKNOWN_RANK", "FREE_RANK", "OCCUPIED_RANK"]

UNKNOWN_RANK, FREE_RANK, OCCUPIED_RANK = 0, 1, 2

#: Colours of the three states in a plain map (unknown, free, occupied).
STATE_COLOURS = ("#141414", "#3d5a73", "#f2f2f2")

#: One colour per robot in a fused map (cycled beyond eight robots). Occupied cells take the
#: colour itself, free cells a dark shade of it.
ROBOT_COLOURS = ("#ff6b6b", "#4dabf7", "#69db7c", "#ffd43b", "#da77f2", "#3bc9db", "#ff922b",
                 "#a9e34b")


def shade(hex_colour: str, amount: float) -> str:
    """``hex_colour`` mixed with the unknown colour (``amount`` of the colour kept)."""
    c = Color.parse(hex_colour).triplet
    b = Color.parse(STATE_COLOURS[0]).triplet
    mix = [round(b[i] + amount * (c[i] - b[i])) for i in range(3)]
    return "#{:02x}{:02x}{:02x}".format(*mix)


def robot_colour(k: int) -> str:
    """The colour of input map ``k`` in a fused map."""
    return ROBOT_COLOURS[k % len(ROBOT_COLOURS)]


def _starts(n: int, out: int) -> np.ndarray:
    """Start index of each of ``out`` equal blocks of ``n`` cells (repeats when out > n)."""
    return np.floor(np.arange(out) * (n / out)).astype(np.intp)


def _block_sum(a: np.ndarray, rs: np.ndarray, cs: np.ndarray) -> np.ndarray:
    """Sum of ``a`` over each block (rows from ``rs``, columns from ``cs``)."""
    return np.add.reduceat(np.add.reduceat(a, rs, axis=0), cs, axis=1)


def downsample(grid: OccupancyGrid, width: int, height: int,
               owner: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """Shrink (or enlarge) a grid to at most ``width`` x ``height`` pixels, keeping its aspect.

    A pixel covering a block of ``n`` cells (about ``k = sqrt(n)`` on a side) is occupied when
    at least ``max(1, 0.8 k)`` of them are occupied (a wall across the block, not one clipping
    its corner), else free when
    at least half of them are known, else unknown. At one cell per pixel this is the map itself.

    Parameters
    ----------
    grid : OccupancyGrid
    width, height : int
        Largest output size in pixels (columns, rows).
    owner : (rows, cols) int array, optional
        Per cell, the index of the map that contributed it (-1 none).

    Returns
    -------
    rank : (h, w) int8 array
        Per pixel, ``0`` unknown, ``1`` free, ``2`` occupied. Row 0 is the *top* of the
        picture (highest y).
    owners : (h, w) int array or None
        Per pixel, the map that contributed most of its known cells (-1 none).
    """
    data = grid.trinary()[::-1]  # row 0 of the picture = highest y
    rows, cols = data.shape
    width, height = max(1, int(width)), max(1, int(height))
    scale = max(rows / height, cols / width)
    out_w = max(1, min(width, int(np.ceil(cols / scale - 1e-9))))
    out_h = max(1, min(height, int(np.ceil(rows / scale - 1e-9))))
    rs, cs = _starts(rows, out_h), _starts(cols, out_w)
    occ = (data >= 50).astype(np.int32)
    known = (data >= 0).astype(np.int32)
    n = _block_sum(np.ones_like(occ), rs, cs)
    occ_n = _block_sum(occ, rs, cs)
    known_n = _block_sum(known, rs, cs)
    rank = np.full(n.shape, UNKNOWN_RANK, np.int8)
    rank[2 * known_n >= n] = FREE_RANK
    rank[(occ_n >= np.maximum(1.0, 0.8 * np.sqrt(n))) & (occ_n > 0)] = OCCUPIED_RANK
    if owner is None:
        return rank, None
    own = np.asarray(owner)[::-1]
    owners = np.full(n.shape, -1, np.int32)
    best = np.zeros(n.shape, np.int32)
    for k in np.unique(own[own >= 0]):
        count = _block_sum((own == k).astype(np.int32), rs, cs)
        better = count > best
        owners[better], best[better] = int(k), count[better]
    return rank, owners


def _pixel_colours(rank: np.ndarray, owners: np.ndarray | None) -> np.ndarray:
    """Per pixel, its colour as a string (object array)."""
    out = np.empty(rank.shape, object)
    for r in (UNKNOWN_RANK, FREE_RANK, OCCUPIED_RANK):
        out[rank == r] = STATE_COLOURS[r]
    if owners is not None:
        for k in np.unique(owners[owners >= 0]):
            base = robot_colour(int(k))
            out[(owners == k) & (rank == OCCUPIED_RANK)] = base
            out[(owners == k) & (rank == FREE_RANK)] = shade(base, 0.35)
    return out


def _mono_char(top: int, bottom: int) -> str:
    if top == OCCUPIED_RANK and bottom == OCCUPIED_RANK:
        return "█"
    if top == OCCUPIED_RANK:
        return "▀"
    if bottom == OCCUPIED_RANK:
        return "▄"
    if top == FREE_RANK or bottom == FREE_RANK:
        return "░"
    return " "


def _known_part(grid: OccupancyGrid, owner: np.ndarray | None):
    """``grid`` (and ``owner``) cut to the box of its known cells when the unknown around them is
    wider than half of it (map_saver's 4000 x 4000 grid around a robot's 300 x 300 cells drew
    as a black square with a dot); as they are otherwise."""
    box = grid.known_box()
    if box is None:
        return grid, owner
    r0, r1, c0, c1 = box
    h, w = r1 - r0, c1 - c0
    if grid.rows - h <= h / 2 and grid.cols - w <= w / 2:
        return grid, owner
    cut = (slice(r0, r1), slice(c0, c1))
    return (grid.with_data(grid.data[cut]), None if owner is None else owner[cut])


def preview_strips(grid: OccupancyGrid, width: int, height: int, *,
                   owner: np.ndarray | None = None, no_color: bool = False,
                   base: Style | None = None) -> list[Strip]:
    """The picture of ``grid`` as ``height`` lines of ``width`` cells, centred.

    Parameters
    ----------
    grid : OccupancyGrid
    width, height : int
        Size in character cells (two map pixels per cell vertically).
    owner : (rows, cols) int array, optional
        Colour each cell by the map that contributed it (a fused map).
    no_color : bool
        Draw the states with distinct characters and no colour.
    base : rich Style, optional
        Style of the margins around the picture.
    """
    base = base or Style()
    if width < 1 or height < 1:
        return []
    grid, owner = _known_part(grid, owner)
    rank, owners = downsample(grid, width, 2 * height, owner)
    if rank.shape[0] % 2:  # an odd number of pixel rows: the last cell row has an empty bottom
        rank = np.vstack([rank, np.full((1, rank.shape[1]), -1, np.int8)])
        if owners is not None:
            owners = np.vstack([owners, np.full((1, owners.shape[1]), -1, owners.dtype)])
    colours = None if no_color else _pixel_colours(rank, owners)
    pic_h, pic_w = rank.shape[0] // 2, rank.shape[1]
    top_pad = (height - pic_h) // 2
    left = (width - pic_w) // 2
    right = width - pic_w - left
    blank = Strip([Segment(" " * width, base)], width)
    strips = [blank] * top_pad
    styles: dict = {}
    for y in range(pic_h):
        segs = [Segment(" " * left, base)] if left else []
        run_text, run_style = [], None
        for x in range(pic_w):
            t, b = int(rank[2 * y, x]), int(rank[2 * y + 1, x])
            if no_color:
                ch, style = _mono_char(t, b), base
            else:
                fg = colours[2 * y, x]
                bg = colours[2 * y + 1, x] if b >= 0 else None
                key = (fg, bg)
                style = styles.get(key)
                if style is None:
                    style = styles[key] = (base + Style(color=fg, bgcolor=bg) if bg is not None
                                           else base + Style(color=fg))
                ch = "▀"
            if style is not run_style and run_text:
                segs.append(Segment("".join(run_text), run_style))
                run_text = []
            run_style = style
            run_text.append(ch)
        if run_text:
            segs.append(Segment("".join(run_text), run_style))
        if right:
            segs.append(Segment(" " * right, base))
        strips.append(Strip(segs, width))
    strips += [blank] * (height - len(strips))
    return strips


class MapPreview(Widget):
    """A map (or a fused map coloured by contributing robot) drawn with half blocks.

    Call :meth:`show` with a grid, :meth:`clear` with a message to show instead.
    """

    DEFAULT_CSS = """
    MapPreview {
        width: 1fr;
        height: 1fr;
        min-height: 4;
        background: $surface;
        color: $text-muted;
    }
    """

    def __init__(self, *, id: str | None = None, classes: str | None = None) -> None:
        super().__init__(id=id, classes=classes)
        self._grid: OccupancyGrid | None = None
        self._owner: np.ndarray | None = None
        self._message = ""
        self._cache: tuple | None = None

    @property
    def grid(self) -> OccupancyGrid | None:
        """The grid shown, or None."""
        return self._grid

    def show(self, grid: OccupancyGrid, owner: np.ndarray | None = None) -> None:
        """Draw ``grid`` (with ``owner``: each cell in its contributing map's colour)."""
        self._grid, self._owner, self._message, self._cache = grid, owner, "", None
        self.refresh()

    def clear(self, message: str = "") -> None:
        """Show ``message`` instead of a map."""
        self._grid, self._owner, self._message, self._cache = None, None, message, None
        self.refresh()

    def _strips(self) -> list[Strip]:
        w, h = self.size
        no_color = bool(getattr(self.app, "no_color", False))
        key = (w, h, no_color, self._grid is None)
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1]
        base = self.rich_style
        if self._grid is None:
            # the message wrapped whole (a reason cut at the width lost what to do), centred
            lines = (textwrap.wrap(self._message, max(w - 2, 1), break_on_hyphens=False)
                     if self._message else [])
            top = max((h - len(lines)) // 2, 0)
            strips = []
            for y in range(h):
                k = y - top
                text = lines[k].center(w)[:w] if 0 <= k < len(lines) else " " * w
                strips.append(Strip([Segment(text, base)], w))
        else:
            strips = preview_strips(self._grid, w, h, owner=self._owner, no_color=no_color, base=base)
        self._cache = (key, strips)
        return strips

    def on_resize(self) -> None:
        self._cache = None

    def render_line(self, y: int) -> Strip:
        strips = self._strips()
        if 0 <= y < len(strips):
            return strips[y]
        return Strip.blank(self.size.width, self.rich_style)
