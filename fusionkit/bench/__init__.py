"""A benchmark suite: every method on the same seeded cases, scored against the truth.

Cases
-----
Each case is made from one ground-truth map (a *world*) and a seed, in one of two modes:

``explore``
    ``K`` simulated robots explore the world (:func:`fusionkit.simulate.simulate`); each brings
    its own map and scans, in its own frame (CONTRACTS section 5).
``crop``
    ``K`` overlapping square windows are cut from the world, each turned by a random angle,
    shifted by a random offset and resampled into a frame of its own: the classic map-merging
    benchmark. These maps come without scans.
``log``
    a real CARMEN laser log (a *log world*, :func:`find_logs`) cut into ``K`` consecutive
    sessions sharing 30 % of their length, each mapped in the frame of its first pose with its
    recorded scans, as ``fusionkit import carmen --split K`` writes them; the world is the map
    of the whole log and the truth the log's corrected poses. Every log world gives one case for
    each ``K`` of ``robots``, besides the ``cases`` drawn from the map worlds.

The *overlap* of two maps is the share of the smaller one's known cells (in the world) that the
other also knows. Cases are drawn so that every map overlaps another one by at least
``min_overlap`` and all are linked to the reference (the first map) by such overlaps; when a
simulation cannot give that in a few tries, the maps left unlinked are scored apart (refusing
them is right). A map with fewer than ``MIN_MAP_WALLS`` occupied cells (a robot that saw no wall
in range, as on an open campus) holds nothing to place it by: it links nothing and is scored
apart too.

Scoring
-------
Every non-reference map of a case is one *pair* (the map and the reference frame). A merged map
is a **success** when its rotation error is below ``max_rotation_deg`` and the known-cell centroid
of the map lands within ``max_cells`` cells of where the true transform puts it; merged outside
those bounds it is a **wrong merge**; not merged it is a **refusal**. The fused map of each case is
scored with the paper's Table 1 metrics (CONTRACTS section 7) against the world, placed by the
reference's true transform, beside the oracle (the fusion with the true transforms). Time per
pair is a merge's wall time over ``K - 1``.

Cases are independent: each is built from its own seed inside whichever process runs it, and
results are gathered in case order, so the figures do not depend on ``jobs`` (wall times do).

Modules
-------
:mod:`.config` (:class:`BenchConfig`), :mod:`.cases` (worlds and case making), :mod:`.runner`
(running a case and a suite) and :mod:`.report` (summary, tables, JSON and figures); every
public name is also importable from :mod:`fusionkit.bench` itself.
"""

from __future__ import annotations

from .cases import (LOG_SPLIT, Case, CaseSpec, WorldSpec, find_logs, find_worlds, load_log,
                    load_world, make_case, plan_cases)
from .config import (DEFAULT_METHODS, MIN_MAP_WALLS, MIN_WORLD_OCCUPIED, MODES, OVERLAP_BINS,
                     BenchConfig)
from .report import format_markdown, format_table, summarize, write_outputs
from .runner import BenchResult, run_bench, run_case

__all__ = ["BenchConfig", "WorldSpec", "CaseSpec", "Case", "find_worlds", "find_logs", "plan_cases",
           "make_case", "load_log", "LOG_SPLIT",
           "run_case", "BenchResult", "run_bench", "summarize", "format_markdown", "write_outputs",
           "MODES", "DEFAULT_METHODS", "OVERLAP_BINS", "load_world", "format_table",
           "MIN_WORLD_OCCUPIED", "MIN_MAP_WALLS"]
