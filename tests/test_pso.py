"""Particle Swarm Optimization: finds minima, respects bounds and periodicity, repeats with a seed."""

import math

import numpy as np
import pytest

from fusionkit.errors import InputError
from fusionkit.pso import PSOConfig, PSOSolver, PSOState, _swarm_step, pso_minimize


def sphere(center):
    center = np.asarray(center, float)
    return lambda X: ((X - center) ** 2).sum(axis=1)


def rastrigin(X):
    return 10.0 * X.shape[1] + (X ** 2 - 10.0 * np.cos(2.0 * np.pi * X)).sum(axis=1)


def naive_step(x, v, pbest, gbest, r1, r2, lo, hi, vmax, periodic, w, c1, c2):
    """The update written the obvious way with numpy (returns new x, v)."""
    width = hi - lo
    dp = pbest - x
    dg = gbest[None, :] - x
    per = periodic.astype(bool)
    dp[:, per] = (dp[:, per] + width[per] / 2) % width[per] - width[per] / 2
    dg[:, per] = (dg[:, per] + width[per] / 2) % width[per] - width[per] / 2
    v = np.clip(w * v + c1 * r1 * dp + c2 * r2 * dg, -vmax, vmax)
    x = x + v
    x[:, per] = lo[per] + (x[:, per] - lo[per]) % width[per]
    out = (~per) & ((x < lo) | (x > hi))
    v = np.where(out, 0.0, v)
    x[:, ~per] = np.clip(x[:, ~per], lo[~per], hi[~per])
    return x, v


def test_kernel_matches_naive_update():
    rng = np.random.default_rng(3)
    p, d = 30, 3
    lo = np.array([-2.0, 0.0, -math.pi])
    hi = np.array([2.0, 5.0, math.pi])
    periodic = np.array([0, 0, 1], np.uint8)
    x = lo + rng.random((p, d)) * (hi - lo)
    v = (rng.random((p, d)) - 0.5) * 3.0  # large enough that some particles leave the box
    pbest = lo + rng.random((p, d)) * (hi - lo)
    gbest = lo + rng.random(d) * (hi - lo)
    r1, r2 = rng.random((p, d)), rng.random((p, d))
    vmax = 0.5 * (hi - lo)
    want_x, want_v = naive_step(x.copy(), v.copy(), pbest, gbest, r1, r2, lo, hi, vmax,
                                periodic, 0.7, 1.5, 1.5)
    _swarm_step(x, v, pbest, gbest, r1, r2, lo, hi, vmax, periodic, 0.7, 1.5, 1.5)
    np.testing.assert_allclose(x, want_x, atol=1e-12)
    np.testing.assert_allclose(v, want_v, atol=1e-12)
    assert (x[:, :2] >= lo[:2]).all() and (x[:, :2] <= hi[:2]).all()
    assert (x[:, 2] >= -math.pi).all() and (x[:, 2] < math.pi).all()


def test_shifted_sphere_3d():
    center = [0.7, -1.3, 2.2]
    res = pso_minimize(sphere(center), [(-4, 4)] * 3, seed=0)
    assert res.success
    np.testing.assert_allclose(res.x, center, atol=1e-3)
    assert res.fun < 1e-6
    assert res.nfev == PSOConfig().particles * (res.nit + 1)
    assert res.history.shape == (res.nit + 1,)
    assert res.x_history.shape == (res.nit + 1, 3)
    assert np.all(np.diff(res.history) <= 0)  # the best never gets worse
    assert res.history[-1] == res.fun
    assert res.positions_history is None


@pytest.mark.parametrize("dims", [2, 3])
def test_rastrigin(dims):
    cfg = PSOConfig(particles=60, iterations=150)
    res = pso_minimize(rastrigin, [(-5.12, 5.12)] * dims, config=cfg, seed=2)
    np.testing.assert_allclose(res.x, 0.0, atol=1e-2)
    assert res.fun < 1e-3


def test_periodic_dimension_finds_minimum_across_the_wrap():
    # cost is smallest at angle pi (= -pi): the wrap point of [-pi, pi)
    def cost(X):
        return 1.0 + np.cos(X[:, 0]) + (X[:, 1] - 0.5) ** 2

    bounds = [(-math.pi, math.pi), (-2, 2)]
    res = pso_minimize(cost, bounds, periodic=[True, False], seed=4, record_positions=True)
    ang = math.remainder(res.x[0] - math.pi, 2 * math.pi)
    assert abs(ang) < 1e-3
    assert abs(res.x[1] - 0.5) < 1e-3
    pos = res.positions_history
    assert pos.shape == (res.nit + 1, PSOConfig().particles, 2)
    assert (pos[:, :, 0] >= -math.pi).all() and (pos[:, :, 0] < math.pi).all()
    # particles actually cross the wrap point (the two ends of the interval are both visited)
    assert (pos[:, :, 0] > 3.0).any() and (pos[:, :, 0] < -3.0).any()


def test_clamped_dimension_finds_minimum_on_the_bound():
    res = pso_minimize(sphere([3.0, 0.0]), [(-1, 1), (-1, 1)], seed=5, record_positions=True)
    assert res.x[0] == 1.0  # held on the bound, not pushed past it
    assert abs(res.x[1]) < 1e-3
    assert (np.abs(res.positions_history) <= 1.0).all()


def test_same_seed_same_run_different_seed_different_path():
    cfg = PSOConfig(particles=15, iterations=30, patience=0)
    a = pso_minimize(rastrigin, [(-5, 5)] * 2, config=cfg, seed=11, record_positions=True)
    b = pso_minimize(rastrigin, [(-5, 5)] * 2, config=cfg, seed=np.random.default_rng(11),
                     record_positions=True)
    c = pso_minimize(rastrigin, [(-5, 5)] * 2, config=cfg, seed=12, record_positions=True)
    assert np.array_equal(a.x, b.x) and a.fun == b.fun
    assert np.array_equal(a.history, b.history)
    assert np.array_equal(a.positions_history, b.positions_history)
    assert not np.array_equal(a.positions_history, c.positions_history)


def test_callback_stops_after_k_iterations():
    seen = []

    def stop_at_5(state):
        assert isinstance(state, PSOState)
        seen.append(state.iteration)
        return state.iteration >= 5

    res = pso_minimize(sphere([0, 0]), [(-1, 1)] * 2, seed=0, callback=stop_at_5)
    assert res.nit == 5
    assert seen == [1, 2, 3, 4, 5]
    assert res.success and res.message == "stopped by callback"
    assert res.history.shape == (6,)
    assert res.nfev == 6 * PSOConfig().particles


def test_callback_state_is_consistent():
    states = []
    pso_minimize(sphere([0.2, 0.1]), [(-1, 1)] * 2, config=PSOConfig(particles=8, iterations=4),
                 seed=0, callback=states.append)
    assert [s.iteration for s in states] == [1, 2, 3, 4]
    for s in states:
        assert s.positions.shape == (8, 2) and s.costs.shape == (8,)
        np.testing.assert_allclose(s.costs, sphere([0.2, 0.1])(s.positions))
        assert s.best_cost <= s.costs.min()
        assert s.evaluations == 8 * (s.iteration + 1)


def test_patience_stops_a_stalled_run():
    # a flat objective never improves: stops after exactly `patience` iterations
    res = pso_minimize(lambda X: np.zeros(len(X)), [(-1, 1)], seed=0,
                       config=PSOConfig(iterations=100, patience=7))
    assert res.nit == 7
    assert res.success and "improved by less than" in res.message
    never = pso_minimize(lambda X: np.zeros(len(X)), [(-1, 1)], seed=0,
                         config=PSOConfig(iterations=12, patience=0))
    assert never.nit == 12 and never.message == "maximum number of iterations reached"


def test_init_seed_at_optimum_is_used_at_iteration_zero():
    center = np.array([1.234, -0.567, 0.89])
    res = pso_minimize(sphere(center), [(-3, 3)] * 3, seed=9, init=center[None, :],
                       config=PSOConfig(iterations=0), record_positions=True)
    assert res.nit == 0 and res.history.shape == (1,)
    assert res.history[0] == pytest.approx(0.0, abs=1e-20)
    np.testing.assert_array_equal(res.x, center)
    np.testing.assert_array_equal(res.positions_history[0, 0], center)
    # the other particles are random, not copies of the seed
    assert len(np.unique(res.positions_history[0][:, 0])) == PSOConfig().particles


def test_init_outside_the_box_is_clipped_or_wrapped():
    solver = PSOSolver(sphere([0, 0]), [(-1, 1), (-math.pi, math.pi)], seed=0,
                       init=[[5.0, 3 * math.pi / 2]], periodic=[False, True])
    x0 = solver.state.positions[0]
    assert x0[0] == 1.0
    assert x0[1] == pytest.approx(-math.pi / 2)


def test_solver_steps_like_the_function():
    cfg = PSOConfig(particles=10, iterations=6, patience=0)
    solver = PSOSolver(rastrigin, [(-3, 3)] * 2, config=cfg, seed=21)
    assert solver.iteration == 0
    states = list(solver)
    assert len(states) == 6 and solver.converged
    with pytest.raises(StopIteration):
        solver.step()
    a = solver.result()
    b = pso_minimize(rastrigin, [(-3, 3)] * 2, config=cfg, seed=21)
    assert np.array_equal(a.history, b.history) and np.array_equal(a.x, b.x)


def test_infinite_costs_are_rejected_positions():
    # inf everywhere except a small region: the swarm still finds it, success reflects finiteness
    def cost(X):
        c = (X ** 2).sum(axis=1)
        return np.where(X[:, 0] > 0, np.inf, c)

    res = pso_minimize(cost, [(-1, 1)] * 2, seed=3)
    assert res.success and math.isfinite(res.fun)
    none = pso_minimize(lambda X: np.full(len(X), np.inf), [(-1, 1)], seed=3,
                        config=PSOConfig(iterations=3))
    assert not none.success and "no particle found a finite cost" in none.message


@pytest.mark.parametrize("kwargs", [
    dict(particles=0), dict(iterations=-1), dict(particles=2.5), dict(w=float("nan")),
    dict(c1=-1.0), dict(v_max=0.0), dict(v_max=1.5), dict(tol=-1e-3), dict(patience=-2),
    dict(particles=True),
])
def test_bad_config(kwargs):
    with pytest.raises(InputError):
        PSOConfig(**kwargs)


@pytest.mark.parametrize("bounds", [
    [(1.0, 1.0)], [(2.0, -2.0)], [(0.0, float("nan"))], [(0.0, float("inf"))], [], [1, 2, 3],
    [(0, 1, 2)], "ab",
])
def test_bad_bounds(bounds):
    with pytest.raises(InputError):
        pso_minimize(sphere([0]), bounds, seed=0)


def test_bad_init_and_periodic():
    with pytest.raises(InputError, match="at most"):
        pso_minimize(sphere([0]), [(-1, 1)], seed=0, init=np.zeros((41, 1)))
    with pytest.raises(InputError, match="shape"):
        pso_minimize(sphere([0]), [(-1, 1)], seed=0, init=np.zeros((2, 3)))
    with pytest.raises(InputError, match="finite"):
        pso_minimize(sphere([0]), [(-1, 1)], seed=0, init=[[np.nan]])
    with pytest.raises(InputError, match="periodic"):
        pso_minimize(sphere([0]), [(-1, 1)], seed=0, periodic=[True, False])


def test_objective_wrong_shape_or_nan():
    with pytest.raises(InputError, match=r"shape \(40,\)"):
        pso_minimize(lambda X: X.sum(), [(-1, 1)] * 2, seed=0)
    with pytest.raises(InputError, match=r"shape \(40,\)"):
        pso_minimize(lambda X: X, [(-1, 1)] * 2, seed=0)

    def nan_later(X):
        c = (X ** 2).sum(axis=1)
        nan_later.calls += 1
        if nan_later.calls == 3:
            c[4] = np.nan
        return c

    nan_later.calls = 0
    with pytest.raises(InputError, match="NaN at iteration 2 for particle 4"):
        pso_minimize(nan_later, [(-1, 1)] * 2, seed=0)


def test_objective_receives_contiguous_float64_copy():
    seen = []

    def cost(X):
        seen.append((X.dtype, X.flags.c_contiguous, X.shape))
        X[:] = 1e9  # scribbling on the argument must not move the swarm
        return np.zeros(len(X))

    res = pso_minimize(cost, [(-1, 1)] * 3, config=PSOConfig(particles=5, iterations=2), seed=0,
                       record_positions=True)
    assert set(seen) == {(np.dtype(np.float64), True, (5, 3))}
    assert (np.abs(res.positions_history) <= 1).all()


def test_a_seed_that_is_not_a_whole_number_is_one_clear_error():
    """'1', 1.5 and -1 raised numpy's TypeError or ValueError, naming no argument."""
    from fusionkit.errors import InputError
    for bad in ("1", 1.5, -1, True):
        with pytest.raises(InputError, match="seed must be a whole number >= 0, a numpy Generator or None"):
            pso_minimize(lambda X: (X ** 2).sum(axis=1), [(-1, 1)] * 2, seed=bad)
    a = pso_minimize(lambda X: (X ** 2).sum(axis=1), [(-1, 1)] * 2, seed=np.int64(4))
    b = pso_minimize(lambda X: (X ** 2).sum(axis=1), [(-1, 1)] * 2, seed=4)
    assert np.array_equal(a.x, b.x)


def test_a_swarm_larger_than_the_command_line_allows_is_refused():
    """PSOConfig(particles=10**9) was taken, and numpy then asked for tens of gigabytes."""
    from fusionkit.errors import InputError
    with pytest.raises(InputError, match="particles must be a whole number from 1 to 10000"):
        PSOConfig(particles=10 ** 9)
    with pytest.raises(InputError, match="iterations must be a whole number from 0 to 100000"):
        PSOConfig(iterations=10 ** 6)
    assert PSOConfig(particles=10_000, iterations=100_000).particles == 10_000
