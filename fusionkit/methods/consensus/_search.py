"""Hypotheses from the grids alone: rotations from wall directions, translations by correlation.

Rotation
--------
The walls' directions are histogrammed (gradient orientation of the blurred wall raster,
weighted by the gradient's magnitude, over ``[0, pi)``). Turning map B by ``theta`` shifts its
histogram by ``theta``, so the circular cross-correlation of the two histograms peaks at the
rotation (modulo ``pi``: a wall has no front side); each peak gives two candidates,
``theta`` and ``theta + pi``.

Translation
-----------
For a candidate rotation, B's wall cells are turned and rasterised; every translation is then
scored at once by FFT correlation against A's *evidence raster*: ``+1`` near A's walls
(softened by a Gaussian), ``-penalty`` on A's clear free space, ``0`` on unknown cells. The best
peaks, kept apart by a suppression radius, are the translation candidates.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from scipy import fft as sfft
from scipy import ndimage

from ..._jit import njit
from ...transform import Transform2D
from ._index import MapIndex

__all__ = ["orientation_histogram", "rotation_candidates", "EvidenceRaster", "evidence_raster",
           "Correlator", "translation_candidates", "rotation_sweep", "pyramid_rotations"]


def orientation_histogram(index: MapIndex, bins: int = 180, sigma: float = 3.0) -> np.ndarray:
    """Histogram (``bins`` over ``[0, pi)``, circularly smoothed, unit sum) of wall directions.

    The walls are blurred by a Gaussian of ``sigma`` cells first: a wall drawn on a grid at a
    slant is a staircase, and the gradient of a sharper raster follows the stairs (biased
    towards the grid's axes by a few degrees) rather than the wall.
    """
    rows = np.flatnonzero(index.occupied.any(axis=1))
    if rows.size == 0:
        return np.full(bins, 1.0 / bins)
    cols = np.flatnonzero(index.occupied.any(axis=0))
    pad = int(3 * sigma) + 2
    window = index.occupied[max(rows[0] - pad, 0):rows[-1] + pad + 1,
                            max(cols[0] - pad, 0):cols[-1] + pad + 1]
    # in whole numbers up to the magnitude (OpenCV blurs 8-bit images bit-exactly, while its
    # floating-point filters and numpy's vector hypot and arctan2 round otherwise on another
    # CPU), the angle in double precision rounded to 1e-9 rad before it is binned: in single
    # precision, the last bit of arctan2 moves a wall lying exactly on a bin's edge (the grid's
    # axes and diagonals) into the next bin
    occ = cv2.GaussianBlur(window.astype(np.uint8) * np.uint8(255), (0, 0), sigma,
                           borderType=cv2.BORDER_CONSTANT)
    gy = cv2.Sobel(occ, cv2.CV_16S, 0, 1, ksize=3).astype(np.float64)
    gx = cv2.Sobel(occ, cv2.CV_16S, 1, 0, ksize=3).astype(np.float64)
    mag = np.sqrt(gx * gx + gy * gy)
    sel = mag > 0.05 * max(float(mag.max()), 1e-12)
    ang = np.round(np.mod(np.arctan2(gy[sel], gx[sel]) + index.grid.origin[2], math.pi), 9)
    ang[ang >= math.pi] = 0.0
    h, _ = np.histogram(ang, bins=bins, range=(0.0, math.pi), weights=mag[sel])
    h = ndimage.gaussian_filter1d(h, 1.0, mode="wrap")
    s = h.sum()
    return h / s if s > 0 else h


def _local_maxima(c: np.ndarray, count: int, min_sep: int) -> list[int]:
    """Indices of the ``count`` largest circular local maxima of ``c``, ``min_sep`` bins apart."""
    n = c.size
    is_max = (c >= np.roll(c, 1)) & (c >= np.roll(c, -1))
    cand = np.nonzero(is_max)[0]
    cand = cand[np.argsort(-c[cand], kind="stable")]
    out: list[int] = []
    for i in cand:
        if all(min(abs(int(i) - j), n - abs(int(i) - j)) >= min_sep for j in out):
            out.append(int(i))
        if len(out) >= count:
            break
    return out


def rotation_candidates(hist_a: np.ndarray, hist_b: np.ndarray, count: int = 3) -> list[float]:
    """Candidate rotations B -> A (rad) from the histograms' circular cross-correlation:
    the ``count`` best peaks, each in both branches (``theta`` and ``theta + pi``)."""
    n = hist_a.size
    # c[k] = sum_phi H_A(phi) H_B(phi - k): B's walls turned by k bins lie on A's; kept to 12
    # digits, so that peaks equal but for rounding (the two axes of a rectangular building)
    # tie exactly and are taken in a fixed order on every CPU
    c = np.fft.irfft(np.fft.rfft(hist_a) * np.conj(np.fft.rfft(hist_b)), n=n)
    top = float(np.abs(c).max())
    if top > 0:
        c = np.round(c / top, 12)
    out = []
    for k in _local_maxima(c, count, max(2, n // 36)):
        th = k * math.pi / n
        out += [th, th + math.pi]
    return [math.atan2(math.sin(t), math.cos(t)) for t in out]


class EvidenceRaster:
    """Map A's evidence at a coarse cell size, with its FFT ready for correlations.

    ``values[row, col]``: near walls up to 1, clear free space ``-penalty``, else 0; ``factor``
    fine cells per coarse cell; coordinates are A's cell frame divided by ``factor``.
    """

    def __init__(self, values: np.ndarray, factor: int, index: MapIndex):
        self.values = values
        self.factor = factor
        self.index = index
        self.cell = index.resolution * factor


def _pool(mask: np.ndarray, f: int, how: str) -> np.ndarray:
    if f == 1:
        return mask
    r, c = mask.shape
    rr, cc = -(-r // f) * f, -(-c // f) * f
    pad = np.zeros((rr, cc), mask.dtype)
    pad[:r, :c] = mask
    # the f x f cells of each block are f * f strided views of the padded mask, combined
    # view by view (the same as reducing each block, without a pass per block)
    out = pad[0::f, 0::f].copy()
    for i in range(f):
        for j in range(f):
            if i or j:
                if how == "any":
                    out |= pad[i::f, j::f]
                else:
                    out &= pad[i::f, j::f]
    return out


def evidence_raster(index: MapIndex, *, coarse: float = 0.1, max_side: int = 256,
                    penalty: float = 1.0, sigma: float = 1.0) -> EvidenceRaster:
    """Build A's evidence raster at about ``coarse`` m per cell (a whole number of A's cells),
    coarser if needed to keep its longer side within ``max_side`` cells."""
    f = max(1, int(round(coarse / index.resolution)),
            int(math.ceil(max(index.occupied.shape) / max_side)))
    walls = _pool(index.occupied, f, "any").astype(np.float32)
    if sigma > 0:
        walls = ndimage.gaussian_filter(walls, sigma)
        walls /= max(float(walls.max()), 1e-12)
    clear = _pool(index.clear, f, "all")
    values = walls - penalty * clear.astype(np.float32) * (walls < 0.05)
    return EvidenceRaster(np.ascontiguousarray(values, np.float32), f, index)


def _turned_cells(ev: EvidenceRaster, points_b: np.ndarray, theta: float) -> np.ndarray:
    """Coarse A-cell coordinates ``(col, row)`` of B's points turned by ``theta`` (before any
    translation); a cell may repeat."""
    rot = Transform2D(0.0, 0.0, theta)
    q0 = ev.index.grid.origin_transform.inverse(rot(points_b)) / ev.cell
    return np.floor(q0).astype(np.int64)


@njit
def _raster_kernel(pts, c1, s1, c2, s2, ox, oy, cell, span):
    """B's points turned by ``(c1, s1)`` (cos, sin), then moved by A's inverse origin
    ``(c2, s2, ox, oy)`` into A's cell frame, divided by the coarse ``cell`` and floored, as
    :func:`_turned_cells` computes them; returns the ``span`` x ``span`` raster of those cells
    (from their least column and row, clipped to the raster) and that least ``(col, row)``."""
    n = pts.shape[0]
    cols = np.empty(n, np.int64)
    rows = np.empty(n, np.int64)
    lo_c = 0
    lo_r = 0
    for k in range(n):
        x = c1 * pts[k, 0] - s1 * pts[k, 1] + 0.0
        y = s1 * pts[k, 0] + c1 * pts[k, 1] + 0.0
        qx = (c2 * x - s2 * y + ox) / cell
        qy = (s2 * x + c2 * y + oy) / cell
        cols[k] = np.int64(math.floor(qx))
        rows[k] = np.int64(math.floor(qy))
        if k == 0 or cols[k] < lo_c:
            lo_c = cols[k]
        if k == 0 or rows[k] < lo_r:
            lo_r = rows[k]
    img = np.zeros((span, span), np.float32)
    for k in range(n):
        img[min(rows[k] - lo_r, span - 1), min(cols[k] - lo_c, span - 1)] = 1.0
    return img, lo_c, lo_r


def _raster(ev: EvidenceRaster, points_b: np.ndarray, theta: float, span: int):
    """``(img, lo)``: B's walls turned by ``theta`` rasterised on A's coarse cells from their
    least cell ``lo = (col, row)`` (:func:`_turned_cells` and the raster, in one pass)."""
    rot = Transform2D(0.0, 0.0, theta)
    inv = ev.index.grid.origin_transform.inverse
    img, lo_c, lo_r = _raster_kernel(points_b, math.cos(rot.theta), math.sin(rot.theta),
                                     math.cos(inv.theta), math.sin(inv.theta), inv.x, inv.y,
                                     float(ev.cell), int(span))
    return img, np.array([lo_c, lo_r], np.int64)


def _rfft2_padded(img: np.ndarray, shape: tuple) -> np.ndarray:
    """``scipy.fft.rfft2(img, s=shape)`` for an image smaller than ``shape``: the rows'
    transforms run on the image's own rows only (the padding rows are zero, and so are their
    transforms), then the columns' on the padded length. The same numbers as ``rfft2``, which
    makes the same two passes over every padded row."""
    rows = sfft.rfft(img, n=shape[1], axis=1, workers=1)
    return sfft.fft(rows, n=shape[0], axis=0, workers=1)


#: Bound on the magnitude of a correlation computed by single-precision FFT: below it, the
#: transform's rounding error stays far under half a unit (about 0.05 at 2^17 on rasters of
#: 448 x 448 cells), so rounding recovers the exact integer sum.
_EXACT = 2.0 ** 18


def _levels(ev: EvidenceRaster, cells: int) -> int:
    """Steps per unit of evidence at which A's raster is correlated with a raster of B holding
    at most about ``cells`` wall cells: the largest power of two up to 64 that keeps every
    correlation's magnitude within :data:`_EXACT` (``cells`` doubled, for the rotations that
    put B's walls on more cells)."""
    peak = max(float(np.abs(ev.values).max()), 1.0)
    room = _EXACT / (2.0 * max(cells, 1) * peak)
    levels = 1
    while levels < 64 and 2 * levels <= room:
        levels *= 2
    return levels


class Correlator:
    """FFT correlation of A's evidence raster with B's turned walls, for any rotation.

    The padded size is fixed by B's extent, so A's transform is computed once. A's evidence is
    taken in whole steps of ``1 / levels`` (:func:`_levels`) and each correlation is rounded to
    a whole number of steps: it is then the exact sum of the evidence under B's walls, the same
    on every CPU (the rounding of the transform differs with the vector instructions numpy
    uses), its equal peaks are equal and taken in a fixed order, and a translation whose walls
    all lie on unknown cells scores 0, not a rounding residue.
    """

    def __init__(self, ev: EvidenceRaster, points_b: np.ndarray):
        self.ev = ev
        self.points = np.ascontiguousarray(points_b, np.float64)
        centre = points_b.mean(axis=0) if len(points_b) else np.zeros(2)
        reach = float(np.sqrt(((points_b - centre) ** 2).sum(axis=1)).max()) if len(points_b) else 0.0
        self.span = int(math.ceil(2 * reach / ev.cell)) + 3
        ha, wa = ev.values.shape
        self.shape = (sfft.next_fast_len(ha + self.span, real=True),
                      sfft.next_fast_len(wa + self.span, real=True))
        cells = int(_raster(ev, self.points, 0.0, self.span)[0].sum()) if len(points_b) else 0
        self.levels = _levels(ev, cells)
        self.steps = np.rint(ev.values * np.float32(self.levels)).astype(np.float32)
        self.fa = _rfft2_padded(self.steps, self.shape)

    def correlate(self, theta: float) -> tuple[np.ndarray, np.ndarray]:
        """``(corr, lo)``: ``corr[dr, dc]`` the summed evidence under B's walls turned by
        ``theta``, in steps of ``1 / levels``, with its raster's cell (0, 0) on A's cell
        ``(lo_y + dr, lo_x + dc)`` (indices modulo the padded shape)."""
        img, lo = _raster(self.ev, self.points, theta, self.span)
        fb = _rfft2_padded(img, self.shape)
        # the product is a temporary: the inverse may work in it
        raw = sfft.irfft2(self.fa * np.conj(fb), s=self.shape, workers=1, overwrite_x=True)
        return np.rint(raw, out=raw), lo

    def best(self, theta: float) -> float:
        """Highest correlation over all translations at rotation ``theta``."""
        if len(self.points) == 0:
            return 0.0
        corr, _ = self.correlate(theta)
        return float(corr.max()) / self.levels

    def translations(self, theta: float, *, count: int = 3,
                     suppress: float = 1.0) -> list[tuple[Transform2D, float]]:
        """Best translations at rotation ``theta``: up to ``count`` ``(transform B -> A,
        correlation)`` pairs, best first, at least ``suppress`` m apart."""
        if len(self.points) == 0:
            return []
        ev = self.ev
        corr, lo = self.correlate(theta)
        ha, wa = ev.values.shape
        rad = max(1, int(round(suppress / ev.cell)))
        out = []
        psi = ev.index.grid.origin[2]
        work = corr                 # a fresh array: its peaks are suppressed in place
        rows, cols = work.shape
        for _ in range(count):
            k = int(np.argmax(work))
            r0, c0 = divmod(k, cols)
            v = float(work[r0, c0])
            if v <= 0:
                break
            # suppress the peak's neighbourhood (indices wrap around the padded shape)
            rr = np.arange(r0 - rad, r0 + rad + 1) % rows
            cc = np.arange(c0 - rad, c0 + rad + 1) % cols
            work[np.ix_(rr, cc)] = -np.inf
            dr = r0 - rows if r0 >= ha else r0
            dc = c0 - cols if c0 >= wa else c0
            # B's raster cell (r, c) holds coarse A-cell coordinates (c + lo_x, r + lo_y) and
            # lands on A's cell (r + dr, c + dc): the shift in A's cell frame is
            # (dc - lo_x, dr - lo_y) coarse cells
            d = np.array([dc - lo[0], dr - lo[1]], float) * ev.cell
            t = (math.cos(psi) * d[0] - math.sin(psi) * d[1], math.sin(psi) * d[0] + math.cos(psi) * d[1])
            out.append((Transform2D(float(t[0]), float(t[1]), theta), v / self.levels))
        return out


def translation_candidates(ev: EvidenceRaster, points_b: np.ndarray, theta: float, *,
                           count: int = 3, suppress: float = 1.0) -> list[tuple[Transform2D, float]]:
    """Best translations for B's wall points (m, B's frame) turned by ``theta``: up to ``count``
    ``(transform B -> A, correlation)`` pairs, best first, at least ``suppress`` m apart. The
    correlation is the summed evidence under B's turned walls (one count per coarse cell)."""
    return Correlator(ev, points_b).translations(theta, count=count, suppress=suppress)


def rotation_sweep(ev: EvidenceRaster, points_b: np.ndarray, *, step: float = math.radians(3.0),
                   count: int = 6) -> list[tuple[float, float]]:
    """Rotations B -> A whose best translation puts the most walls on walls.

    Every rotation on a ``step`` grid is scored by its best correlation; the ``count`` best
    circular local maxima are returned as ``(theta, score)``, best first.
    """
    if len(points_b) == 0:
        return []
    corr = Correlator(ev, points_b)
    n = max(8, int(round(2 * math.pi / step)))
    angles = -math.pi + 2 * math.pi * np.arange(n) / n
    scores = np.array([corr.best(float(a)) for a in angles])
    idx = _local_maxima(scores, count, 2)
    return [(float(angles[i]), float(scores[i])) for i in idx]


def pyramid_rotations(ev: EvidenceRaster, points_b: np.ndarray, *, step: float,
                      count: int = 12) -> list[float]:
    """Rotations B -> A worth a full translation search, from a sweep of every rotation on a
    ``step`` grid at half the resolution of ``ev`` (a level up its pyramid, a quarter of the
    cells to correlate): the ``count`` best circular local maxima of the best correlation at
    each rotation, best first. The coarser raster is kept in A's ``cache``."""
    if len(points_b) == 0:
        return []
    index = ev.index
    key = ("pyramid", ev.factor)
    up = index.cache.get(key)
    if up is None:
        up = evidence_raster(index, coarse=2 * ev.cell, max_side=max(max(ev.values.shape) // 2, 8))
        index.cache[key] = up
    corr = Correlator(up, points_b)
    n = max(8, int(round(2 * math.pi / step)))
    angles = -math.pi + 2 * math.pi * np.arange(n) / n
    scores = np.array([corr.best(float(a)) for a in angles])
    return [float(angles[i]) for i in _local_maxima(scores, count, 2)]
