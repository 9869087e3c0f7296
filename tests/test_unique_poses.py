"""Algorithm 1 (unique poses) and the spectra it rests on (eq. 1)."""

import math

import numpy as np
import pytest

from fusionkit.errors import InputError
from fusionkit.scanlog import ScanLog
from fusionkit.unique_poses import find_unique_poses, relative_heading, scan_spectra


def _log(ranges, inc=None):
    n, b = ranges.shape
    inc = inc or 2 * math.pi / b
    poses = np.column_stack([np.arange(n) * 0.1, np.zeros(n), np.zeros(n)])
    return ScanLog(poses, ranges, -math.pi, inc, 10.0)


def _corridor_log(rng, n=300, b=180, planted=(140, 152)):
    """A robot in a long corridor (the same scan shape everywhere, turned at random), with a
    distinctive place between the planted poses."""
    ang = np.arange(b) * 2 * np.pi / b
    corridor = 1.0 / np.maximum(np.abs(np.sin(ang)), 0.2)           # two parallel walls
    special = 3.0 + 1.5 * np.cos(3 * ang) + 0.8 * np.sin(7 * ang)    # an irregular room
    ranges = np.empty((n, b))
    for i in range(n):
        base = special if planted[0] <= i < planted[1] else corridor
        ranges[i] = np.roll(base, rng.integers(b)) + rng.normal(0, 0.01, b)
    return _log(ranges.astype(np.float32))


def test_spectrum_does_not_change_when_the_scan_is_rotated():
    rng = np.random.default_rng(0)
    scan = rng.uniform(0.5, 8.0, 360)
    spectra = scan_spectra(np.stack([np.roll(scan, k) for k in (0, 1, 37, 180, 359)]))
    for s in spectra[1:]:
        np.testing.assert_allclose(s, spectra[0], rtol=1e-9, atol=1e-9)


def test_spectrum_is_the_magnitude_of_eq1_without_dc_by_default():
    rng = np.random.default_rng(1)
    r = rng.uniform(1, 5, (3, 16))
    n = 16
    u = np.arange(n)
    dft = np.array([[abs(sum(row[x] * np.exp(-2j * np.pi * k * x / n) for x in u)) for k in u]
                    for row in r])
    np.testing.assert_allclose(scan_spectra(r, dc=True), dft[:, : n // 2 + 1], atol=1e-9)
    np.testing.assert_allclose(scan_spectra(r), dft[:, 1: n // 2 + 1], atol=1e-9)


def test_no_return_beams_count_as_range_max():
    r = np.array([[1.0, np.inf, 2.0, 30.0]], np.float32)
    log = ScanLog(np.zeros((1, 3)), r, 0.0, math.pi / 2, 5.0)
    np.testing.assert_allclose(scan_spectra(log, dc=True), scan_spectra([[1.0, 5.0, 2.0, 5.0]], dc=True))


def test_planted_unique_place_is_found():
    log = _corridor_log(np.random.default_rng(2))
    up = find_unique_poses(log, sub_sec=5, target=12)
    assert 10 <= up.count <= 16
    # every unique pose's section reaches into the planted place (poses 140..151)
    assert np.all((up.indices >= 140 - 5) & (up.indices < 152 + 5))


def test_fixed_delta_follows_algorithm_1_line_15():
    log = _corridor_log(np.random.default_rng(3))
    up = find_unique_poses(log, sub_sec=4, delta=None, target=20)
    again = find_unique_poses(log, sub_sec=4, delta=up.delta)
    np.testing.assert_array_equal(up.indices, again.indices)
    # by hand: unique when at most one divergence of the section is under delta
    div = up.divergence
    by_hand = [i for i in range(4, log.n_scans - 4) if (div[i - 4: i + 4] < up.delta).sum() <= 1]
    np.testing.assert_array_equal(again.indices, by_hand)


def test_too_few_poses_for_a_section_is_a_clear_error():
    log = _log(np.ones((8, 32), np.float32))
    with pytest.raises(InputError, match=r"8 poses has no pose with a full section of 2\*sub_sec = 10 "
                                         r"scans \(that needs at least 11 poses\)"):
        find_unique_poses(log, sub_sec=5)
    with pytest.raises(InputError, match="sub_sec must be a whole number"):
        find_unique_poses(log, sub_sec="2")       # a TypeError from the comparison before


def test_relative_heading_recovers_a_turn():
    rng = np.random.default_rng(4)
    scan = rng.uniform(1, 6, 360)
    inc = 2 * math.pi / 360
    # robot b turned by -25 beams sees a's scan shifted by +25 beams
    dth, peak = relative_heading(scan, np.roll(scan, 25), inc)
    assert math.isclose(dth, 25 * inc) and peak > 0.99


@pytest.mark.parametrize("delta", [-1.0, math.nan, "0.1"])
def test_a_threshold_merge_config_refuses_is_refused_here_too(delta):
    """delta=-1 was taken and marked every pose unique (MergeConfig refused it)."""
    rng = np.random.default_rng(0)
    log = _log(rng.uniform(1.0, 5.0, (40, 36)))
    with pytest.raises(InputError, match="delta is a divergence threshold"):
        find_unique_poses(log, sub_sec=2, delta=delta)
    assert find_unique_poses(log, sub_sec=2, delta=0.0) is not None
