"""``fusionkit bench``: cases are reproducible, every method runs on the same cases, the figures
add up, the files are written, and a folder without a usable map is refused clearly."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from fusionkit.bench import (BenchConfig, WorldSpec, find_worlds, make_case, plan_cases, run_bench,
                             summarize, write_outputs)
from fusionkit.bench.report import picture_title
from fusionkit.cli import main
from fusionkit.errors import InputError
from fusionkit.grid import OccupancyGrid
from fusionkit.mapio import save_map
from fusionkit.resample import resample
from fusionkit.worlds import make_world

CAVE = WorldSpec("cave", builtin="cave")
OFFICE = WorldSpec("office", builtin="office")


def _strip(cases):
    """The records without wall times (which vary from run to run)."""
    out = []
    for rec in cases:
        rec = json.loads(json.dumps(rec, default=float))
        rec.pop("build_seconds")
        for m in rec["methods"].values():
            m.pop("seconds")
            m.pop("seconds_per_pair")
        out.append(rec)
    return out


def test_plan_cycles_worlds_modes_and_map_counts():
    cfg = BenchConfig(cases=8, robots=(2, 3), modes=("explore", "crop"))
    specs = plan_cases([CAVE, OFFICE], cfg)
    assert [s.world.name for s in specs] == ["cave", "office"] * 4
    assert [s.mode for s in specs] == ["explore", "explore", "crop", "crop"] * 2
    assert {(s.mode, s.robots) for s in specs} == {(m, k) for m in ("explore", "crop") for k in (2, 3)}
    assert len({s.seed for s in specs}) == 8
    assert plan_cases([CAVE, OFFICE], cfg) == specs


def test_crop_case_truth_puts_every_crop_back_on_the_world():
    cfg = BenchConfig(cases=1, robots=(3,), modes=("crop",), seed=5)
    case = make_case(plan_cases([OFFICE], cfg)[0], cfg)
    assert len(case.grids) == 3 and all(case.linked)
    world = case.world
    for g, t in zip(case.grids, case.truth):
        back = resample(g, t, world).data
        walls = back >= 50
        assert walls.sum() > 100
        # the crop's walls land on the world's walls (nearest-neighbour resampling twice)
        near = np.zeros_like(walls)
        w = world.occupied_mask()
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                near |= np.roll(np.roll(w, dr, 0), dc, 1)
        assert (walls & near).sum() / walls.sum() > 0.97
    for i in range(3):
        assert max(case.overlap[i, j] for j in range(3) if j != i) >= cfg.min_overlap


def test_bench_runs_end_to_end_and_writes_its_files(tmp_path):
    cfg = BenchConfig(methods=("consensus", "map-merge"), modes=("crop", "explore"), cases=2,
                      robots=(3,), poses=400, seed=2)
    result = run_bench([CAVE], cfg, command="fusionkit bench --cases 2")
    assert len(result.cases) == 2
    s = summarize(result)
    for m in cfg.methods:
        t = s["methods"][m]
        assert t["success"] + t["refused"] + t["wrong"] >= t["pairs"] - t["unlinked"]
        assert t["pairs"] + t["unlinked"] == 2 * 2
        assert t["median_seconds_per_pair"] is not None and t["median_seconds_per_pair"] > 0
        for rec in result.cases:
            for e in rec["methods"][m]["maps"]:
                if e["status"] == "success":
                    assert e["rot_err_deg"] < 2 and e["trans_err_cells"] < 3
                elif e["status"] == "wrong":
                    assert e["rot_err_deg"] >= 2 or e["trans_err_cells"] >= 3
    paths = write_outputs(result, tmp_path, s)
    names = {p.name for p in paths}
    assert {"bench.md", "bench.json", "bench_consensus.png", "bench_map-merge.png"} <= names
    for p in paths:
        assert p.stat().st_size > 0
    assert (tmp_path / "bench_consensus.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    doc = json.loads((tmp_path / "bench.json").read_text())
    assert doc["summary"]["methods"]["consensus"]["pairs"] == s["methods"]["consensus"]["pairs"]
    assert len(doc["cases"]) == 2
    md = (tmp_path / "bench.md").read_text()
    assert "| consensus |" in md and "fusionkit bench --cases 2" in md and "By overlap" in md
    # the picture numbers the case and its maps as bench.json does (they were one case index
    # and map numbers counted from 1 side by side)
    show = result.showcase["index"]
    case = doc["cases"][show]
    title = picture_title(result.showcase, "consensus", dict(case["methods"]["consensus"],
                                                              world=case["world"]))
    assert f"case {show} of bench.json ({case['world']}" in title
    assert [int(m) for m in re.findall(r"map (\d+) (?:success|wrong|refused)", title)] == \
        [e["map"] for e in case["methods"]["consensus"]["maps"]] == [1, 2]


def test_results_do_not_depend_on_the_number_of_processes():
    cfg = BenchConfig(methods=("consensus", "map-merge"), modes=("crop",), cases=2, robots=(2,), seed=9)
    one = run_bench([CAVE, OFFICE], cfg, jobs=1)
    two = run_bench([CAVE, OFFICE], cfg, jobs=2)
    assert _strip(one.cases) == _strip(two.cases)


def test_a_folder_without_a_usable_map_is_refused(tmp_path, capsys):
    tiny = OccupancyGrid(np.zeros((20, 20), np.int8), 0.05)
    save_map(tiny, tmp_path / "tiny.yaml")
    (tmp_path / "broken.yaml").write_text("image: missing.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n")
    with pytest.raises(InputError, match="no usable ground-truth map"):
        find_worlds([tmp_path])
    code = main(["bench", str(tmp_path), "--cases", "1", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2
    assert "no usable ground-truth map" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out" / "bench.json").exists()
    with pytest.raises(InputError, match="no such folder"):
        find_worlds([tmp_path / "nowhere"])


def test_a_map_with_few_walls_is_left_out_with_a_hint_at_grey_walls(tmp_path):
    """A real map whose walls are drawn in grey (willow_garage) was said to have "only 544
    occupied cells" without a word of why a map of a whole office has so few."""
    data = np.zeros((200, 200), np.int8)
    data[::40, :] = 100                                   # 1000 wall cells: usable
    save_map(OccupancyGrid(data, 0.05), tmp_path / "ok.yaml")
    data[::40, 100:] = 0                                  # 500: too few
    save_map(OccupancyGrid(data, 0.05), tmp_path / "grey.yaml")
    worlds, skipped = find_worlds([tmp_path])
    assert [w.name for w in worlds] == ["ok"]
    assert skipped == [("grey", "only 500 occupied cells, needs 1000; walls drawn in grey may fall "
                                "short of the map's occupied_thresh")]


def test_bad_settings_are_refused():
    with pytest.raises(InputError, match="unknown method"):
        BenchConfig(methods=("magic",))
    with pytest.raises(InputError):
        BenchConfig(robots=(1,))
    with pytest.raises(InputError):
        BenchConfig(min_overlap=0.9, max_overlap=0.5)
    with pytest.raises(InputError, match="seed must be a whole number >= 0"):
        BenchConfig(seed=-1)
    assert BenchConfig(seed=np.int64(3)).seed == 3


def test_one_name_given_where_a_list_is_taken_is_one_name(tmp_path):
    """BenchConfig(methods="consensus") said "unknown method 'c'", and find_worlds of a folder's
    path "t: no such folder" (after globbing /*.yaml)."""
    cfg = BenchConfig(methods="consensus", modes="crop")
    assert cfg.methods == ("consensus",) and cfg.modes == ("crop",)
    save_map(make_world("cave", 0), tmp_path / "cave.yaml")
    for folder in (str(tmp_path), tmp_path):
        worlds, _ = find_worlds(folder)
        assert [w.name for w in worlds] == ["cave"]
    assert [w.name for w in find_worlds(builtin="office")[0]] == ["office"]


def test_a_negative_seed_is_one_line_and_exit_2(tmp_path, capsys):
    """It was a 25-line traceback from numpy's seeding, exit 1."""
    from fusionkit.cli import main
    with pytest.raises(SystemExit) as exc:   # as argparse ends a command line it refuses
        main(["bench", "--seed", "-1", "--cases", "1", "--out", str(tmp_path / "out")])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--seed: must be between 0 and" in err, err
    assert not (tmp_path / "out").exists()


def test_the_bench_outputs_are_one_set(tmp_path, monkeypatch):
    """bench.md, bench.json and the pictures were written one by one: interrupted, a new
    bench.md stood beside the old bench.json and old pictures."""
    import os

    from fusionkit import _atomic

    first = run_bench([CAVE], BenchConfig(methods=("map-merge", "hough-spectrum"), modes=("crop",),
                                          cases=2, robots=(2,), seed=3))
    second = run_bench([CAVE], BenchConfig(methods=("map-merge",), modes=("crop",), cases=3,
                                           robots=(2,), seed=4))
    write_outputs(first, tmp_path)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    real, calls = os.replace, []

    def interrupted(src, dst):
        calls.append(dst)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(src, dst)

    monkeypatch.setattr(_atomic.os, "replace", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_outputs(second, tmp_path)
    monkeypatch.setattr(_atomic.os, "replace", real)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
    write_outputs(second, tmp_path)                  # whole: the other method's picture goes
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bench.json", "bench.md", "bench_map-merge.png"]
    assert len(json.loads((tmp_path / "bench.json").read_text())["cases"]) == 3


def test_without_folders_it_says_which_maps_it_benches_on(tmp_path, monkeypatch, capsys):
    """Run where there is no ./maps, the same command benched 3 worlds instead of 11, unsaid."""
    from fusionkit.cli import main
    monkeypatch.chdir(tmp_path)
    assert main(["bench", "--cases", "1", "--methods", "map-merge", "--modes", "crop",
                 "--out", str(tmp_path / "out")]) == 0
    said = capsys.readouterr()
    assert "no ./maps or ./maps/real here: the built-in worlds only" in said.out + said.err


def test_worlds_named_with_no_folder_are_benched_alone(tmp_path, monkeypatch, capsys):
    """``fusionkit bench --worlds office`` run beside a ./maps folder drew its cases from every
    map there too (25 worlds from the project's folder), and said so only in passing."""
    import shutil

    (tmp_path / "maps").mkdir()
    for ext in ("yaml", "pgm"):
        shutil.copy(Path(__file__).parents[1] / "maps" / f"cave.{ext}", tmp_path / "maps")
    monkeypatch.chdir(tmp_path)
    assert main(["bench", "--worlds", "office", "--cases", "2", "--methods", "map-merge", "--modes",
                 "crop", "--out", "out", "--quiet"]) == 0
    report = json.loads((tmp_path / "out" / "bench.json").read_text())
    assert [c["world"] for c in report["cases"]] == ["office", "office"]
    assert main(["bench", "--cases", "2", "--methods", "map-merge", "--modes", "crop", "--out",
                 "out2"]) == 0   # no folder and no --worlds: ./maps and the built-in worlds
    assert "no folder given: the maps of ./maps, and the built-in worlds" in capsys.readouterr().out
    report = json.loads((tmp_path / "out2" / "bench.json").read_text())
    assert [c["world"] for c in report["cases"]] == ["cave", "office"]


def test_a_wall_one_cell_wide_stays_in_the_picture_of_a_large_floor():
    """A bench picture is about 560 pixels across; a floor of 1500 cells drawn cell for cell
    there kept one column in three and lost most walls one cell wide. Each block of cells now
    shows its highest label: the wall (5) over free floor (2) and unknown (0)."""
    from fusionkit.bench.report import _PIXELS, _pooled
    img = np.full((1200, 1500), 2, np.int8)
    img[:, :40] = 0
    img[600, 40:] = 5                                 # a wall along a row
    img[:, 777] = 5                                   # and one along a column
    out = _pooled(img, _PIXELS)
    assert max(out.shape) <= _PIXELS and out.shape == (400, 500)
    assert (out == 5).any(axis=1).all()               # the column wall in every row of pixels
    assert (out[200, 14:] == 5).all()                 # the row wall, whole
    assert ((out == 5).sum(axis=1) > 100).sum() == 1  # in one row of pixels
    assert (out[:, :13] == 0).all() and (out[:, 14:] >= 2).all()
    small = img[:300, :400]
    assert _pooled(small, _PIXELS) is small           # a small map is drawn cell for cell


def _map_with_image(folder, name: str, image: str) -> None:
    """A ground-truth map ``NAME.yaml`` of the built-in cave whose image is ``image`` (PNG)."""
    import cv2

    from fusionkit.bench.cases import load_world
    save_map(load_world(CAVE), folder / f"{name}.yaml")
    pgm = folder / f"{name}.pgm"
    cv2.imwrite(str(folder / image), cv2.imread(str(pgm), cv2.IMREAD_UNCHANGED))
    pgm.unlink()
    doc = (folder / f"{name}.yaml").read_text()
    (folder / f"{name}.yaml").write_text(doc.replace(f"{name}.pgm", image))


def test_an_output_that_is_an_input_is_refused_and_an_input_is_never_taken_for_a_stale_picture(
        tmp_path, capsys):
    """With --out the folder of the maps, a map whose image is named bench_consensus.png had it
    replaced by the bench picture, and one named bench_walls.png had it deleted as the picture of
    a method the run did not have; both with exit 0."""
    import hashlib

    def digest(p):
        return hashlib.sha256(p.read_bytes()).hexdigest()

    a = tmp_path / "a"
    a.mkdir()
    _map_with_image(a, "cave", "bench_consensus.png")
    before = digest(a / "bench_consensus.png")
    args = ["--cases", "1", "--modes", "crop", "--robots", "2", "--quiet", "--out"]
    assert main(["bench", str(a), "--methods", "consensus", *args, str(a)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "would overwrite the input" in err[0] and "bench_consensus.png" in err[0], err
    assert digest(a / "bench_consensus.png") == before
    assert sorted(p.name for p in a.iterdir()) == ["bench_consensus.png", "cave.yaml"]

    b = tmp_path / "b"
    b.mkdir()
    _map_with_image(b, "cave", "bench_walls.png")
    before = digest(b / "bench_walls.png")
    assert main(["bench", str(b), "--methods", "map-merge", *args, str(b)]) == 0
    assert digest(b / "bench_walls.png") == before
    assert {"bench.json", "bench.md", "bench_map-merge.png", "bench_walls.png", "cave.yaml"} == \
        {p.name for p in b.iterdir()}



def test_an_output_folder_it_cannot_write_is_refused_before_any_case_runs(tmp_path, monkeypatch, capsys):
    """A read-only --out was found only when the tables were written, after every case had run
    (an hour of work lost on a large bench)."""
    import fusionkit.bench as bench_module
    from fusionkit import _guards
    locked = tmp_path / "locked"
    locked.mkdir()
    real = _guards.os.access
    monkeypatch.setattr(_guards.os, "access",
                        lambda p, mode, **kw: False if Path(p) == locked else real(p, mode, **kw))

    def ran(*a, **k):
        raise AssertionError("a case was run")
    monkeypatch.setattr(bench_module, "run_bench", ran)
    assert main(["bench", "--worlds", "cave", "--cases", "1", "--methods", "map-merge", "--out",
                 str(locked / "b"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is not writable" in err and not (locked / "b").exists()


def test_one_case_on_one_world_is_said_in_the_singular(tmp_path, capsys):
    assert main(["bench", "--worlds", "cave", "--cases", "1", "--methods", "map-merge", "--modes", "crop",
                 "--out", str(tmp_path / "o")]) == 0
    assert "1 case on 1 of 1 world in" in capsys.readouterr().out
    assert "1 case (1 crop) on 1 world (cave)" in (tmp_path / "o" / "bench.md").read_text()


def test_bench_md_names_only_the_worlds_its_cases_were_drawn_on(tmp_path, capsys):
    """With fewer cases than worlds, bench.md said the cases ran "on 2 worlds (cave, office)"
    where the printed line said 1 of 2 and its table by world listed one."""
    assert main(["bench", "--worlds", "cave", "office", "--cases", "1", "--methods", "map-merge",
                 "--modes", "crop", "--out", str(tmp_path / "o")]) == 0
    assert "1 case on 1 of 2 worlds in" in capsys.readouterr().out
    md = (tmp_path / "o" / "bench.md").read_text()
    assert ("1 case (1 crop) on 1 world (cave), 1 more not drawn on (--cases 1 draws on 1 of the 2 "
            "map worlds)") in md


def test_worlds_naming_none_benches_the_folders_alone_and_says_so(tmp_path, monkeypatch, capsys):
    """``--worlds`` with no name said "..., and the built-in worlds" and benched none of them;
    with no ./maps it failed on "(no folder given)"."""
    import shutil
    monkeypatch.chdir(tmp_path)
    assert main(["bench", "--worlds", "--cases", "1", "--out", "o"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--worlds names no world" in err
    (tmp_path / "maps").mkdir()
    for ext in ("yaml", "pgm"):
        shutil.copy(Path(__file__).parents[1] / "maps" / f"cave.{ext}", tmp_path / "maps")
    assert main(["bench", "--worlds", "--cases", "1", "--methods", "map-merge", "--modes", "crop",
                 "--out", "o"]) == 0
    out = capsys.readouterr().out
    assert "no folder given: the maps of ./maps\n" in out
    assert [c["world"] for c in json.loads((tmp_path / "o" / "bench.json").read_text())["cases"]] == ["cave"]
