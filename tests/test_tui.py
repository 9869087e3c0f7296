"""The terminal UI (``fusionkit tui``), driven by Textual's Pilot on a small simulated run.

One run (3 robots x 600 poses, seeded) is simulated for the whole module; every test starts
the app in the run's parent directory with the run given as ``run``, so that no absolute
temporary path reaches the screen (snapshots stay the same from machine to machine).
"""

from __future__ import annotations

import json
import os
import signal
import time
from pathlib import Path

import numpy as np
import pytest
from textual.widgets import DataTable, Input

from fusionkit.cli import main
from fusionkit.errors import InputError
from fusionkit.grid import OccupancyGrid
from fusionkit.mapio import load_map
from fusionkit.pipeline import MergeConfig
from fusionkit_tui import make_app
from fusionkit_tui.screens.export import ConfirmScreen, ExportScreen
from fusionkit_tui.screens.help import HelpScreen
from fusionkit_tui.screens.main import MainScreen
from fusionkit_tui.widgets.map_picker import MapTree
from fusionkit_tui.widgets.map_preview import (FREE_RANK, OCCUPIED_RANK, STATE_COLOURS, UNKNOWN_RANK,
                                               downsample, preview_strips)

ROBOTS = 3
POSES = 600
SIM_SEED = 2  # robot_2 is not merged with these settings: both outcomes are on screen
FAST = {"iterations": "30"}  # fewer PSO iterations keep the merges short


@pytest.fixture(scope="module")
def run_root(tmp_path_factory):
    """A directory holding ``run/``: a simulated run (robot maps, scans, world, truth.json)."""
    from fusionkit.simulate import SimulationConfig, simulate, write_run
    from fusionkit.worlds import default_world

    root = tmp_path_factory.mktemp("tui")
    write_run(simulate(default_world(), SimulationConfig(robots=ROBOTS, poses=POSES, seed=SIM_SEED)),
              root / "run")
    return root


@pytest.fixture()
def in_root(run_root, monkeypatch):
    monkeypatch.chdir(run_root)
    return run_root


async def until(pilot, condition, timeout: float = 60.0) -> None:
    """Let the app run until ``condition()`` holds (fails after ``timeout`` seconds)."""
    t0 = time.monotonic()
    while not condition():
        assert time.monotonic() - t0 < timeout, "the app did not get there"
        await pilot.pause(0.05)


async def ready(pilot) -> None:
    """The directory tree and the first preview are loaded."""
    await until(pilot, lambda: any(isinstance(s, MainScreen) and s.query(MapTree) for s in pilot.app.screen_stack))
    screen = pilot.app.main
    tree = screen.query_one(MapTree)
    await until(pilot, lambda: len(tree.root.children) > 0)
    if screen.maps.selected:
        await until(pilot, lambda: screen.maps.query_one("#preview").grid is not None)
    await pilot.pause()


async def type_setting(pilot, key: str, text: str) -> None:
    inp = pilot.app.main.query_one(f"#set-{key}", Input)
    inp.focus()
    inp.value = ""
    await pilot.press(*text)
    await pilot.pause()


async def run_merge(pilot, settings=FAST) -> None:
    """Press r with ``settings`` typed in, and wait for the merge worker to finish."""
    app = pilot.app
    screen = app.main
    for k, v in settings.items():
        await type_setting(pilot, k, v)
    await pilot.press("ctrl+r")
    merging = [w for w in app.workers if w.group == "merge"]
    assert merging or screen.result is not None, [n.message for n in app._notifications]
    if merging:  # (an empty list would wait for every worker, the tree's loader too)
        await app.workers.wait_for_complete(merging)
    await until(pilot, lambda: not screen.merging)
    await pilot.pause()


# -- the map picture ------------------------------------------------------------------------------
def _grid(data) -> OccupancyGrid:
    return OccupancyGrid(np.asarray(data, np.int8), 0.1, (0.0, 0.0, 0.0), "t")


def test_preview_at_one_cell_per_pixel_is_the_map_upside_down():
    rng = np.random.default_rng(0)
    data = rng.choice(np.array([-1, 0, 100], np.int8), size=(12, 9))
    rank, _ = downsample(_grid(data), 9, 12)
    expected = np.where(data == 100, OCCUPIED_RANK, np.where(data == 0, FREE_RANK, UNKNOWN_RANK))
    assert np.array_equal(rank, expected[::-1])  # row 0 of the picture is the highest y


def test_preview_keeps_a_thin_wall_when_shrinking():
    data = np.zeros((40, 40), np.int8)
    data[:, 20] = 100  # a one-cell wall
    rank, _ = downsample(_grid(data), 10, 10)
    assert rank.shape == (10, 10)
    assert (rank == OCCUPIED_RANK).sum(axis=1).min() >= 1  # the wall is in every row
    assert (rank == FREE_RANK).sum() > 60


def test_preview_draws_the_three_states_distinctly_with_and_without_colour():
    data = np.array([[100, 0, -1]] * 2, np.int8)  # one column per state, two pixel rows
    colour = preview_strips(_grid(data), 3, 1)[0]
    styles = [seg.style for seg in colour if seg.text.strip()]
    fgs = {seg.style.color.name for seg in colour}
    assert all(s is not None for s in styles)
    assert {STATE_COLOURS[OCCUPIED_RANK], STATE_COLOURS[FREE_RANK], STATE_COLOURS[UNKNOWN_RANK]} <= fgs
    mono = preview_strips(_grid(data), 3, 1, no_color=True)[0]
    assert mono.text == "█░ "
    assert all(seg.style is None or seg.style.color is None for seg in mono)


def test_fused_preview_colours_cells_by_the_map_that_gave_them():
    data = np.array([[100, 100], [0, 0]], np.int8)
    owner = np.array([[0, 1], [0, 1]], np.int16)
    a = preview_strips(_grid(data), 2, 1, owner=owner)[0]
    b = preview_strips(_grid(data), 2, 1)[0]
    colours_a = [seg.style.color.name for seg in a for _ in seg.text]
    assert colours_a[0] != colours_a[1]  # two robots, two colours
    assert [seg.style.color.name for seg in b for _ in seg.text] == [STATE_COLOURS[FREE_RANK]] * 2


def test_a_map_with_a_wide_unknown_margin_is_drawn_by_its_known_cells():
    """A map saved on map_saver's 4000 x 4000 grid drew as a black square with a dot."""
    from fusionkit.worlds import make_world
    from fusionkit_tui.widgets.map_preview import preview_strips
    room = make_world("office", 0, size=(20.0, 16.0))
    padded = OccupancyGrid(np.pad(room.data, 1500, constant_values=-1), room.resolution)
    text = lambda g: ["".join(seg.text for seg in strip) for strip in preview_strips(g, 60, 20,
                                                                                     no_color=True)]
    rows, cols = np.flatnonzero(room.known_mask().any(axis=1)), np.flatnonzero(room.known_mask().any(axis=0))
    known = room.with_data(room.data[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1])
    assert text(padded) == text(known)
    assert sum(ch != " " for line in text(padded) for ch in line) > 500    # the office, not a dot


# -- command line ---------------------------------------------------------------------------------
def test_cli_explains_the_subcommand_and_refuses_a_missing_path(capsys, tmp_path):
    with pytest.raises(SystemExit) as exc:
        main(["tui", "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "DIR or MAP.yaml" in out and "NO_COLOR" in out
    assert main(["tui", str(tmp_path / "nowhere")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no such file or directory" in err[0]


def test_without_a_terminal_it_says_so_and_does_not_start(tmp_path):
    """Started from a script (input not a terminal) with its output in a file, it wrote screens
    into the file and kept a core busy until killed."""
    import subprocess
    import sys
    out = tmp_path / "out.txt"
    with open(out, "w") as f:
        proc = subprocess.run([sys.executable, "-m", "fusionkit.cli", "tui", str(tmp_path)],
                              stdin=subprocess.DEVNULL, stdout=f, stderr=subprocess.PIPE,
                              text=True, timeout=60)
    assert proc.returncode == 2 and out.read_text() == ""
    assert proc.stderr.strip().splitlines() == [
        "fusionkit tui: error: the terminal UI needs a terminal for its input and output; run it "
        "in one (over SSH: ssh -t), not from a pipe or with its output in a file"]


def test_a_run_directory_selects_its_robot_maps_not_the_world(in_root):
    app = make_app(["run"])
    assert [p.name for p in app._selected] == [f"robot_{k}.yaml" for k in range(1, ROBOTS + 1)]
    with pytest.raises(InputError):
        make_app(["run", "run/robot_1.yaml"])


# -- the whole flow -------------------------------------------------------------------------------
async def test_select_run_inspect_export_and_the_export_loads_back(in_root):
    app = make_app(["run"])
    async with app.run_test(size=(100, 32)) as pilot:
        await ready(pilot)
        screen = app.main
        assert len(screen.maps.selected) == ROBOTS

        # unselect robot_3 in the tree and select it again, with the keyboard
        tree = screen.query_one(MapTree)
        tree.focus()
        await until(pilot, lambda: any(n.data.path.name == "robot_3.yaml" for n in tree.root.children))
        line = next(n.line for n in tree.root.children if n.data.path.name == "robot_3.yaml")
        tree.cursor_line = line
        await pilot.press("space")
        assert [p.name for p in screen.maps.selected] == ["robot_1.yaml", "robot_2.yaml"]
        await pilot.press("space")
        assert [p.name for p in screen.maps.selected][-1] == "robot_3.yaml"

        # settings typed in become the merge's settings
        await run_merge(pilot, {"iterations": "30", "particles": "30", "seed": "4"})
        result = screen.result
        assert result is not None
        assert result.config == MergeConfig(method="spectral-pso", seed=4).with_pso(iterations=30, particles=30)
        assert app.main.query_one("TabbedContent").active == "result"

        # the live plot got every PSO iteration of every alignment
        plot = screen.run_panel.plot
        assert plot.series and all(len(xs) == len(ys) > 0 for _, xs, ys in plot.series)
        steps_run = [s for s in result.steps if s.alignment is not None]
        assert {lbl for lbl, _, _ in plot.series if not lbl.endswith("refine")} <= \
            {f"{result.placements[s.new].name} -> {result.placements[s.placed].name}" for s in steps_run}

        # inspect: one row per map with its transform, and the Table 1 metrics (truth.json)
        table = screen.query_one("#placements", DataTable)
        assert table.row_count == ROBOTS
        for p in result.placements:
            row = [str(c) for c in table.get_row_at(p.index)]
            assert row[1] == ("yes" if p.merged else "no")
            if p.merged:
                assert row[3] == f"{p.transform.x:.2f}"
        assert screen.evaluation is not None
        metrics = screen.query_one("#metrics", DataTable)
        assert metrics.display and metrics.row_count == len(result.order)
        assert 0 < screen.evaluation.metrics.completeness <= 100

        # export to a path the operator types; a directory that is not there is refused at once
        out = Path("exported") / "merged.yaml"  # relative to the working directory, as typed
        await pilot.press("e")
        await pilot.pause()
        assert isinstance(app.screen, ExportScreen)
        inp = app.screen.query_one(Input)
        inp.value = ""
        await pilot.press(*str(out), "enter")
        await pilot.pause()
        assert isinstance(app.screen, ExportScreen) and not out.parent.exists()
        assert "does not exist" in str(app.screen.query_one("#export-error").render())
        out.parent.mkdir()
        await pilot.press("enter")
        await pilot.pause()
        assert not isinstance(app.screen, ExportScreen)
        grid = load_map(out)
        assert np.array_equal(grid.data, result.grid.trinary())
        report = json.loads(out.with_name("merged.report.json").read_text())
        assert [m["input"] for m in report["maps"]] == [str(p) for p in screen.maps.selected]
        assert report["output"] == str(out)
        assert out.resolve().parent == (in_root / "exported").resolve()

        # exporting again asks first; "n" keeps the files, "y" replaces them
        stamp = out.stat().st_mtime_ns
        await pilot.press("e")
        await pilot.pause()
        await pilot.press("enter")
        await pilot.pause()
        assert isinstance(app.screen, ConfirmScreen)
        await pilot.press("n")
        await pilot.pause()
        assert out.stat().st_mtime_ns == stamp
        # kept: back to the path (it closed the export, and the keys typed next ran commands)
        assert isinstance(app.screen, ExportScreen)
        assert app.screen.query_one(Input).value == str(out)
        assert "Those files are kept" in str(app.screen.query_one("#export-until-edit").render())
        await pilot.press("escape")
        await pilot.pause()
        assert not isinstance(app.screen, ExportScreen) and out.stat().st_mtime_ns == stamp
        os.utime(out, ns=(stamp - 10**9, stamp - 10**9))
        await pilot.press("e")
        await pilot.pause()
        await pilot.press("enter")
        await pilot.pause()
        await pilot.press("y")
        await pilot.pause()
        assert out.stat().st_mtime_ns != stamp - 10**9
        assert screen.exported is not None and screen.exported.yaml == out

        # an input map is never overwritten: the dialog refuses the path
        await pilot.press("e")
        await pilot.pause()
        app.screen.query_one(Input).value = "run/robot_1.yaml"
        await pilot.press("enter")
        await pilot.pause()
        assert isinstance(app.screen, ExportScreen)
        assert "overwrite the input" in str(app.screen.query_one("#export-error").render())
        await pilot.press("escape")
        await pilot.pause()
        assert not isinstance(app.screen, ExportScreen)
        # and so does the export itself, dialog or not
        before = (in_root / "run" / "robot_1.pgm").read_bytes()
        assert screen.export("run/robot_1.yaml") is None
        await pilot.pause()
        assert (in_root / "run" / "robot_1.pgm").read_bytes() == before
        assert any(n.severity == "error" and "overwrite the input" in n.message
                   for n in app._notifications)
        # a failed export opens the dialog again with the path, so the next keys edit it
        assert isinstance(app.screen, ExportScreen)
        assert app.screen.query_one(Input).value == "run/robot_1.yaml"
        assert "Export failed" in str(app.screen.query_one("#export-until-edit").render())
        # said of that path: another typed, it goes (it stayed beside the new path's own line)
        app.screen.query_one(Input).value = "exported/other.yaml"
        await pilot.pause()
        assert not app.screen.query("#export-until-edit")
        # a folder named like a map is refused in the dialog, not after "will be replaced?"
        (in_root / "exported" / "dir.yaml").mkdir()
        app.screen.query_one(Input).value = "exported/dir.yaml"
        await pilot.press("enter")
        await pilot.pause()
        assert isinstance(app.screen, ExportScreen)
        assert "is an existing folder" in str(app.screen.query_one("#export-error").render())
        (in_root / "exported" / "dir.yaml").rmdir()
        await pilot.press("escape")
        await pilot.pause()
        assert not isinstance(app.screen, ExportScreen)

    # the exported map is what `fusionkit evaluate` reads
    assert main(["evaluate", str(out), "--truth", str(in_root / "run" / "truth.json"), "--json"]) == 0


async def test_export_never_replaces_the_ground_truth_of_the_run(in_root):
    """``fusionkit merge`` refuses an output over the run's world or a robot map of its truth;
    the terminal UI's export once asked "will be replaced?" and wrote over ``world.yaml``."""
    app = make_app(["run/robot_1.yaml", "run/robot_2.yaml"])
    world = (in_root / "run" / "world.pgm").read_bytes()
    robot_3 = (in_root / "run" / "robot_3.pgm").read_bytes()
    async with app.run_test(size=(100, 32)) as pilot:
        await ready(pilot)
        screen = app.main
        await run_merge(pilot)
        for path in ("run/world.yaml", "run/robot_3.yaml"):   # robot_3 is not an input here
            await pilot.press("e")
            await pilot.pause()
            app.screen.query_one(Input).value = path
            await pilot.press("enter")
            await pilot.pause()
            assert isinstance(app.screen, ExportScreen)
            assert "ground truth" in str(app.screen.query_one("#export-error").render())
            await pilot.press("escape")
            await pilot.pause()
            assert screen.export(path) is None                 # the export itself refuses too
            await pilot.pause()
            await pilot.press("escape")
            await pilot.pause()
    assert (in_root / "run" / "world.pgm").read_bytes() == world
    assert (in_root / "run" / "robot_3.pgm").read_bytes() == robot_3
    assert not (in_root / "run" / "world.report.json").exists()


def test_a_run_folder_selects_its_robots_whatever_else_stands_there(in_root, tmp_path):
    """A merge written into a run's folder with its report elsewhere was selected, as the
    reference, beside the robots it was made of."""
    import shutil

    from fusionkit_tui.runner import find_maps

    run = tmp_path / "r4"
    shutil.copytree(in_root / "run", run)
    main(["merge", str(run / "robot_1.yaml"), str(run / "robot_2.yaml"), "-o", str(run / "fused.yaml"),
          "--report", str(tmp_path / "r4.json"), "--quiet", "--method", "hough-spectrum"])
    assert (run / "fused.yaml").is_file()
    assert [p.name for p in find_maps(run)] == [f"robot_{k}.yaml" for k in range(1, ROBOTS + 1)]


def test_a_folder_lists_no_map_a_merge_wrote_there(tmp_path):
    """Maps a merge wrote are not robot maps: the output a report names, whatever the report's
    own name (``merge --report r.json``), and the group maps beside it."""
    from fusionkit_tui.runner import find_maps

    for name in ("robot_a", "robot_b", "cli", "cli.group1", "mine", "mine.group2", "x.group1"):
        (tmp_path / f"{name}.yaml").write_text("image: x.pgm\n")
    (tmp_path / "r.json").write_text(json.dumps({
        "method": "consensus", "maps": [], "output": "somewhere/else/cli.yaml",
        "group_outputs": ["somewhere/else/cli.group1.yaml"]}))
    (tmp_path / "mine.report.json").write_text("{}")
    (tmp_path / "notes.json").write_text("[1, 2]")
    assert [p.name for p in find_maps(tmp_path)] == ["robot_a.yaml", "robot_b.yaml", "x.group1.yaml"]


async def test_a_dimmed_key_says_why_it_does_nothing(in_root):
    """e before any merge, r while one runs: the footer dims them, and pressing one did nothing
    at all (the messages written for these cases could never show)."""
    app = make_app(["run"])
    async with app.run_test(size=(100, 32)) as pilot:
        await ready(pilot)
        screen = app.main

        def said(words):
            return any(words in n.message for n in app._notifications)

        app.set_focus(None)                      # no text field: r and e are commands
        await pilot.press("e")
        await pilot.pause()
        assert not isinstance(app.screen, ExportScreen) and said("nothing to export yet")
        screen.merging = True                    # as while a merge runs (no timing involved)
        await pilot.pause()
        await pilot.press("r")
        await pilot.pause()
        assert said("a merge is running")
        await pilot.press("e")
        await pilot.pause()
        assert said("wait for the merge to finish") and not isinstance(app.screen, ExportScreen)
        screen.merging = False


async def test_cancel_stops_the_merge_and_the_app_stays_usable(in_root):
    app = make_app(["run"])
    async with app.run_test(size=(80, 24)) as pilot:
        await ready(pilot)
        screen = app.main
        # a swarm that would run for seconds, cancelled as soon as it is aligning
        await type_setting(pilot, "iterations", "100000")
        await type_setting(pilot, "particles", "4000")
        await pilot.press("ctrl+r")
        await until(pilot, lambda: screen.run_panel.plot.series and screen.run_panel.plot.series[0][1])
        assert screen.merging
        screen.action_cancel()   # (escape) being cancelled: r is refused meanwhile, and it says so
        left = str(screen.run_panel.query_one("#left").render())
        assert "press r to run again" not in left and "once it has stopped" in left, left
        await until(pilot, lambda: not screen.merging)
        assert "press r to run again" in str(screen.run_panel.query_one("#left").render())
        assert screen.result is None
        assert "cancelled" in str(screen.run_panel.query_one("#detail").render())
        # said on the run panel, not in a toast over the plot's axis
        assert not any("cancelled" in n.message for n in app._notifications)

        # still usable: the next run completes
        await run_merge(pilot, {"particles": "40", **FAST})
        assert screen.result is not None
        assert screen.query_one("#placements", DataTable).row_count == ROBOTS


async def test_no_swarm_iterations_is_said_in_words_not_shown_as_an_empty_chart(in_root):
    """With 0 PSO iterations the paper's method's swarms never report, and the Run tab showed
    an empty chart under its usual title, as if the plot had failed."""
    app = make_app(["run"])
    async with app.run_test(size=(100, 32)) as pilot:
        await ready(pilot)
        screen = app.main
        await run_merge(pilot, {"iterations": "0"})
        assert screen.result is not None and screen.result.config.method == "spectral-pso"
        assert not screen.run_panel.plot.display
        said = str(screen.run_panel.query_one("#no-swarm").render())
        assert "0 PSO iterations" in said and screen.run_panel.query_one("#no-swarm").display
        assert screen.run_panel.plot.series == []     # nor a legend of lines never drawn
        await run_merge(pilot, FAST)                       # and the chart is back with them
        assert screen.run_panel.plot.display and screen.run_panel.plot.series
        assert not screen.run_panel.query_one("#no-swarm").display


async def test_the_consensus_method_runs_from_the_settings(in_root):
    from textual.widgets import Select
    app = make_app(["run"])
    async with app.run_test(size=(100, 32)) as pilot:
        await ready(pilot)
        screen = app.main
        assert screen.query_one("#method", Select).value == "spectral-pso"   # its swarm is shown
        screen.query_one("#method", Select).value = "consensus"
        await pilot.pause()
        # the form says what the method is and dims the settings it does not read (it once
        # still read "default spectral-pso: the paper's DFT + Pearson + PSO", every field alike)
        assert "consensus: the library's default" in str(screen.query_one("#hint-method").render())
        assert screen.query_one("#set-particles").has_class("unused")
        assert screen.query_one("#seeding").has_class("unused")
        assert not screen.query_one("#set-max_false_merge").has_class("unused")
        assert not screen.query_one("#set-seed").has_class("unused")
        await run_merge(pilot, {})
        result = screen.result
        assert result is not None and result.config.method == "consensus"
        assert result.all_merged
        assert "no swarm" in screen.run_panel.plot.note
        # said in words, not over an empty chart that fills the tab
        assert not screen.run_panel.plot.display
        assert "no swarm" in str(screen.run_panel.query_one("#no-swarm").render())
        # its own stages, not the paper's method's (it showed "✓ unique poses  ✓ pairing")
        stages = str(screen.run_panel.query_one("#stages").render())
        assert "place pairs" in stages and "unique poses" not in stages, stages
        assert screen.run_panel.plot.series == []              # no swarm, no legend of pairs
        assert screen.query_one("#placements", DataTable).row_count == ROBOTS


async def test_the_method_and_seeding_help_is_given_in_full_when_focused(in_root):
    """Their one-line hints are cut at the terminal's width; the method's help was given in
    full nowhere."""
    from textual.widgets import Select
    app = make_app(["run"])
    async with app.run_test(size=(80, 24)) as pilot:
        await ready(pilot)
        screen = app.main
        await pilot.press("2")
        screen.query_one("#method", Select).focus()
        await pilot.pause()
        note = str(screen.query_one("#settings-note").render())
        assert "method: default spectral-pso: the paper's DFT" in note and "tab moves into the fields" in note
        await pilot.press("enter")            # its list open: still the method's help
        await pilot.pause()
        assert "method: default spectral-pso" in str(screen.query_one("#settings-note").render())
        await pilot.press("escape")
        await pilot.pause()
        screen.query_one("#method", Select).value = "consensus"
        await pilot.pause()
        assert "method: consensus: the library's default" in str(screen.query_one("#settings-note").render())
        screen.query_one("#seeding").focus()
        await pilot.pause()
        assert "seeding: default on: " in str(screen.query_one("#settings-note").render())


async def test_invalid_settings_block_the_run_with_a_message(in_root):
    app = make_app(["run"])
    async with app.run_test(size=(80, 24)) as pilot:
        await ready(pilot)
        screen = app.main
        await pilot.press("2")
        await type_setting(pilot, "particles", "many")
        inp = screen.query_one("#set-particles", Input)
        assert inp.has_class("-invalid")
        assert "whole number" in str(screen.query_one("#hint-particles").render())
        await pilot.press("ctrl+r")
        await pilot.pause()
        assert not screen.merging and not [w for w in app.workers if w.group == "merge"]
        # said once: ctrl+r while typing gave the run's notice and the field's own as it was left
        said = [n.message for n in app._notifications if n.severity == "error" and "particles" in n.message]
        assert len(said) == 1 and "the merge will not run until it is fixed" in said[0], said
        await type_setting(pilot, "particles", "12")
        assert not inp.has_class("-invalid")
        assert screen.settings.config().pso.particles == 12


async def test_a_broken_map_is_a_notification_not_a_crash(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "maps").mkdir()
    (tmp_path / "maps" / "broken.yaml").write_text("image: missing.pgm\nresolution: 0.05\n")
    app = make_app(["maps"])
    async with app.run_test(size=(80, 24)) as pilot:
        screen = app.main
        await until(pilot, lambda: len(screen.query_one(MapTree).root.children) > 0)
        # listed, marked unreadable with the reason, and never merged
        broken = Path("maps") / "broken.yaml"
        assert screen.maps.selected == [broken] and list(screen.maps.unreadable) == [broken]
        assert any(n.severity == "error" and "broken.yaml" in n.message for n in app._notifications)
        await pilot.press("r")
        await pilot.pause()
        assert not screen.merging
        assert any("at least two readable maps" in n.message for n in app._notifications)
        await pilot.press("question_mark")
        await pilot.pause()
        assert isinstance(app.screen, HelpScreen)
        await pilot.press("escape")
        await pilot.pause()
        assert not isinstance(app.screen, HelpScreen)


async def test_a_map_has_one_name_on_every_tab_beside_an_unreadable_namesake(in_root):
    """With an unreadable other/robot_2.yaml chosen too, the Maps tab said run/robot_2 and the
    Result tab robot_2: the names were made over the readable maps only."""
    from fusionkit_tui.runner import map_labels

    other = in_root / "other"
    other.mkdir(exist_ok=True)
    (other / "robot_2.yaml").write_text("image: missing.pgm\nresolution: 0.05\n")
    try:
        app = make_app(["run/robot_1.yaml", "run/robot_2.yaml", "other/robot_2.yaml"])
        async with app.run_test(size=(100, 32)) as pilot:
            await ready(pilot)
            screen = app.main
            shown = map_labels(screen.maps.selected)
            assert shown[:2] == ["robot_1", "run/robot_2"], shown
            await run_merge(pilot)
            assert screen.result is not None
            assert screen.labels == ["robot_1", "run/robot_2"], screen.labels
            table = screen.query_one("#placements", DataTable)
            assert str(table.get_row_at(1)[0]) == "run/robot_2"
            # the unreadable map is said once, not again at every run
            await run_merge(pilot)
            said = [n for n in app._notifications if "unreadable map" in (n.title or "")]
            assert len(said) == 1, [n.title for n in app._notifications]
    finally:
        (other / "robot_2.yaml").unlink()
        other.rmdir()


async def test_a_highlighted_folder_is_not_shown_beside_the_last_maps_preview(in_root):
    """Its row in the tree kept the preview of the map highlighted before (or its "cannot read
    this map"), as if it were that map's; so did the folder above after u, and at the file
    system's root the folder had no name."""
    app = make_app(["."])
    async with app.run_test(size=(100, 32)) as pilot:
        await ready(pilot)
        maps = app.main.maps
        preview = maps.query_one("#preview")
        tree = app.main.query_one(MapTree)
        tree.focus()
        folder = next(n for n in tree.root.children if n.data is not None and n.data.path.name == "run")
        tree.cursor_line = folder.line
        await pilot.press("enter")            # opens it
        await until(pilot, lambda: any(n.data.path.name == "robot_1.yaml" for n in folder.children))
        tree.cursor_line = next(n.line for n in folder.children if n.data.path.name == "robot_1.yaml")
        await until(pilot, lambda: preview.grid is not None)
        tree.cursor_line = folder.line
        await until(pilot, lambda: preview.grid is None)
        assert "folder" in preview._message
        assert "run/: a folder" in str(maps.query_one("#info").render())
        tree.cursor_line = next(n.line for n in folder.children if n.data.path.name == "robot_1.yaml")
        await until(pilot, lambda: preview.grid is not None)
        await pilot.press("u")                # the cursor goes to the folder above
        await until(pilot, lambda: preview.grid is None)
        assert "folder" in preview._message
        assert f"{Path.cwd().parent.name}/: a folder" in str(maps.query_one("#info").render())
        tree.path = Path("/")
        await until(pilot, lambda: str(tree.root.label) == "/")


# -- snapshots ------------------------------------------------------------------------------------
def _snapshot_ready(tab: str | None = None, merge: bool = False, then: str | None = None):
    async def before(pilot):
        await ready(pilot)
        if merge:
            await run_merge(pilot)
        if tab:
            await pilot.press(tab)
        if then:
            await pilot.press(then)
        await pilot.pause()
        for inp in pilot.app.screen.query(Input):
            inp.cursor_blink = False
        pilot.app.clear_notifications()
        await pilot.pause()
    return before


@pytest.mark.parametrize("size", [(80, 24), (120, 40)], ids=["80x24", "120x40"])
def test_snapshot_maps(in_root, snap_compare, size):
    assert snap_compare(make_app(["run"]), terminal_size=size, run_before=_snapshot_ready())


def test_snapshot_settings(in_root, snap_compare):
    assert snap_compare(make_app(["run"]), terminal_size=(80, 24), run_before=_snapshot_ready("2"))


def test_snapshot_run(in_root, snap_compare):
    assert snap_compare(make_app(["run"]), terminal_size=(80, 24),
                        run_before=_snapshot_ready("3", merge=True))


@pytest.mark.parametrize("size", [(80, 24), (120, 40)], ids=["80x24", "120x40"])
def test_snapshot_result(in_root, snap_compare, size):
    assert snap_compare(make_app(["run"]), terminal_size=size,
                        run_before=_snapshot_ready("4", merge=True))


def test_snapshot_export_dialog(in_root, snap_compare):
    assert snap_compare(make_app(["run"]), terminal_size=(80, 24),
                        run_before=_snapshot_ready("4", merge=True, then="e"))


def test_snapshot_help(in_root, snap_compare):
    assert snap_compare(make_app(["run"]), terminal_size=(80, 24),
                        run_before=_snapshot_ready(then="question_mark"))


# -- keys, names, unreadable maps, earlier results ------------------------------------------------
async def test_from_the_settings_tab_the_number_keys_switch_tabs_and_q_quits(in_root):
    app = make_app(["run"])
    async with app.run_test(size=(80, 24)) as pilot:
        await ready(pilot)
        screen = app.main
        tabs = screen.query_one("TabbedContent")
        theta = screen.query_one("#set-theta", Input)
        before = theta.value
        for key, tab in (("3", "run"), ("4", "result"), ("1", "maps"), ("2", "settings")):
            await pilot.press("2")
            assert tabs.active == "settings" and not isinstance(screen.focused, Input)
            await pilot.press(key)
            assert tabs.active == tab
        assert theta.value == before  # no digit went into a field
        # a field takes text once tabbed into (method first, then theta); r is then a letter
        await pilot.press("tab", "tab")
        assert screen.focused is theta
        assert screen.check_action("run", ()) is False and screen.check_action("quit", ()) is False
        await pilot.press("end", "5", "r")
        assert theta.value == before + "5r" and not screen.merging
        # leaving it checks the value: red, and said
        await pilot.press("escape")
        assert screen.focused is screen.settings
        assert theta.has_class("-invalid")
        assert any(n.severity == "error" and "theta" in n.message for n in app._notifications)
        theta.value = before
        await pilot.pause()
        assert screen.check_action("run", ()) is True
        await pilot.press("q")
        await pilot.pause()
    assert app.return_code == 0 and not app.is_running


async def test_maps_of_two_runs_are_told_apart_by_path_and_scored_by_path(in_root):
    import shutil

    other = Path("copy")
    if not other.exists():
        other.mkdir()
        for f in ("robot_1.yaml", "robot_1.pgm", "robot_1.scans.npz"):
            shutil.copy(Path("run") / f, other / f)
    app = make_app(["run/robot_1.yaml", "run/robot_2.yaml", "copy/robot_1.yaml"])
    async with app.run_test(size=(100, 32)) as pilot:
        await ready(pilot)
        screen = app.main
        table = screen.maps.query_one("#selected", DataTable)
        assert [str(table.get_row_at(k)[1]) for k in range(3)] == ["run/robot_1", "robot_2", "copy/robot_1"]
        await run_merge(pilot)
        result = screen.result
        assert [p.name for p in result.placements] == ["run/robot_1", "robot_2", "copy/robot_1"]
        placements = screen.query_one("#placements", DataTable)
        assert [str(placements.get_row_at(k)[0]) for k in range(3)] == ["run/robot_1", "robot_2", "copy/robot_1"]
        # the copy is not a robot of run/truth.json: no true transform is borrowed for it
        assert screen.evaluation is not None and screen.evaluation.errors[2] is None
        assert screen.evaluation.errors[0] is not None  # the reference is run/truth.json's robot_1


async def test_a_corrupt_map_is_shown_unreadable_and_left_out_of_the_run(in_root):
    bad = Path("corrupt")
    bad.mkdir(exist_ok=True)
    (bad / "robot_9.yaml").write_text((Path("run") / "robot_1.yaml").read_text().replace("robot_1", "robot_9"))
    image = (Path("run") / "robot_1.pgm").read_bytes()
    (bad / "robot_9.pgm").write_bytes(image[: len(image) // 2])  # cut short
    app = make_app(["run/robot_1.yaml", "run/robot_2.yaml", "corrupt/robot_9.yaml"])
    async with app.run_test(size=(80, 24)) as pilot:
        await ready(pilot)
        screen = app.main
        await until(pilot, lambda: screen.maps.unreadable)
        assert list(screen.maps.unreadable) == [bad / "robot_9.yaml"]
        row = [str(c) for c in screen.maps.query_one("#selected", DataTable).get_row_at(2)]
        assert row[0] == "✗" and row[2] == "unreadable"
        assert any(n.severity == "error" and "robot_9" in n.message for n in app._notifications)
        await run_merge(pilot)
        assert screen.result is not None and len(screen.result.placements) == 2
        assert any("left out" in (n.title or "") for n in app._notifications)


async def test_after_a_cancelled_run_export_says_the_result_is_an_earlier_one(in_root):
    app = make_app(["run"])
    async with app.run_test(size=(80, 24)) as pilot:
        await ready(pilot)
        screen = app.main
        await run_merge(pilot)
        first = screen.result
        await pilot.press("e")
        await pilot.pause()
        assert isinstance(app.screen, ExportScreen) and not app.screen.query("#export-note")
        await pilot.press("escape")
        await type_setting(pilot, "iterations", "100000")
        await type_setting(pilot, "particles", "4000")
        await pilot.press("ctrl+r")
        await until(pilot, lambda: screen.run_panel.plot.series and screen.run_panel.plot.series[0][1])
        # meanwhile the Result tab says its result is the earlier one, and whose it is
        heading = str(screen.result_panel.query_one("#fused-heading").render())
        assert "(earlier run)" in heading and "(spectral-pso)" in heading, heading
        assert "a merge is running" in str(screen.result_panel.query_one("#why").render())
        bar = screen.run_panel.query_one("ProgressBar")
        shown = bar.progress
        await pilot.press("escape")
        await until(pilot, lambda: not screen.merging)
        assert bar.progress >= shown  # the bar stays where the run stopped
        stages = str(screen.run_panel.query_one("#stages").render())
        assert "(stopped)" in stages and "▶" not in stages  # no stage is still running
        assert screen.result is first
        await pilot.press("e")
        await pilot.pause()
        assert isinstance(app.screen, ExportScreen)
        note = str(app.screen.query_one("#export-note").render())
        assert "EARLIER" in note and "cancelled" in note


async def test_m_shows_the_fused_map_on_the_whole_screen(in_root):
    from fusionkit_tui.screens.map_view import MapScreen
    from fusionkit_tui.widgets.map_preview import MapPreview
    app = make_app(["run"])
    async with app.run_test(size=(80, 24)) as pilot:
        await ready(pilot)
        screen = app.main
        await run_merge(pilot)
        small = screen.result_panel.query_one("#fused-map", MapPreview).size
        await pilot.press("m")
        await pilot.pause()
        assert isinstance(app.screen, MapScreen)
        big = app.screen.query_one(MapPreview).size
        assert big.width == 80 and big.height >= 20 and big.width * big.height > 3 * small.width * small.height
        await pilot.press("escape")
        await pilot.pause()
        assert not isinstance(app.screen, MapScreen)


def test_the_info_line_of_a_map_says_how_a_map_without_scans_is_placed():
    from fusionkit_tui.widgets.map_picker import format_info
    info = {"name": "r", "cols": 40, "rows": 30, "resolution": 0.1, "width_m": 4.0, "height_m": 3.0}
    assert format_info({**info, "has_scans": True}).endswith("scans: yes")
    line = format_info({**info, "has_scans": False})
    assert "placed by its walls" in line and "spectral-pso casts virtual scans" in line


@pytest.mark.parametrize("method, cells, words", [
    ("spectral-pso", 812, "81% of 812 overlapping wall cells agree with the maps fused before it"),
    ("spectral-pso", 0, "the first map of the fusion order"),
    ("consensus", 3211, "confidence 0.81: the chance that no wrong placement of these maps fits as well"),
    ("map-merge", 0, "confidence 0.81 by the consensus test"),
])
def test_why_a_map_was_merged_is_said_in_the_terms_of_its_method(method, cells, words):
    from types import SimpleNamespace

    from fusionkit_tui.widgets.result_panel import merged_because
    assert words in merged_because(SimpleNamespace(confidence=0.81, overlap_cells=cells), method)


async def test_ctrl_c_quits_with_the_exit_status_of_an_interrupt(in_root):
    app = make_app(["run"])
    async with app.run_test(size=(80, 24)) as pilot:
        await ready(pilot)
        await pilot.press("ctrl+c")
        await pilot.pause()
    assert app.return_code == 130 and not app.is_running


async def test_the_false_merge_risk_of_the_consensus_method_is_a_setting(in_root):
    app = make_app(["run"])
    async with app.run_test(size=(80, 24)) as pilot:
        await ready(pilot)
        form = app.main.settings
        assert form.config().max_false_merge == MergeConfig().max_false_merge
        form.set_value("max_false_merge", "0.001")
        await pilot.pause()
        assert form.config().max_false_merge == 0.001
        form.set_value("max_false_merge", "1")
        await pilot.pause()
        with pytest.raises(InputError, match="merge risk"):
            form.config()


async def test_a_map_removed_from_the_selection_is_no_longer_previewed(in_root):
    app = make_app(["run/robot_1.yaml", "run/robot_2.yaml"])
    async with app.run_test(size=(100, 32)) as pilot:
        await ready(pilot)
        maps = app.main.maps
        table = maps.query_one("#selected", DataTable)
        preview = maps.query_one("#preview")
        table.focus()
        table.move_cursor(row=1)
        await until(pilot, lambda: "robot_2" in maps.previewing_label())
        await pilot.press("x")  # the last row goes: the row now under the cursor is shown
        await until(pilot, lambda: len(maps.selected) == 1)
        await until(pilot, lambda: "robot_1" in maps.previewing_label() and preview.grid is not None)
        info = str(maps.query_one("#info").render())
        assert "robot_1" in info and "robot_2" not in info
        await pilot.press("x")  # none left: nothing is previewed, and the pane says so
        await until(pilot, lambda: not maps.selected)
        await until(pilot, lambda: preview.grid is None)
        assert maps.previewing_label() == ""
        assert "robot_" not in str(maps.query_one("#info").render())


async def test_the_info_line_of_a_map_without_scans_is_shown_whole_at_80_by_24(tmp_path,
                                                                             monkeypatch):
    """At 80 x 24 the line was cut after two lines, mid-parenthesis ("(placed by its walls;")."""
    import shutil
    real = Path(__file__).parent.parent / "maps" / "real"
    for suffix in (".yaml", ".pgm"):
        shutil.copy(real / f"izs_campus_outdoor{suffix}", tmp_path)
    monkeypatch.chdir(tmp_path)
    app = make_app(["izs_campus_outdoor.yaml"])
    async with app.run_test(size=(80, 24)) as pilot:
        await ready(pilot)
        info = app.main.maps.query_one("#info")
        await until(pilot, lambda: "scans: none" in str(info.render()))
        await pilot.pause()
        text = str(info.render())
        assert text.endswith("spectral-pso casts virtual scans)")
        # the widest the text can be: it needs three lines, and has them
        assert len(text) > 2 * info.size.width and info.size.height == 3, (info.size, text)


async def test_a_merge_refused_for_another_robots_scans_says_so_whole_naming_the_file(
        run_root, tmp_path, monkeypatch):
    """The line was cut after 80 columns ("...on the map's kno…") and named the scans
    "scans[1] (of map robot_2)", where the command line names the file."""
    import shutil
    for k in (1, 2):
        for suffix in (".yaml", ".pgm"):
            shutil.copy(run_root / "run" / f"robot_{k}{suffix}", tmp_path)
    shutil.copy(run_root / "run" / "robot_1.scans.npz", tmp_path)
    shutil.copy(run_root / "run" / "robot_3.scans.npz", tmp_path / "robot_2.scans.npz")
    monkeypatch.chdir(tmp_path)
    app = make_app(["robot_1.yaml", "robot_2.yaml"])
    async with app.run_test(size=(80, 24)) as pilot:
        await ready(pilot)
        detail = app.main.run_panel.query_one("#detail")
        await pilot.press("ctrl+r")
        await until(pilot, lambda: "failed:" in str(detail.render()))
        await pilot.pause()
        text = str(detail.render())
        assert text.startswith("failed: robot_2.scans.npz (the scans of robot_2.yaml): "), text
        assert text.endswith("(a map without scans is placed by its walls)"), text
        assert detail.size.height >= 2 and len(text) <= detail.size.height * detail.size.width
        await pilot.press("ctrl+r")   # the next run starts on one line again
        await pilot.pause()
        await until(pilot, lambda: not app.main.merging)


async def test_the_result_tab_before_any_run_says_what_to_do(in_root):
    """Before any run the Result tab showed its headings alone (at 80 x 24 the fused map's own
    words had no room)."""
    app = make_app(["run"])
    async with app.run_test(size=(80, 24)) as pilot:
        await ready(pilot)
        await pilot.press("4")
        await pilot.pause()
        why = app.main.query_one("#why")
        assert "no merge yet" in str(why.render()) and why.size.height >= 1
        await run_merge(pilot)
        assert "no merge yet" not in str(why.render())


_STUCK_MERGE = """
import pathlib, threading, sys
import fusionkit_tui.runner as runner
import fusionkit_tui.screens.main as main_screen

def stuck(*a, **k):  # a merge busy in a kernel for a long time: it never reaches a callback
    pathlib.Path("merging.flag").write_text("yes")
    threading.Event().wait()

runner.run_merge = stuck
main_screen.run_merge = stuck
from fusionkit.cli import main
sys.exit(main(["tui", "run"]))
"""


def test_ctrl_c_ends_the_process_while_a_merge_is_busy(in_root):
    """Textual waits for a thread worker before the process may end; a merge that is busy in a
    kernel for minutes (a large map's preparation) does not look at its cancel flag. Ctrl-C
    ends the process anyway: terminal restored, one line, exit status 130."""
    import pty
    import select
    import subprocess
    import sys

    flag = in_root / "merging.flag"
    flag.unlink(missing_ok=True)
    leader, follower = pty.openpty()
    env = {**os.environ, "TERM": "xterm-256color", "COLUMNS": "100", "LINES": "32"}
    proc = subprocess.Popen([sys.executable, "-c", _STUCK_MERGE], stdin=follower, stdout=follower,
                            stderr=follower, env=env, cwd=in_root, start_new_session=True)
    os.close(follower)
    seen = b""

    def read_for(seconds: float, until=lambda: False) -> None:
        nonlocal seen
        t0 = time.monotonic()
        while time.monotonic() - t0 < seconds and not until():
            r, _, _ = select.select([leader], [], [], 0.1)
            if r:
                try:
                    seen += os.read(leader, 65536)
                except OSError:  # the process is gone and its terminal with it
                    return

    try:
        read_for(60, lambda: b"Result" in seen)       # the UI is up
        read_for(2)
        os.write(leader, b"r")                         # run: the merge starts and is stuck
        read_for(60, flag.exists)
        assert flag.exists(), seen[-2000:]
        read_for(1)
        os.write(leader, b"\x03")                     # Ctrl-C
        read_for(60, lambda: proc.poll() is not None)
        try:
            code = proc.wait(timeout=10)               # its terminal closes as it exits
        except subprocess.TimeoutExpired:
            code = None
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, 9)
            proc.wait()
        os.close(leader)
        flag.unlink(missing_ok=True)
    assert code == 130, seen[-3000:]
    tail = seen.decode(errors="replace").replace("\r", "").strip().splitlines()[-1]
    assert tail.endswith("fusionkit tui: interrupted; no output was left half-written"), tail
    assert b"\x1b[?1049l" in seen                     # the terminal left the UI's screen


@pytest.mark.parametrize("iterations, width", [(8, 60), (3, 100), (200, 100), (40, 200)])
async def test_the_convergence_plot_counts_iterations_in_whole_numbers(iterations, width):
    """Its axis read 0.0, 1.8, 3.5 ... iterations (0.00, 0.50 ... for a swarm of three)."""
    import re

    from textual.app import App

    from fusionkit_tui.widgets.convergence_plot import ConvergencePlot

    class One(App):
        def compose(self):
            yield ConvergencePlot()

    app = One()
    async with app.run_test(size=(width, 20)) as pilot:
        plot = app.query_one(ConvergencePlot)
        plot.start("robot_2 -> robot_1")
        for i in range(iterations):
            plot.add(i, 10.0 / (i + 1))
        await pilot.pause()
        lines = ["".join(seg.text for seg in plot.render_line(y)) for y in range(plot.size.height)]
    axis = next(k for k, line in enumerate(lines) if line.lstrip().startswith("└"))
    labels = lines[axis + 1].split()
    assert len(labels) >= 2 or iterations == 1, lines[axis + 1]
    assert all(re.fullmatch(r"\d+", x) for x in labels), lines[axis + 1]
    assert 0 <= int(labels[0]) and int(labels[-1]) <= iterations - 1


def test_stopped_during_an_export_the_app_does_not_call_an_earlier_export_new(in_root, monkeypatch,
                                                                               capsys, tmp_path):
    """Killed while it wrote its second export (rolled back: the first export's files stand),
    the app said 'terminated after writing ... (its set of outputs is whole and new)', of the
    first."""
    from fusionkit import _atomic, _signals
    from fusionkit import cli
    from fusionkit.pipeline import merge
    from fusionkit_tui.runner import export_result

    maps = sorted(str(p) for p in (in_root / "run").glob("robot_*.yaml"))[:2]
    result = merge([load_map(p) for p in maps], config=MergeConfig(method="map-merge"))
    out = tmp_path / "s.yaml"
    export_result(result, maps, out)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    real = _atomic._write_durable

    def stopped(path, payload):   # SIGTERM while the report is staged
        if ".report.json." in str(path):
            raise _signals.Terminated()
        return real(path, payload)

    monkeypatch.setattr(_atomic, "_write_durable", stopped)
    with pytest.raises(_signals.Terminated) as exc:
        export_result(result, maps, out)
    monkeypatch.setattr(_atomic, "_write_durable", real)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        assert cli._interrupted("fusionkit tui", ["tui"], exc.value) == 143
    finally:
        for s, h in saved.items():
            signal.signal(s, h)
    err = capsys.readouterr().err
    assert err.strip() == "fusionkit tui: terminated; no output was left half-written", err


async def test_the_seeding_box_says_whether_it_is_on_or_off(in_root):
    """It read 'on' either way: only the colour of its mark changed."""
    from textual.widgets import Checkbox
    app = make_app(["run"])
    async with app.run_test(size=(120, 40)) as pilot:
        await ready(pilot)
        await pilot.press("2")
        box = app.main.settings.query_one("#seeding", Checkbox)
        box.focus()
        await pilot.press("space")
        await pilot.pause()
        assert box.value is False and str(box.label) == "off"
        assert app.main.settings.config().alignment.seeded is False
        await pilot.press("space")
        await pilot.pause()
        assert box.value is True and str(box.label) == "on"


@pytest.mark.parametrize("key", ["question_mark", "m", "e"])
async def test_a_dialog_opened_from_the_run_tab_closes_back_to_it(in_root, key):
    """Help, the full-screen map and the export dialog, opened from the Run tab, closed onto
    the Maps tab: an operator watching the swarm lost the plot."""
    from textual.widgets import TabbedContent
    app = make_app(["run"])
    async with app.run_test(size=(120, 40)) as pilot:
        await ready(pilot)
        await run_merge(pilot)
        await pilot.press("3")
        await pilot.pause()
        tabs = app.main.query_one(TabbedContent)
        assert tabs.active == "run"
        await pilot.press(key)
        await pilot.pause()
        assert app.screen is not app.main
        await pilot.press("escape")
        await pilot.pause()
        await pilot.pause()
        assert app.screen is app.main and tabs.active == "run"


async def test_choosing_the_map_under_the_cursor_keeps_it_previewed(in_root):
    """Space on a map in the tree chose it, and the preview (and m) jumped to the first map of
    the selection while the cursor stayed on the one chosen."""
    app = make_app(["run"])
    async with app.run_test(size=(120, 40)) as pilot:
        await ready(pilot)
        maps = app.main.maps
        tree = maps.query_one(MapTree)
        tree.focus()
        await until(pilot, lambda: any(n.data and n.data.path.name == "world.yaml"
                                       for n in tree.root.children))
        node = next(n for n in tree.root.children if n.data and n.data.path.name == "world.yaml")
        tree.move_cursor(node)
        await until(pilot, lambda: "world" in maps.previewing_label())
        await pilot.press("space")
        await until(pilot, lambda: any(p.name == "world.yaml" for p in maps.selected))
        await pilot.pause(0.3)
        assert "world" in maps.previewing_label(), maps.previewing_label()
        maps.query_one("#selected", DataTable).focus()   # into the selection: its row's map
        await until(pilot, lambda: "robot_1" in maps.previewing_label())


def test_a_whole_number_settings_range_is_said_in_full():
    """The seed's range read 'a whole number from 0 to 9.22337e+18'."""
    from fusionkit_tui.widgets.settings_form import SETTINGS
    seed = next(s for s in SETTINGS if s.key == "seed")
    assert seed.allowed() == "a whole number from 0 to 9223372036854775807"
    assert all("e+" not in s.allowed() for s in SETTINGS)


async def test_v_before_any_merge_says_why_it_does_nothing(in_root):
    """v (Colours) on the Result tab before a merge, or without colour, did nothing, silently."""
    app = make_app(["run"])
    async with app.run_test(size=(100, 30)) as pilot:
        await ready(pilot)
        await pilot.press("4")
        await pilot.pause()
        app.main.query_one("#placements", DataTable).focus()
        await pilot.press("v")
        await pilot.pause()
        assert any("no merged map yet" in n.message for n in app._notifications)


@pytest.mark.parametrize("width", [80, 120])
async def test_the_run_legend_shows_whole_entries_and_counts_those_left_out(width):
    """Eight swarms at 80 columns: two lines ending in an entry cut off, two swarms not named
    and nothing said of them; at 120 an entry split across the lines."""
    from textual.app import App

    from fusionkit_tui.widgets.run_panel import RunPanel

    class One(App):
        def compose(self):
            yield RunPanel()

    labels = [f"robot_{a} -> robot_{b}{s}" for a, b in ((2, 1), (3, 1), (1, 2), (5, 3))
              for s in ("", " refine")]
    app = One()
    async with app.run_test(size=(width, 30)) as pilot:
        panel = app.query_one(RunPanel)
        for label in labels:
            panel.plot.start(label, "#55aaff")
        panel._legend()
        await pilot.pause()
        legend = app.query_one("#legend")
        text = str(legend.render())
    lines = text.split("\n")
    assert len(lines) <= 2, lines
    shown = [e.strip() for line in lines for e in line.split("━━") if e.strip()]
    more = 0
    if shown and shown[-1].count("+") and shown[-1].endswith("more"):
        shown[-1], _, tail = shown[-1].rpartition("  +")
        shown = [e for e in shown if e]
        more = int(tail.split()[0])
    assert all(e in labels for e in shown), shown
    assert len(shown) + more == len(labels), (shown, more)
    assert all(len(line) <= width for line in lines)


async def test_a_placing_methods_growing_count_of_pairs_is_followed_and_not_called_the_last():
    """A fleet's count of pairs grows as loops are added (23, then 34): the panel said "pair 23
    of 23; fusion after this" and kept the bar at its highest, near 90 %, for the rest."""
    from textual.app import App
    from textual.widgets import ProgressBar

    from fusionkit_tui.messages import MergeProgress
    from fusionkit_tui.widgets.run_panel import RunPanel

    class One(App):
        def compose(self):
            yield RunPanel()

    app = One()
    async with app.run_test(size=(100, 30)) as pilot:
        panel = app.query_one(RunPanel)
        panel.begin(9, 0, method="consensus")
        bar = app.query_one(ProgressBar)
        panel.update_progress(MergeProgress("align", 22, 23, "robot_1 + robot_9", pair=(0, 8)))
        await pilot.pause()
        left = str(app.query_one("#left").render())
        assert "pair 23 of 23 so far" in left and "fusion after this" not in left, left
        high = bar.progress
        panel.update_progress(MergeProgress("align", 23, 34, "robot_2 + robot_9", pair=(1, 8)))
        await pilot.pause()
        assert bar.progress < high          # the count grew: the bar follows it
        assert "pair 24 of 34 so far; 10 more after this" in str(app.query_one("#left").render())
        later = bar.progress
        panel.update_progress(MergeProgress("align", 24, 34, "robot_3 + robot_9", pair=(2, 8)))
        await pilot.pause()
        assert bar.progress >= later        # and within one count it never goes back


async def test_the_fused_maps_legend_never_cuts_an_entry_in_two(in_root):
    """At 80 columns the Result tab's legend ended a line with robot_4's colour and began the
    next with its name."""
    app = make_app(["run/robot_1.yaml", "run/robot_2.yaml", "run/robot_3.yaml"])
    async with app.run_test(size=(80, 24)) as pilot:
        await ready(pilot)
        await run_merge(pilot)
        screen = app.main
        names = [screen.labels[p.index] for p in screen.result.placements if p.merged]
        assert len(names) >= 2
        for width in (12, 25, 60):
            lines = str(screen.result_panel.legend(width)).split("\n")
            for line in lines:
                assert len(line) <= width, (line, width)
                for entry in filter(None, line.split("  ")):
                    assert entry.startswith("█ ") and entry[2:] in names, (entry, lines)
            assert sum(len(list(filter(None, line.split("  ")))) for line in lines) == len(names)
        # on the tab: packed to the legend's own width
        await pilot.press("4")
        await pilot.pause()
        legend = screen.result_panel.query_one("#legend")
        assert str(legend.render()) == str(screen.result_panel.legend(legend.size.width))


async def test_adding_a_folder_whose_maps_are_chosen_says_so(in_root):
    """It said 'added 0 maps from run'."""
    app = make_app(["run"])
    async with app.run_test(size=(100, 30)) as pilot:
        await ready(pilot)
        maps = app.main.maps
        n = len(maps.selected)
        assert maps.add_directory(in_root / "run") == 0 and len(maps.selected) == n
        await pilot.pause()
        said = [m.message for m in app._notifications]
        assert any(f"the {n} maps of" in m and "selected already" in m for m in said), said


async def test_removing_from_an_empty_selection_says_why_nothing_happens(tmp_path, monkeypatch):
    """x (or f) with no map selected did nothing, silently."""
    monkeypatch.chdir(tmp_path)
    app = make_app([str(tmp_path)])
    async with app.run_test(size=(100, 30)) as pilot:
        await pilot.pause(0.5)
        table = app.main.maps.query_one("#selected", DataTable)
        table.focus()
        await pilot.press("x")
        await pilot.pause()
        assert any("no map is selected" in n.message for n in app._notifications)


async def test_long_map_names_leave_the_metrics_columns_in_view(in_root):
    """With maps of two folders named by their paths, Table 1's eff column was cut off at 120
    columns, behind a horizontal scroll bar."""
    import shutil

    other = Path("a_folder_with_a_long_name")
    if not other.exists():
        other.mkdir()
        for f in ("robot_1.yaml", "robot_1.pgm", "robot_1.scans.npz"):
            shutil.copy(Path("run") / f, other / f)
    app = make_app(["run/robot_1.yaml", "run/robot_2.yaml", f"{other}/robot_1.yaml"])
    async with app.run_test(size=(120, 40)) as pilot:
        await ready(pilot)
        await run_merge(pilot)
        await pilot.press("4")
        await pilot.pause()
        metrics = app.main.result_panel.query_one("#metrics", DataTable)
        assert metrics.row_count >= 1
        assert metrics.virtual_size.width <= metrics.size.width, (metrics.virtual_size,
                                                                  metrics.size)
        labels = [str(metrics.get_row_at(k)[0]) for k in range(metrics.row_count)]
        assert all(x.startswith("+ ") for x in labels[1:]), labels


async def test_a_result_of_other_maps_than_those_chosen_now_is_said_to_be_earlier(in_root):
    """After the reference was changed or a map taken away, the Result tab went on showing the
    merge of the maps chosen before, unsaid, and e exported it as if it were of those now."""
    app = make_app(["run"])
    async with app.run_test(size=(100, 30)) as pilot:
        await ready(pilot)
        screen = app.main
        await run_merge(pilot)
        heading = lambda: str(screen.result_panel.query_one("#fused-heading").render())  # noqa: E731
        assert "(earlier run)" not in heading()
        dropped = screen.maps.selected[-1]
        screen.maps.toggle(dropped)
        await pilot.pause()
        assert "(earlier run)" in heading()
        assert "the maps chosen have changed" in str(screen.result_panel.query_one("#why").render())
        await pilot.press("e")
        await pilot.pause()
        assert isinstance(app.screen, ExportScreen)
        assert "have changed since the merge" in str(app.screen.query_one("#export-note").render())
        await pilot.press("escape")
        await pilot.pause()
        screen.maps.toggle(dropped)   # the same maps again, in the same order: the result is theirs
        await pilot.pause()
        assert "(earlier run)" not in heading()
        await pilot.press("e")
        await pilot.pause()
        assert isinstance(app.screen, ExportScreen) and not app.screen.query("#export-note")


def test_the_metrics_table_gives_names_told_apart_by_folder_the_room_a_wide_screen_has():
    """At 120 columns the Table 1 panel cut ``demo/robot_1`` and ``default/robot_1`` to
    ``…o/robot_1`` and ``…t/robot_1``; at 80 it keeps its 12 columns for the fused map's sake."""
    from fusionkit_tui.widgets.result_panel import metrics_label_width
    names = ["robot_2", "demo/robot_1", "default/robot_1"]
    assert metrics_label_width(names, 80) == 12
    assert metrics_label_width(names, 120) == len("+ default/robot_1")
    assert metrics_label_width(["robot_1", "robot_2"], 200) == 12
    assert metrics_label_width(["a" * 60], 300) == 30


async def test_the_result_is_said_earlier_by_the_readable_maps_chosen_now_and_while_it_ran(in_root):
    """Taking away an unreadable map the merge had left out marked its result "(earlier run)";
    a map taken away while the merge ran did not, though the export then said it had changed."""
    other = in_root / "other"
    other.mkdir(exist_ok=True)
    (other / "broken.yaml").write_text("image: missing.pgm\nresolution: 0.05\n")
    try:
        app = make_app(["run/robot_1.yaml", "run/robot_2.yaml", "run/robot_3.yaml", "other/broken.yaml"])
        async with app.run_test(size=(100, 32)) as pilot:
            await ready(pilot)
            screen = app.main
            heading = lambda: str(screen.result_panel.query_one("#fused-heading").render())  # noqa: E731
            await run_merge(pilot)
            assert len(screen.result.placements) == 3 and "(earlier run)" not in heading()
            screen.maps.toggle(Path("other/broken.yaml"))   # the maps a merge would use are the same
            await pilot.pause()
            assert "(earlier run)" not in heading()
            # a map taken away while the merge runs: the result is of the maps chosen before
            for k, v in FAST.items():
                await type_setting(pilot, k, v)
            screen.action_run()   # and at once, before its result can come back:
            assert screen.merging
            screen.maps.toggle(Path("run/robot_3.yaml"))
            await until(pilot, lambda: not screen.merging)
            await pilot.pause()
            assert len(screen.result.placements) == 3
            assert "(earlier run)" in heading()
            assert "changed since this merge started" in str(screen.result_panel.query_one("#why").render())
    finally:
        (other / "broken.yaml").unlink()


async def test_an_unreadable_maps_whole_reason_is_shown_and_a_folder_says_how_many_are_unreadable(in_root):
    """The reason was cut at two lines, mid-sentence, with what to fix lost; adding a folder
    said "added 3 maps" when one of them could not be read."""
    from fusionkit_tui.widgets.map_preview import MapPreview
    bad = Path("bad")
    bad.mkdir()
    for name in ("robot_1", "robot_2"):
        for suffix in (".yaml", ".pgm"):
            (bad / f"{name}{suffix}").write_bytes((Path("run") / f"{name}{suffix}").read_bytes())
    (bad / "empty.yaml").write_text("")
    app = make_app(["run/robot_1.yaml", "run/robot_2.yaml"])
    async with app.run_test(size=(80, 24)) as pilot:
        await ready(pilot)
        maps = app.main.maps
        assert maps.add_directory(in_root / "bad") == 3
        await pilot.pause()
        said = [n.message for n in app._notifications]
        assert any(m.endswith("from " + str(in_root / "bad") + " (1 unreadable, left out of a merge)")
                   for m in said), said
        path, why = next((p, w) for p, w in maps.unreadable.items() if p.name == "empty.yaml")
        maps._preview(path)
        await pilot.pause()
        preview = maps.query_one("#preview", MapPreview)
        shown = " ".join(" ".join(preview.render_line(y).text.split()) for y in range(preview.size.height))
        assert "".join(why.split()) in "".join(shown.split()), (why, shown)   # wrapped, whole


async def test_an_export_path_through_a_file_says_it_is_a_file(in_root):
    """It said the directory "does not exist; create it", which cannot be done."""
    app = make_app(["run/robot_1.yaml", "run/robot_2.yaml"])
    async with app.run_test(size=(100, 32)) as pilot:
        await ready(pilot)
        await run_merge(pilot)
        await pilot.press("e")
        await pilot.pause()
        app.screen.query_one(Input).value = "run/robot_1.pgm/x.yaml"
        await pilot.press("enter")
        await pilot.pause()
        assert isinstance(app.screen, ExportScreen)
        said = str(app.screen.query_one("#export-error").render())
        assert "run/robot_1.pgm is a file, not a folder" in said, said
