"""The simulator's ground-truth worlds: seeded, trinary, closed and connected."""

from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

from fusionkit.errors import InputError
from fusionkit.grid import FREE, OCCUPIED, UNKNOWN
from fusionkit.mapio import load_map
from fusionkit.worlds import (DEFAULT_SIZE, WORLDS, default_world, make_cave, make_office,
                              make_warehouse, make_world)

REPO = Path(__file__).resolve().parents[1]
EIGHT = np.ones((3, 3), bool)


@pytest.fixture(scope="module", params=sorted(WORLDS))
def kind(request):
    return request.param


def test_same_seed_same_world_other_seed_other_world(kind):
    a = make_world(kind, 3)
    b = make_world(kind, 3)
    c = make_world(kind, 4)
    assert np.array_equal(a.data, b.data)
    assert a.data.shape == c.data.shape
    assert not np.array_equal(a.data, c.data)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_free_space_is_one_region_closed_by_walls(kind, seed):
    g = make_world(kind, seed)
    assert set(np.unique(g.data)) == {UNKNOWN, FREE, OCCUPIED}
    free = g.data == FREE
    _, n = ndimage.label(free)  # 4-connected
    assert n == 1, f"{kind} seed {seed}: {n} separate free regions"
    # free cells never touch unknown ones: walls enclose the free space
    assert not (ndimage.binary_dilation(free, EIGHT) & (g.data == UNKNOWN)).any()
    # walls are a skin at most 2 cells (0.2 m) deep: every occupied cell is near free space
    near = ndimage.binary_dilation(free, EIGHT, iterations=2)
    assert near[g.data == OCCUPIED].all()
    # a substantial part of the grid is drivable
    assert free.mean() > 0.3


def test_robots_fit_through_every_door(kind):
    """With 0.3 m clearance from walls, the drivable cells still form one region (nearly)."""
    g = make_world(kind, 0)
    edt = ndimage.distance_transform_edt(g.data == FREE) * g.resolution
    nav = edt >= 0.3
    lab, n = ndimage.label(nav)
    sizes = np.bincount(lab.ravel())[1:]
    assert sizes.max() >= 0.97 * nav.sum()


def test_size_and_resolution_set_the_grid():
    g = make_office(0, size=(20.0, 16.0), resolution=0.05)
    assert g.data.shape == (320, 400)
    assert g.resolution == 0.05 and g.origin == (0.0, 0.0, 0.0)
    assert g.name == "office"
    w = make_warehouse(1, size=(30.0, 20.0), resolution=0.2)
    assert w.data.shape == (100, 150)
    c = make_cave(2, size=(12.0, 10.0))
    assert c.data.shape == (100, 120)


def test_office_is_a_building_of_many_rooms():
    g = default_world()
    assert g.data.shape == (300, 400)
    # rooms: free regions left when doors are closed, i.e. after eroding away the door gaps
    free = g.data == FREE
    closed = ndimage.binary_opening(free, np.ones((13, 13), bool))  # 1.3 m: closes 0.9-1.2 m doors
    _, rooms = ndimage.label(closed)
    assert rooms >= 20
    # the outer 0.5 m is unknown, the building's outer wall occupied
    assert (g.data[:5, :] == UNKNOWN).all() and (g.data[:, :5] == UNKNOWN).all()
    assert (g.data[5, 5:-5] == OCCUPIED).all()


def test_repository_maps_are_the_generated_worlds():
    for kind in WORLDS:
        path = REPO / "maps" / f"{kind}.yaml"
        assert path.is_file(), f"{path} is missing: run python -m fusionkit.worlds --out maps"
        on_disk = load_map(path)
        fresh = make_world(kind, 0, DEFAULT_SIZE, 0.1)
        assert np.array_equal(on_disk.data, fresh.data)
        assert on_disk.resolution == fresh.resolution and on_disk.origin == fresh.origin
    assert np.array_equal(load_map(REPO / "maps" / "office.yaml").data, default_world().data)


def test_world_writer_command(tmp_path, capsys):
    from fusionkit.cli._worlds import main

    assert main(["--out", str(tmp_path / "w"), "--kinds", "cave", "--seed", "5"]) == 0
    g = load_map(tmp_path / "w" / "cave.yaml")
    assert np.array_equal(g.data, make_cave(5).data)
    assert "cave.yaml" in capsys.readouterr().out
    assert main(["--out", str(tmp_path / "w"), "--kinds", "office", "--size", "5", "5"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "at least" in err[0]


@pytest.mark.parametrize("call, words", [
    (lambda: make_world("castle"), "unknown world kind"),
    (lambda: make_office(0, size=(8, 8)), "at least"),
    (lambda: make_cave(0, resolution=0.0), "resolution"),
    (lambda: make_warehouse(-1), "seed"),
    (lambda: make_world("office", 2.7), "world seed must be a whole number"),   # was taken as 2
    (lambda: make_world("cave", "1"), "world seed must be a whole number"),
    (lambda: make_world("cave", True), "world seed must be a whole number"),
    (lambda: make_world("cave", None), "world seed must be a whole number"),
    (lambda: make_office(0, size=(1e5, 1e5)), "cells"),
])
def test_bad_world_requests(call, words):
    with pytest.raises(InputError, match=words):
        call()
