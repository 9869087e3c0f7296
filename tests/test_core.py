"""Transforms, grid coordinates, resampling, mapping, scan logs and atomic writes."""

import math
import os

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from fusionkit.errors import InputError, ScanLogError
from fusionkit._atomic import atomic_path, check_not_input, write_text_atomic
from fusionkit.grid import OccupancyGrid
from fusionkit.mapping import MappingConfig, build_grid
from fusionkit.resample import canvas_for, resample
from fusionkit.scanlog import ScanLog, load_scans, save_scans
from fusionkit.transform import Transform2D, wrap_angle

coord = st.floats(-1e3, 1e3, allow_nan=False)
angle = st.floats(-20.0, 20.0, allow_nan=False)
turn = st.floats(-2 * math.pi, 2 * math.pi, allow_nan=False)   # a grid origin's yaw (radians)
transforms = st.builds(Transform2D, coord, coord, angle)
points = st.lists(st.tuples(coord, coord), min_size=1, max_size=20).map(np.array)


# -- Transform2D -----------------------------------------------------------------------------
@given(transforms, points)
def test_inverse_undoes_the_transform(t, p):
    np.testing.assert_allclose(t.inverse(t(p)), p, atol=1e-6)


@given(transforms, transforms, points)
def test_composition_is_function_composition(a, b, p):
    np.testing.assert_allclose((a @ b)(p), a(b(p)), atol=1e-6)


@given(transforms, transforms, transforms)
def test_composition_is_associative(a, b, c):
    assert ((a @ b) @ c).is_close(a @ (b @ c), atol=1e-6)


@given(transforms)
def test_matrix_round_trip_and_theta_range(t):
    assert Transform2D.from_matrix(t.matrix).is_close(t, atol=1e-9)
    assert -math.pi <= t.theta < math.pi
    np.testing.assert_allclose(t.matrix @ t.inverse.matrix, np.eye(3), atol=1e-9)


@given(coord, coord, angle, points)
def test_from_paper_is_eq4_translate_then_rotate(dx, dy, phi, p):
    t = Transform2D.from_paper(dx, dy, phi)
    x, y = p[:, 0], p[:, 1]
    eq4 = np.stack([(x + dx) * math.cos(phi) - (y + dy) * math.sin(phi),
                    (x + dx) * math.sin(phi) + (y + dy) * math.cos(phi)], axis=1)
    np.testing.assert_allclose(t(p), eq4, atol=1e-6)
    np.testing.assert_allclose(Transform2D.from_paper(*t.to_paper()).matrix, t.matrix, atol=1e-9)


def test_transform_dict_round_trip_and_bad_values():
    t = Transform2D(1.5, -2.25, 0.5)
    assert Transform2D.from_dict(t.as_dict(digits=None)) == t
    with pytest.raises(ValueError):
        Transform2D.from_dict({"x": 1, "y": 2})
    with pytest.raises(ValueError):
        Transform2D(float("nan"), 0, 0)


def test_apply_pose_turns_headings():
    t = Transform2D(1.0, 0.0, math.pi / 2)
    out = t.apply_pose([[1.0, 0.0, 0.0]])
    np.testing.assert_allclose(out, [[1.0, 1.0, math.pi / 2]], atol=1e-12)
    assert wrap_angle(3 * math.pi) == pytest.approx(-math.pi)


# -- OccupancyGrid ---------------------------------------------------------------------------
@settings(max_examples=50)
@given(st.floats(0.01, 1.0), coord, coord, turn, st.integers(0, 49), st.integers(0, 79))
def test_cell_world_round_trip(res, ox, oy, yaw, r, c):
    g = OccupancyGrid(np.zeros((50, 80), np.int8), res, (ox, oy, yaw))
    rr, cc = g.world_to_cell(g.cell_to_world(r, c))
    assert math.floor(rr + 1e-9) == r and math.floor(cc + 1e-9) == c
    assert rr - r == pytest.approx(0.5, abs=1e-6) and cc - c == pytest.approx(0.5, abs=1e-6)


def test_cell_centre_follows_the_contract():
    g = OccupancyGrid(np.zeros((4, 4)), 0.5, (1.0, 2.0, math.pi / 2))
    # origin + R(yaw) @ ((c + 0.5) res, (r + 0.5) res) with r=1, c=2: (1.25, 0.75) turned 90 deg
    np.testing.assert_allclose(g.cell_to_world(1, 2), [1.0 - 0.75, 2.0 + 1.25])


def test_grid_refuses_bad_geometry():
    with pytest.raises(ValueError, match="resolution"):
        OccupancyGrid(np.zeros((2, 2)), 0.0)
    with pytest.raises(ValueError, match="2-D"):
        OccupancyGrid(np.zeros(4), 0.1)
    g = OccupancyGrid(np.array([[-1, 0], [100, 70]]), 0.1)
    assert g.counts() == {"occupied": 2, "free": 1, "unknown": 1}
    assert g.trinary().tolist() == [[-1, 0], [100, 100]]
    with pytest.raises(ValueError):
        g.data[0, 0] = 5          # grids are values: their cells cannot be changed in place


@pytest.mark.parametrize("cells, said", [
    (np.array([[0, 100, 200, 255]]), "from 0 to 255"),          # an image's pixels: 200 became -56
    (np.array([[0.0, 0.3, 0.9]]), "fractions"),                  # probabilities: all became free
    (np.array([[0.0, np.nan]]), "NaN"),
    (np.array([[-5, 0]]), "from -5 to 0"),
])
def test_grid_refuses_cells_it_would_change_in_the_cast(cells, said):
    with pytest.raises(InputError, match=said):
        OccupancyGrid(cells, 0.1)
    # whole numbers in range are taken whatever their type
    assert OccupancyGrid(np.array([[-1.0, 0.0, 100.0]]), 0.1).data.tolist() == [[-1, 0, 100]]
    assert OccupancyGrid(np.array([[0, 55, 100]], np.uint8), 0.1).data.tolist() == [[0, 55, 100]]


# -- resample ---------------------------------------------------------------------------------
def _naive_resample(src: OccupancyGrid, t: Transform2D, target: OccupancyGrid) -> np.ndarray:
    out = np.full(target.shape, -1, np.int8)
    for r in range(target.rows):
        for c in range(target.cols):
            p = t.inverse(target.cell_to_world(r, c))
            rr, cc = src.world_to_cell(p)
            ri, ci = math.floor(rr), math.floor(cc)
            if 0 <= ri < src.rows and 0 <= ci < src.cols:
                out[r, c] = src.data[ri, ci]
    return out


def test_resample_matches_a_naive_reference():
    rng = np.random.default_rng(0)
    src = OccupancyGrid(rng.choice([-1, 0, 100], (23, 31)).astype(np.int8), 0.1, (0.3, -0.2, 0.4))
    t = Transform2D(0.7, 1.1, -0.9)
    target = OccupancyGrid(np.zeros((40, 45), np.int8), 0.07, (-1.0, -0.5, 0.2))
    np.testing.assert_array_equal(resample(src, t, target).data, _naive_resample(src, t, target))


def test_resample_identity_onto_itself_is_exact_and_canvas_covers_the_known_cells():
    rng = np.random.default_rng(1)
    g = OccupancyGrid(rng.choice([-1, 0, 100], (30, 20)).astype(np.int8), 0.05, (1.0, 2.0, 0.0))
    np.testing.assert_array_equal(resample(g, Transform2D.identity(), g).data, g.data)
    t = Transform2D(3.0, -1.0, 2.0)
    canvas = canvas_for([g], [t], 0.05)
    moved = resample(g, t, canvas)
    assert moved.counts()["occupied"] == pytest.approx(g.counts()["occupied"], rel=0.1)


# -- mapping ----------------------------------------------------------------------------------
def test_build_grid_marks_walls_occupied_and_the_space_before_them_free():
    # a robot at the origin in a 4 m x 4 m square room seen with 360 beams
    n = 360
    ang = -math.pi + 2 * math.pi * np.arange(n) / n
    r = 2.0 / np.maximum(np.abs(np.cos(ang)), np.abs(np.sin(ang)))
    log = ScanLog(np.zeros((1, 3)), r[None, :].astype(np.float32), -math.pi, 2 * math.pi / n, 8.0)
    g = build_grid(log, MappingConfig(resolution=0.1, margin=2))
    wall = g.occupied_points()
    assert len(wall) > 100
    assert np.all(np.abs(np.max(np.abs(wall), axis=1) - 2.0) < 0.15)
    rr, cc = g.world_to_cell([[0.5, 0.5], [-1.0, 1.2]])
    assert (g.data[np.floor(rr).astype(int), np.floor(cc).astype(int)] == 0).all()


# -- scan logs --------------------------------------------------------------------------------
def _log(n=5, b=8):
    rng = np.random.default_rng(2)
    return ScanLog(rng.normal(size=(n, 3)), rng.uniform(0.1, 5, (n, b)).astype(np.float32),
                   -math.pi, 2 * math.pi / b, 6.0)


def test_scan_log_round_trip(tmp_path):
    log = _log()
    save_scans(tmp_path / "r.scans.npz", log)
    back = load_scans(tmp_path / "r.scans.npz")
    np.testing.assert_array_equal(back.ranges, log.ranges)
    np.testing.assert_array_equal(back.poses, log.poses)
    assert (back.angle_min, back.angle_increment, back.range_max) == (
        log.angle_min, log.angle_increment, log.range_max)


@pytest.mark.parametrize("change, message", [
    (lambda d: d.pop("ranges"), "missing key"),
    (lambda d: d.update(ranges=d["ranges"][:3]), "each scan needs exactly one pose"),
    (lambda d: d.update(ranges=np.where(d["ranges"] > 2, np.nan, d["ranges"])), "NaN"),
    (lambda d: d.update(ranges=-d["ranges"]), "negative"),
    (lambda d: d.update(range_max=np.float64(0.0)), "range_max"),
])
def test_bad_scan_logs_name_the_file_and_the_fault(tmp_path, change, message):
    log = _log()
    d = dict(poses=log.poses, ranges=log.ranges, angle_min=log.angle_min,
             angle_increment=log.angle_increment, range_max=log.range_max)
    change(d)
    np.savez(tmp_path / "bad.scans.npz", **d)
    with pytest.raises(ScanLogError, match=message) as err:
        load_scans(tmp_path / "bad.scans.npz")
    assert "bad.scans.npz" in str(err.value)


def test_truncated_scan_log_is_a_clear_error(tmp_path):
    save_scans(tmp_path / "a.scans.npz", _log())
    raw = (tmp_path / "a.scans.npz").read_bytes()
    (tmp_path / "t.scans.npz").write_bytes(raw[: len(raw) // 2])
    with pytest.raises(ScanLogError, match="t.scans.npz"):
        load_scans(tmp_path / "t.scans.npz")


# -- atomic writes ----------------------------------------------------------------------------
def test_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    target = tmp_path / "out.txt"
    write_text_atomic(target, "old")
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("disk full")
    assert target.read_text() == "old"
    assert os.listdir(tmp_path) == ["out.txt"]


def test_outputs_may_not_be_inputs(tmp_path):
    (tmp_path / "a.yaml").write_text("x")
    with pytest.raises(InputError, match="overwrite the input"):
        check_not_input([tmp_path / "sub" / ".." / "a.yaml"], [tmp_path / "a.yaml"])


def test_a_bad_grid_or_transform_is_a_fusionkit_error():
    """They raised a plain ValueError: ``except fk.FusionkitError`` let a bad resolution, origin
    or NaN transform through."""
    from fusionkit.errors import FusionkitError
    with pytest.raises(FusionkitError, match="resolution"):
        OccupancyGrid(np.zeros((2, 2)), -1.0)
    with pytest.raises(FusionkitError, match="origin"):
        OccupancyGrid(np.zeros((2, 2)), 0.1, (0.0, math.nan, 0.0))
    with pytest.raises(FusionkitError, match="finite"):
        Transform2D(math.nan, 0.0, 0.0)


def test_a_transform_refuses_points_and_poses_of_the_wrong_shape():
    """A scalar raised IndexError; (N, 3) points were moved by their first two columns and the
    third dropped without a word; a non-number raised a plain ValueError."""
    t = Transform2D(1.0, 2.0, 0.5)
    for bad in (3.0, np.zeros((4, 3))):
        with pytest.raises(InputError, match=r"points of shape \(2,\) or \(N, 2\)"):
            t(bad)
    with pytest.raises(InputError, match=r"poses of shape \(3,\) or \(N, 3\)"):
        t.apply_pose(np.zeros((4, 2)))
    with pytest.raises(InputError, match="must be numbers"):
        Transform2D("a", 0.0, 0.0)
    assert t(np.zeros((0, 2))).shape == (0, 2)
    np.testing.assert_allclose(t([0.0, 0.0]), [1.0, 2.0])


def test_a_grid_refuses_masks_and_out_of_range_int8_and_never_freezes_the_callers_array():
    """A bool wall mask became all free, and so did one of 0 and 1; an int8 image's walls (0)
    became free and its other pixels unknown (-56...); the caller's own array was made
    read-only, and a grid built from a view changed when the array under it did."""
    with pytest.raises(InputError, match=r"boolean mask.*np.where\(mask, 100, 0\)"):
        OccupancyGrid(np.ones((3, 3), bool), 0.1)
    for mask in (np.eye(3, dtype=np.uint8), np.eye(3), 2 * np.eye(3, dtype=np.int64) - 1):
        with pytest.raises(InputError, match=r"no value above 1.*np.where\(mask == 1, 100, 0\)"):
            OccupancyGrid(mask, 0.1)                     # walls as 1: a map with no wall
    assert OccupancyGrid(np.eye(3, dtype=np.int8), 0.1).counts()["free"] == 9   # a map's own type
    with pytest.raises(InputError, match="values from -56 to 127"):
        OccupancyGrid(np.array([[127, -56]], np.int8), 0.1)
    mine = np.zeros((4, 4), np.int8)
    g = OccupancyGrid(mine[:, :], 0.1)
    mine[0, 0] = 100                                    # the caller's array stays theirs
    assert g.data[0, 0] == 0 and not g.data.flags.writeable
    assert OccupancyGrid(g.data, 0.1).data is g.data    # a frozen grid's cells are not copied
    for bad, said in ((None, "resolution must be a positive number"), ("x", "resolution")):
        with pytest.raises(InputError, match=said):
            OccupancyGrid(mine, bad)
    with pytest.raises(InputError, match=r"origin must be \(x, y, yaw\) numbers"):
        OccupancyGrid(mine, 0.1, "abc")
    with pytest.raises(InputError, match=r"yaw 90 is more than a full turn: give it in radians"):
        OccupancyGrid(mine, 0.1, (0.0, 0.0, 90.0))       # degrees: it was turned by 90 rad
    assert OccupancyGrid(mine, 0.1, (0.0, 0.0, -math.pi)).origin[2] == -math.pi


def test_a_scan_log_keeps_its_own_arrays_and_refuses_angles_in_degrees():
    poses, ranges = np.zeros((12, 3)), np.full((12, 8), 2.0, np.float32)
    log = ScanLog(poses, ranges, -math.pi, 2 * math.pi / 8, 8.0)
    poses[0, 0] = 5.0
    assert poses.flags.writeable and log.poses[0, 0] == 0.0
    assert np.shares_memory(log.subset(slice(0, 4)).ranges, log.ranges)   # frozen: shared
    with pytest.raises(ScanLogError, match="more than a full turn: give angle_min and angle_increment in radians"):
        ScanLog(poses, ranges, -180.0, 4.0, 8.0)


def test_mapping_settings_that_would_build_a_wrong_map_are_refused():
    """NaN or a negative clamp built an all-unknown or mostly occupied map without a word, a
    threshold over the clamp a map without walls, a NaN free range a bare ValueError."""
    for kw, said in ((dict(l_clamp=math.nan), "l_clamp must be a finite number"),
                     (dict(l_clamp=-1.0), "l_clamp must be > 0"),
                     (dict(occ_thresh=100.0), r"occ_thresh must be >= 0 and below l_clamp \(6\)"),
                     (dict(free_thresh=-0.5), "free_thresh must be >= 0"),
                     (dict(max_free_range=math.nan), "max_free_range must be a finite number"),
                     (dict(margin=2.5), "margin must be a whole number")):
        with pytest.raises(InputError, match=said):
            MappingConfig(**kw)
    poses, ranges = np.zeros((12, 3)), np.full((12, 8), 2.0, np.float32)
    log = ScanLog(poses, ranges, -math.pi, 2 * math.pi / 8, 8.0)
    with pytest.raises(InputError, match="holds no scan"):
        build_grid(log.subset(slice(0, 0)))
    with pytest.raises(InputError, match="takes a ScanLog"):
        build_grid(ranges)


def test_a_matrix_that_is_not_a_rigid_motion_is_refused():
    """A reflection, a scaling and a bad last row each came back as the identity, silently."""
    for m, said in ((np.diag([1.0, -1.0, 1.0]), "not a rotation"),
                    (np.diag([2.0, 2.0, 1.0]), "not a rotation"),
                    (np.array([[1.0, 0, 0], [0, 1, 0], [5, 5, 5]]), "last row 0 0 1")):
        with pytest.raises(InputError, match=said):
            Transform2D.from_matrix(m)
    t = Transform2D(0.3, -2.0, 2.5)
    assert Transform2D.from_matrix(t.matrix[:2].astype(np.float32)).is_close(t, atol=1e-5)
    with pytest.raises(InputError, match="must be numbers"):
        Transform2D.from_paper(None, 2.0, 0.0)
    with pytest.raises(InputError, match="compares with a Transform2D"):
        t.error_to((0.0, 0.0, 0.0))


def test_scan_indices_out_of_range_and_resample_arguments_of_the_wrong_kind():
    """log.subset([10000]) and endpoints([99999]) raised IndexError; resample with a tuple as
    the transform raised AttributeError."""
    log = ScanLog(np.zeros((12, 3)), np.full((12, 8), 2.0, np.float32), -math.pi, 2 * math.pi / 8, 8.0)
    for call in (lambda: log.subset([10000]), lambda: log.subset(np.ones(3, bool)),
                 lambda: log.endpoints([99999])):
        with pytest.raises(ScanLogError, match=r"a log of 12 scans\): give scan indices in 0..11"):
            call()
    g = OccupancyGrid(np.zeros((4, 4), np.int8), 0.1)
    with pytest.raises(InputError, match="takes two OccupancyGrid maps and a Transform2D, got "
                                         "OccupancyGrid, tuple, OccupancyGrid"):
        resample(g, (0.0, 0.0, 0.0), g)


def test_the_package_offers_its_public_names_and_not_its_own_helpers():
    import fusionkit
    names = dir(fusionkit)           # what tab completion in a notebook offers
    assert set(fusionkit.__all__) <= set(names)
    assert not {"importlib", "annotations"} & set(names)
    assert not [n for n in names if n.startswith("_") and n not in ("__version__", "__doc__")]
    assert all(getattr(fusionkit, n) is not None for n in fusionkit.__all__)
