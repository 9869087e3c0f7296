"""The map_server YAML of a map: read, validated, bounded (CONTRACTS section 2).

Keys ``image`` (resolved relative to the YAML file), ``resolution``, ``origin``, ``negate``,
``occupied_thresh``, ``free_thresh`` and optional ``mode``. The file must be a regular file of
at most 1 MiB; YAML aliases (``*name``, the "billion laughs" flood) are refused; numbers must be
finite and within sane bounds; values quoted in an error are cut short.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from ._atomic import _short, show
from ._inputs import read_bytes
from .errors import MapFormatError

__all__ = ["MAP_MODES"]

#: Interpretations of the pixel values a map YAML may ask for with ``mode``.
MAP_MODES = ("trinary", "scale", "raw")

_REQUIRED_KEYS = ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh")
_YAML_SUFFIXES = (".yaml", ".yml")
_MAX_YAML_BYTES = 1 << 20  # a map YAML is a few hundred bytes; anything this big is not one
#: Sane bounds of a map's geometry (a map YAML outside them is corrupt, not a map).
_RESOLUTION_RANGE = (1e-9, 1e6)  # metres per pixel
_ORIGIN_LIMIT = 1e9  # metres
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


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

        def construct_mapping(self, node, deep=False):
            # a key given twice: PyYAML keeps the last value, map_server's reader may keep
            # another; which one the map means is not for a reader to guess
            seen = set()
            for key_node, _ in node.value:
                key = key_node.value if isinstance(key_node, yaml.ScalarNode) else None
                if key is not None and key in seen:
                    raise yaml.constructor.ConstructorError(
                        None, None, f"the key {key!r} is given twice; keep one",
                        key_node.start_mark)
                seen.add(key)
            return super().construct_mapping(node, deep=deep)

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
    if image_path.is_dir():   # said of the YAML that names it ('image: .')
        raise MapFormatError(f"{_short(yaml_path)}: 'image' names the directory {show(image)}, "
                             f"not a map image; fix the 'image' key")

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
    if abs(origin[2]) > 2 * math.pi:
        # yaw 90 (degrees) turned the map by 90 rad (2.04 rad once wrapped), without a word
        raise MapFormatError(
            f"{_short(yaml_path)}: the origin's yaw {origin[2]:g} is more than a full turn: "
            f"give it in radians (as map_server reads it), e.g. {math.radians(origin[2]):.6g} "
            f"for {origin[2]:g} degrees")

    negate = doc["negate"]
    if isinstance(negate, bool):
        negate = bool(negate)
    elif isinstance(negate, int) and negate in (0, 1):
        negate = bool(negate)
    elif isinstance(negate, str) and negate.strip() in ("0", "1"):
        negate = negate.strip() == "1"   # quoted, as the numbers may be (map_server reads it so)
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
