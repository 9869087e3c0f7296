"""The command line as a newcomer meets it: the command list, run's options and output,
simulate's summary."""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest

from fusionkit.cli import COMMANDS, build_parser, main
from fusionkit.errors import InputError
from fusionkit.pipeline import MergeConfig


def _subparsers(parser):
    return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))


def test_help_lists_every_command_with_its_own_words_without_loading_the_heavy_parts():
    full = _subparsers(build_parser())
    listed = {a.dest: a.help for a in full._choices_actions}
    assert list(listed) == list(COMMANDS)
    for name, (_, help_text) in COMMANDS.items():
        assert listed[name] == help_text, name  # the list says what the command says
    code = ("import sys; from fusionkit.cli import main\n"
            "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
            "heavy = sorted(m for m in ('numba', 'scipy', 'textual', 'cv2', 'matplotlib') if m in sys.modules)\n"
            "print('HEAVY', heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60).stdout
    assert "HEAVY []" in out, out
    assert "docs/formats.md" in out and all(name in out for name in COMMANDS)


def test_merge_node_help_gives_each_parameter_its_default_and_meaning(capsys):
    """The node's warning for an unknown parameter sends the user to --help for the
    parameters, which listed their names alone."""
    with pytest.raises(SystemExit):
        main(["ros2", "merge-node", "--help"])
    text = capsys.readouterr().out
    assert "min_confidence (0.5): least confidence (0-1) for a robot to be placed" in text
    assert "known_init_poses (false):" in text and "world_frame ('world'):" in text
    assert "/<robot>/map_merge/init_pose_x, _y, _z, _yaw" in text


def test_help_cites_the_shipped_formats_document_not_a_contract_section(capsys):
    for name in COMMANDS:
        with pytest.raises(SystemExit):
            main([name, "--help"])
        text = capsys.readouterr().out
        assert "CONTRACTS" not in text, name
    from pathlib import Path
    doc = Path(__file__).resolve().parents[1] / "docs" / "formats.md"
    text = doc.read_text(encoding="utf-8")
    for needle in ("map_server", "scans.npz", "truth.json", "report", "completeness", "radians"):
        assert needle in text


def test_run_takes_seed_like_simulate_and_keeps_the_old_name():
    parser = build_parser(["run"])
    a = parser.parse_args(["run", "--seed", "3"])
    assert a.sim_seed == 3 and a.seed == 0  # the merge keeps its own seed
    assert parser.parse_args(["run", "--sim-seed", "4"]).sim_seed == 4
    b = parser.parse_args(["run", "--merge-seed", "5"])
    assert b.seed == 5 and b.sim_seed == 7


def test_run_prints_one_fusion_order_and_explains_the_table(tmp_path, capsys):
    code = main(["run", "--robots", "2", "--poses", "300", "--seed", "3", "--iterations", "20",
                 "--out", str(tmp_path / "r")])
    out = capsys.readouterr().out
    assert code in (0, 3)
    assert sum(line.startswith("fusion order") for line in out.splitlines()) == 1
    for column in ("Compl ", "Acc ", "Prec ", "Eff ", "Prec1 "):
        assert any(line.strip().startswith(column) for line in out.splitlines()), column
    assert "Row M1 is the first map" in out and "oracle" in out
    assert "(seed 3)" in out
    truth = json.loads((tmp_path / "r" / "truth.json").read_text())
    assert truth["seed"] == 3


def test_simulate_says_which_seed_is_the_world_and_which_the_robots(tmp_path, capsys):
    assert main(["simulate", "--robots", "1", "--poses", "50", "--seed", "1",
                 "--out", str(tmp_path / "s")]) == 0
    out = capsys.readouterr().out
    world = next(line for line in out.splitlines() if line.startswith("world:"))
    assert "layout seed 0" in world and "seed 1" not in world
    assert "simulation seed 1" in out


@pytest.mark.parametrize("argv, command", [
    (["merge", "a.yaml", "b.yaml", "-o", "m.yaml", "--bogus"], "fusionkit merge"),
    (["evaluate", "m.yaml", "--truth", "t.json", "--bogus"], "fusionkit evaluate"),
    (["import", "carmen", "x.log", "--out", "d", "--bogus"], "fusionkit import carmen"),
    (["import", "--bogus", "carmen", "x.log", "--out", "d"], "fusionkit import"),
    (["--bogus", "merge", "a.yaml", "b.yaml", "-o", "m.yaml"], "fusionkit"),
])
def test_an_unknown_option_is_named_by_the_command_it_was_given_to(capsys, argv, command):
    """argparse reports options it does not know from the top-level parser; fusionkit has the
    (sub)command that was given them say so, in one line that says where its options are."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.splitlines() == [f"{command}: error: unrecognized arguments: --bogus; "
                                f"see {command} --help"]


@pytest.mark.parametrize("argv, line", [
    (["merge", "a.yaml", "b.yaml", "--ouput", "m.yaml"],
     "fusionkit merge: error: unrecognized arguments: --ouput (did you mean --output?); "
     "see fusionkit merge --help"),
    (["merge", "a.yaml", "b.yaml", "-o", "m.yaml", "--sed", "3"],
     "fusionkit merge: error: unrecognized arguments: --sed 3 (did you mean --seed?); "
     "see fusionkit merge --help"),
    (["import", "carmen", "x.log", "--ot", "d"],
     "fusionkit import carmen: error: unrecognized arguments: --ot (did you mean --out?); "
     "see fusionkit import carmen --help"),
    (["ros2", "--bogus"], "fusionkit ros2: error: unrecognized arguments: --bogus; "
                          "see fusionkit ros2 --help"),
])
def test_a_mistyped_option_is_named_with_the_option_it_may_mean(capsys, argv, line):
    """A typo in a required option's name used to be reported as that option missing
    ("the following arguments are required: -o/--output"), the word typed never named."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    assert capsys.readouterr().err.splitlines() == [line]


def test_negative_numbers_and_abbreviations_are_not_taken_for_unknown_options(capsys):
    with pytest.raises(SystemExit):
        main(["merge", "a.yaml", "--theta", "-0.5", "--max-false", "0.1"])
    assert "the following arguments are required: -o/--output" in capsys.readouterr().err


@pytest.mark.parametrize("argv, words", [
    (["merge", "a.yaml", "b.yaml", "-o", "m.yaml", "--workers", "0"], "--workers: must be between 1"),
    (["merge", "a.yaml", "b.yaml", "-o", "m.yaml", "--seed", "-1"], "--seed: must be between 0"),
    (["merge", "a.yaml", "b.yaml", "-o", "m.yaml", "--seed", str(2**64)], "--seed: must be between 0"),
    (["merge", "a.yaml", "b.yaml", "-o", "m.yaml", "--method", "map-merge", "--seed", "-1"],
     "--seed: must be between 0"),
    (["merge", "a.yaml", "b.yaml", "-o", "m.yaml", "--delta", "-1"], "--delta: must be >= 0"),
    (["run", "--merge-seed", "-1", "--out", "never_written"], "--merge-seed: must be between 0"),
    (["merge", "a.yaml"], "the following arguments are required: -o/--output"),
    # --split 1 wrote one map named after the log, no robot_1, no truth.json
    (["import", "carmen", "x.log", "--out", "d", "--split", "1"], "--split: must be between 2"),
])
def test_a_bad_option_value_is_one_line_before_any_work(capsys, tmp_path, monkeypatch, argv, words):
    """A value the command cannot use is refused by the option's own check: one line, exit 2,
    nothing written (a negative merge seed once failed in numpy after ``run`` had written its
    simulated run)."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and words in lines[0] and lines[0].endswith("--help"), lines
    assert list(tmp_path.iterdir()) == []


def test_the_library_refuses_a_seed_numpy_cannot_take():
    with pytest.raises(InputError, match="seed"):
        MergeConfig(seed=-1)
    with pytest.raises(InputError, match="delta"):
        MergeConfig(delta=-0.5)


@pytest.mark.parametrize("argv, command", [
    (["ros2", "play", "no_such_run"], "fusionkit ros2 play"),
    (["import", "carmen", "no_such.log", "--out", "d"], "fusionkit import carmen"),
    (["evaluate", "no_such.yaml", "--truth", "t.json"], "fusionkit evaluate"),
])
def test_an_error_is_named_by_the_command_that_met_it_as_its_usage_errors_are(tmp_path, capsys,
                                                                              monkeypatch, argv, command):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"{command}: error: ") and err.count("\n") == 1, err


@pytest.mark.parametrize("argv, said", [
    (["bench", "notes.txt", "--cases", "1", "--out", "out"],
     "fusionkit bench: error: notes.txt: is a file, not a folder of ground-truth maps"),
    (["export", "rosbag", "notes.txt"],
     "fusionkit export rosbag: error: notes.txt: is a file, not a run directory"),
])
def test_a_file_given_for_a_folder_is_said_to_be_a_file(tmp_path, capsys, monkeypatch, argv, said):
    """It was said not to exist ("no such folder", "not found")."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "notes.txt").write_text("not a folder\n")
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(said) and err.count("\n") == 1, err
    assert not (tmp_path / "out").exists()


def test_one_map_or_a_pattern_that_matched_nothing_is_said_as_such(tmp_path, capsys):
    """A shell pattern that matches no file reaches the command as written: it said only "give
    at least two maps to merge", not that no such file exists."""
    from fusionkit.mapio import save_map
    from fusionkit.worlds import make_world
    save_map(make_world("cave", 0), tmp_path / "a.yaml")
    for given, said in ((str(tmp_path / "nothere" / "robot_*.yaml"), "robot_*.yaml': no such map file (a "
                         "pattern such as robot_*.yaml that matches no file is passed on as it is); "
                         "give at least two maps to merge"),
                        (str(tmp_path / "a.yaml"), "give at least two maps to merge")):
        assert main(["merge", given, "-o", str(tmp_path / "m.yaml")]) == 2
        err = capsys.readouterr().err.splitlines()
        assert len(err) == 1 and err[0].endswith(said), err


def test_a_map_given_twice_is_refused_in_one_line(tmp_path, capsys):
    """The same file under one path or two (``a/../a``, a link) is one map: merged with itself it
    would be placed on itself and listed twice in the report."""
    from fusionkit.grid import OccupancyGrid
    from fusionkit.mapio import save_map

    data = np.full((40, 40), 0, np.int8)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    save_map(OccupancyGrid(data, 0.1, (0.0, 0.0, 0.0)), tmp_path / "a.yaml")
    save_map(OccupancyGrid(data, 0.1, (0.0, 0.0, 0.0)), tmp_path / "b.yaml")
    (tmp_path / "link.yaml").symlink_to(tmp_path / "a.yaml")
    for second in (tmp_path / "a.yaml", tmp_path / "sub" / ".." / "a.yaml", tmp_path / "link.yaml"):
        (tmp_path / "sub").mkdir(exist_ok=True)
        argv = ["merge", str(tmp_path / "a.yaml"), str(tmp_path / "b.yaml"), str(second),
                "-o", str(tmp_path / "m.yaml")]
        assert main(argv) == 2
        err = capsys.readouterr().err.splitlines()
        assert len(err) == 1 and "given twice" in err[0] and "maps 1 and 3" in err[0], err
        assert not (tmp_path / "m.yaml").exists()
    # two YAML files naming one image: one map too (they were merged, each on the other)
    (tmp_path / "c.yml").write_text((tmp_path / "a.yaml").read_text())
    assert main(["merge", str(tmp_path / "a.yaml"), str(tmp_path / "c.yml"), "-o",
                 str(tmp_path / "m.yaml")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "name the same image" in err[0] and "give it once" in err[0], err
    assert f"{tmp_path / 'a.yaml'} and {tmp_path / 'c.yml'} (maps 1 and 2)" in err[0], err
    assert not (tmp_path / "m.yaml").exists()


def test_the_world_map_of_a_run_is_refused_as_a_merge_input(tmp_path, capsys):
    """``merge run/*.yaml`` fused the run's ground truth in with its robots without a word, and
    ``evaluate`` then said the merged map was not of that run."""
    run = tmp_path / "run"
    assert main(["simulate", "--robots", "2", "--poses", "40", "--out", str(run), "--quiet"]) == 0
    argv = ["merge", str(run / "robot_1.yaml"), str(run / "robot_2.yaml"), str(run / "world.yaml"),
            "-o", str(tmp_path / "m.yaml")]
    assert main(argv) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "world.yaml" in err[0] and "ground-truth map of a run" in err[0], err
    assert "leave it out of the merge" in err[0] and not (tmp_path / "m.yaml").exists()
    # the terminal UI's merge of the same files, given on its command line, says the same
    from fusionkit_tui.runner import run_merge
    with pytest.raises(InputError, match="ground-truth map of a run"):
        run_merge(argv[1:4], MergeConfig(method="map-merge"))
    # a copy of it outside the run is a map like any other
    (tmp_path / "plan").mkdir()
    for suffix in (".yaml", ".pgm"):
        (tmp_path / "plan" / f"world{suffix}").write_bytes((run / f"world{suffix}").read_bytes())
    assert main(["merge", str(run / "robot_1.yaml"), str(tmp_path / "plan" / "world.yaml"), "-o",
                 str(tmp_path / "m.yaml"), "--quiet"]) in (0, 3)
    assert (tmp_path / "m.yaml").exists()
    # a world the run's truth.json names in another folder is refused as well
    truth = json.loads((run / "truth.json").read_text())
    (tmp_path / "elsewhere").mkdir()
    for suffix in (".yaml", ".pgm"):
        (run / f"world{suffix}").rename(tmp_path / "elsewhere" / f"world{suffix}")
    (run / "truth.json").write_text(json.dumps(dict(truth, world="../elsewhere/world.yaml")))
    assert main(argv[:3] + [str(tmp_path / "elsewhere" / "world.yaml"), "-o", str(tmp_path / "m2.yaml")]) == 2
    assert "ground-truth map of a run" in capsys.readouterr().err
    # and a truth.json that names a robot's own map as its world refuses no robot
    (run / "truth.json").write_text(json.dumps(dict(truth, world="robot_1.yaml")))
    assert main(argv[:3] + ["-o", str(tmp_path / "m2.yaml"), "--quiet"]) in (0, 3)


def test_a_merge_never_writes_over_the_ground_truth_of_the_inputs_run(tmp_path, capsys):
    """Merging two robots of a run into the run's folder may not replace its world map, another
    robot's map or truth.json: ``fusionkit evaluate`` reads them afterwards."""
    run = tmp_path / "run"
    assert main(["simulate", "--robots", "3", "--poses", "40", "--out", str(run), "--quiet"]) == 0
    before = {p.name: p.read_bytes() for p in run.iterdir()}
    for target in ("world.yaml", "robot_3.yaml"):
        assert main(["merge", str(run / "robot_1.yaml"), str(run / "robot_2.yaml"), "-o",
                     str(run / target)]) == 2
        err = capsys.readouterr().err.splitlines()
        assert len(err) == 1 and "ground truth of the inputs' run" in err[0], err
    assert main(["merge", str(run / "robot_1.yaml"), str(run / "robot_2.yaml"), "-o",
                 str(tmp_path / "m.yaml"), "--report", str(run / "truth.json")]) == 2
    assert "ground truth" in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in run.iterdir()} == before


@pytest.mark.parametrize("name", ["other.scans.npz", "other.yaml", "other.pgm"])
def test_a_report_named_like_a_map_or_a_scan_log_is_refused_before_any_work(tmp_path, capsys, name):
    run = tmp_path / "run"
    assert main(["simulate", "--robots", "2", "--poses", "40", "--out", str(run), "--quiet"]) == 0
    target = tmp_path / name
    target.write_bytes(b"keep me")
    assert main(["merge", str(run / "robot_1.yaml"), str(run / "robot_2.yaml"), "-o",
                 str(tmp_path / "m.yaml"), "--report", str(target)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "ending in .json" in err[0], err
    assert target.read_bytes() == b"keep me"
    assert not (tmp_path / "m.yaml").exists()


def test_a_new_run_into_a_folder_takes_the_merges_of_the_old_robots_with_them(tmp_path, capsys):
    """``simulate --out D`` over an earlier run kept D/merged.yaml, a merge of the old robots,
    and ``evaluate`` then scored it against the new truth without a word."""
    run = tmp_path / "run"
    assert main(["simulate", "--robots", "3", "--poses", "40", "--out", str(run), "--quiet"]) == 0
    robots = [str(run / "robot_1.yaml"), str(run / "robot_2.yaml")]
    main(["merge", *robots, "-o", str(run / "merged.yaml"), "--quiet"])
    main(["merge", *robots, "-o", str(run / "m2.yaml"), "--report", str(run / "r.json"), "--quiet"])
    (run / "notes.json").write_text('{"mine": true}')
    capsys.readouterr()
    assert main(["simulate", "--robots", "2", "--poses", "40", "--seed", "5", "--out", str(run)]) == 0
    # every file taken away is said: robot_3's too (only the merges' YAML files were)
    said = capsys.readouterr().out
    assert ("removed the earlier run's files that this one makes wrong: m2.pgm, m2.yaml, "
            "merged.pgm, merged.report.json, merged.yaml, r.json, robot_3.pgm, robot_3.scans.npz, "
            "robot_3.yaml") in said, said
    assert sorted(p.name for p in run.iterdir()) == [
        "notes.json", "robot_1.pgm", "robot_1.scans.npz", "robot_1.yaml", "robot_2.pgm",
        "robot_2.scans.npz", "robot_2.yaml", "truth.json", "world.pgm", "world.yaml"]


def test_two_maps_whose_paths_differ_only_where_clipped_print_apart():
    """The table clipped each path to its last 28 characters: two runs' robot_1.yaml of the
    same floor printed as the same map."""
    from fusionkit.cli.merge import format_placements
    from fusionkit.pipeline import MapPlacement, MergeConfig
    from fusionkit.transform import Transform2D

    class Result:
        placements = [MapPlacement(0, "a", True, Transform2D.identity(), 1.0),
                      MapPlacement(1, "b", False, None, 0.0, reason="why")]
        fusion_order = ()
        config = MergeConfig()
        seconds = {"total": 0.1}

    names = ["site_alpha/session_morning_floor2/robot_1.yaml",
             "site_beta/session_morning_floor2/robot_1.yaml"]
    lines = format_placements(Result, names).splitlines()
    assert lines[1].startswith(names[0] + " ") and lines[2].startswith(names[1] + " ")
    assert lines[0].index("merged") == lines[1].index("yes") == lines[2].index("no")
    short = format_placements(Result, ["a.yaml", "runs/b.yaml"]).splitlines()   # as before
    assert short[1].startswith("a.yaml" + " " * 22 + " yes")


def test_a_map_merged_by_a_methods_own_rule_that_the_test_doubts_is_noted():
    """A peer's or the paper's merge at confidence 0.00 read as a success: exit 0, no word."""
    from fusionkit.cli.merge import format_placements
    from fusionkit.pipeline import MapPlacement, MergeConfig
    from fusionkit.transform import Transform2D

    def table(method):
        class Result:
            placements = [MapPlacement(0, "a", True, Transform2D.identity(), 1.0),
                          MapPlacement(1, "b", True, Transform2D(1.0, 2.0, 3.0), 0.0),
                          MapPlacement(2, "c", True, Transform2D(1.0, 2.0, 0.0), 0.97)]
            fusion_order = ((0, 1), (0, 2))
            config = MergeConfig(method=method)
            seconds = {"total": 0.1}
        return format_placements(Result, ["a.yaml", "b.yaml", "c.yaml"])

    assert ("note: 1 map merged by spectral-pso's own rule at confidence under 0.50, where the "
            "test cannot tell it from a wrong placement: b.yaml") in table("spectral-pso")
    assert "note:" not in table("consensus")


def test_a_number_that_rounds_to_zero_prints_as_0_not_minus_0():
    """evaluate printed "-0.0" for a true heading of -1e-9 rad."""
    from fusionkit.labels import fixed

    assert fixed(-1e-9, 8, 1) == "     0.0"
    assert fixed(-0.04, 6, 2) == " -0.04"


def test_a_finished_command_is_not_killed_by_a_late_ctrl_c(monkeypatch, capsys):
    """Python gives SIGINT its default action back as it shuts down: a Ctrl-C in that 0.1 s
    killed a merge that had written its files and printed its table (exit -2, no word)."""
    import signal

    monkeypatch.setattr(sys, "argv", ["fusionkit", "--version"])
    before = signal.getsignal(signal.SIGINT)
    try:
        with pytest.raises(SystemExit):
            main()
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, before)


def test_an_upper_case_output_name_is_taken_and_an_empty_report_path_refused(tmp_path, capsys):
    """-o M.YAML was refused ('must end in .yaml'), though maps so named are read; --report ''
    silently meant the default report."""
    from fusionkit.grid import OccupancyGrid
    from fusionkit.mapio import load_map, save_map

    data = np.full((60, 60), 0, np.int8)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    data[20:40, 30] = 100
    save_map(OccupancyGrid(data, 0.1, (0.0, 0.0, 0.0)), tmp_path / "a.yaml")
    save_map(OccupancyGrid(data, 0.1, (1.0, 0.5, 0.0)), tmp_path / "b.yaml")
    maps = [str(tmp_path / "a.yaml"), str(tmp_path / "b.yaml")]
    assert main(["merge", *maps, "-o", str(tmp_path / "M.YAML"), "--method", "map-merge",
                 "--quiet"]) in (0, 3)
    assert load_map(tmp_path / "M.YAML").resolution == 0.1
    assert (tmp_path / "M.report.json").is_file()
    capsys.readouterr()
    assert main(["merge", *maps, "-o", str(tmp_path / "m.yaml"), "--report", ""]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--report is empty" in err, err
    assert not (tmp_path / "m.yaml").exists()


def test_a_map_the_papers_method_leaves_out_has_confidence_0_with_its_agreement_in_the_reason(tmp_path, capsys):
    """Left out, robot_2 and robot_4 of this run read confidence 0.32 and 0.45 (their best
    alignment's agreement), where every other method gives a map it leaves out 0."""
    assert main(["run", "--robots", "5", "--poses", "200", "--out", str(tmp_path / "r")]) == 3
    # Table 1 keeps the rows that need the maps left out, blank on fusionkit's side (they were
    # dropped, the oracle's with them); a line below the table says so
    printed = capsys.readouterr().out.splitlines()
    last = next(line for line in printed if line.startswith("M1,2,3,4,5 "))
    ours, oracle = last.split("|")[1:3]
    assert not ours.strip() and len(oracle.split()) == 5, last
    assert any(line.endswith("left out by the merge: the oracle fuses them last, and fusionkit's "
                             "cells of rows M1,2,3,4 to M1,2,3,4,5 are blank") or
               line.endswith("left out by the merge: the oracle fuses it last, and fusionkit's "
                             "cells of row M1,2,3,4,5 are blank") for line in printed), printed
    report = json.loads((tmp_path / "r" / "merged.report.json").read_text())
    left = [m for m in report["maps"] if not m["merged"]]
    assert left and all(m["confidence"] == 0.0 for m in left), left
    assert all(re.search(r"best alignment agrees on \d+% of \d+ overlapping wall cells", m["reason"])
               for m in left), left
    # and names the maps it was aligned to: maps merged (the reference is placed here)
    merged = {os.path.splitext(os.path.basename(m["input"]))[0] for m in report["maps"] if m["merged"]}
    for m in left:
        named = re.search(r"with the maps placed before it \(([^)]*)\)$", m["reason"])
        assert named and set(named[1].split(", ")) <= merged, (m, merged)


def test_a_loop_of_symbolic_links_is_one_line_and_exit_2(tmp_path, capsys):
    """pathlib's "RuntimeError: Symlink loop" came out as a 32-line traceback, exit 1."""
    (tmp_path / "a.yaml").symlink_to(tmp_path / "b.yaml")
    (tmp_path / "b.yaml").symlink_to(tmp_path / "a.yaml")
    (tmp_path / "x").symlink_to(tmp_path / "y")
    (tmp_path / "y").symlink_to(tmp_path / "x")
    for argv in (["merge", str(tmp_path / "a.yaml"), str(tmp_path / "b.yaml"), "-o", str(tmp_path / "m.yaml")],
                 ["simulate", "--out", str(tmp_path / "x"), "--robots", "2", "--poses", "100"]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "a loop of symbolic links; check the path" in err, err
        assert re.search(rf"error: {re.escape(str(tmp_path))}/(a\.yaml|x)", err), err


def test_a_world_seed_given_with_a_world_map_is_refused(tmp_path, capsys):
    """--world-seed beside --world was ignored without a word (--world-size was refused)."""
    from pathlib import Path
    world = Path(__file__).resolve().parents[1] / "maps" / "office.yaml"
    assert main(["simulate", "--world", str(world), "--world-seed", "3", "--out", str(tmp_path / "r")]) == 2
    assert capsys.readouterr().err == ("fusionkit simulate: error: --world-seed applies to generated worlds "
                                       "only; leave it out with --world\n")
    assert not (tmp_path / "r").exists()


def test_far_more_workers_than_cores_and_a_lone_scheduler_timeout_are_refused(tmp_path, monkeypatch,
                                                                            capsys):
    """--workers 1000 (a typo for --cases 1000) started 1000 processes on 2 cores, and a SIGTERM
    took minutes to end them; --scheduler-timeout without --scheduler was silently ignored."""
    import os
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    for argv, said in (
            (["bench", "--cases", "1", "--workers", "17", "--backend", "dask", "--out", "b"],
             "--workers 17 would start 17 workers on this machine's 2 cores; give at most 16 (8 a "
             "core), or --scheduler for a cluster"),
            (["bench", "--cases", "1", "--jobs", "40", "--out", "b"], "--workers 40 would start"),
            (["bench", "--cases", "1", "--scheduler-timeout", "5", "--out", "b"],
             "--scheduler-timeout is how long to wait for --scheduler; give both, or neither")):
        assert main(argv) == 2
        captured = capsys.readouterr()
        assert captured.out == "" and captured.err.startswith(f"fusionkit bench: error: {said}"), captured
        assert captured.err.count("\n") == 1 and not (tmp_path / "b").exists()


def test_bench_with_no_folder_says_only_the_error_of_a_bad_option(tmp_path, monkeypatch, capsys):
    """The line on the folders found came first, so the error was the second of two lines."""
    monkeypatch.chdir(tmp_path)
    assert main(["bench", "--cases", "2", "--jobs", "2", "--workers", "3", "--out", "bq"]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err == ("fusionkit bench: error: --jobs and --workers "
                                                   "disagree; give one of them\n")
