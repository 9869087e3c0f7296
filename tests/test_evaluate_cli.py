"""``fusionkit evaluate`` on a hand-built world, truth.json and merge report."""

import json
import math

import numpy as np
import pytest

from fusionkit.cli import main
from fusionkit.grid import OccupancyGrid
from fusionkit.mapio import load_map, save_map
from fusionkit.metrics import evaluate_map
from fusionkit.resample import canvas_for, resample
from fusionkit.transform import Transform2D

RES = 0.05
# robot frame -> world frame. Quarter turns and whole-cell shifts keep nearest-neighbour
# resampling exact, so a perfect merged map scores exactly 100 %.
T1 = Transform2D(40 * RES, 10 * RES, math.pi / 2)
T2 = Transform2D(-20 * RES, 30 * RES, math.pi)
T3 = Transform2D(5 * RES, -5 * RES, 0.0)


def make_world() -> OccupancyGrid:
    data = np.full((40, 60), -1, np.int8)
    data[2:38, 2:58] = 0
    data[2, 2:58] = data[37, 2:58] = 100
    data[2:38, 2] = data[2:38, 57] = 100
    data[10:30, 30] = 100
    return OccupancyGrid(data, RES, (-1.0, -0.5, 0.0), "world")


def in_robot_frame(world: OccupancyGrid, t: Transform2D) -> OccupancyGrid:
    """The world map drawn in a robot's frame (``t``: robot frame -> world frame)."""
    canvas = canvas_for([world], [t.inverse], RES)
    return resample(world, t.inverse, canvas)


@pytest.fixture()
def scene(tmp_path):
    world = make_world()
    (tmp_path / "maps").mkdir()
    save_map(world, tmp_path / "maps" / "world.yaml")
    truth = {"world": "maps/world.yaml", "seed": 7, "robots": [
        {"name": "robot_1", "transform": T1.as_dict(digits=None), "poses": 10, "path_length_m": 1.0},
        {"name": "robot_2", "transform": T2.as_dict(digits=None), "poses": 10, "path_length_m": 1.0},
        {"name": "robot_3", "transform": T3.as_dict(digits=None), "poses": 10, "path_length_m": 1.0},
    ]}
    (tmp_path / "truth.json").write_text(json.dumps(truth))
    out = tmp_path / "out"
    out.mkdir()
    merged = in_robot_frame(world, T1)  # merged in robot_1's frame, perfect
    save_map(merged, out / "merged.yaml")
    true_12 = T1.inverse @ T2
    est_12 = Transform2D(true_12.x + 0.1, true_12.y, true_12.theta + math.radians(0.5))
    report = {
        "method": "spectral-pso", "reference": "robot_1.yaml", "output": "out/merged.yaml",
        "maps": [
            {"input": "robot_1.yaml", "merged": True, "confidence": 1.0,
             "transform": {"x": 0.0, "y": 0.0, "theta": 0.0}},
            {"input": "robot_2.yaml", "merged": True, "confidence": 0.93,
             "transform": est_12.as_dict(digits=None)},
            {"input": "robot_3.yaml", "merged": False, "confidence": 0.1, "transform": None},
        ],
        "fusion_order": [["robot_1.yaml", "robot_2.yaml"]], "seconds": {"total": 0.4},
    }
    (out / "merged.report.json").write_text(json.dumps(report))
    return tmp_path, world, report


def run(argv, capsys):
    code = main(["evaluate", *map(str, argv)])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def test_json_with_report_beside_the_map(scene, capsys):
    root, world, _ = scene
    code, out, err = run([root / "out/merged.yaml", "--truth", root / "truth.json", "--json"], capsys)
    assert code == 0, err
    res = json.loads(out)
    assert res["reference"] == "robot_1"
    assert res["report"].endswith("merged.report.json")
    m = res["metrics"]
    assert (m["completeness"], m["accuracy"], m["precision"], m["efficiency"]) == (100.0,) * 4
    assert m["known_truth"] == int(world.known_mask().sum())
    maps = {r["robot"]: r for r in res["maps"]}
    assert list(maps) == ["robot_1", "robot_2", "robot_3"]
    assert maps["robot_1"]["error"] == {"translation_m": 0.0, "translation_cells": 0.0, "rotation_deg": 0.0}
    e2 = maps["robot_2"]["error"]
    assert e2["translation_m"] == pytest.approx(0.1, abs=1e-4)
    assert e2["translation_cells"] == pytest.approx(2.0, abs=1e-3)
    assert e2["rotation_deg"] == pytest.approx(0.5, abs=1e-4)
    true_12 = T1.inverse @ T2
    assert maps["robot_2"]["true_transform"]["x"] == pytest.approx(true_12.x, abs=1e-6)
    assert maps["robot_2"]["merged"] is True and maps["robot_2"]["confidence"] == 0.93
    assert maps["robot_3"]["merged"] is False and maps["robot_3"]["error"] is None
    assert maps["robot_3"]["transform"] is None


def test_metrics_equal_the_library_call(scene, capsys):
    root, world, _ = scene
    # spoil the merged map: drop a block of cells and draw a false wall
    merged = load_map(root / "out/merged.yaml")
    data = merged.data.copy()
    data[5:15, 5:20] = -1
    data[20, 10:30] = 100
    save_map(merged.with_data(data), root / "out/merged.yaml")
    code, out, err = run([root / "out/merged.yaml", "--truth", root / "truth.json", "--json"], capsys)
    assert code == 0, err
    want = evaluate_map(load_map(root / "out/merged.yaml"), world, T1).as_dict()
    got = json.loads(out)["metrics"]
    assert got == want
    assert got["completeness"] < 100.0 and got["precision"] < 100.0


def test_plain_output_is_a_table(scene, capsys):
    root, _, _ = scene
    code, out, err = run([root / "out/merged.yaml", "--truth", root / "truth.json"], capsys)
    assert code == 0 and err == ""
    assert any(line.split() == ["completeness", "100.00", "%"] for line in out.splitlines())
    assert "precision (within 1 cell)" in out
    lines = out.splitlines()
    r2 = next(line for line in lines if line.strip().startswith("robot_2.yaml"))
    assert "yes" in r2 and "0.93" in r2 and "0.100" in r2 and "2.0" in r2 and "0.50" in r2
    r3 = next(line for line in lines if line.strip().startswith("robot_3.yaml"))
    assert " no " in r3


def test_report_json_in_the_same_directory(scene, capsys):
    root, _, report = scene
    (root / "out/merged.report.json").rename(root / "out/report.json")
    code, out, _ = run([root / "out/merged.yaml", "--truth", root / "truth.json", "--json"], capsys)
    assert code == 0 and json.loads(out)["report"].endswith("report.json")
    assert len(json.loads(out)["maps"]) == 3
    # a report.json for another output is not this map's report
    report["output"] = "out/other.yaml"
    (root / "out/report.json").write_text(json.dumps(report))
    code, out, _ = run([root / "out/merged.yaml", "--truth", root / "truth.json", "--json"], capsys)
    res = json.loads(out)
    assert code == 0 and res["report"] is None and res["maps"] == []
    assert res["reference"] == "robot_1"  # the first robot of truth.json


def _with_a_group(root, world, report, est_23):
    """The scene's merge as it is when robot_2 and robot_3 link to each other but not to
    robot_1: both left out of merged.yaml, group 1's map merged.group1.yaml in robot_2's frame."""
    ident = {"x": 0.0, "y": 0.0, "theta": 0.0}
    member = {"merged": False, "confidence": 0.0, "transform": None, "group": 1,
              "group_reference": "robot_2.yaml"}
    rep = dict(report, group_outputs=["out/merged.group1.yaml"], maps=[
        dict(report["maps"][0], group=0),
        dict(member, input="robot_2.yaml", group_transform=ident),
        dict(member, input="robot_3.yaml", confidence=0.97, group_transform=est_23.as_dict(digits=None)),
    ])
    (root / "out/merged.report.json").write_text(json.dumps(rep))
    save_map(in_robot_frame(world, T2), root / "out/merged.group1.yaml")
    return rep


def test_a_groups_map_is_scored_in_the_frame_of_its_first_map(scene, capsys):
    root, world, report = scene
    true_23 = T2.inverse @ T3
    est_23 = Transform2D(true_23.x, true_23.y + 0.05, true_23.theta)
    _with_a_group(root, world, report, est_23)
    group_map = root / "out/merged.group1.yaml"
    code, out, err = run([group_map, "--truth", root / "truth.json", "--json"], capsys)
    assert code == 0, err
    res = json.loads(out)
    # found through the main report's group_outputs, scored in robot_2's frame
    assert res["report"] == str(root / "out/merged.report.json")
    assert res["group"] == 1 and res["reference"] == "robot_2"
    assert res["metrics"] == evaluate_map(load_map(group_map), world, T2).as_dict()
    assert res["metrics"]["completeness"] == 100.0 and res["metrics"]["accuracy"] == 100.0
    rows = {r["robot"]: r for r in res["maps"]}
    assert set(rows) == {"robot_2", "robot_3"} and all(r["merged"] for r in rows.values())
    assert rows["robot_2"]["error"]["translation_m"] == pytest.approx(0.0, abs=1e-9)
    assert rows["robot_3"]["error"]["translation_m"] == pytest.approx(0.05, abs=1e-6)
    assert rows["robot_3"]["true_transform"] == pytest.approx(true_23.as_dict(digits=None))
    # the table says whose frame it is
    code, out, _ = run([group_map, "--truth", root / "truth.json"], capsys)
    assert code == 0 and "group 1 of the report" in out and "in the frame of robot_2" in out
    # its maps are in the group's map, not "merged" (the report has them left out of merged.yaml)
    header = next(line for line in out.splitlines() if line.lstrip().startswith("map "))
    assert header.split()[:3] == ["map", "in", "map"], header
    # the main map: the group's maps are listed as left out of it
    code, out, _ = run([root / "out/merged.yaml", "--truth", root / "truth.json", "--json"], capsys)
    res = json.loads(out)
    assert code == 0 and res["group"] is None and res["reference"] == "robot_1"
    assert [r["merged"] for r in res["maps"]] == [True, False, False]


def _broken_group_reports():
    """Reports that list merged.group1.yaml but do not say whose frame it is in."""
    def no_members(rep):
        for m in rep["maps"]:
            m.pop("group", None)

    def true_is_no_group(rep):
        for m in rep["maps"][1:]:
            m["group"] = True

    def reference_outside_the_group(rep):
        for m in rep["maps"][1:]:
            m["group_reference"] = "robot_1.yaml"

    def two_references(rep):
        rep["maps"][2]["group_reference"] = "robot_3.yaml"

    return [no_members, true_is_no_group, reference_outside_the_group, two_references]


@pytest.mark.parametrize("spoil", _broken_group_reports(), ids=lambda f: f.__name__)
def test_a_report_that_lists_a_groups_map_without_its_maps_is_refused(scene, capsys, spoil):
    root, world, report = scene
    rep = _with_a_group(root, world, report, Transform2D(0.0, 0.0, 0.0))
    spoil(rep)
    (root / "out/merged.report.json").write_text(json.dumps(rep))
    code, out, err = run([root / "out/merged.group1.yaml", "--truth", root / "truth.json"], capsys)
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1
    assert "group 1" in err and "Traceback" not in err


def test_a_groups_map_without_its_report_needs_a_reference(scene, capsys):
    root, world, report = scene
    rep = _with_a_group(root, world, report, Transform2D(0.0, 0.0, 0.0))
    (root / "out/merged.report.json").unlink()
    group_map = root / "out/merged.group1.yaml"
    code, out, err = run([group_map, "--truth", root / "truth.json"], capsys)
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1
    assert "--reference" in err and "--report" in err
    # the same when the report beside it does not list it
    rep["group_outputs"] = []
    (root / "out/merged.report.json").write_text(json.dumps(rep))
    code, out, err = run([group_map, "--truth", root / "truth.json"], capsys)
    assert code == 2 and "group_outputs" in err
    # with the robot whose frame it is in, it is scored in that frame
    code, out, err = run([group_map, "--truth", root / "truth.json", "--reference", "robot_2",
                          "--json"], capsys)
    res = json.loads(out)
    assert code == 0 and res["reference"] == "robot_2" and res["group"] is None
    assert res["metrics"]["accuracy"] == 100.0
    # --reference that disagrees with the group's frame names the group
    rep["group_outputs"] = ["out/merged.group1.yaml"]
    (root / "out/merged.report.json").write_text(json.dumps(rep))
    code, out, err = run([group_map, "--truth", root / "truth.json", "--reference", "robot_1"],
                         capsys)
    assert code == 2 and "group 1" in err and "robot_2.yaml" in err


def test_explicit_report_and_reference_without_report(scene, capsys):
    root, world, _ = scene
    rep = root / "elsewhere.json"
    (root / "out/merged.report.json").rename(rep)
    code, out, _ = run([root / "out/merged.yaml", "--truth", root / "truth.json", "--report", rep,
                        "--json"], capsys)
    assert code == 0 and len(json.loads(out)["maps"]) == 3
    # without a report the frame comes from --reference: the wrong robot scores badly
    code, out, _ = run([root / "out/merged.yaml", "--truth", root / "truth.json",
                        "--reference", "robot_2", "--json"], capsys)
    res = json.loads(out)
    assert code == 0 and res["reference"] == "robot_2" and res["maps"] == []
    assert res["metrics"]["accuracy"] < 90.0
    want = evaluate_map(load_map(root / "out/merged.yaml"), world, T2).as_dict()
    assert res["metrics"] == want


def test_world_path_relative_to_the_current_directory(scene, capsys, monkeypatch):
    root, _, _ = scene
    sub = root / "sim"
    sub.mkdir()
    (sub / "truth.json").write_text((root / "truth.json").read_text())  # "maps/world.yaml"
    monkeypatch.chdir(root)
    code, out, err = run(["out/merged.yaml", "--truth", "sim/truth.json", "--json"], capsys)
    assert code == 0, err
    assert json.loads(out)["metrics"]["completeness"] == 100.0


def write(path, obj):
    path.write_text(obj if isinstance(obj, str) else json.dumps(obj))
    return path


@pytest.mark.parametrize("case, message", [
    ("missing_merged", "no such map file"),
    ("missing_truth", "no such truth file; check the path"),
    ("truth_not_json", "not valid JSON"),
    ("truth_no_robots", "no robots"),
    ("truth_bad_transform", "numeric x, y"),
    ("world_missing", "world map"),
    ("unknown_reference", "no such robot"),
    ("report_other_output", "this report is for"),
    ("report_unknown_robot", "not in"),
    ("report_reference_conflict", "disagrees"),
    ("report_missing", "no such merge report"),
])
def test_bad_input_one_line_exit_2(scene, capsys, case, message):
    root, _, report = scene
    merged, truth = root / "out/merged.yaml", root / "truth.json"
    t = json.loads(truth.read_text())
    extra = []
    if case == "missing_merged":
        merged = root / "out/nothing.yaml"
    elif case == "missing_truth":
        truth = root / "nope.json"
    elif case == "truth_not_json":
        truth = write(root / "t.json", "{world: ")
    elif case == "truth_no_robots":
        truth = write(root / "t.json", {**t, "robots": []})
    elif case == "truth_bad_transform":
        t["robots"][1]["transform"] = {"x": 1}
        truth = write(root / "t.json", t)
    elif case == "world_missing":
        truth = write(root / "t.json", {**t, "world": "maps/none.yaml"})
    elif case == "unknown_reference":
        (root / "out/merged.report.json").unlink()
        extra = ["--reference", "robot_9"]
    elif case == "report_other_output":
        extra = ["--report", write(root / "r.json", {**report, "output": "x/other.yaml"})]
    elif case == "report_unknown_robot":
        report["maps"][1]["input"] = "robot_7.yaml"
        write(root / "out/merged.report.json", report)
    elif case == "report_reference_conflict":
        extra = ["--reference", "robot_2"]
    elif case == "report_missing":
        extra = ["--report", root / "none.json"]
    code, out, err = run([merged, "--truth", truth, *extra], capsys)
    assert code == 2
    assert out == ""
    assert len(err.strip().splitlines()) == 1 and message in err, err
    assert err.startswith("fusionkit evaluate: error:")


def test_help_explains_every_option(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["evaluate", "--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    for opt in ("--truth", "--report", "--reference", "--json", "MERGED.yaml"):
        assert opt in text


def test_maps_are_matched_to_the_truth_by_path_not_by_name(scene, capsys, monkeypatch):
    """Two runs both have a robot_2.yaml: only the one beside truth.json gets its true transform."""
    root, world, report = scene
    for name, t in (("robot_1", T1), ("robot_2", T2)):
        save_map(in_robot_frame(world, t), root / f"{name}.yaml")
    (root / "other").mkdir()
    save_map(in_robot_frame(world, T3), root / "other" / "robot_2.yaml")
    monkeypatch.chdir(root)
    code, out, err = run(["out/merged.yaml", "--truth", "truth.json", "--json"], capsys)
    assert code == 0, err
    rows = json.loads(out)["maps"]
    assert [r["robot"] for r in rows] == ["robot_1", "robot_2", "robot_3"]
    true_12 = (T1.inverse @ T2).as_dict()
    assert rows[1]["true_transform"] == pytest.approx(true_12)
    # the same report naming the other run's robot_2: refused, not scored against this run's
    report["maps"][1]["input"] = "other/robot_2.yaml"
    write(root / "out/merged.report.json", report)
    code, out, err = run(["out/merged.yaml", "--truth", "truth.json", "--json"], capsys)
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and "other/robot_2.yaml" in err and "not in the run" in err
    # from another directory the paths are found from the report's directory... or not at all:
    # two maps of the same name that cannot be found cannot be told apart
    report["maps"][2]["input"] = "elsewhere/robot_2.yaml"
    report["maps"][1]["input"] = "gone/robot_2.yaml"
    write(root / "out/merged.report.json", report)
    code, out, err = run(["out/merged.yaml", "--truth", "truth.json"], capsys)
    assert code == 2 and "cannot be told apart" in err


def test_long_map_paths_are_cut_with_an_ellipsis(scene, capsys):
    root, _, report = scene
    report["maps"][1]["input"] = "some/very/long/directory/of/runs/robot_2.yaml"
    write(root / "out/merged.report.json", report)
    code, out, err = run([root / "out/merged.yaml", "--truth", root / "truth.json"], capsys)
    assert code == 0, err
    row = next(line for line in out.splitlines() if "robot_2.yaml" in line)
    assert row.split()[0].startswith("…") and row.split()[0].endswith("runs/robot_2.yaml")
    # a path of 26 characters is shown whole (it was cut at 24, to "…where/run/robot_2.yaml");
    # one that exists nowhere, as above (runs/default/ of the README's first command would)
    report["maps"][1]["input"] = "elsewhere/run/robot_2.yaml"
    write(root / "out/merged.report.json", report)
    code, out, err = run([root / "out/merged.yaml", "--truth", root / "truth.json"], capsys)
    assert code == 0, err
    row = next(line for line in out.splitlines() if "robot_2.yaml" in line)
    assert row.split()[0] == "elsewhere/run/robot_2.yaml", row


def test_a_robots_own_map_is_scored_in_its_own_frame(scene, capsys):
    """``evaluate robot_2.yaml`` (no report) places robot_2's map by robot_2's transform, not the
    first robot's: a perfect map of robot_2 scores 100 %."""
    root, world, _ = scene
    save_map(in_robot_frame(world, T2), root / "robot_2.yaml")
    assert main(["evaluate", str(root / "robot_2.yaml"), "--truth", str(root / "truth.json"),
                 "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["reference"] == "robot_2"
    assert out["metrics"]["precision"] == pytest.approx(100.0)
    # a frame given is still the frame used
    assert main(["evaluate", str(root / "robot_2.yaml"), "--truth", str(root / "truth.json"),
                 "--reference", "robot_1", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["reference"] == "robot_1" and out["metrics"]["precision"] < 50.0


def test_a_map_of_another_run_is_refused_from_any_folder(tmp_path, monkeypatch, capsys):
    """The report names its inputs relative to where merge ran; evaluated from another folder,
    none was found, the file names matched the other run's robots, and a merge of one run was
    scored against another's truth (exit 0, precision 7.7 %)."""
    from fusionkit.cli import main

    monkeypatch.chdir(tmp_path)
    for run, seed in (("three", "2"), ("default", "3")):
        assert main(["simulate", "--robots", "2", "--poses", "60", "--seed", seed, "--out",
                     f"runs/{run}", "--quiet"]) == 0
    main(["merge", "runs/three/robot_1.yaml", "runs/three/robot_2.yaml", "-o",
          "runs/three/merged.yaml", "--quiet"])
    (tmp_path / "elsewhere").mkdir()
    monkeypatch.chdir(tmp_path / "elsewhere")
    capsys.readouterr()
    assert main(["evaluate", str(tmp_path / "runs/three/merged.yaml"), "--truth",
                 str(tmp_path / "runs/default/truth.json")]) == 2
    assert "is not in the run of" in capsys.readouterr().err
    assert main(["evaluate", str(tmp_path / "runs/three/merged.yaml"), "--truth",
                 str(tmp_path / "runs/three/truth.json"), "--json"]) == 0


def test_a_merge_of_maps_since_replaced_by_a_new_run_is_refused(tmp_path, monkeypatch, capsys):
    """A folder simulated again holds new maps under the old names: a merge of the old ones,
    evaluated against the new truth, matched by path and was scored (36.98 m off, exit 0)."""
    from fusionkit.cli import main

    monkeypatch.chdir(tmp_path)
    (tmp_path / "outm").mkdir()
    assert main(["simulate", "--robots", "2", "--poses", "60", "--seed", "1", "--out", "w3", "--quiet"]) == 0
    main(["merge", "w3/robot_1.yaml", "w3/robot_2.yaml", "-o", "outm/m.yaml", "--quiet"])
    assert main(["evaluate", "outm/m.yaml", "--truth", "w3/truth.json", "--json"]) == 0
    assert main(["simulate", "--robots", "2", "--poses", "60", "--seed", "2", "--out", "w3", "--quiet"]) == 0
    capsys.readouterr()
    assert main(["evaluate", "outm/m.yaml", "--truth", "w3/truth.json"]) == 2
    assert "is not the file that was merged" in capsys.readouterr().err


def test_a_merge_with_its_own_report_name_takes_the_earlier_report_of_its_output_away(
        tmp_path, capsys):
    """merge -o s.yaml (report s.report.json), then merge of other maps -o s.yaml --report
    s_new.json: s.report.json stayed, and evaluate s.yaml read it: errors of a map not in s.yaml."""
    run_dir = tmp_path / "run"
    assert main(["simulate", "--robots", "3", "--poses", "300", "--seed", "2", "--out",
                 str(run_dir), "--quiet"]) == 0
    r1, r2, r3 = (str(run_dir / f"robot_{k}.yaml") for k in (1, 2, 3))
    out = tmp_path / "out"
    out.mkdir()
    main(["merge", r1, r2, "-o", str(out / "s.yaml"), "--method", "map-merge", "--quiet"])
    assert (out / "s.report.json").is_file()
    notes = out / "notes.json"                  # JSON, not a merge report: stays
    notes.write_text('{"maps": "mine"}')
    main(["merge", r1, r3, "-o", str(out / "s.yaml"), "--method", "map-merge", "--report",
          str(out / "s_new.json"), "--quiet"])
    assert not (out / "s.report.json").exists()
    assert notes.is_file() and (out / "s_new.json").is_file()
    capsys.readouterr()
    code = main(["evaluate", str(out / "s.yaml"), "--truth", str(run_dir / "truth.json"),
                 "--json"])
    res = json.loads(capsys.readouterr().out)
    assert code == 0 and res["report"].endswith("s_new.json")
    assert [r["robot"] for r in res["maps"]] == ["robot_1", "robot_3"]


def test_merge_takes_its_reference_however_its_path_is_written(tmp_path, monkeypatch, capsys):
    """--reference ./robot_2.yaml for a map given as robot_2.yaml was 'not one of the maps
    given'."""
    run_dir = tmp_path / "run"
    assert main(["simulate", "--robots", "2", "--poses", "300", "--seed", "3", "--out",
                 str(run_dir), "--quiet"]) == 0
    monkeypatch.chdir(run_dir)
    code = main(["merge", "robot_1.yaml", "robot_2.yaml", "-o", str(tmp_path / "m.yaml"),
                 "--method", "map-merge", "--reference", "./robot_2.yaml", "--quiet"])
    assert code in (0, 3), capsys.readouterr().err
    assert json.loads((tmp_path / "m.report.json").read_text())["reference"] == "robot_2.yaml"


def test_a_groups_map_that_is_not_there_is_said_to_be_missing(scene, capsys):
    """It was said to be named like a group's map with no report listing it, not missing."""
    root, _, _ = scene
    code, out, err = run([root / "out/merged.group2.yaml", "--truth", root / "truth.json"], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "no such map file" in err, err


def test_a_map_scored_without_a_report_or_reference_says_whose_frame_was_taken(scene, capsys):
    """A copy of robot_2's map, no report beside it: scored in robot_1's frame (2.8 % precision
    in a trial), exit 0, and nothing said the frame was only the first robot's by default."""
    root, world, _ = scene
    (root / "copy").mkdir()
    save_map(in_robot_frame(world, T2), root / "copy/robot_2.yaml")
    code, out, _ = run([root / "copy/robot_2.yaml", "--truth", root / "truth.json"], capsys)
    assert code == 0
    assert ("the map was taken to be in the frame of robot_1, the first robot of the truth: give "
            "--reference ROBOT if it is in another's") in out
    for given in (["--reference", "robot_2"], ["--json"]):   # a frame given; the JSON says it too
        code, out, _ = run([root / "copy/robot_2.yaml", "--truth", root / "truth.json", *given], capsys)
        assert code == 0 and "taken to be in the frame" not in out
    assert json.loads(out)["frame_guessed"] is True
    code, out, _ = run([root / "out/merged.yaml", "--truth", root / "truth.json", "--json"], capsys)
    assert json.loads(out)["frame_guessed"] is False
