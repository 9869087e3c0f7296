"""Coercion of settings values with one-line errors (shared by the settings dataclasses)."""

from __future__ import annotations

import math
import os

import numpy as np

from ._atomic import show
from .errors import InputError

__all__ = ["number", "whole", "digits_arg", "random_source", "own_array"]


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


def digits_arg(digits) -> int | None:
    """``digits`` of rounding as given to an ``as_dict``: ``None`` (no rounding) or a whole
    number >= 0, else :class:`InputError` (``round`` said only "cannot be interpreted")."""
    if digits is None:
        return None
    if isinstance(digits, (bool, np.bool_)) or not isinstance(digits, (int, np.integer)) or digits < 0:
        raise InputError(f"digits must be None or a whole number >= 0, got {show(digits)}")
    return int(digits)


def random_source(seed, name: str = "seed") -> np.random.Generator:
    """``numpy.random.default_rng(seed)`` for a seed a user may give (None, a whole number >= 0,
    a Generator or SeedSequence), or :class:`InputError` (numpy's own error named nothing)."""
    if isinstance(seed, (np.random.Generator, np.random.SeedSequence)) or seed is None:
        return np.random.default_rng(seed)
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"{name} must be a whole number >= 0, a numpy Generator or None, got {show(seed)}")
    return np.random.default_rng(int(seed))


def own_array(array: np.ndarray, given) -> np.ndarray:
    """``array`` (made from ``given``), copied when it is the caller's array or a view of one
    that is writeable: freezing it would freeze theirs, and their writes would change it."""
    if isinstance(given, np.ndarray) and np.may_share_memory(array, given):
        base = given
        while isinstance(base, np.ndarray):
            if base.flags.writeable:
                return array.copy()
            base = base.base
    return array


def names(value) -> tuple:
    """``value`` as a tuple of names: one string or path is one name (``"consensus"`` was
    taken letter by letter, ``'c'`` then said to be no method)."""
    if isinstance(value, (str, bytes, os.PathLike)):
        return (value,)
    return tuple(value)
