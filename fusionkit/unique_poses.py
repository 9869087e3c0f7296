"""Unique poses by the DFT of the scans (paper Section 3.2, Algorithm 1, eq. 1).

Each scan ``f(x)``, ``x = 0..B-1`` over beam angle, has the spectrum
``|DFT(u)| = |sum_x f(x) exp(-i 2 pi u x / B)|`` (eq. 1). The *overall spectrum* is the mean
spectrum over all of a robot's poses: it is dominated by what the robot sees most often, the
typical and repeated places. A pose is *unique* when its section, the ``2 * sub_sec`` poses
around it, diverges from the overall spectrum: at most one of the section's spectra lies
within ``delta`` of the overall spectrum (Algorithm 1, line 15).

Rotation invariance
-------------------
For a 360-degree scan, turning the robot by ``k`` beams shifts the scan circularly by ``k``;
the DFT of a circularly shifted signal only changes phase (``exp(-i 2 pi u k / B)``), so its
magnitude ``|DFT|`` is unchanged. A place therefore has the same spectrum whatever the robot's
heading: spectra can be compared between robots whose frames are rotated against each other.
(The phase that ``|DFT|`` discards holds the heading: see :func:`relative_heading`.)

The DC term
-----------
Bin ``u = 0`` is ``B`` times the mean range: it is large, varies slowly along a trajectory and
correlates every spectrum with every other (with it, Pearson's rho exceeds 0.9 for almost every
pair of scans, matching or not). fusionkit keeps DC out of the spectra by default
(``dc=False``), so divergences and correlations measure the *shape* of the scan.
"""

from __future__ import annotations

import math
from numbers import Real
from dataclasses import dataclass

import numpy as np

from ._jit import njit
from ._validate import whole
from .errors import InputError
from .scanlog import ScanLog

__all__ = ["scan_spectra", "UniquePoses", "find_unique_poses", "relative_heading"]


def scan_spectra(log_or_ranges, *, dc: bool = False, range_max: float | None = None) -> np.ndarray:
    """Magnitude spectra ``|DFT|`` of each scan over beam angle (eq. 1).

    Parameters
    ----------
    log_or_ranges : ScanLog or (N, B) array
        Scans; no-return beams (inf or above ``range_max``) count as ``range_max``.
    dc : bool
        Keep bin 0 (the mean range times B). Default False: see the module notes.

    Returns
    -------
    (N, B // 2 + 1) or (N, B // 2) float64
        One-sided magnitude spectrum per scan (the real signal's spectrum is symmetric).
    """
    if isinstance(log_or_ranges, ScanLog):
        r = log_or_ranges.clipped_ranges()
    else:
        r = np.asarray(log_or_ranges, dtype=np.float64)
        if r.ndim != 2:
            raise InputError(f"ranges must be (N, beams), got shape {r.shape}")
        if range_max is not None:
            r = np.minimum(np.where(np.isfinite(r), r, range_max), range_max)
        elif not np.isfinite(r).all():
            raise InputError("ranges contain inf/NaN; pass range_max to clip no-return beams")
    spec = np.abs(np.fft.rfft(np.asarray(r, dtype=np.float64), axis=1))
    return spec if dc else spec[:, 1:]


@njit
def _section_second_smallest(div, sub_sec):
    """For each pose i in [sub_sec, N - sub_sec): the 2nd smallest divergence among the
    section ``div[i - sub_sec : i + sub_sec]`` (Algorithm 1, line 4's slice)."""
    n = div.shape[0]
    out = np.full(n, -np.inf)
    for i in range(sub_sec, n - sub_sec):
        m1 = np.inf
        m2 = np.inf
        for k in range(i - sub_sec, i + sub_sec):
            d = div[k]
            if d < m1:
                m2 = m1
                m1 = d
            elif d < m2:
                m2 = d
        out[i] = m2
    return out


@dataclass(frozen=True, eq=False)
class UniquePoses:
    """Result of Algorithm 1 for one robot.

    Attributes
    ----------
    indices : (K,) int
        Indices of the unique poses into the robot's scans, ascending.
    delta : float
        The threshold used (found from ``target`` when one was given).
    divergence : (N,) float
        ``sum_u |spec_i(u) - o_spec(u)|`` for each pose (line 6).
    section_score : (N,) float
        Second-smallest divergence in each pose's section; pose i is unique iff
        ``section_score[i] >= delta`` (at most one spectrum of the section under delta).
        ``-inf`` for the first and last ``sub_sec`` poses, which have no full section.
    overall_spectrum : (F,) float
        The mean spectrum ``o_spec``.
    spectra : (N, F) float
        Every pose's spectrum (DC removed unless ``dc=True``).
    sub_sec : int
    """

    indices: np.ndarray
    delta: float
    divergence: np.ndarray
    section_score: np.ndarray
    overall_spectrum: np.ndarray
    spectra: np.ndarray
    sub_sec: int

    @property
    def count(self) -> int:
        return int(self.indices.size)

    @property
    def unique_spectra(self) -> np.ndarray:
        return self.spectra[self.indices]


def find_unique_poses(log: ScanLog, *, sub_sec: int = 5, delta: float | None = None,
                      target: int | None = 200, dc: bool = False) -> UniquePoses:
    """Algorithm 1: the poses whose surroundings diverge from the robot's overall spectrum.

    Parameters
    ----------
    log : ScanLog
        The robot's scans, in trajectory order.
    sub_sec : int
        Half-width of a section in poses (the paper's default 5: sections of 10 scans).
    delta : float, optional
        Divergence threshold (same units as the spectra: metres times beams). When given it is
        used as is and ``target`` is ignored.
    target : int, optional
        The paper adjusts delta "to ensure identification of a standardized number of poses":
        with ``delta=None``, delta is set so that (about) ``target`` poses are unique, the
        ``target`` poses with the most divergent sections. Ties at the threshold may add a few.
    dc : bool
        Keep the DC bin in the spectra (default False, see module notes).

    Returns
    -------
    UniquePoses
    """
    sub_sec = whole(sub_sec, "sub_sec")
    if sub_sec < 1:
        raise InputError(f"sub_sec must be >= 1 pose, got {sub_sec}")
    n = log.n_scans
    if n < 2 * sub_sec + 1:
        raise InputError(f"a robot with {n} poses has no pose with a full section of 2*sub_sec = "
                         f"{2 * sub_sec} scans (that needs at least {2 * sub_sec + 1} poses); "
                         f"record more poses or lower sub_sec")
    if delta is None and (target is None or target < 1):
        raise InputError("give either delta (a threshold) or target (a number of unique poses >= 1)")
    if delta is not None and not (isinstance(delta, Real) and not isinstance(delta, bool)
                                  and 0.0 <= delta < math.inf):
        # as MergeConfig: a negative threshold marked every pose unique
        raise InputError(f"delta is a divergence threshold >= 0 (or None), got {delta!r}")
    spectra = scan_spectra(log, dc=dc)
    o_spec = spectra.mean(axis=0)                        # line 1: overall spectrum
    divergence = np.abs(spectra - o_spec).sum(axis=1)    # line 6: dif = sum |spec - o_spec|
    score = _section_second_smallest(divergence, sub_sec)
    valid = np.isfinite(score)
    if delta is None:
        cand = np.sort(score[valid])[::-1]
        k = min(int(target), cand.size)
        delta = float(cand[k - 1])
    else:
        delta = float(delta)
        if not math.isfinite(delta):
            raise InputError(f"delta must be a finite number, got {delta}")
    # line 15: unique when at most one spectrum of the section lies under delta
    indices = np.nonzero(valid & (score >= delta))[0]
    return UniquePoses(indices, delta, divergence, score, o_spec, spectra, sub_sec)


def relative_heading(scan_a, scan_b, angle_increment: float) -> tuple[float, float]:
    """Heading of scan ``b``'s robot relative to scan ``a``'s, from the phase |DFT| discards.

    Both scans are 360-degree and of equal beam count. If the same place is seen, ``b`` is ``a``
    circularly shifted by ``k`` beams when ``b``'s robot is turned by ``-k * angle_increment``;
    the circular cross-correlation (by FFT) over beam shifts peaks at that ``k``.

    Returns
    -------
    (dtheta, peak)
        ``dtheta`` (rad): add it to ``b``'s heading to get ``a``'s (theta_a = theta_b + dtheta
        for the same world direction); ``peak``: normalised correlation at the best shift (-1..1).
    """
    a = np.asarray(scan_a, float)
    b = np.asarray(scan_b, float)
    a = a - a.mean()
    b = b - b.mean()
    denom = math.sqrt(float((a * a).sum() * (b * b).sum())) or 1.0
    xc = np.fft.irfft(np.fft.rfft(b) * np.conj(np.fft.rfft(a)), n=a.size)
    k = int(np.argmax(xc))
    # b[j] == a[j - k]: beam j of b looks where beam j - k of a looks
    return (k * angle_increment, float(xc[k] / denom))
