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
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ._atomic import write_bytes_atomic
from .errors import ScanLogError

__all__ = ["ScanLog", "load_scans", "save_scans", "encode_scans", "scans_path_for"]

_KEYS = ("poses", "ranges", "angle_min", "angle_increment", "range_max")


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
            v = float(np.asarray(getattr(self, name)).reshape(()))
            if not math.isfinite(v):
                raise ScanLogError(f"{name} must be a finite number, got {v}")
            object.__setattr__(self, name, v)
        if self.angle_increment == 0:
            raise ScanLogError("angle_increment must not be 0")
        if self.range_max <= 0:
            raise ScanLogError(f"range_max must be > 0 m, got {self.range_max}")
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
        return ScanLog(self.poses[index], self.ranges[index], self.angle_min,
                       self.angle_increment, self.range_max)

    def endpoints(self, index=None) -> np.ndarray:
        """Map-frame points (m) of the beams that returned, shape ``(K, 2)``."""
        poses = self.poses if index is None else self.poses[index]
        ranges = self.ranges if index is None else self.ranges[index]
        ang = poses[:, 2:3] + self.beam_angles[None, :]
        hit = np.isfinite(ranges) & (ranges <= self.range_max)
        r = np.where(hit, ranges, 0.0)
        x = poses[:, 0:1] + r * np.cos(ang)
        y = poses[:, 1:2] + r * np.sin(ang)
        return np.stack([x[hit], y[hit]], axis=-1)


def scans_path_for(map_yaml) -> Path:
    """``NAME.scans.npz`` beside ``NAME.yaml``."""
    p = Path(map_yaml)
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
    write_bytes_atomic(path, encode_scans(log))


def load_scans(path) -> ScanLog:
    """Read a ``.scans.npz``; raise :class:`ScanLogError` naming the file on any problem."""
    path = Path(path)
    if not path.is_file():
        raise ScanLogError(f"{path}: scan log not found")
    try:
        with np.load(path, allow_pickle=False) as z:
            missing = [k for k in _KEYS if k not in z.files]
            if missing:
                raise ScanLogError(f"{path}: missing key(s) {', '.join(missing)}; a scan log needs "
                                   f"{', '.join(_KEYS)}")
            arrays = {k: z[k] for k in _KEYS}
    except ScanLogError:
        raise
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise ScanLogError(f"{path}: not a readable .npz scan log ({exc})") from None
    for k in ("angle_min", "angle_increment", "range_max"):
        if np.asarray(arrays[k]).size != 1:
            raise ScanLogError(f"{path}: {k} must be a single number")
    try:
        return ScanLog(**arrays)
    except ScanLogError as exc:
        raise ScanLogError(f"{path}: {exc}") from None
