"""Map merging by Hough spectra (Carpin, Autonomous Robots 2008).

The rotation between two maps is read from their Hough spectra, the translation from the
projections of their occupied cells, and every hypothesis is ranked by the acceptance index.
Followed from the paper and from the author's ``mapmerge`` library (S. Carpin, UC Merced,
2007-2008: ``hough.cpp``, ``manipulatemap.cpp``, function ``get_hypothesis`` and its
``_robust`` variant):

1. Hough transform of the occupied cells, ``HT(rho, theta)`` with ``rho = x cos(theta) +
   y sin(theta)``, and its spectrum ``HS(theta) = sum_rho HT(rho, theta)^2`` normalised to a
   maximum of 1.
2. Map A is turned so that its dominant direction (the maximum of its spectrum) lies along an
   axis; the circular cross-correlation ``CC(k) = sum_j HS_A(j) HS_B(j - k)`` is computed and
   its strongest local maxima (4 by default) are the rotation candidates. A spectrum has period
   pi (a line's normal at ``theta`` and ``theta + pi`` is the same line), so each candidate
   ``k`` stands for the two rotations ``k`` and ``k + pi``; both are tried. (Carpin's code
   covers 360 degrees with 360 bins, where every peak appears twice; the result is the same.)
3. For each rotation, map B's occupied cells are turned by it (and by A's dominant-direction
   turn) and the ``x`` and ``y`` histograms of A's and B's occupied cells are cross-correlated;
   the peak of each gives the translation along that axis.
4. Each hypothesis is scored by the acceptance index ``omega = agr / (agr + dis)`` over the
   cells known in both maps (``agr``: same state, ``dis``: one free, the other occupied), and
   the hypotheses are ranked by it.

Where this differs from the library: it works on occupied cell centres directly, with
1-degree angle bins over ``[0, pi)`` and ``rho`` bins of one cell over the full range (the
library uses 256 ``rho`` bins over twice the largest coordinate and drops votes that fall
outside); map B is turned with nearest-neighbour sampling instead of cubic interpolation and
re-thresholding. ``robust=True`` adds the library's robust variant (each rotation also tried
one bin to either side). The accept rule is fusionkit's: the paper ranks hypotheses but sets no
threshold. The default 0.96 was chosen on crops of real maps (``benchmarks/baselines_bench.py``):
correct estimates scored 0.89-0.997 (median 0.98), unrelated pairs 0.79-0.97 (median 0.89),
because two mostly free maps agree on most of their free cells whatever the transform. The
index ranks hypotheses of one pair well; as an absolute accept test it is weak.

References
----------
S. Carpin, "Fast and accurate map merging for multi-robot systems", Autonomous Robots 25(3),
305-316, 2008.
A. Birk and S. Carpin, "Merging occupancy grid maps from multiple robots", Proceedings of the
IEEE 94(7), 1384-1397, 2006 (the acceptance index).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...errors import InputError
from ...grid import OccupancyGrid
from ...transform import Transform2D
from ._common import (PairEstimate, Stopwatch, acceptance_index, cell_to_map, make_options,
                      occupied_cell_centres, prepare_pair, warp_cells)

__all__ = ["HoughSpectrumOptions", "estimate_pair", "hough_transform", "hough_spectrum",
           "circular_cross_correlation", "circular_local_maxima", "METHOD"]

METHOD = "hough-spectrum"


@dataclass(frozen=True)
class HoughSpectrumOptions:
    """Settings of the Hough-spectrum merger.

    Attributes
    ----------
    theta_bins : int
        Angle bins over ``[0, pi)`` (180: one degree).
    rho_step : float
        Width of a ``rho`` bin (cells).
    hypotheses : int
        Local maxima of the spectra's cross-correlation kept as rotation candidates; each gives
        two rotations (``theta`` and ``theta + pi``).
    robust : bool
        Also try each rotation one angle bin to either side.
    accept : float
        Least acceptance index for the best hypothesis to be accepted.
    min_overlap : float
        Least number of cells known in both maps under the best hypothesis, as a fraction of
        the smaller map's known cells.
    """

    theta_bins: int = 180
    rho_step: float = 1.0
    hypotheses: int = 4
    robust: bool = False
    accept: float = 0.96
    min_overlap: float = 0.1

    def __post_init__(self):
        if self.theta_bins < 8:
            raise InputError(f"theta_bins must be >= 8, got {self.theta_bins}")
        if not self.rho_step > 0:
            raise InputError(f"rho_step must be > 0 cells, got {self.rho_step}")
        if self.hypotheses < 1:
            raise InputError(f"hypotheses must be >= 1, got {self.hypotheses}")
        if not 0 <= self.accept <= 1:
            raise InputError(f"accept must be in [0, 1], got {self.accept}")
        if not 0 <= self.min_overlap <= 1:
            raise InputError(f"min_overlap must be in [0, 1], got {self.min_overlap}")


def hough_transform(points: np.ndarray, theta_bins: int = 180, rho_step: float = 1.0):
    """Hough transform of points ``(K, 2)`` (cells), ``rho`` measured from their centroid.

    Returns
    -------
    ht : (theta_bins, n_rho) ndarray of int64
        Votes; row ``j`` is angle ``j * pi / theta_bins``.
    thetas : (theta_bins,) ndarray
        The bin angles (rad).
    """
    thetas = np.arange(theta_bins) * (np.pi / theta_bins)
    p = np.asarray(points, float)
    if len(p) == 0:
        return np.zeros((theta_bins, 1), np.int64), thetas
    p = p - p.mean(axis=0)
    radius = float(np.sqrt((p ** 2).sum(axis=1).max()))
    n_rho = int(math.ceil(2 * radius / rho_step)) + 2
    # rho = x cos(theta) + y sin(theta)
    rho = p[:, :1] * np.cos(thetas) + p[:, 1:] * np.sin(thetas)           # (K, T)
    idx = np.floor((rho + radius) / rho_step + 0.5).astype(np.int64)
    flat = idx + n_rho * np.arange(theta_bins)
    ht = np.bincount(flat.ravel(), minlength=theta_bins * n_rho).reshape(theta_bins, n_rho)
    return ht, thetas


def hough_spectrum(ht: np.ndarray) -> np.ndarray:
    """``HS(theta) = sum_rho HT(rho, theta)^2``, normalised to a maximum of 1."""
    hs = (ht.astype(float) ** 2).sum(axis=1)
    m = hs.max()
    return hs / m if m > 0 else hs


def circular_cross_correlation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``CC(k) = sum_j a(j) b(j - k)`` (indices mod n), rescaled to ``[0, 1]``.

    If ``a(j) = b(j - s)`` the maximum is at ``k = s``."""
    cc = np.real(np.fft.ifft(np.fft.fft(a) * np.conj(np.fft.fft(b))))
    lo, hi = cc.min(), cc.max()
    return (cc - lo) / (hi - lo) if hi > lo else np.zeros_like(cc)


def circular_local_maxima(seq: np.ndarray, count: int) -> np.ndarray:
    """Indices of the ``count`` largest strict local maxima of a circular sequence, largest
    first (fewer if there are fewer maxima; the global maximum when the sequence is flat)."""
    s = np.asarray(seq, float)
    is_max = (s > np.roll(s, 1)) & (s > np.roll(s, -1))
    idx = np.flatnonzero(is_max)
    if idx.size == 0:
        return np.array([int(np.argmax(s))])
    order = np.argsort(-s[idx], kind="stable")
    return idx[order[:count]]


def _axis_shift(qa: np.ndarray, qb: np.ndarray) -> float:
    """Integer shift ``d`` maximising the cross-correlation of the 1-cell histograms of ``qa``
    and ``qb + d``."""
    ia = np.floor(qa).astype(np.int64)
    ib = np.floor(qb).astype(np.int64)
    a0, b0 = int(ia.min()), int(ib.min())
    ha = np.bincount(ia - a0).astype(float)
    hb = np.bincount(ib - b0).astype(float)
    n = len(ha) + len(hb) - 1
    size = 1 << (n - 1).bit_length()
    cc = np.fft.irfft(np.fft.rfft(ha, size) * np.conj(np.fft.rfft(hb, size)), size)
    # circular lag k (mod size) means ha[n + k] ~ hb[n]; lags run from -(len(hb)-1) to len(ha)-1
    lags = np.concatenate([np.arange(0, len(ha)), np.arange(-(len(hb) - 1), 0)])
    vals = np.concatenate([cc[:len(ha)], cc[size - (len(hb) - 1):]])
    lag = int(lags[int(np.argmax(vals))])
    return float(a0 - b0 + lag)


def _rot(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


def estimate_pair(a: OccupancyGrid, b: OccupancyGrid, *, seed: int = 0, **options) -> PairEstimate:
    """Estimate the transform from map ``b``'s frame into map ``a``'s frame by Hough spectra.

    Parameters
    ----------
    a, b : OccupancyGrid
        The fixed and the moving map; ``b`` is resampled to ``a``'s resolution if they differ.
    seed : int
        Unused: the method is deterministic.
    **options
        Fields of :class:`HoughSpectrumOptions`.

    Returns
    -------
    PairEstimate
        ``confidence`` is the best hypothesis' acceptance index; ``accepted`` when it reaches
        ``accept`` and the maps share at least ``min_overlap`` of the smaller one's known
        cells. ``candidates`` are all hypotheses ranked by acceptance index; ``diagnostics``
        holds the rotation candidates (rad), the dominant direction of ``a`` and the overlap.
    """
    clock = Stopwatch()
    opts = make_options(HoughSpectrumOptions, options, METHOD)
    a, b = prepare_pair(a, b)
    pa, pb = occupied_cell_centres(a.data), occupied_cell_centres(b.data)
    if len(pa) < 2 or len(pb) < 2:
        return PairEstimate(None, 0.0, False, (), METHOD, clock(),
                            {"reason": "fewer than two occupied cells in a map"})

    ht_a, thetas = hough_transform(pa, opts.theta_bins, opts.rho_step)
    ht_b, _ = hough_transform(pb, opts.theta_bins, opts.rho_step)
    hs_a, hs_b = hough_spectrum(ht_a), hough_spectrum(ht_b)
    step = math.pi / opts.theta_bins
    alpha = float(thetas[int(np.argmax(hs_a))])          # A's dominant direction
    cc = circular_cross_correlation(hs_a, hs_b)
    peaks = circular_local_maxima(cc, opts.hypotheses)
    offsets = (-1, 0, 1) if opts.robust else (0,)
    rotations = []
    for k in peaks:
        for half in (0.0, math.pi):
            for o in offsets:
                rotations.append((k + o) * step + half)

    qa = pa @ _rot(-alpha).T
    known_a = int(np.count_nonzero(a.data >= 0))
    known_b = int(np.count_nonzero(b.data >= 0))
    hyps = []
    for phi in rotations:
        qb = pb @ (_rot(-alpha) @ _rot(phi)).T
        d = np.array([_axis_shift(qa[:, 0], qb[:, 0]), _axis_shift(qa[:, 1], qb[:, 1])])
        t = _rot(alpha) @ d                               # p_A = R(phi) p_B + R(alpha) d
        cell_t = Transform2D(t[0], t[1], phi)
        omega, agr, dis = acceptance_index(a.data, warp_cells(b.data, cell_t, a.data.shape))
        hyps.append((omega, agr + dis, cell_t))
    hyps.sort(key=lambda h: -h[0])
    candidates = tuple((cell_to_map(a, b, h[2]), float(h[0])) for h in hyps)
    omega, overlap, _ = hyps[0]
    overlap_frac = overlap / max(1, min(known_a, known_b))
    accepted = omega >= opts.accept and overlap_frac >= opts.min_overlap
    diag = {"rotation_candidates": tuple(float(r) for r in rotations), "dominant_direction": alpha,
            "overlap_cells": int(overlap), "overlap_fraction": float(overlap_frac)}
    return PairEstimate(candidates[0][0], float(omega), bool(accepted), candidates, METHOD, clock(), diag)
