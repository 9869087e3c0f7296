"""The consensus method behind :func:`fusionkit.pipeline.merge` (the ``"consensus"`` name of
:mod:`fusionkit.methods`).

It returns the same :class:`~fusionkit.methods.base.MethodResult` as every other method, so the
command line and the benchmark compare them on equal terms: :func:`estimate_maps` places the
maps over its maximum spanning tree, and the result lists every pair it tried.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..base import MergeEvent, MergeStep, PreparedMaps, tree_result
from ._config import ConsensusConfig

__all__ = ["CONSENSUS", "ConsensusSettings", "ConsensusMethod"]

CONSENSUS = "consensus"


@dataclass(frozen=True)
class ConsensusSettings:
    """The consensus method's settings: its config, the poses of virtual scans, the seed."""

    consensus: ConsensusConfig = ConsensusConfig()
    virtual_poses: int = 1500
    seed: int = 0


class ConsensusMethod:
    """The consensus method (:mod:`fusionkit.methods.consensus`)."""

    name = CONSENSUS
    #: maps of several cell sizes compared at the finest (the paper's and the peers' rules were
    #: set on maps of one cell size)
    finest_cells = True

    def settings(self, config) -> ConsensusSettings:
        cfg = config.consensus if config.consensus is not None else ConsensusConfig()
        cfg = replace(cfg, max_false_merge=config.max_false_merge)
        return ConsensusSettings(cfg, config.virtual_poses, config.seed)

    def place(self, maps: PreparedMaps, settings: ConsensusSettings, emit):
        """Run :func:`estimate_maps` on the maps and list its pairs as steps."""
        from . import estimate_maps
        grids, scans, names = list(maps.grids), list(maps.scans), maps.names
        n = len(grids)
        ref = maps.reference
        seconds: dict = {}
        steps = []
        overlap = [0] * n

        def cb(stage, step, total, pair):
            label = names[step] if pair is None else f"{names[pair[1]]} -> {names[pair[0]]}"
            emit(MergeEvent(stage, step, total, label, pair))

        res = estimate_maps(grids, scans, config=settings.consensus, reference=ref,
                            seed=settings.seed, virtual_poses=settings.virtual_poses, callback=cb,
                            names=list(names))
        g = res.graph
        transforms, conf = list(g.transforms), list(g.confidences)
        tree, reasons = list(g.tree), list(g.reasons)
        groups = (list(g.groups), list(g.group_transforms), list(g.group_confidences),
                  list(g.group_trees))
        rivals = list(g.rivals) if g.rivals else [()] * n
        residual = [None] * n
        for a, b in tree:
            residual[b] = _residual(res.indexes[a], res.indexes[b],
                                    transforms[a].inverse @ transforms[b])
        for (i, j), p in res.pairs.items():
            ov = p.best.check.overlap if p.best is not None else 0
            steps.append(MergeStep(i, j, None, p.transform, p.confidence, ov,
                                   p.accepted or (i, j) in g.resolved, p.hypotheses))
        for a, b in tree:
            p = res.pairs.get((min(a, b), max(a, b)))
            overlap[b] = p.best.check.overlap if p is not None and p.best is not None else 0
        counts = np.zeros((n, n), int)
        for (i, j), p in res.pairs.items():
            counts[i, j] = counts[j, i] = len(p.plausible)
        virtual = tuple(ix.virtual for ix in res.indexes)
        logs = tuple(ix.log for ix in res.indexes)
        seconds.update(res.seconds)
        return tree_result(maps, transforms, conf, tree, reasons, overlap, counts, steps, logs,
                           virtual, seconds, groups=groups, rivals=rivals, residual=residual)


def _residual(a, b, t) -> float | None:
    """Median distance (m) from B's walls, placed in A by ``t`` (B -> A), to A's nearest wall,
    over those landing where A is known: how far a bent map's walls stay from the other's."""
    if len(b.points) == 0:
        return None
    ri, ci, inside = a.cells(t(b.points))
    ri, ci = ri[inside], ci[inside]
    keep = a.known[ri, ci]
    if not keep.any():
        return None
    return float(np.median(a.dist[ri[keep], ci[keep]])) * a.resolution
