"""Map images: PGM (P5 8/16-bit, P2) and PNG headers, pixels, and map_server's pixel rule.

Headers are parsed and the image's size checked (cells, and bytes once decoded) before any
pixel is decoded, so a decompression bomb is refused from its first bytes; only regular files
are opened. :func:`_pixels_to_cells` applies map_server / nav2_map_server semantics (see
:mod:`fusionkit.mapio`).
"""

from __future__ import annotations

import os
import re
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ._atomic import _short
from ._inputs import regular_file
from .errors import MapFormatError
from .grid import FREE, OCCUPIED, UNKNOWN
from .map_yaml import _PNG_SIGNATURE, _MapYaml
from .mapping import MAX_CELLS

__all__ = ["MAX_IMAGE_BYTES"]

_MAX_HEADER_BYTES = 1 << 16  # PNM headers (with comments) longer than this are refused
#: Most bytes a map image may decode to (width x height x channels x bytes per sample): a
#: decompression bomb is refused from its header, before any pixel is decoded.
MAX_IMAGE_BYTES = 800_000_000
_MAX_PLAIN_PGM_PIXELS = 20_000_000  # P2 is text: ~40 bytes of memory per pixel while parsing
_WHITESPACE = b" \t\r\n\v\f"


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
    elif re.search(rb"(^|[{,\s])image\s*:", head) and re.search(rb"(^|[{,\s])resolution\s*:", head):
        raise MapFormatError(f"{path}: a map YAML, not an image; the 'image' key must name the map's "
                             f"PGM or PNG file")
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
