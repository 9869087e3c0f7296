"""Coercion of settings values with one-line errors (shared by the settings dataclasses)."""

from __future__ import annotations

import math

import numpy as np

from ._atomic import show
from .errors import InputError

__all__ = ["number", "whole"]


def number(value, name: str) -> float:
    """``value`` as a finite float, or :class:`InputError` naming ``name``."""
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{name} must be a number, got {show(value)}") from None
    if not math.isfinite(v):
        raise InputError(f"{name} must be a finite number, got {show(value)}")
    return v


def whole(value, name: str) -> int:
    """``value`` as an int (a float only when it is integral), or :class:`InputError`."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        if isinstance(value, float) and value.is_integer():
            return int(value)
        raise InputError(f"{name} must be a whole number, got {show(value)}")
    return int(value)
