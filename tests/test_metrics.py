"""Table 1 metrics (CONTRACTS section 7) against values worked out by hand."""

import math

import numpy as np
import pytest

from fusionkit.errors import InputError
from fusionkit.grid import OccupancyGrid
from fusionkit.metrics import (PAPER_TABLE1, MapMetrics, TransformError, evaluate_map,
                               format_percent, format_table1, round_percent, table1,
                               table1_label, transform_errors)
from fusionkit.transform import Transform2D

U, F, O = -1, 0, 100
RES = 0.5

# data[row, col]; row 0 is the lowest y.
TRUTH = np.array([
    [F, F, O, U],
    [F, O, O, U],
    [F, F, F, U],
    [U, U, U, U],
], np.int8)
FUSED = np.array([
    [F, O, O, F],
    [U, O, F, F],
    [F, F, U, U],
    [O, U, U, U],
], np.int8)
# By hand:
#   known(G) = the 3 x 3 block = 9 cells; occupied(G) = (0,2), (1,1), (1,2)
#   known(F) = 4 + 3 + 2 + 1 = 10 cells
#   known(F) & known(G): row 0: 3, row 1: (1,1),(1,2) = 2, row 2: (2,0),(2,1) = 2  -> 7
#   same state on known(G): (0,0) (0,2) (1,1) (2,0) (2,1) -> 5   [(0,1) O/F, (1,2) F/O differ]
#   occupied(F) = (0,1), (0,2), (1,1), (3,0) -> 4; also occupied in G: (0,2), (1,1) -> 2
#   within one cell of an occupied G cell: (0,1), (0,2), (1,1) -> 3; (3,0) is two rows away
#   completeness = 7/9, accuracy = 5/9, precision = 2/4, efficiency = 7/9 * 2/4,
#   precision_tol1 = 3/4


def grid(data, origin=(0.0, 0.0, 0.0)):
    return OccupancyGrid(np.asarray(data, np.int8), RES, origin)


def test_hand_computed_4x4():
    m = evaluate_map(grid(FUSED), grid(TRUTH))
    assert isinstance(m, MapMetrics)
    assert m.completeness == pytest.approx(100 * 7 / 9)
    assert m.accuracy == pytest.approx(100 * 5 / 9)
    assert m.precision == pytest.approx(50.0)
    assert m.efficiency == pytest.approx(100 * 7 / 9 * 2 / 4)
    assert m.precision_tol1 == pytest.approx(75.0)
    assert (m.known_truth, m.known_fused, m.known_both, m.correct) == (9, 10, 7, 5)
    assert (m.occupied_fused, m.occupied_correct, m.occupied_correct_tol1, m.occupied_truth) == (4, 2, 3, 3)
    d = m.as_dict()
    assert d["completeness"] == 77.7778 and d["known_truth"] == 9
    assert set(d) >= {"completeness", "accuracy", "precision", "efficiency", "precision_tol1"}


def test_map_against_itself_is_perfect():
    m = evaluate_map(grid(TRUTH), grid(TRUTH))
    assert (m.completeness, m.accuracy, m.precision, m.efficiency, m.precision_tol1) == (
        100.0, 100.0, 100.0, 100.0, 100.0)


def test_no_occupied_cells_gives_zero_precision():
    m = evaluate_map(grid(np.full((4, 4), F)), grid(TRUTH))
    assert m.precision == 0.0 and m.efficiency == 0.0 and m.precision_tol1 == 0.0
    assert m.completeness == 100.0
    assert m.accuracy == pytest.approx(100 * 6 / 9)   # the 6 free cells of G match


def test_probabilities_count_as_three_states():
    probs = np.where(TRUTH == O, 80, np.where(TRUTH == F, 10, -1)).astype(np.int8)
    m = evaluate_map(grid(probs), grid(TRUTH))
    assert m.accuracy == 100.0 and m.precision == 100.0


def test_translation_placement():
    # F is the truth stored with its corner 1.5 m to the left in its own frame:
    # F frame -> truth frame is a shift of +1.5 m in x
    f = grid(TRUTH, origin=(-1.5, 0.0, 0.0))
    assert evaluate_map(f, grid(TRUTH)).precision < 100.0
    m = evaluate_map(f, grid(TRUTH), Transform2D(1.5, 0.0, 0.0))
    assert m.completeness == 100.0 and m.accuracy == 100.0 and m.precision == 100.0


def test_rotation_placement():
    # F holds the truth turned a quarter turn: F cell (r, c) is truth cell (c, 3 - r), so
    # F -> truth is a rotation by pi/2 then a shift of 4 cells in x (cell-centre formula)
    f = grid(TRUTH[:, ::-1].T)
    t = Transform2D(4 * RES, 0.0, math.pi / 2)
    np.testing.assert_allclose(t(f.cell_to_world(1, 2)), grid(TRUTH).cell_to_world(2, 3 - 1))
    m = evaluate_map(f, grid(TRUTH), t)
    assert (m.completeness, m.accuracy, m.precision) == (100.0, 100.0, 100.0)
    wrong = evaluate_map(f, grid(TRUTH), Transform2D(4 * RES, 0.0, -math.pi / 2))
    assert wrong.completeness < 100.0


def test_fused_cells_outside_the_truth_are_ignored():
    big = np.full((8, 8), O, np.int8)
    big[:4, :4] = TRUTH
    m = evaluate_map(grid(big), grid(TRUTH))
    assert m.known_fused == 16 - 7  # only the 4 x 4 window is sampled; 7 of it unknown
    assert m.precision == 100.0


def test_empty_truth_raises():
    with pytest.raises(InputError, match="no known cell"):
        evaluate_map(grid(TRUTH), grid(np.full((4, 4), U)))
    with pytest.raises(InputError):
        evaluate_map(TRUTH, grid(TRUTH))


def test_transform_errors():
    e = transform_errors(Transform2D(1.0, 1.0, 0.1), Transform2D(1.0, 1.3, -0.1), 0.1)
    assert isinstance(e, TransformError)
    assert e.translation_m == pytest.approx(0.3)
    assert e.translation_cells == pytest.approx(3.0)
    assert e.rotation_deg == pytest.approx(math.degrees(0.2))
    # rotation error goes the short way round
    w = transform_errors(Transform2D(0, 0, 3.1), Transform2D(0, 0, -3.1), 0.05)
    assert w.rotation_deg == pytest.approx(math.degrees(2 * math.pi - 6.2))
    assert e.as_dict() == {"translation_m": 0.3, "translation_cells": 3.0, "rotation_deg": 11.4592}
    with pytest.raises(InputError):
        transform_errors(Transform2D(), Transform2D(), 0.0)


def test_a_map_with_one_wrong_cell_is_never_printed_as_perfect():
    truth = np.full((200, 200), F, np.int8)
    truth[::7, :] = O
    fused = truth.copy()
    fused[3, 3] = O                                   # one free cell of 40000 called occupied
    m = evaluate_map(grid(fused), grid(truth))
    assert m.accuracy == pytest.approx(100 * 39999 / 40000) and m.completeness == 100.0
    line = next(s for s in format_table1([m], paper=False).splitlines() if s.startswith("M1"))
    assert line.split()[2:5] == ["100.00", "99.99", "99.98"]    # Compl, Acc, Prec
    assert m.as_dict()["accuracy"] == 99.9975 and m.as_dict(2)["accuracy"] == 99.99
    assert round_percent(99.99999, 4) == 99.9999 and round_percent(0.00001) == 0.01
    assert round_percent(100.0) == 100.0 and round_percent(0.0) == 0.0
    assert format_percent(99.996, 2, 7) == "  99.99" and format_percent(12.345, 1) == "12.3"


@pytest.mark.parametrize("digits", ["2", 2.5, -1, True])
def test_a_rounding_of_the_wrong_kind_is_refused_in_one_line(digits):
    m = evaluate_map(grid(np.full((4, 4), F, np.int8)), grid(np.full((4, 4), F, np.int8)))
    error = transform_errors(Transform2D(0.1, 0.0, 0.0), Transform2D(), 0.05)
    for as_dict in (m.as_dict, error.as_dict, Transform2D(1.0, 2.0, 0.3).as_dict):
        with pytest.raises(InputError, match=r"^digits must be None or a whole number >= 0, got "):
            as_dict(digits)
        assert as_dict(np.int64(1)) == as_dict(1) and as_dict(None) is not None


def test_table1_rows_and_labels():
    steps = [grid(FUSED), grid(TRUTH)]
    rows = table1(steps, grid(TRUTH))
    assert rows == [evaluate_map(s, grid(TRUTH)) for s in steps]
    assert [table1_label(k) for k in range(3)] == ["M1", "M1,2", "M1,2,3"]
    assert [r.label for r in PAPER_TABLE1] == [table1_label(k) for k in range(5)]
    assert PAPER_TABLE1[0].completeness == 79.55 and PAPER_TABLE1[-1].efficiency == 66.67
    assert PAPER_TABLE1[3].accuracy == 85.57 and PAPER_TABLE1[2].precision == 61.59


def test_format_table1_side_by_side():
    rows = table1([grid(FUSED), grid(TRUTH)], grid(TRUTH))
    text = format_table1(rows, oracle=rows[::-1])
    lines = text.splitlines()
    assert "fusionkit" in lines[0] and "oracle" in lines[0] and "paper" in lines[0]
    m1 = next(line for line in lines if line.startswith("M1 "))
    assert "77.78" in m1 and "55.56" in m1 and "50.00" in m1 and "38.89" in m1 and "75.00" in m1
    assert "100.00" in m1  # the oracle's first row is the perfect map
    assert "79.55" in m1 and "46.51" in m1
    # paper rows beyond ours are still shown
    assert any(line.startswith("M1,2,3,4,5") and "96.91" in line for line in lines)
    plain = format_table1(rows, paper=False)
    assert "79.55" not in plain and len(plain.splitlines()) == 3 + 2


def test_table1_takes_a_fused_map_and_refuses_a_single_grid():
    """table1(fused_map, truth) raised "'FusedMap' object is not iterable"."""
    from fusionkit.errors import InputError
    from fusionkit.fusion import fuse_maps
    from fusionkit.transform import Transform2D
    from fusionkit.worlds import default_world
    world = default_world()
    fused = fuse_maps([world, world], [Transform2D(), Transform2D()], keep_steps=True)
    assert [r.completeness for r in table1(fused, world)] == [r.completeness for r in table1(fused.steps, world)]
    with pytest.raises(InputError, match="for one map, use evaluate_map"):
        table1(fused.grid, world)
    with pytest.raises(InputError, match="keep_steps=True"):
        table1(fuse_maps([world], [Transform2D()]), world)
