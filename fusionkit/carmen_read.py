"""Real laser logs in the CARMEN format, turned into fusionkit robot logs (CONTRACTS section 3).

A CARMEN log is plain text, one record per line, the record type first. Two record types carry
a laser scan with a pose and are read here:

``FLASER n r_1 .. r_n x y theta odom_x odom_y odom_theta timestamp host logger_timestamp``
    ``n`` ranges (m) of a front laser covering 180 degrees counter-clockwise from -90 degrees
    (right) to +90 degrees (left) of the heading; ``x y theta`` is the laser pose (m, rad).
    The beam angles follow one rule (see :func:`flaser_geometry`): an even ``n`` has ``n``
    steps of ``180 / n`` degrees starting at -90 (intel: 180 beams, the last at +89 degrees),
    an odd ``n`` runs from -90 to +90 inclusive in ``180 / (n - 1)`` degree steps (orebro:
    181 beams).
``ROBOTLASER1 laser_type start_angle fov angular_res max_range accuracy remission_mode
n r_1 .. r_n m e_1 .. e_m laser_x laser_y laser_theta robot_x robot_y robot_theta tv rv
forward_safety side_safety turn_axis timestamp host logger_timestamp``
    Angles in radians; the scan's own geometry and maximum range are in the record, and the
    laser pose (not the robot pose) is the sensor pose stored.

Every other record type (``ODOM``, ``NEFF``, ``PARAM``, ``RAWLASER1``, comments starting with
``#``, ...) is skipped and counted by type, as are lines cut short or holding values that are
not numbers, and scans whose beam count (or angles) differ from the log's dominant scans.

No return
    A SICK scanner writes its maximum value when a beam returns nothing (intel: 81.83 m,
    orebro: 32.767 m) and a few error codes just below it (orebro: 32.759, 32.763, 32.765).
    The no-return value is the largest reading when it occurs more than once and is not the
    only value, else (a single stray reading above them) the most frequent reading within 1 %
    below the largest when at least one reading in a thousand has it (for ``ROBOTLASER1``: the
    record's ``max_range``); it and every reading within 0.1 % below it, or above it, become
    ``inf``. With ``max_range`` given, readings at or beyond it are no return too.
    ``range_max`` of the scan log is ``max_range`` when given, else the largest remaining
    reading, capped at ``range_cap`` (40 m).

Time order
    Scans are sorted by their timestamp (a stable sort: equal timestamps, for example a log
    whose timestamps are all 0, keep the file order); how many were out of order is counted.

Frames
    Poses are re-expressed in the frame of the first scan's pose (that robot's own map frame:
    the first pose becomes ``(0, 0, 0)``); the transform from that frame to the log's frame is
    returned with the result.

Reading is bounded: only a regular file is read, a line longer than :data:`MAX_LINE_BYTES` is
skipped (never held whole) and counted as ``too_long``, and a log of more than
:data:`MAX_READINGS` range readings is refused.
"""

from __future__ import annotations

import math
import os
from collections import Counter
from dataclasses import dataclass, field
from numbers import Real
from types import MappingProxyType
from typing import Mapping

import numpy as np

from ._atomic import _short, show
from ._inputs import regular_file
from .errors import InputError, ScanLogError
from .scanlog import ScanLog
from .transform import wrap_angle

__all__ = ["CarmenConfig", "CarmenStats", "CarmenLog", "read_carmen", "flaser_geometry",
           "NO_RETURN_BAND", "MAX_LINE_BYTES", "MAX_READINGS"]

#: Readings this fraction below the no-return value count as no return (scanner error codes).
NO_RETURN_BAND = 1e-3
#: Longest line read (bytes); a longer one (no laser has that many beams) is skipped and counted.
MAX_LINE_BYTES = 1 << 20
#: Most range readings one log may hold (about 0.8 GB while converting); a larger log is refused.
MAX_READINGS = 50_000_000


@dataclass(frozen=True)
class CarmenConfig:
    """How CARMEN ranges are interpreted.

    Attributes
    ----------
    max_range : float or None
        Usable sensor range (m). When given, readings at or beyond it are no return (FLASER
        logs are then not searched for a no-return value) and it is the scan log's
        ``range_max``; ``None`` detects the no-return value from the log.
    range_cap : float
        Largest ``range_max`` chosen when ``max_range`` is ``None`` (m).
    """

    max_range: float | None = None
    range_cap: float = 40.0

    def __post_init__(self):
        for name in ("max_range", "range_cap"):
            v = getattr(self, name)
            if v is None and name == "max_range":
                continue
            if isinstance(v, (bool, np.bool_)) or not isinstance(v, (Real, np.number)) \
                    or not (math.isfinite(v) and v > 0):
                none = " or None" if name == "max_range" else ""
                raise InputError(f"{name} must be a positive number of metres{none}, got {show(v)}")


@dataclass(frozen=True)
class CarmenStats:
    """What reading a CARMEN log found.

    Attributes
    ----------
    records : int
        Non-blank lines read (every record, whatever its type).
    scans : int
        Scans kept.
    kind : str
        Record type the kept scans came from (``"FLASER"`` or ``"ROBOTLASER1"``).
    skipped : Mapping[str, int]
        Lines not used, by reason: an unknown record type by its name (``"ODOM"``, ``"NEFF"``,
        ...), ``"comment"``, ``"truncated"`` (fewer fields than the record needs),
        ``"malformed"`` (a field that is not a number, a negative or NaN range, a non-finite
        pose) and ``"other_geometry"`` (a beam count or beam angles other than the dominant
        scans').
    out_of_order : int
        Kept scans whose timestamp was earlier than the one before them in the file (they are
        sorted into time order).
    no_return_value : float or None
        The detected (FLASER) or declared (ROBOTLASER1 ``max_range``) no-return reading (m);
        ``None`` when none was found or ``max_range`` was given for a FLASER log.
    no_return_readings : int
        Readings turned into ``inf`` (no return).
    """

    records: int
    scans: int
    kind: str
    skipped: Mapping[str, int]
    out_of_order: int
    no_return_value: float | None
    no_return_readings: int

    @property
    def skipped_total(self) -> int:
        return int(sum(self.skipped.values()))


@dataclass(frozen=True, eq=False)
class CarmenLog:
    """The scans of a CARMEN log in time order, in the log's own frame.

    Attributes
    ----------
    scans : ScanLog
        Poses in the log's frame (m, rad), ranges (m, ``inf`` = no return).
    timestamps : (N,) float64
        Timestamp per scan (s), sorted.
    stats : CarmenStats
    source : str
        The log path as given.
    """

    scans: ScanLog
    timestamps: np.ndarray
    stats: CarmenStats
    source: str



# -- reading ------------------------------------------------------------------------------------

def flaser_geometry(n: int) -> tuple[float, float]:
    """``(angle_min, angle_increment)`` (rad) of an ``n``-beam FLASER scan covering 180 degrees.

    An even ``n`` steps ``pi / n`` from ``-pi/2`` (the last beam at ``pi/2 - pi/n``: 180
    beams of 1 degree, as the intel log); an odd ``n`` runs from ``-pi/2`` to ``+pi/2``
    inclusive in ``pi / (n - 1)`` steps (181 beams of 1 degree, as the orebro log).
    """
    if n < 2:
        raise InputError(f"a FLASER scan needs at least 2 beams, got {n}")
    inc = math.pi / n if n % 2 == 0 else math.pi / (n - 1)
    return -math.pi / 2, inc


class _Scan:
    __slots__ = ("key", "ranges", "pose", "stamp", "max_range")

    def __init__(self, key, ranges, pose, stamp, max_range):
        self.key = key
        self.ranges = ranges
        self.pose = pose
        self.stamp = stamp
        self.max_range = max_range


class _Bad(Exception):
    def __init__(self, reason: str):
        self.reason = reason


def _floats(tokens) -> list[float]:
    try:
        return [float(t) for t in tokens]
    except ValueError:
        raise _Bad("malformed") from None


def _count(tokens, i: int) -> int:
    try:
        n = int(tokens[i])
    except ValueError:
        raise _Bad("malformed") from None
    if n < 0:
        raise _Bad("malformed")
    return n


def _check(ranges: list[float], pose: list[float]) -> None:
    if not all(math.isfinite(v) for v in pose):
        raise _Bad("malformed")
    if any(not (r >= 0) for r in ranges):  # catches NaN and negatives
        raise _Bad("malformed")


def _parse_flaser(tokens) -> _Scan:
    if len(tokens) < 2:
        raise _Bad("truncated")
    n = _count(tokens, 1)
    if n < 2:
        raise _Bad("malformed")
    need = 2 + n + 6 + 1  # ranges, laser pose, odometry pose, timestamp
    if len(tokens) < need:
        raise _Bad("truncated")
    vals = _floats(tokens[2:need])
    ranges, pose, stamp = vals[:n], vals[n:n + 3], vals[n + 6]
    _check(ranges, pose)
    amin, inc = flaser_geometry(n)
    return _Scan(("FLASER", n, round(amin, 9), round(inc, 9)), np.array(ranges), pose, stamp, None)


def _parse_robotlaser(tokens) -> _Scan:
    if len(tokens) < 10:
        raise _Bad("truncated")
    head = _floats(tokens[2:8])  # start_angle fov angular_res max_range accuracy remission_mode
    start, _fov, res, max_range = head[0], head[1], head[2], head[3]
    n = _count(tokens, 8)
    if n < 2 or not (math.isfinite(start) and math.isfinite(res) and res != 0):
        raise _Bad("malformed")
    if len(tokens) < 9 + n + 1:
        raise _Bad("truncated")
    m = _count(tokens, 9 + n)
    i = 10 + n + m  # laser pose
    need = i + 3 + 3 + 5 + 1  # laser pose, robot pose, tv rv fwd side turn, timestamp
    if len(tokens) < need:
        raise _Bad("truncated")
    ranges = _floats(tokens[9:9 + n])
    _floats(tokens[10 + n:i])
    rest = _floats(tokens[i:need])
    pose, stamp = rest[:3], rest[11]
    _check(ranges, pose)
    mr = max_range if math.isfinite(max_range) and max_range > 0 else None
    return _Scan(("ROBOTLASER1", n, round(start, 9), round(res, 9)), np.array(ranges), pose, stamp, mr)


_PARSERS = {"FLASER": _parse_flaser, "ROBOTLASER1": _parse_robotlaser}


def _no_return_value(ranges: np.ndarray) -> float | None:
    """The FLASER no-return value of ``ranges``: the largest reading when it repeats (and is not
    the only value); else, when a single stray reading tops them (acapulco: one 51.25 m above
    12,284 no-return readings of 51.14-51.15 m), the most frequent reading within 1 % below the
    largest when it repeats at least once in a thousand readings; else None."""
    if ranges.size == 0:
        return None
    top = float(ranges.max())
    if not (ranges < top * (1.0 - NO_RETURN_BAND)).any():
        return None                              # one value only: nothing tells it apart
    if int((ranges == top).sum()) >= 2:
        return top
    near = ranges[ranges >= top * (1.0 - 10 * NO_RETURN_BAND)]
    values, counts = np.unique(near, return_counts=True)
    k = int(np.argmax(counts))                   # the least of equally frequent values
    if counts[k] >= max(2, ranges.size // 1000):
        return float(values[k])
    return None


def read_carmen(path, config: CarmenConfig = CarmenConfig()) -> CarmenLog:
    """Read the FLASER / ROBOTLASER1 scans of a CARMEN log (see the module notes).

    Parameters
    ----------
    path : path-like
        The CARMEN log (plain text).
    config : CarmenConfig
        Range interpretation.

    Returns
    -------
    CarmenLog
        Scans in time order in the log's frame, with counts of what was skipped.

    Raises
    ------
    InputError
        The file cannot be read, or holds no usable FLASER or ROBOTLASER1 record.
    """
    path = regular_file(path, "CARMEN log")
    skipped: Counter = Counter()
    scans: list[_Scan] = []
    records = readings = 0
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
        with open(fd, "rb") as fh:
            for line in _lines(fh, skipped):
                tokens = line.decode("utf-8", errors="replace").split()
                if not tokens:
                    continue
                records += 1
                kind = tokens[0]
                if kind.startswith("#"):
                    skipped["comment"] += 1
                    continue
                parser = _PARSERS.get(kind)
                if parser is None:
                    skipped[kind[:32] if kind.isprintable() and kind.isascii() else "unreadable"] += 1
                    continue
                try:
                    scan = parser(tokens)
                except _Bad as bad:
                    skipped[bad.reason] += 1
                    continue
                readings += scan.ranges.size
                if readings > MAX_READINGS:
                    raise InputError(
                        f"{_short(path)}: the log holds more than {MAX_READINGS:,} range readings, more "
                        f"than fusionkit converts at once; cut it into parts and import each")
                scans.append(scan)
    except OSError as exc:
        raise InputError(f"{_short(path)}: cannot read the CARMEN log ({exc.strerror or exc})") from None
    if not scans:
        unusable = skipped.get("malformed", 0) + skipped.get("truncated", 0)
        if unusable:   # laser records there, none of them usable (a NaN pose in every one)
            raise InputError(f"{path}: none of its {unusable} laser records is usable "
                             f"({skipped.get('malformed', 0)} malformed: a field that is not a "
                             f"number, a negative or NaN range or a non-finite pose; "
                             f"{skipped.get('truncated', 0)} truncated); check the log")
        raise InputError(f"{path}: no FLASER or ROBOTLASER1 records in the log "
                         f"({records} lines read); is this a CARMEN laser log?")

    # Keep the dominant scan geometry (beam count and angles); count the rest.
    keys = Counter(s.key for s in scans)
    best = max(keys.values())
    key = next(s.key for s in scans if keys[s.key] == best)  # first seen among the most common
    if len(keys) > 1:
        skipped["other_geometry"] += len(scans) - best
        scans = [s for s in scans if s.key == key]
    kind, n, amin, inc = key

    ranges = np.array([s.ranges for s in scans], dtype=np.float64)
    poses = np.array([s.pose for s in scans], dtype=np.float64)
    stamps = np.array([s.stamp for s in scans], dtype=np.float64)
    out_of_order = int((np.diff(stamps) < 0).sum()) if len(stamps) > 1 else 0
    order = np.argsort(stamps, kind="stable")
    ranges, poses, stamps = ranges[order], poses[order], stamps[order]
    poses[:, 2] = wrap_angle(poses[:, 2])

    # No return: the scanner's maximum (the record's max_range for ROBOTLASER1, else the
    # largest reading when it repeats) and the error codes just below it.
    sentinel = None
    if kind == "ROBOTLASER1":
        mrs = [s.max_range for s in scans if s.max_range is not None]
        sentinel = Counter(mrs).most_common(1)[0][0] if mrs else None
    else:
        # (also with max_range given: a scanner's real maximum is often the user's max_range
        # too, and its no-return value, below it, was drawn as a ring of walls)
        sentinel = _no_return_value(ranges)
    no_return = np.zeros(ranges.shape, bool)
    if sentinel is not None:
        no_return |= ranges >= sentinel * (1.0 - NO_RETURN_BAND)
    if config.max_range is not None:
        no_return |= ranges >= config.max_range
    if no_return.all():
        # nothing returned from a wall: the map would be all free floor, no wall to merge on
        shortest = float(np.min(np.where(np.isfinite(ranges), ranges, np.inf)))
        # the shortest reading is no return by --max-range alone, not by the scanner's value
        if sentinel is None or shortest < sentinel * (1.0 - NO_RETURN_BAND):
            raise InputError(f"{_short(path)}: every reading is at or beyond --max-range "
                             f"{config.max_range:g} m (the shortest is {shortest:.2f} m): give the "
                             f"scanner's usable range, or leave --max-range out")
        raise InputError(f"{_short(path)}: no reading of the log returned from a wall (all "
                         f"{ranges.size} are the scanner's no-return value): nothing to map")
    ranges[no_return] = np.inf
    if config.max_range is not None:
        range_max = float(config.max_range)
    else:
        finite = ranges[np.isfinite(ranges)]
        largest = float(finite.max()) if finite.size else config.range_cap
        range_max = min(largest, config.range_cap) if largest > 0 else config.range_cap

    stats = CarmenStats(
        records=records, scans=len(scans), kind=kind,
        skipped=MappingProxyType(dict(sorted(skipped.items()))), out_of_order=out_of_order,
        no_return_value=sentinel, no_return_readings=int(no_return.sum()))
    try:
        log = ScanLog(poses, ranges.astype(np.float32), amin, inc, range_max)
    except ScanLogError as exc:   # poses 1e308 m away: said of this log
        raise InputError(f"{_short(path)}: {exc}") from None
    stamps.setflags(write=False)
    return CarmenLog(log, stamps, stats, str(path))


def _lines(fh, skipped: Counter):
    """The lines of a binary file; a line longer than :data:`MAX_LINE_BYTES` is skipped (read
    through in blocks, never held whole) and counted as ``too_long``."""
    while True:
        line = fh.readline(MAX_LINE_BYTES + 1)
        if not line:
            return
        if len(line) > MAX_LINE_BYTES and not line.endswith(b"\n"):
            while True:
                rest = fh.readline(MAX_LINE_BYTES)
                if not rest or rest.endswith(b"\n"):
                    break
            skipped["too_long"] += 1
            continue
        yield line
