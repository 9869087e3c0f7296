"""The consensus method on crops of rack rows (the built-in warehouse): a placement one rack
period off overlaps the other map more than the truth does, so it gathers more evidence while
fitting no better. These cases come from ``fusionkit bench --worlds office warehouse --robots 5
--modes explore crop --cases 40`` (the seed and case named in each test)."""

from __future__ import annotations

import math

from fusionkit.bench import BenchConfig
from fusionkit.bench.cases import find_worlds, make_case, plan_cases
from fusionkit.methods.consensus import estimate_pair
from fusionkit.methods.peers import placement_error
from fusionkit.pipeline import MergeConfig, merge


def _fleet_case(seed: int, index: int):
    worlds, _ = find_worlds((), ("office", "warehouse"))
    cfg = BenchConfig(methods=("consensus",), modes=("explore", "crop"), robots=(5,), cases=40,
                      seed=seed)
    return make_case(plan_cases(worlds, cfg)[index], cfg)


def test_a_placement_that_fits_as_well_where_the_maps_overlap_less_is_a_rival():
    """Seed 46, case 19, maps 1 and 5. One rack period off, map 5 meets 1270 of map 1's wall
    cells and misses none; at the truth it meets 718 and misses none either. The alias led on
    evidence (the count of meeting walls) by more than the rival fraction, so it was merged,
    3.5 m off. A distinct placement that passes the test itself and meets walls at least as
    often as the best one is a rival: the pair is ambiguous, and the truth is among its
    placements."""
    case = _fleet_case(46, 19)
    a, b = case.grids[0], case.grids[4]
    truth = case.truth[0].inverse @ case.truth[4]
    est = estimate_pair(a, b, priors=[truth])
    pr = est.diagnostics["pair"]
    assert placement_error(pr.transform, truth, b)[0] > 3.0     # the best placement is the alias
    assert not est.accepted and pr.ambiguous, pr.reason
    # both meet every wall they can: said once ("100-100%" read as a range)
    assert pr.reason.startswith("ambiguous: 2 distinct placements fit about as well (100% of the "
                                "walls meet, a wall on the other map's open floor counted as three "
                                "misses)"), pr.reason
    near = [placement_error(c.transform, truth, b)[0] for c in pr.plausible]
    assert min(near) < 0.2, near


def test_a_loop_through_a_pair_of_several_placements_keeps_the_truth_in_a_broken_loop():
    """Seed 47, case 39: maps 1, 4 and 5 make a loop that does not close; maps 1-4 and 4-5
    were right, 1-5 a placement 16 m off that met more walls than the truth (which the
    search did not find). Each broke as many loops as it closed, and the weaker evidence was
    dropped: the right 1-4, so that every map was then placed 16 m off through 1-5. Loops
    through pairs that fit in several places (1-3, 1-2) close with 1-4 and not with 1-5: the
    tie is broken by them, and every map is placed right."""
    case = _fleet_case(47, 39)
    res = merge(list(case.grids), config=MergeConfig(method="consensus"))
    ref = case.truth[0]
    for p in res.placements[1:]:
        assert p.merged, p.reason
        d, rot = placement_error(p.transform, ref.inverse @ case.truth[p.index], case.grids[p.index])
        assert d < 3 * case.world.resolution and math.degrees(rot) < 2.0, (p.index, d, rot)
