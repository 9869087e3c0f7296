"""Crash safety of every output: a write interrupted at each step leaves one whole set.

The writes are interrupted the ways they fail in the field: an exception or a signal at each
rename (in process), ``kill -9`` at each rename (a child process), SIGTERM and SIGINT to the
command line, and two writers on one output. After each, every file set left behind must be
whole and of one write: the old one or the new one, never a mix, never a temporary file.
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from fusionkit import _atomic, _signals
from fusionkit.errors import InputError
from fusionkit.grid import OccupancyGrid
from fusionkit.mapio import load_map, save_map, save_maps

ROOT = Path(__file__).resolve().parents[1]


def _grid(seed: int, shape=(7, 9), res=0.05) -> OccupancyGrid:
    rng = np.random.default_rng(seed)
    data = rng.choice(np.array([-1, 0, 100], np.int8), size=shape)
    return OccupancyGrid(data, res, (float(seed), -float(seed), 0.1 * seed))


OLD = {"merged": _grid(1), "merged.group1": _grid(2, (5, 4), 0.1)}
NEW = {"merged": _grid(3, (11, 6), 0.2), "merged.group1": _grid(4, (3, 8))}


def _write(out: Path, grids: dict, tag: str, by: str = "", **kw) -> None:
    maps = [(g, out / f"{name}.yaml") for name, g in grids.items()]
    save_maps(maps, (out / "merged.report.json", json.dumps({"write": tag, "by": by}) + "\n"), **kw)


def _same(a: OccupancyGrid, b: OccupancyGrid) -> bool:
    return (a.data.shape == b.data.shape and (a.trinary() == b.trinary()).all()
            and a.resolution == b.resolution and a.origin == b.origin)


def _state(out: Path) -> str:
    """``"old"``, ``"new"`` or ``"none"`` for a consistent folder; fails on anything else.

    Consistent: no temporary, backup or journal file; every map present loads and is one
    write's map; with the report present, every map of that write is present and of it.
    """
    leftovers = [p.name for p in out.iterdir() if p.name.startswith(".")]
    assert not leftovers, f"left behind: {leftovers}"
    report = out / "merged.report.json"
    tags = set()
    for name in OLD:
        if (out / f"{name}.yaml").exists():
            g = load_map(out / f"{name}.yaml")
            tag = "old" if _same(g, OLD[name]) else "new" if _same(g, NEW[name]) else None
            assert tag, f"{name}.yaml loads as neither write's map"
            tags.add(tag)
    if report.exists():
        tag = json.loads(report.read_text())["write"]
        assert tags == {tag}, f"report of the {tag} write beside maps of {tags}"
        assert all((out / f"{n}.yaml").exists() for n in OLD), "the report names a missing map"
        return tag
    # No report: a write is unfinished (killed); the maps a reader finds are all of one write.
    assert len(tags) <= 1, f"maps of two writes together: {tags}"
    return "unfinished"


# -- in process: an exception or a signal at each rename ----------------------------------------
def _count_replaces(tmp_path) -> int:
    calls = []
    real = os.replace

    def counting(src, dst):
        calls.append(dst)
        return real(src, dst)

    out = tmp_path / "count"
    out.mkdir()
    _write(out, OLD, "old")
    _atomic.os.replace = counting
    try:
        _write(out, NEW, "new")
    finally:
        _atomic.os.replace = real
    return len(calls)


@pytest.mark.parametrize("fault", [OSError(28, "No space left on device"), KeyboardInterrupt(),
                                   _signals.Terminated()], ids=["disk full", "SIGINT", "SIGTERM"])
def test_a_write_failing_at_any_rename_leaves_the_old_set_whole(tmp_path, monkeypatch, fault):
    n = _count_replaces(tmp_path)
    assert n >= 6  # journal, backups, images, YAMLs, report: the steps under test
    real = os.replace
    for k in range(n):
        out = tmp_path / f"at{k}"
        out.mkdir()
        _write(out, OLD, "old")
        before = {p.name: p.read_bytes() for p in out.iterdir()}
        calls = []

        def failing(src, dst):
            calls.append(dst)
            if len(calls) == k + 1:
                raise fault
            return real(src, dst)

        monkeypatch.setattr(_atomic.os, "replace", failing)
        with pytest.raises((InputError, KeyboardInterrupt)):
            _write(out, NEW, "new")
        monkeypatch.setattr(_atomic.os, "replace", real)
        assert {p.name: p.read_bytes() for p in out.iterdir()} == before, f"rename {k + 1}"
        _write(out, NEW, "new")  # the next write succeeds and leaves only its own set
        assert _state(out) == "new"


def test_an_output_that_is_a_dangling_symbolic_link_is_replaced_or_left_as_it_was(tmp_path, monkeypatch):
    """The link was hidden as a backup, then its backup copy (which followed the link) failed:
    the write ended "cannot be written (No such file or directory)" and the rollback, asking
    whether the dangling backup existed, never put the link back."""
    real = os.replace
    for k in range(1, 4):
        out = tmp_path / f"at{k}"
        out.mkdir()
        (out / "merged.yaml").symlink_to(out / "nowhere" / "x")
        calls = []

        def failing(src, dst):
            calls.append(dst)
            if len(calls) == k:
                raise OSError(28, "No space left on device")
            return real(src, dst)

        monkeypatch.setattr(_atomic.os, "replace", failing)
        with pytest.raises(InputError):
            _write(out, NEW, "new")
        monkeypatch.setattr(_atomic.os, "replace", real)
        assert sorted(p.name for p in out.iterdir()) == ["merged.yaml"], f"rename {k}"
        assert os.readlink(out / "merged.yaml") == str(out / "nowhere" / "x")
        _write(out, NEW, "new")       # the link is replaced by the map
        assert not (out / "merged.yaml").is_symlink() and _state(out) == "new"


def test_a_signal_during_the_commit_rolls_back_then_interrupts(tmp_path, monkeypatch):
    """With the command-line handlers, SIGTERM arriving mid-commit is held until the old set
    is put back, then ends the command."""
    out = tmp_path / "o"
    out.mkdir()
    _write(out, OLD, "old")
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    real, calls = os.replace, []

    def signalled(src, dst):
        calls.append(dst)
        if len(calls) == 4:
            os.kill(os.getpid(), signal.SIGTERM)
        return real(src, dst)

    try:
        _signals.install()
        monkeypatch.setattr(_atomic.os, "replace", signalled)
        with pytest.raises(_signals.Terminated):
            _write(out, NEW, "new")
    finally:
        for s, h in saved.items():
            signal.signal(s, h)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_stale_group_maps_go_with_the_commit_and_come_back_on_failure(tmp_path, monkeypatch):
    out = tmp_path / "o"
    out.mkdir()
    save_maps([(OLD["merged"], out / "merged.yaml"), (OLD["merged.group1"], out / "merged.group1.yaml")],
              (out / "merged.report.json", "{}"))
    from fusionkit.mapio import group_map_files
    stale = group_map_files(out / "merged.yaml")
    assert [p.name for p in stale] == ["merged.group1.pgm", "merged.group1.yaml"]
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    monkeypatch.setattr(_atomic, "_fsync_dir", lambda d: (_ for _ in ()).throw(KeyboardInterrupt()))
    with pytest.raises(KeyboardInterrupt):
        save_maps([(NEW["merged"], out / "merged.yaml")], (out / "merged.report.json", "{}"), remove=stale)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    monkeypatch.undo()
    save_maps([(NEW["merged"], out / "merged.yaml")], (out / "merged.report.json", "{}"), remove=stale)
    assert sorted(p.name for p in out.iterdir()) == ["merged.pgm", "merged.report.json", "merged.yaml"]


# -- child processes: kill -9, SIGTERM, SIGINT at a controlled rename ---------------------------
_CHILD = textwrap.dedent("""
    import json, os, signal, sys, time
    sys.path.insert(0, {tests!r})
    from test_crash_safety import NEW, OLD, _write
    from pathlib import Path
    from fusionkit import _atomic, _signals
    out, k, how = Path(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
    real, calls = os.replace, []
    def held(src, dst):
        calls.append(dst)
        if len(calls) == k:
            if how == "hold":  # wait at this rename (holding the lock) until told to go on
                Path(str(out) + ".held").touch()
                while not Path(str(out) + ".go").exists():
                    time.sleep(0.01)
            else:
                os.kill(os.getpid(), getattr(signal, how))
        return real(src, dst)
    _atomic.os.replace = held
    _signals.install()
    try:
        if how == "none":
            _write(out, OLD, "old", by="second")
        else:
            _write(out, NEW, "new")
    except KeyboardInterrupt as exc:
        sys.exit(143 if isinstance(exc, _signals.Terminated) else 130)
""")


def _child(out: Path, k: int, how: str) -> subprocess.Popen:
    code = _CHILD.format(tests=str(Path(__file__).parent))
    env = {**os.environ, "NUMBA_THREADING_LAYER": "threadsafe"}
    return subprocess.Popen([sys.executable, "-c", code, str(out), str(k), how], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT)


@pytest.mark.parametrize("how", ["SIGKILL", "SIGTERM", "SIGINT"])
def test_a_process_killed_at_any_rename_leaves_one_whole_set(tmp_path, how):
    n = _count_replaces(tmp_path)
    for k in range(1, n + 1):
        out = tmp_path / f"{how}{k}"
        out.mkdir()
        _write(out, OLD, "old")
        before = {p.name: p.read_bytes() for p in out.iterdir()}
        proc = _child(out, k, how)
        try:
            _, err = proc.communicate(timeout=120)
        finally:
            proc.kill()
        if how == "SIGKILL":
            assert proc.returncode == -signal.SIGKILL
            # What a reader finds right after the crash: maps that load are right; a report
            # only beside its own maps (it is absent while a write is unfinished).
            leftover = [p for p in out.iterdir() if p.name.startswith(".")]
            for p in leftover:  # set them aside to check what a reader sees
                p.rename(tmp_path / f"{p.name}.{how}{k}")
            _state(out)
            for p in leftover:
                (tmp_path / f"{p.name}.{how}{k}").rename(p)
            # The next write to the output finishes or undoes the killed one first.
            _atomic._recover(out / "merged.report.json")
            _atomic._sweep([out / "merged.report.json", out / "merged.yaml", out / "merged.pgm",
                            out / "merged.group1.yaml", out / "merged.group1.pgm"])
            assert _state(out) in ("old", "new"), f"killed at rename {k}"
        else:
            assert proc.returncode == (143 if how == "SIGTERM" else 130), err.decode()
            assert b"Traceback" not in err
            if k < n:  # before the commit point: rolled back
                assert {p.name: p.read_bytes() for p in out.iterdir()} == before, f"rename {k}"
            else:
                assert _state(out) == "new"


def test_a_killed_write_is_finished_or_undone_by_any_later_write_or_read_in_its_folder(tmp_path):
    """A ``kill -9`` mid-commit left its journal, backups and temporary files, and the folder
    short of the set's YAML and report, until a write of that same output: an export of
    another name into the folder, or a merge (or the TUI) reading its maps, left them so."""
    n = _count_replaces(tmp_path)
    for k in range(1, n + 1):
        out = tmp_path / f"k{k}"
        out.mkdir()
        _write(out, OLD, "old")
        save_map(_grid(9), out / "other.yaml")
        proc = _child(out, k, "SIGKILL")
        try:
            proc.communicate(timeout=120)
        finally:
            proc.kill()
        assert proc.returncode == -signal.SIGKILL
        if k % 2:
            save_map(_grid(5), out / "another.yaml")   # a write of another name
        else:
            assert _same(load_map(out / "other.yaml"), _grid(9))   # a read of another map
        assert _state(out) in ("old", "new"), f"killed at rename {k}"


def test_the_tuis_overwrite_question_lists_the_files_a_killed_write_had_hidden(tmp_path):
    """After a ``kill -9`` mid-commit, the TUI asked to replace only merged.pgm: the YAML and
    the report, hidden as backups, came back (and were replaced) only after the answer."""
    import sys
    sys.path.insert(0, str(ROOT / "tui"))
    from fusionkit_tui.runner import export_paths
    names = ["merged.yaml", "merged.pgm", "merged.report.json", "merged.group1.yaml", "merged.group1.pgm"]
    for k in range(1, _count_replaces(tmp_path)):   # killed before the commit point
        out = tmp_path / f"k{k}"
        out.mkdir()
        _write(out, OLD, "old")
        proc = _child(out, k, "SIGKILL")
        try:
            proc.communicate(timeout=120)
        finally:
            proc.kill()
        listed = export_paths(out / "merged.yaml", groups=1).existing()
        assert sorted(p.name for p in listed) == sorted(names), f"killed at rename {k}"
        assert _state(out) == "old"


def test_two_writers_on_one_output_end_with_one_whole_set(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    _write(out, OLD, "old")
    first = _child(out, 3, "hold")  # writes NEW; held mid-commit, holding the lock
    try:
        deadline = time.monotonic() + 120
        while not Path(str(out) + ".held").exists():
            assert first.poll() is None and time.monotonic() < deadline, first.stderr.read()
            time.sleep(0.05)
        # A second writer (of OLD) to the same output waits for the first instead of mixing.
        second = _child(out, 0, "none")
        time.sleep(1.0)
        assert second.poll() is None, "the second writer did not wait for the lock"
        Path(str(out) + ".go").touch()
        assert first.wait(timeout=120) == 0
        assert second.wait(timeout=120) == 0
    finally:
        first.kill()
        if "second" in locals():
            second.kill()
    Path(str(out) + ".held").unlink()
    Path(str(out) + ".go").unlink()
    assert _state(out) == "old"  # the second writer's set, whole, written after the first's
    assert json.loads((out / "merged.report.json").read_text())["by"] == "second"


def test_a_killed_write_leaves_no_map_naming_an_image_of_another_write(tmp_path):
    """The worst outcome of the old writer: kill -9 between the image and the YAML left the
    old YAML beside the new image, a map that loads and is wrong."""
    out = tmp_path / "m"
    out.mkdir()
    save_map(OLD["merged"], out / "merged.yaml")
    real, calls = os.replace, []

    class Killed(BaseException):
        pass

    def kill_after_image(src, dst):
        real(src, dst)
        calls.append(dst)
        if str(dst).endswith(".pgm"):
            raise Killed()  # stands for kill -9: no cleanup below this point may matter

    _atomic.os.replace = kill_after_image
    orig = _atomic._rollback
    _atomic._rollback = lambda entries: False  # a killed process rolls nothing back
    try:
        with pytest.raises(Killed):
            save_map(NEW["merged"], out / "merged.yaml")
    finally:
        _atomic.os.replace = real
        _atomic._rollback = orig
    assert not (out / "merged.yaml").exists()  # the old YAML is not left naming the new image
    save_map(OLD["merged"], out / "merged.yaml")  # the next write recovers and writes
    assert _same(load_map(out / "merged.yaml"), OLD["merged"])
    assert sorted(p.name for p in out.iterdir()) == ["merged.pgm", "merged.yaml"]


# -- the command line: one line, exit 130 / 143, nothing half-written ---------------------------
_CLI = textwrap.dedent("""
    import os, signal, sys
    from fusionkit import _atomic
    k, how, argv = int(sys.argv[1]), sys.argv[2], sys.argv[3:]
    real, calls = os.replace, []
    def signalled(src, dst):
        calls.append(dst)
        if len(calls) == k:
            os.kill(os.getpid(), getattr(signal, how))
        return real(src, dst)
    if k > 0:
        _atomic.os.replace = signalled
    else:  # while computing, before anything is written
        import ctypes
        import fusionkit.simulate as sim
        compute = sim.simulate
        def signal_now():
            os.kill(os.getpid(), getattr(signal, how))
            sum(range(100000))          # the handler runs here
        def interrupted(*a, **kw):
            if k == -1:   # inside a ctypes callback (numba's compiler calls some): Python
                ctypes.CFUNCTYPE(None)(signal_now)()     # ignores what is raised there
            elif k == -2:   # inside Python code a compiled function called, which reports the
                try:        # interrupt as its own failure (as a numba dispatcher does)
                    signal_now()
                except KeyboardInterrupt as exc:
                    raise SystemError("CPUDispatcher(<function kernel>) returned a result "
                                      "with an exception set") from exc
            else:
                signal_now()
            return compute(*a, **kw)
        sim.simulate = interrupted
    from fusionkit.cli import main
    sys.exit(main(argv))
""")


def _files(folder: Path) -> dict:
    return {p.name: p.read_bytes() for p in folder.iterdir()}


@pytest.fixture(scope="module")
def earlier_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("cli") / "run"
    from fusionkit.cli import main
    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        assert main(["simulate", "--robots", "2", "--poses", "40", "--seed", "1", "--out", str(out),
                     "--quiet"]) == 0
    finally:
        for s, h in saved.items():
            signal.signal(s, h)
    return out


def _as_at_a_terminal():
    """The child takes a hang-up as a program started at a terminal does, even when these tests
    run under ``nohup`` (which starts every process with SIGHUP ignored)."""
    signal.signal(signal.SIGHUP, signal.SIG_DFL)


@pytest.mark.parametrize("k, how, code", [(0, "SIGINT", 130), (0, "SIGTERM", 143),
                                          (6, "SIGTERM", 143), (9, "SIGINT", 130),
                                          (-1, "SIGINT", 130), (-1, "SIGTERM", 143),
                                          (-2, "SIGTERM", 143), (0, "SIGHUP", 129),
                                          (6, "SIGHUP", 129)],
                         ids=["SIGINT computing", "SIGTERM computing", "SIGTERM mid-commit",
                              "SIGINT mid-commit", "SIGINT in a ctypes callback",
                              "SIGTERM in a ctypes callback", "SIGTERM in a compiled function",
                              "SIGHUP computing", "SIGHUP mid-commit"])
def test_a_signalled_command_exits_130_or_143_with_one_line_and_its_outputs_unchanged(
        earlier_run, k, how, code):
    before = _files(earlier_run)
    env = {**os.environ, "NUMBA_THREADING_LAYER": "threadsafe"}
    proc = subprocess.run(
        [sys.executable, "-c", _CLI, str(k), how, "simulate", "--robots", "3", "--poses", "40",
         "--seed", "2", "--out", str(earlier_run), "--quiet"],
        capture_output=True, text=True, timeout=300, env=env, cwd=ROOT,
        preexec_fn=_as_at_a_terminal)
    assert proc.returncode == code, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert lines[0].startswith("fusionkit simulate: " + {"SIGINT": "interrupted", "SIGTERM": "terminated",
                                                         "SIGHUP": "hung up"}[how])
    assert _files(earlier_run) == before


def test_a_command_started_under_nohup_runs_through_a_hang_up(tmp_path):
    """``nohup fusionkit bench ... &`` over SSH: the hang-up the program was started to ignore
    ended it with exit 129 and nothing written, as its handler took the signal back."""
    out = tmp_path / "run"
    env = {**os.environ, "NUMBA_THREADING_LAYER": "threadsafe"}
    proc = subprocess.run(
        [sys.executable, "-c", _CLI, "0", "SIGHUP", "simulate", "--robots", "2", "--poses", "40",
         "--seed", "2", "--out", str(out), "--quiet"], capture_output=True, text=True,
        timeout=300, env=env, cwd=ROOT,
        preexec_fn=lambda: signal.signal(signal.SIGHUP, signal.SIG_IGN))   # as nohup starts it
    assert proc.returncode == 0, proc.stderr
    assert (out / "robot_1.yaml").is_file() and (out / "truth.json").is_file()


def test_ctrl_c_during_start_up_is_one_line_and_exit_130(monkeypatch, capsys):
    import importlib

    from fusionkit import cli

    def interrupted(name, package=None):
        raise KeyboardInterrupt()

    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    monkeypatch.setattr(importlib, "import_module", interrupted)
    try:
        assert cli.main(["merge", "a.yaml", "b.yaml", "-o", "m.yaml"]) == 130
    finally:
        for s, h in saved.items():
            signal.signal(s, h)
    err = capsys.readouterr().err
    # the command is named though its parser was never built
    assert err == "fusionkit merge: interrupted; no output was left half-written\n"


def test_an_export_sweeps_the_temporary_folder_a_killed_export_left(tmp_path):
    """... and so does any later write or read of a map in its folder, whatever the names (only
    an export to that same output removed it)."""
    from fusionkit.rosbag_export import export_rosbag
    from fusionkit.scanlog import ScanLog, save_scans

    run = tmp_path / "run"
    run.mkdir()
    rng = np.random.default_rng(0)
    save_scans(run / "robot_1.scans.npz", ScanLog(rng.normal(size=(4, 3)), rng.uniform(1, 2, (4, 6)),
                                                   -1.0, 0.4, 5.0))
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)
    killed = tmp_path / f".run_bag.{int(dead.stdout)}.abc123.tmp"  # what a killed export leaves
    (killed / "run_bag").mkdir(parents=True)
    (killed / "run_bag" / "run_bag_0.db3").write_bytes(b"half")
    mine = tmp_path / f".run_bag.{os.getpid()}.xyz789.tmp"  # a live export's folder is left alone
    mine.mkdir()
    other = tmp_path / f".other_bag.{int(dead.stdout)}.k3x_9q2z.tmp"    # of another output
    (other / "other_bag").mkdir(parents=True)
    res = export_rosbag(run, tmp_path / "run_bag")
    assert res.path.is_dir() and not killed.exists() and not other.exists() and mine.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == [mine.name, "run", "run_bag"]
    (killed / "run_bag").mkdir(parents=True)
    save_map(OccupancyGrid(np.zeros((4, 4), np.int8), 0.1), tmp_path / "m.yaml")  # any write
    assert not killed.exists() and mine.exists()
    (killed / "run_bag").mkdir(parents=True)
    load_map(tmp_path / "m.yaml")                                           # a map read there
    assert not killed.exists() and mine.exists()


@pytest.mark.parametrize("command", ["simulate", "import"])
@pytest.mark.parametrize("fault", [OSError(28, "No space left on device"), KeyboardInterrupt()])
def test_a_failed_write_takes_back_the_folders_it_made(tmp_path, monkeypatch, capsys, command, fault):
    """A run written into a folder that did not exist: when its write fails (a full disk) or is
    interrupted, the folders made for it are removed again, not left empty."""
    from fusionkit.cli import main

    def failing(*a, **k):
        raise fault

    # imported before write_set is patched: imported after, they would bind the patched one
    # and monkeypatch would "restore" it for the tests that follow
    import fusionkit.io_carmen as io_carmen
    import fusionkit.sim_output as sim_output
    monkeypatch.setattr(_atomic, "write_set", failing)
    monkeypatch.setattr(sim_output, "write_set", failing)
    monkeypatch.setattr(io_carmen, "write_set", failing)
    (tmp_path / "have").mkdir()
    out = tmp_path / "have" / "new" / "run"
    if command == "simulate":
        argv = ["simulate", "--robots", "2", "--poses", "40", "--out", str(out), "--quiet"]
    else:
        log = tmp_path / "have" / "tiny.log"
        lines = [f"FLASER 3 1.0 1.0 1.0 {0.1 * k:.2f} 0.0 0.0 {0.1 * k:.2f} 0.0 0.0 {k}.0 host {k}.0"
                 for k in range(30)]
        log.write_text("\n".join(lines) + "\n")
        argv = ["import", "carmen", str(log), "--out", str(out), "--split", "2"]
    code = main(argv)
    assert code == (130 if isinstance(fault, KeyboardInterrupt) else 2), capsys.readouterr().err
    assert sorted(p.name for p in (tmp_path / "have").iterdir()) == \
        (["tiny.log"] if command == "import" else [])


def _killed_at_rename(write: str) -> str:
    """A child process that runs ``write`` (``src`` and ``out`` its first two arguments) and
    kills itself with SIGKILL at its write's rename number ``sys.argv[3]``."""
    return textwrap.dedent("""
        import os, pickle, signal, sys
        from pathlib import Path
        from fusionkit import _atomic
        src, out, k = Path(sys.argv[1]), Path(sys.argv[2]), int(sys.argv[3])
        real, calls = os.replace, []
        def killed(a, b):
            calls.append(b)
            if len(calls) == k:
                os.kill(os.getpid(), signal.SIGKILL)
            return real(a, b)
        _atomic.os.replace = killed
    """) + write + "\n"


_RUN_CHILD = _killed_at_rename("from fusionkit.sim_output import write_run\n"
                               "write_run(pickle.loads(src.read_bytes()), out)")


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory):
    """Two small simulations pickled: an earlier run of three robots, a new one of two."""
    from fusionkit.simulate import SimulationConfig, simulate
    from fusionkit.worlds import default_world

    d = tmp_path_factory.mktemp("runs")
    (d / "old.pkl").write_bytes(pickle.dumps(simulate(default_world(), SimulationConfig(
        robots=3, poses=60, seed=1))))
    (d / "new.pkl").write_bytes(pickle.dumps(simulate(default_world(), SimulationConfig(
        robots=2, poses=60, seed=2))))
    return d


@pytest.mark.parametrize("earlier", [True, False], ids=["over an earlier run", "into a new folder"])
def test_a_run_killed_while_written_is_finished_or_undone_by_the_next_write(tmp_path, two_runs,
                                                                           earlier):
    """``kill -9`` during ``simulate --out D`` left a journal and temporary files in D, and the
    next ``simulate --out D`` refused D ("not empty and holds no truth.json")."""
    from fusionkit.sim_output import check_run_dir, write_run

    old = pickle.loads((two_runs / "old.pkl").read_bytes())
    new_sim = pickle.loads((two_runs / "new.pkl").read_bytes())
    counted = tmp_path / "counted"
    calls = []
    real = os.replace
    _atomic.os.replace = lambda src, dst: (calls.append(dst), real(src, dst))[1]
    try:
        write_run(new_sim, counted)
    finally:
        _atomic.os.replace = real
    for k in range(1, len(calls) + 1):
        out = tmp_path / f"k{k}"
        if earlier:
            write_run(old, out)
        before = {p.name: p.read_bytes() for p in out.iterdir()} if earlier else {}
        proc = subprocess.run([sys.executable, "-c", _RUN_CHILD, str(two_runs / "new.pkl"), str(out),
                               str(k)], cwd=ROOT, capture_output=True, timeout=120,
                              env={**os.environ, "NUMBA_THREADING_LAYER": "threadsafe"})
        assert proc.returncode == -signal.SIGKILL, proc.stderr.decode()[-2000:]
        check_run_dir(out)                                   # not refused: recovered first
        now = {p.name: p.read_bytes() for p in out.iterdir()} if out.exists() else {}
        new = {p.name: p.read_bytes() for p in counted.iterdir()}
        assert now in (before, new), f"killed at rename {k}: {sorted(now)}"
        write_run(new_sim, out)
        assert {p.name: p.read_bytes() for p in out.iterdir()} == new, f"killed at rename {k}"


_IMPORT_CHILD = _killed_at_rename("from fusionkit.io_carmen import import_carmen\n"
                                  "import_carmen(src, out, split=2, overwrite=True)")


def test_a_split_import_killed_over_an_earlier_one_leaves_none_of_its_sessions_behind(tmp_path):
    """``import carmen --split 2 --force`` killed over a folder of ``--split 3``, then run
    again: it wrote the two new sessions and left the earlier robot_3, whose files then
    loaded and merged as one of the new run's (the truth.json naming it had been taken away at
    the kill, so the new write did not know it for the earlier run's)."""
    from fusionkit.io_carmen import import_carmen

    log = tmp_path / "tiny.log"
    lines = [f"FLASER 5 1.0 2.0 1.5 2.5 1.2 {0.1 * k:.2f} 0.0 0.0 {0.1 * k:.2f} 0.0 0.0 {k}.0 "
             f"host {k}.0" for k in range(60)]
    log.write_text("\n".join(lines) + "\n")
    clean = tmp_path / "clean"
    calls = []
    real = os.replace
    _atomic.os.replace = lambda src, dst: (calls.append(dst), real(src, dst))[1]
    try:
        import_carmen(log, clean, split=2)
    finally:
        _atomic.os.replace = real
    new = {p.name: p.read_bytes() for p in clean.iterdir()}
    for k in range(1, len(calls) + 1):
        out = tmp_path / f"k{k}"
        import_carmen(log, out, split=3)
        proc = subprocess.run([sys.executable, "-c", _IMPORT_CHILD, str(log), str(out), str(k)],
                              cwd=ROOT, capture_output=True, timeout=120,
                              env={**os.environ, "NUMBA_THREADING_LAYER": "threadsafe"})
        assert proc.returncode == -signal.SIGKILL, proc.stderr.decode()[-2000:]
        import_carmen(log, out, split=2, overwrite=True)
        assert {p.name: p.read_bytes() for p in out.iterdir()} == new, f"killed at rename {k}"


def test_a_full_disk_is_said_of_the_file_that_did_not_fit(tmp_path, monkeypatch):
    """The disk filling while an image was written was reported as the report (the set's last
    file) failing: "merged.report.json: cannot be written (No space left on device)"."""
    real = _atomic._write_durable

    def full(path, payload):
        if path.name.startswith(".merged.group1.pgm."):
            raise OSError(28, "No space left on device")
        return real(path, payload)

    monkeypatch.setattr(_atomic, "_write_durable", full)
    with pytest.raises(InputError) as info:
        _write(tmp_path, NEW, "new")
    assert str(info.value).startswith(str(tmp_path / "merged.group1.pgm"))
    assert "No space left on device" in str(info.value)
    assert list(tmp_path.iterdir()) == []


def test_an_interrupt_after_the_outputs_were_written_says_they_are_new(tmp_path, monkeypatch, capsys):
    """Ctrl-C while merge printed its table, after its set was committed: exit 130 with "no
    output was left half-written", and a script could not tell that the new set was in place."""
    from fusionkit.cli import main
    from fusionkit.cli import merge as merge_cli

    for name, g in (("a", _grid(1, (30, 40))), ("b", _grid(1, (30, 40)))):
        save_map(g, tmp_path / f"{name}.yaml")

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(merge_cli, "format_placements", interrupted)
    code = main(["merge", str(tmp_path / "a.yaml"), str(tmp_path / "b.yaml"), "-o",
                 str(tmp_path / "m.yaml"), "--method", "fourier-mellin"])
    assert code == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"fusionkit merge: interrupted after writing {tmp_path / 'm.report.json'} (its set "
                   f"of outputs is whole and new); nothing was left half-written"], err
    assert (tmp_path / "m.report.json").is_file()
    # the next command of the same process starts with nothing written
    monkeypatch.setattr(merge_cli, "merge_config_from_args", interrupted)
    assert main(["merge", str(tmp_path / "a.yaml"), str(tmp_path / "b.yaml"), "-o",
                 str(tmp_path / "n.yaml")]) == 130
    assert capsys.readouterr().err.strip() == "fusionkit merge: interrupted; no output was left half-written"


def test_a_failure_after_the_commit_is_no_failure_of_the_write(tmp_path, monkeypatch):
    """The journal's removal failing after the commit point raised "m.report.json: cannot be
    written (Input/output error)", exit 2, while the new set was whole and in place."""
    _write(tmp_path, OLD, "old")
    real = Path.unlink

    def failing(self, missing_ok=False):
        if self.name.endswith(".journal"):
            raise OSError(5, "Input/output error")
        return real(self, missing_ok=missing_ok)

    monkeypatch.setattr(Path, "unlink", failing)
    _write(tmp_path, NEW, "new")                                # no error: the set is new
    assert json.loads((tmp_path / "merged.report.json").read_text())["write"] == "new"
    assert _same(load_map(tmp_path / "merged.yaml"), NEW["merged"])
    monkeypatch.setattr(Path, "unlink", real)
    _write(tmp_path, OLD, "old")                                # the next write tidies up
    assert _state(tmp_path) == "old"
    assert not [p.name for p in tmp_path.iterdir() if p.name.startswith(".")]


class _Killed(BaseException):
    """A kill -9 played in the process: nothing after it runs, nothing is rolled back."""


def test_a_write_killed_while_it_tidies_up_leaves_nothing_hidden_after_the_next(tmp_path, monkeypatch):
    """Killed after the journal was dropped and before the backups were, a write left hidden
    backups (full copies of the removed group map) that no later write removed."""
    from fusionkit.mapio import group_map_files
    out = tmp_path / "o"
    out.mkdir()
    save_maps([(OLD["merged"], out / "merged.yaml"), (OLD["merged.group1"], out / "merged.group1.yaml")],
              (out / "merged.report.json", "{}"))
    real = Path.unlink

    def unlink(self, missing_ok=False):
        if self.name.endswith(".bak"):
            raise _Killed
        return real(self, missing_ok=missing_ok)

    monkeypatch.setattr(Path, "unlink", unlink)
    with pytest.raises(_Killed):
        save_maps([(NEW["merged"], out / "merged.yaml")], (out / "merged.report.json", "{}"),
                  remove=group_map_files(out / "merged.yaml"))
    monkeypatch.undo()
    save_maps([(NEW["merged"], out / "merged.yaml")], (out / "merged.report.json", "{}"))
    assert sorted(p.name for p in out.iterdir()) == ["merged.pgm", "merged.report.json", "merged.yaml"]


def test_the_next_bench_after_one_killed_mid_commit_leaves_exactly_its_own_files(tmp_path, monkeypatch):
    """The pictures to remove were listed from the names in view before the killed write was
    undone: a picture it had hidden came back and stayed beside the new tables for good."""
    from fusionkit.bench import BenchConfig, WorldSpec, run_bench, write_outputs
    cave = WorldSpec("cave", builtin="cave")
    first = run_bench([cave], BenchConfig(methods=("map-merge", "hough-spectrum"), modes=("crop",),
                                          cases=1, robots=(2,), seed=3))
    second = run_bench([cave], BenchConfig(methods=("map-merge",), modes=("crop",), cases=1,
                                           robots=(2,), seed=4))
    real = os.replace
    for k in range(1, 7):
        out = tmp_path / f"k{k}"
        write_outputs(first, out)
        calls = []

        def killed(src, dst):
            calls.append(dst)
            if len(calls) == k:
                raise _Killed
            return real(src, dst)

        monkeypatch.setattr(_atomic.os, "replace", killed)
        monkeypatch.setattr(_atomic, "_rollback", lambda entries: False)  # killed: no undo
        with pytest.raises(_Killed):
            write_outputs(second, out)
        monkeypatch.undo()
        write_outputs(second, out)
        assert sorted(p.name for p in out.iterdir()) == ["bench.json", "bench.md", "bench_map-merge.png"], k


def _swallowing(monkeypatch, then=None):
    """Make the CLI's module loading receive a real SIGINT and swallow it, as an optional
    import does that fails with ImportError while it loads (``then``: raise that instead)."""
    import importlib
    real = importlib.import_module

    def load(name, package=None):
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.5)   # the handler runs here
        except KeyboardInterrupt:
            if then is not None:
                raise then from None
        return real(name, package)

    monkeypatch.setattr(importlib, "import_module", load)


@pytest.mark.parametrize("then", [None, RuntimeError("Error calling __set_name__ on 'cached_property'")])
def test_a_ctrl_c_a_library_swallows_while_modules_load_still_stops_the_command(tmp_path, monkeypatch,
                                                                                capsys, then):
    """3 of 150 Ctrl-Cs during start-up were lost (the merge ran on and replaced its outputs,
    exit 0); others came out as a library's own error, with a traceback and exit 1."""
    import shutil

    from fusionkit import cli
    for name in ("a", "b"):
        shutil.copy(ROOT / "maps" / "cave.pgm", tmp_path / f"{name}.pgm")
        (tmp_path / f"{name}.yaml").write_text(
            (ROOT / "maps" / "cave.yaml").read_text().replace("cave.pgm", f"{name}.pgm"))
    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    _swallowing(monkeypatch, then)
    try:
        code = cli.main(["merge", str(tmp_path / "a.yaml"), str(tmp_path / "b.yaml"), "-o",
                         str(tmp_path / "m.yaml"), "--method", "map-merge", "--quiet"])
    finally:
        for s, h in saved.items():
            signal.signal(s, h)
    assert code == 130
    assert capsys.readouterr().err == "fusionkit merge: interrupted; no output was left half-written\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.pgm", "a.yaml", "b.pgm", "b.yaml"]


def test_a_group_map_a_merge_removes_never_names_a_missing_image_mid_commit(tmp_path, monkeypatch):
    """Killed between the two, a commit that removed a group map had taken its image away while
    its YAML still named it."""
    from fusionkit.mapio import group_map_files
    out = tmp_path / "o"
    out.mkdir()
    save_maps([(OLD["merged"], out / "merged.yaml"), (OLD["merged.group1"], out / "merged.group1.yaml")],
              (out / "merged.report.json", "{}"))
    real, seen = os.replace, []

    def watched(src, dst):
        real(src, dst)
        seen.append(not (out / "merged.group1.yaml").exists() or (out / "merged.group1.pgm").exists())

    monkeypatch.setattr(_atomic.os, "replace", watched)
    save_maps([(NEW["merged"], out / "merged.yaml")], (out / "merged.report.json", "{}"),
              remove=group_map_files(out / "merged.yaml"))
    assert seen and all(seen), seen
    assert sorted(p.name for p in out.iterdir()) == ["merged.pgm", "merged.report.json", "merged.yaml"]


def test_a_ctrl_c_handled_after_a_command_does_not_stop_a_later_save(tmp_path, capsys):
    """After a command run in the process (a notebook's cli.main), a Ctrl-C the caller handled
    itself made the next save raise it again and write nothing."""
    from fusionkit import cli
    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        assert cli.main(["merge", "missing_a.yaml", "missing_b.yaml", "-o", str(tmp_path / "m.yaml")]) == 2
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.5)
        except KeyboardInterrupt:
            pass   # the caller's own handling
        _atomic.write_text_atomic(tmp_path / "note.txt", "kept")
    finally:
        for s, h in saved.items():
            signal.signal(s, h)
    assert (tmp_path / "note.txt").read_text() == "kept"


@pytest.mark.parametrize("argv, named", [
    (["import", "carmen", "missing.log", "--out", "OUT"], "fusionkit import carmen"),
    (["export", "rosbag", "missing_run", "--out", "OUT.bag"], "fusionkit export rosbag"),
    (["import", "cramen", "missing.log"], "fusionkit import"),
])
def test_a_ctrl_c_while_a_command_with_kinds_loads_names_the_command_whole(monkeypatch, capsys, argv,
                                                                         named):
    """Stopped while its modules loaded, ``import carmen`` said ``fusionkit import: interrupted``,
    not the command the user typed (and its usage errors name)."""
    from fusionkit import cli
    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    _swallowing(monkeypatch, RuntimeError("Error calling __set_name__ on 'cached_property'"))
    try:
        code = cli.main(argv)
    finally:
        for s, h in saved.items():
            signal.signal(s, h)
    assert code == 130
    assert capsys.readouterr().err == f"{named}: interrupted; no output was left half-written\n"


def test_the_kinds_an_interrupt_names_are_those_the_commands_register():
    from fusionkit.cli import KINDS, build_parser
    for command, kinds in KINDS.items():
        parser = build_parser([command])
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        inner = next(a for a in sub.choices[command]._actions if isinstance(a, argparse._SubParsersAction))
        assert tuple(inner.choices) == kinds, command


def test_a_ctrl_c_while_the_programs_modules_load_is_one_line_and_exit_130():
    """Between the program's start and its command's handler, a Ctrl-C came out of an import
    as a traceback. A Python session that imports the command line keeps its own Ctrl-C."""
    code = textwrap.dedent("""
        import os, signal, sys, time
        signal.signal(signal.SIGINT, signal.default_int_handler)   # as started from a shell
        sys.argv = [{argv0!r}, "merge", "a.yaml", "b.yaml", "-o", "m.yaml"]
        import fusionkit.cli
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(5)
    """)
    env = {**os.environ, "NUMBA_THREADING_LAYER": "threadsafe"}
    done = subprocess.run([sys.executable, "-c", code.format(argv0="/venv/bin/fusionkit")], env=env,
                          capture_output=True, timeout=60, cwd=ROOT)
    assert done.returncode == 130
    assert done.stderr == b"fusionkit merge: interrupted; no output was left half-written\n"
    done = subprocess.run([sys.executable, "-c", code.format(argv0="-c")], env=env,
                          capture_output=True, timeout=60, cwd=ROOT)
    assert b"KeyboardInterrupt" in done.stderr
