"""``fusionkit bench --logs``: real laser logs split into sessions as cases of the suite. A log
case holds what ``fusionkit import carmen --split K`` writes, is scored on the log's corrected
poses, runs the same wherever it runs, and bad log arguments get one line and exit 2."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from fusionkit.bench import BenchConfig, WorldSpec, find_logs, make_case, plan_cases, run_bench
from fusionkit.cli import main
from fusionkit.errors import InputError
from fusionkit.io_carmen import import_carmen
from fusionkit.mapio import load_map
from fusionkit.scanlog import load_scans
from fusionkit.transform import Transform2D

REPO = Path(__file__).resolve().parents[1]
LOGS = REPO.parent / "shared" / "logs" / "real"
OREBRO = LOGS / "orebro.gfs.log"
OFFICE = WorldSpec("office", builtin="office")


def test_a_log_case_holds_the_maps_scans_and_truth_the_split_import_writes(tmp_path):
    import_carmen(OREBRO, tmp_path, split=3)
    truth = json.loads((tmp_path / "truth.json").read_text())
    (spec,), _ = find_logs([OREBRO])
    assert spec.name == "orebro"
    case = make_case(plan_cases([spec], BenchConfig(cases=0, robots=(3,)))[0], BenchConfig())
    assert case.spec.mode == "log" and len(case.grids) == 3
    for k, (g, s, t) in enumerate(zip(case.grids, case.scans, case.truth)):
        written = load_map(tmp_path / f"robot_{k + 1}.yaml")
        assert np.array_equal(g.data, written.data) and g.origin == pytest.approx(written.origin)
        assert np.array_equal(s.poses, load_scans(tmp_path / f"robot_{k + 1}.scans.npz").poses)
        true = Transform2D(**truth["robots"][k]["transform"])
        assert t.error_to(true) == pytest.approx((0.0, 0.0), abs=1e-12)
    world = load_map(tmp_path / "world.yaml")
    assert np.array_equal(case.world.data, world.trinary())
    # consecutive sessions share 30 % of their length: each overlaps the one before it
    assert all(case.overlap[k, k + 1] > 0.3 for k in range(2)) and all(case.linked)


def test_every_log_gives_one_case_per_k_after_the_cases_of_the_maps():
    (orebro,), _ = find_logs([OREBRO])
    specs = plan_cases([OFFICE, orebro], BenchConfig(cases=3, robots=(2, 4), modes=("crop",)))
    assert [(s.world.name, s.mode) for s in specs[:3]] == [("office", "crop")] * 3
    assert [(s.world.name, s.mode, s.robots) for s in specs[3:]] == [("orebro", "log", 2),
                                                                    ("orebro", "log", 4)]
    assert [s.index for s in specs] == list(range(5))
    # the map cases are those of a suite without the log, seeds included; a log case's seed
    # is the same whatever the suite holds beside it (its merges are seeded by it)
    assert specs[:3] == plan_cases([OFFICE], BenchConfig(cases=3, robots=(2, 4), modes=("crop",)))
    alone = plan_cases([orebro], BenchConfig(cases=0, robots=(4, 2)))
    assert {(s.robots, s.seed) for s in alone} == {(s.robots, s.seed) for s in specs[3:]}
    assert len({s.seed for s in specs}) == 5


def test_bench_scores_the_sessions_of_a_log_alone_and_the_same_in_worker_processes(tmp_path, capsys):
    out = tmp_path / "b"
    assert main(["bench", "--logs", str(OREBRO), "--cases", "0", "--robots", "2", "3",
                 "--methods", "consensus", "map-merge", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "2 cases on 1 of 1 world in" in text and "no folder given" not in text
    rec = json.loads((out / "bench.json").read_text())
    assert [(c["world"], c["mode"], c["robots"]) for c in rec["cases"]] == [("orebro", "log", 2),
                                                                          ("orebro", "log", 3)]
    consensus = rec["summary"]["methods"]["consensus"]
    assert consensus["pairs"] == 3 and consensus["success"] == 3 and consensus["wrong"] == 0
    assert rec["summary"]["by"]["mode"]["log"]["consensus"]["success"] == 3
    # workers get the log's scans with the cases, not its path (gone here once it was read):
    # the same figures
    shutil.copy(OREBRO, tmp_path / "orebro.gfs.log")
    (spec,), _ = find_logs([tmp_path / "orebro.gfs.log"])
    (tmp_path / "orebro.gfs.log").unlink()
    cfg = BenchConfig(methods=("consensus",), cases=0, robots=(2,))
    strip = [json.dumps({k: v for k, v in c.items() if k != "build_seconds"}
                        | {"methods": {m: {k: v for k, v in r.items() if "seconds" not in k}
                                       for m, r in c["methods"].items()}}, default=float)
             for run in (run_bench([spec], cfg), run_bench([spec], cfg, jobs=2)) for c in run.cases]
    assert strip[0] == strip[1]


def test_a_folder_of_logs_takes_every_log_and_sets_aside_an_unreadable_one(tmp_path):
    shutil.copy(OREBRO, tmp_path / "orebro.gfs.log")
    (tmp_path / "notes.log").write_text("this is not a laser log\n")
    worlds, skipped = find_logs([tmp_path])
    assert [w.name for w in worlds] == ["orebro"]
    assert [n for n, _ in skipped] == ["notes"] and "no FLASER or ROBOTLASER1" in skipped[0][1]
    # a log of a robot that saw nothing: no world to judge a merge on
    lines = OREBRO.read_text().splitlines()
    flaser = [ln for ln in lines if ln.startswith("FLASER")][:40]
    blind = []
    for ln in flaser:
        f = ln.split()
        n = int(f[1])
        blind.append(" ".join([f[0], f[1]] + ["0"] * n + f[2 + n:]))
    (tmp_path / "blind").mkdir()
    (tmp_path / "blind" / "blind.log").write_text("\n".join(blind) + "\n")
    none, why = find_logs([tmp_path / "blind"])
    assert none == [] and why[0][0] == "blind" and "occupied cells" in why[0][1], why
    # named on its own, the same file is bad input
    with pytest.raises(InputError, match="notes.log: no FLASER or ROBOTLASER1"):
        find_logs([tmp_path, tmp_path / "notes.log"])
    # a log given twice (by two paths, or in a folder given too) is one log
    again, _ = find_logs([tmp_path / "orebro.gfs.log", tmp_path,
                          tmp_path / ".." / tmp_path.name / "orebro.gfs.log"])
    assert [w.name for w in again] == ["orebro"]
    # a log named as a world of maps (or as another log) is told apart in the tables
    (tmp_path / "more").mkdir()
    shutil.copy(OREBRO, tmp_path / "more" / "orebro.log")
    two, _ = find_logs([tmp_path, tmp_path / "more"], taken=["office", "orebro"])
    assert [w.name for w in two] == ["orebro (log)", "orebro (log 2)"]


def _bad(tmp: Path, kind: str) -> list:
    if kind == "missing":
        return ["--logs", str(tmp / "nowhere.log")]
    if kind == "empty folder":
        (tmp / "sub").mkdir()
        return ["--logs", str(tmp / "sub")]
    if kind == "not a log":
        (tmp / "bad.log").write_text("this is not a laser log\n")
        return ["--logs", str(tmp / "bad.log")]
    if kind == "one bad of two":
        (tmp / "bad.log").write_text("this is not a laser log\n")
        return ["--logs", str(OREBRO), str(tmp / "bad.log"), "--cases", "0"]
    if kind == "maps after --logs":
        return ["--logs", str(OREBRO), str(REPO / "maps"), "--cases", "1"]
    if kind == "maps with no case":
        return [str(REPO / "maps"), "--logs", str(OREBRO), "--cases", "0"]
    if kind == "fifo":
        os.mkfifo(tmp / "fifo.log")
        return ["--logs", str(tmp / "fifo.log")]
    return ["--cases", "0"]


@pytest.mark.parametrize("kind, says", [
    ("missing", "nowhere.log: no such CARMEN log or folder of logs"),
    ("empty folder", "the folder holds no CARMEN log (*.log)"),
    ("not a log", "bad.log: no FLASER or ROBOTLASER1 records"),
    ("fifo", "fifo.log: is not a regular file"),
    ("one bad of two", "bad.log: no FLASER or ROBOTLASER1 records"),
    ("maps after --logs", "a folder of maps given among --logs; give the folders of maps before"),
    ("maps with no case", "--cases 0 draws no case from the maps"),
    ("no case", "--cases 0 leaves no case to run"),
])
def test_bad_log_arguments_get_one_line_and_exit_2(tmp_path, capsys, kind, says):
    code = main(["bench", *_bad(tmp_path, kind), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and says in err[0], err
    assert not (tmp_path / "out").exists()


def test_a_log_is_never_overwritten_by_the_bench_tables(tmp_path, capsys):
    import shutil

    log = tmp_path / "bench.md"
    shutil.copy(OREBRO, log)
    before = log.read_bytes()
    assert main(["bench", "--logs", str(log), "--cases", "0", "--robots", "2", "--methods",
                 "map-merge", "--quiet", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "would overwrite the input" in err[0], err
    assert log.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["bench.md"]
