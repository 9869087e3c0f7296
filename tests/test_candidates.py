"""Candidate pairs: the signature ranks a map's true neighbour among its candidates, the
selection connects the fleet and grows linearly with it, and the cross-check filter skips only
pairs that cannot overlap."""

from __future__ import annotations

import itertools
import math
from types import SimpleNamespace

import numpy as np
import pytest

from fusionkit.methods.consensus.candidates import (boxes_apart, candidate_pairs, closing_pairs, estimate_fleet,
                                  fleet_scores, rank_partners, signature_scores)
from fusionkit.methods.consensus import ConsensusConfig, prepare_maps
from fusionkit.methods.consensus._pair import corners
from fusionkit.methods.consensus._verify import verify
from fusionkit.errors import InputError
from fusionkit.io_carmen import split_sessions
from fusionkit.mapping import build_grid
from fusionkit.scanlog import ScanLog
from fusionkit.simulate import SimulationConfig, simulate
from fusionkit.transform import Transform2D
from fusionkit.worlds import make_world


@pytest.fixture(scope="module")
def sessions():
    """One robot's long run in a cave cut into 8 stretches that share 15 % of their scans with
    the next one, each stretch a map in its own frame: the true neighbours of stretch k are
    k - 1 and k + 1."""
    world = make_world("cave", seed=4, size=(60.0, 45.0))
    sim = simulate(world, SimulationConfig(robots=1, poses=2400, seed=2))
    log = sim.robots[0].scans
    logs, grids = [], []
    for a, b in split_sessions(log.n_scans, 8, 0.15):
        p = log.poses[a:b]
        start = Transform2D(*p[0])
        own = start.inverse(p[:, :2])
        theta = np.arctan2(np.sin(p[:, 2] - start.theta), np.cos(p[:, 2] - start.theta))
        s = ScanLog(np.column_stack([own, theta]), log.ranges[a:b], log.angle_min,
                    log.angle_increment, log.range_max)
        logs.append(s)
        grids.append(build_grid(s, name=f"stretch_{len(grids)}"))
    return grids, logs


def test_signature_ranks_the_true_neighbour_among_the_candidates(sessions):
    grids, logs = sessions
    indexes = prepare_maps(grids, logs, config=ConsensusConfig())
    scores = fleet_scores(indexes)
    assert scores.shape == (8, 8) and np.allclose(scores, scores.T)
    chosen = set(candidate_pairs(scores, 2))
    assert len(chosen) < 28                                  # not every pair
    for k in range(8):
        neighbours = {(min(k, j), max(k, j)) for j in (k - 1, k + 1) if 0 <= j < 8}
        assert neighbours & chosen, f"stretch {k} lost both of its neighbours"


def test_candidate_pairs_cover_every_pair_when_top_reaches_the_fleet():
    rng = np.random.default_rng(0)
    s = rng.random((6, 6))
    s = s + s.T
    np.fill_diagonal(s, -np.inf)
    assert candidate_pairs(s, 5) == list(itertools.combinations(range(6), 2))
    with pytest.raises(InputError):
        candidate_pairs(s, 0)


def test_candidate_pairs_link_two_cliques_that_rank_only_themselves():
    # maps 0-3 and 4-7 score high among themselves; top-2 alone would leave two islands
    s = np.full((8, 8), 0.1)
    s[:4, :4] = s[4:, 4:] = 0.9
    s[3, 4] = s[4, 3] = 0.2
    np.fill_diagonal(s, -np.inf)
    chosen = candidate_pairs(s, 2)
    assert (3, 4) in chosen
    # connected: every map reaches map 0 through chosen pairs
    reach, frontier = {0}, [0]
    while frontier:
        a = frontier.pop()
        for i, j in chosen:
            for p, q in ((i, j), (j, i)):
                if p == a and q not in reach:
                    reach.add(q)
                    frontier.append(q)
    assert reach == set(range(8))


def test_votes_go_to_the_map_holding_the_same_rows():
    rng = np.random.default_rng(3)

    def unit(x):
        x = x - x.mean(axis=1, keepdims=True)
        return x / np.linalg.norm(x, axis=1, keepdims=True)

    base = [unit(rng.normal(size=(40, 16))) for _ in range(4)]
    # map 4 shares half its rows with map 2 (plus noise); the others are unrelated
    shared = unit(np.vstack([base[2][:20] + 0.05 * rng.normal(size=(20, 16)),
                             rng.normal(size=(20, 16))]))
    s = signature_scores(base + [shared], queries=40, votes=1)
    assert rank_partners(s, 4)[0] == 2
    assert rank_partners(s, 2)[0] == 4
    with pytest.raises(InputError):
        signature_scores([base[0], base[1][:, :8]])


def test_closing_pairs_close_one_triangle_per_open_accepted_pair():
    scores = np.zeros((6, 6))
    scores[2, 4] = scores[4, 2] = 5.0
    accepted = [(0, 1), (1, 2), (0, 2), (2, 3), (3, 4)]
    # (0,1), (1,2), (0,2) are a closed triangle; (2,3) and (3,4) are not: (2, 4) closes both
    out = closing_pairs(accepted, accepted, scores)
    assert out == [(2, 4)]
    assert closing_pairs(accepted, accepted + [(2, 4)], scores) in ([(1, 3)], [(0, 3)])


def test_estimate_fleet_grows_linearly_with_the_fleet(monkeypatch):
    def fleet(n):
        # a ring: map k overlaps k +- 1; scores say so, with a faint noise elsewhere
        rng = np.random.default_rng(n)
        s = rng.random((n, n)) * 0.1
        for k in range(n):
            s[k, (k + 1) % n] = s[(k + 1) % n, k] = 1.0
        s = s + s.T
        np.fill_diagonal(s, -np.inf)
        return s

    counts = {}
    for n in (20, 40, 80):
        s = fleet(n)
        calls = []

        def estimate(todo, n=n):
            calls.append(list(todo))
            return {(i, j): SimpleNamespace(accepted=(j - i) in (1, n - 1), ambiguous=False)
                    for i, j in todo}

        monkeypatch.setattr("fusionkit.methods.consensus.candidates.fleet_scores", lambda indexes, hists=None, **kw: s)
        pairs = estimate_fleet(estimate, list(range(n)), None, 3)
        assert list(pairs) == sorted(pairs)
        assert all((k, k + 1) in pairs for k in range(n - 1))
        counts[n] = len(pairs)
    assert counts[80] <= 2.2 * counts[40] and counts[40] <= 2.2 * counts[20]
    assert counts[80] < 80 * 79 / 2 / 10


def test_boxes_apart_only_when_the_maps_share_no_cell(sessions):
    grids, logs = sessions
    a, b = prepare_maps(grids[:2], logs[:2], config=ConsensusConfig())
    res = a.resolution
    rng = np.random.default_rng(1)
    apart = 0
    for _ in range(60):
        t = Transform2D(rng.uniform(-40, 40), rng.uniform(-40, 40), rng.uniform(-math.pi, math.pi))
        if boxes_apart(corners(a), corners(b), t, 3 * res):
            apart += 1
            assert verify(a, b, t).overlap == 0
    assert apart > 5
    assert not boxes_apart(corners(a), corners(b), Transform2D.identity(), 3 * res)


def test_a_map_its_signature_misranks_still_gets_every_pair(monkeypatch):
    # the last map's only real partner, map 0, is the one it scores lowest
    n = 30
    s = np.ones((n, n))
    for k in range(n - 2):                      # the chain 0 - 1 - ... - (n - 2) ranks itself
        s[k, k + 1] = s[k + 1, k] = 2.0
    s[n - 1, 0] = s[0, n - 1] = 0.0
    np.fill_diagonal(s, -np.inf)
    monkeypatch.setattr("fusionkit.methods.consensus.candidates.fleet_scores", lambda indexes, hists=None, **kw: s)

    def estimate(todo):
        return {(i, j): SimpleNamespace(accepted=(i, j) == (0, n - 1) or j - i == 1 and j < n - 1,
                                        ambiguous=False) for i, j in todo}

    pairs = estimate_fleet(estimate, list(range(n)), None, 2)
    assert (0, n - 1) in pairs and pairs[(0, n - 1)].accepted
    assert len(pairs) < n * (n - 1) // 4
