"""The paper's method (``"spectral-pso"``): the placement part of its Fig. 1.

1. every map gets its scans (its ``.scans.npz``, or virtual scans cast in its free space);
2. unique poses by the DFT of the scans (Algorithm 1, eq. 1, :mod:`fusionkit.unique_poses`);
3. agreement between every two robots' unique poses and the fusion order (eq. 2,
   :mod:`fusionkit.pairing`);
4. for each step of the order, the alignment by PSO on the masks' MSE (eqs. 3-4,
   :mod:`fusionkit.alignment`, :mod:`fusionkit.pso`), checked against the maps already fused: a
   map that does not fit with confidence is left out, never forced.

The fusion of every placed map into the reference frame (Section 3.6, :mod:`fusionkit.fusion`)
is :func:`fusionkit.pipeline.merge`'s, as for every method.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ..alignment import align_points, mask_points, overlap_score, refine_points, seed_transforms
from ..errors import InputError
from ..fusion import fuse_maps
from ..pairing import PairAgreement, agreement, fusion_order
from ..pso import PSOState
from ..transform import Transform2D
from ..unique_poses import find_unique_poses
from .base import MergeEvent, MergeStep, MethodResult, Placement, PreparedMaps, common_confidence

__all__ = ["SPECTRAL_PSO", "SpectralPSO"]

SPECTRAL_PSO = "spectral-pso"


class SpectralPSO:
    """The paper's method: unique poses, Pearson pairing, PSO alignment."""

    name = SPECTRAL_PSO

    def settings(self, config):
        """The :class:`~fusionkit.pipeline.MergeConfig` itself: its fields are this method's
        settings (``sub_sec``, ``delta``, ``unique_count``, ``theta``, ``alignment``, ``accept``,
        ``min_overlap_cells``, ``refine``, ``virtual_poses``, ``seed``)."""
        return config

    def place(self, maps: PreparedMaps, config, emit) -> MethodResult:
        """Place the maps by steps 1-4 of the paper's Fig. 1 (``config``: :meth:`settings`)."""
        grids, scans, names = maps.grids, maps.scans, maps.names
        seconds: dict = {}

        # 1. scans: recorded, or cast virtually in the map's free space
        t0 = time.perf_counter()
        from ..virtual_scans import virtual_scans
        logs, virtual = [], []
        n = len(grids)
        ref = maps.reference
        # a map this method cannot use (nothing to scan from, too few scans, another beam count)
        # is left out with its reason and the others are merged; the reference cannot be
        reasons = [""] * n

        def unusable(k: int, why: str) -> None:
            if k == ref:
                raise InputError(f"{names[k]}: the reference map {why}; choose another map as the "
                                 "reference")
            reasons[k] = f"it {why}"

        for k, (g, s) in enumerate(zip(grids, scans)):
            emit(MergeEvent("scans", k, len(grids), names[k]))
            if k != ref and not g.occupied_mask().any():
                # no wall to align (the map's reason is the pipeline's): out of the plan, so
                # that it is never the first map placed, whose masks the others align to
                logs.append(None)
                virtual.append(False)
                continue
            if s is None:
                try:
                    s = virtual_scans(g, n_poses=config.virtual_poses, seed=config.seed + k)
                except InputError:
                    unusable(k, "has no free cell and no recorded scans, so no scan to match "
                                "(this method places maps by their scans)")
                virtual.append(s is not None)
            else:
                virtual.append(False)
            logs.append(s)
        beams = logs[ref].n_beams
        for k, s in enumerate(logs):
            if s is not None and s.n_beams != beams:
                unusable(k, f"has scans of {s.n_beams} beams where the reference's have {beams}; "
                            "spectra compare only scans of one beam count")
                logs[k] = None
        seconds["scans"] = time.perf_counter() - t0

        # 2. unique poses (Algorithm 1)
        t0 = time.perf_counter()
        unique = []
        least = 2 * config.sub_sec + 1
        for k, s in enumerate(logs):
            emit(MergeEvent("unique_poses", k, len(logs), names[k]))
            if s is not None and config.sub_sec >= 1 and s.n_scans < least:
                unusable(k, (f"has only {s.n_scans} scans" if not virtual[k] else
                             f"has free space for only {s.n_scans} virtual scans")
                         + f", fewer than the {least} of one section of Algorithm 1 "
                         f"(2*sub_sec+1)")
                logs[k] = None
            if logs[k] is None:
                unique.append(None)
                continue
            try:
                unique.append(find_unique_poses(s, sub_sec=config.sub_sec, delta=config.delta,
                                                target=config.unique_count))
            except InputError as exc:
                raise InputError(f"{names[k]}: {exc}") from None
        seconds["unique_poses"] = time.perf_counter() - t0

        # 3. agreement and fusion order (eq. 2)
        t0 = time.perf_counter()
        counts = np.zeros((n, n), int)
        agreements: dict = {}
        for a in range(n):
            for b in range(a + 1, n):
                emit(MergeEvent("pairing", len(agreements), n * (n - 1) // 2, f"{names[a]} ~ {names[b]}"))
                if unique[a] is None or unique[b] is None:
                    ka, kb = (len(u.indices) if u is not None else 0 for u in (unique[a], unique[b]))
                    agreements[(a, b)] = PairAgreement(a, b, np.zeros((ka, kb)), np.zeros((0, 2), int), 0)
                    continue
                ag = agreement(unique[a].unique_spectra, unique[b].unique_spectra, config.theta, a=a, b=b)
                agreements[(a, b)] = ag
                counts[a, b] = counts[b, a] = ag.count
        plan = fusion_order(counts)
        seconds["pairing"] = time.perf_counter() - t0

        # 4. alignment, step by step, each checked against what is already fused
        t0 = time.perf_counter()
        rng = np.random.default_rng(config.seed)
        res = grids[maps.reference].resolution
        transforms: list = [None] * n
        overlap = [0] * n
        steps: list[MergeStep] = []
        accepted_order: list = []
        if plan.steps:
            first = plan.steps[0][0]
            transforms[first] = Transform2D.identity()
        for si, (anchor, new) in enumerate(plan.steps):
            placed = [k for k in range(n) if transforms[k] is not None]
            ref_pts, mov_idx, seeds = [], set(), []
            for p in placed:
                ag = _pair(agreements, p, new)
                if ag.count == 0:
                    continue
                up, un = unique[p].indices, unique[new].indices
                matched_p = up[np.unique(ag.matches[:, 0])]
                ref_pts.append(transforms[p](mask_points(logs[p], matched_p)))
                mov_idx.update(un[np.unique(ag.matches[:, 1])].tolist())
                if config.alignment.seeded:
                    pairs = [(up[i], un[j]) for i, j in ag.matches[: config.alignment.max_seeds]]
                    seeds += [(ag_rho, transforms[p] @ t) for ag_rho, t in
                              zip(ag.rho[ag.matches[:, 0], ag.matches[:, 1]][: len(pairs)],
                                  seed_transforms(logs[p], logs[new], pairs))]
            seeds.sort(key=lambda st: -st[0])
            label = f"{names[new]} -> {names[anchor]}"

            def pso_cb(state: PSOState, _si=si, _label=label, _pair=(anchor, new)):
                emit(MergeEvent("align", _si, len(plan.steps), _label, _pair, state))

            emit(MergeEvent("align", si, len(plan.steps), label, (anchor, new)))
            mov_pts = mask_points(logs[new], sorted(mov_idx))
            if not ref_pts or len(mov_pts) == 0 or not grids[new].occupied_mask().any():
                # a map without walls is left out (its reason is the pipeline's), not the merge
                steps.append(MergeStep(anchor, new, None, None, 0.0, 0, False, 0))
                reasons[new] = "no matched scan end points to align"
                continue
            al = align_points(np.concatenate(ref_pts), mov_pts, res, config=config.alignment,
                              seeds=[t for _, t in seeds], seed=rng, callback=pso_cb)
            fused_now = fuse_maps([grids[k] for k in placed], [transforms[k] for k in placed]).grid
            if config.refine:
                fine = refine_points(fused_now.occupied_points(), grids[new].occupied_points(),
                                     al.transform, res, config=config.alignment, seed=rng,
                                     callback=pso_cb)
                al = replace(al, transform=fine.transform, params=fine.params, cost=fine.cost,
                             refinement=fine.pso)
            score, cells = overlap_score(fused_now, grids[new], al.transform)
            ok = score >= config.accept and cells >= config.min_overlap_cells
            steps.append(MergeStep(anchor, new, al, al.transform, score, cells, ok,
                                   int(_pair(agreements, anchor, new).count)))
            overlap[new] = cells   # a map left out: its agreement is in its reason
            if ok:
                transforms[new] = al.transform
                # the step's anchor may have been refused itself: the map is then fused onto the
                # placed map it agrees with most, and the order must say so
                onto = anchor if transforms[anchor] is not None else max(
                    placed, key=lambda p: (_pair(agreements, p, new).count, -p))
                accepted_order.append((onto, new))
            else:
                # as many digits as tell the share from the threshold (69.96% read "70%, needs 70%")
                digits = next((d for d in range(4) if f"{100 * score:.{d}f}"
                               != f"{100 * config.accept:.{d}f}"), 0)
                # named with the maps it was aligned to: the fused map of those placed so far
                reasons[new] = (f"best alignment agrees on {100 * score:.{digits}f}% of {cells} "
                                f"overlapping wall cells (needs {100 * config.accept:.{digits}f}% "
                                f"of >= {config.min_overlap_cells}) with the maps placed before it "
                                f"({', '.join(names[k] for k in placed)})")
        seconds["align"] = time.perf_counter() - t0

        # express everything in the reference map's frame
        ref = maps.reference
        if transforms[ref] is None:
            # the reference was not placed with the others: it stands alone, the rest is not merged
            transforms = [None] * n
            transforms[ref] = Transform2D.identity()
            accepted_order = []
            for k in range(n):
                if k != ref:
                    reasons[k] = reasons[k] or "no confident link to the reference map"
        else:
            to_ref = transforms[ref].inverse
            transforms = [None if t is None else to_ref @ t for t in transforms]
        # the report's confidence on the one scale of every method: the consensus test of the
        # link that placed each map (its share of walls says how much agreed, not how sure the
        # placement is)
        t1 = time.perf_counter()
        tested, _ = common_confidence(grids, transforms, accepted_order,
                                      ([None] * n, [None] * n, [0.0] * n, []), ref, config.seed,
                                      config.consensus, config.max_false_merge)
        confidence = [float(tested[k]) if transforms[k] is not None else 0.0 for k in range(n)]
        seconds["confidence"] = time.perf_counter() - t1
        for k in plan.unplaced:
            reasons[k] = reasons[k] or "its unique poses agree with none of the placed maps"

        # the fusion order: the accepted steps', the reference first when no step was accepted
        order = [accepted_order[0][0]] + [k for _, k in accepted_order] if accepted_order else []
        if ref not in order:
            order.insert(0, ref)
        placements = tuple(Placement(transforms[k], float(confidence[k]),
                                     "" if transforms[k] is not None else reasons[k], int(overlap[k]))
                           for k in range(n))
        return MethodResult(placements, tuple(accepted_order), tuple(order), plan, tuple(steps),
                            tuple(logs), tuple(virtual), tuple(unique), agreements, seconds)


def _pair(agreements: dict, a: int, b: int) -> PairAgreement:
    """The agreement of maps a and b with a's unique poses first."""
    if a < b:
        return agreements[(a, b)]
    ag = agreements[(b, a)]
    m = ag.matches[:, ::-1] if ag.count else ag.matches
    return PairAgreement(a, b, ag.rho.T, np.ascontiguousarray(m), ag.count)
