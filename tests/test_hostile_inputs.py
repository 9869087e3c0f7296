"""A corpus of broken and hostile inputs: each is answered by one line and exit 2 (or handled),
within a time bound, with no input changed and nothing half-written.

Classes: hangs (FIFOs), decompression and zip bombs, YAML alias floods, absurd numbers, long
and odd names, outputs that collide with inputs or with each other, folders where files are
expected and files where folders are, deep JSON, pickled / text / complex / string arrays,
oversized lines, and inputs that an earlier output's contents name.
"""

from __future__ import annotations

import io
import json
import os
import signal
import struct
import subprocess
import sys
import warnings
import zipfile
import zlib
from pathlib import Path

import numpy as np
import pytest

from fusionkit.cli import main
from fusionkit.grid import OccupancyGrid
from fusionkit.mapio import save_map
from fusionkit.scanlog import ScanLog, encode_scans

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(autouse=True)
def _keep_signal_handlers():
    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    yield
    for s, h in saved.items():
        signal.signal(s, h)


def _grid(seed=0) -> OccupancyGrid:
    rng = np.random.default_rng(seed)
    return OccupancyGrid(rng.choice(np.array([-1, 0, 100], np.int8), size=(20, 30)), 0.1, (0.0, 0.0, 0.0))


def _log(**change) -> dict:
    rng = np.random.default_rng(0)
    d = dict(poses=rng.normal(size=(5, 3)), ranges=rng.uniform(0.5, 3, (5, 8)).astype(np.float32),
             angle_min=np.float64(-np.pi), angle_increment=np.float64(np.pi / 4),
             range_max=np.float64(4.0))
    d.update(change)
    return d


def _npz(arrays: dict) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def _png_header(width: int, height: int, depth: int, colour: int) -> bytes:
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    ihdr = struct.pack(">IIBBBBB", width, height, depth, colour, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\0" * 4096))
            + chunk(b"IEND", b""))


def _claims_1_pib() -> bytes:
    """An npz whose ranges header declares 2**48 float32 values (1 PiB) over a few bytes."""
    arrays = _log()
    raw = io.BytesIO()
    with zipfile.ZipFile(raw, "w") as zf:
        for k, v in arrays.items():
            b = io.BytesIO()
            np.save(b, v)
            data = b.getvalue()
            if k == "ranges":
                header = {"descr": "<f4", "fortran_order": False, "shape": (2 ** 48, 1)}
                b = io.BytesIO()
                np.lib.format.write_array_header_1_0(b, header)
                data = b.getvalue() + b"\0" * 64
            zf.writestr(k + ".npy", data)
    return raw.getvalue()


def _zip_bomb() -> bytes:
    """An npz whose directory says ranges.npy unpacks to 4 GB (a 1.4 MB file can)."""
    data = bytearray(_npz(_log()))
    at = data.find(b"PK\x01\x02")
    while at >= 0:
        name_len = struct.unpack_from("<H", data, at + 28)[0]
        if data[at + 46:at + 46 + name_len] == b"ranges.npy":
            struct.pack_into("<I", data, at + 24, 4_000_000_000)  # uncompressed size
        at = data.find(b"PK\x01\x02", at + 4)
    return bytes(data)


_LAUGHS = "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{c}: &{c} [*{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}]\n"
    for p, c in zip("abcdefgh", "bcdefghi"))


def _map_yaml(**fields) -> str:
    doc = {"image": "B.pgm", "resolution": "0.1", "origin": "[0.0, 0.0, 0.0]", "negate": "0",
           "occupied_thresh": "0.65", "free_thresh": "0.196"}
    doc.update(fields)
    prefix = doc.pop("_prefix", "")
    return prefix + "".join(f"{k}: {v}\n" for k, v in doc.items())


# Each case: (id, setup(folder) -> argv, words the one-line error must hold)
def _merge_b(**fields):
    def setup(d):
        (d / "B.yaml").write_text(_map_yaml(**fields))
        return ["merge", str(d / "A.yaml"), str(d / "B.yaml"), "-o", str(d / "out" / "m.yaml")]
    return setup


def _merge_with_scans(payload):
    def setup(d):
        (d / "B.scans.npz").write_bytes(payload() if callable(payload) else payload)
        return ["merge", str(d / "A.yaml"), str(d / "B.yaml"), "-o", str(d / "out" / "m.yaml")]
    return setup


def _merge_out(out=None, report=None, mkdir=None):
    def setup(d):
        if mkdir:
            (d / mkdir).mkdir(parents=True)
        argv = ["merge", str(d / "A.yaml"), str(d / "B.yaml"), "-o", str(d / (out or "out/m.yaml"))]
        return argv + (["--report", str(d / report)] if report else [])
    return setup


def _png_bomb(d):
    (d / "bomb.png").write_bytes(_png_header(12000, 12000, 16, 6))
    return _merge_b(image="bomb.png")(d)


def _evaluate(truth_text, report_text=None):
    def setup(d):
        (d / "truth.json").write_text(truth_text)
        argv = ["evaluate", str(d / "A.yaml"), "--truth", str(d / "truth.json")]
        if report_text is not None:
            (d / "r.json").write_text(report_text)
            argv += ["--report", str(d / "r.json")]
        return argv
    return setup


def _carmen(setup_log, *extra):
    def setup(d):
        log = setup_log(d)
        return ["import", "carmen", str(log), "--out", str(d / "out" / "imp"), *extra]
    return setup


def _bag_folder_as_output(d):
    bag = d / "bag"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    (bag / "bag_0.db3").write_bytes(b"SQLite format 3\0")
    return ["import", "rosbag", str(bag), "--scan-topic", "/scan", "--odom-topic", "/odom",
            "--out", str(bag), "--name", "metadata", "--force"]


def _export_bomb(d):
    run = d / "run"
    run.mkdir()
    (run / "robot_1.scans.npz").write_bytes(_zip_bomb())
    return ["export", "rosbag", str(run), "--out", str(d / "out" / "x_bag")]


def _all_unknown_reference(d):
    save_map(OccupancyGrid(np.full((20, 30), -1, np.int8), 0.05, (0.0, 0.0, 0.0)), d / "U.yaml")
    return ["merge", str(d / "U.yaml"), str(d / "A.yaml"), "-o", str(d / "out" / "m.yaml")]


def _no_wall_reference(d):
    save_map(OccupancyGrid(np.zeros((20, 30), np.int8), 0.1, (0.0, 0.0, 0.0)), d / "F.yaml")
    return ["merge", str(d / "F.yaml"), str(d / "A.yaml"), "-o", str(d / "out" / "m.yaml")]


def _no_free_reference(d):
    data = np.full((20, 30), -1, np.int8)
    data[2:18, 3] = data[2:18, 26] = 100
    save_map(OccupancyGrid(data, 0.1, (0.0, 0.0, 0.0)), d / "W.yaml")
    return ["merge", str(d / "W.yaml"), str(d / "A.yaml"), "-o", str(d / "out" / "m.yaml"),
            "--method", "spectral-pso"]


def _coarse_giant(d):
    data = np.zeros((300, 300), np.int8)
    data[0, :] = data[-1, :] = 100
    save_map(OccupancyGrid(data, 10.0, (0.0, 0.0, 0.0)), d / "G.yaml")
    return ["merge", str(d / "A.yaml"), str(d / "G.yaml"), "-o", str(d / "out" / "m.yaml")]


def _evaluate_all_unknown(d):
    save_map(OccupancyGrid(np.full((20, 30), -1, np.int8), 0.1, (0.0, 0.0, 0.0)), d / "U.yaml")
    (d / "truth.json").write_text(json.dumps({"world": "A.yaml", "robots": [
        {"name": "A", "transform": {"x": 0, "y": 0, "theta": 0}}]}))
    return ["evaluate", str(d / "U.yaml"), "--truth", str(d / "truth.json")]


DEEP = "[" * 100_000 + "]" * 100_000
CASES = [
    ("yaml alias flood in origin", _merge_b(_prefix=_LAUGHS, origin="*i"), "alias"),
    ("yaml alias flood in image", _merge_b(_prefix=_LAUGHS, image="*i"), "alias"),
    ("a key given twice", _merge_b(_prefix="resolution: 0.2\n"), "'resolution' is given twice"),
    ("a folder as the image", _merge_b(image="."), "B.yaml: 'image' names the directory"),
    ("resolution 1e-300", _merge_b(resolution="1e-300"), "resolution"),
    ("resolution 1e300", _merge_b(resolution="1e300"), "resolution"),
    ("origin 1e308", _merge_b(origin="[1e308, 0, 0]"), "origin"),
    ("300-digit resolution", _merge_b(resolution="1" * 300), "resolution"),
    ("NUL in the image name", _merge_b(image='"B\\0.pgm"'), "image"),
    ("PNG decompression bomb", _png_bomb, "decoded"),
    ("300-character input name", lambda d: ["merge", str(d / "A.yaml"), str(d / ("x" * 300 + ".yaml")),
                                            "-o", str(d / "out" / "m.yaml")], "long"),
    ("300-character output name", _merge_out(out="out/" + "m" * 300 + ".yaml"), "name"),
    ("npz of plain text", _merge_with_scans(b"poses ranges angle_min\n1 2 3\n"), "not an .npz"),
    ("npz header claims 1 PiB", _merge_with_scans(_claims_1_pib), "declares"),
    ("npz zip bomb", _merge_with_scans(_zip_bomb), "GB once loaded"),
    ("npz of pickled objects", _merge_with_scans(lambda: _npz(_log(ranges=np.array([None] * 8, object)))),
     "pickled"),
    ("npz ranges of strings", _merge_with_scans(lambda: _npz(_log(ranges=np.full((5, 8), "1.0")))), "text"),
    ("npz complex ranges", _merge_with_scans(lambda: _npz(_log(ranges=np.ones((5, 8), complex)))), "complex"),
    ("npz range_max 1e300", _merge_with_scans(lambda: _npz(_log(range_max=np.float64(1e300)))), "range_max"),
    ("--report is -o", _merge_out(report="out/m.yaml"), "same file"),
    ("--report is the output image", _merge_out(report="out/m.pgm"), "same file"),
    ("--report is an input's image", _merge_out(report="B.pgm"), "overwrite the input"),
    ("--report is a folder", _merge_out(report="out/r", mkdir="out/r"), "folder"),
    ("-o is an existing folder", _merge_out(out="out/d.yaml", mkdir="out/d.yaml"), "folder"),
    ("-o in a missing folder", _merge_out(out="nowhere/m.yaml"), "does not exist"),
    ("/ as a map to merge", lambda d: ["merge", str(d / "A.yaml"), "/", "-o", str(d / "out" / "m.yaml")],
     "/: is a directory, not a map"),
    (". as the map to evaluate", lambda d: (d / "truth.json").write_text(json.dumps(
        {"world": "A.yaml", "robots": [{"name": "A", "transform": {"x": 0, "y": 0, "theta": 0}}]}))
     and ["evaluate", ".", "--truth", str(d / "truth.json")], ".: is a directory, not a map"),
    ("truth.json nested 100000 deep", _evaluate(DEEP), "nested"),
    ("report nested 100000 deep",
     _evaluate(json.dumps({"world": "A.yaml", "robots": [{"name": "A", "transform": {"x": 0, "y": 0, "theta": 0}}]}),
               DEEP), "nested"),
    ("CARMEN log is a folder", _carmen(lambda d: (d / "logdir").mkdir() or d / "logdir"), "directory"),
    ("CARMEN --out is a file", lambda d: ["import", "carmen", str(d / "A.yaml"), "--out", str(d / "A.pgm")],
     "is a file"),
    ("import into the ROS 2 bag's folder over its metadata.yaml", _bag_folder_as_output, "overwrite the input"),
    ("export from a zip-bomb scan log", _export_bomb, "GB once loaded"),
    ("all-unknown reference map", _all_unknown_reference, "U.yaml: the reference map has no known cell"),
    ("reference map with no wall", _no_wall_reference, "F.yaml: the reference map has no wall"),
    ("spectral-pso, reference map with no free cell", _no_free_reference,
     "the reference map has no free cell"),
    ("coarse map that would be 9e8 cells at the reference cell size", _coarse_giant, "G: at the reference map's"),
    ("evaluate an all-unknown map", _evaluate_all_unknown, "nothing to evaluate"),
]


@pytest.fixture
def folder(tmp_path):
    save_map(_grid(1), tmp_path / "A.yaml")
    save_map(_grid(2), tmp_path / "B.yaml")
    (tmp_path / "out").mkdir()
    return tmp_path


def _snapshot(root: Path) -> dict:
    return {p.relative_to(root): (p.read_bytes() if p.is_file() else None)
            for p in sorted(root.rglob("*"))}


@pytest.mark.parametrize("setup, words", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_hostile_input_is_one_line_exit_2_and_changes_nothing(folder, capsys, setup, words):
    argv = setup(folder)
    before = _snapshot(folder)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a RuntimeWarning or ComplexWarning is a failure too
        code = main(argv)
    out, err = capsys.readouterr()
    assert code == 2, err
    assert err.endswith("\n") and err.count("\n") == 1, err[:2000]
    assert "Traceback" not in err and "\0" not in err and len(err) < 700, err[:2000]
    assert words in err, err
    assert "allow_pickle" not in err  # never suggest loading pickled data
    assert _snapshot(folder) == before  # no input changed, nothing written


def test_a_scan_log_that_cannot_be_read_says_the_map_merges_without_it(folder, capsys):
    """The scans beside a map are optional: the error said only how to write them again, not
    that moving the file away lets the map be placed by its walls."""
    code = main(_merge_with_scans(b"poses ranges angle_min\n1 2 3\n")(folder))
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert "B.scans.npz" in err and "or move it away from B.yaml: a map without scans is placed " \
        "by its walls" in err, err


def test_a_write_error_is_one_line_and_leaves_nothing(folder, capsys, monkeypatch):
    """A read-only or full output folder (as root, permissions do not stop writes, so the
    refusal of the file system is injected)."""
    from fusionkit import _atomic

    def refused(path, payload):
        raise PermissionError(13, "Permission denied", str(path))

    monkeypatch.setattr(_atomic, "_write_durable", refused)
    log = folder / "r.log"
    log.write_text("".join(f"FLASER 4 1 2 3 1.5 {i * 0.1} 0 0 {i * 0.1} 0 0 {i} h {i}\n" for i in range(30)))
    before = _snapshot(folder)
    assert main(["import", "carmen", str(log), "--out", str(folder / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Permission denied" in err and "r.scans.npz" in err, err
    assert _snapshot(folder) == before


def test_an_overlong_carmen_line_is_skipped_and_counted_not_held(folder, capsys, monkeypatch):
    from fusionkit import carmen_read

    monkeypatch.setattr(carmen_read, "MAX_LINE_BYTES", 4096)
    log = folder / "r.log"
    good = "".join(f"FLASER 4 1 2 3 1.5 {i * 0.1} 0 0 {i * 0.1} 0 0 {i} h {i}\n" for i in range(30))
    log.write_text(good + "FLASER 200000 " + "1.0 " * 200_000 + "\n" + good.replace("FLASER", "FLASER", 1))
    assert main(["import", "carmen", str(log), "--out", str(folder / "imp")]) == 0
    out = capsys.readouterr().out
    assert "too_long 1" in out


def test_simulate_removes_only_robot_files_it_wrote(folder, capsys):
    """An earlier run's truth.json naming `notes` (or the world given as input) never leads to
    those files being removed; robot files of the earlier run are replaced or removed."""
    run = folder / "run"
    assert main(["simulate", "--robots", "3", "--poses", "40", "--out", str(run), "--quiet"]) == 0
    truth = json.loads((run / "truth.json").read_text())
    truth["robots"].append({"name": "notes", "transform": {"x": 0, "y": 0, "theta": 0}})
    (run / "truth.json").write_text(json.dumps(truth))
    save_map(_grid(3), run / "notes.yaml")
    kept = {n: (run / n).read_bytes() for n in ("notes.yaml", "notes.pgm", "robot_3.yaml",
                                                "robot_3.pgm", "robot_3.scans.npz")}
    # The world is a robot map of the earlier run, and the new run has fewer robots.
    assert main(["simulate", "--world", str(run / "robot_3.yaml"), "--robots", "2", "--poses", "40",
                 "--out", str(run), "--quiet"]) == 0
    assert {n: (run / n).read_bytes() for n in kept} == kept
    assert not [p for p in run.iterdir() if p.name.startswith(".")]
    assert [r["name"] for r in json.loads((run / "truth.json").read_text())["robots"]] == ["robot_1", "robot_2"]


# -- hangs: a FIFO where a file is expected is refused at once, never read ----------------------
def _fifo_cases(d: Path):
    os.mkfifo(d / "fifo.yaml")
    os.mkfifo(d / "fifo.pgm")
    (d / "C.yaml").write_text(_map_yaml(image="fifo.pgm"))
    os.mkfifo(d / "fifo.log")
    os.mkfifo(d / "world_fifo.yaml")
    (d / "truth.json").write_text(json.dumps({"world": "world_fifo.yaml", "robots": [
        {"name": "A", "transform": {"x": 0, "y": 0, "theta": 0}}]}))
    m = ["merge", str(d / "A.yaml")]
    return {
        "map YAML is a FIFO": m + [str(d / "fifo.yaml"), "-o", str(d / "out" / "m.yaml")],
        "map image is a FIFO": m + [str(d / "C.yaml"), "-o", str(d / "out" / "m.yaml")],
        "CARMEN log is a FIFO": ["import", "carmen", str(d / "fifo.log"), "--out", str(d / "out")],
        "truth.json's world is a FIFO": ["evaluate", str(d / "A.yaml"), "--truth", str(d / "truth.json")],
    }


def test_fifos_are_refused_without_hanging(folder):
    env = {**os.environ, "NUMBA_THREADING_LAYER": "threadsafe"}
    for name, argv in _fifo_cases(folder).items():
        proc = subprocess.run([sys.executable, "-m", "fusionkit.cli", *argv], capture_output=True,
                              text=True, timeout=60, env=env, cwd=ROOT)
        assert proc.returncode == 2, (name, proc.stderr)
        assert proc.stderr.count("\n") == 1 and "regular file" in proc.stderr, (name, proc.stderr)
