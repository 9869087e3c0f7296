"""Groups: maps that link among themselves but not to the reference are kept, group by group
(CONTRACTS section 6)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from fusionkit.methods.peers import crop_pair, placement_error
from fusionkit.cli import main
from fusionkit.mapio import load_map, save_map
from fusionkit.pipeline import MergeConfig, merge

REPO = Path(__file__).resolve().parents[1]
REAL = REPO / "maps" / "real"
if not (REAL / "intel_lab.yaml").is_file():
    REAL = REPO.parent / "shared" / "maps" / "real"


@pytest.fixture(scope="module")
def two_buildings():
    """Two overlapping windows of the Osnabrueck floor and two of the UT Austin floor (both
    0.05 m cells): the second pair shares no wall with the first."""
    uos = load_map(REAL / "uos_avz_floor5.yaml")
    utexas = load_map(REAL / "utexas_gdc_floor3.yaml")
    one = crop_pair(uos, np.random.default_rng(3), size=240, min_overlap=0.5)
    two = crop_pair(utexas, np.random.default_rng(7), size=240, min_overlap=0.5)
    return one, two


def test_a_group_not_linked_to_the_reference_is_reported_as_a_group(two_buildings):
    one, two = two_buildings
    result = merge([one.a, two.a, one.b, two.b], config=MergeConfig(method="consensus"))
    p = result.placements
    assert [q.merged for q in p] == [True, False, True, False]
    assert [q.group for q in p] == [0, 1, 0, 1]
    # map 3 (second UT Austin window) in the frame of map 1 (the first one): the crops' truth
    assert p[3].group_reference == 1 and p[1].group_reference == 1
    d, r = placement_error(p[3].group_transform, two.truth, two.b)
    assert d < 3 * two.a.resolution and r < math.radians(2.0)
    assert p[1].group_transform.is_close(p[1].group_transform.identity(), atol=1e-9)
    assert "group 1" in p[3].reason
    # whose frame, said of each member as it is to it (the first map's: "its own")
    assert p[3].reason.endswith("kept in group 1 with 1 other map, fused in the frame of the "
                                f"group's first map, {p[1].name}"), p[3].reason
    assert p[1].reason.endswith("fused in its own frame (the group's first map)"), p[1].reason
    assert 0.0 < p[3].confidence <= 1.0
    (group,) = result.groups
    assert group.members == (1, 3)
    # the group's fused map holds both UT Austin windows' walls, in the first one's frame
    assert group.grid.occupied_mask().sum() >= two.a.occupied_mask().sum()
    assert not result.grid.occupied_mask().sum() > 2 * one.a.occupied_mask().sum()


def test_cli_writes_each_groups_map_and_lists_it(two_buildings, tmp_path):
    one, two = two_buildings
    inputs = []
    for name, g in (("a", one.a), ("c", two.a), ("b", one.b), ("d", two.b)):
        save_map(g, tmp_path / f"{name}.yaml")
        inputs.append(str(tmp_path / f"{name}.yaml"))
    out = tmp_path / "m.yaml"
    code = main(["merge", *inputs, "-o", str(out), "--quiet"])
    assert code == 3                                           # some maps left out of m.yaml
    rep = json.loads((tmp_path / "m.report.json").read_text())
    assert rep["group_outputs"] == [str(tmp_path / "m.group1.yaml")]
    entries = {Path(e["input"]).stem: e for e in rep["maps"]}
    assert entries["d"]["group"] == 1 and entries["d"]["group_reference"] == inputs[1]
    assert set(entries["d"]["group_transform"]) == {"x", "y", "theta"}
    assert entries["b"]["group"] == 0 and "group_transform" not in entries["b"]
    fused = load_map(tmp_path / "m.group1.yaml")
    assert fused.resolution == two.a.resolution
    assert fused.occupied_mask().sum() >= two.a.occupied_mask().sum()


def test_a_map_linked_to_nothing_has_no_group(two_buildings):
    one, two = two_buildings
    result = merge([one.a, one.b, two.a], config=MergeConfig(method="consensus"))
    assert result.placements[2].group is None and not result.groups
    assert result.report(output="m.yaml")["group_outputs"] == []


def test_a_pair_with_a_rival_confirms_no_loop(tmp_path, capsys):
    """Five robots in the built-in office (rooms alike along a corridor), 60 poses each (seed
    11). Robot 2's pairs with robots 3 and 4 fit best one room period (17 m) off: with 3 it is
    ambiguous, with 4 not significant and with a rival. A loop through the pair with 4 used to
    confirm the alias in the pair with 3, and robot 2 joined the group of 3, 4 and 5 17 m off.
    A pair with a rival is no witness: every map placed (in the merged map, or in a group's
    map when the others are not linked to the reference) is where it belongs, and robot 2 is
    left out."""
    from fusionkit.cli.evaluate import evaluate_files
    run = tmp_path / "run"
    assert main(["simulate", "--robots", "5", "--poses", "60", "--seed", "11", "--out", str(run),
                 "--quiet"]) == 0
    robots = [str(run / f"robot_{k}.yaml") for k in range(1, 6)]
    out = tmp_path / "m.yaml"
    assert main(["merge", *robots, "-o", str(out)]) == 3
    capsys.readouterr()
    rep = json.loads((tmp_path / "m.report.json").read_text())
    assert sum(e["merged"] or e.get("group") is not None for e in rep["maps"]) >= 3
    for m in [out, *map(Path, rep["group_outputs"])]:
        res = evaluate_files(m, run / "truth.json")
        for row in res["maps"]:
            if row["merged"]:
                assert row["error"]["translation_cells"] < 3, (m.name, row)
    entries = {Path(e["input"]).name: e for e in rep["maps"]}
    assert entries["robot_2.yaml"].get("group") is None


def test_the_tui_export_writes_each_groups_map_as_merge_does(two_buildings, tmp_path):
    """The terminal UI's export once wrote a report listing ``merged.group1.yaml`` without
    writing that map (and removed any earlier one of that name)."""
    from fusionkit_tui.runner import export_result, run_merge

    one, two = two_buildings
    inputs = []
    for name, g in (("a", one.a), ("c", two.a), ("b", one.b), ("d", two.b)):
        save_map(g, tmp_path / f"{name}.yaml")
        inputs.append(str(tmp_path / f"{name}.yaml"))
    result = run_merge(inputs, MergeConfig(method="consensus"))
    paths = export_result(result, inputs, tmp_path / "merged.yaml")
    assert paths.groups == (tmp_path / "merged.group1.yaml",)
    rep = json.loads((tmp_path / "merged.report.json").read_text())
    assert rep["group_outputs"] == [str(tmp_path / "merged.group1.yaml")]
    fused = load_map(tmp_path / "merged.group1.yaml")
    assert np.array_equal(fused.data, result.groups[0].grid.trinary())


async def test_the_tui_result_names_a_maps_group(two_buildings, tmp_path):
    """The Result tab showed a map of another group as "merged: no" beside its confidence 1.00,
    as if it had been refused."""
    from textual.widgets import DataTable, Select

    from fusionkit_tui import make_app
    from test_tui import ready, run_merge

    one, two = two_buildings
    paths = []
    for name, g in (("a", one.a), ("c", two.a), ("b", one.b), ("d", two.b)):
        save_map(g, tmp_path / f"{name}.yaml")
        paths.append(str(tmp_path / f"{name}.yaml"))
    app = make_app(paths)
    async with app.run_test(size=(120, 40)) as pilot:
        await ready(pilot)
        app.main.query_one("#method", Select).value = "consensus"
        await pilot.pause()
        await run_merge(pilot, {})
        table = app.main.query_one("#placements", DataTable)
        assert [str(table.get_row_at(k)[1]) for k in range(4)] == ["yes", "group 1", "yes", "group 1"]


@pytest.mark.parametrize("order", [(0, 2, 3, 1), (0, 1, 2, 3)], ids=["apart", "together"])
def test_map_merge_keeps_every_linked_set_whatever_the_order(two_buildings, order):
    """Two windows of each of two floors: map-merge kept its largest set of matched maps alone.
    Given A, C, D, B (two sets of two), it kept C and D and left B out though B links to the
    reference A; given A, B, C, D, it merged B and dropped C and D with no group."""
    one, two = two_buildings
    maps = [one.a, one.b, two.a, two.b]
    result = merge([maps[k] for k in order], config=MergeConfig(method="map-merge"))
    p = {order[k]: q for k, q in enumerate(result.placements)}
    assert p[0].merged and p[1].merged and not p[2].merged and not p[3].merged
    d, r = placement_error(p[1].transform, one.truth, one.b)
    assert d < 3 * one.a.resolution and r < math.radians(2.0)
    assert p[2].group == p[3].group == 1
    first, second = sorted((2, 3), key=order.index)   # the group is in its first map's frame
    t = p[second].group_transform if second == 3 else p[second].group_transform.inverse
    d, r = placement_error(t, two.truth, two.b)
    assert d < 3 * two.a.resolution and r < math.radians(2.0)
    (group,) = result.groups
    assert sorted(group.members) == sorted(order.index(k) for k in (2, 3))


@pytest.mark.parametrize("method", ["map-merge", "map-merge-shipped"])
def test_map_merges_largest_group_without_the_reference_is_a_group(two_buildings, method):
    """A map of another building first, then two windows of one floor: map-merge's largest
    group of matched maps is the two windows. They were reported left out with no group, and
    fusion_order listed their join though the merged map did not hold it."""
    one, two = two_buildings
    result = merge([two.a, one.a, one.b], config=MergeConfig(method=method))
    p = result.placements
    assert [q.merged for q in p] == [True, False, False]
    assert [q.group for q in p] == [0, 1, 1]
    assert result.fusion_order == ()
    d, r = placement_error(p[2].group_transform, one.truth, one.b)
    assert d < 3 * one.a.resolution and r < math.radians(2.0)
    assert "group 1" in p[2].reason
    (group,) = result.groups
    assert group.members == (1, 2)


def test_a_groups_map_keeps_its_own_cell_size(two_buildings):
    """The reference at 0.1 m cells, a group of two windows at 0.05 m: the group's map was
    written at 0.1 m, its walls coarsened (precision 54 % against 80 % merged at 0.05 m)."""
    one, _ = two_buildings
    intel = load_map(REAL / "intel_lab.yaml")
    other = crop_pair(intel, np.random.default_rng(5), size=160, min_overlap=0.5).a
    assert other.resolution == pytest.approx(2 * one.a.resolution)
    result = merge([other, one.a, one.b], config=MergeConfig(method="consensus"))
    assert [q.group for q in result.placements] == [0, 1, 1]
    (group,) = result.groups
    assert group.grid.resolution == pytest.approx(one.a.resolution)
    assert result.grid.resolution == pytest.approx(other.resolution)
    alone = merge([one.a, one.b], config=MergeConfig(method="consensus"))
    assert group.grid.known_mask().sum() == pytest.approx(alone.grid.known_mask().sum(), rel=0.05)


def test_a_map_left_out_names_the_map_its_reason_is_about():
    """With three maps, a map left out was given the words of its surest pair, which could be a
    pair with another map left out, without saying so: both maps read the same reason."""
    from pathlib import Path

    from fusionkit.pipeline import merge
    real = Path(__file__).resolve().parents[1] / "maps" / "real"
    res = merge([real / f"{n}.yaml" for n in ("intel_lab", "mit_stata_basement", "gatech_ilab")])
    mit, gatech = res.placements[1], res.placements[2]
    assert not mit.merged and not gatech.merged
    # by the names the report gives them (a position, "map 3 of those given", had to be counted)
    assert mit.reason.endswith(f"(against {gatech.name}, its surest pair)"), mit.reason
    assert gatech.reason.endswith(f"(against {mit.name}, its surest pair)"), gatech.reason
    assert gatech.name.startswith("gatech_ilab") and mit.name.startswith("mit_stata_basement")
