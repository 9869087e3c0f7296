"""Transform hypotheses from matched scans, and their clustering (voting).

Every scan of map B is matched against every scan of map A by the Pearson correlation of their
DC-free ``|DFT|`` spectra (eqs. 1-2; rotation invariant for 360-degree scans). Each of B's scans
keeps its ``top_k`` best partners. A match ``(i, j)`` gives one hypothesis of the transform
B -> A: the circular cross-correlation of the two scans over beam angle gives the relative
heading (the phase that ``|DFT|`` discards), and the two poses then give the translation that
puts pose j of B on pose i of A. Correct matches agree with each other; wrong ones scatter. The
hypotheses are clustered in ``(x, y, theta)`` and the clusters with the most (rho-weighted)
support become the candidates that are refined and verified on the whole maps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ...transform import Transform2D
from ._index import MapIndex

__all__ = ["Hypotheses", "scan_hypotheses", "Cluster", "cluster_hypotheses"]


@dataclass(frozen=True, eq=False)
class Hypotheses:
    """Hypotheses of the transform B -> A, one per scan match.

    Attributes
    ----------
    params : (M, 3) float64
        ``(x, y, theta)`` (m, m, rad) of each hypothesis.
    weight : (M,) float64
        Its vote (grows with the spectra's correlation and the scans' heading correlation).
    pairs : (M, 2) int
        ``(i, j)``: the scans of A and B (indices into the logs) that were matched.
    """

    params: np.ndarray
    weight: np.ndarray
    pairs: np.ndarray

    def __len__(self) -> int:
        return len(self.weight)


def _headings(fa: np.ndarray, fb: np.ndarray, n_beams: int) -> tuple[np.ndarray, np.ndarray]:
    """Beam shift ``k`` maximising the circular cross-correlation of each row pair, and the
    normalised correlation there (-1..1). ``fa, fb``: (M, B//2+1) FFTs of centred scans."""
    xc = np.fft.irfft(fb * np.conj(fa), n=n_beams, axis=1)
    k = np.argmax(xc, axis=1)
    energy_a = (np.abs(fa) ** 2).sum(axis=1)
    energy_b = (np.abs(fb) ** 2).sum(axis=1)
    # Parseval for a one-sided spectrum: count the interior bins twice
    edge_a = np.abs(fa[:, 0]) ** 2 + (np.abs(fa[:, -1]) ** 2 if n_beams % 2 == 0 else 0)
    edge_b = np.abs(fb[:, 0]) ** 2 + (np.abs(fb[:, -1]) ** 2 if n_beams % 2 == 0 else 0)
    na = (2 * energy_a - edge_a) / n_beams
    nb = (2 * energy_b - edge_b) / n_beams
    denom = np.sqrt(np.maximum(na * nb, 1e-30))
    peak = xc[np.arange(len(k)), k] / denom
    return k, peak


def scan_hypotheses(a: MapIndex, b: MapIndex, *, top_k: int = 3, min_rho: float = 0.5,
                    max_matches: int = 6000) -> Hypotheses:
    """One hypothesis of the transform B -> A per matched scan pair.

    Parameters
    ----------
    a, b : MapIndex
        The two maps with their spectra.
    top_k : int
        Partners kept per scan of B (its ``top_k`` highest Pearson rho among A's scans).
    min_rho : float
        Matches with a lower rho are dropped.
    max_matches : int
        At most this many matches (the highest rho) are turned into hypotheses.
    """
    empty = Hypotheses(np.zeros((0, 3)), np.zeros(0), np.zeros((0, 2), np.int64))
    la, lb = a.log, b.log
    if (la.n_beams != lb.n_beams or not math.isclose(la.angle_increment, lb.angle_increment, rel_tol=1e-6)
            or len(a.spectra) == 0 or len(b.spectra) == 0):
        return empty
    rho = b.spectra @ a.spectra.T                      # (Pb, Pa) Pearson's rho (eq. 2)
    k = min(top_k, rho.shape[1])
    part = np.argpartition(-rho, k - 1, axis=1)[:, :k]
    jj = np.repeat(np.arange(rho.shape[0]), k)
    ii = part.ravel()
    r = rho[jj, ii].astype(np.float64)
    keep = r >= min_rho
    ii, jj, r = ii[keep], jj[keep], r[keep]
    if r.size == 0:
        return empty
    if r.size > max_matches:
        sel = np.argsort(-r, kind="stable")[:max_matches]
        ii, jj, r = ii[sel], jj[sel], r[sel]
    shift, peak = _headings(a.ranges_fft[ii], b.ranges_fft[jj], la.n_beams)
    dth = shift * la.angle_increment
    pa = la.poses[a.pose_index[ii]]
    pb = lb.poses[b.pose_index[jj]]
    # theta_a = theta_b + dth for one world direction; the rotation B -> A then turns pose j's
    # heading into pose i's, and the translation puts pose j on pose i
    phi = np.angle(np.exp(1j * (pa[:, 2] - dth - pb[:, 2])))
    c, s = np.cos(phi), np.sin(phi)
    tx = pa[:, 0] - (c * pb[:, 0] - s * pb[:, 1])
    ty = pa[:, 1] - (s * pb[:, 0] + c * pb[:, 1])
    w = np.clip(r - min_rho, 0, None) / (1 - min_rho) * np.clip(peak, 0, None)
    pairs = np.stack([a.pose_index[ii], b.pose_index[jj]], axis=1)
    return Hypotheses(np.column_stack([tx, ty, phi]), w, pairs)


@dataclass(frozen=True)
class Cluster:
    """A group of agreeing hypotheses: its weighted centre, total support and size."""

    transform: Transform2D
    support: float
    size: int


def _embed(params: np.ndarray, angle_scale: float) -> np.ndarray:
    """Points of R^4 where hypotheses close in (x, y, theta) are close (theta on a circle)."""
    return np.column_stack([params[:, 0], params[:, 1],
                            angle_scale * np.cos(params[:, 2]), angle_scale * np.sin(params[:, 2])])


def cluster_hypotheses(h: Hypotheses, *, radius: float = 0.75, angle: float = math.radians(6.0),
                       centre: np.ndarray | None = None, max_clusters: int = 8) -> list[Cluster]:
    """The strongest groups of agreeing hypotheses, best first.

    Two hypotheses agree when their translations differ by less than about ``radius`` (m) and
    their rotations by less than about ``angle`` (rad), measured together in one metric.
    Translations are taken at ``centre`` (B-frame point, m; default the origin): the position
    of B's centre under each hypothesis is compared, so a small rotation difference does not
    show as a large translation difference far from the origin.

    Returns at most ``max_clusters`` clusters: repeatedly the hypothesis with the largest
    support within the radius is taken, its neighbours are averaged into the cluster's
    transform, and everything within twice the radius is removed.
    """
    if len(h) == 0:
        return []
    p = h.params.copy()
    if centre is not None:
        c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
        p[:, 0] = p[:, 0] + c * centre[0] - s * centre[1]
        p[:, 1] = p[:, 1] + s * centre[0] + c * centre[1]
    scale = radius / (2 * math.sin(angle / 2))
    emb = _embed(p, scale)
    tree = cKDTree(emb)
    w = h.weight
    pairs = tree.query_pairs(radius, output_type="ndarray")
    support = w.copy()
    if len(pairs):
        support += np.bincount(pairs[:, 0], weights=w[pairs[:, 1]], minlength=len(w))
        support += np.bincount(pairs[:, 1], weights=w[pairs[:, 0]], minlength=len(w))
    alive = np.ones(len(w), bool)
    out = []
    order = np.argsort(-support, kind="stable")
    for i in order:
        if len(out) >= max_clusters:
            break
        if not alive[i]:
            continue
        members = np.asarray(tree.query_ball_point(emb[i], radius), np.int64)
        mw = w[members]
        if mw.sum() <= 0:
            continue
        xy = (p[members, :2] * mw[:, None]).sum(axis=0) / mw.sum()
        th = math.atan2((np.sin(p[members, 2]) * mw).sum(), (np.cos(p[members, 2]) * mw).sum())
        if centre is not None:
            cc, ss = math.cos(th), math.sin(th)
            xy = xy - np.array([cc * centre[0] - ss * centre[1], ss * centre[0] + cc * centre[1]])
        # numpy's vector sines and cosines round by the CPU's instruction set: the centre is
        # snapped to a micrometre and a tenth of a microradian, so that differences that small
        # (1e-10 rad seen) rarely move the start the same scans give
        out.append(Cluster(Transform2D(round(float(xy[0]), 6), round(float(xy[1]), 6), round(th, 7)),
                           float(support[i]), len(members)))
        alive[tree.query_ball_point(emb[i], 2 * radius)] = False
    return out
