"""Pearson agreement (eq. 2) and the fusion order."""

import numpy as np
import pytest

from fusionkit.errors import InputError
from fusionkit.pairing import agreement, fusion_order, pearson_matrix


def test_pearson_matrix_matches_numpy_corrcoef():
    rng = np.random.default_rng(0)
    x, y = rng.normal(size=(5, 30)), rng.normal(size=(7, 30))
    full = np.corrcoef(np.vstack([x, y]))
    np.testing.assert_allclose(pearson_matrix(x, y), full[:5, 5:], atol=1e-12)


def test_agreement_counts_pairs_above_theta_best_first():
    rng = np.random.default_rng(1)
    a = rng.normal(size=(4, 50))
    b = np.vstack([a[2] + rng.normal(0, 0.05, 50), rng.normal(size=50), a[0] * 3 + 1])
    ag = agreement(a, b, 0.9)
    assert ag.count == 2
    assert {tuple(m) for m in ag.matches} == {(2, 0), (0, 2)}
    assert ag.matches[0].tolist() == [0, 2]          # a[0] vs 3 a[0] + 1 correlates exactly


def test_theta_out_of_range_is_refused():
    with pytest.raises(InputError, match="theta"):
        agreement(np.ones((1, 3)), np.ones((1, 3)), 1.5)


def test_fusion_order_starts_with_the_best_pair_and_grows_greedily():
    c = np.array([[0, 5, 1, 0],
                  [5, 0, 9, 0],
                  [1, 9, 0, 2],
                  [0, 0, 2, 0]])
    plan = fusion_order(c)
    assert plan.steps == ((1, 2), (1, 0), (2, 3))
    assert plan.order == (1, 2, 0, 3)
    assert plan.unplaced == ()


def test_maps_that_agree_with_nobody_are_reported_not_forced():
    c = np.array([[0, 3, 0], [3, 0, 0], [0, 0, 0]])
    plan = fusion_order(c)
    assert plan.unplaced == (2,)
    assert fusion_order(np.zeros((3, 3), int)).steps == ()


@pytest.mark.parametrize("reference", [3, -1, 1.0, True])
def test_fusion_order_refuses_a_reference_that_is_not_a_maps_index(reference):
    """3 raised a bare IndexError; -1 was taken as the last map, which then joined as a new one."""
    c = np.array([[0, 5, 1], [5, 0, 7], [1, 7, 0]])
    with pytest.raises(InputError, match="index of one of the 3 maps"):
        fusion_order(c, reference=reference)
    assert fusion_order(c, reference=2).steps[0][0] == 2


def test_counts_thresholds_and_spectra_no_step_can_use_are_refused():
    """NaN counts made the first step (0, 1) whatever they said; NaN spectra gave NaN rho
    (documented in [-1, 1]); "0.9" and UniquePoses objects raised a bare TypeError."""
    for counts in ([[0, np.nan], [np.nan, 0]], [[0, 3], [1, 0]], [[0, -2], [-2, 0]]):
        with pytest.raises(InputError, match="symmetric matrix of numbers >= 0"):
            fusion_order(np.array(counts))
    with pytest.raises(InputError, match="NaN or infinite"):
        pearson_matrix(np.full((2, 4), np.nan), np.ones((2, 4)))
    with pytest.raises(InputError, match="theta is a correlation threshold"):
        agreement(np.ones((2, 4)), np.ones((2, 4)), "0.9")
    with pytest.raises(InputError, match=r"\.unique_spectra"):
        agreement(object(), np.ones((2, 4)), 0.9)
    assert fusion_order(np.array([[0, 2], [2, 0]])).steps == ((0, 1),)
