"""Rigid 2-D transforms (CONTRACTS section 4).

A :class:`Transform2D` ``T = {x, y, theta}`` maps a point ``p`` of one frame (metres) to another:
``T(p) = R(theta) @ p + (x, y)``. Composition follows function composition:
``(A @ B)(p) == A(B(p))``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._validate import digits_arg
from .errors import InputError

__all__ = ["Transform2D", "wrap_angle"]


def wrap_angle(theta):
    """Wrap an angle (radians, scalar or array) into ``[-pi, pi)``."""
    if isinstance(theta, (float, int)) or np.ndim(theta) == 0:
        # plain arithmetic for a scalar: transforms are made in inner loops
        return (float(theta) + math.pi) % (2.0 * math.pi) - math.pi
    return (np.asarray(theta) + np.pi) % (2.0 * np.pi) - np.pi


@dataclass(frozen=True)
class Transform2D:
    """A rigid motion of the plane: rotation ``theta`` (rad) then translation ``(x, y)`` (m).

    Examples
    --------
    >>> T = Transform2D(1.0, 2.0, math.pi / 2)
    >>> T([[1.0, 0.0]]).round(6).tolist()
    [[1.0, 3.0]]
    >>> (T @ T.inverse).is_close(Transform2D.identity())
    True
    """

    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0

    def __post_init__(self):
        try:
            x, y, theta = float(self.x), float(self.y), float(self.theta)
        except (TypeError, ValueError):
            raise InputError(f"a transform's x, y, theta must be numbers, got "
                             f"{self.x!r}, {self.y!r}, {self.theta!r}") from None
        for name, v in (("x", x), ("y", y), ("theta", theta)):
            if not math.isfinite(v):
                raise InputError(f"transform {name} must be finite, got {v}")
        object.__setattr__(self, "x", x)
        object.__setattr__(self, "y", y)
        object.__setattr__(self, "theta", wrap_angle(theta))

    # -- constructors -------------------------------------------------------------------------
    @classmethod
    def identity(cls) -> "Transform2D":
        return cls(0.0, 0.0, 0.0)

    @classmethod
    def from_matrix(cls, m) -> "Transform2D":
        """From a 3x3 homogeneous (or 2x3) matrix; the rotation part is orthonormalised."""
        try:
            m = np.asarray(m, dtype=float)
        except (TypeError, ValueError):
            raise InputError(f"expected a 3x3 or 2x3 matrix of numbers, got {m!r}") from None
        if m.shape not in ((3, 3), (2, 3)):
            raise InputError(f"expected a 3x3 or 2x3 matrix, got shape {m.shape}")
        if not np.isfinite(m).all():
            raise InputError("the matrix holds NaN or infinite values")
        if m.shape == (3, 3) and not np.allclose(m[2], (0.0, 0.0, 1.0), atol=1e-6):
            raise InputError(f"a rigid motion's matrix has the last row 0 0 1, got {m[2].tolist()}")
        sv, det = np.linalg.svd(m[:2, :2], compute_uv=False), np.linalg.det(m[:2, :2])
        if det <= 0 or np.abs(sv - 1.0).max() > 0.01:
            # atan2 of a reflection or a scaling gives some rotation: not the motion given
            raise InputError(f"the matrix's 2x2 part is not a rotation (singular values "
                             f"{sv[0]:.4g}, {sv[1]:.4g}, determinant {det:.4g}): "
                             f"a reflection or a scaling is not a rigid motion")
        return cls(m[0, 2], m[1, 2], math.atan2(m[1, 0] - m[0, 1], m[0, 0] + m[1, 1]))

    @classmethod
    def from_dict(cls, d) -> "Transform2D":
        """From ``{"x": .., "y": .., "theta": ..}`` as in truth.json and merge reports."""
        try:
            return cls(float(d["x"]), float(d["y"]), float(d["theta"]))
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"a transform needs numeric keys x, y, theta; got {d!r}") from exc

    @classmethod
    def from_paper(cls, dx: float, dy: float, dphi: float) -> "Transform2D":
        """The paper's eq. (4): translate by ``(dx, dy)`` first, then rotate by ``dphi``.

        ``x' = (x + dx) cos(dphi) - (y + dy) sin(dphi)``,
        ``y' = (x + dx) sin(dphi) + (y + dy) cos(dphi)``; i.e. ``R(dphi) @ (p + d)``.
        """
        try:
            dx, dy, dphi = float(dx), float(dy), float(dphi)
        except (TypeError, ValueError):
            raise InputError(f"dx, dy, dphi must be numbers, got {dx!r}, {dy!r}, {dphi!r}") from None
        c, s = math.cos(dphi), math.sin(dphi)
        return cls(c * dx - s * dy, s * dx + c * dy, dphi)

    def to_paper(self) -> tuple[float, float, float]:
        """Inverse of :meth:`from_paper`: ``(dx, dy, dphi)`` with
        ``from_paper(dx, dy, dphi).is_close(self)`` (equal up to rounding)."""
        c, s = math.cos(self.theta), math.sin(self.theta)
        return (c * self.x + s * self.y, -s * self.x + c * self.y, self.theta)

    # -- algebra -------------------------------------------------------------------------------
    @property
    def matrix(self) -> np.ndarray:
        """The 3x3 homogeneous matrix."""
        c, s = math.cos(self.theta), math.sin(self.theta)
        return np.array([[c, -s, self.x], [s, c, self.y], [0.0, 0.0, 1.0]])

    @property
    def inverse(self) -> "Transform2D":
        c, s = math.cos(self.theta), math.sin(self.theta)
        return Transform2D(-(c * self.x + s * self.y), -(-s * self.x + c * self.y), -self.theta)

    def __matmul__(self, other: "Transform2D") -> "Transform2D":
        if not isinstance(other, Transform2D):
            return NotImplemented
        c, s = math.cos(self.theta), math.sin(self.theta)
        return Transform2D(
            c * other.x - s * other.y + self.x,
            s * other.x + c * other.y + self.y,
            self.theta + other.theta,
        )

    def __call__(self, points) -> np.ndarray:
        """Apply to points of shape ``(2,)`` or ``(N, 2)`` (metres); returns float64 array."""
        p = np.asarray(points, dtype=float)
        if p.ndim == 0 or p.shape[-1] != 2:
            raise InputError(f"a transform applies to points of shape (2,) or (N, 2), got shape {p.shape}")
        c, s = math.cos(self.theta), math.sin(self.theta)
        x, y = p[..., 0], p[..., 1]
        return np.stack([c * x - s * y + self.x, s * x + c * y + self.y], axis=-1)

    def apply_pose(self, poses) -> np.ndarray:
        """Apply to poses ``(N, 3)`` ``(x, y, heading)``: positions moved, headings turned."""
        p = np.asarray(poses, dtype=float)
        if p.ndim == 0 or p.shape[-1] != 3:
            raise InputError(f"apply_pose takes poses of shape (3,) or (N, 3), got shape {p.shape}")
        out = np.empty_like(p)
        out[..., :2] = self(p[..., :2])
        out[..., 2] = wrap_angle(p[..., 2] + self.theta)
        return out

    # -- comparisons ------------------------------------------------------------------------------
    def error_to(self, other: "Transform2D") -> tuple[float, float]:
        """``(translation error in m, |rotation error| in rad)`` between two transforms."""
        if not isinstance(other, Transform2D):
            raise InputError(f"error_to compares with a Transform2D, got {type(other).__name__}")
        return (math.hypot(self.x - other.x, self.y - other.y),
                abs(float(wrap_angle(self.theta - other.theta))))

    def is_close(self, other: "Transform2D", atol: float = 1e-9) -> bool:
        dt, dr = self.error_to(other)
        return dt <= atol and dr <= atol

    def as_dict(self, digits: int | None = 6) -> dict:
        digits = digits_arg(digits)
        r = (lambda v: round(v, digits)) if digits is not None else float
        return {"x": r(self.x), "y": r(self.y), "theta": r(self.theta)}
