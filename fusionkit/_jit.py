"""Numba settings shared by every kernel.

Kernels are compiled with ``cache=True`` (set ``NUMBA_CACHE_DIR`` to share the cache between
processes) and ``nogil=True`` so the terminal UI stays responsive while they run. Parallel
kernels use a thread-safe threading layer (OpenMP or TBB) unless the user chose one with
``NUMBA_THREADING_LAYER``: the default workqueue layer aborts when two threads launch parallel
kernels at once.
"""

from __future__ import annotations

import os

import numba

if "NUMBA_THREADING_LAYER" not in os.environ:
    numba.config.THREADING_LAYER = "threadsafe"

__all__ = ["njit", "pjit", "prange"]

prange = numba.prange


def njit(fn=None, **kw):
    """``numba.njit`` with ``cache=True, nogil=True``."""
    opts = dict(cache=True, nogil=True)
    opts.update(kw)
    return numba.njit(**opts) if fn is None else numba.njit(**opts)(fn)


def pjit(fn=None, **kw):
    """Parallel ``numba.njit`` (``parallel=True``) with ``cache=True, nogil=True``."""
    opts = dict(cache=True, nogil=True, parallel=True)
    opts.update(kw)
    return numba.njit(**opts) if fn is None else numba.njit(**opts)(fn)
