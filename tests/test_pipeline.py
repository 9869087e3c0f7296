"""The paper's chain end to end: merge(), `fusionkit merge`, `fusionkit run`, evaluate."""

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from fusionkit.cli import main
from fusionkit.cli.evaluate import evaluate_files
from fusionkit.errors import InputError
from fusionkit.mapio import load_map, save_map
from fusionkit.metrics import evaluate_map
from fusionkit.pipeline import MergeConfig, merge
from fusionkit.scanlog import ScanLog, load_scans, save_scans
from fusionkit.simulate import SimulationConfig, simulate, write_run
from fusionkit.transform import Transform2D
from fusionkit.worlds import default_world, make_world


@pytest.fixture(scope="module")
def sim():
    return simulate(default_world(), SimulationConfig(robots=3, poses=1500, seed=4))


@pytest.fixture(scope="module")
def run_dir(sim, tmp_path_factory):
    d = tmp_path_factory.mktemp("run") / "run"
    write_run(sim, d)
    return d


def _true_relative(sim, k, ref=0):
    return sim.robots[ref].transform.inverse @ sim.robots[k].transform


def test_merge_places_every_robot_within_2_deg_and_3_cells(sim):
    res = merge([r.grid for r in sim.robots], scans=[r.scans for r in sim.robots],
                config=MergeConfig(method="spectral-pso", seed=1))
    assert res.all_merged
    for p in res.placements:
        dt, dr = p.transform.error_to(_true_relative(sim, p.index))
        assert dt < 3 * sim.world.resolution and math.degrees(dr) < 2.0, p
        assert 0.7 <= p.confidence <= 1.0
    # the fused map, put in the world, is as good as the maps allow
    m = evaluate_map(res.grid, sim.world, sim.robots[0].transform)
    assert m.completeness > 60 and m.precision_tol1 > 95
    # diagnostics a notebook draws from
    assert len(res.unique) == 3 and all(u.count >= 150 for u in res.unique)
    assert res.plan.counts.shape == (3, 3)
    assert all(s.alignment is not None and len(s.alignment.pso.history) >= 2 for s in res.steps)
    assert len(res.fused.steps) == 3 and set(res.order) == {0, 1, 2}


def test_merge_is_deterministic_for_a_seed(sim):
    grids, scans = [r.grid for r in sim.robots[:2]], [r.scans for r in sim.robots[:2]]
    a = merge(grids, scans=scans, config=MergeConfig(method="spectral-pso", seed=5))
    b = merge(grids, scans=scans, config=MergeConfig(method="spectral-pso", seed=5))
    assert a.placements[1].transform == b.placements[1].transform
    np.testing.assert_array_equal(a.grid.data, b.grid.data)


def test_callback_sees_each_pso_iteration_and_can_cancel(sim):
    from fusionkit.pipeline import MergeCancelled
    grids, scans = [r.grid for r in sim.robots[:2]], [r.scans for r in sim.robots[:2]]
    seen = []

    def cb(ev):
        seen.append(ev)
        return ev.stage == "align" and ev.pso is not None and ev.pso.iteration >= 3

    with pytest.raises(MergeCancelled):
        merge(grids, scans=scans, config=MergeConfig(method="spectral-pso"), callback=cb)
    stages = [e.stage for e in seen]
    assert stages.index("unique_poses") < stages.index("pairing") < stages.index("align")
    assert seen[-1].pso.iteration == 3


@pytest.mark.parametrize("settings, said", [
    ({"theta": "0.9"}, "theta must be a number"),          # a TypeError deep in a comparison
    ({"accept": float("nan")}, "accept must be a number"),
    ({"unique_count": 1.5}, "unique_count must be a whole number"),   # taken as it was
    ({"reference": True}, "reference must be a whole number"),
])
def test_merge_settings_of_the_wrong_kind_are_refused_in_one_line(settings, said):
    with pytest.raises(InputError, match=said):
        MergeConfig(**settings)


def test_the_report_needs_one_input_name_per_map_and_a_canvas_a_resolution(sim):
    """Too few names raised an IndexError; a resolution of 0 an OverflowError."""
    from fusionkit.resample import canvas_for
    grids = [r.grid for r in sim.robots[:2]]
    result = merge(grids, config=MergeConfig(method="map-merge"))
    with pytest.raises(InputError, match="one input name per map: 1 for 2 maps"):
        result.report(["only_one.yaml"])
    assert [m["input"] for m in result.report(["a.yaml", "b.yaml"])["maps"]] == ["a.yaml", "b.yaml"]
    with pytest.raises(InputError, match="resolution must be a positive number"):
        canvas_for(grids, [Transform2D(), Transform2D()], 0)


@pytest.mark.parametrize("method", ["consensus", "spectral-pso", "map-merge"])
def test_a_grid_with_no_cell_is_refused_with_its_reason_by_every_method(method):
    """The default method crashed in OpenCV (an empty image) on a 0 x 3 grid."""
    from fusionkit.grid import OccupancyGrid
    empty = OccupancyGrid(np.zeros((0, 3), np.int8), 0.1, name="empty")
    result = merge([default_world(), empty], config=MergeConfig(method=method))
    p = result.placements[1]
    assert not p.merged and p.transform is None and "no known cell" in p.reason, p


@pytest.mark.parametrize("with_scans", [True, False])
def test_a_map_without_walls_is_left_out_by_the_papers_method_and_the_rest_merged(sim, with_scans):
    """spectral-pso ended the whole merge with "an empty moving mask" (naming no map) when one
    map had no wall, as a SLAM map has at start-up; every other method left that map out."""
    grids = [r.grid for r in sim.robots]
    grids[1] = grids[1].with_data(np.where(grids[1].data >= 50, 0, grids[1].data))
    res = merge(grids, scans=[r.scans for r in sim.robots] if with_scans else None,
                config=MergeConfig(method="spectral-pso", seed=1))
    gone = res.placements[1]
    assert not gone.merged and gone.reason == "it holds no wall (occupied cell) to place it by"
    assert res.placements[0].merged and res.placements[2].merged


def test_a_map_without_walls_given_first_is_left_out_by_the_papers_method(sim):
    """With the wall-less map first and another map the reference, the paper's order placed the
    wall-less map first and aligned the next to its empty masks: the whole merge ended with "an
    empty mask" instead of that map's own reason."""
    grids = [r.grid for r in sim.robots[:2]]
    grids[0] = grids[0].with_data(np.where(grids[0].data >= 50, 0, grids[0].data))
    res = merge(grids, config=MergeConfig(method="spectral-pso", seed=1, reference=1))
    gone = res.placements[0]
    assert not gone.merged and gone.reason == "it holds no wall (occupied cell) to place it by"
    assert res.placements[1].merged and res.placements[1].transform is not None


def test_maps_of_different_worlds_are_not_merged():
    a = simulate(make_world("office", seed=1), SimulationConfig(robots=1, poses=800, seed=1)).robots[0]
    b = simulate(make_world("cave", seed=2), SimulationConfig(robots=1, poses=800, seed=2)).robots[0]
    res = merge([a.grid, b.grid], scans=[a.scans, b.scans])
    assert res.placements[0].merged and not res.placements[1].merged
    assert res.placements[1].transform is None and res.placements[1].reason


def test_merge_refuses_a_single_map_and_mismatched_scans(sim):
    g = sim.robots[0].grid
    with pytest.raises(InputError, match="at least two"):
        merge([g])
    with pytest.raises(InputError, match="scan logs for"):
        merge([g, g], scans=[sim.robots[0].scans])
    short = sim.robots[1].scans.subset(slice(0, 8))
    # too few scans for one section of Algorithm 1 in the reference (another map is left out)
    with pytest.raises(InputError, match=r"the reference map has only 8 scans.*2\*sub_sec\+1"):
        merge([sim.robots[1].grid, g], scans=[short, sim.robots[0].scans],
              config=MergeConfig(method="spectral-pso"))


def test_scans_of_another_robot_are_refused_naming_them(sim, run_dir, tmp_path, capsys):
    """Another robot's scan log beside a map (or given for it) was used without a word: its end
    points miss the map's walls, and the paper's method placed the map by them."""
    grids, scans = [r.grid for r in sim.robots], [r.scans for r in sim.robots]
    with pytest.raises(InputError, match=r"scans\[1\] \(of map robot_2\): \d+% of its scan end "
                                         r"points .* not this map's scans"):
        merge(grids, scans=[scans[0], scans[2], scans[1]])
    # from files: the scans beside robot_2.yaml are robot_3's
    import shutil
    for k in (1, 2):
        for suffix in (".yaml", ".pgm"):
            shutil.copy(run_dir / f"robot_{k}{suffix}", tmp_path)
    shutil.copy(run_dir / "robot_1.scans.npz", tmp_path)
    shutil.copy(run_dir / "robot_3.scans.npz", tmp_path / "robot_2.scans.npz")
    before = sorted(p.name for p in tmp_path.iterdir())
    code = main(["merge", str(tmp_path / "robot_1.yaml"), str(tmp_path / "robot_2.yaml"),
                 "-o", str(tmp_path / "m.yaml")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    assert f"{tmp_path / 'robot_2.scans.npz'} (the scans of {tmp_path / 'robot_2.yaml'})" in err
    assert "give its own, or none" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == before
    # its own scans are taken
    assert merge(grids, scans=scans, config=MergeConfig(seed=1)).placements[1].merged
    # a map with no known cell gives nothing to judge scans by: it is left out with its reason
    from fusionkit.grid import OccupancyGrid
    blank = OccupancyGrid(np.full_like(grids[1].data, -1), grids[1].resolution, grids[1].origin, "b")
    left = merge([grids[0], blank], scans=scans[:2]).placements[1]
    assert not left.merged and "no known cell" in left.reason, left.reason


def test_cli_merge_writes_the_contract_report_and_evaluate_agrees(run_dir, sim, capsys):
    inputs = [str(run_dir / f"robot_{k}.yaml") for k in (1, 2, 3)]
    out = run_dir / "merged.yaml"
    report = run_dir / "report.json"
    code = main(["merge", *inputs, "-o", str(out), "--report", str(report), "--seed", "2"])
    assert code == 0
    rep = json.loads(report.read_text())
    assert rep["method"] == "consensus" and rep["reference"] == inputs[0]     # the default
    assert rep["output"] == str(out)
    assert [m["input"] for m in rep["maps"]] == inputs
    assert rep["maps"][0]["transform"] == {"x": 0.0, "y": 0.0, "theta": 0.0}
    for m in rep["maps"]:
        assert m["merged"] is True and set(m["transform"]) == {"x", "y", "theta"}
        assert 0.0 <= m["confidence"] <= 1.0
    assert all(len(pair) == 2 for pair in rep["fusion_order"])
    assert rep["seconds"]["total"] > 0
    merged = load_map(out)
    lib = evaluate_map(merged, load_map(run_dir / "world.yaml"), sim.robots[0].transform)
    ev = evaluate_files(out, run_dir / "truth.json", report=report)
    assert ev["metrics"]["completeness"] == pytest.approx(lib.completeness, abs=1e-3)
    assert ev["metrics"]["precision"] == pytest.approx(lib.precision, abs=1e-3)
    capsys.readouterr()
    assert main(["evaluate", str(out), "--truth", str(run_dir / "truth.json"),
                 "--report", str(report), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["metrics"]["accuracy"] == pytest.approx(lib.accuracy, abs=1e-3)


def test_cli_merge_exit_3_when_a_map_does_not_fit(tmp_path, run_dir, capsys):
    other = simulate(make_world("cave", seed=3), SimulationConfig(robots=1, poses=800, seed=3)).robots[0]
    save_map(other.grid, tmp_path / "cave.yaml")
    save_scans(tmp_path / "cave.scans.npz", other.scans)
    out = tmp_path / "m.yaml"
    code = main(["merge", str(run_dir / "robot_1.yaml"), str(tmp_path / "cave.yaml"), "-o", str(out)])
    assert code == 3
    rep = json.loads((tmp_path / "m.report.json").read_text())
    assert rep["maps"][1]["merged"] is False and rep["maps"][1]["transform"] is None
    assert rep["maps"][1]["reason"] and "reason" not in rep["maps"][0]
    assert load_map(out).shape == load_map(run_dir / "robot_1.yaml").shape or out.exists()


def _one_line_error(capsys, code):
    err = capsys.readouterr().err.strip()
    assert code == 2 and "Traceback" not in err and len(err.splitlines()) == 1, err
    return err


def test_cli_merge_bad_inputs_give_one_line_and_write_nothing(tmp_path, run_dir, capsys):
    a, b = str(run_dir / "robot_1.yaml"), str(run_dir / "robot_2.yaml")
    before = (run_dir / "robot_1.pgm").read_bytes()
    err = _one_line_error(capsys, main(["merge", a, b, "-o", a]))
    assert "overwrite" in err and (run_dir / "robot_1.pgm").read_bytes() == before
    err = _one_line_error(capsys, main(["merge", a, str(tmp_path / "nope.yaml"), "-o", str(tmp_path / "m.yaml")]))
    assert "nope.yaml" in err
    err = _one_line_error(capsys, main(["merge", a, "-o", str(tmp_path / "m.yaml")]))
    assert "two maps" in err
    # NaN ranges in a scan log
    bad = tmp_path / "bad"
    bad.mkdir()
    for ext in (".yaml", ".pgm"):
        shutil.copy(run_dir / f"robot_2{ext}", bad / f"robot_2{ext}")
    log = load_scans(run_dir / "robot_2.scans.npz")
    r = log.ranges.copy()
    r[3, 5] = np.nan
    np.savez(bad / "robot_2.scans.npz", poses=log.poses, ranges=r, angle_min=log.angle_min,
             angle_increment=log.angle_increment, range_max=log.range_max)
    err = _one_line_error(capsys, main(["merge", a, str(bad / "robot_2.yaml"), "-o", str(tmp_path / "m.yaml")]))
    assert "NaN" in err and "robot_2.scans.npz" in err
    assert not (tmp_path / "m.yaml").exists() and not (tmp_path / "m.pgm").exists()


def test_maps_without_scans_merge_by_virtual_scans(sim):
    grids = [r.grid for r in sim.robots[:2]]
    res = merge(grids, config=MergeConfig(method="spectral-pso", seed=3))
    assert res.virtual == (True, True)
    p = res.placements[1]
    assert p.merged
    dt, dr = p.transform.error_to(_true_relative(sim, 1))
    assert dt < 3 * sim.world.resolution and math.degrees(dr) < 2.0


def test_a_map_of_another_resolution_is_resampled_to_the_reference(sim):
    from fusionkit.resample import canvas_for, resample
    b = sim.robots[1].grid
    fine = resample(b, Transform2D.identity(), canvas_for([b], [Transform2D.identity()], 0.05))
    res = merge([sim.robots[0].grid, fine], scans=[sim.robots[0].scans, sim.robots[1].scans],
                config=MergeConfig(method="spectral-pso", seed=2))
    assert res.grid.resolution == sim.robots[0].grid.resolution
    p = res.placements[1]
    assert p.merged
    dt, dr = p.transform.error_to(_true_relative(sim, 1))
    assert dt < 3 * sim.world.resolution and math.degrees(dr) < 2.0


def test_a_map_of_another_resolution_with_no_known_cell_is_refused_with_its_reason(sim):
    """Nothing to resample: such a map is refused as one of the reference's cell size is."""
    from fusionkit.grid import OccupancyGrid
    blank = OccupancyGrid(np.full((300, 200), -1, np.int8), 0.05, (1.0, 2.0, 0.0), "blank")
    res = merge([sim.robots[0].grid, blank], config=MergeConfig(method="consensus", seed=2))
    p = res.placements[1]
    assert not p.merged and "no known cell (all unknown)" in p.reason
    assert res.grid.resolution == sim.robots[0].grid.resolution


@pytest.mark.parametrize("method", ["consensus", "spectral-pso", "map-merge", "fourier-mellin",
                                    "hough-spectrum"])
def test_a_map_without_walls_is_left_out_in_the_same_words_by_every_method(sim, method):
    from fusionkit.grid import OccupancyGrid
    free = OccupancyGrid(np.zeros((80, 80), np.int8), sim.robots[0].grid.resolution, (0.0, 0.0, 0.0), "free")
    res = merge([sim.robots[0].grid, free], config=MergeConfig(method=method, seed=2))
    p = res.placements[1]
    assert not p.merged and p.reason == "it holds no wall (occupied cell) to place it by"


def _unscannable(kind, run_dir, d):
    """A third map the paper's method cannot use, written as d/odd.yaml (and its scans)."""
    from fusionkit.grid import OccupancyGrid
    if kind in ("walls only", "tiny free space"):
        data = np.full((60, 80), -1, np.int8)
        if kind == "walls only":
            data[5:55, 10] = data[5:55, 70] = data[5, 10:71] = 100
        else:
            data[10:15, 10:15] = 100
            data[11:14, 11:14] = 0
        save_map(OccupancyGrid(data, 0.1, (0.0, 0.0, 0.0), "odd"), d / "odd.yaml")
        return
    save_map(load_map(run_dir / "robot_3.yaml"), d / "odd.yaml")
    log = load_scans(run_dir / "robot_3.scans.npz")
    if kind == "five scans":
        log = ScanLog(log.poses[:5], log.ranges[:5], log.angle_min, log.angle_increment, log.range_max)
    else:
        log = ScanLog(log.poses, log.ranges[:, ::2], log.angle_min, 2 * log.angle_increment, log.range_max)
    save_scans(d / "odd.scans.npz", log)


@pytest.mark.parametrize("kind, words", [("walls only", "no free cell"),
                                         ("tiny free space", "free space for only"),
                                         ("five scans", "only 5 scans"),
                                         ("other beam count", "180 beams")])
def test_the_papers_method_leaves_out_a_map_it_cannot_scan_and_merges_the_rest(run_dir, tmp_path, capsys,
                                                                              kind, words):
    """A map the paper's method cannot use (nothing to cast a virtual scan from, too few scans
    for one section of Algorithm 1, scans of another beam count) is left out with its reason
    (exit 3), not the whole merge."""
    _unscannable(kind, run_dir, tmp_path)
    out = tmp_path / "m.yaml"
    code = main(["merge", str(run_dir / "robot_1.yaml"), str(run_dir / "robot_2.yaml"),
                 str(tmp_path / "odd.yaml"), "-o", str(out), "--method", "spectral-pso", "--seed", "3"])
    assert code == 3, capsys.readouterr().err
    report = json.loads((tmp_path / "m.report.json").read_text())
    rows = {Path(m["input"]).stem: m for m in report["maps"]}
    assert rows["robot_2"]["merged"]
    assert not rows["odd"]["merged"] and words in rows["odd"]["reason"], rows["odd"]["reason"]


@pytest.mark.parametrize("shape", [(1, 1), (1, 400)])
def test_map_merge_refuses_a_map_one_cell_wide_instead_of_crashing(tmp_path, run_dir, shape):
    """OpenCV's AKAZE fails on a single cell and corrupts its heap on a long single row, which
    kills the process: the merge runs in a child process so that a crash fails this test."""
    import subprocess
    import sys
    from fusionkit.grid import OccupancyGrid
    data = np.zeros(shape, np.int8)
    data[0, ::7] = 100
    save_map(OccupancyGrid(data, 0.1, (0.0, 0.0, 0.0)), tmp_path / "thin.yaml")
    out = tmp_path / "m.yaml"
    done = subprocess.run([sys.executable, "-c", "import sys; from fusionkit.cli import main; "
                           "sys.exit(main(sys.argv[1:]))", "merge", str(run_dir / "robot_1.yaml"),
                           str(tmp_path / "thin.yaml"), "-o", str(out), "--method", "map-merge"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 3, done.stderr[-2000:]
    assert "Traceback" not in done.stderr
    assert json.loads(out.with_name("m.report.json").read_text())["maps"][1]["merged"] is False


def test_virtual_scans_see_the_map_walls_and_unknown_as_returns():
    from fusionkit.grid import OccupancyGrid
    from fusionkit.virtual_scans import virtual_scans
    d = np.full((40, 60), -1, np.int8)
    d[5:35, 5:55] = 0
    d[5, 5:55] = d[34, 5:55] = d[5:35, 5] = 100          # three walls; the east side is unexplored
    g = OccupancyGrid(d, 0.1, (2.0, -1.0, 0.5))
    log = virtual_scans(g, n_poses=50, range_max=20.0, seed=1)
    assert log.n_scans == 50 and log.n_beams == 360
    # every beam ends on a wall or at the edge of the known area: nothing escapes the map
    assert np.isfinite(log.ranges).all()
    # a range ends on the face of the cell that returned it: step a quarter cell into it
    ends = ScanLog(log.poses, log.ranges + 0.025, log.angle_min, log.angle_increment,
                   30.0).endpoints()
    r, c = g.world_to_cell(ends)
    r, c = np.floor(r).astype(int), np.floor(c).astype(int)
    inside = (r >= 0) & (r < 40) & (c >= 0) & (c < 60)
    assert inside.mean() > 0.99
    assert (d[r[inside], c[inside]] != 0).mean() > 0.95


def test_paper_method_never_claims_a_map_the_fused_map_lacks():
    # Two runs of the office: the paper's plan first aligns the other run's map onto robot 2,
    # which fails; robot 1 is then aligned onto robot 2 itself. Every map reported merged must
    # be in the fused map, and each fusion step must start from a placed map.
    a = simulate(default_world(), SimulationConfig(robots=3, poses=800, seed=1))
    b = simulate(default_world(), SimulationConfig(robots=3, poses=800, seed=7))
    grids = [a.robots[0].grid, a.robots[1].grid, b.robots[0].grid]
    scans = [a.robots[0].scans, a.robots[1].scans, b.robots[0].scans]
    res = merge(grids, scans=scans, config=MergeConfig(method="spectral-pso"))
    merged = {p.index for p in res.placements if p.merged}
    assert merged == set(res.fused.order) == set(res.order)
    assert {0, 1} <= merged
    for anchor, new in res.fusion_order:
        assert anchor in merged and new in merged


def test_wrong_kinds_of_merge_arguments_are_one_clear_error(sim):
    """A dict as config, a path string as a scan log, a number as callback ended in an
    AttributeError or TypeError deep in the method; one path was split into characters ("/: the
    same map file is given twice"); the same grid object twice was merged onto itself."""
    a, b = sim.robots[0].grid, sim.robots[1].grid
    for args, kw, said in ((("robot_1.yaml",), {}, "a list of two or more maps"),
                           (([a, b],), dict(config={"method": "consensus"}), r"config must be a MergeConfig"),
                           (([a, b],), dict(scans=["a.scans.npz", None]), r"scans\[0\] is a str"),
                           (([a, b],), dict(callback=5), "callback must be callable"),
                           (([a, a],), {}, "map 2 is the same OccupancyGrid object")):
        with pytest.raises(InputError, match=said):
            merge(*args, **kw)


def test_settings_take_numpy_numbers_and_refuse_wrong_kinds():
    """np.float32(0.9) was refused as "not a number"; refine="no" counted as True; a dict as
    alignment failed later in the merge; a misspelt PSO setting raised a TypeError."""
    c = MergeConfig(theta=np.float32(0.5), max_false_merge=np.float64(0.02))
    assert isinstance(c.theta, float) and c.max_false_merge == 0.02
    for kw, said in ((dict(refine="no"), "refine must be True or False"),
                     (dict(alignment={}), r"alignment must be an AlignmentConfig"),
                     (dict(consensus={}), r"consensus must be a ConsensusConfig"),
                     (dict(reference=-1), "reference is the index of a map")):
        with pytest.raises(InputError, match=said):
            MergeConfig(**kw)
    with pytest.raises(InputError, match=r"with_pso takes PSO settings \(particles, .*got particle"):
        MergeConfig().with_pso(particle=40)


def test_the_report_gives_the_paths_merge_was_given_and_can_be_written_as_json(run_dir):
    """It gave the maps' stems, and kept Path objects json could not write."""
    paths = [run_dir / "robot_1.yaml", run_dir / "robot_2.yaml"]
    report = merge(paths).report(output=Path("out.yaml"))
    assert [m["input"] for m in report["maps"]] == [str(p) for p in paths]
    assert report["output"] == "out.yaml" and json.loads(json.dumps(report)) == report
    with pytest.raises(InputError, match="one name or path per map"):
        merge(paths).report(inputs="ab")


def test_maps_read_from_files_of_one_name_in_two_folders_get_names_that_tell_them_apart(tmp_path):
    """Two runs' robot_2.yaml were both named "robot_2": a dict of placements by name lost one."""
    for k, (folder, name) in enumerate((("a", "robot_1"), ("a", "robot_2"), ("b", "robot_2"))):
        (tmp_path / folder).mkdir(exist_ok=True)
        save_map(make_world("cave", k, size=(20.0, 16.0)), tmp_path / folder / f"{name}.yaml")
    paths = [tmp_path / "a" / "robot_1.yaml", tmp_path / "a" / "robot_2.yaml",
             tmp_path / "b" / "robot_2.yaml"]
    result = merge(paths, config=MergeConfig(method="map-merge"))
    assert [p.name for p in result.placements] == ["robot_1", "a/robot_2", "b/robot_2"]
    assert [p.name for p in merge(paths[:2], config=MergeConfig(method="map-merge")).placements] == \
        ["robot_1", "robot_2"]
