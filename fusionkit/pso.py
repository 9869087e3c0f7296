"""Particle Swarm Optimization over a box (the search of the paper's Section 3.4).

Each particle ``i`` has a position ``x_i`` and a velocity ``v_i`` in ``D`` dimensions; it
remembers the best position it has visited (``p_i``), and the swarm shares the best position any
particle has visited (``g``). One iteration moves every particle (Kennedy & Eberhart 1995, with
the inertia weight ``w`` of Shi & Eberhart 1998)::

    v_i <- w v_i + c1 r1 (p_i - x_i) + c2 r2 (g - x_i)      r1, r2 ~ U(0, 1) per dimension
    x_i <- x_i + v_i

Speeds are clamped to ``v_max`` times each bound's width. On an ordinary dimension a particle
that leaves the box is put back on the bound and loses that component of its speed; on a
*periodic* dimension (an angle) it re-enters from the other side, and the pulls towards ``p_i``
and ``g`` take the short way round.

The swarm is scored with one call of the objective per iteration, so a vectorised or jitted
objective scores all particles at once. The update runs in a numba kernel; its random numbers
are drawn in Python from a :class:`numpy.random.Generator`, so a seeded run repeats bit for bit.

References
----------
J. Kennedy and R. Eberhart, "Particle swarm optimization", Proc. ICNN'95, pp. 1942-1948, 1995.
Y. Shi and R. Eberhart, "A modified particle swarm optimizer", Proc. IEEE ICEC, pp. 69-73, 1998.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from numbers import Integral, Real
from typing import Callable

import numpy as np

from ._jit import njit
from ._validate import random_source
from .errors import InputError

__all__ = ["PSOConfig", "PSOState", "PSOResult", "PSOSolver", "pso_minimize"]


def _is_int(v) -> bool:
    return isinstance(v, Integral) and not isinstance(v, bool)


def _is_real(v) -> bool:
    return isinstance(v, Real) and not isinstance(v, bool) and math.isfinite(float(v))


@dataclass(frozen=True)
class PSOConfig:
    """Swarm settings.

    Attributes
    ----------
    particles : int
        Swarm size, >= 1.
    iterations : int
        Most swarm updates after the initial scoring, >= 0.
    w : float
        Inertia weight (Shi & Eberhart 1998), >= 0; below 1 for the swarm to settle.
    c1, c2 : float
        Cognitive (towards the particle's own best) and social (towards the swarm's best)
        acceleration coefficients, >= 0. The defaults ``w = 0.72, c1 = c2 = 1.49`` are the
        constriction-equivalent values of Clerc & Kennedy (2002).
    v_max : float
        Largest speed per iteration, as a fraction of each bound's width, in ``(0, 1]``.
    tol : float
        An iteration counts as stalled when the best cost improved by less than ``tol``
        (same units as the cost), >= 0.
    patience : int
        Stop after this many stalled iterations in a row; ``0`` never stops early.

    Raises
    ------
    InputError
        When a value is out of range; the message says which and what is allowed.
    """

    particles: int = 40
    iterations: int = 80
    w: float = 0.72
    c1: float = 1.49
    c2: float = 1.49
    v_max: float = 0.25
    tol: float = 1e-9
    patience: int = 25

    def __post_init__(self):
        # the command line's and the terminal UI's ranges: a billion particles asked numpy
        # for tens of gigabytes
        if not _is_int(self.particles) or not 1 <= self.particles <= 10_000:
            raise InputError(f"PSO particles must be a whole number from 1 to 10000, got {self.particles!r}")
        if not _is_int(self.iterations) or not 0 <= self.iterations <= 100_000:
            raise InputError(f"PSO iterations must be a whole number from 0 to 100000, got {self.iterations!r}")
        if not _is_int(self.patience) or self.patience < 0:
            raise InputError(f"PSO patience must be a whole number >= 0 (0 = never stop early), "
                             f"got {self.patience!r}")
        for name in ("w", "c1", "c2", "tol"):
            v = getattr(self, name)
            if not _is_real(v) or v < 0:
                raise InputError(f"PSO {name} must be a finite number >= 0, got {v!r}")
        if not _is_real(self.v_max) or not 0 < self.v_max <= 1:
            raise InputError(f"PSO v_max is a fraction of each bound's width and must be in (0, 1], "
                             f"got {self.v_max!r}")


@dataclass(frozen=True, eq=False)
class PSOState:
    """The swarm after an iteration, as a callback sees it.

    Attributes
    ----------
    iteration : int
        Swarm updates done so far (``0`` = after the initial scoring).
    best_cost : float
        Lowest cost found so far.
    best_position : (D,) ndarray
        Where it was found.
    positions : (P, D) ndarray
        Current particle positions.
    costs : (P,) ndarray
        Their costs.
    evaluations : int
        Positions scored so far (particles times objective calls).
    """

    iteration: int
    best_cost: float
    best_position: np.ndarray
    positions: np.ndarray
    costs: np.ndarray
    evaluations: int


@dataclass(frozen=True, eq=False)
class PSOResult:
    """Outcome of :func:`pso_minimize`.

    Attributes
    ----------
    x : (D,) ndarray
        Best position found.
    fun : float
        Its cost.
    nit : int
        Swarm updates done.
    nfev : int
        Positions scored (``particles * (nit + 1)``).
    success : bool
        ``True`` when a finite best cost was found (whether the run used every iteration,
        stalled for ``patience`` iterations or was stopped by the callback).
    message : str
        Why the run ended.
    history : (nit + 1,) ndarray
        Best cost after the initial scoring and after each iteration (non-increasing).
    x_history : (nit + 1, D) ndarray
        Best position at the same moments.
    positions_history : (nit + 1, P, D) ndarray or None
        Every particle's position at the same moments, when ``record_positions=True``.
    """

    x: np.ndarray
    fun: float
    nit: int
    nfev: int
    success: bool
    message: str
    history: np.ndarray
    x_history: np.ndarray
    positions_history: np.ndarray | None = None


# -- kernels -------------------------------------------------------------------------------------
@njit
def _swarm_step(x, v, pbest, gbest, r1, r2, lo, hi, vmax, periodic, w, c1, c2):
    """Move every particle once, in place.

    ``x, v, pbest, r1, r2`` are (P, D); ``gbest, lo, hi, vmax`` (D,); ``periodic`` (D,) uint8.
    """
    n, d = x.shape
    for i in range(n):
        for k in range(d):
            width = hi[k] - lo[k]
            dp = pbest[i, k] - x[i, k]
            dg = gbest[k] - x[i, k]
            if periodic[k]:
                # the short way round the circle
                dp -= width * math.floor(dp / width + 0.5)
                dg -= width * math.floor(dg / width + 0.5)
            # v <- w v + c1 r1 (p - x) + c2 r2 (g - x)   (Shi & Eberhart 1998)
            vel = w * v[i, k] + c1 * r1[i, k] * dp + c2 * r2[i, k] * dg
            if vel > vmax[k]:
                vel = vmax[k]
            elif vel < -vmax[k]:
                vel = -vmax[k]
            # x <- x + v
            pos = x[i, k] + vel
            if periodic[k]:
                pos -= width * math.floor((pos - lo[k]) / width)
                if pos >= hi[k]:  # rounding just below lo wraps onto hi
                    pos = lo[k]
            elif pos < lo[k]:
                pos = lo[k]
                vel = 0.0
            elif pos > hi[k]:
                pos = hi[k]
                vel = 0.0
            x[i, k] = pos
            v[i, k] = vel


@njit
def _update_personal_best(x, cost, pbest, pbest_cost):
    """Where a particle's new cost is lower than its best, remember position and cost."""
    n, d = x.shape
    for i in range(n):
        if cost[i] < pbest_cost[i]:
            pbest_cost[i] = cost[i]
            for k in range(d):
                pbest[i, k] = x[i, k]


# -- input checks --------------------------------------------------------------------------------
def _check_bounds(bounds) -> tuple[np.ndarray, np.ndarray]:
    try:
        b = np.array(bounds, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"PSO bounds must be a sequence of (low, high) pairs, got {bounds!r}") from None
    if b.ndim != 2 or b.shape[1] != 2 or b.shape[0] == 0:
        raise InputError(f"PSO bounds must be a sequence of (low, high) pairs, one per dimension; "
                         f"got shape {b.shape}")
    if not np.isfinite(b).all():
        raise InputError(f"PSO bounds must be finite numbers, got {b.tolist()}")
    bad = np.nonzero(b[:, 0] >= b[:, 1])[0]
    if bad.size:
        k = int(bad[0])
        raise InputError(f"PSO bound of dimension {k} must have low < high, got "
                         f"({b[k, 0]:g}, {b[k, 1]:g})")
    return np.ascontiguousarray(b[:, 0]), np.ascontiguousarray(b[:, 1])


def _check_periodic(periodic, d: int) -> np.ndarray:
    if periodic is None:
        return np.zeros(d, np.uint8)
    p = np.asarray(periodic)
    if p.shape != (d,) or p.dtype != bool:
        raise InputError(f"PSO periodic must be {d} booleans (one per dimension), got {periodic!r}")
    return p.astype(np.uint8)


def _wrap_or_clip(x, lo, hi, periodic):
    x = x.copy()
    per = periodic.astype(bool)
    if per.any():
        width = hi[per] - lo[per]
        x[:, per] = lo[per] + np.mod(x[:, per] - lo[per], width)
        x[:, per] = np.where(x[:, per] >= hi[per], lo[per], x[:, per])
    if (~per).any():
        x[:, ~per] = np.clip(x[:, ~per], lo[~per], hi[~per])
    return x


# -- solver --------------------------------------------------------------------------------------
class PSOSolver:
    """A swarm that advances one iteration per :meth:`step` (or per item when iterated).

    Construction scores the initial swarm (iteration 0). Use :func:`pso_minimize` unless you
    want to drive the iterations yourself; the parameters are the same.

    Examples
    --------
    >>> solver = PSOSolver(lambda X: (X ** 2).sum(axis=1), [(-1, 1), (-1, 1)], seed=0)
    >>> for state in solver:
    ...     pass
    >>> solver.result().fun < 1e-6
    True
    """

    def __init__(self, objective: Callable[[np.ndarray], np.ndarray], bounds, *,
                 config: PSOConfig = PSOConfig(), seed=None, init=None, periodic=None,
                 record_positions: bool = False):
        if not isinstance(config, PSOConfig):
            raise InputError(f"config must be a PSOConfig, got {type(config).__name__}")
        if not callable(objective):
            raise InputError("the PSO objective must be callable: positions (P, D) -> costs (P,)")
        self.config = config
        self._objective = objective
        self._lo, self._hi = _check_bounds(bounds)
        d = self._lo.size
        self._periodic = _check_periodic(periodic, d)
        width = self._hi - self._lo
        self._vmax = np.ascontiguousarray(config.v_max * width)
        self._rng = random_source(seed)
        p = config.particles

        x = self._lo + self._rng.random((p, d)) * width
        if init is not None:
            seeds = np.array(init, dtype=float)
            if seeds.ndim == 1:
                seeds = seeds[None, :]
            if seeds.ndim != 2 or seeds.shape[1] != d:
                raise InputError(f"PSO init must be (K, {d}) seed positions, got shape {seeds.shape}")
            if seeds.shape[0] > p:
                raise InputError(f"PSO init has {seeds.shape[0]} seed positions but the swarm has "
                                 f"{p} particles; pass at most {p} or raise particles")
            if not np.isfinite(seeds).all():
                raise InputError("PSO init seed positions must be finite numbers")
            x[: seeds.shape[0]] = _wrap_or_clip(seeds, self._lo, self._hi, self._periodic)
        self._x = np.ascontiguousarray(x)
        self._v = np.ascontiguousarray((2.0 * self._rng.random((p, d)) - 1.0) * self._vmax)

        self._iteration = 0
        self._evaluations = 0
        self._stalled = 0
        self._message = ""
        self._cost = self._score()
        self._pbest = self._x.copy()
        self._pbest_cost = self._cost.copy()
        self._set_global_best()
        self._history = [self._gbest_cost]
        self._x_history = [self._gbest.copy()]
        self._positions_history = [self._x.copy()] if record_positions else None

    # -- internals -----------------------------------------------------------------------------
    def _score(self) -> np.ndarray:
        p, d = self._x.shape
        cost = self._objective(self._x.copy())
        try:
            cost = np.asarray(cost, dtype=float)
        except (TypeError, ValueError):
            raise InputError(f"the PSO objective must return {p} numbers (one per particle), "
                             f"got {type(cost).__name__}") from None
        if cost.shape != (p,):
            raise InputError(f"the PSO objective must return an array of shape ({p},), one cost per "
                             f"particle, got shape {cost.shape}")
        bad = np.isnan(cost)
        if bad.any():
            i = int(np.argmax(bad))
            raise InputError(f"the PSO objective returned NaN at iteration {self._iteration} for "
                             f"particle {i} at {self._x[i].tolist()}; it must return a number "
                             f"(use inf for positions to reject)")
        self._evaluations += p
        return np.ascontiguousarray(cost)

    def _set_global_best(self) -> None:
        i = int(np.argmin(self._pbest_cost))
        self._gbest = self._pbest[i].copy()
        self._gbest_cost = float(self._pbest_cost[i])

    # -- public --------------------------------------------------------------------------------
    @property
    def iteration(self) -> int:
        """Swarm updates done so far."""
        return self._iteration

    @property
    def converged(self) -> bool:
        """``True`` once the run should end (iterations used up or stalled for ``patience``)."""
        return bool(self._message)

    @property
    def state(self) -> PSOState:
        """A snapshot of the swarm (copies; later steps do not change it)."""
        return PSOState(self._iteration, self._gbest_cost, self._gbest.copy(), self._x.copy(),
                        self._cost.copy(), self._evaluations)

    def step(self) -> PSOState:
        """Move and rescore the swarm once; return the new state.

        Raises
        ------
        StopIteration
            When the run has already ended (see :attr:`converged`).
        """
        cfg = self.config
        if self._message:
            raise StopIteration(self._message)
        if self._iteration >= cfg.iterations:
            self._message = "maximum number of iterations reached"
            raise StopIteration(self._message)
        shape = self._x.shape
        r1 = self._rng.random(shape)
        r2 = self._rng.random(shape)
        _swarm_step(self._x, self._v, self._pbest, self._gbest, r1, r2, self._lo, self._hi,
                    self._vmax, self._periodic, float(cfg.w), float(cfg.c1), float(cfg.c2))
        self._iteration += 1
        self._cost = self._score()
        _update_personal_best(self._x, self._cost, self._pbest, self._pbest_cost)
        previous = self._gbest_cost
        self._set_global_best()
        self._history.append(self._gbest_cost)
        self._x_history.append(self._gbest.copy())
        if self._positions_history is not None:
            self._positions_history.append(self._x.copy())

        improved = previous - self._gbest_cost  # inf - inf would be NaN: no improvement
        self._stalled = 0 if improved >= cfg.tol else self._stalled + 1
        if cfg.patience and self._stalled >= cfg.patience:
            self._message = (f"best cost improved by less than tol={cfg.tol:g} for "
                             f"{cfg.patience} iterations")
        elif self._iteration >= cfg.iterations:
            self._message = "maximum number of iterations reached"
        return self.state

    def stop(self, message: str) -> None:
        """End the run early with ``message`` (as a callback returning ``True`` does)."""
        self._message = message

    def __iter__(self):
        return self

    def __next__(self) -> PSOState:
        return self.step()

    def result(self) -> PSOResult:
        """The best position found so far, with the run's history."""
        message = self._message or "maximum number of iterations reached"
        success = math.isfinite(self._gbest_cost)
        if not success:
            message = f"no particle found a finite cost ({message})"
        positions = (np.stack(self._positions_history) if self._positions_history is not None
                     else None)
        return PSOResult(
            x=self._gbest.copy(), fun=self._gbest_cost, nit=self._iteration,
            nfev=self._evaluations, success=success, message=message,
            history=np.array(self._history, dtype=float), x_history=np.stack(self._x_history),
            positions_history=positions,
        )


def pso_minimize(objective: Callable[[np.ndarray], np.ndarray], bounds, *,
                 config: PSOConfig = PSOConfig(), seed=None, init=None, periodic=None,
                 callback: Callable[[PSOState], bool | None] | None = None,
                 record_positions: bool = False) -> PSOResult:
    """Minimise ``objective`` over a box with a particle swarm.

    Parameters
    ----------
    objective : callable
        ``objective(positions) -> costs``: ``positions`` is a float64, C-contiguous ``(P, D)``
        array (a copy: the objective may change it), ``costs`` a ``(P,)`` array. ``inf`` marks a
        position to reject; NaN is an error.
    bounds : sequence of (low, high)
        One pair per dimension, ``low < high``, finite.
    config : PSOConfig
        Swarm size, iterations, coefficients and the stall rule.
    seed : int, numpy.random.Generator or None
        Source of every random number (initial swarm, speeds, ``r1``, ``r2``); the same seed
        gives the same result bit for bit.
    init : (K, D) array_like, optional
        Positions placed in the swarm as its first ``K`` particles (``K <= particles``); the
        rest start uniformly in the box. Values outside the box are clipped (wrapped on periodic
        dimensions).
    periodic : sequence of bool, optional
        Per dimension: ``True`` wraps around the bounds (an angle over ``[-pi, pi)``) instead of
        stopping at them.
    callback : callable, optional
        ``callback(state: PSOState)`` after every iteration; returning ``True`` ends the run
        (``success`` stays ``True``, ``message`` is ``"stopped by callback"``).
    record_positions : bool
        Keep every particle's position after each iteration in ``positions_history``.

    Returns
    -------
    PSOResult

    Raises
    ------
    InputError
        Bad ``config``, ``bounds``, ``init`` or ``periodic``, or an objective that returns the
        wrong shape or NaN.

    Examples
    --------
    >>> res = pso_minimize(lambda X: ((X - 0.3) ** 2).sum(axis=1), [(-2, 2)] * 2, seed=1)
    >>> np.allclose(res.x, 0.3, atol=1e-3)
    True
    """
    solver = PSOSolver(objective, bounds, config=config, seed=seed, init=init, periodic=periodic,
                       record_positions=record_positions)
    for state in solver:
        if callback is not None and callback(state):
            solver.stop("stopped by callback")
    return solver.result()
