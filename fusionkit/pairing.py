"""The best pair of maps and the fusion order (paper Section 3.3, eq. 2).

The unique-pose spectra of every two robots are compared with Pearson's correlation
coefficient (eq. 2)::

    rho_xy = sum (x_i - x_mean)(y_i - y_mean) / sqrt(sum (x_i - x_mean)^2 sum (y_i - y_mean)^2)

computed here over the frequency bins of two spectra. Two unique poses *agree* when their rho
exceeds theta. The pair of robots with the most agreeing unique poses is fused first; then the
robot that agrees most with the robots already placed joins, and so on until every robot is
placed or none of the rest agrees with the placed ones (those are reported, not forced).
"""

from __future__ import annotations

from dataclasses import dataclass
from numbers import Real

import numpy as np

from .errors import InputError

__all__ = ["pearson_matrix", "PairAgreement", "agreement", "FusionPlan", "fusion_order"]


def pearson_matrix(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Pearson's rho (eq. 2) between every row of ``x`` (K, F) and every row of ``y`` (L, F).

    Returns a (K, L) array in [-1, 1]; a constant row correlates 0 with everything.
    """
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    if x.ndim != 2 or y.ndim != 2 or x.shape[1] != y.shape[1]:
        raise InputError(f"spectra must be (K, F) and (L, F) with the same F; got {x.shape}, {y.shape}")
    if not (np.isfinite(x).all() and np.isfinite(y).all()):
        raise InputError("spectra hold NaN or infinite values; Pearson's rho of them is not defined")
    xc = x - x.mean(axis=1, keepdims=True)
    yc = y - y.mean(axis=1, keepdims=True)
    xn = np.sqrt((xc * xc).sum(axis=1, keepdims=True))
    yn = np.sqrt((yc * yc).sum(axis=1, keepdims=True))
    xn[xn == 0] = np.inf
    yn[yn == 0] = np.inf
    return (xc / xn) @ (yc / yn).T


@dataclass(frozen=True, eq=False)
class PairAgreement:
    """How two robots' unique poses agree.

    Attributes
    ----------
    rho : (Ka, Kb) float
        Pearson rho between unique pose i of robot a and j of robot b.
    matches : (M, 2) int
        Index pairs ``(i, j)`` (into the unique-pose lists) with ``rho > theta``, best first.
    count : int
        Number of agreeing unique-pose pairs, ``M``.
    """

    a: int
    b: int
    rho: np.ndarray
    matches: np.ndarray
    count: int


def agreement(spectra_a: np.ndarray, spectra_b: np.ndarray, theta: float, *, a: int = 0,
              b: int = 1) -> PairAgreement:
    """Agreeing unique poses of two robots: pairs with ``rho > theta`` (Section 3.3).
    ``spectra_a``, ``spectra_b`` are the unique poses' spectra (``UniquePoses.unique_spectra``)."""
    if isinstance(theta, (bool, np.bool_)) or not isinstance(theta, Real) or not -1.0 <= theta <= 1.0:
        raise InputError(f"theta is a correlation threshold in [-1, 1], got {theta!r}")
    for name, spectra in (("spectra_a", spectra_a), ("spectra_b", spectra_b)):
        if not isinstance(spectra, (np.ndarray, list, tuple)):
            raise InputError(f"{name} must be an array of spectra (for unique poses, their "
                             f".unique_spectra), got {type(spectra).__name__}")
    if len(spectra_a) == 0 or len(spectra_b) == 0:
        return PairAgreement(a, b, np.zeros((len(spectra_a), len(spectra_b))),
                             np.zeros((0, 2), int), 0)
    rho = pearson_matrix(spectra_a, spectra_b)
    ii, jj = np.nonzero(rho > theta)
    order = np.argsort(-rho[ii, jj], kind="stable")
    matches = np.stack([ii[order], jj[order]], axis=1) if ii.size else np.zeros((0, 2), int)
    return PairAgreement(a, b, rho, matches, int(ii.size))


@dataclass(frozen=True, eq=False)
class FusionPlan:
    """The order in which maps are fused.

    Attributes
    ----------
    counts : (N, N) int
        Agreeing unique-pose pairs between every two robots (symmetric, 0 on the diagonal).
    steps : tuple of (int, int)
        ``(placed, new)``: map ``new`` joins the fused map, aligned against map ``placed`` (the
        placed map it agrees with most) and the others placed before it. The first step's
        ``placed`` is the reference of the best pair.
    unplaced : tuple of int
        Maps that agree with none of the placed maps.
    """

    counts: np.ndarray
    steps: tuple
    unplaced: tuple

    @property
    def order(self) -> tuple:
        """Map indices in the order they join, starting with the first pair."""
        if not self.steps:
            return ()
        return (self.steps[0][0],) + tuple(new for _, new in self.steps)


def fusion_order(counts: np.ndarray, *, reference: int | None = None) -> FusionPlan:
    """Greedy fusion order from agreement counts (Section 3.3).

    The first pair is the one with the most agreeing unique poses (with ``reference`` given,
    the reference's best partner). Then, repeatedly, the unplaced map with the largest total
    agreement with the placed maps joins, aligned against the placed map it agrees with most.
    """
    counts = np.asarray(counts)
    n = counts.shape[0] if counts.ndim else 0
    if counts.ndim != 2 or counts.shape != (n, n):
        raise InputError(f"agreement counts must be square, got {counts.shape}")
    if counts.dtype.kind not in "iuf" or not np.isfinite(counts).all() or (counts < 0).any() \
            or not np.array_equal(counts, counts.T):
        # NaN made the first step (0, 1) whatever the counts; a step read one map's row only
        raise InputError("agreement counts must be a symmetric matrix of numbers >= 0 (the "
                         "agreeing unique poses of each two maps)")
    if reference is not None and (isinstance(reference, bool) or not isinstance(reference, (int, np.integer))
                                  or not 0 <= reference < n):
        # -1 was taken as the last map, which then joined as a new one
        raise InputError(f"reference must be the index of one of the {n} maps (0 to {n - 1}), "
                         f"got {reference!r}")
    c = counts.copy()
    np.fill_diagonal(c, 0)
    if n < 2 or c.max() <= 0:
        return FusionPlan(counts, (), tuple(range(n)) if n >= 2 else ())
    if reference is None:
        a, b = np.unravel_index(int(np.argmax(c)), c.shape)
    else:
        a, b = reference, int(np.argmax(c[reference]))
        if c[a, b] <= 0:
            return FusionPlan(counts, (), tuple(i for i in range(n) if i != reference))
    placed = [int(a), int(b)]
    steps = [(int(a), int(b))]
    while len(placed) < n:
        rest = [k for k in range(n) if k not in placed]
        totals = np.array([c[k, placed].sum() for k in rest])
        if totals.max() <= 0:
            break
        k = rest[int(np.argmax(totals))]
        anchor = placed[int(np.argmax(c[k, placed]))]
        steps.append((anchor, k))
        placed.append(k)
    return FusionPlan(counts, tuple(steps), tuple(k for k in range(n) if k not in placed))
