"""The consensus method: it recovers a known motion, refuses maps that do not overlap, chains
five simulated robots consistently, and its pieces agree with plain references."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fusionkit.methods.peers import crop_pair, placement_error
from fusionkit.methods.consensus import (Check, ConsensusConfig, PairResult, estimate_maps, estimate_pair,
                                 prepare_maps, verify)
from fusionkit.methods.consensus._graph import solve_graph
from fusionkit.methods.consensus._hypotheses import Hypotheses, cluster_hypotheses
from fusionkit.methods.consensus._pair import Candidate
from fusionkit.methods.consensus._pair import displacement
from fusionkit.methods.consensus._verify import (_one_way, refine_cloud, refine_icp,
                                                 refine_icp_numpy, rigid_fit)
from fusionkit.errors import InputError
from fusionkit.grid import OccupancyGrid
from fusionkit.mapio import load_map
from fusionkit.pipeline import METHODS, MergeConfig, merge
from fusionkit.transform import Transform2D
from fusionkit.worlds import make_world

REPO = Path(__file__).resolve().parents[1]
REAL = REPO / "maps" / "real"
if not (REAL / "intel_lab.yaml").is_file():
    REAL = REPO.parent / "shared" / "maps" / "real"


def _one_way_numpy(a, points_b: np.ndarray, t: Transform2D,
                   b=None) -> tuple[int, int, int]:
    """The count of :func:`_one_way` written plainly in numpy: the reference its kernel is
    tested against."""
    ri, ci, inside = a.cells(t(points_b))
    keep = inside.copy()
    if b is not None and points_b is b.points and len(b.sided) == len(points_b):
        sr, sc, s_in = a.cells(t(b.sides))
        s_known = np.zeros(len(points_b), bool)
        s_known[s_in] = a.known[sr[s_in], sc[s_in]] & ~a.occupied[sr[s_in], sc[s_in]]
        near_all = np.zeros(len(points_b), bool)
        near_all[inside] = a.near[ri[inside], ci[inside]]
        keep &= ~(near_all & b.sided & ~s_known)
    ri, ci = ri[keep], ci[keep]
    near = a.near[ri, ci]
    n = int((a.known[ri, ci] | near).sum())
    return n, int(near.sum()), int(a.clear[ri, ci].sum())


@pytest.fixture(scope="module")
def intel() -> OccupancyGrid:
    return load_map(REAL / "intel_lab.yaml")


@pytest.fixture(scope="module")
def crop(intel):
    """Two 200-cell windows of the Intel lab, the second turned and moved into its own frame."""
    return crop_pair(intel, np.random.default_rng(3), size=200, min_overlap=0.4)


def within(t: Transform2D, truth: Transform2D, moving: OccupancyGrid, res: float) -> bool:
    d, r = placement_error(t, truth, moving)
    return r < math.radians(2.0) and d < 3 * res


# -- pieces against plain references --------------------------------------------------------------

def test_rigid_fit_recovers_a_motion_exactly():
    rng = np.random.default_rng(1)
    src = rng.uniform(-5, 5, (50, 2))
    t = Transform2D(1.3, -0.4, 2.2)
    fit = rigid_fit(src, t(src))
    assert fit.is_close(t, atol=1e-9)


def test_icp_kernel_matches_the_numpy_reference(crop):
    a, b = prepare_maps([crop.a, crop.b])
    start = Transform2D(crop.truth.x + 0.25, crop.truth.y - 0.2, crop.truth.theta + 0.03)
    fast = refine_icp(a, b.refine_points, start)
    slow = refine_icp_numpy(a, b.refine_points, start)
    dt, dr = fast.error_to(slow)
    assert dt < 1e-6 and dr < 1e-9
    assert within(fast, crop.truth, crop.b, crop.a.resolution)


def test_verification_prefers_the_true_placement(crop):
    a, b = prepare_maps([crop.a, crop.b])
    right = verify(a, b, crop.truth)
    wrong = verify(a, b, Transform2D(crop.truth.x + 1.0, crop.truth.y, crop.truth.theta))
    turned = verify(a, b, crop.truth @ Transform2D(0, 0, 0.2))
    assert right.score > 0.97 and right.conflicts <= 2
    assert right.quality() > wrong.quality() and right.quality() > turned.quality()
    assert wrong.score < 0.8 and turned.score < 0.8


def test_verification_counts_match_the_numpy_reference(crop):
    a, b = prepare_maps([crop.a, crop.b])
    rng = np.random.default_rng(11)
    for _ in range(20):
        t = Transform2D(crop.truth.x + rng.normal(0, 1.0), crop.truth.y + rng.normal(0, 1.0),
                        crop.truth.theta + rng.normal(0, 0.3))
        assert _one_way(a, b.points, t) == _one_way_numpy(a, b.points, t)
        assert _one_way(b, a.points, t.inverse) == _one_way_numpy(b, a.points, t.inverse)
        # with the walls' sides (a wall seen from one side meets only in front of A's room)
        assert _one_way(a, b.points, t, b) == _one_way_numpy(a, b.points, t, b)
        assert _one_way(b, a.points, t.inverse, a) == _one_way_numpy(b, a.points, t.inverse, a)


def test_displacement_is_the_largest_move_of_the_points():
    rng = np.random.default_rng(2)
    pts = rng.normal(0, 5.0, (4, 2))
    for _ in range(10):
        t1 = Transform2D(*rng.normal(0, 2.0, 2), rng.uniform(-3, 3))
        t2 = Transform2D(*rng.normal(0, 2.0, 2), rng.uniform(-3, 3))
        want = np.sqrt(((t1(pts) - t2(pts)) ** 2).sum(axis=1)).max()
        assert displacement(t1, t2, pts) == pytest.approx(want, rel=1e-9, abs=1e-12)


def test_scan_cloud_refinement_recovers_a_motion_beyond_the_grid():
    from scipy.spatial import cKDTree
    rng = np.random.default_rng(5)
    # walls of a room with a few inner walls, sampled every 2 cm
    segs = [((0, 0), (8, 0)), ((8, 0), (8, 5)), ((8, 5), (0, 5)), ((0, 5), (0, 0)),
            ((3, 0), (3, 2.5)), ((5, 5), (5, 3)), ((1, 3.5), (2.5, 3.5))]
    pts = np.concatenate([np.linspace(p, q, int(np.hypot(q[0] - p[0], q[1] - p[1]) / 0.02))
                          for p, q in segs])
    truth = Transform2D(0.7, -0.3, 0.4)
    b = truth.inverse(pts[rng.permutation(len(pts))[: len(pts) // 2]]) + rng.normal(0, 0.005, (len(pts) // 2, 2))
    start = Transform2D(truth.x + 0.15, truth.y - 0.1, truth.theta + 0.02)
    t = refine_cloud(pts, cKDTree(pts), b, start)
    dt, dr = t.error_to(truth)
    assert dt < 0.01 and dr < math.radians(0.1)


def test_clustering_finds_the_agreeing_hypotheses():
    rng = np.random.default_rng(2)
    truth = np.array([2.0, -1.0, 0.5])
    good = truth + rng.normal(0, [0.1, 0.1, 0.01], (40, 3))
    bad = np.column_stack([rng.uniform(-10, 10, (60, 2)), rng.uniform(-math.pi, math.pi, 60)])
    params = np.vstack([bad, good])
    h = Hypotheses(params, np.ones(len(params)), np.zeros((len(params), 2), np.int64))
    clusters = cluster_hypotheses(h, max_clusters=3)
    best = clusters[0]
    assert best.size >= 35
    assert math.hypot(best.transform.x - 2.0, best.transform.y + 1.0) < 0.1
    assert abs(best.transform.theta - 0.5) < 0.02


# -- pairs ------------------------------------------------------------------------------------------

def test_recovers_a_known_rotation_and_translation_on_a_crop(crop):
    est = estimate_pair(crop.a, crop.b)
    assert est.accepted
    assert within(est.transform, crop.truth, crop.b, crop.a.resolution)
    assert 0.9 <= est.confidence <= 1.0


def test_virtual_scans_can_join_the_grid_search(crop):
    est = estimate_pair(crop.a, crop.b, config=ConsensusConfig(virtual_scans=True))
    pair = est.diagnostics["pair"]
    assert pair.hypotheses > 0                      # scans were cast and matched
    assert est.accepted and within(est.transform, crop.truth, crop.b, crop.a.resolution)


def test_refuses_maps_that_do_not_overlap(intel):
    data = intel.trinary()
    a = OccupancyGrid(data[:200, :200], intel.resolution, intel.origin)
    far = intel.cell_to_world(379.5, 379.5)
    b = OccupancyGrid(data[380:580, 380:580], intel.resolution, (float(far[0]), float(far[1]), 0.0))
    est = estimate_pair(a, b)
    assert not est.accepted
    result = merge([a, b])                                  # the default method
    assert result.config.method == "consensus"
    assert not result.placements[1].merged
    assert result.placements[1].transform is None
    assert result.placements[1].reason


def test_refuses_maps_of_different_buildings():
    office = make_world("office", 3, size=(20.0, 16.0))
    cave = make_world("cave", 3, size=(20.0, 16.0))
    result = merge([office, cave], config=MergeConfig(method="consensus"))
    assert not result.placements[1].merged


# -- N maps -----------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def five_robots():
    from fusionkit.simulate import SimulationConfig, simulate
    world = make_world("office", 0, size=(24.0, 18.0))
    return simulate(world, SimulationConfig(robots=5, poses=900, seed=4))


def test_chains_five_simulated_robots_consistently(five_robots):
    sim = five_robots
    grids = [r.grid for r in sim.robots]
    scans = [r.scans for r in sim.robots]
    result = merge(grids, scans=scans, config=MergeConfig(method="consensus", reference=0))
    ref = sim.robots[0].transform
    assert result.all_merged
    for r, p in zip(sim.robots, result.placements):
        truth = ref.inverse @ r.transform
        assert within(p.transform, truth, r.grid, sim.world.resolution), p.name
    # every map is placed by one chain from the reference, each link fused once
    assert len(result.fusion_order) == 4
    assert sorted(result.order) == [0, 1, 2, 3, 4]
    assert result.report()["method"] == "consensus"


def test_a_map_from_elsewhere_is_left_out_of_a_chain(five_robots):
    sim = five_robots
    grids = [r.grid for r in sim.robots[:3]] + [make_world("cave", 1, size=(20.0, 16.0))]
    scans = [r.scans for r in sim.robots[:3]] + [None]
    result = merge(grids, scans=scans, config=MergeConfig(method="consensus"))
    assert [p.merged for p in result.placements] == [True, True, True, False]


def _pair(a, b, t, score=0.99, ok=True, plausible=(), nfa=1e-6):
    chk = Check(score, score, score, 500, 1000, 10, 0, 0.0)
    best = Candidate(t, chk, "walls", nfa)
    return PairResult(a, b, t, score, ok and not plausible, bool(plausible),
                      tuple(plausible) or (best,), best, nfa=nfa)


def _boxes(n):
    return [np.array([[0.0, 0.0], [5.0, 0.0], [0.0, 5.0], [5.0, 5.0]])] * n


def test_a_loop_through_a_third_map_decides_an_ambiguous_pair():
    t01 = Transform2D(1.0, 0.0, 0.3)
    t12 = Transform2D(0.0, 2.0, -0.5)
    t02 = t01 @ t12
    alias = Transform2D(t02.x + 3.0, t02.y, t02.theta)
    cands = tuple(Candidate(t, Check(0.98, 0.98, 0.98, 400, 800, 5, 0, 0.0), "walls") for t in (alias, t02))
    pairs = {(0, 1): _pair(0, 1, t01), (1, 2): _pair(1, 2, t12),
             (0, 2): _pair(0, 2, alias, plausible=cands)}
    cfg = ConsensusConfig(final_check=False)
    g = solve_graph(pairs, _fake_indexes(3), 0, cfg, _boxes(3))
    assert (0, 2) in g.resolved
    assert g.transforms[2].error_to(t02)[0] < 1e-9


def test_a_pair_that_breaks_loops_is_dropped():
    t01 = Transform2D(1.0, 0.0, 0.3)
    t12 = Transform2D(0.0, 2.0, -0.5)
    t23 = Transform2D(-1.0, 1.0, 0.2)
    t02, t13 = t01 @ t12, t12 @ t23
    wrong = Transform2D(t02.x + 4.0, t02.y - 1.0, t02.theta + 0.4)
    pairs = {(0, 1): _pair(0, 1, t01), (1, 2): _pair(1, 2, t12), (2, 3): _pair(2, 3, t23),
             (1, 3): _pair(1, 3, t13), (0, 3): _pair(0, 3, t01 @ t13),
             (0, 2): _pair(0, 2, wrong, score=0.995)}
    g = solve_graph(pairs, _fake_indexes(4), 0, ConsensusConfig(final_check=False), _boxes(4))
    assert (0, 2) in g.dropped
    assert g.transforms[2].error_to(t02)[0] < 1e-9
    assert g.transforms[3].error_to(t02 @ t23)[0] < 1e-9


def test_a_lone_fit_of_a_map_with_repeated_structure_needs_a_loop():
    # map 2 fits map 1 in two places equally well (repeated structure); its single fit with
    # map 0 is no stronger, and no loop confirms it: map 2 is left out rather than guessed
    t01 = Transform2D(1.0, 0.0, 0.3)
    opts = tuple(Candidate(Transform2D(x, 1.0, 0.0), Check(0.99, 0.99, 0.99, 400, 800, 5, 0, 0.0), "walls")
                 for x in (2.0, 6.0))
    lone = Transform2D(-7.0, 3.0, 1.2)
    pairs = {(0, 1): _pair(0, 1, t01), (1, 2): _pair(1, 2, opts[0].transform, plausible=opts),
             (0, 2): _pair(0, 2, lone)}
    g = solve_graph(pairs, _fake_indexes(3), 0, ConsensusConfig(final_check=False), _boxes(3))
    assert g.transforms[2] is None and (0, 2) in g.dropped
    assert "repeats" in g.reasons[2]
    # the same fit closing a loop with map 1's placement and one of its options is used
    pairs[(0, 2)] = _pair(0, 2, t01 @ opts[1].transform)
    g = solve_graph(pairs, _fake_indexes(3), 0, ConsensusConfig(final_check=False), _boxes(3))
    assert g.transforms[2] is not None
    assert g.transforms[2].error_to(t01 @ opts[1].transform)[0] < 1e-6


def test_a_witness_decides_which_of_two_clashing_pairs_is_wrong():
    # maps 1, 2, 3 agree among themselves; map 0's fits with 2 and 3 clash, and the wrong one
    # (0, 3) carries more evidence; the fit (0, 1) is too weak to be accepted (0.5 false alarms
    # expected), but as a witness it closes a loop with (0, 2), not with (0, 3)
    t01 = Transform2D(1.0, 0.0, 0.3)
    t12 = Transform2D(0.0, 2.0, -0.5)
    t23 = Transform2D(-1.0, 1.0, 0.2)
    t02, t13 = t01 @ t12, t12 @ t23
    wrong = Transform2D(t02.x + 3.0, t02.y, t02.theta) @ t23
    weak = Check(0.99, 0.99, 0.99, 500, 1000, 10, 0, 0.0)
    strong = Check(0.99, 0.99, 0.99, 900, 1800, 10, 0, 0.0)
    pairs = {(0, 1): _pair(0, 1, t01, ok=False, nfa=0.5), (1, 2): _pair(1, 2, t12), (2, 3): _pair(2, 3, t23),
             (1, 3): _pair(1, 3, t13), (0, 2): _pair(0, 2, t02),
             (0, 3): _pair(0, 3, wrong)}
    pairs[(0, 3)] = PairResult(0, 3, wrong, 0.99, True, False, (Candidate(wrong, strong, "walls"),),
                               Candidate(wrong, strong, "walls"))
    pairs[(0, 2)] = PairResult(0, 2, t02, 0.99, True, False, (Candidate(t02, weak, "walls"),),
                               Candidate(t02, weak, "walls"))
    g = solve_graph(pairs, _fake_indexes(4), 0, ConsensusConfig(final_check=False), _boxes(4))
    assert (0, 3) in g.dropped and (0, 1) not in [e for e in g.tree]
    for k, truth in ((1, t01), (2, t02), (3, t02 @ t23)):
        assert g.transforms[k].error_to(truth)[0] < 1e-6, k


def test_a_map_without_walls_is_left_out_with_a_reason(crop):
    empty = OccupancyGrid(np.where(crop.b.data == 100, 0, crop.b.data).astype(crop.b.data.dtype),
                          crop.b.resolution, crop.b.origin)
    assert not empty.occupied_mask().any()
    result = merge([crop.a, empty], config=MergeConfig(method="consensus"))
    assert not result.placements[1].merged
    assert "wall" in result.placements[1].reason


def test_threads_do_not_change_the_result(five_robots):
    grids = [r.grid for r in five_robots.robots]
    scans = [r.scans for r in five_robots.robots]
    one = estimate_maps(grids, scans, config=ConsensusConfig(threads=1))
    two = estimate_maps(grids, scans, config=ConsensusConfig(threads=2))
    for a, b in zip(one.transforms, two.transforms):
        assert (a is None) == (b is None)
        if a is not None:
            assert a.x == b.x and a.y == b.y and a.theta == b.theta


def test_repeated_racks_make_a_pair_ambiguous_not_wrong():
    # two windows of the warehouse whose overlap is all racks: shifted by a rack's pitch, one
    # still fits the other perfectly, with more wall in common than in the true placement
    from fusionkit.bench import BenchConfig, CaseSpec, WorldSpec, make_case
    spec = CaseSpec(0, WorldSpec("warehouse", builtin="warehouse"), "crop", 2, 180735306)
    case = make_case(spec, BenchConfig())
    truth = case.truth[0].inverse @ case.truth[1]
    assert verify(*prepare_maps(case.grids), truth).score > 0.99       # the truth fits too
    est = estimate_pair(case.grids[0], case.grids[1])
    pair = est.diagnostics["pair"]
    assert not est.accepted and pair.ambiguous and len(pair.plausible) >= 2
    result = merge(list(case.grids), config=MergeConfig(method="consensus"))
    assert not result.placements[1].merged and "ambiguous" in result.placements[1].reason


def _fake_indexes(n):
    class _Res:
        resolution = 0.1
    return [_Res()] * n


# -- the same interface for every method ------------------------------------------------------------

def test_every_method_is_reachable_through_merge(crop):
    assert {"consensus", "map-merge", "hough-spectrum", "fourier-mellin", "spectral-pso"} <= set(METHODS)
    for method in ("consensus", "map-merge"):
        result = merge([crop.a, crop.b], config=MergeConfig(method=method))
        assert result.config.method == method
        assert result.placements[0].transform.is_close(Transform2D.identity())
        assert within(result.placements[1].transform, crop.truth, crop.b, crop.a.resolution), method


def test_bad_settings_are_refused():
    with pytest.raises(InputError):
        ConsensusConfig(max_false_merge=1.5)
    with pytest.raises(InputError):
        ConsensusConfig(rotation_peaks=0)
    with pytest.raises(InputError):
        estimate_maps([make_world("cave", 0, size=(12.0, 10.0))])


def _room_behind_wall(room_rows: slice, rows: int = 120, cols: int = 100) -> "OccupancyGrid":
    """One room seen from inside: free cells in ``room_rows``, a 2-cell wall on each side of
    it, unknown elsewhere (0.05 m cells)."""
    from fusionkit.grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
    data = np.full((rows, cols), UNKNOWN, np.int8)
    r0, r1 = room_rows.start, room_rows.stop
    data[r0 - 2:r1 + 2, 8:cols - 8] = OCCUPIED
    data[r0:r1, 10:cols - 10] = FREE
    return OccupancyGrid(data, 0.05, (0.0, 0.0, 0.0))


def test_a_wall_seen_from_one_side_points_into_its_room():
    from fusionkit.methods.consensus import prepare_maps
    (a,) = prepare_maps([_room_behind_wall(slice(20, 60))])
    # every wall cell of a room seen from inside has a side, and its point in front of it
    # lies in the room (on free space)
    assert a.sided.mean() > 0.95
    ri, ci, inside = a.cells(a.sides[a.sided])
    assert inside.all() and a.grid.free_mask()[ri, ci].mean() > 0.95


def test_walls_that_meet_back_to_back_are_no_evidence():
    """Two rooms on either side of one wall line (each map saw its own room): the shared wall
    lines meet cell for cell, but the room in front of each lies where the other map knows
    nothing, so they do not count as agreeing; the same room seen by both maps does."""
    from fusionkit.methods.consensus import prepare_maps, verify
    below = _room_behind_wall(slice(20, 60))          # walls at rows 18-19 and 60-61
    above = _room_behind_wall(slice(62, 100))         # walls at rows 60-61 and 100-101
    a, b = prepare_maps([below, above])
    t = Transform2D(0.0, 0.0, 0.0)
    walls_alone = _one_way(a, b.points, t)[1] + _one_way(b, a.points, t.inverse)[1]
    assert walls_alone >= 2 * 80                      # the shared wall, both ways
    assert verify(a, b, t).agreeing < 0.1 * walls_alone
    a2, b2 = prepare_maps([below, _room_behind_wall(slice(20, 60))])
    same = verify(a2, b2, t)
    assert same.agreeing >= 0.95 * (len(a2.points) + len(b2.points))
