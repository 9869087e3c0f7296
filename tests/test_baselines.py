"""The three classic map-merging peers: each recovers a known motion between two crops of a
real map, the feature merger chains N maps like OpenCV (and correctly), and none is fooled
into a confident merge of unrelated maps."""

from __future__ import annotations

import math
from collections import Counter
from pathlib import Path

import cv2
import numpy as np
import pytest

from fusionkit.methods.peers import ESTIMATORS, PairEstimate, crop_pair, placement_error
from fusionkit.methods.peers import fourier_mellin, hough_spectrum, map_merge
from fusionkit.methods.peers._common import (acceptance_index, cell_to_map, make_options, map_to_cell,
                                         prepare_pair, warp_cells)
from fusionkit.errors import InputError
from fusionkit.grid import OccupancyGrid
from fusionkit.mapio import load_map
from fusionkit.resample import resample
from fusionkit.transform import Transform2D
from fusionkit.worlds import make_cave

REPO = Path(__file__).resolve().parents[1]
REAL = REPO / "maps" / "real"
if not (REAL / "intel_lab.yaml").is_file():
    REAL = REPO.parent / "shared" / "maps" / "real"

TOL_ROT = math.radians(2.0)
TOL_CELLS = 3.0


@pytest.fixture(scope="module")
def intel() -> OccupancyGrid:
    return load_map(REAL / "intel_lab.yaml")


@pytest.fixture(scope="module")
def crop_case(intel):
    """Two 200-cell windows of the Intel lab sharing 86% of their area; the second turned by
    -165 degrees into a frame whose origin is tens of metres away."""
    case = crop_pair(intel, np.random.default_rng(0), size=200)
    assert case.overlap >= 0.5
    assert abs(case.b.origin[0]) > 1 and abs(case.b.origin[1]) > 1
    return case


def recovered(est: PairEstimate, truth: Transform2D, moving: OccupancyGrid, res: float) -> bool:
    if est.transform is None:
        return False
    d, r = placement_error(est.transform, truth, moving)
    return r <= TOL_ROT and d <= TOL_CELLS * res


# -- shared pieces -----------------------------------------------------------------------------

def test_cell_and_map_frames_agree_with_the_grids_geometry():
    a = OccupancyGrid(np.zeros((30, 40), np.int8), 0.05, (2.0, -3.0, 0.4))
    b = OccupancyGrid(np.zeros((25, 35), np.int8), 0.05, (-7.5, 1.25, -1.1))
    cell_t = Transform2D(12.5, -4.0, 0.8)
    t = cell_to_map(a, b, cell_t)
    rows, cols = np.array([0, 3, 24]), np.array([0, 17, 34])
    # a point of b's cell frame, moved by cell_t, is the same place as b's cell moved by t
    p_cells = np.stack([cols + 0.5, rows + 0.5], axis=1)
    expected = a.origin_transform(cell_t(p_cells) * a.resolution)
    np.testing.assert_allclose(t(b.cell_to_world(rows, cols)), expected, atol=1e-9)
    assert map_to_cell(a, b, t).is_close(cell_t, atol=1e-9)


def test_second_map_is_brought_to_the_first_ones_resolution():
    a = OccupancyGrid(np.zeros((10, 10), np.int8), 0.1, (1.0, 2.0, 0.0))
    data = np.full((20, 30), -1, np.int8)
    data[5:15, 10] = 100
    b = OccupancyGrid(data, 0.05, (-3.0, 4.0, 0.3))
    _, b2 = prepare_pair(a, b)
    assert b2.resolution == a.resolution and b2.origin == b.origin
    assert b2.shape == (10, 15)
    # the wall stays where it was in b's frame
    wall = b2.occupied_points()
    assert np.all(np.abs(b.origin_transform.inverse(wall)[:, 0] - 10.5 * 0.05) <= 0.05)
    with pytest.raises(InputError, match="OccupancyGrid"):
        prepare_pair(a, data)


def test_unknown_or_bad_options_are_refused_in_one_sentence():
    with pytest.raises(InputError, match="valid options are"):
        make_options(hough_spectrum.HoughSpectrumOptions, {"acept": 0.9}, "hough-spectrum")
    for fn, bad in ((map_merge.estimate_pair, {"confidence": 0.0}),
                    (hough_spectrum.estimate_pair, {"accept": 1.5}),
                    (fourier_mellin.estimate_pair, {"angle_bins": 4}),
                    (fourier_mellin.estimate_pair, {"no_such_option": 1})):
        g = OccupancyGrid(np.zeros((8, 8), np.int8), 0.1)
        with pytest.raises(InputError):
            fn(g, g, **bad)


def test_acceptance_index_counts_only_cells_known_in_both():
    a = np.array([[0, 0, 100, -1]], np.int8)
    b = np.array([[0, 100, 100, 0]], np.int8)
    assert acceptance_index(a, b) == (2 / 3, 2, 1)
    assert acceptance_index(a, np.full_like(a, -1)) == (0.0, 0, 0)


def test_crop_pair_truth_puts_the_second_window_back_on_the_first(intel, crop_case):
    back = resample(crop_case.b, crop_case.truth, crop_case.a)
    omega, agr, _ = acceptance_index(crop_case.a.data, back.data)
    assert agr > 0.5 * np.count_nonzero(crop_case.a.data >= 0)
    assert omega > 0.97


# -- each peer on a crop case -------------------------------------------------------------------

@pytest.mark.parametrize("method", sorted(ESTIMATORS))
def test_peer_recovers_a_known_motion_between_crops_of_a_real_map(method, crop_case):
    est = ESTIMATORS[method](crop_case.a, crop_case.b)
    assert est.method == method
    assert recovered(est, crop_case.truth, crop_case.b, crop_case.a.resolution), est
    assert est.accepted
    assert est.candidates[0] == (est.transform, est.confidence)
    assert est.seconds > 0


@pytest.mark.parametrize("method", sorted(ESTIMATORS))
def test_peer_is_deterministic(method, crop_case):
    e1 = ESTIMATORS[method](crop_case.a, crop_case.b, seed=1)
    e2 = ESTIMATORS[method](crop_case.a, crop_case.b, seed=2)
    assert e1.transform.is_close(e2.transform, atol=1e-12) and e1.confidence == e2.confidence


def test_coarser_second_map_is_resampled_and_still_placed(intel, crop_case):
    b = crop_case.b
    coarse = OccupancyGrid(np.full((b.rows // 2, b.cols // 2), -1, np.int8), 2 * b.resolution, b.origin)
    coarse = resample(b, Transform2D.identity(), coarse)
    est = fourier_mellin.estimate_pair(crop_case.a, coarse)
    assert recovered(est, crop_case.truth, coarse, crop_case.a.resolution)


@pytest.mark.parametrize("method", sorted(ESTIMATORS))
def test_unrelated_maps_are_not_merged_with_confidence(method, crop_case):
    """A cave and an office share nothing: each peer either refuses or scores the pair below
    the true overlap (the Hough acceptance index is high on any two mostly free maps, so its
    guarantee is the ranking; the other two refuse)."""
    cave = make_cave(seed=5, size=(24.0, 24.0), resolution=crop_case.a.resolution)
    fn = ESTIMATORS[method]
    true = fn(crop_case.a, crop_case.b)
    false = fn(crop_case.a, cave)
    assert false.confidence < true.confidence
    if method != hough_spectrum.METHOD:
        assert not false.accepted


@pytest.mark.parametrize("method", sorted(ESTIMATORS))
def test_map_without_walls_gives_no_confident_answer(method, crop_case):
    empty = OccupancyGrid(np.zeros((50, 50), np.int8), crop_case.a.resolution)
    est = ESTIMATORS[method](crop_case.a, empty)
    assert not est.accepted


# -- Hough spectrum internals against obvious references -----------------------------------------

def test_hough_transform_matches_a_loop():
    rng = np.random.default_rng(3)
    pts = rng.uniform(0, 40, (25, 2))
    ht, thetas = hough_spectrum.hough_transform(pts, 36, 1.5)
    c = pts - pts.mean(axis=0)
    radius = np.sqrt((c ** 2).sum(axis=1).max())
    ref = np.zeros_like(ht)
    for x, y in c:
        for j, th in enumerate(thetas):
            ref[j, int(math.floor((x * math.cos(th) + y * math.sin(th) + radius) / 1.5 + 0.5))] += 1
    np.testing.assert_array_equal(ht, ref)


def test_circular_cross_correlation_peaks_at_the_shift():
    rng = np.random.default_rng(4)
    b = rng.random(60)
    a = np.roll(b, 17)                                   # a(j) = b(j - 17)
    cc = hough_spectrum.circular_cross_correlation(a, b)
    ref = np.array([sum(a[j] * b[(j - k) % 60] for j in range(60)) for k in range(60)])
    np.testing.assert_allclose(cc, (ref - ref.min()) / (ref.max() - ref.min()), atol=1e-12)
    assert int(np.argmax(cc)) == 17
    assert list(hough_spectrum.circular_local_maxima(np.array([3., 1, 2, 1, 5, 4, 0, 2]), 3)) == [4, 0, 2]


def test_histogram_shift_matches_a_direct_correlation():
    rng = np.random.default_rng(5)
    qa = rng.uniform(10, 90, 300)
    qb = np.concatenate([qa[:200] - 23.0, rng.uniform(0, 60, 50)])
    ha = Counter(np.floor(qa).astype(int).tolist())
    hb = Counter(np.floor(qb).astype(int).tolist())
    shifts = list(range(-150, 151))
    score = [sum(n * ha.get(x + s, 0) for x, n in hb.items()) for s in shifts]
    assert hough_spectrum._axis_shift(qa, qb) == shifts[int(np.argmax(score))] == 23


def test_fourier_mellin_highpass_is_zero_at_dc_and_two_at_nyquist():
    h = fourier_mellin.highpass_emphasis(64)
    assert h[32, 32] == 0.0 and h[0, 0] == pytest.approx(2.0)
    assert np.all(h >= 0) and np.all(h <= 2)


# -- map_merge on N maps --------------------------------------------------------------------------

def chain_of_windows(intel, count=4):
    """``count`` windows in a row, each overlapping the next by 59%, every one turned into a
    frame of its own; truth maps each frame into the first one's."""
    rng = np.random.default_rng(3)
    data, res = intel.trinary(), intel.resolution
    size, step, r0, c0 = 220, 90, 150, 40
    grids, to_world = [], []
    for k in range(count):
        src = OccupancyGrid(data[r0:r0 + size, c0 + k * step:c0 + k * step + size], res,
                            (res * (c0 + k * step), res * r0, 0.0))
        t = Transform2D(*rng.uniform(-5, 5, 2), rng.uniform(-math.pi, math.pi))
        side = int(size * 1.5)
        centre = t.inverse(src.cell_to_world(size / 2, size / 2))
        target = OccupancyGrid(np.full((side, side), -1, np.int8), res,
                               (centre[0] - side * res / 2, centre[1] - side * res / 2, 0.0))
        grids.append(resample(src, t.inverse, target))
        to_world.append(t)
    return grids, [to_world[0].inverse @ t for t in to_world]


@pytest.fixture(scope="module")
def chain(intel):
    return chain_of_windows(intel)


def test_corrected_chaining_places_every_map(chain):
    grids, truth = chain
    est = map_merge.estimate_maps(grids, chaining="corrected")
    assert est.component == (0, 1, 2, 3) and est.reference == 0
    assert est.transforms[0] == Transform2D.identity()
    for k in range(4):
        assert recovered(PairEstimate(est.transforms[k], 1.0, True), truth[k], grids[k], grids[0].resolution), k
    # consistent: composing through map 1 gives the same place as directly
    d, r = placement_error(est.transforms[1] @ est.transforms[1].inverse @ est.transforms[2],
                           est.transforms[2], grids[2])
    assert d < 1e-9 and r < 1e-12
    assert all(abs(s - 1) < 0.02 for s in est.scales)
    assert est.pair_confidence.shape == (4, 4) and np.allclose(est.pair_confidence, est.pair_confidence.T)


def test_shipped_chaining_misplaces_maps_two_edges_from_the_centre(chain):
    grids, truth = chain
    fixed = map_merge.estimate_maps(grids, chaining="corrected")
    shipped = map_merge.estimate_maps(grids, chaining="shipped")
    assert shipped.tree == fixed.tree
    depth = {shipped.centre: 0}
    for frm, to in shipped.tree:
        depth[to] = depth[frm] + 1
    assert depth[0] <= 1 and max(depth.values()) >= 2
    for k, dk in depth.items():
        d, _ = placement_error(shipped.transforms[k], fixed.transforms[k], grids[k])
        if dk <= 1:            # next to the centre both orders agree
            assert d < 1e-6, k
        else:                  # further out the shipped order misplaces the map
            assert d > 10 * grids[0].resolution, k
            assert not recovered(PairEstimate(shipped.transforms[k], 1.0, True), truth[k], grids[k],
                                 grids[0].resolution)


def _opencv_pairwise(grids):
    """OpenCV's own features and pairwise matches, and the same as this module's pairs."""
    finder = cv2.AKAZE_create()
    feats = [cv2.detail.computeImageFeatures2(finder, map_merge.grid_image(g)) for g in grids]
    pm = cv2.detail_AffineBestOf2NearestMatcher(False, False, 0.3, 6).apply2(feats)
    n = len(grids)
    pairs = {}
    for i in range(n):
        for j in range(n):
            p = pm[i * n + j]
            if i == j:
                pairs[i, j] = map_merge._Pair()
                continue
            m = np.array([(d.queryIdx, d.trainIdx) for d in p.getMatches()], np.int64).reshape(-1, 2)
            inliers = np.array(p.getInliers(), bool).ravel() if len(m) else np.zeros(0, bool)
            pairs[i, j] = map_merge._Pair(None if p.H is None else np.asarray(p.H, float), m, inliers,
                                          int(p.num_inliers), float(p.confidence))
    mine = [map_merge._Features(np.array([k.pt for k in f.keypoints], np.float32), None) for f in feats]
    return feats, pm, pairs, mine


def _unique_tree(pairs, n):
    weights = sorted((pairs[i, j].num_inliers for i in range(n) for j in range(i + 1, n)
                      if pairs[i, j].H is not None), reverse=True)
    # the n - 1 strongest pairs are untied and stronger than the rest: one spanning tree only
    return len(set(weights[:n - 1])) == n - 1 and weights[n - 2] > weights[n - 1]


def test_spanning_tree_and_shipped_chaining_match_opencv(chain):
    """Fed OpenCV's own pairwise matches, the spanning tree, its centre and the shipped chaining
    reproduce ``cv2.detail.AffineBasedEstimator``; the component matches
    ``leaveBiggestComponent``."""
    grids, _ = chain
    feats, pm, pairs, _ = _opencv_pairwise(grids)
    n = len(grids)
    assert _unique_tree(pairs, n)
    conf = np.array([[pairs[i, j].confidence for j in range(n)] for i in range(n)])
    for thr in (0.3, 1.0, 1.5):
        assert map_merge._biggest_component(conf, thr) == list(cv2.detail.leaveBiggestComponent(feats, pm, thr))
    ok, cams = cv2.detail_AffineBasedEstimator().apply(feats, pm, None)
    assert ok
    mine, _, _ = map_merge._chain(pairs, n, shipped=True)
    for k in range(n):
        np.testing.assert_allclose(mine[k], cams[k].R, atol=1e-6)


@pytest.fixture(scope="module")
def loop(intel):
    """Four windows that all overlap one another (every pair confident): a graph with loops."""
    rng = np.random.default_rng(4)
    data, res, size = intel.trinary(), intel.resolution, 220
    grids, to_world = [], []
    for r0, c0 in ((150, 40), (150, 110), (210, 75), (200, 140)):
        src = OccupancyGrid(data[r0:r0 + size, c0:c0 + size], res, (res * c0, res * r0, 0.0))
        t = Transform2D(*rng.uniform(-5, 5, 2), rng.uniform(-math.pi, math.pi))
        side = int(size * 1.5)
        centre = t.inverse(src.cell_to_world(size / 2, size / 2))
        target = OccupancyGrid(np.full((side, side), -1, np.int8), res,
                               (centre[0] - side * res / 2, centre[1] - side * res / 2, 0.0))
        grids.append(resample(src, t.inverse, target))
        to_world.append(t)
    return grids, [to_world[0].inverse @ t for t in to_world]


def test_shipped_bundle_adjustment_matches_opencv(loop):
    grids, _ = loop
    feats, pm, pairs, mine_feats = _opencv_pairwise(grids)
    n = len(grids)
    assert _unique_tree(pairs, n)
    ok, cams = cv2.detail_AffineBasedEstimator().apply(feats, pm, None)
    for c in cams:
        c.R = c.R.astype(np.float32)
    adjuster = cv2.detail_BundleAdjusterAffinePartial()
    adjuster.setConfThresh(1.0)
    ok, cams = adjuster.apply(feats, pm, cams)
    assert ok
    mine, centre, _ = map_merge._chain(pairs, n, shipped=True)
    mine = map_merge._bundle_adjust(mine, mine_feats, pairs, 1.0, shipped=True)
    inv_c = np.linalg.inv(mine[centre])
    for k in range(n):
        np.testing.assert_allclose(inv_c @ mine[k], np.asarray(cams[k].R, float), rtol=0, atol=2e-3)


def test_corrected_bundle_adjustment_keeps_maps_in_place_where_shipped_does_not(loop):
    grids, truth = loop
    res = grids[0].resolution
    fixed = map_merge.estimate_maps(grids, chaining="corrected")
    assert np.all(fixed.pair_confidence[~np.eye(4, dtype=bool)] >= 1.0)
    for k in range(4):
        assert recovered(PairEstimate(fixed.transforms[k], 1.0, True), truth[k], grids[k], res), k
    shipped = map_merge.estimate_maps(grids, chaining="shipped")
    wrong = [k for k in range(4)
             if not recovered(PairEstimate(shipped.transforms[k], 1.0, True), truth[k], grids[k], res)]
    assert len(wrong) >= 2
    assert max(abs(s - 1) for s in shipped.scales) > 0.05


def test_maps_left_out_when_nothing_matches(chain):
    grids, _ = chain
    cave = make_cave(seed=2, size=(20.0, 20.0), resolution=grids[0].resolution)
    est = map_merge.estimate_maps([grids[0], grids[1], cave])
    assert est.component == (0, 1)
    assert est.transforms[2] is None and est.confidences[2] == 0.0
    alone = map_merge.estimate_maps([grids[0], cave])
    assert alone.transforms == (Transform2D.identity(), None) and alone.centre is None
    with pytest.raises(InputError, match="chaining"):
        map_merge.estimate_maps(grids, chaining="backwards")
    with pytest.raises(InputError, match="at least two"):
        map_merge.estimate_maps(grids[:1])


def test_warp_cells_is_resample_in_cell_units():
    data = np.full((5, 6), -1, np.int8)
    data[1, 2] = 100
    out = warp_cells(data, Transform2D(3.0, 1.0, 0.0), (8, 9))
    assert out[2, 5] == 100 and np.count_nonzero(out == 100) == 1
