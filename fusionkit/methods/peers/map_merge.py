"""Feature-based map merging as done by ROS ``multirobot_map_merge`` (m-explore).

A re-implementation of the estimation half of ``combine_grids::MergingPipeline``
(hrnr/m-explore, ``map_merge/src/combine_grids/merging_pipeline.cpp``,
``estimation_internal.h``, ``grid_compositor.cpp``, ``grid_warper.cpp``) and of the OpenCV
stitching pieces it calls (opencv ``modules/stitching/src/matchers.cpp``:
``CpuMatcher``, ``AffineBestOf2NearestMatcher``; ``motion_estimators.cpp``:
``leaveBiggestComponent``, ``findMaxSpanningTree``, ``AffineBasedEstimator``,
``BundleAdjusterAffinePartial``).

What is followed
----------------
* The grid is read as an 8-bit image exactly as the node does (the ``int8`` cells viewed as
  ``uint8``): free 0, occupied 100, unknown 255; image ``x`` = column, ``y`` = row.
* AKAZE features with OpenCV's defaults (``cv2.AKAZE_create()``), the node's default finder.
* Best-of-2-nearest matching both ways with ``match_conf = 0.3`` (a match is kept when
  ``d1 < (1 - 0.3) d2``, i.e. ratio 0.7), the 2->1 matches added when not already found 1->2.
* Fewer than 6 matches: no motion. Otherwise ``cv2.estimateAffinePartial2D`` (RANSAC, 3 px,
  2000 iterations, 0.99, 10 refinement iterations: OpenCV's defaults, as the matcher calls it)
  and ``confidence = inliers / (8 + 0.3 * matches)`` (Brown and Lowe's coefficients).
* N maps: the pairwise matrix, the largest connected component of pairs whose confidence is at
  least the threshold (``leaveBiggestComponent``, with OpenCV's union by rank so that ties go
  the same way), a maximum spanning tree weighted by inlier counts over every pair of the
  component that has a motion (even one below the threshold, as OpenCV does), its centre as
  the reference, the motions chained breadth-first from the centre, then the affine-partial
  bundle adjustment over the pairs whose confidence exceeds the threshold, renormalised to the
  centre.

What is not followed
--------------------
* Matching is exact (brute-force Hamming) where OpenCV uses approximate FLANN LSH; this can
  only help the method and makes it deterministic (``seed`` is accepted for a uniform
  interface and has no effect).
* The node lets scale float (``estimateAffinePartial2D`` is a similarity). fusionkit returns a
  rigid transform: the rotation of the similarity and the translation that agrees with it at
  the centroid of the moving map's features; the scale is kept in ``diagnostics["scale"]``.
* The node re-centres the merged grid (its origin at minus half its size) and composes the
  grids by cell-wise maximum; those are output steps and are not reproduced here: transforms
  are returned in the frame of a chosen reference map instead.
* ``chaining="corrected"`` composes the chain and the bundle adjustment's prediction in the
  right order (see :func:`estimate_maps`); ``chaining="shipped"`` reproduces OpenCV's order.
* The bundle adjustment's Levenberg-Marquardt is SciPy's (MINPACK) instead of OpenCV's
  ``CvLevMarq``; both reach the same minimum of the same residuals.

References
----------
J. Hörner, "Map-merging for multi-robot system", Bachelor's thesis, Charles University, 2016.
M. Brown and D. G. Lowe, "Automatic panoramic image stitching using invariant features",
IJCV 74(1), 2007.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from ...errors import InputError
from ...grid import OccupancyGrid
from ...transform import Transform2D
from ._common import PairEstimate, Stopwatch, cell_to_map, make_options, prepare_pair
from ._map_merge_tree import _biggest_component, _bundle_adjust, _chain

__all__ = ["MapMergeOptions", "MapsEstimate", "estimate_pair", "estimate_maps", "grid_image", "METHOD"]

METHOD = "map-merge"


@dataclass(frozen=True)
class MapMergeOptions:
    """Settings of the feature-based merger (defaults are the node's and OpenCV's).

    Attributes
    ----------
    confidence : float
        ``estimation_confidence``: least pair confidence for a pair to count (> 0).
    match_conf : float
        OpenCV's ``match_conf``; a nearest neighbour is kept when its distance is below
        ``(1 - match_conf)`` times the second nearest's.
    num_matches_thresh1 : int
        Fewest matches for which a motion is estimated.
    ransac_reproj_threshold : float
        RANSAC inlier distance (pixels = cells).
    ransac_max_iters : int
        RANSAC iterations.
    ransac_confidence : float
        RANSAC confidence, in (0, 1).
    refine_iters : int
        Levenberg-Marquardt iterations refining the RANSAC motion on its inliers.
    bundle_adjust : bool
        Run the affine-partial bundle adjustment after chaining (N maps only).
    """

    confidence: float = 1.0
    match_conf: float = 0.3
    num_matches_thresh1: int = 6
    ransac_reproj_threshold: float = 3.0
    ransac_max_iters: int = 2000
    ransac_confidence: float = 0.99
    refine_iters: int = 10
    bundle_adjust: bool = True

    def __post_init__(self):
        if not self.confidence > 0:
            raise InputError(f"confidence must be > 0, got {self.confidence}")
        if not 0 <= self.match_conf < 1:
            raise InputError(f"match_conf must be in [0, 1), got {self.match_conf}")
        if self.num_matches_thresh1 < 3:
            raise InputError(f"num_matches_thresh1 must be >= 3, got {self.num_matches_thresh1}")
        if not self.ransac_reproj_threshold > 0:
            raise InputError(f"ransac_reproj_threshold must be > 0 cells, got {self.ransac_reproj_threshold}")
        if self.ransac_max_iters < 1 or self.refine_iters < 0:
            raise InputError("ransac_max_iters must be >= 1 and refine_iters >= 0")
        if not 0 < self.ransac_confidence < 1:
            raise InputError(f"ransac_confidence must be in (0, 1), got {self.ransac_confidence}")


# -- features and pairwise motion ------------------------------------------------------------

@dataclass(frozen=True)
class _Features:
    points: np.ndarray        # (K, 2) float32 image coordinates (x = col, y = row)
    descriptors: np.ndarray | None


@dataclass
class _Pair:
    """OpenCV's ``MatchesInfo`` for an ordered pair (src -> dst)."""

    H: np.ndarray | None = None                    # 3x3, maps src image points to dst
    matches: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))  # (query, train)
    inliers: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    num_inliers: int = 0
    confidence: float = 0.0

    def reversed(self) -> "_Pair":
        return _Pair(None if self.H is None else np.linalg.inv(self.H), self.matches[:, ::-1].copy(),
                     self.inliers.copy(), self.num_inliers, self.confidence)


def grid_image(grid: OccupancyGrid) -> np.ndarray:
    """The node's view of a grid: the ``int8`` cells as ``uint8`` (free 0, occupied 100,
    unknown 255), row 0 first."""
    return np.ascontiguousarray(grid.data).view(np.uint8)


#: Grids with fewer rows or columns than this have no features: OpenCV's AKAZE fails on a single
#: cell and corrupts its heap on a single row of many cells.
MIN_SIDE = 3


def _features(grid: OccupancyGrid) -> _Features:
    if min(grid.data.shape) < MIN_SIDE:
        return _Features(np.zeros((0, 2), np.float32), None)
    kps, desc = cv2.AKAZE_create().detectAndCompute(grid_image(grid), None)
    pts = np.array([k.pt for k in kps], np.float32).reshape(-1, 2)
    return _Features(pts, desc if len(kps) else None)


def _match(f1: _Features, f2: _Features, match_conf: float) -> np.ndarray:
    """OpenCV ``CpuMatcher``: best of two nearest neighbours both ways; rows ``(query, train)``
    with query in ``f1`` and train in ``f2``."""
    if f1.descriptors is None or f2.descriptors is None:
        return np.zeros((0, 2), np.int64)
    bf = cv2.BFMatcher(cv2.NORM_HAMMING)
    ratio = 1.0 - match_conf
    out, seen = [], set()
    for m in bf.knnMatch(f1.descriptors, f2.descriptors, k=2):
        if len(m) == 2 and m[0].distance < ratio * m[1].distance:
            out.append((m[0].queryIdx, m[0].trainIdx))
            seen.add((m[0].queryIdx, m[0].trainIdx))
    for m in bf.knnMatch(f2.descriptors, f1.descriptors, k=2):
        if len(m) == 2 and m[0].distance < ratio * m[1].distance:
            if (m[0].trainIdx, m[0].queryIdx) not in seen:
                out.append((m[0].trainIdx, m[0].queryIdx))
    return np.array(out, np.int64).reshape(-1, 2)


def _pair_motion(f1: _Features, f2: _Features, opts: MapMergeOptions) -> _Pair:
    """OpenCV ``AffineBestOf2NearestMatcher::match`` (partial affine)."""
    pair = _Pair(matches=_match(f1, f2, opts.match_conf))
    if len(pair.matches) < opts.num_matches_thresh1:
        pair.inliers = np.zeros(len(pair.matches), bool)
        return pair
    src = f1.points[pair.matches[:, 0]].reshape(-1, 1, 2)
    dst = f2.points[pair.matches[:, 1]].reshape(-1, 1, 2)
    m, mask = cv2.estimateAffinePartial2D(
        src, dst, method=cv2.RANSAC, ransacReprojThreshold=opts.ransac_reproj_threshold,
        maxIters=opts.ransac_max_iters, confidence=opts.ransac_confidence,
        refineIters=opts.refine_iters)
    if m is None or math.hypot(m[0, 0], m[1, 0]) < 1e-9:
        # no motion; a degenerate (zero-scale) one cannot be inverted and counts as none
        pair.inliers = np.zeros(len(pair.matches), bool)
        return pair
    pair.inliers = mask.ravel().astype(bool)
    pair.num_inliers = int(pair.inliers.sum())
    # confidence = inliers / (8 + 0.3 * matches)  (Brown and Lowe)
    pair.confidence = pair.num_inliers / (8 + 0.3 * len(pair.matches))
    pair.H = np.vstack([m, [0.0, 0.0, 1.0]])
    return pair


def _rigid_cells(sim_px: np.ndarray, anchor_cells: np.ndarray) -> tuple[Transform2D, float]:
    """A similarity between image pixel coordinates (moving -> fixed) as a rigid transform
    between cell frames (cell = pixel + 0.5) and its scale.

    The rigid transform keeps the similarity's rotation and agrees with it at ``anchor_cells``
    (the centroid of the moving map's features, cell frame)."""
    a = sim_px[:2, :2]
    t = sim_px[:2, 2]
    scale = math.hypot(a[0, 0], a[1, 0])
    theta = math.atan2(a[1, 0], a[0, 0])
    # pixel similarity -> cell similarity: c' = A (c - 0.5) + t + 0.5
    t_cell = t + 0.5 - a @ np.array([0.5, 0.5])
    target = a @ anchor_cells + t_cell
    c, s = math.cos(theta), math.sin(theta)
    r = np.array([[c, -s], [s, c]])
    tr = target - r @ anchor_cells
    return Transform2D(tr[0], tr[1], theta), scale


def estimate_pair(a: OccupancyGrid, b: OccupancyGrid, *, seed: int = 0, **options) -> PairEstimate:
    """Estimate the transform from map ``b``'s frame into map ``a``'s frame by AKAZE features.

    Parameters
    ----------
    a, b : OccupancyGrid
        The fixed and the moving map; ``b`` is resampled to ``a``'s resolution if they differ.
    seed : int
        Unused: the method is deterministic (accepted for a uniform interface).
    **options
        Fields of :class:`MapMergeOptions`.

    Returns
    -------
    PairEstimate
        ``confidence`` is ``inliers / (8 + 0.3 matches)``; ``accepted`` when it is at least
        ``options.confidence`` (1.0), as ``leaveBiggestComponent`` keeps a pair. ``transform``
        is None when fewer than ``num_matches_thresh1`` matches or no motion were found.
        ``diagnostics`` holds ``keypoints`` (a, b), ``matches``, ``inliers``, ``scale`` and
        the pixel-frame ``similarity`` (b -> a, 2x3).
    """
    clock = Stopwatch()
    opts = make_options(MapMergeOptions, options, METHOD)
    a, b = prepare_pair(a, b)
    fa, fb = _features(a), _features(b)
    # the pipeline matches image 0 against image 1: H maps a's pixels to b's
    pair = _pair_motion(fa, fb, opts)
    diag = {"keypoints": (len(fa.points), len(fb.points)), "matches": len(pair.matches),
            "inliers": pair.num_inliers}
    if pair.H is None:
        return PairEstimate(None, pair.confidence, False, (), METHOD, clock(), diag)
    sim = np.linalg.inv(pair.H)                      # b's pixels -> a's pixels
    anchor = fb.points[pair.matches[pair.inliers, 1]].astype(float).mean(axis=0) + 0.5
    cell_t, scale = _rigid_cells(sim, anchor)
    t = cell_to_map(a, b, cell_t)
    diag.update(scale=scale, similarity=sim[:2].copy())
    accepted = pair.confidence >= opts.confidence
    return PairEstimate(t, float(pair.confidence), bool(accepted), ((t, float(pair.confidence)),),
                        METHOD, clock(), diag)


@dataclass(frozen=True)
class MapsEstimate:
    """Result of :func:`estimate_maps`.

    Attributes
    ----------
    transforms : tuple of (Transform2D or None)
        Per input map, the transform from its frame into the reference map's frame (m, rad);
        None for a map left out (not in the largest confidently matched component).
    confidences : tuple of float
        Per input map, the best confidence of its pairs with the other kept maps (0 for a map
        left out).
    pair_confidence : (n, n) ndarray
        Every pair's confidence ``inliers / (8 + 0.3 matches)`` (symmetric, 0 on the diagonal).
    component : tuple of int
        Indices of the maps kept (``leaveBiggestComponent``).
    centre : int or None
        Index of the spanning tree's centre (the node's reference), None with fewer than two
        kept maps.
    tree : tuple of (int, int)
        Spanning-tree edges ``(parent, child)`` in the order they were chained.
    scales : tuple of float or None
        Per map, the scale of its similarity into the reference (1 for a perfect estimate).
    chaining : str
        ``"corrected"`` or ``"shipped"``.
    reference : int
        Index of the map whose frame the transforms are in.
    seconds : float
        Wall-clock time (s).
    diagnostics : dict
        ``keypoints`` per map, ``matches`` and ``inliers`` per pair ``(i, j)``, ``i < j``.
    group_transforms : tuple of (Transform2D or None) or None
        When the kept maps do not hold the reference: per map, its transform into the frame of
        the first kept map (None outside them); else None.
    """

    transforms: tuple
    confidences: tuple
    pair_confidence: np.ndarray
    component: tuple
    centre: int | None
    tree: tuple
    scales: tuple
    chaining: str
    reference: int
    seconds: float
    diagnostics: dict = field(default_factory=dict)
    group_transforms: tuple | None = None


def estimate_maps(grids, *, confidence: float = 1.0, chaining: str = "corrected", reference: int = 0,
                  seed: int = 0, **options) -> MapsEstimate:
    """Place N maps in one frame as ``multirobot_map_merge`` does.

    The pairwise motions are chained over a maximum spanning tree from its centre. With
    cameras ``R_k`` that map the reference (centre) image into image k (the node warps image k
    by ``R_k^-1``) and pair motions ``H_ij`` that map image i into image j, the child of an edge
    ``(i, j)`` must get ``R_j = H_ij R_i``; OpenCV's ``CalcAffineTransform`` computes
    ``R_j = R_i H_ij``. The two agree next to the centre (``R_i = I``) and whenever the motions
    commute (pure translations), so two maps always merge right, but a map two or more edges from
    the centre is misplaced once rotations are involved. The bundle adjustment predicts a match
    of pair ``(i, j)`` by ``R_i^-1 R_j`` where ``R_j R_i^-1`` is right, so it is right only for
    pairs that include the centre: when only the spanning tree's pairs are confident the
    misplaced chain has zero residual and stays; when other pairs are confident too (loops) it
    pulls maps away from their places, scale included, even maps next to the centre.
    ``"corrected"`` uses the right order in both steps. (m-explore report #70,
    "Improper merging when robots have different orientations", describes the symptom without a
    diagnosis; this ordering is one cause that fits it.)

    Parameters
    ----------
    grids : sequence of OccupancyGrid
        Two or more maps; each is resampled to the first one's resolution if needed.
    confidence : float
        Least pair confidence for a pair to join maps (the node's ``estimation_confidence``).
    chaining : {"corrected", "shipped"}
        Composition order along the spanning tree and in the bundle adjustment.
    reference : int
        Index of the map whose frame the transforms are returned in. If it is not in the kept
        component, every other map is reported left out.
    seed : int
        Unused: the method is deterministic.
    **options
        Other fields of :class:`MapMergeOptions` (``bundle_adjust``, RANSAC settings, ...).

    Returns
    -------
    MapsEstimate
    """
    clock = Stopwatch()
    if chaining not in ("corrected", "shipped"):
        raise InputError(f"chaining must be 'corrected' or 'shipped', got {chaining!r}")
    grids = list(grids)
    if len(grids) < 2:
        raise InputError(f"estimate_maps needs at least two maps, got {len(grids)}")
    if not 0 <= reference < len(grids):
        raise InputError(f"reference must be an index into the {len(grids)} maps, got {reference}")
    opts = make_options(MapMergeOptions, dict(options, confidence=confidence), METHOD)
    first = prepare_pair(grids[0], grids[0])[0]
    prepared = [first] + [prepare_pair(first, g)[1] for g in grids[1:]]
    n = len(prepared)
    feats = [_features(g) for g in prepared]

    # pairwise matrix: H of (i, j) maps image i into image j
    pairs = {}
    for i in range(n):
        pairs[i, i] = _Pair()
        for j in range(i + 1, n):
            if len(feats[i].points) and len(feats[j].points):
                pairs[i, j] = _pair_motion(feats[i], feats[j], opts)
            else:
                pairs[i, j] = _Pair()
            pairs[j, i] = pairs[i, j].reversed()
    conf = np.array([[pairs[i, j].confidence for j in range(n)] for i in range(n)])

    keep = _biggest_component(conf, opts.confidence)
    base = dict(pair_confidence=conf, chaining=chaining, reference=reference,
                diagnostics={"keypoints": tuple(len(f.points) for f in feats),
                             "matches": {(i, j): len(pairs[i, j].matches) for i in range(n) for j in range(i + 1, n)},
                             "inliers": {(i, j): pairs[i, j].num_inliers for i in range(n) for j in range(i + 1, n)}})
    if len(keep) < 2:
        # the node puts the first non-empty map at the identity and leaves the rest out
        ref_only = tuple(Transform2D.identity() if k == reference else None for k in range(n))
        return MapsEstimate(ref_only, tuple(0.0 for _ in range(n)), component=tuple(keep), centre=None,
                            tree=(), scales=tuple(1.0 if k == reference else None for k in range(n)),
                            seconds=clock(), **base)

    m = len(keep)
    sub = {(a, b): pairs[keep[a], keep[b]] for a in range(m) for b in range(m)}
    shipped = chaining == "shipped"
    cams, centre, tree_local = _chain(sub, m, shipped)
    tree = [(keep[a], keep[b]) for a, b in tree_local]
    if opts.bundle_adjust:
        cams = _bundle_adjust(cams, [feats[k] for k in keep], sub, opts.confidence, shipped)
        inv_c = np.linalg.inv(cams[centre])
        cams = [inv_c @ c if shipped else c @ inv_c for c in cams]

    def in_frame_of(root: int) -> tuple[tuple, tuple]:
        """The kept maps' transforms into map ``root``'s frame (a kept map), and their scales."""
        r_root = cams[keep.index(root)]
        transforms, scales = [None] * n, [None] * n
        for a, k in enumerate(keep):
            sim = r_root @ np.linalg.inv(cams[a])      # image k -> root image (pixels)
            pts = feats[k].points
            anchor = (pts.astype(float).mean(axis=0) + 0.5) if len(pts) else \
                np.array([prepared[k].cols / 2.0, prepared[k].rows / 2.0])
            cell_t, s = _rigid_cells(sim, anchor)
            transforms[k] = cell_to_map(prepared[root], prepared[k], cell_t)
            scales[k] = s
        transforms[root] = Transform2D.identity()
        return tuple(transforms), tuple(scales)

    group_transforms = None
    if reference not in keep:
        transforms = tuple(Transform2D.identity() if k == reference else None for k in range(n))
        scales = tuple(1.0 if k == reference else None for k in range(n))
        group_transforms = in_frame_of(keep[0])[0]
    else:
        transforms, scales = in_frame_of(reference)
    confs = tuple(float(max((conf[k, j] for j in keep if j != k), default=0.0)) if k in keep else 0.0
                  for k in range(n))
    return MapsEstimate(transforms, confs, component=tuple(keep), centre=keep[centre], tree=tuple(tree),
                        group_transforms=group_transforms,
                        scales=scales, seconds=clock(), **base)
