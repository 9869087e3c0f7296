"""The merge node's parts that need no running ROS graph: message conversion with the real
``nav_msgs`` classes, parameters, topic names, and the hysteresis rule."""

import array
import math

import numpy as np
import pytest
from nav_msgs.msg import OccupancyGrid as GridMsg

import fusionkit as fk
# the module path: once imported, the submodule shadows the lazy name fk.simulate
from fusionkit.simulate import SimulationConfig, simulate, write_run
from fusionkit.ros2._convert import BadMap, fill_msg, grid_from_msg
from fusionkit.ros2._names import is_robot_map_topic, robot_of
from fusionkit.ros2._params import settings_from
from fusionkit.ros2._tracker import Tracker
from fusionkit.ros2.play import find_robots, growth_steps


def _grid(rows=30, cols=40, seed=0):
    rng = np.random.default_rng(seed)
    data = rng.choice(np.array([-1, 0, 100], np.int8), size=(rows, cols))
    return fk.OccupancyGrid(data, 0.05, (1.5, -2.0, 0.3), "g")


def test_grid_message_round_trip():
    g = _grid()
    msg = GridMsg()
    fill_msg(msg, g, "world", msg.header.stamp)
    assert (msg.info.width, msg.info.height) == (40, 30)
    back = grid_from_msg(msg, max_cells=10_000)
    np.testing.assert_array_equal(back.data, g.data)
    assert back.resolution == pytest.approx(0.05)
    np.testing.assert_allclose(back.origin, g.origin, atol=1e-6)


@pytest.mark.parametrize("edit, reason", [
    (lambda m: setattr(m, "data", array.array("b", bytes(50))), "data holds 50 cells but width x height is 40 x 30"),
    (lambda m: setattr(m.info, "resolution", float("nan")), "resolution nan is not a positive"),
    (lambda m: setattr(m.info, "resolution", 0.0), "resolution 0.0 is not a positive"),
    (lambda m: setattr(m.info.origin.position, "x", float("inf")), "is not finite"),
    (lambda m: (setattr(m.info, "width", 0), setattr(m, "data", array.array("b"))), "empty"),
])
def test_malformed_grid_messages_are_refused_with_the_reason(edit, reason):
    msg = GridMsg()
    fill_msg(msg, _grid(), "world", msg.header.stamp)
    edit(msg)
    with pytest.raises(BadMap) as info:
        grid_from_msg(msg, max_cells=10_000)
    assert reason in str(info.value)


def test_huge_grid_is_refused_before_it_is_copied():
    msg = GridMsg()
    fill_msg(msg, _grid(), "world", msg.header.stamp)
    with pytest.raises(BadMap, match="more than max_map_cells"):
        grid_from_msg(msg, max_cells=1000)


def test_settings_take_map_merge_defaults_and_init_poses():
    s = settings_from({})
    assert (s.robot_map_topic, s.merged_map_topic, s.world_frame, s.robot_namespace) == \
        ("map", "map", "world", "")
    assert (s.merging_rate, s.discovery_rate, s.estimation_rate, s.known_init_poses) == \
        (4.0, 0.05, 0.5, False)
    s = settings_from({"merging_rate": 2, "known_init_poses": True, "reference_robot": "robot2",
                       "/robot1/map_merge/init_pose_x": -3.0, "/robot1/map_merge/init_pose_y": 1,
                       "/robot1/map_merge/init_pose_z": 0.0, "/robot1/map_merge/init_pose_yaw": 0.5})
    assert s.merging_rate == 2.0 and s.reference_robot == "/robot2"
    assert s.init_poses["/robot1"].is_close(fk.Transform2D(-3.0, 1.0, 0.5))


def test_a_half_given_initial_pose_skips_that_robot_not_the_node():
    """As map_merge, which skips a robot it cannot read a whole initial pose for: a parameter
    file it runs with used to stop this node with exit 2."""
    s = settings_from({"known_init_poses": True, "/r1/map_merge/init_pose_x": 1.0,
                       "/r2/map_merge/init_pose_x": 2.0, "/r2/map_merge/init_pose_y": 0.5,
                       "/r2/map_merge/init_pose_yaw": 0.0})
    assert set(s.init_poses) == {"/r2"} and set(s.partial_init_poses) == {"/r1"}
    assert "give /r1/map_merge/init_pose_y, /r1/map_merge/init_pose_yaw too" in s.partial_init_poses["/r1"]


@pytest.mark.parametrize("values, message", [
    ({"merging_rate": "fast"}, "parameter merging_rate: expected a number"),
    ({"estimation_rate": 0.0}, "parameter estimation_rate: expected a rate in Hz"),
    ({"known_init_poses": 3}, "parameter known_init_poses: expected true or false"),
    ({"method": "magic"}, "parameter method: 'magic' is not a method"),
    ({"min_confidence": 1.5}, "parameter min_confidence: expected a number between 0 and 1"),
    ({"merged_map_topic": "bad topic"}, "parameter merged_map_topic: 'bad topic' is not a ROS 2 topic name"),
    ({"robot_map_topic": "9map"}, "parameter robot_map_topic: '9map' is not a ROS 2 topic name"),
    # these passed the check, then overflowed a timer (a traceback at start, or a thread of a
    # running node dead) or stopped every estimation
    ({"discovery_rate": 1e-300}, "parameter discovery_rate: expected a rate in Hz"),
    ({"merging_rate": 1e-11}, "parameter merging_rate: expected a rate in Hz"),
    ({"estimation_rate": 1e-12}, "parameter estimation_rate: expected a rate in Hz"),
    ({"seed": 99999999999999999999}, "parameter seed: expected a whole number from 0 to 2^63 - 1"),
    ({"seed": 10 ** 400}, "parameter seed: expected a whole number from 0 to 2^63 - 1"),
    ({"seed": 1.5}, "parameter seed: expected a whole number from 0 to 2^63 - 1"),
    ({"max_map_cells": 2 ** 70}, "parameter max_map_cells: expected a whole number from 0 to 2^63 - 1"),
    # a robot no topic can name: the node waited for it for ever
    ({"reference_robot": "///"}, "parameter reference_robot: give a robot's namespace such as /robot_1"),
])
def test_bad_parameters_say_what_to_fix(values, message):
    with pytest.raises(fk.InputError) as info:
        settings_from(values)
    assert message in str(info.value)


def test_the_estimation_rate_may_be_0_with_known_initial_poses_as_map_merge_configurations_give():
    """map_merge's files for known initial poses set estimation_rate 0 (no estimation): it was
    refused, though the node does not estimate then."""
    s = settings_from({"known_init_poses": True, "estimation_rate": 0.0,
                       "/r1/map_merge/init_pose_x": 0.0, "/r1/map_merge/init_pose_y": 0.0,
                       "/r1/map_merge/init_pose_yaw": 0.0})
    assert s.known_init_poses and s.estimation_rate == 0.0
    with pytest.raises(fk.InputError, match="parameter estimation_rate: expected a rate in Hz"):
        settings_from({"known_init_poses": False, "estimation_rate": 0.0})


def test_initial_poses_are_not_read_unless_known_init_poses_is_set():
    """As map_merge: with known_init_poses false, a half-given initial pose is no error (it
    once stopped the node with exit 2)."""
    assert settings_from({"/robot_9/map_merge/init_pose_x": 1.0}).init_poses == {}


def test_an_initial_pose_written_nested_is_said_how_to_write_it():
    from fusionkit.ros2._params import unknown_parameter

    for name in ("robot_3.map_merge.init_pose_x", "/robot_3.map_merge.init_pose_x"):
        assert unknown_parameter(name).endswith(
            "ignored (an initial pose is written flat, as map_merge's params.yaml does: "
            "/robot_3/map_merge/init_pose_x: VALUE)")
    assert unknown_parameter("merging_rte") == ("parameter merging_rte is not one of this node's; "
                                                "ignored (the parameters: fusionkit ros2 "
                                                "merge-node --help)")


@pytest.mark.parametrize("topic, robot, message", [
    ("a b", "robot_1", "--topic: 'a b' is not a ROS 2 topic name"),
    ("map", "robot 1", "robot 1.yaml (its name is the robot's topic namespace): '/robot 1/map' is not"),
])
def test_play_refuses_a_topic_name_ros_cannot_take_before_it_starts(tmp_path, topic, robot, message):
    from fusionkit.ros2.play import play
    from fusionkit.worlds import default_world
    sim = simulate(default_world(), SimulationConfig(robots=1, poses=30, seed=1))
    write_run(sim, tmp_path / "run")
    if robot != "robot_1":
        for f in (tmp_path / "run").glob("robot_1.*"):
            f.rename(f.with_name(f.name.replace("robot_1", robot)))
        yaml = tmp_path / "run" / f"{robot}.yaml"
        yaml.write_text(yaml.read_text().replace("robot_1.pgm", f"{robot}.pgm"))
        (tmp_path / "run" / "truth.json").unlink()  # its robots are found by their scans
    with pytest.raises(fk.InputError) as info:
        play(tmp_path / "run", duration=0.0, steps=1, topic=topic, hold=0.0)
    assert message in str(info.value)


def test_robot_map_topics_are_found_as_map_merge_finds_them():
    kw = dict(robot_map_topic="map", robot_namespace="", merged_topic="/map")
    grid = ["nav_msgs/msg/OccupancyGrid"]
    assert is_robot_map_topic("/robot1/map", grid, **kw)
    assert robot_of("/robot1/map", "map") == "/robot1" and robot_of("/map", "map") == "/"
    # a map topic of two levels (map_merge matched no topic then)
    nested = {**kw, "robot_map_topic": "slam/map"}
    assert is_robot_map_topic("/robot1/slam/map", grid, **nested)
    assert robot_of("/robot1/slam/map", "slam/map") == "/robot1"
    assert not is_robot_map_topic("/robot1/map", grid, **nested)
    assert not is_robot_map_topic("/robot1/myslam/map", grid, **nested)
    assert not is_robot_map_topic("/map", grid, **kw)                      # our own output
    assert not is_robot_map_topic("/robot1/map", ["std_msgs/msg/String"], **kw)
    assert not is_robot_map_topic("/robot1/map_updates", grid, **kw)
    assert not is_robot_map_topic("/other/map", grid, **{**kw, "robot_namespace": "tb3"})
    assert is_robot_map_topic("/tb3_0/map", grid, **{**kw, "robot_namespace": "tb3"})


def _tracker():
    return Tracker(min_confidence=0.5, switch_margin=0.05, switch_confirmations=2)


def test_first_confident_estimate_places_a_robot_and_a_close_one_confirms_it():
    tr = _tracker()
    assert tr.decide("/r", None, 0.0, "no overlap", 0.1).action == "not placed"
    assert tr.decide("/r", fk.Transform2D(1, 2, 0.1), 0.3, "", 0.1).action == "not placed"
    d = tr.decide("/r", fk.Transform2D(1, 2, 0.1), 0.9, "", 0.1)
    assert d.action == "placed" and "placed at x=1.000 m y=2.000 m" in d.line()
    d = tr.decide("/r", fk.Transform2D(1.15, 2, 0.1 + math.radians(0.5)), 0.95, "", 0.1)
    assert d.action == "confirmed" and d.transform == fk.Transform2D(1, 2, 0.1)


def test_a_different_estimate_replaces_the_held_one_only_when_confidently_better_twice():
    tr = _tracker()
    old, new = fk.Transform2D(1, 2, 0.1), fk.Transform2D(4, 2, 0.1)
    tr.decide("/r", old, 0.9, "", 0.1)
    scores = {old: 0.80, new: 0.82}
    d = tr.decide("/r", new, 0.9, "", 0.1, score=lambda t: scores[t])
    assert d.action == "kept" and tr.held("/r")[0] == old          # not better by the margin
    assert tr.decide("/r", None, 0.0, "refused", 0.1).transform == old
    scores[new] = 0.95
    d = tr.decide("/r", new, 0.9, "", 0.1, score=lambda t: scores[t])
    assert d.action == "kept" and "confirmation 1 of 2" in d.why
    d = tr.decide("/r", new, 0.9, "", 0.1, score=lambda t: scores[t])
    assert d.action == "switched" and tr.held("/r")[0] == new


def test_the_same_placement_fixed_better_on_grown_maps_replaces_the_held_one_at_once():
    tr = _tracker()
    old, near, worse = fk.Transform2D(1, 2, 0.1), fk.Transform2D(1.27, 2, 0.1), fk.Transform2D(0.7, 2, 0.1)
    tr.decide("/r", old, 0.9, "", 0.1)
    scores = {old: 0.97, near: 1.0, worse: 0.9}
    d = tr.decide("/r", worse, 0.9, "", 0.1, score=lambda t: scores[t])
    assert d.action == "kept" and tr.held("/r")[0] == old           # nearby but worse
    d = tr.decide("/r", near, 0.9, "", 0.1, score=lambda t: scores[t])
    assert d.action == "refined" and tr.held("/r")[0] == near        # 2.7 cells, better: at once
    assert "refined at x=1.270 m" in d.line()


def test_a_closer_estimate_that_scores_higher_is_taken_however_close():
    """Within 2 cells and 1 degree an estimate used to confirm the held transform unscored: a
    placement 1.5 cells off stayed 1.5 cells off while the maps grew."""
    tr = _tracker()
    old, near = fk.Transform2D(1, 2, 0.1), fk.Transform2D(1.15, 2, 0.1)
    tr.decide("/r", old, 0.9, "", 0.1)
    d = tr.decide("/r", near, 0.9, "", 0.1, score={old: 0.95, near: 0.99}.__getitem__)
    assert d.action == "refined" and tr.held("/r")[0] == near
    d = tr.decide("/r", old, 0.9, "", 0.1, score={old: 0.95, near: 0.99}.__getitem__)
    assert d.action == "confirmed" and tr.held("/r")[0] == near       # not back to the worse one


def test_a_pending_switch_is_known_to_the_node():
    tr = _tracker()
    old, new = fk.Transform2D(0, 0, 0), fk.Transform2D(5, 0, 0)
    tr.decide("/r", old, 0.9, "", 0.1)
    assert not tr.pending()
    tr.decide("/r", new, 0.9, "", 0.1, score=lambda t: 0.9 if t == new else 0.2)
    assert tr.pending()
    assert tr.decide("/r", new, 0.9, "", 0.1, score=lambda t: 0.9 if t == new else 0.2).action == "switched"
    assert not tr.pending()


def test_an_interrupted_run_of_better_estimates_starts_over():
    tr = _tracker()
    old, new = fk.Transform2D(0, 0, 0), fk.Transform2D(5, 0, 0)
    tr.decide("/r", old, 0.9, "", 0.1)
    better = lambda t: 0.9 if t == new else 0.5  # noqa: E731
    assert "confirmation 1" in tr.decide("/r", new, 0.9, "", 0.1, score=better).why
    tr.decide("/r", old, 0.9, "", 0.1)
    assert "confirmation 1" in tr.decide("/r", new, 0.9, "", 0.1, score=better).why


def test_a_held_transform_that_no_longer_fits_the_maps_is_dropped_not_kept():
    """A robot whose SLAM restarted in a new frame: the method refuses its new map, and its old
    transform, which the test no longer takes on the current maps, used to stay merged (with
    its old confidence) across the other robots' walls."""
    tr = _tracker()
    old, new = fk.Transform2D(1, 2, 0.1), fk.Transform2D(4, 2, 1.6)
    tr.decide("/r", old, 0.9, "", 0.1)
    # refused this round, the held one still fits: kept
    d = tr.decide("/r", None, 0.0, "ambiguous", 0.1, fits=lambda t: 0.8)
    assert d.action == "kept" and tr.held("/r")[0] == old
    # refused, and the held one no longer fits: dropped, the robot left out
    d = tr.decide("/r", None, 0.0, "best placement is contradicted", 0.1, fits=lambda t: 0.01)
    assert d.action == "dropped" and d.transform is None and tr.held("/r") is None
    assert "no longer fits the current maps: confidence 0.01 there" in d.why
    assert d.why.endswith("new estimate refused: best placement is contradicted")
    # a different, confident estimate while the held one no longer fits: placed at once, not
    # after switch_confirmations rounds
    tr.decide("/r", old, 0.9, "", 0.1)
    scores = {old: 0.15, new: 1.0}
    d = tr.decide("/r", new, 0.9, "", 0.1, score=scores.__getitem__, fits=lambda t: 0.0)
    assert d.action == "placed" and tr.held("/r")[0] == new and "anew" in d.why
    # the held transform is only checked where it would be kept
    asked = []
    d = tr.decide("/r", new, 0.95, "", 0.1, fits=lambda t: asked.append(t) or 0.0)
    assert d.action == "confirmed" and not asked


def test_a_robot_whose_map_restarts_in_a_new_frame_is_not_left_at_its_old_place():
    from pathlib import Path

    from fusionkit.methods.peers import crop_pair
    from fusionkit.ros2._params import NodeSettings
    from fusionkit.ros2._robots import estimate_round
    real = Path(__file__).resolve().parents[1] / "maps" / "real"
    pair = crop_pair(fk.load_map(real / "intel_lab.yaml"), np.random.default_rng(3), size=200,
                     min_overlap=0.4)
    settings = NodeSettings()

    def placed_tracker():
        tr = _tracker()
        tr.fix("/r1", fk.Transform2D.identity())
        [d] = estimate_round([("/r1", pair.a), ("/r2", pair.b)], "/r1", settings, tr)
        assert d.action == "placed"
        return tr, d.transform

    # the new map is 8 x 8 m of another building, at the old map's origin: refused, and the
    # old transform lays it across the first robot's walls
    mit = fk.load_map(real / "mit_stata_basement.yaml")
    r, c = np.nonzero(mit.occupied_mask())
    r0, c0 = int(r[len(r) // 2]), int(c[len(c) // 2])
    small = fk.OccupancyGrid(mit.data[r0 - 80:r0 + 80, c0 - 80:c0 + 80].copy(), mit.resolution,
                             pair.b.origin, "small")
    tr, _ = placed_tracker()
    [d] = estimate_round([("/r1", pair.a), ("/r2", small)], "/r1", settings, tr)
    assert d.action == "dropped" and tr.held("/r2") is None and "new estimate refused" in d.why
    # the same map turned a quarter turn in its new frame: placed again at once, where it fits
    turned = fk.OccupancyGrid(np.rot90(pair.b.data).copy(), pair.b.resolution, pair.b.origin, "turned")
    tr, old = placed_tracker()
    [d] = estimate_round([("/r1", pair.a), ("/r2", turned)], "/r1", settings, tr)
    assert d.action == "placed" and d.transform != old and "anew" in d.why
    assert fk.overlap_score(pair.a, turned, d.transform)[0] > 0.9


def test_play_finds_a_runs_robots_and_grows_their_maps(tmp_path):
    sim = simulate(fk.default_world(), SimulationConfig(robots=2, poses=300, seed=3))
    write_run(sim, tmp_path / "run")
    robots = find_robots(tmp_path / "run")
    assert [r.name for r in robots] == ["robot_1", "robot_2"]
    steps = growth_steps(robots[0], 4)
    assert len(steps) == 4
    known = [int(g.known_mask().sum()) for g in steps]
    assert known == sorted(known) and known[0] < known[-1]
    np.testing.assert_array_equal(steps[-1].data, fk.load_map(robots[0].map_path).data)
    with pytest.raises(fk.InputError, match="no robot map"):
        find_robots(tmp_path)


def test_a_parameter_file_with_no_section_for_the_node_is_found(tmp_path):
    """A file written for another node (or for the node before it was renamed) was taken
    silently, none of its parameters applied."""
    from fusionkit.ros2._runtime import unapplied_params_files
    files = {"other": "other_node:\n  ros__parameters:\n    merging_rate: 2.0\n",
             "mine": "map_merge:\n  ros__parameters:\n    merging_rate: 2.0\n",
             "slash": "/map_merge:\n  ros__parameters:\n    merging_rate: 2.0\n",
             "all": "/**:\n  ros__parameters:\n    use_sim_time: true\n",
             "nested": "ns:\n  map_merge:\n    ros__parameters:\n      merging_rate: 2.0\n",
             "deep": "/**/map_merge:\n  ros__parameters:\n    merging_rate: 2.0\n"}
    paths = {}
    for name, text in files.items():
        paths[name] = tmp_path / f"{name}.yaml"
        paths[name].write_text(text)
    assert unapplied_params_files(list(paths.values()), "/map_merge") == \
        [str(paths["other"]), str(paths["nested"])]
    assert unapplied_params_files([paths["nested"], paths["deep"]], "/ns/map_merge") == []
