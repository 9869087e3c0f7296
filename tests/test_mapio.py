"""Map file I/O in the ROS map_server format: real maps, round trips, every image flavour,
every bad input, and property tests for the loaders."""

from __future__ import annotations

import math
import os
import re
import struct
import tempfile
import zlib
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fusionkit.errors import InputError, MapFormatError
from fusionkit.grid import OccupancyGrid
from fusionkit.mapio import load_map, map_info, save_map
from fusionkit.mapping import MAX_CELLS

REPO = Path(__file__).resolve().parents[1]
PROJECT_REAL = REPO / "maps" / "real"
SHARED_REAL = Path(__file__).resolve().parents[2] / "shared" / "maps" / "real"
REAL = SHARED_REAL if SHARED_REAL.is_dir() else PROJECT_REAL
REAL_YAMLS = sorted(REAL.glob("*.yaml"))
REDISTRIBUTED = ("gatech_ilab", "intel_lab", "izs_campus_outdoor", "mit_stata_basement",
                 "uos_avz_floor5", "utexas_gdc_floor3", "willow_garage", "yujin_office_run1",
                 "yujin_office_run2")


# ---------------------------------------------------------------------------------------------
# An independent reference: the map_server rule written out over the raw PGM bytes
# ---------------------------------------------------------------------------------------------
def reference_cells(yaml_file: Path) -> tuple[np.ndarray, dict]:
    """map_server's trinary rule on an 8-bit P5 PGM, from the raw bytes, rows flipped."""
    meta = yaml.safe_load(yaml_file.read_text())
    raw = (yaml_file.parent / meta["image"]).read_bytes()
    tokens = []
    pos = 2
    assert raw[:2] == b"P5"
    while len(tokens) < 3:
        m = re.compile(rb"(?:\s|#[^\n]*\n)*(\d+)").match(raw, pos)
        tokens.append(int(m.group(1)))
        pos = m.end()
    width, height, maxval = tokens
    assert maxval == 255
    pixels = np.frombuffer(raw[pos + 1: pos + 1 + width * height], np.uint8).reshape(height, width)
    p = (255.0 - pixels) / 255.0
    if meta["negate"]:
        p = pixels / 255.0
    cells = np.full(pixels.shape, -1, np.int8)
    cells[p > meta["occupied_thresh"]] = 100
    cells[p < meta["free_thresh"]] = 0
    return cells[::-1], meta


def write_map(folder: Path, name: str, image_bytes: bytes, image_name: str | None = None, **keys) -> Path:
    """A YAML + image pair; ``keys`` override the map_server defaults (None removes a key)."""
    image_name = image_name or f"{name}.pgm"
    (folder / image_name).write_bytes(image_bytes)
    doc = {"image": image_name, "resolution": 0.05, "origin": [0.0, 0.0, 0.0], "negate": 0,
           "occupied_thresh": 0.65, "free_thresh": 0.196}
    doc.update(keys)
    doc = {k: v for k, v in doc.items() if v is not None}
    path = folder / f"{name}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def p5(pixels: np.ndarray, maxval: int = 255, comment: bool = True) -> bytes:
    pixels = np.asarray(pixels)
    h, w = pixels.shape
    head = b"P5\n" + (b"# a comment\n" if comment else b"") + f"{w} {h}\n{maxval}\n".encode()
    body = pixels.astype(np.uint8 if maxval < 256 else ">u2").tobytes()
    return head + body


def png(pixels: np.ndarray, color_type: int, bit_depth: int = 8, ihdr_size=None) -> bytes:
    """A PNG written by hand (filter 0 on every row), so grey+alpha can be made as well."""
    pixels = np.asarray(pixels)
    h, w = pixels.shape[:2]
    dtype = ">u2" if bit_depth == 16 else np.uint8
    rows = b"".join(b"\x00" + pixels[r].astype(dtype).tobytes() for r in range(h))

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    iw, ih = ihdr_size or (w, h)
    ihdr = struct.pack(">IIBBBBB", iw, ih, bit_depth, color_type, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(rows))
            + chunk(b"IEND", b""))


# ---------------------------------------------------------------------------------------------
# Real maps
# ---------------------------------------------------------------------------------------------
def test_real_maps_are_present():
    names = {p.stem for p in REAL_YAMLS}
    assert set(REDISTRIBUTED) <= names


@pytest.mark.parametrize("yaml_file", REAL_YAMLS, ids=[p.stem for p in REAL_YAMLS])
def test_real_map_matches_map_server_rule(yaml_file):
    grid = load_map(yaml_file)
    expected, meta = reference_cells(yaml_file)
    assert grid.name == yaml_file.stem
    assert grid.data.dtype == np.int8 and grid.data.shape == expected.shape
    assert np.array_equal(grid.data, expected)
    assert grid.resolution == meta["resolution"]
    assert grid.origin == tuple(float(v) for v in meta["origin"])
    counts = grid.counts()
    assert counts == {"occupied": int((expected == 100).sum()), "free": int((expected == 0).sum()),
                      "unknown": int((expected == -1).sum())}
    assert counts["occupied"] > 0 and counts["free"] > 0


def _real(name: str) -> Path:
    path = REAL / f"{name}.yaml"
    if not path.exists():
        pytest.skip(f"{name} is not in {REAL}")
    return path


def test_intel_uses_its_own_thresholds():
    path = _real("intel_lab")
    meta = yaml.safe_load(path.read_text())
    assert (meta["occupied_thresh"], meta["free_thresh"]) == (0.2, 0.05)
    grid = load_map(path)
    pixels = np.frombuffer(path.with_suffix(".pgm").read_bytes()[-579 * 581:], np.uint8).reshape(581, 579)
    # Light grey 230 (p = 0.098) lies between the thresholds: unknown. With the standard
    # thresholds (0.65 / 0.196) it would be free, so this checks the YAML values are honoured.
    assert (pixels == 230).sum() > 10_000
    assert np.all(grid.data[::-1][pixels == 230] == -1)
    assert grid.rows == 581 and grid.cols == 579 and grid.resolution == 0.1


def test_willow_has_only_a_few_hundred_occupied_cells():
    grid = load_map(_real("willow_garage"))
    counts = grid.counts()
    # Anti-aliased grey walls: only the darkest pixels (v <= 89) pass p > 0.65.
    assert 300 < counts["occupied"] < 1000
    assert counts["occupied"] < 0.002 * grid.data.size


def test_izs_is_trinary_with_some_pure_white():
    path = _real("izs_campus_outdoor")
    grid = load_map(path)
    raw = path.with_suffix(".pgm").read_bytes()
    pixels = np.frombuffer(raw[-1668 * 1332:], np.uint8)
    values, counts = np.unique(pixels, return_counts=True)
    assert set(values.tolist()) == {0, 205, 254, 255}
    assert dict(zip(values.tolist(), counts.tolist()))[255] == 38
    c = grid.counts()
    assert c["occupied"] == (pixels == 0).sum()
    assert c["free"] == (pixels >= 254).sum()
    assert c["unknown"] == (pixels == 205).sum()


def test_map_info_of_real_maps_is_consistent_with_load():
    for yaml_file in REAL_YAMLS[:3]:
        info = map_info(yaml_file)
        grid = load_map(yaml_file)
        assert (info["rows"], info["cols"]) == grid.shape
        assert info["resolution"] == grid.resolution and info["origin"] == grid.origin
        assert info["name"] == yaml_file.stem and info["has_scans"] is False
        assert info["width_m"] == pytest.approx(grid.cols * grid.resolution)


def test_project_copies_are_byte_identical_and_attributed():
    sources = (PROJECT_REAL / "SOURCES.md").read_text()
    for name in REDISTRIBUTED:
        for suffix in (".pgm", ".yaml"):
            copy = PROJECT_REAL / f"{name}{suffix}"
            assert copy.is_file()
            if SHARED_REAL.is_dir():
                assert copy.read_bytes() == (SHARED_REAL / f"{name}{suffix}").read_bytes()
        assert f"### {name}.pgm" in sources
    assert not list(PROJECT_REAL.glob("belgioioso*"))
    assert "belgioioso" in sources and "not redistributed" in sources.lower()


# ---------------------------------------------------------------------------------------------
# Round trips and what save writes
# ---------------------------------------------------------------------------------------------
def _grid(seed=0, shape=(7, 11)):
    rng = np.random.default_rng(seed)
    data = rng.choice(np.array([-1, 0, 100], np.int8), size=shape)
    return OccupancyGrid(data, 0.05, (-12.345678901234, 3.0000000001, 0.7), "g")


@pytest.mark.parametrize("fmt", ["pgm", "png"])
def test_save_load_round_trip_is_bit_exact(tmp_path, fmt):
    grid = _grid()
    out = tmp_path / "out.yaml"
    save_map(grid, out, image_format=fmt)
    back = load_map(out)
    assert np.array_equal(back.data, grid.data)
    assert back.resolution == grid.resolution and back.origin == grid.origin
    assert back.name == "out"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["out.yaml", f"out.{fmt}"])


def test_saved_files_are_what_map_saver_writes(tmp_path):
    grid = _grid(1)
    out = tmp_path / "saved.yaml"
    save_map(grid, out)
    meta = yaml.safe_load(out.read_text())
    assert meta["image"] == "saved.pgm"  # relative, beside the YAML
    assert meta["mode"] == "trinary" and meta["negate"] == 0
    assert (meta["occupied_thresh"], meta["free_thresh"]) == (0.65, 0.196)
    assert meta["resolution"] == 0.05 and meta["origin"] == list(grid.origin)
    raw = (tmp_path / "saved.pgm").read_bytes()
    assert raw.startswith(b"P5\n")
    pixels = np.frombuffer(raw[-grid.data.size:], np.uint8).reshape(grid.shape)
    expected = np.select([grid.data == 100, grid.data == 0], [0, 254], 205)[::-1]
    assert np.array_equal(pixels, expected)  # top image row = last grid row
    ref, _ = reference_cells(out)  # the saved pair also passes the independent reference
    assert np.array_equal(ref, grid.data)


def test_probabilities_are_saved_as_their_state(tmp_path):
    grid = OccupancyGrid(np.array([[1, 49, 50, 99, -1, 0]], np.int8), 0.1)
    save_map(grid, tmp_path / "p.yaml")
    assert load_map(tmp_path / "p.yaml").data.tolist() == [[0, 0, 100, 100, -1, 0]]


def test_tiny_and_huge_numbers_survive_the_yaml(tmp_path):
    grid = OccupancyGrid(np.zeros((2, 3), np.int8), 1e-5, (1e-300, -123456789.123456789, -math.pi))
    save_map(grid, tmp_path / "n.yaml")
    back = load_map(tmp_path / "n.yaml")
    assert back.resolution == 1e-5 and back.origin == grid.origin


def test_save_refuses_to_overwrite_an_input(tmp_path):
    grid = _grid()
    first = tmp_path / "a.yaml"
    save_map(grid, first)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    other = _grid(5)
    with pytest.raises(InputError, match="a.yaml"):
        save_map(other, first, inputs=[first])
    # The image an input YAML names is protected as well.
    (tmp_path / "b.yaml").write_text((tmp_path / "a.yaml").read_text())
    with pytest.raises(InputError, match="a.pgm"):
        save_map(other, tmp_path / "a.yml", inputs=[tmp_path / "b.yaml"])
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.name != "b.yaml"} == before


def test_failed_save_leaves_targets_and_no_temp_files(tmp_path, monkeypatch):
    out = tmp_path / "m.yaml"
    save_map(_grid(), out)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}

    real_replace, calls = os.replace, []

    def disk_full_on_the_yaml(src, dst):  # the image is already in place when the YAML fails
        if str(dst).endswith("m.yaml") and not calls:
            calls.append(dst)
            raise OSError(28, "No space left on device", str(src))
        return real_replace(src, dst)

    monkeypatch.setattr(os, "replace", disk_full_on_the_yaml)
    with pytest.raises(InputError, match=r"m.yaml: cannot be written \(No space left on device\)"):
        save_map(_grid(3), out)
    monkeypatch.undo()
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


def test_save_rejects_bad_requests(tmp_path):
    grid = _grid()
    with pytest.raises(InputError, match="bmp"):
        save_map(grid, tmp_path / "a.yaml", image_format="bmp")
    with pytest.raises(InputError, match="a.pgm"):
        save_map(grid, tmp_path / "a.pgm")
    with pytest.raises(InputError, match="does not exist"):
        save_map(grid, tmp_path / "missing" / "a.yaml")
    with pytest.raises(InputError, match="no cells"):
        save_map(OccupancyGrid(np.zeros((0, 4), np.int8), 0.1), tmp_path / "e.yaml")
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------------------------
# Image flavours and modes
# ---------------------------------------------------------------------------------------------
def test_row_flip_orientation(tmp_path):
    pixels = np.full((4, 6), 254, np.uint8)
    pixels[0, 0] = 0  # image top-left corner
    grid = load_map(write_map(tmp_path, "corner", p5(pixels)))
    assert grid.data[grid.rows - 1, 0] == 100
    assert (grid.data == 100).sum() == 1
    x, y = grid.cell_to_world(grid.rows - 1, 0)
    assert y == pytest.approx(grid.bounds()[3] - grid.resolution / 2)  # highest y
    assert x == pytest.approx(grid.resolution / 2)


def test_threshold_boundaries_follow_map_server(tmp_path):
    v = np.arange(256, dtype=np.uint8).reshape(16, 16)
    grid = load_map(write_map(tmp_path, "ramp", p5(v)))
    p = (255.0 - v) / 255.0
    expected = np.where(p > 0.65, 100, np.where(p < 0.196, 0, -1))[::-1]
    assert np.array_equal(grid.data, expected)
    flat = grid.data[::-1].ravel()
    assert flat[89] == 100 and flat[90] == -1 and flat[204] == -1 and flat[205] == -1 and flat[206] == 0


def test_plain_pgm_equals_binary_pgm(tmp_path):
    rng = np.random.default_rng(4)
    pixels = rng.integers(0, 256, (5, 9)).astype(np.uint8)
    body = "\n".join(" ".join(str(v) for v in row) for row in pixels)
    plain = f"P2\n# made by hand\n9 # width\n5\n255\n{body}\n".encode()
    a = load_map(write_map(tmp_path, "plain", plain))
    b = load_map(write_map(tmp_path, "binary", p5(pixels)))
    assert np.array_equal(a.data, b.data)


def test_sixteen_bit_and_small_maxval_pgm(tmp_path):
    v16 = np.array([[0, 65535, 20000, 60000]], np.uint16)
    grid = load_map(write_map(tmp_path, "deep", p5(v16, maxval=65535)))
    p = (65535.0 - v16) / 65535.0
    assert grid.data.tolist() == np.where(p > 0.65, 100, np.where(p < 0.196, 0, -1)).tolist()
    small = np.array([[0, 15, 7]], np.uint8)  # maxval 15: 15 is white
    assert load_map(write_map(tmp_path, "small", p5(small, maxval=15))).data.tolist() == [[100, 0, -1]]


def test_png_grey_rgb_and_alpha(tmp_path):
    grey = np.array([[0, 205, 254]], np.uint8)
    g = load_map(write_map(tmp_path, "grey", png(grey, 0), "grey.png"))
    assert g.data.tolist() == [[100, -1, 0]]
    # RGB: channels are averaged. (0, 0, 255) -> 85 -> p = 0.667 occupied; (0, 255, 255) -> 170
    # -> p = 0.333 unknown; (255, 255, 250) -> free.
    rgb = np.array([[[0, 0, 255], [0, 255, 255], [255, 255, 250]]], np.uint8)
    c = load_map(write_map(tmp_path, "rgb", png(rgb, 2), "rgb.png"))
    assert c.data.tolist() == [[100, -1, 0]]
    # Grey + alpha in trinary mode: map_server averages R = G = B = grey with the opacity,
    # (3 g + a) / 4. So opaque 205 gives 217.5 -> p 0.147: free (a map_server quirk, kept);
    # grey 205 at alpha 0 gives 153.75 -> p 0.397 unknown; opaque black gives 63.75 -> p 0.75
    # occupied; white at alpha 0 gives 191.25 -> p 0.25 unknown; opaque 160 gives 183.75 ->
    # p 0.279 unknown.
    ga = np.array([[[205, 255], [205, 0], [0, 255], [255, 0], [160, 255]]], np.uint8)
    a = load_map(write_map(tmp_path, "ga", png(ga, 4), "ga.png"))
    assert a.data.tolist() == [[0, -1, 100, -1, -1]]
    rgba = np.array([[[0, 0, 0, 255], [255, 255, 255, 255], [100, 100, 100, 255]]], np.uint8)
    r = load_map(write_map(tmp_path, "rgba", png(rgba, 6), "rgba.png"))
    # (3*100 + 255) / 4 = 138.75 -> p = 0.456 unknown
    assert r.data.tolist() == [[100, 0, -1]]
    deep = np.array([[0, 65535]], np.uint16)
    assert load_map(write_map(tmp_path, "deep", png(deep, 0, 16), "deep.png")).data.tolist() == [[100, 0]]


def test_negate(tmp_path):
    pixels = np.array([[0, 255, 128]], np.uint8)
    grid = load_map(write_map(tmp_path, "neg", p5(pixels), negate=1))
    assert grid.data.tolist() == [[0, 100, -1]]
    assert load_map(write_map(tmp_path, "neg_b", p5(pixels), negate=True)).data.tolist() == [[0, 100, -1]]
    # quoted, as numbers may be: it was refused ("'negate' must be 0 or 1, got '1'")
    assert load_map(write_map(tmp_path, "neg_q", p5(pixels), negate="1")).data.tolist() == [[0, 100, -1]]


def test_scale_mode(tmp_path):
    v = np.array([[0, 255, 150, 120, 200]], np.uint8)
    grid = load_map(write_map(tmp_path, "scale", p5(v), mode="scale"))
    p = (255.0 - v[0, 2:]) / 255.0
    middle = np.rint((p - 0.196) / (0.65 - 0.196) * 100).astype(int).tolist()
    assert grid.data.tolist() == [[100, 0, *middle]]
    assert all(1 <= m <= 99 for m in middle)
    # Pixels that are not fully opaque are unknown in scale mode, whatever their shade.
    ga = np.array([[[0, 255], [0, 254], [255, 0], [150, 255]]], np.uint8)
    g = load_map(write_map(tmp_path, "scale_a", png(ga, 4), "scale_a.png", mode="scale"))
    assert g.data.tolist() == [[100, -1, -1, middle[0]]]


def test_raw_mode(tmp_path):
    v = np.array([[0, 1, 50, 100, 101, 205, 255]], np.uint8)
    grid = load_map(write_map(tmp_path, "raw", p5(v), mode="raw"))
    assert grid.data.tolist() == [[0, 1, 50, 100, -1, -1, -1]]
    # negate does not apply to raw values (nav2_map_server)
    assert load_map(write_map(tmp_path, "raw_n", p5(v), mode="raw", negate=1)).data.tolist() == \
        [[0, 1, 50, 100, -1, -1, -1]]


def test_image_paths_relative_and_absolute(tmp_path):
    sub = tmp_path / "img"
    sub.mkdir()
    pixels = np.array([[0, 254]], np.uint8)
    (sub / "x.pgm").write_bytes(p5(pixels))
    rel = write_map(tmp_path, "rel", p5(pixels), "unused.pgm", image="img/x.pgm")
    ab = write_map(tmp_path, "ab", p5(pixels), "unused2.pgm", image=str(sub / "x.pgm"))
    assert load_map(rel).data.tolist() == load_map(ab).data.tolist() == [[100, 0]]
    assert load_map(str(rel)).name == "rel"


def test_map_info_reads_the_header_only(tmp_path):
    good = np.zeros((3, 4), np.uint8)
    path = write_map(tmp_path, "cut", p5(good)[:-5])  # raster truncated
    info = map_info(path)
    assert (info["rows"], info["cols"], info["image_type"]) == (3, 4, "P5")
    with pytest.raises(MapFormatError, match="truncated"):
        load_map(path)
    assert info["has_scans"] is False
    (tmp_path / "cut.scans.npz").write_bytes(b"")
    assert map_info(path)["has_scans"] is True


# ---------------------------------------------------------------------------------------------
# Bad input: one MapFormatError naming the file
# ---------------------------------------------------------------------------------------------
GOOD = p5(np.array([[0, 205, 254]], np.uint8))


def _bad_cases():
    # (id, builder(folder) -> yaml path, file name the message must contain, extra text)
    def yaml_text(text):
        def build(d):
            (d / "m.pgm").write_bytes(GOOD)
            (d / "m.yaml").write_text(text)
            return d / "m.yaml"
        return build

    def keys(**kw):
        return lambda d: write_map(d, "m", GOOD, **kw)

    def image(data, name="m.pgm"):
        return lambda d: write_map(d, "m", data, name)

    huge_png = png(np.zeros((1, 1), np.uint8), 0, ihdr_size=(100_000, 100_000))
    good_png = png(np.zeros((4, 4), np.uint8), 0)
    return [
        ("missing yaml", lambda d: d / "nothing.yaml", "nothing.yaml", "no such"),
        ("yaml is a directory", lambda d: (d / "dir.yaml").mkdir() or d / "dir.yaml", "dir.yaml", "directory"),
        ("yaml is an image", lambda d: ((d / "m.pgm").write_bytes(GOOD), d / "m.pgm")[1], "m.pgm", "image"),
        ("unparsable yaml", yaml_text("image: m.pgm\nresolution: [0.05\n"), "m.yaml", "YAML"),
        ("binary yaml", yaml_text("image: m.pgm\x00\x01\x02"), "m.yaml", "YAML"),
        ("yaml not a mapping", yaml_text("- 1\n- 2\n"), "m.yaml", "mapping"),
        ("empty yaml", yaml_text(""), "m.yaml", "mapping"),
        ("missing keys", keys(resolution=None, origin=None), "m.yaml", "'resolution', 'origin'"),
        ("missing negate", keys(negate=None), "m.yaml", "negate"),
        ("negative resolution", keys(resolution=-0.05), "m.yaml", "resolution"),
        ("zero resolution", keys(resolution=0), "m.yaml", "resolution"),
        ("text resolution", keys(resolution="fine"), "m.yaml", "resolution"),
        ("bool resolution", keys(resolution=True), "m.yaml", "resolution"),
        ("nan resolution", keys(resolution=float("nan")), "m.yaml", "resolution"),
        ("origin of 2", keys(origin=[0.0, 0.0]), "m.yaml", "origin"),
        ("origin not numbers", keys(origin=[0.0, "a", 0.0]), "m.yaml", "origin"),
        ("origin scalar", keys(origin=3.0), "m.yaml", "origin"),
        ("yaw in degrees", keys(origin=[0.0, 0.0, 90.0]), "m.yaml",
         "yaw 90 is more than a full turn: give it in radians"),
        ("occupied above 1", keys(occupied_thresh=1.5), "m.yaml", "occupied_thresh"),
        ("free below 0", keys(free_thresh=-0.1), "m.yaml", "free_thresh"),
        ("free above occupied", keys(free_thresh=0.7, occupied_thresh=0.65), "m.yaml", "smaller"),
        ("free equals occupied", keys(free_thresh=0.5, occupied_thresh=0.5), "m.yaml", "smaller"),
        ("negate 2", keys(negate=2), "m.yaml", "negate"),
        ("unknown mode", keys(mode="fuzzy"), "m.yaml", "mode"),
        ("image not a string", keys(image=5), "m.yaml", "image"),
        ("image empty", keys(image=""), "m.yaml", "image"),
        ("missing image", keys(image="gone.pgm"), "gone.pgm", "does not exist"),
        ("image is a directory", lambda d: (d / "sub").mkdir() or write_map(d, "m", GOOD, image="sub"),
         "sub", "directory"),
        ("empty image", image(b""), "m.pgm", "empty"),
        ("truncated raster", image(GOOD[:-1]), "m.pgm", "truncated"),
        ("truncated header", image(b"P5\n3 1\n"), "m.pgm", "truncated"),
        ("header only magic", image(b"P5"), "m.pgm", "P5"),
        ("non-numeric width", image(b"P5\nthree 1\n255\n\x00\x00\x00"), "m.pgm", "width"),
        ("width glued to junk", image(b"P5\n3x 1\n255\n\x00\x00\x00"), "m.pgm", "width"),
        ("zero width", image(b"P5\n0 1\n255\n"), "m.pgm", "0 x 1"),
        ("maxval 0", image(b"P5\n3 1\n0\n\x00\x00\x00"), "m.pgm", "maxval"),
        ("maxval too big", image(b"P5\n3 1\n70000\n" + bytes(6)), "m.pgm", "maxval"),
        ("value above maxval", image(b"P5\n3 1\n15\n\x00\x10\x00"), "m.pgm", "maxval"),
        ("huge header dims", image(b"P5\n100000 100000\n255\n\x00"), "m.pgm", str(MAX_CELLS)),
        ("huge dims below limit", image(b"P5\n14000 14000\n255\n\x00"), "m.pgm", "truncated"),
        ("endless header", image(b"P5\n" + b"#" * 70_000 + b"\n3 1\n255\n\x00\x00\x00"), "m.pgm", "header"),
        ("plain pgm short", image(b"P2\n3 1\n255\n0 1\n"), "m.pgm", "truncated"),
        ("plain pgm junk", image(b"P2\n3 1\n255\n0 x 1\n"), "m.pgm", "whole number"),
        ("plain pgm above maxval", image(b"P2\n3 1\n255\n0 256 1\n"), "m.pgm", "maxval"),
        ("plain pgm negative", image(b"P2\n3 1\n255\n0 -1 1\n"), "m.pgm", "maxval"),
        ("ppm", image(b"P6\n1 1\n255\n\x00\x00\x00"), "m.pgm", "PPM"),
        ("jpeg", image(b"\xff\xd8\xff\xe0" + bytes(40), "m.jpg"), "m.jpg", "PGM"),
        ("truncated png", image(good_png[:40], "m.png"), "m.png", "PNG"),
        ("png bad checksum", image(good_png[:45] + bytes([good_png[45] ^ 0xFF]) + good_png[46:], "m.png"),
         "m.png", "checksum"),
        ("png without IHDR", image(b"\x89PNG\r\n\x1a\n" + bytes(30), "m.png"), "m.png", "IHDR"),
        ("huge png dims", image(huge_png, "m.png"), "m.png", str(MAX_CELLS)),
        ("image is another map's yaml",
         lambda d: (write_map(d, "other", GOOD), write_map(d, "m", GOOD, image="other.yaml"))[1],
         "other.yaml", "a map YAML, not an image"),
        ("image is a map yaml in flow style after ---",
         lambda d: ((d / "other.yaml").write_text("---\n{image: m.pgm, resolution: 0.05}\n"),
                    write_map(d, "m", GOOD, image="other.yaml"))[1],
         "other.yaml", "a map YAML, not an image"),
    ]


BAD = _bad_cases()


@pytest.mark.parametrize("build, filename, needle", [c[1:] for c in BAD], ids=[c[0] for c in BAD])
def test_bad_input_gives_one_clear_error(tmp_path, build, filename, needle):
    path = build(tmp_path)
    with pytest.raises(MapFormatError) as info:
        load_map(path)
    message = str(info.value)
    assert filename in message
    assert needle in message
    assert "\n" not in message
    assert info.value.__cause__ is None  # no chained deep traceback
    assert info.value.__suppress_context__ or info.value.__context__ is None


@pytest.mark.parametrize("build", [c[1] for c in BAD if c[2] not in ("m.yaml", "nothing.yaml", "dir.yaml")
                                   and c[0] != "yaml is an image"],
                         ids=[c[0] for c in BAD if c[2] not in ("m.yaml", "nothing.yaml", "dir.yaml")
                              and c[0] != "yaml is an image"])
def test_a_fault_of_the_image_names_the_map_yaml_first(tmp_path, build):
    """Among several maps given, the user named the YAML: the line starts with it, whichever
    file is at fault."""
    path = build(tmp_path)
    with pytest.raises(MapFormatError) as info:
        load_map(path)
    assert str(info.value).startswith(str(path) + ":")
    try:
        map_info(path)                      # reads the header only: a bad raster passes it
    except MapFormatError as exc:
        assert str(exc).startswith(str(path) + ":")


def test_map_info_reports_the_same_errors(tmp_path):
    with pytest.raises(MapFormatError, match="nothing.yaml"):
        map_info(tmp_path / "nothing.yaml")
    path = write_map(tmp_path, "m", b"P5\n100000 100000\n255\n")
    with pytest.raises(MapFormatError, match=str(MAX_CELLS)):
        map_info(path)


# ---------------------------------------------------------------------------------------------
# Property tests
# ---------------------------------------------------------------------------------------------
def _load_image_bytes(data: bytes, suffix: str = ".pgm"):
    with tempfile.TemporaryDirectory() as d:
        path = write_map(Path(d), "m", data, f"m{suffix}")
        try:
            return load_map(path)
        except MapFormatError as exc:
            assert "m" + suffix in str(exc) or "m.yaml" in str(exc)
            return exc


@settings(max_examples=150, deadline=None)
@given(prefix=st.sampled_from([b"", b"P5", b"P5\n", b"P2\n", b"P5 4 3 255\n", b"P2 2 2 9\n",
                               b"\x89PNG\r\n\x1a\n"]),
       body=st.binary(max_size=120))
def test_random_bytes_never_raise_anything_else(prefix, body):
    result = _load_image_bytes(prefix + body)
    if isinstance(result, OccupancyGrid):
        assert result.data.dtype == np.int8 and set(np.unique(result.data).tolist()) <= {-1, 0, 100}


@settings(max_examples=120, deadline=None)
@given(width=st.integers(0, 10**12), height=st.integers(0, 10**12), maxval=st.integers(0, 70000),
       body=st.binary(max_size=64), plain=st.booleans())
def test_random_header_dimensions(width, height, maxval, body, plain):
    magic = b"P2" if plain else b"P5"
    result = _load_image_bytes(magic + f"\n{width} {height}\n{maxval}\n".encode() + body)
    if isinstance(result, OccupancyGrid):
        assert result.shape == (height, width) and 1 <= maxval <= 65535
    elif width * height > MAX_CELLS and 1 <= maxval <= 65535:
        assert str(MAX_CELLS) in str(result)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(rows=st.integers(1, 12), cols=st.integers(1, 12), seed=st.integers(0, 2**32 - 1),
       resolution=st.floats(1e-6, 1e3, allow_nan=False, allow_infinity=False),
       origin=st.tuples(st.floats(-1e9, 1e9), st.floats(-1e9, 1e9), st.floats(-math.pi, math.pi)),
       fmt=st.sampled_from(["pgm", "png"]))
def test_random_trinary_grids_round_trip(rows, cols, seed, resolution, origin, fmt):
    rng = np.random.default_rng(seed)
    data = rng.choice(np.array([-1, 0, 100], np.int8), size=(rows, cols))
    grid = OccupancyGrid(data, resolution, origin, "r")
    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / "r.yaml"
        save_map(grid, out, image_format=fmt)
        back = load_map(out)
        assert sorted(p.name for p in Path(d).iterdir()) == sorted(["r.yaml", f"r.{fmt}"])
    assert np.array_equal(back.data, grid.data)
    assert back.resolution == grid.resolution
    assert back.origin == grid.origin


def test_what_is_not_a_path_or_a_grid_is_one_clear_error(tmp_path):
    """None, a number or a grid given as a path, and save_map's arguments swapped, raised
    pathlib's TypeError naming no argument."""
    from fusionkit.errors import ScanLogError
    from fusionkit.scanlog import ScanLog, load_scans, save_scans, scans_path_for
    grid = _grid()
    for call, said in ((lambda: load_map(None), "the map's YAML must be a path"),
                       (lambda: load_map(grid), "got OccupancyGrid"),
                       (lambda: map_info(5), "the map's YAML must be a path"),
                       (lambda: scans_path_for(None), "the map's YAML must be a path"),
                       (lambda: scans_path_for("/"), "/: is a folder, not a map's YAML"),
                       (lambda: save_map(str(tmp_path / "m.yaml"), grid), "writes an OccupancyGrid first")):
        with pytest.raises(InputError, match=said):
            call()
    with pytest.raises(ScanLogError, match="the scan log must be a path"):
        load_scans(None)
    with pytest.raises(ScanLogError, match="writes a ScanLog, got ndarray"):
        save_scans(tmp_path / "s.scans.npz", np.zeros(3))
    log = ScanLog(np.zeros((1, 3)), np.ones((1, 4)), 0.0, 0.5, 10.0)
    with pytest.raises(ScanLogError, match=r"got str \(the path comes first here, unlike save_map"):
        save_scans(log, str(tmp_path / "s.scans.npz"))   # in save_map's order
    assert list(tmp_path.iterdir()) == []
