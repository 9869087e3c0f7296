"""The multi-robot LIDAR simulator, its run directory and ``fusionkit simulate``."""

import json
import math

import numpy as np
import pytest
from scipy import ndimage

from fusionkit.cli import main
from fusionkit.errors import InputError
from fusionkit.grid import OccupancyGrid
from fusionkit.mapio import load_map, save_map
from fusionkit.resample import resample
from fusionkit.scanlog import load_scans
from fusionkit.simulate import (LidarConfig, MotionConfig, Simulation, SimulationConfig,
                                cast_scans, simulate, write_run)
from fusionkit.transform import Transform2D
from fusionkit.worlds import make_cave, make_office

from naive_simulate import slab_ranges

SMALL = SimulationConfig(robots=2, poses=300, seed=3)


@pytest.fixture(scope="module")
def office():
    return make_office(0)


@pytest.fixture(scope="module")
def sim(office):
    return simulate(office, SMALL)


def random_free_poses(world, n, seed):
    rng = np.random.default_rng(seed)
    r, c = np.nonzero(world.free_mask())
    k = rng.choice(r.size, n, replace=False)
    xy = world.cell_to_world(r[k] + rng.uniform(-0.5, 0.5, n), c[k] + rng.uniform(-0.5, 0.5, n))
    return np.column_stack([xy, rng.uniform(-math.pi, math.pi, n)])


# -- the sensor ---------------------------------------------------------------------------------
def test_lidar_angles_follow_laserscan():
    full = LidarConfig(beams=360)
    assert full.angle_min == -math.pi
    assert full.angle_increment == pytest.approx(2 * math.pi / 360)
    assert full.angles[-1] < math.pi  # no duplicated beam at +pi
    fan = LidarConfig(beams=5, fov_deg=90)
    assert np.degrees(fan.angles) == pytest.approx([-45, -22.5, 0, 22.5, 45])


@pytest.mark.parametrize("world_fn, origin", [
    (lambda: make_office(0), (0.0, 0.0, 0.0)),
    (lambda: make_cave(1, size=(20, 15)), (-3.0, 2.0, 0.4)),  # a rotated map origin
])
def test_ray_caster_matches_slab_reference(world_fn, origin):
    w = world_fn()
    w = OccupancyGrid(w.data, w.resolution, origin, w.name)
    lidar = LidarConfig(beams=72, max_range=6.0, range_noise=0.0)
    poses = random_free_poses(w, 25, seed=1)
    fast = cast_scans(w, poses, lidar)
    slow = slab_ranges(w, poses, lidar.angles, lidar.max_range)
    assert fast.dtype == np.float32 and fast.shape == slow.shape
    assert np.array_equal(np.isinf(fast), np.isinf(slow))
    assert np.isfinite(fast).mean() > 0.5
    fin = np.isfinite(slow)
    np.testing.assert_allclose(fast[fin], slow[fin], atol=2e-5)


def test_only_occupied_cells_return_beams():
    data = np.zeros((40, 40), np.int8)
    data[:, 30] = -1  # unknown strip to the east, an occupied wall behind it
    data[:, 35] = 100
    data[:, 5] = 100  # occupied wall to the west
    w = OccupancyGrid(data, 0.1)
    r = cast_scans(w, [[2.05, 2.0, 0.0], [2.05, 2.0, math.pi]], LidarConfig(beams=4, range_noise=0))
    # beams: -pi, -pi/2, 0, pi/2 (relative to the heading); the grid ends north and south
    assert r[0, 2] == pytest.approx(3.5 - 2.05, abs=1e-5)  # east: through unknown to the wall
    assert r[0, 0] == pytest.approx(2.05 - 0.6, abs=1e-5)  # west: wall cell 5 ends at x = 0.6
    assert np.isinf(r[0, 1]) and np.isinf(r[0, 3])  # off the grid: no return
    assert r[1, 2] == pytest.approx(r[0, 0], abs=1e-6)
    short = cast_scans(w, [[2.05, 2.0, 0.0]], LidarConfig(beams=4, max_range=1.4, range_noise=0))
    assert np.isinf(short[0]).all()  # both walls beyond 1.4 m


def test_range_noise_has_the_configured_spread(office):
    poses = random_free_poses(office, 60, seed=2)
    lidar = LidarConfig(range_noise=0.05)
    exact = cast_scans(office, poses, LidarConfig(range_noise=0.0))
    noisy = cast_scans(office, poses, lidar, rng=np.random.default_rng(0))
    both = np.isfinite(exact) & np.isfinite(noisy) & (exact > 0.3) & (exact < 7.5)
    d = noisy[both] - exact[both]
    assert abs(d.mean()) < 0.005
    assert d.std() == pytest.approx(0.05, rel=0.1)
    assert (noisy[np.isfinite(noisy)] <= lidar.max_range).all()


# -- the robots ---------------------------------------------------------------------------------
def test_result_shape_and_own_frames(sim, office):
    assert isinstance(sim, Simulation) and len(sim.robots) == 2
    for k, r in enumerate(sim.robots):
        assert r.name == f"robot_{k + 1}"
        assert r.scans.poses.shape == (300, 3) and r.scans.ranges.shape == (300, 360)
        assert r.scans.poses[0].tolist() == [0.0, 0.0, 0.0]
        assert r.trajectory.shape == (300, 3)
        # without drift, the recorded poses are the true ones seen from the start pose
        assert r.transform.is_close(Transform2D(*r.trajectory[0]))
        np.testing.assert_allclose(r.transform.apply_pose(r.scans.poses)[:, :2], r.trajectory[:, :2],
                                   atol=1e-9)
        steps = np.hypot(*np.diff(r.trajectory[:, :2], axis=0).T)
        assert r.path_length == pytest.approx(steps.sum())
        assert r.path_length > 0.5 * 300 * MotionConfig().step  # it moved, not stuck
        assert r.grid.resolution == office.resolution


def test_same_seed_same_run_other_seed_other_run(office, sim):
    again = simulate(office, SMALL)
    other = simulate(office, SimulationConfig(robots=2, poses=300, seed=4))
    for a, b, c in zip(sim.robots, again.robots, other.robots):
        assert np.array_equal(a.scans.poses, b.scans.poses)
        assert np.array_equal(a.scans.ranges, b.scans.ranges)
        assert np.array_equal(a.grid.data, b.grid.data)
        assert a.transform == b.transform
        assert not np.array_equal(a.trajectory, c.trajectory)
        assert not np.array_equal(a.scans.ranges, c.scans.ranges)


@pytest.mark.parametrize("mode", ["waypoint", "wander"])
def test_robots_never_enter_walls(office, mode):
    cfg = SimulationConfig(robots=3, poses=600, seed=5, motion=MotionConfig(mode=mode))
    s = simulate(office, cfg)
    wall_dist = ndimage.distance_transform_edt(office.free_mask()) * office.resolution
    for r in s.robots:
        rows, cols = office.world_to_cell(r.trajectory[:, :2])
        ri, ci = np.floor(rows).astype(int), np.floor(cols).astype(int)
        assert (office.data[ri, ci] == 0).all()
        assert wall_dist[ri, ci].min() >= cfg.motion.clearance - 1e-9
        # and straight moves between poses do not cut through walls either
        mid = (r.trajectory[1:, :2] + r.trajectory[:-1, :2]) / 2
        mr, mc = office.world_to_cell(mid)
        assert (office.data[np.floor(mr).astype(int), np.floor(mc).astype(int)] == 0).all()


def test_maps_agree_with_the_world(sim, office):
    """Robot maps moved into the world by their true transforms put walls on world walls."""
    walls = ndimage.binary_dilation(office.occupied_mask(), np.ones((3, 3), bool))
    for r in sim.robots:
        placed = resample(r.grid, r.transform, office)
        occ = placed.occupied_mask()
        assert occ.sum() > 300
        assert (occ & walls).sum() / occ.sum() >= 0.95
        free = placed.free_mask()
        assert (free & (office.data == 0)).sum() / free.sum() >= 0.97
    cov = sim.coverage()
    assert all(0.05 < c < 1 for c in cov.per_robot)
    assert cov.combined >= max(cov.per_robot)


def test_a_world_with_a_rotated_origin(office):
    """Map frames whose grid is rotated (origin yaw) work the same way."""
    w = OccupancyGrid(office.data, office.resolution, (-5.0, 3.0, 0.7), "rotated")
    s = simulate(w, SimulationConfig(robots=1, poses=300, seed=2))
    r = s.robots[0]
    rows, cols = w.world_to_cell(r.trajectory[:, :2])
    assert (w.data[np.floor(rows).astype(int), np.floor(cols).astype(int)] == 0).all()
    placed = resample(r.grid, r.transform, w)
    walls = ndimage.binary_dilation(w.occupied_mask(), np.ones((3, 3), bool))
    occ = placed.occupied_mask()
    assert occ.sum() > 300 and (occ & walls).sum() / occ.sum() >= 0.95


def test_odometry_drift_bends_the_recorded_path(office):
    cfg = SimulationConfig(robots=1, poses=400, seed=6,
                           motion=MotionConfig(drift_xy=0.02, drift_theta=0.01))
    s = simulate(office, cfg)
    exact = simulate(office, SimulationConfig(robots=1, poses=400, seed=6))
    r, e = s.robots[0], exact.robots[0]
    assert r.scans.poses[0].tolist() == [0.0, 0.0, 0.0]
    assert np.array_equal(r.trajectory, e.trajectory)  # the robot drove the same way
    assert np.array_equal(r.scans.ranges, e.scans.ranges)  # and saw the same
    err = np.hypot(*(r.scans.poses[:, :2] - e.scans.poses[:, :2]).T)
    assert err[1] < 0.05 and err[-1] > err[1]
    assert 0.01 < err[-1] < 5.0


def test_a_long_default_run_explores_the_office(office):
    """The paper's single robot knows about 80 % of its world after 5000 poses."""
    s = simulate(office, SimulationConfig(robots=1, poses=5000, seed=0, lidar=LidarConfig(beams=90)))
    assert s.coverage().per_robot[0] >= 0.7


# -- bad input ----------------------------------------------------------------------------------
@pytest.mark.parametrize("make, words", [
    (lambda: SimulationConfig(robots=0), "robots"),
    (lambda: SimulationConfig(robots=65), "robots"),
    (lambda: SimulationConfig(poses=3), "poses"),
    (lambda: SimulationConfig(seed=-1), "seed"),
    (lambda: SimulationConfig(robots=64, poses=1_000_000), "fewer"),
    (lambda: LidarConfig(beams=1), "beams"),
    (lambda: LidarConfig(fov_deg=0), "field of view"),
    (lambda: LidarConfig(max_range=-1), "range"),
    (lambda: MotionConfig(mode="fly"), "motion mode"),
    (lambda: MotionConfig(speed=0), "speed"),
    (lambda: MotionConfig(drift_xy=-0.1), "drift"),
])
def test_bad_settings_raise_input_error(make, words):
    with pytest.raises(InputError, match=words):
        make()


def test_worlds_without_room_raise_input_error():
    solid = OccupancyGrid(np.full((50, 50), 100, np.int8), 0.1, name="solid")
    with pytest.raises(InputError, match="no free cells"):
        simulate(solid, SMALL)
    closet = np.full((50, 50), 100, np.int8)
    closet[20:30, 20:30] = 0  # 1 m square: no spot 0.6 m from the walls
    with pytest.raises(InputError, match="start position"):
        simulate(OccupancyGrid(closet, 0.1, name="closet"), SMALL)


# -- the run directory (CONTRACTS section 5) -------------------------------------------------------
def test_write_run_layout_and_round_trip(sim, office, tmp_path):
    out = tmp_path / "run"
    truth_path = write_run(sim, out)
    assert truth_path == out / "truth.json"
    names = {p.name for p in out.iterdir()}
    assert names == {"robot_1.yaml", "robot_1.pgm", "robot_1.scans.npz",
                     "robot_2.yaml", "robot_2.pgm", "robot_2.scans.npz",
                     "world.yaml", "world.pgm", "truth.json"}
    truth = json.loads(truth_path.read_text())
    assert truth["world"] == "world.yaml" and truth["seed"] == 3
    assert [r["name"] for r in truth["robots"]] == ["robot_1", "robot_2"]
    world = load_map(out / truth["world"])
    assert np.array_equal(world.data, office.data) and world.resolution == office.resolution
    for entry, r in zip(truth["robots"], sim.robots):
        assert set(entry) >= {"name", "transform", "poses", "path_length_m"}
        assert entry["poses"] == 300
        assert entry["path_length_m"] == pytest.approx(r.path_length, abs=1e-3)
        assert Transform2D.from_dict(entry["transform"]).is_close(r.transform, atol=1e-8)
        g = load_map(out / f"{r.name}.yaml")
        assert np.array_equal(g.data, r.grid.data) and g.origin == r.grid.origin
        log = load_scans(out / f"{r.name}.scans.npz")
        assert np.array_equal(log.poses, r.scans.poses)
        assert np.array_equal(log.ranges, r.scans.ranges)
        assert log.angle_min == r.scans.angle_min and log.range_max == 8.0
    assert truth["config"]["robots"] == 2 and truth["config"]["lidar"]["beams"] == 360


def test_write_run_replaces_an_earlier_run_only(sim, office, tmp_path):
    out = tmp_path / "run"
    three = simulate(office, SimulationConfig(robots=3, poses=20, seed=1))
    write_run(three, out)
    (out / "notes.txt").write_text("mine")
    write_run(sim, out)  # two robots now: robot_3's files go, the user's notes stay
    names = {p.name for p in out.iterdir()}
    assert "robot_3.yaml" not in names and "robot_3.scans.npz" not in names
    assert "notes.txt" in names and "robot_2.yaml" in names
    assert len(json.loads((out / "truth.json").read_text())["robots"]) == 2
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary left

    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "thesis.tex").write_text("x")
    with pytest.raises(InputError, match="not empty"):
        write_run(sim, foreign)
    assert [p.name for p in foreign.iterdir()] == ["thesis.tex"]


def test_write_run_never_overwrites_its_world(sim, office, tmp_path):
    out = tmp_path / "run"
    write_run(sim, out)
    before = (out / "world.pgm").read_bytes()
    with pytest.raises(InputError, match="overwrite"):
        write_run(sim, out, world_path=out / "world.yaml")
    assert (out / "world.pgm").read_bytes() == before


# -- the command line ---------------------------------------------------------------------------
def test_cli_simulate_writes_a_run(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["simulate", "--world-kind", "cave", "--world-size", "20", "15", "--robots", "2",
                 "--poses", "200", "--beams", "90", "--seed", "2", "--out", str(out)])
    assert code == 0
    text = capsys.readouterr().out
    assert "robot_1" in text and "robot_2" in text and "covers" in text
    truth = json.loads((out / "truth.json").read_text())
    assert truth["seed"] == 2 and len(truth["robots"]) == 2
    assert load_map(out / "world.yaml").data.shape == (150, 200)
    assert load_scans(out / "robot_1.scans.npz").ranges.shape == (200, 90)


def test_cli_simulate_from_a_world_file(tmp_path, capsys):
    world = make_cave(0, size=(15, 12))
    save_map(world, tmp_path / "w.yaml")
    out = tmp_path / "run"
    assert main(["simulate", "--world", str(tmp_path / "w.yaml"), "--robots", "1", "--poses", "50",
                 "--quiet", "--out", str(out)]) == 0
    assert capsys.readouterr().out == ""
    truth = json.loads((out / "truth.json").read_text())
    assert truth["world_source"] == str(tmp_path / "w.yaml")
    assert np.array_equal(load_map(out / "world.yaml").data, world.data)


@pytest.mark.parametrize("args, words", [
    (["--world", "{tmp}/missing.yaml"], "missing.yaml"),
    (["--world", "{tmp}/solid.yaml"], "no free cells"),
    (["--range-noise", "5"], "range noise"),
])
def test_cli_bad_input_is_one_line_and_exit_2(tmp_path, capsys, args, words):
    save_map(OccupancyGrid(np.full((30, 30), 100, np.int8), 0.1), tmp_path / "solid.yaml")
    args = [a.format(tmp=tmp_path) for a in args]
    code = main(["simulate", *args, "--robots", "1", "--poses", "10", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and words in err[0] and err[0].startswith("fusionkit simulate: error:")
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("args", [["--robots", "0"], ["--poses", "3"], ["--beams", "x"]])
def test_cli_rejects_out_of_range_options(tmp_path, capsys, args):
    with pytest.raises(SystemExit) as exc:
        main(["simulate", *args, "--out", str(tmp_path / "o")])
    assert exc.value.code == 2
    assert "error: argument" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_fk_simulate_is_callable_even_after_the_module_was_imported():
    import importlib

    import fusionkit as fk

    module = importlib.import_module("fusionkit.simulate")   # binds fk.simulate to the module
    world = fk.default_world()
    cfg = fk.SimulationConfig(robots=2, poses=60, seed=3)
    a, b = fk.simulate(world, cfg), module.simulate(world, cfg)
    assert len(a.robots) == 2
    assert all(np.array_equal(x.grid.data, y.grid.data) for x, y in zip(a.robots, b.robots))


def test_fk_resample_is_callable_even_after_the_module_was_imported():
    """fk.resample, exported as a function, was the module (not callable) once anything had
    imported fusionkit.resample: fk.fuse_maps, fk.merge and fk.simulate all do."""
    import importlib

    import fusionkit as fk

    module = importlib.import_module("fusionkit.resample")   # binds fk.resample to the module
    g = fk.default_world()
    canvas = fk.canvas_for([g], [fk.Transform2D()], g.resolution)
    t = fk.Transform2D(0.5, 0.0, 0.1)
    assert np.array_equal(fk.resample(g, t, canvas).data, module.resample(g, t, canvas).data)



def test_the_callable_modules_show_their_functions_parameters():
    """inspect.signature (a notebook's call tip) gave (*args, **kwargs) for fk.simulate and
    fk.resample once their modules were imported."""
    import importlib
    import inspect

    import fusionkit as fk

    for name, first in (("simulate", "world"), ("resample", "source")):
        importlib.import_module(f"fusionkit.{name}")
        assert list(inspect.signature(getattr(fk, name)).parameters)[0] == first
