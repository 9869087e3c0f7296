"""Candidate pairs: which pairs of a large fleet's maps are worth a full estimate.

A full pair estimate (hypotheses, refinement, verification) costs tens of milliseconds to
seconds; a fleet of ``K`` maps has ``K (K - 1) / 2`` pairs. A cheap global *signature* per map
ranks the other maps first, and only each map's best-ranked ``top`` others are estimated in
full, plus the pairs the placement graph needs to check its loops: so the number of full
estimates grows about linearly with ``K``.

Signature
    The scans' ``|DFT|`` spectra that the consensus method has already computed (DC-free, centred
    and scaled so that a dot product is Pearson's rho, the paper's eqs. 1-2), ``samples`` of them
    spread over the map. Two maps that saw the same places hold scans taken from about the same
    positions, whose spectra agree whatever the maps' frames. The score of a pair is the mean,
    over the quarter of each map's samples that match best, of the best rho in the other map
    (both ways, averaged). Maps without scans fall back to the rotation-invariant ``|DFT|`` of
    their wall-direction histograms.
Selection (:func:`candidate_pairs`)
    Each map's ``top`` best-scored others, and the links of a maximum spanning tree of the
    scores, so that the candidate graph connects every map.
Loops (:func:`closing_pairs`)
    After the candidates are estimated, for every map, each two of its accepted partners that
    were not yet compared: the triangles through which the placement graph checks its links.
"""

from __future__ import annotations

import itertools
from typing import Callable, Iterable, Sequence

import numpy as np

from ...errors import InputError

__all__ = ["map_signature", "signature_scores", "fleet_scores", "candidate_pairs", "closing_pairs",
           "estimate_fleet", "rank_partners", "boxes_apart"]

#: Spectra pooled into a map's signature.
DEFAULT_SAMPLES = 128
#: Signature rows of each map that vote (:func:`signature_scores`).
DEFAULT_QUERIES = 48
#: Closest rows each query votes for.
DEFAULT_VOTES = 3
#: Coefficients of the wall-direction spectrum used when a map has no scans.
HIST_COEFFS = 24


def _spread(count: int, samples: int) -> np.ndarray:
    """``samples`` indices spread evenly over ``range(count)`` (all of them when fewer)."""
    if count <= samples:
        return np.arange(count)
    return np.unique(np.round(np.linspace(0, count - 1, samples)).astype(np.int64))


def map_signature(spectra: np.ndarray, *, samples: int = DEFAULT_SAMPLES) -> np.ndarray:
    """A map's signature: ``samples`` of its scans' unit spectra, as ``(S, F)`` float32 rows.

    Parameters
    ----------
    spectra : (P, F) array
        Unit-norm, centred ``|DFT|`` spectra (:attr:`fusionkit.methods.consensus.MapIndex.spectra`).
    samples : int
        Most rows kept (spread evenly over the map's scans, which are spread over its area).
    """
    spectra = np.asarray(spectra, dtype=np.float32)
    if spectra.ndim != 2:
        raise InputError(f"spectra must be a (poses, coefficients) array, got shape {spectra.shape}")
    if samples < 1:
        raise InputError(f"samples must be >= 1, got {samples}")
    return np.ascontiguousarray(spectra[_spread(len(spectra), samples)])


def _hist_signature(hist: np.ndarray) -> np.ndarray:
    """Rotation-invariant signature of a wall-direction histogram: its ``|DFT|`` without DC,
    centred and scaled to unit norm (one row)."""
    mag = np.abs(np.fft.rfft(np.asarray(hist, dtype=np.float64)))[1:HIST_COEFFS + 1]
    mag = mag - mag.mean()
    nrm = float(np.linalg.norm(mag))
    return (mag / nrm if nrm > 0 else mag).astype(np.float32)[None, :]


def signature_scores(signatures: Sequence[np.ndarray], *, queries: int = DEFAULT_QUERIES,
                     votes: int = DEFAULT_VOTES) -> np.ndarray:
    """Symmetric ``(K, K)`` similarity of the maps' signatures (diagonal ``-inf``).

    Place recognition by votes: ``queries`` rows of each map's signature (spread over it) look
    for their ``votes`` most similar rows (largest rho) among every *other* map's signature
    rows, and each map owning one of those gets a vote (one per query at most). The score of a
    pair is the votes each gave the other. A raw similarity saturates (any map holds some scan
    much like any other); a vote only goes to the maps that hold the *closest* scans, which
    are the maps that saw the same place.
    """
    k = len(signatures)
    sigs = [np.asarray(s, dtype=np.float32) for s in signatures]
    widths = {s.shape[1] for s in sigs if s.size}
    if len(widths) > 1:
        raise InputError("signatures of different widths cannot be compared; build them alike")
    if queries < 1 or votes < 1:
        raise InputError(f"queries and votes must be >= 1, got {queries} and {votes}")
    scores = np.zeros((k, k))
    present = [m for m, s in enumerate(sigs) if s.size]
    if len(present) > 1:
        stacked = np.concatenate([sigs[m] for m in present])
        owner = np.concatenate([np.full(len(sigs[m]), m) for m in present])
        for a in present:
            q = sigs[a][_spread(len(sigs[a]), queries)]
            rho = q @ stacked.T                                     # (queries, all rows)
            rho[:, owner == a] = -np.inf
            v = min(votes, int((owner != a).sum()))
            best = np.argpartition(-rho, v - 1, axis=1)[:, :v]      # the v closest rows
            voted = np.zeros((len(q), k), bool)
            voted[np.arange(len(q))[:, None], owner[best]] = True  # one vote per map a query
            scores[a] += voted.sum(axis=0)
    scores = scores + scores.T
    np.fill_diagonal(scores, -np.inf)
    return scores


def fleet_scores(indexes: Sequence, hists: Sequence[np.ndarray] | None = None, *,
                 samples: int = DEFAULT_SAMPLES) -> np.ndarray:
    """:func:`signature_scores` of prepared maps (:class:`fusionkit.methods.consensus.MapIndex`): their
    scans' spectra when every map has some of one width, else their wall-direction histograms
    (``hists``, :func:`fusionkit.methods.consensus._search.orientation_histogram`)."""
    widths = {ix.spectra.shape[1] for ix in indexes if len(ix.spectra)}
    if len(widths) == 1 and all(len(ix.spectra) for ix in indexes):
        return signature_scores([map_signature(ix.spectra, samples=samples) for ix in indexes])
    if hists is None:
        from ._search import orientation_histogram
        hists = [orientation_histogram(ix) for ix in indexes]
    return signature_scores([_hist_signature(h) for h in hists])


def rank_partners(scores: np.ndarray, k: int) -> np.ndarray:
    """The other maps in order of decreasing score for map ``k`` (ties: lower index first)."""
    row = np.asarray(scores[k], dtype=np.float64)
    order = np.lexsort((np.arange(len(row)), -row))
    return order[order != k]


def candidate_pairs(scores: np.ndarray, top: int) -> list[tuple[int, int]]:
    """Pairs ``(i, j)``, ``i < j``, sorted, worth a full estimate.

    Each map's ``top`` best-scored others, and the links of a maximum spanning tree of the
    scores (so that every map is linked, through candidates, to every other). ``top`` of
    ``K - 1`` or more gives every pair.
    """
    scores = np.asarray(scores, dtype=np.float64)
    n = scores.shape[0]
    if scores.shape != (n, n):
        raise InputError(f"scores must be a square matrix, got shape {scores.shape}")
    if top < 1:
        raise InputError(f"top must be >= 1, got {top}")
    if top >= n - 1:
        return list(itertools.combinations(range(n), 2))
    chosen: set = set()
    for k in range(n):
        for j in rank_partners(scores, k)[:top]:
            chosen.add((min(k, int(j)), max(k, int(j))))
    # Prim's maximum spanning tree over the scores (dense: O(n^2))
    finite = np.where(np.isfinite(scores), scores, -np.inf)
    inside = np.zeros(n, bool)
    inside[0] = True
    best = finite[0].copy()
    link = np.zeros(n, np.int64)
    for _ in range(n - 1):
        cand = np.where(inside, -np.inf, best)
        q = int(np.argmax(cand))
        p = int(link[q])
        chosen.add((min(p, q), max(p, q)))
        inside[q] = True
        better = (finite[q] > best) & ~inside
        best[better] = finite[q][better]
        link[better] = q
    return sorted(chosen)


def closing_pairs(accepted: Iterable[tuple[int, int]], done: Iterable[tuple[int, int]],
                  scores: np.ndarray) -> list[tuple[int, int]]:
    """Pairs ``(a, b)``, ``a < b``, sorted, not estimated yet (``done``), that would close a
    triangle of accepted pairs around an accepted pair that is in none.

    For each accepted pair ``(i, j)`` with no map ``k`` accepted with both, one pair is added:
    ``(j, k)`` for an accepted partner ``k`` of ``i``, or ``(i, k)`` for one of ``j``, the one
    whose maps score highest. At most one pair per accepted pair: the extra work grows linearly
    with the fleet.
    """
    scores = np.asarray(scores, dtype=np.float64)
    acc = {(min(a, b), max(a, b)) for a, b in accepted}
    partners: dict = {}
    for i, j in acc:
        partners.setdefault(i, set()).add(j)
        partners.setdefault(j, set()).add(i)
    done = {(min(a, b), max(a, b)) for a, b in done}
    out: set = set()
    for i, j in sorted(acc):
        if partners[i] & partners[j]:
            continue                                   # already in a triangle
        options = []
        for hub, far, near in ((i, j, partners[i]), (j, i, partners[j])):
            for k in near:
                if k == far:
                    continue
                e = (min(far, k), max(far, k))
                if e not in done and e not in out:
                    options.append((-float(scores[far, k]), e))
        if options:
            out.add(min(options)[1])
    return sorted(out)


def estimate_fleet(estimate: Callable[[list], dict], indexes: Sequence, hists: Sequence | None,
                   top: int) -> dict:
    """Pairwise results of a fleet: every pair, or with ``top`` its candidate pairs.

    ``estimate(pairs)`` runs the full estimate on a list of pairs ``(i, j)``, ``i < j``, and
    returns ``{(i, j): PairResult}``. With ``top`` >= 1 and more than ``top + 1`` maps:

    1. each map's ``top`` best-scored others and a maximum spanning tree of the scores
       (:func:`candidate_pairs`);
    2. a map with no accepted or ambiguous pair then: its next ``top`` candidates, then the
       next ``2 top``, ``4 top``, ... until it links or all its pairs are estimated;
    3. the pairs that close a triangle around each accepted pair in none (:func:`closing_pairs`).

    Returns the results sorted by pair.
    """
    n = len(indexes)
    if not top or n <= top + 1:
        pairs = estimate(list(itertools.combinations(range(n), 2)))
        return dict(sorted(pairs.items()))
    scores = fleet_scores(indexes, hists)
    pairs = dict(estimate(candidate_pairs(scores, top)))

    def linked(k):
        return any(k in e and (p.accepted or p.ambiguous) for e, p in pairs.items())

    # a map without a link: its next candidates, twice as many each round, until it links or
    # every pair of it is estimated (its scans may look like no other map's while its walls
    # fit), so that no map the exhaustive search would place is lost
    lo = top
    while lo < n - 1:
        alone = [k for k in range(n) if not linked(k)]
        if not alone:
            break
        more = set()
        for k in alone:
            for j in rank_partners(scores, k)[lo:2 * lo]:
                e = (min(k, int(j)), max(k, int(j)))
                if e not in pairs:
                    more.add(e)
        if more:
            pairs.update(estimate(sorted(more)))
        lo *= 2
    accepted = [e for e, p in pairs.items() if p.accepted]
    close = closing_pairs(accepted, pairs, scores)
    if close:
        pairs.update(estimate(close))
    return dict(sorted(pairs.items()))


def boxes_apart(box_a: np.ndarray, box_b: np.ndarray, t_ba, margin: float) -> bool:
    """Whether map b, placed in map a's frame by ``t_ba``, certainly does not overlap map a.

    ``box_a``, ``box_b``: the corners (m, own frames) of each map's known area
    (:func:`fusionkit.methods.consensus._pair.corners`); ``margin`` (m) widens both boxes. Two maps whose
    boxes are apart share no cell, so no check between them can find a disagreement: a large
    fleet's cross checks are then about linear in its size instead of quadratic.
    """
    pb = t_ba(np.asarray(box_b, dtype=np.float64))
    pa = np.asarray(box_a, dtype=np.float64)
    return bool(pb[:, 0].min() - margin > pa[:, 0].max() + margin
                or pb[:, 0].max() + margin < pa[:, 0].min() - margin
                or pb[:, 1].min() - margin > pa[:, 1].max() + margin
                or pb[:, 1].max() + margin < pa[:, 1].min() - margin)
