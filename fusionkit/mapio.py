"""Map files in the ROS ``map_server`` format (CONTRACTS section 2).

A map on disk is a YAML file plus the image it names::

    image: office.pgm          # resolved relative to the YAML file (absolute paths allowed)
    resolution: 0.05           # metres per pixel
    origin: [-10.0, -5.0, 0.0] # x, y (m), yaw (rad) of the lower-left pixel
    negate: 0                  # 1: white is occupied, black is free
    occupied_thresh: 0.65
    free_thresh: 0.196
    mode: trinary              # optional: trinary (default), scale or raw

The pixels are interpreted exactly as ``map_server`` (ROS 1, ``image_loader.cpp``) and
``nav2_map_server`` (``map_io.cpp``) interpret them. With ``m`` the image's maximum value
(255 for 8-bit images) and ``v`` the pixel value averaged over its channels::

    p = (m - v) / m        (negate: 0)        p = v / m        (negate: 1)
    occupied if p > occupied_thresh, free if p < free_thresh, unknown otherwise.

The image's top row is the highest y; the grid's row 0 is the lowest y, so rows are flipped on
load and on save. :func:`save_map` writes what ``map_saver`` writes: a trinary 8-bit image
(occupied 0, free 254, unknown 205) and a YAML with ``occupied_thresh: 0.65``,
``free_thresh: 0.196``, ``negate: 0``, so a saved trinary grid loads back bit-exact.

Supported images: binary (P5, 8- and 16-bit) and plain (P2) PGM, and PNG (grey, grey+alpha,
RGB, RGBA; 8- or 16-bit).
"""

from __future__ import annotations

import math
import os
import re
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ._atomic import _short, check_not_input, show, write_set
from ._inputs import read_bytes, regular_file
from .errors import FusionkitError, InputError, MapFormatError
from .grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from .mapping import MAX_CELLS
from .scanlog import scans_path_for

__all__ = ["load_map", "save_map", "save_maps", "encode_map", "map_info", "MAP_MODES",
           "IMAGE_FORMATS", "MAX_IMAGE_BYTES"]

#: Interpretations of the pixel values a map YAML may ask for with ``mode``.
MAP_MODES = ("trinary", "scale", "raw")
#: Image formats :func:`save_map` writes.
IMAGE_FORMATS = ("pgm", "png")

_REQUIRED_KEYS = ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh")
_YAML_SUFFIXES = (".yaml", ".yml")
_MAX_YAML_BYTES = 1 << 20  # a map YAML is a few hundred bytes; anything this big is not one
_MAX_HEADER_BYTES = 1 << 16  # PNM headers (with comments) longer than this are refused
#: Most bytes a map image may decode to (width x height x channels x bytes per sample): a
#: decompression bomb is refused from its header, before any pixel is decoded.
MAX_IMAGE_BYTES = 800_000_000
_MAX_PLAIN_PGM_PIXELS = 20_000_000  # P2 is text: ~40 bytes of memory per pixel while parsing
#: Sane bounds of a map's geometry (a map YAML outside them is corrupt, not a map).
_RESOLUTION_RANGE = (1e-9, 1e6)  # metres per pixel
_ORIGIN_LIMIT = 1e9  # metres
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_WHITESPACE = b" \t\r\n\v\f"

# What map_saver writes (ROS 1 map_saver.cpp defaults).
_SAVE_OCCUPIED_THRESH = 0.65
_SAVE_FREE_THRESH = 0.196
_PIXEL_OCCUPIED, _PIXEL_FREE, _PIXEL_UNKNOWN = 0, 254, 205


# ---------------------------------------------------------------------------------------------
# YAML
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _MapYaml:
    """The validated contents of a map YAML."""

    yaml_path: Path
    image: Path
    resolution: float
    origin: tuple[float, float, float]
    negate: bool
    occupied_thresh: float
    free_thresh: float
    mode: str


def _safe_yaml(raw: bytes):
    """``yaml.safe_load`` without aliases: ``*name`` references (the "billion laughs" bomb,
    anchors expanding to gigabytes) are refused; a map YAML never needs one."""
    import yaml  # PyYAML

    class NoAliasLoader(yaml.SafeLoader):
        def compose_node(self, parent, index):
            if self.check_event(yaml.events.AliasEvent):
                mark = self.peek_event().start_mark
                raise yaml.composer.ComposerError(
                    None, None, "an alias (*name); write the value out instead", mark)
            return super().compose_node(parent, index)

    loader = NoAliasLoader(raw)
    try:
        return loader.get_single_data()
    finally:
        loader.dispose()


def _read_yaml(yaml_path: Path) -> _MapYaml:
    import yaml  # PyYAML

    raw = read_bytes(yaml_path, "map", _MAX_YAML_BYTES, MapFormatError)
    if raw[:2] in (b"P2", b"P5") or raw.startswith(_PNG_SIGNATURE):
        raise MapFormatError(
            f"{_short(yaml_path)}: is an image, not a map YAML; give the .yaml file that names this image")
    try:
        doc = _safe_yaml(raw)
    except yaml.YAMLError as exc:
        where = ""
        mark = getattr(exc, "problem_mark", None)
        if mark is not None:
            where = f" at line {mark.line + 1}, column {mark.column + 1}"
        problem = show(getattr(exc, "problem", None) or "invalid syntax", 120).strip("'\"")
        raise MapFormatError(f"{_short(yaml_path)}: is not valid YAML ({problem}{where}); fix the syntax") from None
    except (UnicodeError, ValueError, RecursionError, OverflowError, MemoryError) as exc:
        raise MapFormatError(f"{_short(yaml_path)}: is not valid YAML ({show(str(exc), 120)}); "
                             f"fix the file") from None
    if not isinstance(doc, dict):
        raise MapFormatError(
            f"{yaml_path}: does not hold a map_server mapping (image, resolution, origin, negate, "
            f"occupied_thresh, free_thresh); write it as 'key: value' lines")
    missing = [k for k in _REQUIRED_KEYS if k not in doc or doc[k] is None]
    if missing:
        raise MapFormatError(
            f"{yaml_path}: the map_server key{'s' if len(missing) > 1 else ''} "
            f"{', '.join(repr(k) for k in missing)} {'are' if len(missing) > 1 else 'is'} missing; "
            f"add {'them' if len(missing) > 1 else 'it'} to the YAML")

    image = doc["image"]
    if not isinstance(image, str) or not image.strip():
        raise MapFormatError(f"{_short(yaml_path)}: 'image' must be the file name of the map image, "
                             f"got {show(image)}")
    if "\x00" in image or len(image.strip().encode()) > 4096:
        raise MapFormatError(f"{_short(yaml_path)}: 'image' is not a usable file name "
                             f"({show(image)}); fix the 'image' key")
    image_path = Path(image.strip())
    if not image_path.is_absolute():
        image_path = yaml_path.parent / image_path

    resolution = _number(doc["resolution"], "resolution", yaml_path)
    lo, hi = _RESOLUTION_RANGE
    if not lo <= resolution <= hi:
        raise MapFormatError(
            f"{_short(yaml_path)}: 'resolution' must be a positive number of metres per pixel between "
            f"{lo:g} and {hi:g}, got {show(doc['resolution'])}")

    origin = doc["origin"]
    if not isinstance(origin, (list, tuple)) or len(origin) != 3:
        raise MapFormatError(
            f"{_short(yaml_path)}: 'origin' must be a list of 3 numbers [x, y, yaw] (m, m, rad), "
            f"got {show(origin)}")
    origin = tuple(_number(v, "origin", yaml_path, whole=origin) for v in origin)
    if max(abs(v) for v in origin) > _ORIGIN_LIMIT:
        raise MapFormatError(
            f"{_short(yaml_path)}: 'origin' must lie within {_ORIGIN_LIMIT:g} m (and rad) of 0, got "
            f"{show(doc['origin'])}; fix the origin")

    negate = doc["negate"]
    if isinstance(negate, bool):
        negate = bool(negate)
    elif isinstance(negate, int) and negate in (0, 1):
        negate = bool(negate)
    else:
        raise MapFormatError(f"{_short(yaml_path)}: 'negate' must be 0 or 1, got {show(negate)}")

    occ = _number(doc["occupied_thresh"], "occupied_thresh", yaml_path)
    free = _number(doc["free_thresh"], "free_thresh", yaml_path)
    for key, value in (("occupied_thresh", occ), ("free_thresh", free)):
        if not 0.0 <= value <= 1.0:
            raise MapFormatError(f"{_short(yaml_path)}: '{key}' must lie in [0, 1], got {show(doc[key])}")
    if free >= occ:
        raise MapFormatError(
            f"{yaml_path}: 'free_thresh' ({free:g}) must be smaller than 'occupied_thresh' ({occ:g}); "
            f"fix the thresholds")

    mode = doc.get("mode")
    if mode is None:
        mode = "trinary"
    elif not isinstance(mode, str) or mode.strip().lower() not in MAP_MODES:
        raise MapFormatError(
            f"{_short(yaml_path)}: unknown 'mode' {show(mode)}; use one of {', '.join(MAP_MODES)} (or leave it out for trinary)")
    else:
        mode = mode.strip().lower()
    return _MapYaml(yaml_path, image_path, resolution, origin, negate, occ, free, mode)


def _number(value, key: str, yaml_path: Path, whole=None) -> float:
    """A finite float from a YAML scalar (numbers, or strings that spell a number)."""
    shown = whole if whole is not None else value
    x = None
    if isinstance(value, str) and len(value) > 100:
        x = None
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        try:
            x = float(value)
        except OverflowError:
            x = None
    elif isinstance(value, str) and len(value) <= 100:
        try:
            x = float(value.strip())
        except ValueError:
            x = None
    if x is None or not math.isfinite(x):
        what = "a list of 3 finite numbers [x, y, yaw]" if key == "origin" else "a finite number"
        raise MapFormatError(f"{_short(yaml_path)}: '{key}' must be {what}, got {show(shown)}")
    return x


# ---------------------------------------------------------------------------------------------
# Images
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _ImageHeader:
    kind: str  # "P5", "P2" or "PNG"
    width: int
    height: int
    maxval: int
    offset: int  # first raster byte (PNM only)


def _check_size(path: Path, width: int, height: int) -> None:
    if width <= 0 or height <= 0:
        raise MapFormatError(
            f"{path}: the image header declares a size of {width} x {height} pixels; a map needs at "
            f"least one pixel, so the file is corrupt: re-export it")
    if width * height > MAX_CELLS:
        raise MapFormatError(
            f"{path}: the image header declares {width} x {height} = {width * height} pixels, more than "
            f"the {MAX_CELLS} cells fusionkit can hold; the header is corrupt or the map must be "
            f"cropped or saved at a coarser resolution")


def _parse_pnm_header(head: bytes, path: Path, file_size: int) -> _ImageHeader:
    """Parse ``P5``/``P2`` magic, width, height and maxval (comments allowed between tokens)."""
    kind = head[:2].decode("ascii")
    if len(head) >= _MAX_HEADER_BYTES and file_size > len(head):
        truncated = MapFormatError(
            f"{path}: the PGM header does not end within its first {_MAX_HEADER_BYTES} bytes; the "
            f"header is corrupt (or holds overlong comments): re-export the image")
    else:
        truncated = MapFormatError(
            f"{path}: the PGM header is truncated (it must give width, height and maxval); "
            f"the file is incomplete or not a PGM: re-export it")
    pos = 2
    if pos >= len(head) or head[pos] not in _WHITESPACE and head[pos] != ord("#"):
        raise MapFormatError(f"{path}: the PGM magic number {kind} must be followed by white space; "
                             f"the header is corrupt: re-export the image")
    names = ("width", "height", "maxval")
    values = []
    for name in names:
        while True:  # skip white space and comments
            if pos >= len(head):
                raise truncated
            ch = head[pos]
            if ch in _WHITESPACE:
                pos += 1
            elif ch == ord("#"):
                ends = [i for i in (head.find(b"\n", pos), head.find(b"\r", pos)) if i >= 0]
                if not ends:
                    raise truncated
                pos = min(ends) + 1
            else:
                break
        start = pos
        while pos < len(head) and 48 <= head[pos] <= 57:
            pos += 1
        if pos == start:
            raise MapFormatError(
                f"{path}: the PGM header is corrupt: expected the {name} as a decimal number at byte "
                f"{start}, found {head[start:start + 12]!r}; re-export the image")
        if pos - start > 30:
            raise MapFormatError(
                f"{path}: the PGM header is corrupt: the {name} has {pos - start} digits; re-export the image")
        if pos >= len(head):
            raise truncated
        if head[pos] not in _WHITESPACE and head[pos] != ord("#"):
            raise MapFormatError(
                f"{path}: the PGM header is corrupt: the {name} is followed by {bytes([head[pos]])!r} "
                f"instead of white space; re-export the image")
        values.append(int(head[start:pos]))
    width, height, maxval = values
    # Exactly one white-space character (or a comment up to its line end) ends the header.
    if head[pos] == ord("#"):
        ends = [i for i in (head.find(b"\n", pos), head.find(b"\r", pos)) if i >= 0]
        if not ends:
            raise truncated
        pos = min(ends) + 1
    else:
        pos += 1
    if not 1 <= maxval <= 65535:
        raise MapFormatError(
            f"{path}: the PGM maxval is {maxval}, but it must be between 1 and 65535; the header is "
            f"corrupt: re-export the image")
    _check_size(path, width, height)
    return _ImageHeader(kind, width, height, maxval, pos)


def _png_header(head: bytes, path: Path) -> _ImageHeader:
    # Signature (8) + IHDR chunk: length (4), type (4), width (4), height (4), ...
    if len(head) < 24 or head[12:16] != b"IHDR":
        raise MapFormatError(f"{path}: the PNG file is truncated or corrupt (no IHDR header); re-export it")
    width = int.from_bytes(head[16:20], "big")
    height = int.from_bytes(head[20:24], "big")
    _check_size(path, width, height)
    depth, colour = (head[24], head[25]) if len(head) >= 26 else (8, 0)
    channels = {0: 1, 2: 3, 3: 3, 4: 2, 6: 4}.get(colour)
    if channels is None or depth not in (1, 2, 4, 8, 16):
        raise MapFormatError(f"{_short(path)}: the PNG header is corrupt (colour type {colour}, bit depth "
                             f"{depth}); re-export it")
    decoded = width * height * channels * (2 if depth == 16 else 1)
    if decoded > MAX_IMAGE_BYTES:
        raise MapFormatError(
            f"{_short(path)}: the PNG declares {width} x {height} pixels of {channels} channel(s) at "
            f"{depth} bits, {decoded / 1e6:.0f} MB once decoded, more than the {MAX_IMAGE_BYTES / 1e6:.0f} MB "
            f"fusionkit decodes; save the map as an 8-bit grey image or crop it")
    return _ImageHeader("PNG", width, height, 0, 0)


def _image_header(path: Path) -> tuple[_ImageHeader, int]:
    """Identify the image and parse its header; returns the header and the file size (bytes)."""
    regular_file(path, "map image", MapFormatError)
    try:
        with open(path, "rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            head = fh.read(_MAX_HEADER_BYTES)
    except OSError as exc:
        raise MapFormatError(f"{path}: the map image cannot be read ({exc.strerror or exc}); check its permissions") from None
    if head[:2] in (b"P5", b"P2"):
        return _parse_pnm_header(head, path, size), size
    if head.startswith(_PNG_SIGNATURE):
        return _png_header(head, path), size
    if head[:2] in (b"P1", b"P3", b"P4", b"P6", b"P7"):
        kind = {b"P1": "PBM", b"P4": "PBM", b"P3": "PPM", b"P6": "PPM", b"P7": "PAM"}[head[:2]]
    elif not head:
        raise MapFormatError(f"{path}: the map image is empty; re-export it as PGM or PNG")
    else:
        kind = "unrecognised"
    raise MapFormatError(
        f"{path}: {kind} image files are not supported as map images; convert it to PGM (P5/P2) or PNG")


def _read_pixels(path: Path) -> tuple[np.ndarray, int]:
    """Pixels ``(height, width[, channels])`` in file order (top row first) and their maxval."""
    header, size = _image_header(path)
    w, h = header.width, header.height
    if header.kind == "P5":
        bps = 1 if header.maxval < 256 else 2
        need = w * h * bps
        have = max(size - header.offset, 0)
        if have < need:
            raise MapFormatError(
                f"{path}: the PGM is truncated: its header declares {w} x {h} pixels ({need} bytes) but "
                f"only {have} bytes follow; the file is incomplete: re-export it")
        try:
            with open(path, "rb") as fh:
                fh.seek(header.offset)
                raw = fh.read(need)
        except OSError as exc:
            raise MapFormatError(f"{path}: the map image cannot be read ({exc.strerror or exc})") from None
        if len(raw) < need:
            raise MapFormatError(f"{path}: the PGM is truncated (the file shrank while being read); re-export it")
        pixels = np.frombuffer(raw, dtype=np.uint8 if bps == 1 else ">u2").reshape(h, w)
        if bps == 2:
            pixels = pixels.astype(np.uint16)
    elif header.kind == "P2":
        pixels = _read_plain_pgm(path, header)
    else:
        pixels = _read_png(path, header)
        return pixels, 255 if pixels.dtype == np.uint8 else 65535
    if header.maxval not in (255, 65535):
        top = int(pixels.max())
        if top > header.maxval:
            raise MapFormatError(
                f"{path}: a pixel value {top} exceeds the PGM maxval {header.maxval}; the file is "
                f"corrupt: re-export it")
    return pixels, header.maxval


def _read_plain_pgm(path: Path, header: _ImageHeader) -> np.ndarray:
    w, h = header.width, header.height
    if w * h > _MAX_PLAIN_PGM_PIXELS:
        raise MapFormatError(
            f"{_short(path)}: a plain (P2, text) PGM of {w} x {h} pixels is too large to read (at most "
            f"{_MAX_PLAIN_PGM_PIXELS} pixels); save it as a binary PGM (P5) or PNG")
    try:
        with open(path, "rb") as fh:
            fh.seek(header.offset)
            text = fh.read()
    except OSError as exc:
        raise MapFormatError(f"{path}: the map image cannot be read ({exc.strerror or exc})") from None
    tokens = re.sub(rb"#[^\r\n]*", b" ", text).split()
    if len(tokens) < w * h:
        raise MapFormatError(
            f"{path}: the plain PGM is truncated: its header declares {w} x {h} = {w * h} pixels but only "
            f"{len(tokens)} values follow; the file is incomplete: re-export it")
    del text
    try:
        values = np.array(tokens[: w * h], dtype=np.bytes_).astype(np.int64)
    except (ValueError, OverflowError):
        raise MapFormatError(
            f"{path}: the plain PGM holds a pixel value that is not a whole number; the file is "
            f"corrupt: re-export it") from None
    if values.size and (values.min() < 0 or values.max() > header.maxval):
        raise MapFormatError(
            f"{path}: the plain PGM holds pixel values outside 0..{header.maxval} (its maxval); the file "
            f"is corrupt: re-export it")
    return values.astype(np.uint8 if header.maxval < 256 else np.uint16).reshape(h, w)


def _check_png_chunks(data: bytes, path: Path) -> None:
    """Walk the PNG chunks (length, type, CRC) up to IEND, so that a truncated or damaged file
    is reported here rather than half-decoded."""
    pos = len(_PNG_SIGNATURE)
    while True:
        if pos + 12 > len(data):
            raise MapFormatError(f"{path}: the PNG is truncated (it ends before its IEND chunk); re-export it")
        length = int.from_bytes(data[pos:pos + 4], "big")
        end = pos + 12 + length
        if end > len(data):
            raise MapFormatError(f"{path}: the PNG is truncated (a chunk runs past the end of the file); re-export it")
        kind = data[pos + 4:pos + 8]
        if zlib.crc32(data[pos + 4:end - 4]) != int.from_bytes(data[end - 4:end], "big"):
            raise MapFormatError(
                f"{path}: the PNG is corrupt (checksum mismatch in its {kind!r} chunk); re-export it")
        if kind == b"IEND":
            return
        pos = end


def _read_png(path: Path, header: _ImageHeader) -> np.ndarray:
    import cv2

    try:
        buf = np.fromfile(path, dtype=np.uint8)
    except OSError as exc:
        raise MapFormatError(f"{path}: the map image cannot be read ({exc.strerror or exc})") from None
    _check_png_chunks(buf.tobytes(), path)
    try:
        img = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED)
    except cv2.error:
        img = None
    if img is None:
        raise MapFormatError(f"{path}: the PNG cannot be decoded (truncated or corrupt); re-export it")
    if img.dtype not in (np.uint8, np.uint16):
        raise MapFormatError(f"{path}: PNG pixels of type {img.dtype} are not supported; save it as 8- or 16-bit")
    if img.shape[:2] != (header.height, header.width) or img.ndim not in (2, 3) or (
            img.ndim == 3 and img.shape[2] not in (1, 2, 3, 4)):
        raise MapFormatError(f"{path}: the PNG decodes to an unexpected shape {img.shape}; re-export it")
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    return img


# ---------------------------------------------------------------------------------------------
# Pixels -> cells (map_server / nav2_map_server semantics)
# ---------------------------------------------------------------------------------------------
def _pixels_to_cells(pixels: np.ndarray, maxval: int, meta: _MapYaml) -> np.ndarray:
    """Occupancy values int8 ``(height, width)`` in image order (top row first).

    Every result depends on the pixel only through an integer channel sum, so the rule is
    evaluated once per possible sum (a lookup table) and then indexed by the image.
    """
    m = float(maxval)
    alpha = None
    if pixels.ndim == 2:
        colour_sum, n_colour = pixels, 1
    else:
        c = pixels.shape[2]
        if c == 2:  # grey + alpha: the colour channels are R = G = B = grey
            colour_sum, n_colour = pixels[:, :, 0].astype(np.uint32) * 3, 3
            alpha = pixels[:, :, 1]
        else:
            colour_sum = pixels[:, :, :3].sum(axis=2, dtype=np.uint32)
            n_colour = 3
            alpha = pixels[:, :, 3] if c == 4 else None

    if meta.mode == "trinary" and alpha is not None:
        # map_server averages the alpha (opacity) channel in with the colours in trinary mode.
        index = colour_sum + alpha.astype(np.uint32)
        n = n_colour + 1
    else:
        index, n = colour_sum, n_colour

    sums = np.arange(n * maxval + 1, dtype=np.float64)
    avg = sums / n  # color_avg = color_sum / n_channels
    if meta.mode == "raw":
        # nav2: occ_percent = round(shade * 255), kept when in [0, 100]; negate does not apply.
        value = np.floor(avg / m * 255.0 + 0.5)
        lut = np.where((value >= 0) & (value <= 100), value, UNKNOWN)
    else:
        if meta.negate:
            avg = m - avg  # color_avg = 255 - color_avg
        p = (m - avg) / m  # occ = (255 - color_avg) / 255
        lut = np.full(sums.shape, UNKNOWN, np.float64)
        if meta.mode == "scale":
            # nav2: intermediate shades become rint(100 * (occ - free) / (occ_th - free)).
            lut = np.rint((p - meta.free_thresh) / (meta.occupied_thresh - meta.free_thresh) * 100.0)
        lut = np.where(p > meta.occupied_thresh, OCCUPIED, np.where(p < meta.free_thresh, FREE, lut))
    cells = lut.astype(np.int8)[index]
    if meta.mode == "scale" and alpha is not None:
        cells[alpha != maxval] = UNKNOWN  # nav2: any pixel that is not fully opaque is unknown
    return cells


# ---------------------------------------------------------------------------------------------
# Public API
# ---------------------------------------------------------------------------------------------
def load_map(yaml_path) -> OccupancyGrid:
    """Load a ``map_server`` map (YAML + PGM/PNG image) as an occupancy grid.

    Parameters
    ----------
    yaml_path : str or os.PathLike
        The map's YAML file. Its ``image`` is resolved relative to the YAML's directory.

    Returns
    -------
    OccupancyGrid
        ``data[row, col]`` int8 with row 0 the image's *bottom* row (lowest y): ``-1`` unknown,
        ``0`` free, ``100`` occupied; in ``mode: scale`` intermediate shades give
        ``rint(100 (p - free_thresh) / (occupied_thresh - free_thresh))``, in ``mode: raw`` the
        pixel values 0..100 are kept and others become unknown. ``resolution`` (m/cell) and
        ``origin`` (x, y, yaw) come from the YAML; ``name`` is the YAML file's stem.

    Raises
    ------
    MapFormatError
        The YAML or image is missing, unreadable, malformed, truncated, of an unsupported type
        or declares more than :data:`fusionkit.mapping.MAX_CELLS` pixels. The message names the
        file and what to fix.

    Notes
    -----
    Pixel value ``v`` (averaged over the colour channels; in trinary mode the alpha channel is
    averaged in as well, as map_server does) with image maximum ``m`` gives
    ``p = (m - v) / m`` (``v / m`` when ``negate: 1``); ``p > occupied_thresh`` is occupied,
    ``p < free_thresh`` free, anything between unknown. In scale mode a pixel that is not fully
    opaque is unknown (nav2_map_server; ROS 1 map_server scaled by 99 and truncated instead).
    """
    yaml_path = Path(yaml_path)
    meta = _read_yaml(yaml_path)
    if not meta.image.exists():
        raise MapFormatError(
            f"{yaml_path}: the image {meta.image} it names does not exist; fix the 'image' key or "
            f"restore the file")
    pixels, maxval = _read_pixels(meta.image)
    cells = _pixels_to_cells(pixels, maxval, meta)
    data = np.ascontiguousarray(cells[::-1])  # image top row = highest y; grid row 0 = lowest y
    return OccupancyGrid(data, meta.resolution, meta.origin, yaml_path.stem)


def map_info(yaml_path) -> dict:
    """Cheap facts about a map file, for listings and file pickers (reads the image header only).

    Parameters
    ----------
    yaml_path : str or os.PathLike
        The map's YAML file.

    Returns
    -------
    dict
        ``name`` (YAML stem), ``yaml`` and ``image`` (paths as str), ``image_type`` (``"P5"``,
        ``"P2"`` or ``"PNG"``), ``rows`` and ``cols`` (cells), ``resolution`` (m/cell),
        ``origin`` (x, y, yaw), ``width_m`` and ``height_m`` (m), ``mode``, ``negate``,
        ``occupied_thresh``, ``free_thresh`` and ``has_scans`` (``NAME.scans.npz`` stands beside
        the YAML).

    Raises
    ------
    MapFormatError
        As :func:`load_map`, for faults found in the YAML or the image header.
    """
    yaml_path = Path(yaml_path)
    meta = _read_yaml(yaml_path)
    if not meta.image.exists():
        raise MapFormatError(
            f"{yaml_path}: the image {meta.image} it names does not exist; fix the 'image' key or "
            f"restore the file")
    header, _ = _image_header(meta.image)
    return {
        "name": yaml_path.stem,
        "yaml": str(yaml_path),
        "image": str(meta.image),
        "image_type": header.kind,
        "rows": header.height,
        "cols": header.width,
        "resolution": meta.resolution,
        "origin": meta.origin,
        "width_m": header.width * meta.resolution,
        "height_m": header.height * meta.resolution,
        "mode": meta.mode,
        "negate": meta.negate,
        "occupied_thresh": meta.occupied_thresh,
        "free_thresh": meta.free_thresh,
        "has_scans": scans_path_for(yaml_path).is_file(),
    }


def encode_map(grid: OccupancyGrid, yaml_path, *, image_format: str = "pgm") -> tuple[Path, bytes, bytes]:
    """The two files of a saved map, as bytes: ``(image_path, image_bytes, yaml_bytes)``.

    What :func:`save_map` writes (see there), without writing it; for callers that write a map
    as part of a larger set of files with :func:`save_maps`.
    """
    import cv2
    import yaml

    fmt = str(image_format).lower().lstrip(".")
    if fmt not in IMAGE_FORMATS:
        raise InputError(f"image format {show(image_format)} is not supported; use one of {', '.join(IMAGE_FORMATS)}")
    yaml_path = Path(yaml_path)
    if yaml_path.suffix.lower() not in _YAML_SUFFIXES:
        raise InputError(f"{_short(yaml_path)}: a map must be saved to a .yaml (or .yml) file; change the output name")
    if not isinstance(grid, OccupancyGrid):
        raise InputError(f"{_short(yaml_path)}: save_map needs an OccupancyGrid, got {type(grid).__name__}")
    if grid.data.size == 0:
        raise InputError(f"{_short(yaml_path)}: the grid has no cells ({grid.rows} x {grid.cols}); there is nothing to save")
    image_path = yaml_path.with_name(yaml_path.stem + "." + fmt)

    states = grid.trinary()
    pixels = np.full(states.shape, _PIXEL_UNKNOWN, np.uint8)
    pixels[states == FREE] = _PIXEL_FREE
    pixels[states == OCCUPIED] = _PIXEL_OCCUPIED
    pixels = np.ascontiguousarray(pixels[::-1])  # grid row 0 (lowest y) is the image's bottom row
    if fmt == "pgm":
        head = f"P5\n# CREATOR: fusionkit {grid.resolution:.3f} m/pix\n{grid.cols} {grid.rows}\n255\n"
        payload = head.encode("ascii") + pixels.tobytes()
    else:
        ok, buf = cv2.imencode(".png", pixels)
        if not ok:
            raise InputError(f"{_short(image_path)}: the PNG encoder failed; save as pgm instead")
        payload = buf.tobytes()

    text = yaml.safe_dump(
        {
            "image": image_path.name,
            "mode": "trinary",
            "resolution": float(grid.resolution),
            "origin": [float(v) for v in grid.origin],
            "negate": 0,
            "occupied_thresh": _SAVE_OCCUPIED_THRESH,
            "free_thresh": _SAVE_FREE_THRESH,
        },
        sort_keys=False, default_flow_style=None, allow_unicode=True,
    )
    return image_path, payload, text.encode("utf-8")


def save_map(grid: OccupancyGrid, yaml_path, *, image_format: str = "pgm", inputs=()) -> None:
    """Write ``grid`` as a ``map_server`` map: ``NAME.yaml`` and ``NAME.pgm`` (or ``.png``) beside it.

    The image is what ``map_saver`` writes: 8-bit grey, occupied 0, free 254, unknown 205, top
    row = highest y. The YAML names the image by its bare file name and gives
    ``occupied_thresh: 0.65``, ``free_thresh: 0.196``, ``negate: 0``, ``mode: trinary``;
    ``resolution`` and ``origin`` are written with full precision, so loading the files gives
    back the grid's cells (as :meth:`OccupancyGrid.trinary`), resolution and origin exactly.

    Parameters
    ----------
    grid : OccupancyGrid
        The grid to write. Probabilities 1..99 are written as their state
        (:meth:`OccupancyGrid.trinary`: >= 50 occupied, otherwise free).
    yaml_path : str or os.PathLike
        Output YAML path, ending in ``.yaml`` or ``.yml``. The image goes beside it as
        ``<stem>.<image_format>``.
    image_format : {"pgm", "png"}, keyword-only
        Image file type (binary P5 PGM or 8-bit grey PNG).
    inputs : iterable of paths, keyword-only
        Files that must not be overwritten (the maps this one was made from). For a YAML among
        them, the image it names is protected too.

    Raises
    ------
    InputError
        Unknown ``image_format``, a YAML path without a .yaml/.yml suffix, an empty grid, an
        output that would overwrite one of ``inputs``, a missing or read-only output folder.

    Notes
    -----
    The pair is written as one set (:func:`save_maps`): the old YAML is taken away before the
    new image is renamed into place and the new YAML comes last, so a YAML never names an
    image of another write; on any failure or interrupt both files are left as they were.
    """
    save_maps([(grid, yaml_path)], image_format=image_format, inputs=inputs)


def save_maps(maps, report=None, *, image_format: str = "pgm", inputs=(), remove=()) -> None:
    """Write several maps and a report as one set of files (a merged map and its group maps).

    Parameters
    ----------
    maps : sequence of (OccupancyGrid, yaml path)
        The maps of the set; each is written as :func:`save_map` writes it.
    report : (path, bytes or str), optional
        A report written last, as the set's commit point: while it is absent the set is being
        written (or a write was killed); once present every file of the set is of one write.
        Without it, the first map's YAML is the commit point.
    image_format : {"pgm", "png"}, keyword-only
    inputs : iterable of paths, keyword-only
        Files that must not be overwritten or removed (and, for a map YAML, the image it names).
    remove : iterable of paths, keyword-only
        Files of an earlier write of this set that the new set does not have (for example a
        group map the new merge no longer finds); removed as part of the same commit.

    Raises
    ------
    InputError
        As :func:`save_map`; also two outputs of the set that are the same file.

    Notes
    -----
    Crash safety (:func:`fusionkit._atomic.write_set`): a reader never finds files of two
    writes together with the commit file; after a crash the next write to the same output
    finishes or undoes the interrupted one; two writers to one output end with one whole set.
    """
    maps = [(g, Path(y)) for g, y in maps]
    if not maps:
        raise InputError("save_maps needs at least one map to write")
    encoded = [encode_map(g, y, image_format=image_format) for g, y in maps]
    files = [(img, payload) for img, payload, _ in encoded]
    yamls = [(y, text) for (_, y), (_, _, text) in zip(maps, encoded)]
    if report is not None:
        rpath, rbytes = Path(report[0]), report[1]
        commit = (rpath, rbytes.encode("utf-8") if isinstance(rbytes, str) else bytes(rbytes))
        files += yamls
    else:
        commit = yamls[0]
        files += yamls[1:]
    remove = [Path(p) for p in remove if p is not None and os.path.lexists(p)]
    protected = _protected(inputs)
    check_not_input([y for y, _ in yamls] + [p for p, _ in files] + [commit[0]] + remove, protected)
    files += [(p, None) for p in remove]
    write_set(files, commit, hide_first=[y for y, _ in yamls])


def group_map_files(yaml_path) -> list[Path]:
    """The group maps of a merge written beside ``yaml_path`` (``NAME.groupK.yaml`` and its
    ``.pgm``/``.png``), found by name only (never by what a file says)."""
    yaml_path = Path(yaml_path)
    parent = yaml_path.parent if str(yaml_path.parent) else Path(".")
    pattern = re.compile(re.escape(yaml_path.stem) + r"\.group[1-9][0-9]{0,3}\.(yaml|yml|pgm|png)")
    try:
        names = os.listdir(parent)
    except OSError:
        return []
    return sorted(parent / n for n in names if pattern.fullmatch(n) and (parent / n).is_file())


def _protected(inputs) -> list[Path]:
    """``inputs`` plus the image each input YAML names (so that it is not overwritten either)."""
    import yaml

    out = []
    for p in inputs:
        if p is None:
            continue
        p = Path(p)
        out.append(p)
        if p.suffix.lower() in _YAML_SUFFIXES:
            try:
                doc = _safe_yaml(read_bytes(p, "map YAML", _MAX_YAML_BYTES))
                image = doc.get("image") if isinstance(doc, dict) else None
            except (FusionkitError, yaml.YAMLError, UnicodeError, ValueError, RecursionError):
                image = None
            if isinstance(image, str) and image.strip() and "\x00" not in image:
                ip = Path(image.strip())
                out.append(ip if ip.is_absolute() else p.parent / ip)
    return out
