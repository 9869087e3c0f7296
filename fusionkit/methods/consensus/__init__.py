"""The consensus method: many hypotheses, each verified on the whole maps, kept consistent
over all maps, and a refusal when it is not sure.

For every pair of maps, candidate placements come from two independent sources:

* **scans** (when the maps come with recorded scans): every scan of one map is matched to every
  scan of the other by Pearson's rho of their DC-free ``|DFT|`` spectra (the paper's eqs. 1-2,
  over all poses, not only Algorithm 1's unique ones); each match gives a hypothesis (heading
  from the circular cross-correlation of the two scans, translation from the two poses), and the
  hypotheses are clustered (:mod:`._hypotheses`);
* **walls**: rotations from the correlation of the maps' wall-direction histograms, and for each
  the translations that put the most walls on walls and the fewest on open floor, by FFT
  correlation (:mod:`._search`).

Each candidate is refined on the full maps' walls (ICP on the distance field; the best ones
also turned a degree or two either way and refined again, as ICP can settle a degree off on a
cluttered map; optionally the paper's PSO of eq. 3 in a small box) and verified both ways
(:func:`verify`): the fraction of
each map's walls, where the other map is known, that lie within one cell of the other's walls,
and the walls drawn on the other's clear free space. The decision does not rest on thresholds in
metres, cells or percent: the best placement's evidence is judged against the evidence the same
two maps reach at many wrong placements (a null distribution drawn from the maps themselves,
:class:`NullModel`), and accepted when its number of false alarms is at most the risk the user
accepts (``max_false_merge``) and no distinct placement comes close; when several fit
(repetitive buildings), loops through third maps decide. The placements are chained over a maximum
spanning tree by confidence and every two placed maps are cross-checked (:mod:`._graph`).
"""

from __future__ import annotations

import contextlib
import functools
import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Callable, Sequence

from scipy.spatial import cKDTree

from .candidates import estimate_fleet
from ...errors import InputError
from ...executor import Executor, InProcess, current_executor
from ...grid import OccupancyGrid
from ...scanlog import ScanLog
from ._graph import GraphResult, solve_graph
from ._index import MapIndex, index_map
from ._pair import Candidate, ConsensusConfig, PairResult, corners, estimate_indexed
from ._search import evidence_raster, orientation_histogram
from ._null import NullModel, null_model
from ._memo import forget_pairs
from ._verify import Check, refine_icp, refine_pso, verify

__all__ = ["ConsensusConfig", "Check", "Candidate", "PairResult", "GraphResult", "MapsResult",
           "MapIndex", "prepare_maps", "estimate_pair", "estimate_maps", "verify", "refine_icp",
           "refine_pso", "NullModel", "null_model", "placement_confidence", "METHOD"]

METHOD = "consensus"


def prepare_maps(grids: Sequence[OccupancyGrid], scans: Sequence[ScanLog | None] | None = None, *,
                 config: ConsensusConfig = ConsensusConfig(), virtual_poses: int = 1500,
                 seed: int = 0) -> list[MapIndex]:
    """One :class:`MapIndex` per map (virtual scans are cast only with ``config.virtual_scans``)."""
    grids = list(grids)
    scans = list(scans) if scans is not None else [None] * len(grids)
    if len(scans) != len(grids):
        raise InputError(f"{len(scans)} scan logs for {len(grids)} maps: give one per map (None for none)")
    out = []
    for k, (g, s) in enumerate(zip(grids, scans)):
        if not isinstance(g, OccupancyGrid):
            raise InputError(f"map {k} is a {type(g).__name__}, not an OccupancyGrid")
        virtual = False
        if s is None or not config.use_scans:
            s = None
            if config.use_scans and config.virtual_scans and g.free_mask().any():
                from ...virtual_scans import virtual_scans
                s = virtual_scans(g, n_poses=virtual_poses, seed=seed + k)
                virtual = True
        out.append(index_map(g, s, virtual=virtual, pose_spacing=config.pose_spacing,
                             max_poses=config.max_poses, max_refine_points=config.max_refine_points))
    if len({round(i.resolution, 12) for i in out}) > 1:
        raise InputError("the maps have different resolutions; resample them to one first")
    return out


def _pair(indexes, hists, evidence, trees, cfg, i, j, seed, exhaustive=False) -> PairResult:
    return estimate_indexed(indexes[i], indexes[j], cfg, hist_a=hists[i], hist_b=hists[j],
                            evidence_a=evidence[i], ia=i, ib=j, seed=seed, exhaustive=exhaustive,
                            tree_a=trees.get(i))


def _pair_task(shared, task) -> PairResult:
    indexes, hists, evidence, trees, cfg = shared
    i, j, seed, exhaustive = task
    return _pair(indexes, hists, evidence, trees, cfg, i, j, seed, exhaustive)


def estimate_pair(a: OccupancyGrid, b: OccupancyGrid, *, scans_a: ScanLog | None = None,
                  scans_b: ScanLog | None = None, config: ConsensusConfig = ConsensusConfig(),
                  seed: int = 0, priors=()):
    """Place map ``b`` in map ``a``'s frame.

    Returns
    -------
    fusionkit.methods.peers.PairEstimate
        ``transform`` maps b's frame into a's (m, rad), ``confidence`` how sure the method
        is of it (0..1; :attr:`PairResult.confidence`), ``accepted`` whether it passed;
        ``candidates`` lists every distinct placement that passed the test, each with that
        confidence (the best one with the pair's); ``diagnostics["pair"]`` is the
        :class:`PairResult`. ``priors``: placements (B -> A) from elsewhere refined and judged
        with the search's own (:func:`estimate_indexed`).
    """
    from ..peers import PairEstimate
    t0 = time.perf_counter()
    ia, ib = prepare_maps([a, b], [scans_a, scans_b], config=config, seed=seed)
    pr = estimate_indexed(ia, ib, config, hist_a=orientation_histogram(ia),
                          hist_b=orientation_histogram(ib),
                          evidence_a=evidence_raster(ia, coarse=config.coarse, max_side=config.coarse_side), seed=seed,
                          priors=priors)
    return PairEstimate(pr.transform, pr.confidence, pr.accepted,
                        tuple((c.transform, pr.confidence if c is pr.best else c.confidence)
                              for c in pr.plausible) or
                        (((pr.transform, pr.confidence),) if pr.transform is not None else ()),
                        METHOD, time.perf_counter() - t0, {"pair": pr, "reason": pr.reason})


def placement_confidence(a: MapIndex, b: MapIndex, t, *, config: ConsensusConfig = ConsensusConfig(),
                         seed: int = 0) -> float:
    """The confidence (0..1, ``exp(-nfa)``) the consensus test gives a placement ``t`` (B -> A)
    found by any method: the same scale for every method's report."""
    import math

    import numpy as np
    if len(a.points) == 0 or len(b.points) == 0 or t is None:
        return 0.0
    box = corners(b)
    null, _ = null_model(a, b, t, box, samples=config.null_samples,
                         distinct=config.distinct_cells * a.resolution,
                         points=b.refine_points[:: max(1, len(b.refine_points) // config.coarse_points)],
                         calibration=config.calibration, correlation=config.wall_correlation,
                         correlation_max=config.wall_correlation_max, basin=config.test_basin,
                         seed=np.random.default_rng(seed))
    nfa = null.nfa(verify(a, b, t))
    return math.exp(-nfa) if math.isfinite(nfa) else 0.0


@dataclass(frozen=True, eq=False)
class MapsResult:
    """Result of :func:`estimate_maps`: the per-pair results, the placement of every map and
    the indexes built (``seconds`` per stage)."""

    pairs: dict
    graph: GraphResult
    indexes: tuple
    seconds: dict = field(default_factory=dict)

    @property
    def transforms(self) -> tuple:
        return self.graph.transforms


def estimate_maps(grids: Sequence[OccupancyGrid], scans: Sequence[ScanLog | None] | None = None, *,
                  config: ConsensusConfig = ConsensusConfig(), reference: int = 0, seed: int = 0,
                  virtual_poses: int = 1500,
                  callback: Callable[[str, int, int, tuple | None], None] | None = None,
                  executor: Executor | None = None, names: Sequence[str] | None = None) -> MapsResult:
    """Place every map in the reference map's frame (or leave it out when not sure).

    Parameters
    ----------
    grids : sequence of OccupancyGrid
        Two or more maps of one resolution.
    scans : sequence of ScanLog or None, optional
        Recorded scans per map (None where a map has none).
    config : ConsensusConfig
    reference : int
        Index of the map whose frame the transforms are in.
    seed : int
        Seed of the random steps (virtual scans, the optional swarm polish).
    callback : callable(stage, step, total, pair), optional
        Called, in the calling thread, as each map is prepared (``"scans"``) and each pair is
        estimated (``"align"``, with ``pair = (i, j)``). The pairs are counted over the whole
        merge: a fleet's pairs added after the first candidates and the pairs of a map left
        out searched again over every rotation raise ``total`` and ``step`` counts on, so that
        ``step`` never goes back.

    executor : fusionkit.executor.Executor, optional
        Where the pairs are estimated (default: the one set by
        :func:`fusionkit.executor.using`, else ``config.threads`` threads here).
    names : sequence of str, optional
        What the reasons call each map (default: "map K of those given", K from 1).

    Maps are prepared on ``config.threads`` threads (the kernels release the interpreter) and
    pairs estimated on the executor; the result does not depend on either. With
    ``config.candidates``, a large fleet has only its candidate pairs estimated
    (:func:`fusionkit.methods.consensus.candidates.estimate_fleet`).
    """
    grids = list(grids)
    n = len(grids)
    if n < 2:
        raise InputError(f"merging needs at least two maps, got {n}")
    if not 0 <= reference < n:
        raise InputError(f"reference index {reference} is not one of the {n} maps")
    seconds = {}
    t0 = time.perf_counter()
    scans = list(scans) if scans is not None else [None] * n
    workers = config.threads or os.cpu_count() or 1
    workers = max(1, min(workers, max(n, n * (n - 1) // 2)))
    with ThreadPoolExecutor(max_workers=workers) if workers > 1 else contextlib.nullcontext() as pool:

        def run(jobs, stage, label):
            # results are gathered in a fixed order, so they do not depend on the threads
            futures = None if pool is None else [pool.submit(fn) for fn in jobs]
            out = []
            for step, fn in enumerate(jobs):
                if callback is not None:
                    callback(stage, step, len(jobs), label(step))
                out.append(fn() if futures is None else futures[step].result())
            return out

        def prepare(k):
            ix = prepare_maps([grids[k]], [scans[k]], config=config, seed=seed + k,
                              virtual_poses=virtual_poses)[0]
            corners(ix)
            return (ix, orientation_histogram(ix),
                    evidence_raster(ix, coarse=config.coarse, max_side=config.coarse_side),
                    cKDTree(ix.cloud) if len(ix.cloud) else None)

        prepared = run([functools.partial(prepare, k) for k in range(n)], "scans", lambda s: None)
        indexes = [p[0] for p in prepared]
        if len({round(i.resolution, 12) for i in indexes}) > 1:
            raise InputError("the maps have different resolutions; resample them to one first")
        hists = [p[1] for p in prepared]
        evidence = [p[2] for p in prepared]
        trees = {k: p[3] for k, p in enumerate(prepared) if p[3] is not None}
        seconds["prepare"] = time.perf_counter() - t0

        ex = executor if executor is not None else current_executor()
        ex = ex if ex is not None else InProcess(workers)
        shared = (indexes, hists, evidence, trees, config)

        counted = [0]  # pairs estimated before this call: the count runs on over every call

        def estimate(todo, exhaustive=False):
            before = counted[0]

            def progress(done, total):
                # step = pairs finished, pair = the next one in order; a fleet's later pairs
                # and the wider search of a map left out count on from the pairs before them
                if callback is not None and done < total:
                    callback("align", before + done, before + total, todo[done])
            tasks = [(i, j, seed, exhaustive) for i, j in todo]
            out = dict(zip(todo, ex.map(_pair_task, tasks, shared=shared, progress=progress)))
            counted[0] += len(todo)
            return out

        t0 = time.perf_counter()
        pairs = estimate_fleet(estimate, indexes, hists, config.candidates)
        seconds["pairs"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        boxes = [corners(ix) for ix in indexes]
        graph = solve_graph(pairs, indexes, reference, config, boxes, names)
        seconds["graph"] = time.perf_counter() - t0
        left = [k for k in range(n) if graph.transforms[k] is None]
        if config.fallback and left:
            # a map left out: search its undecided pairs again, exhaustively
            t0 = time.perf_counter()
            redo = [(i, j) for (i, j), p in pairs.items() if (i in left or j in left) and not p.accepted]
            pairs.update(estimate(redo, exhaustive=True))
            graph = solve_graph(pairs, indexes, reference, config, boxes, names)
            seconds["fallback"] = time.perf_counter() - t0
        for ix in indexes:
            forget_pairs(ix)
    return MapsResult(pairs, graph, tuple(indexes), seconds)
