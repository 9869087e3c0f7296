"""Finding the best fit: PSO over (dx, dy, dphi) minimising the masks' MSE (Sections 3.4-3.5).

Masks
-----
A *mask* is built from a robot's matched unique poses: the scan end points (beams that
returned) seen from those poses, in the robot's map frame. The reference mask is rasterised at
the map resolution and softened by a Gaussian of ``sigma`` cells, so the cost falls smoothly as
the masks approach each other (a binary mask gives a cost surface of isolated spikes that no
swarm can climb). The moving mask is the set of distinct cells hit by the other robot's points.

Objective (eq. 3)
-----------------
``MSE = 1/n sum_i (yhat_i - y_i)^2`` over the ``n`` cells of the reference mask's raster,
``y`` the reference mask and ``yhat`` the moving mask transformed by eq. 4
(``x' = (x + dx) cos dphi - (y + dy) sin dphi``, ``y' = (x + dx) sin dphi + (y + dy) cos dphi``)
and rasterised. With the moving mask binary this is
``(sum y^2 + sum_{p in moved mask} (1 - 2 y(p))) / n``, which the kernel evaluates for every
particle of the swarm in one parallel call, without drawing the moved mask.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import ndimage

from ._atomic import show
from ._jit import pjit, prange
from ._validate import number, whole
from .errors import InputError
from .grid import OccupancyGrid
from .mapping import MAX_CELLS
from .pso import PSOConfig, PSOResult, pso_minimize
from .scanlog import ScanLog
from .transform import Transform2D, wrap_angle
from .unique_poses import relative_heading

__all__ = ["MaskField", "mask_points", "make_field", "mse_cost", "mse_cost_numpy",
           "seed_transforms", "AlignmentConfig", "Alignment", "align_points", "refine_points",
           "overlap_score"]


@dataclass(frozen=True, eq=False)
class MaskField:
    """A softened reference mask: ``values[row, col]`` in [0, 1] over an axis-aligned raster.

    ``x0, y0`` (m) is the lower-left corner of cell (0, 0), ``resolution`` m/cell;
    ``sum_sq`` is ``sum values^2`` and ``n`` the raster's cell count (eq. 3's n).
    """

    values: np.ndarray
    x0: float
    y0: float
    resolution: float
    sum_sq: float
    n: int

    @property
    def radius(self) -> float:
        """Largest distance (m) of the raster's corners from the frame origin."""
        h, w = self.values.shape
        xs = np.array([self.x0, self.x0 + w * self.resolution])
        ys = np.array([self.y0, self.y0 + h * self.resolution])
        return float(np.sqrt((xs[:, None] ** 2 + ys[None, :] ** 2)).max())


def mask_points(log: ScanLog, indices) -> np.ndarray:
    """End points (m, the robot's map frame) of the returned beams at poses ``indices``."""
    idx = np.asarray(indices, dtype=np.int64)
    if idx.size == 0:
        return np.zeros((0, 2))
    return log.endpoints(idx)


def _points(points, name: str) -> np.ndarray:
    """``points`` as a finite (N, 2) float array (N may be 0), or one :class:`InputError`."""
    try:
        pts = np.asarray(points, float)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be an (N, 2) array of x, y in metres, got {show(points)}") from None
    if pts.size == 0:
        return np.zeros((0, 2))
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise InputError(f"{name} must be an (N, 2) array of x, y in metres, got shape {pts.shape}")
    if not np.isfinite(pts).all():
        raise InputError(f"{name} holds NaN or infinite coordinates: drop those points")
    return pts


def _cell_size(resolution) -> float:
    """``resolution`` as a positive finite float (m per cell), or one :class:`InputError`."""
    r = number(resolution, "resolution")
    if r <= 0:
        raise InputError(f"resolution must be > 0 m per cell, got {show(resolution)}")
    return r


def dedupe_points(points: np.ndarray, resolution: float) -> np.ndarray:
    """One point per occupied ``resolution`` cell (the cell centre): a binary mask as points."""
    if len(points) == 0:
        return np.zeros((0, 2))
    cells = np.unique(np.floor(np.asarray(points) / resolution).astype(np.int64), axis=0)
    return (cells + 0.5) * resolution


def make_field(points: np.ndarray, resolution: float, *, sigma: float = 1.0,
               margin: float = 2.0) -> MaskField:
    """Rasterise ``points`` (m) at ``resolution`` with ``margin`` m around, soften by a
    Gaussian of ``sigma`` cells and scale to a maximum of 1."""
    pts = np.asarray(points, float)
    if pts.size == 0:
        raise InputError("an empty mask: no scan end points to align (no unique poses matched)")
    x0 = math.floor((pts[:, 0].min() - margin) / resolution) * resolution
    y0 = math.floor((pts[:, 1].min() - margin) / resolution) * resolution
    cols = int(math.ceil((pts[:, 0].max() + margin - x0) / resolution)) + 1
    rows = int(math.ceil((pts[:, 1].max() + margin - y0) / resolution)) + 1
    if rows * cols > MAX_CELLS:
        # points in millimetres, or a resolution of 1e-5 m, asked numpy for terabytes
        raise InputError(f"the mask's points span {cols * resolution:.6g} x {rows * resolution:.6g} m: "
                         f"at {resolution:g} m cells, {cols} x {rows} cells, more than the "
                         f"{MAX_CELLS} fusionkit can hold; give the points in metres and the "
                         f"resolution in metres per cell")
    raster = np.zeros((rows, cols), np.float32)
    c = np.floor((pts[:, 0] - x0) / resolution).astype(np.int64)
    r = np.floor((pts[:, 1] - y0) / resolution).astype(np.int64)
    raster[r, c] = 1.0
    if sigma > 0:
        raster = ndimage.gaussian_filter(raster, sigma, mode="constant")
        raster /= max(float(raster.max()), 1e-12)
    raster = np.ascontiguousarray(raster, np.float32)
    return MaskField(raster, x0, y0, resolution, float((raster.astype(np.float64) ** 2).sum()),
                     raster.size)


@pjit
def _mse_kernel(values, x0, y0, inv_res, pts, params, sum_sq, n):
    """eq. 3 for each particle ``params[p] = (dx, dy, dphi)`` with eq. 4's motion."""
    P = params.shape[0]
    K = pts.shape[0]
    rows, cols = values.shape
    out = np.empty(P)
    for p in prange(P):
        dx = params[p, 0]
        dy = params[p, 1]
        c = math.cos(params[p, 2])
        s = math.sin(params[p, 2])
        acc = sum_sq
        for k in range(K):
            x = pts[k, 0] + dx
            y = pts[k, 1] + dy
            xr = x * c - y * s          # eq. 4
            yr = x * s + y * c
            ci = int(math.floor((xr - x0) * inv_res))
            ri = int(math.floor((yr - y0) * inv_res))
            v = 0.0
            if 0 <= ri < rows and 0 <= ci < cols:
                v = values[ri, ci]
            acc += 1.0 - 2.0 * v        # (yhat - y)^2 summed: y^2 + yhat (1 - 2y), yhat = 1
        out[p] = acc / n
    return out


def mse_cost(field: MaskField, moving: np.ndarray, params: np.ndarray) -> np.ndarray:
    """eq. 3 cost of each row ``(dx, dy, dphi)`` of ``params`` (m, m, rad); shape (P,)."""
    params = np.ascontiguousarray(np.atleast_2d(params), np.float64)
    return _mse_kernel(field.values, field.x0, field.y0, 1.0 / field.resolution,
                       np.ascontiguousarray(moving, np.float64), params, field.sum_sq, field.n)


def mse_cost_numpy(field: MaskField, moving: np.ndarray, params: np.ndarray) -> np.ndarray:
    """The same cost, written plainly in numpy: the reference the kernel is checked against,
    and the baseline of the speed benchmark. It draws the moved mask explicitly."""
    params = np.atleast_2d(params)
    out = np.empty(len(params))
    rows, cols = field.values.shape
    for p, (dx, dy, phi) in enumerate(params):
        t = Transform2D.from_paper(dx, dy, phi)
        q = t(moving)
        ci = np.floor((q[:, 0] - field.x0) / field.resolution).astype(np.int64)
        ri = np.floor((q[:, 1] - field.y0) / field.resolution).astype(np.int64)
        inside = (ri >= 0) & (ri < rows) & (ci >= 0) & (ci < cols)
        yhat = np.zeros_like(field.values, dtype=np.float64)
        np.add.at(yhat, (ri[inside], ci[inside]), 1.0)
        outside = int((~inside).sum())
        diff = yhat - field.values
        out[p] = ((diff * diff).sum() + outside) / field.n
    return out


def seed_transforms(log_a: ScanLog, log_b: ScanLog, pairs) -> list[Transform2D]:
    """One transform hypothesis (b's frame -> a's frame) per matched pose pair ``(i, j)``.

    The relative heading comes from the circular cross-correlation of the two scans
    (:func:`~fusionkit.unique_poses.relative_heading`); the translation then puts pose j of b
    on pose i of a. Exact when both scans were taken at the same spot.
    """
    if log_a.n_beams != log_b.n_beams or not math.isclose(
            log_a.angle_increment, log_b.angle_increment, rel_tol=1e-6):
        return []
    ra, rb = log_a.clipped_ranges(), log_b.clipped_ranges()
    out = []
    for i, j in pairs:
        dth, _ = relative_heading(ra[i], rb[j], log_a.angle_increment)
        pa, pb = log_a.poses[i], log_b.poses[j]
        phi = float(wrap_angle(pa[2] - dth - pb[2]))
        c, s = math.cos(phi), math.sin(phi)
        tx = pa[0] - (c * pb[0] - s * pb[1])
        ty = pa[1] - (s * pb[0] + c * pb[1])
        out.append(Transform2D(tx, ty, phi))
    return out


@dataclass(frozen=True)
class AlignmentConfig:
    """How masks are built and aligned.

    Attributes
    ----------
    pso : PSOConfig
        Swarm settings.
    sigma : float
        Softening of the reference mask (cells).
    seeded : bool
        Place the transforms given by matched scans (:func:`seed_transforms`) into the initial
        swarm. False gives the paper's blind search over the whole space.
    max_seeds : int
        At most this many seed transforms go into the swarm.
    """

    pso: PSOConfig = PSOConfig()
    sigma: float = 1.0
    seeded: bool = True
    max_seeds: int = 20

    def __post_init__(self):
        if not isinstance(self.pso, PSOConfig):
            raise InputError(f"AlignmentConfig's pso must be a PSOConfig, got {type(self.pso).__name__}")
        if not isinstance(self.seeded, (bool, np.bool_)):
            raise InputError(f"seeded must be True or False, got {show(self.seeded)}")
        object.__setattr__(self, "seeded", bool(self.seeded))
        object.__setattr__(self, "sigma", number(self.sigma, "sigma"))
        object.__setattr__(self, "max_seeds", whole(self.max_seeds, "max_seeds"))
        if self.sigma < 0:
            raise InputError(f"sigma must be >= 0 cells, got {self.sigma}")
        if self.max_seeds < 0:
            raise InputError(f"max_seeds must be >= 0, got {self.max_seeds}")


@dataclass(frozen=True, eq=False)
class Alignment:
    """Result of aligning a moving mask to a reference mask.

    ``transform`` maps the moving frame into the reference frame; ``params`` are the paper's
    ``(dx, dy, dphi)`` (eq. 4) of the same motion; ``pso`` the optimiser's result with its
    history; ``seeds`` the seed transforms placed in the swarm; ``refinement`` the local
    swarm's result when the alignment was polished (:func:`refine_points`).
    """

    transform: Transform2D
    params: tuple
    cost: float
    pso: PSOResult
    seeds: tuple = field(default=())
    refinement: PSOResult | None = None


def align_points(reference: np.ndarray, moving: np.ndarray, resolution: float, *,
                 config: AlignmentConfig = AlignmentConfig(), seeds=(), seed=None,
                 callback=None) -> Alignment:
    """Align ``moving`` points (m) to ``reference`` points (m) by PSO on eq. 3.

    The swarm searches the whole box of ``config`` from random starts: on whole maps' walls,
    without ``seeds`` it often settles in a local minimum far from the truth and says nothing of
    it (``success`` means only that the swarm stopped improving). Give it the hypotheses of the
    paper's pairing as ``seeds`` (what the ``spectral-pso`` method does; notebook 04 shows
    both), or use :func:`fusionkit.merge`, which also judges the placement it finds.

    Parameters
    ----------
    reference, moving : (K, 2), (L, 2) float
        Mask points in the reference frame and in the moving frame.
    resolution : float
        Raster cell size (m).
    seeds : sequence of Transform2D
        Hypotheses placed in the initial swarm (when ``config.seeded``).
    seed : int or numpy.random.Generator
        Randomness of the swarm.
    callback : callable(PSOState) -> bool, optional
        Called each iteration; True stops the swarm.
    """
    if not isinstance(config, AlignmentConfig):
        raise InputError(f"config must be an AlignmentConfig, got {type(config).__name__}")
    resolution = _cell_size(resolution)
    reference, moving = _points(reference, "reference"), _points(moving, "moving")
    fld = make_field(reference, resolution, sigma=config.sigma)
    mov = dedupe_points(moving, resolution)
    if len(mov) == 0:
        raise InputError("an empty moving mask: no scan end points to align")
    r_mov = float(np.sqrt((mov ** 2).sum(axis=1)).max())
    reach = fld.radius + r_mov + resolution
    bounds = np.array([[-reach, reach], [-reach, reach], [-math.pi, math.pi]])
    seeds = tuple(seeds)
    if not all(isinstance(t, Transform2D) for t in seeds):
        raise InputError("seeds must be Transform2D objects (Transform2D(x, y, theta), or "
                         "Transform2D.from_paper(dx, dy, dphi))")
    init = None
    used = tuple(seeds[: min(config.max_seeds, config.pso.particles)]) if config.seeded else ()
    if used:
        init = np.array([t.to_paper() for t in used])
        init[:, :2] = np.clip(init[:, :2], -reach, reach)

    def objective(params):
        return mse_cost(fld, mov, params)

    res = pso_minimize(objective, bounds, config=config.pso, seed=seed, init=init,
                       periodic=[False, False, True], callback=callback)
    dx, dy, dphi = (float(v) for v in res.x)
    return Alignment(Transform2D.from_paper(dx, dy, dphi), (dx, dy, dphi), float(res.fun), res, used)


def overlap_score(a: OccupancyGrid, b: OccupancyGrid, transform: Transform2D, *,
                  tolerance: int = 1) -> tuple[float, int]:
    """How well ``b`` (moved by ``transform`` into ``a``'s frame) agrees with ``a``.

    Returns ``(score, n)``: of b's occupied cells that land on a's known cells (``n`` of them),
    the fraction within ``tolerance`` cells of an occupied cell of a. A correct placement scores
    near 1; a wrong one lands walls in a's free space and scores low.
    """
    tolerance = whole(tolerance, "tolerance")
    if tolerance < 0:
        raise InputError(f"tolerance must be >= 0 cells, got {tolerance}")
    if not isinstance(a, OccupancyGrid) or not isinstance(b, OccupancyGrid):
        raise InputError("overlap_score compares two OccupancyGrid maps")
    if not isinstance(transform, Transform2D):
        raise InputError(f"transform must be a Transform2D, got {show(transform)}")
    occ_b = b.occupied_points()
    if len(occ_b) == 0:
        return 0.0, 0
    rr, cc = a.world_to_cell(transform(occ_b))
    ri = np.floor(rr).astype(np.int64)
    ci = np.floor(cc).astype(np.int64)
    inside = (ri >= 0) & (ri < a.rows) & (ci >= 0) & (ci < a.cols)
    ri, ci = ri[inside], ci[inside]
    known = a.known_mask()[ri, ci]
    n = int(known.sum())
    if n == 0:
        return 0.0, 0
    near = ndimage.binary_dilation(a.occupied_mask(), iterations=tolerance,
                                   structure=np.ones((3, 3), bool)) if tolerance > 0 else a.occupied_mask()
    return float(near[ri[known], ci[known]].mean()), n


def refine_points(reference: np.ndarray, moving: np.ndarray, initial: Transform2D,
                  resolution: float, *, config: AlignmentConfig = AlignmentConfig(),
                  reach: float | None = None, turn: float = math.radians(2.0), seed=None,
                  callback=None) -> Alignment:
    """Polish ``initial`` with a second, local swarm on the same eq. 3 objective.

    The masks are now the maps' whole sets of occupied cells, rasterised at half the map
    resolution, and the swarm searches a small box around ``initial``: ``reach`` m (default
    3 cells) and ``turn`` rad either way. This takes an alignment found from the unique poses'
    masks to sub-cell accuracy.
    """
    resolution = _cell_size(resolution)
    reference, moving = _points(reference, "reference"), _points(moving, "moving")
    if not isinstance(initial, Transform2D):
        raise InputError(f"initial must be a Transform2D, got {show(initial)}")
    if len(moving) == 0:
        raise InputError("an empty moving mask: no scan end points to align")
    fine = resolution / 2.0
    reach = 3 * resolution if reach is None else number(reach, "reach")
    turn = number(turn, "turn")
    if reach < 0 or turn < 0:
        raise InputError(f"reach and turn must be >= 0, got {show(reach)} m and {show(turn)} rad")
    fld = make_field(reference, fine, sigma=config.sigma)
    mov = dedupe_points(moving, fine)
    x0 = np.array(initial.to_paper())
    bounds = np.array([[x0[0] - reach, x0[0] + reach], [x0[1] - reach, x0[1] + reach],
                       [x0[2] - turn, x0[2] + turn]])
    pso = replace(config.pso, particles=min(config.pso.particles, 24),
                  iterations=min(config.pso.iterations, 40))

    def objective(params):
        return mse_cost(fld, mov, params)

    res = pso_minimize(objective, bounds, config=pso, seed=seed, init=x0[None, :],
                       callback=callback)
    dx, dy, dphi = (float(v) for v in res.x)
    return Alignment(Transform2D.from_paper(dx, dy, dphi), (dx, dy, dphi), float(res.fun), res,
                     (initial,))
