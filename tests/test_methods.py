"""Every merging method behind one interface: the registry, what a method gives back, and that
merge() builds its result from it."""

from pathlib import Path

import numpy as np
import pytest

from fusionkit.errors import InputError
from fusionkit.mapio import load_map
from fusionkit.methods import METHODS, get_method
from fusionkit.methods.base import MethodResult, PreparedMaps
from fusionkit.methods.peers import crop_pair
from fusionkit.pipeline import MergeConfig, merge
from fusionkit.transform import Transform2D

REAL = Path(__file__).parent.parent / "maps" / "real"


@pytest.fixture(scope="module")
def maps():
    """Two overlapping windows of the Intel lab, the second turned and moved into its own frame."""
    intel = load_map(REAL / "intel_lab.yaml")
    pair = crop_pair(intel, np.random.default_rng(3), size=200, min_overlap=0.4)
    return [pair.a, pair.b]


def test_registry_names_every_method_and_refuses_an_unknown_one():
    assert set(METHODS) == {"spectral-pso", "consensus", "map-merge", "map-merge-shipped",
                            "hough-spectrum", "fourier-mellin"}
    assert [get_method(m).name for m in METHODS] == list(METHODS)
    with pytest.raises(InputError, match="unknown method 'icp'"):
        get_method("icp")


@pytest.mark.parametrize("name", METHODS)
def test_a_method_places_each_map_or_says_why_not_and_merge_fuses_what_it_placed(name, maps):
    method = get_method(name)
    config = MergeConfig(method=name, reference=1, seed=2)
    events = []
    out = method.place(PreparedMaps(tuple(maps), (None, None), ("a", "b"), 1),
                       method.settings(config), events.append)
    assert isinstance(out, MethodResult) and len(out.placements) == 2
    ref = out.placements[1]
    assert ref.transform.is_close(Transform2D.identity()) and ref.confidence == 1.0
    # a map is in the fusion order exactly when it is placed; one left out says why
    assert 1 in out.order
    assert all((k in out.order) == (p.transform is not None) for k, p in enumerate(out.placements))
    assert all(bool(p.reason) == (p.transform is None) for p in out.placements)
    assert all(p.confidence >= 0.0 for p in out.placements)
    assert events and all(ev.stage in ("scans", "unique_poses", "pairing", "align") for ev in events)

    result = merge(maps, config=config)
    assert [p.merged for p in result.placements] == [p.transform is not None for p in out.placements]
    assert result.order == out.order and result.fusion_order == out.links
    for got, want in zip(result.placements, out.placements):
        assert got.confidence == want.confidence and got.reason == (want.reason if not got.merged else "")
        if want.transform is not None:
            assert got.transform.is_close(want.transform)
    assert set(result.seconds) >= {"fuse", "total"}


def test_peer_confidence_goes_to_the_map_each_link_placed():
    # map-merge roots its tree at the centre map, not the reference: the common-scale
    # confidence of a link must still go to the map it placed, and the reference keeps 1
    from fusionkit.bench import BenchConfig, WorldSpec, make_case, plan_cases
    from fusionkit.pipeline import MergeConfig, merge

    cfg = BenchConfig(cases=1, robots=(3,), modes=("explore",), seed=0)
    case = make_case(plan_cases([WorldSpec("office", builtin="office")], cfg)[0], cfg)
    res = merge(list(case.grids), config=MergeConfig(method="map-merge", seed=1))
    conf = [p.confidence for p in res.placements]
    assert all(p.merged for p in res.placements)
    assert conf[0] == 1.0
    assert all(0.9 <= c <= 1.0 for c in conf), conf


def _windows_of_a_basement():
    """Three 623-cell windows of the MIT basement, each in its own frame: A at the top left, B at
    the bottom right turned 90 degrees, C at the centre (B meets A only through C)."""
    from fusionkit.grid import OccupancyGrid
    img = load_map(REAL / "mit_stata_basement.yaml").data[::-1]     # rows from the top
    rows, cols = np.nonzero(img >= 0)
    r0, c0, hh, ww = rows.min(), cols.min(), np.ptp(rows), np.ptp(cols)
    win = int(0.6 * max(hh, ww))
    corners = {"A": (r0, c0), "B": (r0 + hh - win, c0 + ww - win),
               "C": (r0 + (hh - win) // 2, c0 + (ww - win) // 2)}
    grids = []
    for name, (r, c) in corners.items():
        sub = img[r:r + win, c:c + win]
        sub = np.rot90(sub) if name == "B" else sub
        grids.append(OccupancyGrid(np.ascontiguousarray(sub[::-1]), 0.05, (0.0, 0.0, 0.0), name))
    return grids


def test_the_papers_method_reports_the_common_tests_confidence_not_its_share_of_walls():
    """The paper's method merged B turned 176 degrees from its place with confidence 1.00 (all
    its overlapping walls agreed): its confidence was its share of walls, not how sure the
    placement is. It still merges what its rule accepts; the confidence is now the consensus
    test's, as every other method's, and says that placement cannot be told from chance."""
    grids = _windows_of_a_basement()
    paper = merge(grids, config=MergeConfig(method="spectral-pso", seed=0))
    right = merge(grids, config=MergeConfig(method="consensus", seed=0))
    assert all(p.merged and p.confidence > 0.99 for p in right.placements)
    b_paper, b_right = paper.placements[1].transform, right.placements[1].transform
    assert paper.placements[1].merged and b_paper is not None
    dist, ang = b_paper.error_to(b_right)
    assert dist > 5.0 and ang > np.radians(90)        # the paper's rule took a wrong placement
    assert paper.placements[1].confidence < 0.01
    assert paper.placements[0].confidence == 1.0       # the reference


def test_map_merge_gives_the_same_bits_every_time_in_one_process():
    # its bundle adjustment has a free gauge (every map moved together): held at the chain's
    # first map, the same input gives the same transforms, whatever ran before in the process
    from fusionkit.bench import BenchConfig, WorldSpec, make_case, plan_cases
    from fusionkit.methods.consensus import ConsensusConfig, prepare_maps
    from fusionkit.methods.peers.map_merge import estimate_maps

    cfg = BenchConfig(cases=6, robots=(3,), modes=("explore", "crop"), seed=0)
    worlds = [WorldSpec("office", builtin="office"), WorldSpec("cave", builtin="cave")]
    grids = list(make_case(plan_cases(worlds, cfg)[0], cfg).grids)
    seen = set()
    for _ in range(8):
        est = estimate_maps(grids, chaining="shipped", reference=0)
        seen.add(tuple(None if t is None else (t.x.hex(), t.y.hex(), t.theta.hex())
                       for t in est.transforms))
        prepare_maps(grids, config=ConsensusConfig(use_scans=False))   # other work between
    assert len(seen) == 1
