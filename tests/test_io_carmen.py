"""CARMEN logs to fusionkit robot logs: parsing, no-return handling, frames, splits, CLI."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

from fusionkit.errors import InputError
from fusionkit.io_carmen import (CarmenConfig, flaser_geometry, import_carmen, read_carmen,
                                 split_sessions, to_own_frame)
from fusionkit.mapio import load_map
from fusionkit.scanlog import load_scans
from fusionkit.transform import Transform2D, wrap_angle

REAL = Path("/work/shared/logs/real")
INTEL = REAL / "intel.gfs.log"
ACAPULCO = REAL / "acapulco.gfs.log"


def flaser(ranges, pose, stamp, host="pippo"):
    r = " ".join(f"{v:g}" for v in ranges)
    x, y, t = pose
    return f"FLASER {len(ranges)} {r} {x} {y} {t} {x} {y} {t} {stamp} {host} {stamp}"


def robotlaser(ranges, laser_pose, robot_pose, stamp, *, start=-1.5, res=0.02, max_range=8.0,
               remissions=(0.5, 0.25)):
    r = " ".join(f"{v:g}" for v in ranges)
    e = " ".join(f"{v:g}" for v in remissions)
    lx, ly, lt = laser_pose
    rx, ry, rt = robot_pose
    fov = res * (len(ranges) - 1)
    return (f"ROBOTLASER1 0 {start} {fov} {res} {max_range} 0.01 0 {len(ranges)} {r} "
            f"{len(remissions)} {e} {lx} {ly} {lt} {rx} {ry} {rt} 0.1 0.2 0.5 0.3 1.0 "
            f"{stamp} host {stamp}")


def write(tmp_path, lines, name="log.clf") -> Path:
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n")
    return p


# -- parsing -----------------------------------------------------------------------------------------

def test_flaser_180_beams_step_one_degree_from_minus_90(tmp_path):
    r1 = [1.0 + 0.01 * i for i in range(180)]
    r1[5] = r1[7] = 81.83  # the scanner's no-return value, repeated
    lines = ["# a comment", "PARAM robot_width 0.5", "ODOM 0 0 0 0 0 0 0.5 pippo 0.5",
             flaser(r1, (1.0, 2.0, 0.5), 1.0), "NEFF 59.9",
             flaser([2.0] * 179 + [81.83], (1.5, 2.0, 0.6), 2.0),
             "FLASER 180 1.0 2.0 3.0"]  # truncated
    c = read_carmen(write(tmp_path, lines))
    log = c.scans
    assert (log.n_scans, log.n_beams) == (2, 180)
    assert log.angle_min == pytest.approx(-math.pi / 2)
    assert log.angle_increment == pytest.approx(math.radians(1.0))
    assert log.beam_angles[-1] == pytest.approx(math.radians(89.0))
    assert np.isinf(log.ranges[0, [5, 7]]).all() and np.isinf(log.ranges[1, -1])
    assert c.stats.no_return_value == pytest.approx(81.83)
    assert c.stats.no_return_readings == 3
    assert log.range_max == pytest.approx(2.79)  # largest other reading, below the 40 m cap
    assert log.ranges[0, 0] == np.float32(1.0)
    assert dict(c.stats.skipped) == {"NEFF": 1, "ODOM": 1, "PARAM": 1, "comment": 1,
                                     "truncated": 1}
    assert c.stats.records == 7 and c.stats.scans == 2 and c.stats.kind == "FLASER"
    np.testing.assert_allclose(log.poses, [[1.0, 2.0, 0.5], [1.5, 2.0, 0.6]])


def test_flaser_181_beams_span_minus_90_to_plus_90_inclusive(tmp_path):
    lines = [flaser([3.0] * 181, (0, 0, 0), 1.0), flaser([3.0] * 181, (0.1, 0, 0), 2.0)]
    log = read_carmen(write(tmp_path, lines)).scans
    assert log.angle_min == pytest.approx(-math.pi / 2)
    assert log.beam_angles[-1] == pytest.approx(math.pi / 2)
    assert log.angle_increment == pytest.approx(math.radians(1.0))


def test_flaser_general_rule():
    assert flaser_geometry(360) == pytest.approx((-math.pi / 2, math.pi / 360))
    assert flaser_geometry(361) == pytest.approx((-math.pi / 2, math.pi / 360))
    amin, inc = flaser_geometry(91)
    assert amin + 90 * inc == pytest.approx(math.pi / 2)


def test_robotlaser1_uses_its_geometry_laser_pose_and_max_range(tmp_path):
    ranges = [1.0, 2.0, 8.0, 3.0, 9.5, 4.0]
    lines = [robotlaser(ranges, (1.0, 1.0, 0.3), (0.8, 1.0, 0.3), 10.0),
             robotlaser(ranges, (1.2, 1.0, 0.3), (1.0, 1.0, 0.3), 10.1, remissions=()),
             "RAWLASER1 0 -1.5 3.0 0.5 8 0.01 0 2 1 1 0 10.2 host 10.2"]
    c = read_carmen(write(tmp_path, lines))
    log = c.scans
    assert c.stats.kind == "ROBOTLASER1" and log.n_scans == 2 and log.n_beams == 6
    assert log.angle_min == pytest.approx(-1.5) and log.angle_increment == pytest.approx(0.02)
    np.testing.assert_allclose(log.poses[:, 0], [1.0, 1.2])  # laser pose, not robot pose
    assert np.isinf(log.ranges[:, [2, 4]]).all()  # at or beyond max_range 8
    assert c.stats.no_return_value == 8.0
    assert log.range_max == pytest.approx(4.0)
    assert dict(c.stats.skipped) == {"RAWLASER1": 1}


def test_varying_beam_count_keeps_the_dominant_scans(tmp_path):
    lines = [flaser([2.0] * 180, (i * 0.1, 0, 0), i) for i in range(3)]
    lines.insert(1, flaser([2.0] * 361, (9, 9, 0), 0.5))
    c = read_carmen(write(tmp_path, lines))
    assert c.scans.n_scans == 3 and c.scans.n_beams == 180
    assert c.stats.skipped["other_geometry"] == 1
    assert not np.isinf(c.scans.ranges).any()  # the largest value is the only value: a reading


def test_malformed_values_are_counted(tmp_path):
    good = [flaser([2.0, 3.0], (i, 0, 0), i) for i in range(2)]
    lines = good + ["FLASER 2 1.0 abc 0 0 0 0 0 0 1 h 1", "FLASER 2 1.0 -2.0 0 0 0 0 0 0 1 h 1",
                    "FLASER x"]
    c = read_carmen(write(tmp_path, lines))
    assert c.stats.scans == 2
    assert c.stats.skipped["malformed"] == 3


@pytest.mark.parametrize("lines, said", [
    ([], "no FLASER or ROBOTLASER1 records"),
    (["ODOM 0 0 0 0 0 0 1 h 1", "# only comments"], "no FLASER or ROBOTLASER1 records"),
    # laser records that are all unusable are said as such (it said there were none)
    (["FLASER 180 1 2"], r"none of its 1 laser records is usable \(0 malformed.*; 1 truncated\)"),
    ([flaser([2.0, 3.0], (float("nan"), 0, 0), i) for i in range(3)],
     r"none of its 3 laser records is usable \(3 malformed: .*a non-finite pose; 0 truncated\)")])
def test_nothing_usable_is_an_input_error(tmp_path, lines, said):
    p = write(tmp_path, lines)
    with pytest.raises(InputError, match=said):
        read_carmen(p)


def test_poses_far_from_the_origin_are_said_of_the_log(tmp_path):
    p = write(tmp_path, [flaser([2.0, 3.0], (1e308, 0, 0), i) for i in range(3)])
    with pytest.raises(InputError, match=r"/log\.clf: poses lie more than 1e\+09 m from the origin"):
        read_carmen(p)


def test_out_of_order_timestamps_are_sorted_and_counted(tmp_path):
    stamps = [1.0, 3.0, 2.0, 4.0]
    lines = [flaser([1.0 + k, 0.5, 0.6, 0.7], (k, 0, 0), t) for k, t in enumerate(stamps)]
    c = read_carmen(write(tmp_path, lines))
    assert c.stats.out_of_order == 1
    np.testing.assert_array_equal(c.timestamps, [1.0, 2.0, 3.0, 4.0])
    np.testing.assert_allclose(c.scans.poses[:, 0], [0, 2, 1, 3])
    np.testing.assert_allclose(c.scans.ranges[:, 0], [1, 3, 2, 4])


def test_equal_timestamps_keep_file_order(tmp_path):
    lines = [flaser([1.0 + k] * 4, (k, 0, 0), 0) for k in range(5)]
    c = read_carmen(write(tmp_path, lines))
    assert c.stats.out_of_order == 0
    np.testing.assert_allclose(c.scans.poses[:, 0], np.arange(5))


def test_max_range_option_and_single_max_is_a_reading(tmp_path):
    lines = [flaser([1.0, 5.0, 12.0, 50.0], (0, 0, 0), 1), flaser([1.0, 2.0, 3.0, 4.0], (0, 0, 0), 2)]
    p = write(tmp_path, lines)
    c = read_carmen(p)
    assert c.stats.no_return_value is None  # 50 occurs once: a real reading
    assert c.scans.range_max == 40.0 and not np.isinf(c.scans.ranges).any()
    c = read_carmen(p, CarmenConfig(max_range=10.0))
    assert c.scans.range_max == 10.0
    np.testing.assert_array_equal(np.isinf(c.scans.ranges[0]), [False, False, True, True])


@pytest.mark.parametrize("kw", [{"max_range": "10"}, {"max_range": True}, {"max_range": -1.0},
                                {"range_cap": None}, {"range_cap": "40"}, {"range_cap": float("inf")}])
def test_a_carmen_config_of_the_wrong_kind_is_refused_in_one_line(kw):
    (name, value), = kw.items()
    with pytest.raises(InputError, match=rf"^{name} must be a positive number of metres.*, got "):
        CarmenConfig(**kw)
    assert CarmenConfig(max_range=np.float32(10.0), range_cap=30).range_cap == 30


def test_a_log_with_no_reading_left_is_refused_not_imported_as_an_empty_map(tmp_path):
    lines = [flaser([1.0, 5.0, 12.0, 50.0], (0, 0, 0), 1), flaser([1.0, 2.0, 3.0, 4.0], (0, 0, 0), 2)]
    p = write(tmp_path, lines)
    with pytest.raises(InputError, match=r"every reading is at or beyond --max-range 0.5 m "
                                         r"\(the shortest is 1.00 m\)"):
        read_carmen(p, CarmenConfig(max_range=0.5))
    with pytest.raises(InputError, match="every reading"):
        import_carmen(p, tmp_path / "out", config=CarmenConfig(max_range=0.5))
    assert not (tmp_path / "out").exists()
    blind = write(tmp_path, [robotlaser([8.0, 9.0, 8.0], (k, 0, 0), (k, 0, 0), k) for k in range(3)],
                  name="blind.clf")     # a scanner that saw nothing within its 8 m
    with pytest.raises(InputError, match="no reading of the log returned from a wall"):
        read_carmen(blind)


def test_own_frame_and_split_sessions():
    rng = np.random.default_rng(3)
    from fusionkit.scanlog import ScanLog
    poses = np.c_[rng.uniform(-5, 5, (20, 2)), rng.uniform(-3, 3, 20)]
    log = ScanLog(poses, rng.uniform(1, 2, (20, 8)), -1.0, 0.25, 5.0)
    own, t = to_own_frame(log)
    np.testing.assert_allclose(own.poses[0], 0, atol=1e-12)
    back = t.apply_pose(own.poses)
    np.testing.assert_allclose(back[:, :2], poses[:, :2], atol=1e-12)
    np.testing.assert_allclose(wrap_angle(back[:, 2] - poses[:, 2]), 0, atol=1e-12)
    s = split_sessions(910, 3, 0.3)
    assert s[0][0] == 0 and s[-1][1] == 910
    lengths = [b - a for a, b in s]
    assert max(lengths) - min(lengths) <= 1
    shared = s[0][1] - s[1][0]
    assert shared / lengths[0] == pytest.approx(0.3, abs=0.01)
    with pytest.raises(InputError):
        split_sessions(3, 5, 0.3)


# -- the real intel log -------------------------------------------------------------------------------

def _crisp_fraction(grid) -> float:
    occ = grid.occupied_mask()
    nb = ndimage.convolve(occ.astype(int), np.ones((3, 3), int), mode="constant") - occ
    return float((nb[occ] > 0).mean())


def test_orebro_scanner_error_codes_below_the_maximum_are_no_return():
    c = read_carmen(REAL / "orebro.gfs.log")
    s = c.stats
    assert (s.scans, c.scans.n_beams) == (237, 181)
    assert s.no_return_value == pytest.approx(32.767)
    # 32.767 (463 readings), 32.765 (7), 32.763 (465), 32.759 (33): codes, not walls
    assert s.no_return_readings == 463 + 7 + 465 + 33
    r = c.scans.ranges[np.isfinite(c.scans.ranges)]
    assert r.max() == pytest.approx(32.63) and c.scans.range_max == pytest.approx(32.63)


def test_intel_log_imports_with_crisp_walls(tmp_path):
    res = import_carmen(INTEL, tmp_path)
    s = res.stats
    assert (s.records, s.scans, s.kind) == (16361, 910, "FLASER")
    assert dict(s.skipped) == {"NEFF": 910, "ODOM": 14541}
    assert s.no_return_value == pytest.approx(81.83) and s.out_of_order == 4
    log = load_scans(tmp_path / "intel.scans.npz")
    assert log.n_scans == 910 and log.n_beams == 180
    np.testing.assert_allclose(log.poses[0], 0, atol=1e-12)
    assert 20.0 <= log.range_max <= 40.0
    grid = load_map(tmp_path / "intel.yaml")
    assert grid.resolution == 0.05
    occ = grid.counts()["occupied"]
    assert 8_000 <= occ <= 20_000  # about 40 m x 40 m of walls at 5 cm
    assert _crisp_fraction(grid) >= 0.9  # noisy poses (10 cm, 2 deg) give about 0.78


def test_intel_split_in_three_agrees_with_the_full_map(tmp_path):
    res = import_carmen(INTEL, tmp_path, split=3)
    truth = json.loads((tmp_path / "truth.json").read_text())
    assert truth["world"] == "world.yaml"
    assert [r["name"] for r in truth["robots"]] == ["robot_1", "robot_2", "robot_3"]
    world = load_map(tmp_path / truth["world"])
    near = ndimage.binary_dilation(world.occupied_mask(), structure=np.ones((3, 3), bool))
    full = read_carmen(INTEL).scans
    total = 0
    for entry, sess in zip(truth["robots"], truth["sessions"]):
        T = Transform2D.from_dict(entry["transform"])
        log = load_scans(tmp_path / f"{entry['name']}.scans.npz")
        assert entry["poses"] == log.n_scans
        total += log.n_scans
        np.testing.assert_allclose(log.poses[0], 0, atol=1e-12)
        # the transform takes the robot's poses back onto the log's poses
        back = T.apply_pose(log.poses)
        ref = full.poses[sess["first_scan"]:sess["last_scan"] + 1]
        np.testing.assert_allclose(back[:, :2], ref[:, :2], atol=1e-9)
        g = load_map(tmp_path / f"{entry['name']}.yaml")
        rr, cc = world.world_to_cell(T(g.occupied_points()))
        rr, cc = np.floor(rr).astype(int), np.floor(cc).astype(int)
        inside = (rr >= 0) & (rr < world.rows) & (cc >= 0) & (cc < world.cols)
        assert inside.all()
        assert near[rr, cc].mean() >= 0.9
    assert total > 910  # sessions overlap
    assert len(res.files) == 3 * 3 + 3


def test_outputs_are_not_overwritten_without_permission(tmp_path):
    p = write(tmp_path, [flaser([2.0] * 8, (i * 0.1, 0, 0), i) for i in range(4)])
    out = tmp_path / "out"
    import_carmen(p, out, name="a")
    before = (out / "a.scans.npz").read_bytes()
    with pytest.raises(InputError, match=r"already exist.*\(--force; overwrite=True from Python\)"):
        import_carmen(p, out, name="a")
    assert (out / "a.scans.npz").read_bytes() == before
    for kw, said in ((dict(overlap=None), "overlap must be a number"),
                     (dict(resolution="x"), "resolution must be a number"),
                     (dict(split=2.5), r"split \(--split\) must be a whole number")):
        with pytest.raises(InputError, match=said):     # a TypeError from a comparison before
            import_carmen(p, tmp_path / "other", **kw)
    import_carmen(p, out, name="a", overwrite=True)
    # an input is never replaced, even when overwriting is allowed
    src = out / "a.pgm"
    src.write_bytes(p.read_bytes())
    with pytest.raises(InputError, match="overwrite the input"):
        import_carmen(src, out, name="a", overwrite=True)
    assert src.read_bytes() == p.read_bytes()


# -- command line -------------------------------------------------------------------------------------

def _main(argv):
    from fusionkit.cli import main
    return main(argv)


def test_cli_imports_and_reports(tmp_path, capsys):
    p = write(tmp_path, [flaser([2.0] * 180, (i * 0.1, 0, 0), i) for i in range(6)])
    assert _main(["import", "carmen", str(p), "--out", str(tmp_path / "o"), "--split", "2"]) == 0
    out = capsys.readouterr().out
    assert "6 FLASER scans kept" in out
    assert {f.name for f in (tmp_path / "o").iterdir()} >= {
        "robot_1.yaml", "robot_2.scans.npz", "world.yaml", "world.pgm", "truth.json"}
    assert _main(["import", "carmen", str(p), "--out", str(tmp_path / "q"), "--split", "2",
                  "--quiet"]) == 0
    assert capsys.readouterr() == ("", "")
    assert sorted(f.name for f in (tmp_path / "q").iterdir()) == sorted(f.name for f in (tmp_path / "o").iterdir())


def test_a_split_over_an_earlier_run_says_which_of_its_files_it_removed(tmp_path, capsys):
    """--force removed the earlier run's robot_3 and its merge without a word (simulate says so)."""
    p = write(tmp_path, [flaser([2.0] * 180, (i * 0.1, 0, 0), i) for i in range(6)])
    out = tmp_path / "o"
    assert _main(["import", "carmen", str(p), "--out", str(out), "--split", "3"]) == 0
    assert _main(["merge", str(out / "robot_1.yaml"), str(out / "robot_2.yaml"), str(out / "robot_3.yaml"),
                  "-o", str(out / "merged.yaml"), "--quiet"]) in (0, 3)
    capsys.readouterr()
    assert _main(["import", "carmen", str(p), "--out", str(out), "--split", "2", "--force"]) == 0
    said = capsys.readouterr().out.splitlines()[-1]
    assert said.startswith("removed the earlier run's files: ")
    for name in ("robot_3.yaml", "robot_3.pgm", "robot_3.scans.npz", "merged.report.json", "merged.yaml"):
        assert name in said and not (out / name).exists()


@pytest.mark.parametrize("case", ["missing", "empty", "name_with_split", "exists", "overlap"])
def test_cli_bad_input_exits_2_with_one_line(tmp_path, capsys, case):
    good = write(tmp_path, [flaser([2.0] * 8, (i * 0.1, 0, 0), i) for i in range(4)], "good.log")
    out = tmp_path / "o"
    args = {"missing": [str(tmp_path / "nope.log"), "--out", str(out)],
            "empty": [str(write(tmp_path, ["ODOM 1 2 3"], "e.log")), "--out", str(out)],
            "name_with_split": [str(good), "--out", str(out), "--split", "2", "--name", "x"],
            "exists": [str(good), "--out", str(out)],
            "overlap": [str(good), "--out", str(out), "--split", "2", "--overlap", "0.95"]}[case]
    if case == "exists":
        assert _main(["import", "carmen", *args]) == 0
        capsys.readouterr()
    if case == "overlap":  # argparse rejects the value with exit 2 and names the option
        with pytest.raises(SystemExit) as exc:
            _main(["import", "carmen", *args])
        assert exc.value.code == 2
        assert "--overlap" in capsys.readouterr().err.strip().splitlines()[-1]
        assert not out.exists()
        return
    assert _main(["import", "carmen", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("fusionkit import carmen: error: ")


def test_a_split_imported_again_with_force_replaces_the_earlier_sessions_whole(tmp_path):
    """Imported in 4 sessions, merged, then in 2 with --force: robot_3 and robot_4 and the merge
    of the four stayed, merged with the new sessions and scored against the new truth."""
    from fusionkit.cli import main

    out = tmp_path / "re"
    import_carmen(INTEL, out, split=4)
    maps = [str(out / f"robot_{k}.yaml") for k in range(1, 5)]
    assert main(["merge", *maps, "-o", str(out / "merged.yaml"), "--method", "map-merge",
                 "--quiet"]) in (0, 3)
    assert (out / "merged.report.json").is_file()
    notes = out / "notes.txt"                    # not the run's: never removed
    notes.write_text("mine")
    import_carmen(INTEL, out, split=2, overwrite=True)
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted(["notes.txt", "truth.json", "world.yaml", "world.pgm"]
                           + [f"robot_{k}{s}" for k in (1, 2)
                              for s in (".yaml", ".pgm", ".scans.npz")]), names


def test_a_max_range_beyond_the_no_return_value_does_not_draw_it_as_walls(tmp_path):
    """--max-range 90 on the Intel log (a SICK scanner: 81.83 m means no return) turned off the
    detection: 4172 no-return readings became a ring of walls 81.83 m out, the map 3689 x 3661
    cells instead of 773 x 811."""
    c = read_carmen(INTEL, CarmenConfig(max_range=90.0))
    assert c.stats.no_return_value == pytest.approx(81.83)
    assert c.stats.no_return_readings == 4172 and c.scans.range_max == 90.0
    a = import_carmen(INTEL, tmp_path / "a", config=CarmenConfig(max_range=90.0))
    b = import_carmen(INTEL, tmp_path / "b")
    assert a.robots[0].shape == b.robots[0].shape


def test_no_return_readings_under_a_single_stray_maximum_are_found():
    """Acapulco's scanner writes 51.14-51.15 m for no return (12,284 readings) and one reading
    of 51.25 m tops them: none was found."""
    c = read_carmen(ACAPULCO)
    assert c.stats.no_return_value == pytest.approx(51.15)
    assert 12_284 <= c.stats.no_return_readings <= 12_400
    assert not (c.scans.ranges[np.isfinite(c.scans.ranges)] >= 51.1).any()   # 51.1-51.25 m: no return


def test_an_empty_name_is_refused_not_replaced(tmp_path, capsys):
    """--name '' fell back to the log's name, silently."""
    from fusionkit.cli import main
    assert main(["import", "carmen", str(INTEL), "--out", str(tmp_path / "o"), "--name", ""]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "map name ''" in err, err
    assert not (tmp_path / "o").exists()


class _Killed(BaseException):
    """A kill -9 played in the process: nothing after it runs, nothing is rolled back."""


@pytest.mark.parametrize("split", [None, 2])
def test_an_import_killed_mid_commit_into_a_new_folder_can_be_run_again_without_force(
        tmp_path, monkeypatch, split):
    """Killed while it put its files in place, an import left some of them in view; the same
    import run again said they already existed (--force needed) though no import had finished."""
    import os

    from fusionkit import _atomic
    p = write(tmp_path, [flaser([2.0] * 180, (i * 0.1, 0, 0), i) for i in range(6)])
    out = tmp_path / "o"
    real, calls = os.replace, []

    def killed(src, dst):
        calls.append(dst)
        if len(calls) == 3:   # the journal, a first file, then killed
            raise _Killed
        return real(src, dst)

    monkeypatch.setattr(_atomic.os, "replace", killed)
    monkeypatch.setattr(_atomic, "_rollback", lambda entries: False)  # killed: no undo
    with pytest.raises(_Killed):
        import_carmen(p, out, split=split)
    monkeypatch.undo()
    assert any(not f.name.startswith(".") for f in out.iterdir())   # part of it in view
    import_carmen(p, out, split=split)                               # no --force needed
    assert not [f.name for f in out.iterdir() if f.name.startswith(".")]


@pytest.mark.parametrize("split", [2.5, "2", True])
def test_a_split_that_is_not_a_whole_number_is_refused_in_one_line(tmp_path, split):
    """2.5 raised a TypeError deep in the split."""
    p = write(tmp_path, [flaser([1.0, 2.0, 3.0, 4.0], (k, 0, 0), k) for k in range(30)])
    with pytest.raises(InputError, match="whole number >= 1 of sessions"):
        import_carmen(p, tmp_path / "out", split=split)
    assert not (tmp_path / "out").exists()
