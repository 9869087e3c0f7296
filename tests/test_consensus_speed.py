"""The cheaper parts of the consensus method decide as the full ones: the null distribution
drawn until the decision is settled, the fall-back's rotation sweep a level up the pyramid."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fusionkit.errors import InputError
from fusionkit.grid import OccupancyGrid
from fusionkit.mapio import load_map
from fusionkit.methods.consensus import ConsensusConfig, estimate_pair, prepare_maps
from fusionkit.methods.consensus._search import evidence_raster, pyramid_rotations
from fusionkit.methods.peers import crop_pair
from fusionkit.transform import Transform2D

REPO = Path(__file__).resolve().parents[1]
REAL = REPO / "maps" / "real"
if not (REAL / "intel_lab.yaml").is_file():
    REAL = REPO.parent / "shared" / "maps" / "real"


@pytest.fixture(scope="module")
def intel():
    return load_map(REAL / "intel_lab.yaml")


@pytest.fixture(scope="module")
def intel_crop(intel):
    return crop_pair(intel, np.random.default_rng(3), size=200, min_overlap=0.4)


def test_a_clear_pair_stops_drawing_wrong_placements_early_with_the_same_decision(intel_crop):
    quick = estimate_pair(intel_crop.a, intel_crop.b).diagnostics["pair"]
    full = estimate_pair(intel_crop.a, intel_crop.b,
                         config=ConsensusConfig(null_margin=math.inf)).diagnostics["pair"]
    assert quick.accepted and full.accepted
    assert len(quick.null.fractions) < len(full.null.fractions) == 64
    assert quick.transform.error_to(full.transform)[0] < intel_crop.a.resolution


def test_a_pair_of_two_buildings_is_refused_with_or_without_the_early_stop():
    a = crop_pair(load_map(REAL / "gatech_ilab.yaml"), np.random.default_rng(0), size=150,
                  min_overlap=0.4).a
    b = crop_pair(load_map(REAL / "mit_stata_basement.yaml"), np.random.default_rng(1), size=150,
                  min_overlap=0.4).a
    for margin in (5.0, math.inf):
        assert not estimate_pair(a, b, config=ConsensusConfig(null_margin=margin)).accepted


@pytest.mark.parametrize("degrees", [37.0, -121.0, 170.0])
def test_the_pyramid_sweep_finds_the_rotation_of_a_turned_map(intel_crop, degrees):
    a, b = prepare_maps([intel_crop.a, intel_crop.b])
    turn = Transform2D(0.0, 0.0, math.radians(degrees))
    truth = intel_crop.truth @ turn.inverse            # B's points turned by ``turn`` first
    pts = turn(b.points)
    rots = pyramid_rotations(evidence_raster(a), pts, step=math.radians(2.0), count=12)
    assert any(abs(math.remainder(r - truth.theta, 2 * math.pi)) < math.radians(3) for r in rots)


@pytest.mark.parametrize("field, value", [("null_margin", 0.0), ("null_margin", -1.0),
                                          ("fallback_rotations", -1)])
def test_bad_settings_of_the_cheaper_parts_are_refused(field, value):
    with pytest.raises(InputError, match=field):
        ConsensusConfig(**{field: value})


@pytest.mark.parametrize("seed", range(4))
def test_the_padded_forward_transform_gives_the_numbers_of_rfft2(seed):
    from scipy import fft as sfft

    from fusionkit.methods.consensus._search import _rfft2_padded
    rng = np.random.default_rng(seed)
    h, w = (int(v) for v in rng.integers(3, 200, 2))
    shape = (sfft.next_fast_len(h + int(rng.integers(1, 200)), real=True),
             sfft.next_fast_len(w + int(rng.integers(1, 200)), real=True))
    img = rng.standard_normal((h, w)).astype(np.float32)
    assert np.array_equal(_rfft2_padded(img, shape), sfft.rfft2(img, s=shape, workers=1))


def _same(p, q) -> bool:
    return (p.accepted == q.accepted and p.ambiguous == q.ambiguous and p.nfa == q.nfa
            and p.reason == q.reason and (p.transform is None) == (q.transform is None)
            and (p.transform is None or (p.transform.x, p.transform.y, p.transform.theta)
                 == (q.transform.x, q.transform.y, q.transform.theta)))


def test_a_pair_searched_again_exhaustively_decides_as_a_fresh_exhaustive_search(intel_crop):
    from fusionkit.methods.consensus._pair import estimate_indexed
    from fusionkit.methods.consensus._search import orientation_histogram

    cfg = ConsensusConfig()

    def search(a, b, exhaustive):
        return estimate_indexed(a, b, cfg, hist_a=orientation_histogram(a),
                                hist_b=orientation_histogram(b), evidence_a=evidence_raster(a),
                                seed=4, exhaustive=exhaustive)

    a, b = prepare_maps([intel_crop.a, intel_crop.b])
    search(a, b, False)                       # what the first search keeps for the pair
    again = search(a, b, True)
    fresh = search(*prepare_maps([intel_crop.a, intel_crop.b]), True)
    assert again.transform is not None and again.accepted
    assert _same(again, fresh)
    assert [c.transform for c in again.refined] == [c.transform for c in fresh.refined]


def test_merging_leaves_nothing_of_its_pairs_in_the_maps(intel_crop):
    from fusionkit.methods.consensus import estimate_maps

    res = estimate_maps([intel_crop.a, intel_crop.b])
    assert res.transforms[1] is not None
    for ix in res.indexes:
        assert not any(isinstance(k, tuple) and k[0] == "pairs" for k in ix.cache)


@pytest.mark.parametrize("degrees", [0.0, 33.0, -97.0, 180.0])
def test_the_raster_kernel_puts_the_walls_where_the_plain_computation_does(intel_crop, degrees):
    from fusionkit.methods.consensus._search import Correlator, _raster, _turned_cells

    a, b = prepare_maps([intel_crop.a, intel_crop.b])
    ev = evidence_raster(a)
    span = Correlator(ev, b.points).span
    theta = math.radians(degrees)
    cells = _turned_cells(ev, b.points, theta)
    lo = cells.min(axis=0)
    want = np.zeros((span, span), np.float32)
    want[np.minimum(cells[:, 1] - lo[1], span - 1), np.minimum(cells[:, 0] - lo[0], span - 1)] = 1
    img, got_lo = _raster(ev, b.points, theta, span)
    assert np.array_equal(got_lo, lo)
    assert np.array_equal(img, want)


@pytest.mark.parametrize("f", [1, 2, 3, 5])
def test_pooling_reduces_each_block_as_a_block_reduction_does(f):
    from fusionkit.methods.consensus._search import _pool

    mask = np.random.default_rng(f).random((37, 52)) < 0.4
    rr, cc = -(-37 // f) * f, -(-52 // f) * f
    pad = np.zeros((rr, cc), bool)
    pad[:37, :52] = mask
    blocks = pad.reshape(rr // f, f, cc // f, f)
    assert np.array_equal(_pool(mask, f, "any"), blocks.any(axis=(1, 3)))
    assert np.array_equal(_pool(mask, f, "all"), blocks.all(axis=(1, 3)))


def test_each_cell_is_given_the_wall_of_its_distance_label(intel):
    import cv2

    from fusionkit.methods.consensus._index import _nearest_walls

    occupied = intel.occupied_mask()
    dist, nearest = _nearest_walls(occupied)
    # the plain computation: OpenCV numbers the wall pixels in raster order
    want, labels = cv2.distanceTransformWithLabels((~occupied).astype(np.uint8), cv2.DIST_L2,
                                                   cv2.DIST_MASK_PRECISE,
                                                   labelType=cv2.DIST_LABEL_PIXEL)
    wr, wc = np.nonzero(occupied)
    assert np.array_equal(dist, want)
    assert np.array_equal(nearest[0], wr[labels - 1]) and np.array_equal(nearest[1], wc[labels - 1])
    assert occupied[nearest[0], nearest[1]].all()


def test_the_nearness_of_kept_placements_is_that_of_their_displacement():
    from fusionkit.methods.consensus._verify import Placements, displacement

    rng = np.random.default_rng(7)
    box = rng.uniform(-10, 10, (4, 2))
    kept = [Transform2D(*rng.normal(0, 0.3, 2), rng.normal(0, 0.02)) for _ in range(30)]
    places = Placements(box)
    for t in kept:
        places.add(t)
    for _ in range(300):
        t = Transform2D(*rng.normal(0, 0.3, 2), rng.normal(0, 0.02))
        for limit in (0.05, 0.2, 0.5):
            assert places.near(t, limit) == any(displacement(t, u, box) < limit for u in kept)


@pytest.mark.parametrize("degrees", [12.0, -150.0])
def test_the_correlation_is_the_exact_sum_of_the_evidence_under_the_walls(intel_crop, degrees):
    from scipy import fft as sfft

    from fusionkit.methods.consensus._search import Correlator, _turned_cells

    a, b = prepare_maps([intel_crop.a, intel_crop.b])
    corr = Correlator(evidence_raster(a), b.points)
    theta = math.radians(degrees)
    got, lo = corr.correlate(theta)
    cells = _turned_cells(corr.ev, b.points, theta)
    img = np.zeros((corr.span, corr.span), np.float32)
    img[np.minimum(cells[:, 1] - lo[1], corr.span - 1),
        np.minimum(cells[:, 0] - lo[0], corr.span - 1)] = 1
    # A's evidence in whole steps, correlated in double precision: exact once rounded
    steps = np.rint(corr.ev.values.astype(np.float64) * corr.levels)
    assert np.array_equal(steps, corr.steps)
    want = np.rint(sfft.irfft2(sfft.rfft2(steps, s=corr.shape) * np.conj(sfft.rfft2(img, s=corr.shape)),
                               s=corr.shape))
    assert np.array_equal(got, want)
    # and at the best translation, the plain sum of the steps under B's walls
    r0, c0 = np.unravel_index(int(np.argmax(got)), got.shape)
    pad = np.zeros(corr.shape)
    pad[:steps.shape[0], :steps.shape[1]] = steps
    rr, cc = np.nonzero(img)
    assert got[r0, c0] == pad[(rr + r0) % corr.shape[0], (cc + c0) % corr.shape[1]].sum()


def test_the_translations_do_not_hang_on_the_rounding_of_the_transform(intel_crop, monkeypatch):
    # numpy multiplies the transforms with other vector instructions on another CPU, which
    # moves every correlation by a rounding residue: the translations found must not move
    from fusionkit.methods.consensus import _search

    a, b = prepare_maps([intel_crop.a, intel_crop.b])
    ev = evidence_raster(a)
    thetas = [math.radians(d) for d in (0.0, 31.0, -90.0, 178.0)]
    want = [_translations(_search, ev, b.points, th) for th in thetas]
    irfft2 = _search.sfft.irfft2
    rng = np.random.default_rng(3)

    def jittered(*args, **kwargs):
        out = irfft2(*args, **kwargs)
        return out + rng.uniform(-0.1, 0.1, out.shape).astype(out.dtype)

    monkeypatch.setattr(_search.sfft, "irfft2", jittered)
    got = [_translations(_search, ev, b.points, th) for th in thetas]
    assert got == want


def _translations(search, ev, points, theta):
    return [(t.x, t.y, t.theta, s)
            for t, s in search.Correlator(ev, points).translations(theta, count=6)]


def test_the_wall_directions_do_not_hang_on_the_last_bit_of_arctan2(monkeypatch):
    # walls along the grid's axes and diagonals lie exactly on the edges of the direction
    # histogram's bins; another CPU's arctan2 may differ from this one's in the last bit
    from fusionkit.methods.consensus import _search

    occ = np.zeros((120, 120), np.uint8)
    occ[20, 10:110] = 1
    occ[10:110, 60] = 1
    idx = np.arange(15, 105)
    occ[idx, idx] = 1
    occ[idx, 119 - idx] = 1
    a = prepare_maps([OccupancyGrid(np.where(occ, 100, 0).astype(np.int8), 0.05)])[0]
    want = _search.orientation_histogram(a)
    arctan2 = np.arctan2
    for way in (-np.inf, np.inf):
        monkeypatch.setattr(_search.np, "arctan2",
                            lambda y, x, way=way: np.nextafter(arctan2(y, x), way))
        assert np.array_equal(_search.orientation_histogram(a), want)
