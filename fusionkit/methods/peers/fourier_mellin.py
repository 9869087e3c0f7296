"""Map registration by the Fourier-Mellin transform (Reddy and Chatterji, 1996).

The magnitude of an image's Fourier transform does not change when the image is translated,
and it turns with the image; resampled on a log-polar grid, a rotation becomes a shift along
the angle axis, which phase correlation finds. The translation is then found by phase
correlation of the first image with the second one turned back. Followed from the paper:

1. Both maps become images of their occupied cells (1 occupied, 0 otherwise), centred on one
   square canvas large enough for any relative shift; each is multiplied by a Hann window and
   Fourier transformed; the centred magnitude is multiplied by the paper's high-pass emphasis
   ``H(u, v) = (1 - X)(2 - X)``, ``X = cos(pi u) cos(pi v)`` (``u, v`` in cycles per sample
   from -0.5 to 0.5).
2. The filtered magnitudes are resampled on a log-polar grid (``cv2.warpPolar``); because the
   magnitude of a real image is symmetric, only the half turn ``[0, pi)`` is kept, whose shift
   by phase correlation (``cv2.phaseCorrelate``) gives the rotation modulo pi.
3. Both rotations ``phi`` and ``phi + pi`` are tried: the second map is turned back by each and
   phase-correlated with the first; the branch with the higher peak wins and gives the
   translation.

The scale, which the log-radius shift would give, is not used (maps of one resolution share
their scale); it is reported in ``diagnostics["scale"]``. The confidence is the winning
branch's phase-correlation response: the share of the normalised cross-power spectrum's
energy in the 5x5 cells around its peak (1 for a pure cyclic shift). The accept threshold is
fusionkit's: the paper sets none. The default 0.18 was chosen on crops of real maps
(``benchmarks/baselines_bench.py``): correct estimates scored 0.20-0.95 (median 0.6),
unrelated pairs 0.01-0.16 (median 0.05).

References
----------
B. S. Reddy and B. N. Chatterji, "An FFT-based technique for translation, rotation, and
scale-invariant image registration", IEEE Transactions on Image Processing 5(8), 1266-1271,
1996.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from ...errors import InputError
from ...grid import OCCUPIED, OccupancyGrid
from ...transform import Transform2D
from ._common import PairEstimate, Stopwatch, cell_to_map, make_options, prepare_pair

__all__ = ["FourierMellinOptions", "estimate_pair", "highpass_emphasis", "log_polar_magnitude",
           "METHOD"]

METHOD = "fourier-mellin"


@dataclass(frozen=True)
class FourierMellinOptions:
    """Settings of the Fourier-Mellin registration.

    Attributes
    ----------
    angle_bins : int
        Samples of the log-polar grid over a half turn (360: half-degree steps).
    radius_bins : int
        Samples of the log-polar grid along the log radius.
    window : bool
        Multiply the images by a Hann window before the rotation stage's transform.
    highpass : bool
        Apply the paper's high-pass emphasis to the magnitudes.
    accept : float
        Least phase-correlation response for the estimate to be accepted.
    """

    angle_bins: int = 360
    radius_bins: int = 256
    window: bool = True
    highpass: bool = True
    accept: float = 0.18

    def __post_init__(self):
        if self.angle_bins < 16 or self.radius_bins < 16:
            raise InputError(f"angle_bins and radius_bins must be >= 16, got "
                             f"{self.angle_bins} and {self.radius_bins}")
        if not 0 <= self.accept <= 1:
            raise InputError(f"accept must be in [0, 1], got {self.accept}")


def highpass_emphasis(n: int) -> np.ndarray:
    """The paper's filter ``H = (1 - X)(2 - X)``, ``X = cos(pi u) cos(pi v)``, on a centred
    ``n`` x ``n`` spectrum (``u, v`` from -0.5 to 0.5 cycles per sample)."""
    u = np.fft.fftshift(np.fft.fftfreq(n))
    x = np.outer(np.cos(np.pi * u), np.cos(np.pi * u))
    return (1.0 - x) * (2.0 - x)


def log_polar_magnitude(image: np.ndarray, opts: FourierMellinOptions) -> tuple[np.ndarray, float]:
    """Centred, filtered Fourier magnitude of a square image on a log-polar grid.

    Returns
    -------
    lp : (angle_bins, radius_bins) float32
        Row ``k`` is the angle ``k * pi / angle_bins``; only the half turn is kept.
    log_base : float
        Log-radius per column (natural log units), for reading a scale from a column shift.
    """
    n = image.shape[0]
    img = image * cv2.createHanningWindow((n, n), cv2.CV_64F) if opts.window else image
    mag = np.abs(np.fft.fftshift(np.fft.fft2(img)))
    if opts.highpass:
        mag = mag * highpass_emphasis(n)
    radius = n / 2.0
    lp = cv2.warpPolar(mag.astype(np.float32), (opts.radius_bins, 2 * opts.angle_bins),
                       (n / 2.0, n / 2.0), radius, cv2.WARP_POLAR_LOG | cv2.INTER_LINEAR)
    return np.ascontiguousarray(lp[:opts.angle_bins]), math.log(radius) / opts.radius_bins


def _known_box(data: np.ndarray):
    r, c = np.nonzero(data >= 0)
    if r.size == 0:
        return 0, 0, data.shape[0], data.shape[1]
    return int(r.min()), int(c.min()), int(r.max()) + 1, int(c.max()) + 1


def estimate_pair(a: OccupancyGrid, b: OccupancyGrid, *, seed: int = 0, **options) -> PairEstimate:
    """Estimate the transform from map ``b``'s frame into map ``a``'s frame by Fourier-Mellin
    phase correlation.

    Parameters
    ----------
    a, b : OccupancyGrid
        The fixed and the moving map; ``b`` is resampled to ``a``'s resolution if they differ.
    seed : int
        Unused: the method is deterministic.
    **options
        Fields of :class:`FourierMellinOptions`.

    Returns
    -------
    PairEstimate
        ``confidence`` is the winning branch's phase-correlation response, ``accepted`` when it
        reaches ``accept``; ``candidates`` are both branches, best first. ``diagnostics`` holds
        the rotation peak's response, the scale read from the log radius and the canvas size.
    """
    clock = Stopwatch()
    opts = make_options(FourierMellinOptions, options, METHOD)
    a, b = prepare_pair(a, b)
    if not (np.any(a.data == OCCUPIED) and np.any(b.data == OCCUPIED)):
        return PairEstimate(None, 0.0, False, (), METHOD, clock(),
                            {"reason": "a map has no occupied cells"})
    # each map's known part, as a 0/1 image of its occupied cells
    boxes = [_known_box(g.data) for g in (a, b)]
    imgs = [(g.data[r0:r1, c0:c1] == OCCUPIED).astype(np.float64)
            for g, (r0, c0, r1, c1) in zip((a, b), boxes)]
    diag_max = max(math.hypot(*im.shape) for im in imgs)
    n = cv2.getOptimalDFTSize(int(math.ceil(2 * diag_max)) + 2)
    canvases, offsets = [], []
    for im, (r0, c0, _, _) in zip(imgs, boxes):
        cv = np.zeros((n, n), np.float64)
        ro, co = (n - im.shape[0]) // 2, (n - im.shape[1]) // 2
        cv[ro:ro + im.shape[0], co:co + im.shape[1]] = im
        canvases.append(cv)
        # canvas pixel (x, y) has its centre at cell-frame point (x - co + c0 + 0.5, y - ro + r0 + 0.5)
        offsets.append(np.array([co - c0, ro - r0], float))
    ca, cb = canvases
    oa, ob = offsets

    # rotation: shift along the angle axis of the log-polar magnitudes
    lp_a, log_base = log_polar_magnitude(ca, opts)
    lp_b, _ = log_polar_magnitude(cb, opts)
    (d_logr, d_ang), rot_response = cv2.phaseCorrelate(lp_b, lp_a)
    phi = float(d_ang) * math.pi / opts.angle_bins         # B's spectrum turned by phi lands on A's
    scale = math.exp(float(d_logr) * log_base)

    c = np.array([(n - 1) / 2.0, (n - 1) / 2.0])
    branches = []
    for rot in (phi, phi + math.pi):
        cs, sn = math.cos(rot), math.sin(rot)
        r = np.array([[cs, -sn], [sn, cs]])
        # B' (q) = B (R^-1 (q - c) + c): B turned by rot about the canvas centre
        r_inv = r.T
        m_inv = np.hstack([r_inv, (c - r_inv @ c)[:, None]])
        turned = cv2.warpAffine(cb, m_inv, (n, n), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
        (dx, dy), response = cv2.phaseCorrelate(ca, turned)
        s = -np.array([dx, dy])                            # B' point q' lies at A point q' + s
        # p_A = R (p_B - 0.5 + ob - c) + c + s + 0.5 - oa, all in cells
        t = r @ (ob - 0.5 - c) + c + s + 0.5 - oa
        branches.append((float(response), Transform2D(t[0], t[1], rot)))
    branches.sort(key=lambda br: -br[0])
    candidates = tuple((cell_to_map(a, b, t), resp) for resp, t in branches)
    best_t, best_resp = candidates[0]
    diag = {"rotation_response": float(rot_response), "scale": scale, "canvas": n,
            "rotation_mod_pi": phi % math.pi}
    return PairEstimate(best_t, best_resp, bool(best_resp >= opts.accept), candidates, METHOD,
                        clock(), diag)
