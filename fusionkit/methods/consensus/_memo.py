"""What a pair's search, its fall-back and its null distribution ask again: the refinements of
their starts and the checks of the placements they end on, kept per pair (B placed in A) in
A's ``cache`` until :func:`forget_pairs`."""

from __future__ import annotations

import numpy as np

from ...transform import Transform2D
from ._index import MapIndex
from ._verify import Check, refine_icp, verify

__all__ = ["pair_memo", "forget_pairs", "points_key", "refine_memo", "verify_memo"]


def pair_memo(a: MapIndex, b: MapIndex) -> dict:
    """What has been computed for the pair (B placed in A) and will be asked again: the
    refinements of the starts and the checks of their results, keyed by what they depend on.
    A pair searched again exhaustively (the fall-back) meets most of its first search's
    starts, and the null distribution its first draws, again. Kept in A's ``cache`` until
    :func:`forget_pairs`."""
    key = ("pairs", id(b))
    got = a.cache.get(key)
    if got is None or got[0] is not b:
        got = a.cache[key] = (b, {})
    return got[1]


def forget_pairs(a: MapIndex) -> None:
    """Drop what :func:`pair_memo` kept for A's pairs."""
    for key in [k for k in a.cache if isinstance(k, tuple) and k and k[0] == "pairs"]:
        a.cache.pop(key, None)


def points_key(points: np.ndarray) -> tuple:
    """A key that tells point sets apart in a :func:`pair_memo`."""
    return (points.shape, hash(np.ascontiguousarray(points).tobytes()))


def _key(t: Transform2D) -> tuple:
    return (t.x, t.y, t.theta)


def refine_memo(memo: dict, a: MapIndex, points: np.ndarray, name: tuple, start: Transform2D,
                gates) -> Transform2D:
    """:func:`refine_icp` of ``points`` (already in A's cells; ``name``, their
    :func:`points_key`, tells them apart in the ``memo``) from ``start``, computed once per
    start."""
    key = ("icp", name, _key(start), tuple(gates))
    got = memo.get(key)
    if got is None:
        got = memo[key] = refine_icp(a, points, start, gates=gates, cells=True)
    return got


def verify_memo(memo: dict, a: MapIndex, b: MapIndex, t: Transform2D) -> Check:
    """:func:`verify` of ``t``, computed once per placement."""
    key = ("check", _key(t))
    got = memo.get(key)
    if got is None:
        got = memo[key] = verify(a, b, t)
    return got
