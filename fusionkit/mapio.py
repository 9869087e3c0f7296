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

import contextlib
import hashlib
import os
import re
from pathlib import Path

import numpy as np

from ._atomic import _digest, _parent, _short, check_not_input, recover_folder, show, write_set
from ._inputs import path_arg, read_bytes
from .errors import FusionkitError, InputError, MapFormatError
from .grid import FREE, OCCUPIED, OccupancyGrid
from .map_image import MAX_IMAGE_BYTES, _image_header, _pixels_to_cells, _read_pixels
from .map_yaml import _MAX_YAML_BYTES, _YAML_SUFFIXES, MAP_MODES, _read_yaml, _safe_yaml
from .scanlog import scans_path_for

__all__ = ["load_map", "save_map", "save_maps", "encode_map", "map_info", "group_map_files",
           "MAP_MODES", "IMAGE_FORMATS", "MAX_IMAGE_BYTES"]

#: Image formats :func:`save_map` writes.
IMAGE_FORMATS = ("pgm", "png")

# What map_saver writes (ROS 1 map_saver.cpp defaults).
_SAVE_OCCUPIED_THRESH = 0.65
_SAVE_FREE_THRESH = 0.196
_PIXEL_OCCUPIED, _PIXEL_FREE, _PIXEL_UNKNOWN = 0, 254, 205


@contextlib.contextmanager
def _named_by(yaml_path: Path, image: Path):
    """A fault of a map's image named by the map's YAML too: among several maps given, the YAML
    is the file the user named, and an image may be shared or named by mistake (another map's
    YAML)."""
    try:
        yield
    except MapFormatError as exc:
        message = str(exc)
        for name in (str(image), _short(image)):
            if message.startswith(name + ": "):
                raise MapFormatError(f"{yaml_path}: its image {message}") from None
        raise


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
    yaml_path = path_arg(yaml_path, "the map's YAML")
    # a write of fusionkit's that a kill cut short there is finished or undone first (unless
    # a write holds the folder now), so that the YAML and its image are of one write
    recover_folder(_parent(yaml_path), wait=False)
    meta = _read_yaml(yaml_path)
    if not os.path.lexists(meta.image):
        raise MapFormatError(
            f"{yaml_path}: the image {meta.image} it names does not exist; fix the 'image' key or "
            f"restore the file")
    with _named_by(yaml_path, meta.image):
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
    yaml_path = path_arg(yaml_path, "the map's YAML")
    meta = _read_yaml(yaml_path)
    if not os.path.lexists(meta.image):
        raise MapFormatError(
            f"{yaml_path}: the image {meta.image} it names does not exist; fix the 'image' key or "
            f"restore the file")
    with _named_by(yaml_path, meta.image):
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
    if not isinstance(grid, OccupancyGrid):
        raise InputError(f"save_map(grid, yaml_path) writes an OccupancyGrid first, got "
                         f"{type(grid).__name__}")
    save_maps([(grid, path_arg(yaml_path, "the output YAML"))], image_format=image_format,
              inputs=inputs)


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
    # a YAML to remove goes before its image, so that no YAML names a missing image mid-commit
    remove = sorted((Path(p) for p in remove if p is not None and os.path.lexists(p)),
                    key=lambda p: p.suffix.lower() not in _YAML_SUFFIXES)
    protected = _protected(inputs)
    check_not_input([y for y, _ in yamls] + [p for p, _ in files] + [commit[0]] + remove, protected)
    files += [(p, None) for p in remove]
    write_set(files, commit, hide_first=[y for y, _ in yamls])


def map_digest(yaml_path) -> str:
    """SHA-256 of a map's YAML and the image it names, read as bytes: what a merge report keeps
    of each input, so that an evaluation can tell the file merged from a later one of that
    name (a new run written into the same folder)."""
    h = hashlib.sha256()
    for p in _protected([yaml_path]):
        h.update(f"{p.name}:{_digest(p) or '-'};".encode())
    return h.hexdigest()


def merge_reports(folder) -> list[tuple[Path, dict]]:
    """The merge reports among the ``*.json`` files directly in ``folder`` (any name: ``merge
    --report R.json``), read: those holding a ``maps`` list and an ``output`` path. Unreadable
    or other JSON files are passed over."""
    from ._inputs import read_json

    try:
        entries = sorted(Path(folder).iterdir())
    except OSError:
        return []
    found = []
    for p in entries:
        if p.suffix.lower() != ".json" or not p.is_file():
            continue
        try:
            doc = read_json(p, "merge report")
        except (FusionkitError, OSError):
            continue
        if isinstance(doc, dict) and isinstance(doc.get("maps"), list) \
                and isinstance(doc.get("output"), str):
            found.append((p, doc))
    return found


#: what a group map's name adds to its merge output's stem: ``NAME.group1.yaml``, ...
GROUP_SUFFIX = r"\.group[1-9][0-9]{0,3}"


def group_map_files(yaml_path) -> list[Path]:
    """The group maps of a merge written beside ``yaml_path`` (``NAME.groupK.yaml`` and its
    ``.pgm``/``.png``), found by name only (never by what a file says)."""
    yaml_path = Path(yaml_path)
    parent = yaml_path.parent if str(yaml_path.parent) else Path(".")
    pattern = re.compile(re.escape(yaml_path.stem) + GROUP_SUFFIX + r"\.(yaml|yml|pgm|png)")
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
