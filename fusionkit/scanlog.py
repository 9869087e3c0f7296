"""Scan logs: what a robot recorded (CONTRACTS section 3).

``NAME.scans.npz`` beside ``NAME.yaml`` holds ``poses`` (N, 3) float64 (x, y, theta of the
sensor in that robot's map frame), ``ranges`` (N, B) float32 (m; ``inf`` or > ``range_max``
means no return), ``angle_min``, ``angle_increment`` (rad) and ``range_max`` (m), mirroring
``sensor_msgs/LaserScan``.
"""

from __future__ import annotations

import io
import math
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ._atomic import _short, show, write_bytes_atomic
from ._inputs import path_arg, regular_file
from ._validate import own_array
from .errors import InputError, ScanLogError

__all__ = ["ScanLog", "load_scans", "save_scans", "encode_scans", "scans_path_for"]

_KEYS = ("poses", "ranges", "angle_min", "angle_increment", "range_max")
#: Largest sensor range accepted (m); larger is a corrupt log, not a LIDAR.
MAX_RANGE = 1e5
#: Poses farther than this from the origin (m) are a corrupt log.
MAX_COORDINATE = 1e9
#: Most bytes the arrays of one scan log may take once loaded (a zip bomb is refused unread).
MAX_SCAN_BYTES = 2_000_000_000
_ZIP_SIGNATURES = (b"PK\x03\x04", b"PK\x05\x06")


@dataclass(frozen=True, eq=False)
class ScanLog:
    """Poses and 2-D LIDAR ranges of one robot, in its own map frame.

    Attributes
    ----------
    poses : (N, 3) float64
        Sensor pose per scan: x, y (m), theta (rad).
    ranges : (N, B) float32
        Range per beam (m); ``inf`` or values above ``range_max`` mean no return.
    angle_min, angle_increment : float
        Angle of beam 0 relative to the heading, and between beams (rad).
    range_max : float
        Sensor range (m).
    """

    poses: np.ndarray
    ranges: np.ndarray
    angle_min: float
    angle_increment: float
    range_max: float

    def __post_init__(self):
        for name in ("poses", "ranges"):
            kind = np.asarray(getattr(self, name)).dtype.kind
            if kind not in "fiu":
                what = {"c": "complex numbers", "U": "text", "S": "text", "O": "Python objects",
                        "b": "true/false values"}.get(kind, f"values of type {np.asarray(getattr(self, name)).dtype}")
                raise ScanLogError(f"{name} must hold real numbers (metres, radians), not {what}")
        with np.errstate(over="ignore"):  # ranges beyond float32 are no return (inf) anyway
            poses = np.ascontiguousarray(self.poses, dtype=np.float64)
            ranges = np.ascontiguousarray(self.ranges, dtype=np.float32)
        if poses.ndim != 2 or poses.shape[1] != 3:
            raise ScanLogError(f"poses must have shape (N, 3) as x, y, theta; got {poses.shape}")
        if ranges.ndim != 2:
            raise ScanLogError(f"ranges must have shape (N, beams); got {ranges.shape}")
        if ranges.shape[0] != poses.shape[0]:
            raise ScanLogError(
                f"{ranges.shape[0]} scans but {poses.shape[0]} poses: each scan needs exactly one pose")
        if ranges.shape[1] < 2:
            raise ScanLogError(f"a scan needs at least 2 beams; got {ranges.shape[1]}")
        if not np.isfinite(poses).all():
            raise ScanLogError("poses contain NaN or infinite values; drop or repair those scans")
        if np.isnan(ranges).any():
            n = int(np.isnan(ranges).any(axis=1).sum())
            raise ScanLogError(
                f"ranges contain NaN in {n} scan(s); write no-return beams as inf, not NaN")
        if (ranges < 0).any():
            raise ScanLogError("ranges contain negative values; ranges are distances in metres (>= 0)")
        for name in ("angle_min", "angle_increment", "range_max"):
            a = np.asarray(getattr(self, name))
            if a.dtype.kind not in "fiu" or a.size != 1:
                raise ScanLogError(f"{name} must be a single real number")
            v = float(a.reshape(()))
            if not math.isfinite(v):
                raise ScanLogError(f"{name} must be a finite number, got {v:.6g}")
            object.__setattr__(self, name, v)
        if self.angle_increment == 0:
            raise ScanLogError("angle_increment must not be 0")
        if not 0 < self.range_max <= MAX_RANGE:
            raise ScanLogError(f"range_max must be > 0 m and at most {MAX_RANGE:g} m, got {self.range_max:.6g}")
        if np.abs(poses[:, :2]).max(initial=0.0) > MAX_COORDINATE:
            raise ScanLogError(f"poses lie more than {MAX_COORDINATE:g} m from the origin; the log "
                               f"is corrupt or not in metres")
        span = abs(self.angle_increment) * (ranges.shape[1] - 1)
        if span > 2 * math.pi + abs(self.angle_increment) or abs(self.angle_min) > 2 * math.pi:
            raise ScanLogError(f"the beams span {span:.6g} rad from angle_min {self.angle_min:.6g} rad, "
                               f"more than a full turn: give angle_min and angle_increment in radians")
        # the caller's arrays (or views of them) are neither frozen nor aliased
        poses, ranges = (own_array(a, getattr(self, name)) for a, name in ((poses, "poses"), (ranges, "ranges")))
        poses.setflags(write=False)
        ranges.setflags(write=False)
        object.__setattr__(self, "poses", poses)
        object.__setattr__(self, "ranges", ranges)

    @property
    def n_scans(self) -> int:
        return self.ranges.shape[0]

    @property
    def n_beams(self) -> int:
        return self.ranges.shape[1]

    @property
    def beam_angles(self) -> np.ndarray:
        """Angle of each beam relative to the heading (rad), shape ``(B,)``."""
        return self.angle_min + self.angle_increment * np.arange(self.n_beams)

    @property
    def field_of_view(self) -> float:
        """Angular span covered by the beams (rad)."""
        return abs(self.angle_increment) * self.n_beams

    def clipped_ranges(self) -> np.ndarray:
        """Ranges with no-return beams (inf or > range_max) set to ``range_max``, float32."""
        r = np.where(np.isfinite(self.ranges), self.ranges, self.range_max)
        return np.minimum(r, self.range_max).astype(np.float32)

    def hit_mask(self) -> np.ndarray:
        """True where a beam returned (finite and <= range_max)."""
        return np.isfinite(self.ranges) & (self.ranges <= self.range_max)

    def subset(self, index) -> "ScanLog":
        """The scans at ``index`` (slice, mask or integer array)."""
        poses, ranges = self._at(index)
        return ScanLog(poses, ranges, self.angle_min, self.angle_increment, self.range_max)

    def _at(self, index):
        """Poses and ranges at ``index``, or :class:`ScanLogError` for an index out of range."""
        try:
            return self.poses[index], self.ranges[index]
        except IndexError as exc:
            raise ScanLogError(f"{exc} (a log of {self.n_scans} scans): give scan indices in "
                               f"0..{self.n_scans - 1}, a slice or a mask of {self.n_scans}") from None

    def endpoints(self, index=None) -> np.ndarray:
        """Map-frame points (m) of the beams that returned, shape ``(K, 2)``."""
        poses, ranges = (self.poses, self.ranges) if index is None else self._at(index)
        ang = poses[:, 2:3] + self.beam_angles[None, :]
        hit = np.isfinite(ranges) & (ranges <= self.range_max)
        r = np.where(hit, ranges, 0.0)
        x = poses[:, 0:1] + r * np.cos(ang)
        y = poses[:, 1:2] + r * np.sin(ang)
        return np.stack([x[hit], y[hit]], axis=-1)


def scans_path_for(map_yaml) -> Path:
    """``NAME.scans.npz`` beside ``NAME.yaml``."""
    p = path_arg(map_yaml, "the map's YAML")
    if not p.name:
        raise InputError(f"{p}: is a folder, not a map's YAML; give the file's path")
    return p.with_name(p.stem + ".scans.npz")


def encode_scans(log: ScanLog) -> bytes:
    """The bytes of ``log`` as a ``.scans.npz`` (CONTRACTS section 3), for writing in a set."""
    buf = io.BytesIO()
    np.savez_compressed(
        buf, poses=log.poses, ranges=log.ranges, angle_min=np.float64(log.angle_min),
        angle_increment=np.float64(log.angle_increment), range_max=np.float64(log.range_max))
    return buf.getvalue()


def save_scans(path, log: ScanLog) -> None:
    """Write ``log`` to ``path`` (``.scans.npz``) atomically, in the CONTRACTS section 3 layout."""
    if not isinstance(log, ScanLog):
        swapped = (" (the path comes first here, unlike save_map(grid, path))"
                   if isinstance(path, ScanLog) else "")
        raise ScanLogError(f"save_scans(path, log) writes a ScanLog, got {type(log).__name__}{swapped}")
    write_bytes_atomic(path_arg(path, "the scan log's path"), encode_scans(log))


def load_scans(path) -> ScanLog:
    """Read a ``.scans.npz``; raise :class:`ScanLogError` naming the file on any problem.

    The file must be a regular file holding an npz archive (never pickled data) whose arrays
    together take at most :data:`MAX_SCAN_BYTES` once loaded; each array's header is checked
    against its stored size before anything is decompressed.
    """
    path = regular_file(path, "scan log", ScanLogError)
    name = _short(path)
    try:
        with open(path, "rb") as fh:
            magic = fh.read(4)
    except OSError as exc:
        raise ScanLogError(f"{name}: the scan log cannot be read ({exc.strerror or exc})") from None
    if magic not in _ZIP_SIGNATURES:
        raise ScanLogError(f"{name}: is not an .npz scan log (an npz is a zip archive of arrays, "
                           f"this file is not one); write it with numpy.savez or fusionkit")
    try:
        with zipfile.ZipFile(path) as zf:
            members = {i.filename: i for i in zf.infolist()}
            missing = [k for k in _KEYS if k + ".npy" not in members]
            if missing:
                raise ScanLogError(f"{name}: missing key(s) {', '.join(missing)}; a scan log needs "
                                   f"{', '.join(_KEYS)}")
            total = sum(members[k + ".npy"].file_size for k in _KEYS)
            if total > MAX_SCAN_BYTES:
                raise ScanLogError(
                    f"{name}: its arrays take {total / 1e9:.1f} GB once loaded, more than the "
                    f"{MAX_SCAN_BYTES / 1e9:.0f} GB fusionkit reads from one scan log; record "
                    f"fewer scans per log")
            arrays = {k: _read_member(zf, members[k + ".npy"], k, name) for k in _KEYS}
    except ScanLogError:
        raise
    except (OSError, ValueError, zipfile.BadZipFile, EOFError, NotImplementedError,
            RuntimeError, zlib.error) as exc:
        raise ScanLogError(f"{name}: not a readable .npz scan log ({show(str(exc), 100)}); "
                           f"it may be truncated: write it again") from None
    try:
        return ScanLog(**arrays)
    except ScanLogError as exc:
        raise ScanLogError(f"{name}: {exc}") from None


def _read_member(zf: zipfile.ZipFile, info: zipfile.ZipInfo, key: str, name: str) -> np.ndarray:
    """One array of the archive, its header checked before the data is read."""
    fmt = np.lib.format
    with zf.open(info) as fh:
        version = fmt.read_magic(fh)
        if version == (1, 0):
            shape, fortran, dtype = fmt.read_array_header_1_0(fh, max_header_size=10000)
        elif version in ((2, 0), (3, 0)):
            shape, fortran, dtype = fmt.read_array_header_2_0(fh, max_header_size=10000)
        else:
            raise ScanLogError(f"{name}: {key} is stored in an unknown .npy version {version}")
        if dtype.hasobject:
            raise ScanLogError(f"{name}: {key} holds Python objects (pickled data), which fusionkit "
                               f"never loads; store it as an array of numbers")
        count = 1
        for n in shape:
            count *= int(n)
        if count * dtype.itemsize > info.file_size:
            raise ScanLogError(
                f"{name}: the header of {key} declares {count * dtype.itemsize / 1e9:.3g} GB of "
                f"data but the archive holds {info.file_size} bytes; the file is corrupt: write it again")
        data = fh.read(count * dtype.itemsize)
    if len(data) != count * dtype.itemsize:
        raise ScanLogError(f"{name}: {key} is truncated; the file is incomplete: write it again")
    return np.frombuffer(data, dtype=dtype).reshape(shape, order="F" if fortran else "C")
