"""Fusion rules (paper Section 3.6), placing maps in the common frame, and eq. (4)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fusionkit.errors import InputError
from fusionkit.fusion import FusedMap, apply_paper_transform, fuse_cells, fuse_maps
from fusionkit.grid import OccupancyGrid
from fusionkit.resample import resample
from fusionkit.transform import Transform2D

U, F, O = -1, 0, 100
RES = 0.1


def naive_fuse(a, b):
    """The paper's rules read literally, one cell at a time."""
    out = np.empty(a.shape, np.int8)
    for idx in np.ndindex(a.shape):
        x, y = int(a[idx]), int(b[idx])
        if x == U and y == U:
            out[idx] = U
        elif x == O or y == O:
            out[idx] = O
        else:
            out[idx] = F
    return out


@pytest.mark.parametrize("a, b, want", [
    (U, U, U), (U, F, F), (U, O, O),
    (F, U, F), (F, F, F), (F, O, O),
    (O, U, O), (O, F, O), (O, O, O),
])
def test_rules_all_nine_combinations(a, b, want):
    out = fuse_cells(np.array([[a]], np.int8), np.array([[b]], np.int8))
    assert out.dtype == np.int8 and out.tolist() == [[want]]


def test_rules_as_one_table():
    a = np.array([[U, U, U], [F, F, F], [O, O, O]], np.int8)
    b = np.array([[U, F, O], [U, F, O], [U, F, O]], np.int8)
    want = np.array([[U, F, O], [F, F, O], [O, O, O]], np.int8)
    np.testing.assert_array_equal(fuse_cells(a, b), want)


def test_probabilities_count_by_threshold():
    out = fuse_cells(np.array([[30, 70, -1]], np.int8), np.array([[-1, -1, 49]], np.int8))
    assert out.tolist() == [[F, O, F]]


def test_shape_mismatch():
    with pytest.raises(InputError, match="same shape"):
        fuse_cells(np.zeros((2, 2), np.int8), np.zeros((2, 3), np.int8))


@settings(max_examples=50, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_matches_naive_and_is_commutative_associative(seed):
    rng = np.random.default_rng(seed)
    a, b, c = (rng.choice(np.array([U, F, O], np.int8), size=(5, 7)) for _ in range(3))
    ab = fuse_cells(a, b)
    np.testing.assert_array_equal(ab, naive_fuse(a, b))
    np.testing.assert_array_equal(ab, fuse_cells(b, a))
    np.testing.assert_array_equal(fuse_cells(ab, c), fuse_cells(a, fuse_cells(b, c)))


# -- fusing placed maps -------------------------------------------------------------------------
def known_world(seed=0, rows=20, cols=30):
    rng = np.random.default_rng(seed)
    data = rng.choice(np.array([F, O], np.int8), size=(rows, cols), p=[0.7, 0.3])
    return OccupancyGrid(data, RES, (0.0, 0.0, 0.0), "world")


def two_halves(world):
    """Map A: columns 0..17 in the world frame. Map B: columns 12..29, in a frame turned by 90
    degrees; B's cell (r, c) is world cell (c, 29 - r), so B -> world is a rotation by pi/2
    then a shift of 30 cells in x (worked out from the cell-centre formula)."""
    a = OccupancyGrid(world.data[:, :18], RES, (0, 0, 0), "A")
    b = OccupancyGrid(world.data[:, 12:][:, ::-1].T, RES, (0, 0, 0), "B")
    t_b = Transform2D(30 * RES, 0.0, math.pi / 2)
    return a, b, t_b


def test_two_halves_reconstruct_the_grid():
    world = known_world()
    a, b, t_b = two_halves(world)
    # check the hand-derived layout of B: its cell centres land on the right world cells
    r, c = 3, 5
    np.testing.assert_allclose(t_b(b.cell_to_world(r, c)), world.cell_to_world(c, 29 - r))

    fused = fuse_maps([a, b], [Transform2D.identity(), t_b])
    assert isinstance(fused, FusedMap)
    assert fused.grid.resolution == RES and fused.grid.origin[2] == 0.0
    assert fused.order == (0, 1) and fused.steps == ()
    back = resample(fused.grid, Transform2D.identity(), world)
    np.testing.assert_array_equal(back.data, world.data)
    # nothing known outside the world's area: the canvas margin stays unknown
    assert fused.grid.counts()["unknown"] == fused.grid.data.size - world.data.size


def test_fused_frame_is_the_reference_frame():
    # the reference map has an offset origin; the fused cells sit at the same reference-frame
    # points as the reference map's cells
    world = known_world(seed=1)
    ref = OccupancyGrid(world.data, RES, (-1.3, 2.2, 0.0))
    other = OccupancyGrid(world.data, RES, (0.0, 0.0, 0.0))
    t_other = Transform2D(-1.3, 2.2, 0.0)  # other's frame -> reference frame: same cells
    fused = fuse_maps([ref, other], [Transform2D.identity(), t_other])
    rows, cols = np.nonzero(fused.grid.known_mask())
    pts = fused.grid.cell_to_world(rows, cols)
    rr, cc = ref.world_to_cell(pts)
    np.testing.assert_array_equal(world.data[np.floor(rr).astype(int), np.floor(cc).astype(int)],
                                  fused.grid.data[rows, cols])
    assert len(rows) == world.data.size


def test_owner_labels_follow_the_fusion_order():
    world = known_world(seed=2)
    a, b, t_b = two_halves(world)
    transforms = [Transform2D.identity(), t_b]
    fwd = fuse_maps([a, b], transforms)
    rev = fuse_maps([a, b], transforms, order=[1, 0])
    own_fwd = resample(fwd.grid.with_data(fwd.owner.astype(np.int8)), Transform2D.identity(), world)
    own_rev = resample(rev.grid.with_data(rev.owner.astype(np.int8)), Transform2D.identity(), world)
    assert (own_fwd.data[:, :18] == 0).all() and (own_fwd.data[:, 18:] == 1).all()
    assert (own_rev.data[:, :12] == 0).all() and (own_rev.data[:, 12:] == 1).all()
    assert fwd.owner.dtype == np.int16
    np.testing.assert_array_equal(fwd.owner == -1, ~fwd.grid.known_mask())
    # the order changes who owns a cell, never the fused cells
    np.testing.assert_array_equal(fwd.grid.data, rev.grid.data)
    assert rev.order == (1, 0)


def test_steps_are_cumulative():
    world = known_world(seed=3)
    a, b, t_b = two_halves(world)
    c = OccupancyGrid(np.where(np.arange(16).reshape(4, 4) % 2, O, F).astype(np.int8), RES)
    fused = fuse_maps([a, b, c], [Transform2D.identity(), t_b, Transform2D(0.5, 0.5, 0.0)],
                      keep_steps=True)
    assert len(fused.steps) == 3
    for s in fused.steps:
        assert s.shape == fused.grid.shape and s.origin == fused.grid.origin
    np.testing.assert_array_equal(fused.steps[-1].data, fused.grid.data)
    only_a = resample(a, Transform2D.identity(), fused.grid)
    np.testing.assert_array_equal(fused.steps[0].data, only_a.data)
    known = [s.counts()["unknown"] for s in fused.steps]
    assert known[0] > known[1] >= known[2]
    # an occupied cell never turns free in a later step
    for s0, s1 in zip(fused.steps, fused.steps[1:]):
        assert (s1.data[s0.data == O] == O).all()


def test_none_transforms_are_left_out():
    world = known_world(seed=4)
    a, b, t_b = two_halves(world)
    junk = OccupancyGrid(np.full((50, 50), O, np.int8), RES)
    fused = fuse_maps([a, junk, b], [Transform2D.identity(), None, t_b], keep_steps=True)
    assert fused.order == (0, 2) and len(fused.steps) == 2
    assert set(np.unique(fused.owner)) == {-1, 0, 2}
    back = resample(fused.grid, Transform2D.identity(), world)
    np.testing.assert_array_equal(back.data, world.data)


def test_resolution_defaults_to_the_reference_and_can_be_set():
    world = known_world(seed=5)
    coarse = OccupancyGrid(world.data, 2 * RES)
    fine = OccupancyGrid(world.data, RES)
    # the reference (identity transform) is the coarse map even though it is fused second
    f = fuse_maps([fine, coarse], [Transform2D(1.0, 0, 0), Transform2D.identity()], order=[0, 1])
    assert f.grid.resolution == 2 * RES
    g = fuse_maps([fine, coarse], [Transform2D(1.0, 0, 0), Transform2D.identity()], resolution=0.05)
    assert g.grid.resolution == 0.05


def test_bad_inputs():
    g = known_world()
    with pytest.raises(InputError, match="one transform per grid"):
        fuse_maps([g, g], [Transform2D()])
    with pytest.raises(InputError, match="no map to fuse"):
        fuse_maps([g], [None])
    with pytest.raises(InputError, match="twice"):
        fuse_maps([g, g], [Transform2D(), Transform2D()], order=[0, 0])
    with pytest.raises(InputError, match="indices"):
        fuse_maps([g], [Transform2D()], order=[1])
    with pytest.raises(InputError, match="resolution"):
        fuse_maps([g], [Transform2D()], resolution=0.0)
    with pytest.raises(InputError, match="no known cells"):
        fuse_maps([g.with_data(np.full(g.shape, U, np.int8))], [Transform2D()])
    with pytest.raises(InputError, match="OccupancyGrid"):
        fuse_maps([g.data], [Transform2D()])


# -- eq. (4) ------------------------------------------------------------------------------------
def test_paper_transform_by_hand():
    # (1, 0) moved by (1, 0) is (2, 0); turned a quarter left it is (0, 2)
    np.testing.assert_allclose(apply_paper_transform([1.0, 0.0], 1.0, 0.0, math.pi / 2), [0.0, 2.0],
                               atol=1e-12)
    # (0, 0) moved by (3, 4) then turned a half turn is (-3, -4)
    np.testing.assert_allclose(apply_paper_transform([[0.0, 0.0]], 3.0, 4.0, math.pi),
                               [[-3.0, -4.0]], atol=1e-12)


@settings(max_examples=50, deadline=None)
@given(st.floats(-10, 10), st.floats(-10, 10), st.floats(-4, 4), st.integers(0, 2**32 - 1))
def test_paper_transform_equals_transform2d_from_paper(dx, dy, dphi, seed):
    pts = np.random.default_rng(seed).uniform(-5, 5, size=(6, 2))
    np.testing.assert_allclose(apply_paper_transform(pts, dx, dy, dphi),
                               Transform2D.from_paper(dx, dy, dphi)(pts), atol=1e-9)


def test_paper_transform_bad_shape():
    with pytest.raises(InputError):
        apply_paper_transform(np.zeros((3, 3)), 0, 0, 0)


def test_a_fused_map_or_canvas_too_large_to_hold_is_refused_before_it_is_allocated():
    """fuse_maps at 1e-4 m cells asked numpy for 187 GiB (MemoryError); two maps 100 km apart
    were fused into a 600-million-cell map; a transform fewer than the grids dropped a grid."""
    from fusionkit.resample import canvas_for
    from fusionkit.worlds import default_world
    g = default_world()
    with pytest.raises(InputError, match="more than the 200000000 fusionkit can hold"):
        fuse_maps([g, g], [Transform2D(), Transform2D()], resolution=1e-4)
    with pytest.raises(InputError, match="more than the 200000000 fusionkit can hold"):
        fuse_maps([g, g], [Transform2D(), Transform2D(1e5, 0.0, 0.0)])
    with pytest.raises(InputError, match="one transform per grid, got 2 grids and 1"):
        canvas_for([g, g], [Transform2D()], 0.1)


def test_fuse_cells_refuses_values_no_grid_holds():
    """NaN was fused as free, 1000 and an image's 255 as occupied, text raised a numpy error."""
    for bad, said in (([[np.nan]], "hold NaN"), ([[255]], "up to 255"), ([["ab"]], "must be numbers")):
        with pytest.raises(InputError, match=said):
            fuse_cells(bad, [[0]])
    assert fuse_cells([[-5, 100]], [[0, -1]]).tolist() == [[0, 100]]   # any negative is unknown
