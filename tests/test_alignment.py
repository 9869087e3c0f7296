"""The eq. 3 objective, its kernel, and PSO recovering a known transform."""

import math

import numpy as np

from fusionkit.alignment import (AlignmentConfig, align_points, dedupe_points, make_field,
                                 mse_cost, mse_cost_numpy, overlap_score)
from fusionkit.grid import OccupancyGrid
from fusionkit.pso import PSOConfig
from fusionkit.transform import Transform2D


def _room_points(res=0.1):
    """Walls of an irregular room with an inner wall (m)."""
    pts = []
    for x in np.arange(0, 8, res / 2):
        pts += [(x, 0.0), (x, 5.0)]
    for y in np.arange(0, 5, res / 2):
        pts += [(0.0, y), (8.0, y)]
    for y in np.arange(0, 3, res / 2):
        pts.append((3.0, y))
    for x in np.arange(5, 8, res / 2):
        pts.append((x, 3.5))
    return np.array(pts)


def test_kernel_agrees_with_the_plain_numpy_mse():
    rng = np.random.default_rng(0)
    ref = _room_points()
    fld = make_field(ref, 0.1, sigma=1.0)
    mov = dedupe_points(Transform2D(0.3, -0.2, 0.4).inverse(ref), 0.1)
    params = np.column_stack([rng.uniform(-3, 3, 20), rng.uniform(-3, 3, 20), rng.uniform(-3.1, 3.1, 20)])
    # the numpy version draws the moved mask, where two points rotated into one cell make a 2;
    # the kernel treats the moved mask as binary points, so they agree exactly without rotation
    # and within the few collisions otherwise
    fast, slow = mse_cost(fld, mov, params), mse_cost_numpy(fld, mov, params)
    np.testing.assert_allclose(fast, slow, rtol=0.08)
    p0 = params.copy()
    p0[:, 2] = 0.0
    p0[:, :2] = np.round(p0[:, :2], 1)
    np.testing.assert_allclose(mse_cost(fld, mov, p0), mse_cost_numpy(fld, mov, p0), rtol=1e-5)


def test_true_transform_has_the_lowest_cost():
    ref = _room_points()
    truth = Transform2D(1.2, -0.7, 2.0)
    mov = truth.inverse(ref)
    fld = make_field(ref, 0.1)
    p_true = np.array([truth.to_paper()])
    p_off = np.array([Transform2D(1.6, -0.7, 2.0).to_paper(), Transform2D(1.2, -0.7, 2.2).to_paper()])
    assert mse_cost(fld, mov, p_true)[0] < mse_cost(fld, mov, p_off).min()


def test_pso_recovers_a_known_transform_from_a_rough_seed():
    ref = _room_points()
    truth = Transform2D(1.2, -0.7, 2.0)
    mov = truth.inverse(ref)
    rough = Transform2D(1.6, -0.4, 2.15)
    cfg = AlignmentConfig(pso=PSOConfig(particles=30, iterations=60))
    al = align_points(ref, mov, 0.1, config=cfg, seeds=[rough], seed=3)
    dt, dr = al.transform.error_to(truth)
    assert dt < 0.1 and math.degrees(dr) < 1.0
    assert len(al.pso.history) == al.pso.nit + 1
    assert np.all(np.diff(al.pso.history) <= 0)


def test_same_seed_same_alignment():
    ref = _room_points()
    mov = Transform2D(0.5, 0.5, 0.5).inverse(ref)
    cfg = AlignmentConfig(pso=PSOConfig(particles=20, iterations=20))
    a1 = align_points(ref, mov, 0.1, config=cfg, seed=5)
    a2 = align_points(ref, mov, 0.1, config=cfg, seed=5)
    assert a1.params == a2.params
    np.testing.assert_array_equal(a1.pso.history, a2.pso.history)


def test_overlap_score_separates_right_from_wrong_placement():
    d = np.full((60, 90), -1, np.int8)
    d[5:55, 5:85] = 0
    d[5, 5:85] = d[54, 5:85] = 100
    d[5:55, 5] = d[5:55, 84] = 100
    d[20:54, 40] = 100
    a = OccupancyGrid(d, 0.1)
    b = OccupancyGrid(d, 0.1, (2.0, 1.0, 0.3))       # the same map, its frame moved
    right = a.origin_transform @ b.origin_transform.inverse
    s_right, n = overlap_score(a, b, right)
    s_wrong, _ = overlap_score(a, b, Transform2D(0.7, 0.5, 0.2) @ right)
    assert s_right > 0.95 and n > 100
    assert s_wrong < 0.5


def test_more_seeds_than_particles_fill_the_swarm_with_the_best():
    ref = _room_points()
    truth = Transform2D(1.2, -0.7, 2.0)
    mov = truth.inverse(ref)
    seeds = [truth] + [Transform2D(5.0, 5.0, 0.0)] * 30
    cfg = AlignmentConfig(pso=PSOConfig(particles=5, iterations=5))
    al = align_points(ref, mov, 0.1, config=cfg, seeds=seeds, seed=0)
    assert len(al.seeds) == 5
    dt, dr = al.transform.error_to(truth)
    assert dt < 0.1 and dr < 0.02


def test_bad_points_resolution_or_tolerance_are_one_clear_error():
    """They raised IndexError, OverflowError, MemoryError or a numpy ValueError, or were taken
    silently: a one-column moving mask was aligned, and a negative ``tolerance`` dilated ``a``'s walls until
    they filled the map (scipy's ``iterations < 1``), so every placement scored 1."""
    import pytest

    from fusionkit.alignment import refine_points
    from fusionkit.errors import InputError
    pts = _room_points()
    cases = [((pts, pts, 0.0), "resolution must be > 0"),
             ((pts, pts, float("nan")), "resolution must be a finite number"),
             ((pts[:, :1], pts, 0.1), r"reference must be an \(N, 2\) array.*shape \(\d+, 1\)"),
             ((pts, pts[:, :1], 0.1), r"moving must be an \(N, 2\) array"),
             ((pts, np.full((3, 2), np.nan), 0.1), "moving holds NaN"),
             # points in millimetres, a resolution of 1e-5 m: numpy's MemoryError (terabytes)
             ((pts * 1000, pts * 1000, 0.1),
              r"cells, more than the 200000000 fusionkit can hold; give the points in metres"),
             ((pts, pts, 1e-5), r"at 1e-05 m cells, \d+ x \d+ cells, more than")]
    for args, said in cases:
        with pytest.raises(InputError, match=said):
            align_points(*args, seed=0)
    with pytest.raises(InputError, match="reach and turn must be >= 0"):
        refine_points(pts, pts, Transform2D(), 0.1, reach=-0.1, seed=0)
    with pytest.raises(InputError, match="initial must be a Transform2D"):
        refine_points(pts, pts, (0.0, 0.0, 0.0), 0.1, seed=0)
    d = np.full((40, 40), -1, np.int8)
    d[5:35, 5:35] = 0
    d[5, 5:35] = d[34, 5:35] = 100
    g = OccupancyGrid(d, 0.1)
    far = Transform2D(0.0, 1.5, 0.0)               # b's walls 15 cells off a's walls
    assert overlap_score(g, g, far, tolerance=1)[0] < 0.5
    for tol, said in ((-1, "tolerance must be >= 0"), (1.5, "tolerance must be a whole number")):
        with pytest.raises(InputError, match=said):
            overlap_score(g, g, far, tolerance=tol)


def test_alignment_settings_of_the_wrong_kind_are_refused():
    """sigma=NaN softened the mask to nothing (the paper's method then refused a placeable
    pair without an error); a dict as pso, or "no" as seeded (taken as True), went through."""
    import pytest

    from fusionkit.errors import InputError
    for kw, said in ((dict(sigma=math.nan), "sigma must be a finite number"),
                     (dict(pso={}), "pso must be a PSOConfig"),
                     (dict(seeded="no"), "seeded must be True or False"),
                     (dict(max_seeds=1.5), "max_seeds must be a whole number")):
        with pytest.raises(InputError, match=said):
            AlignmentConfig(**kw)
    assert AlignmentConfig(seeded=np.bool_(False)).seeded is False


def test_seeds_and_config_of_the_wrong_kind_are_one_clear_error():
    """A tuple as a seed raised "'tuple' object has no attribute 'to_paper'"; a PSOConfig as
    config raised AttributeError 'sigma'."""
    import pytest

    from fusionkit.errors import InputError
    pts = _room_points()
    with pytest.raises(InputError, match="seeds must be Transform2D objects"):
        align_points(pts, pts, 0.1, seeds=[(0.0, 0.0, 0.0)], seed=0)
    with pytest.raises(InputError, match="config must be an AlignmentConfig, got PSOConfig"):
        align_points(pts, pts, 0.1, config=PSOConfig(), seed=0)
