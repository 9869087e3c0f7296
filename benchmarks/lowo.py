"""Leave-one-world-out over every family of cases, with the peers on the same pairs in the same run.

    python benchmarks/lowo.py [--maps DIR] [--logs DIR] [--seed 1] [--crops 5] [--explore 2]
                              [--drift-cases 2] [--drift 0.01] [--drift-theta 0.001]
                              [--repetitive 6] [--splits 2 3 4] [--negatives 1.0]
                              [--peers map-merge fourier-mellin hough-spectrum spectral-pso]
                              [--peers-on-negatives] [--quick] [--out FILE] [--from FILE]
    python benchmarks/lowo.py --pooled RECORD [RECORD ...] [--crop-records RECORD ...] [--cross-wall M]

Families of pairs of maps (K = 2), each pair with its truth and its *world* (the building; two
maps of one building, such as the two RoboCup arena maps, the two Yujin runs or the Intel lab map
and the Intel log, are one world):

``crop``
    two overlapping windows of a real floor of ``--maps`` at its native cell size
    (``fusionkit.bench`` crop cases, 55 % of the floor's shorter side, at least 15 % shared);
``explore``
    two simulated robots exploring a real floor, without odometry drift;
``drift``
    the same with odometry drift (``--drift`` m and ``--drift-theta`` rad per sqrt(m));
``repetitive``
    crops and explorations of the built-in worlds of identical rooms (``office``) and rack rows
    (``warehouse``);
``logs``
    the CARMEN logs of ``--logs`` split into K = 2..4 sessions (``fusionkit import carmen
    --split K``); every two consecutive sessions are a pair.

*Negatives*: in each family, the first map of a pair against the second map of a pair of another
world (resampled to the first's cell size when they differ): every placement is wrong. And a
family of their own, ``apart``: maps of one building whose robots never met (simulated runs of
every real floor and of the repetitive worlds, pairs whose known areas share at most 2 %,
``--apart`` runs per world, :func:`apart_pairs`); in a building of identical rooms or rack rows
their best placement lays one room on another. The threshold is chosen on the negatives of two
buildings; those of one building are judged with it, not chosen on.

The consensus method estimates every pair (:func:`fusionkit.methods.consensus.estimate_pair`,
default settings) and the inputs of its decision are recorded: ``log10_nfa - calibration`` (the
model's count of false alarms without the calibrated offset), whether a distinct rival placement
fits nearly as well (the rival test does not depend on the offset), and whether its best placement
is right (within 3 cells at the moving map's known-area centroid and 2 degrees). With an offset
``c`` a pair is merged when ``model + c <= log10(max_false_merge)``, no rival is found and the
walls that meet at its best placement fix it in every direction (``cross_wall_m``, the metres of
them across the direction it is least held in, at least ``ConsensusConfig.cross_wall``; neither
check depends on the offset).

Leave-one-world-out: for each world, the offset is chosen on the negatives of all the other worlds
by the rule the shipped constant was chosen by (the least offset, in quarter decades and possibly
below zero, at which the whole decision merges none of them, plus one decade) and that world's
positives and negatives are judged with it. In sample: the offset chosen on every world. The
default offset (``ConsensusConfig.calibration``) is reported too, and so is a stricter choice:
the offset at which the test alone, without the rival test, would refuse every negative.

A positive is *resolvable* unless some distinct placement fits at least as well as the truth: the
truth (and the truth polished by ICP on the walls, when that stays within 3 cells) is verified on
both maps (:func:`fusionkit.methods.consensus.verify`, the robust evidence: agreeing wall cells
minus misfits, three times per wall on clear free space), against every distinct placement
(more than ``ConsensusConfig.distinct_cells`` cells away) that the consensus search refined or
that a peer returned. Crops of identical rooms whose overlap holds no unique feature are the
pairs this leaves out.

The peers run on the same maps through :func:`fusionkit.pipeline.merge` (``MergeConfig(method=...)``,
same seed), scored alike; their time is the merge's wall time less its fusion and the common-scale
confidence. Prints Markdown tables; ``--out`` records every pair (JSON, written after every pair),
``--from`` redoes the tables from such a record in seconds. ``--pooled`` judges several draws' records
with offsets chosen on the negatives of all of them (and of the crop draws' records of
``benchmarks/calibrate_consensus.py``, ``--crop-records``), each world left out: the rule the
shipped constant is chosen by, the highest choice of several draws, measured out of sample.

Default sizes: 5 crops, 2 explorations and 2 drifting explorations per real floor, 6 crops and 6
explorations per repetitive world, the logs at K = 2, 3, 4, one negative per positive, one
``apart`` run per world: 246 positives, 246 negatives of two buildings and about 600 of one,
about 1650 s on the project's 2-core machine beside a second run
(``benchmarks/records/lowo_seed1.json`` and ``lowo_seed2.json`` are the records of ``--seed 1``
and ``--seed 2``). ``--quick``: 4 floors, one pair of
each kind, K = 2, no ``apart`` runs, spectral-pso left out: 40 pairs in about 80 s.
"""

from __future__ import annotations

import argparse
import functools
import itertools
import json
import math
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parents[1]
FAMILIES = ("crop", "explore", "drift", "repetitive", "logs", "apart")
PEERS = ("map-merge", "fourier-mellin", "hough-spectrum", "spectral-pso")
#: offsets tried (decades, quarter steps); below 0 the model counts more false alarms than occur
GRID = np.arange(-20.0, 100.01, 0.25)
#: decades added to the least offset that merges no negative (as the shipped constant was chosen)
MARGIN = 1.0
#: ``--cross-wall``: the least metres of meeting wall across a placement the tables judge with
#: (None: the shipped ``ConsensusConfig.cross_wall``)
CROSS_WALL = None
#: map or log name -> building, where two of them show the same place
SAME_PLACE = {"robocup17_nagoya_gmapping": "robocup17_nagoya", "robocup17_nagoya_srrg": "robocup17_nagoya",
              "yujin_office_run1": "yujin_office", "yujin_office_run2": "yujin_office",
              "intel_lab": "intel"}


def building(name: str) -> str:
    """The world (building) a map or log shows."""
    return SAME_PLACE.get(name, name)


# ---------------------------------------------------------------------------------------------
# Pairs
# ---------------------------------------------------------------------------------------------
def _seed(*keys: int) -> int:
    return int(np.random.SeedSequence([int(k) for k in keys]).generate_state(1)[0] % 2**31)


def _rescale(g, resolution: float):
    """``g`` resampled (nearest neighbour) to cells of ``resolution`` metres, same frame."""
    from fusionkit.resample import canvas_for, resample
    from fusionkit.transform import Transform2D
    if abs(g.resolution - resolution) < 1e-12:
        return g
    ident = Transform2D.identity()
    return resample(g, ident, canvas_for([g], [ident], resolution))


def case_pairs(family: str, worlds, per_world: int, seed: int, fam_id: int, *, modes=("crop",),
               drift=(0.0, 0.0), skipped: list) -> list[dict]:
    """Pairs from ``fusionkit.bench`` cases: ``per_world`` cases of each world in each mode."""
    from fusionkit.bench import BenchConfig, CaseSpec, make_case
    from fusionkit.errors import FusionkitError
    out = []
    for mi, mode in enumerate(modes):
        cfg = BenchConfig(methods=("consensus",), modes=(mode,), robots=(2,), cases=1,
                          drift=drift[0], drift_theta=drift[1], seed=seed)
        for wi, w in enumerate(worlds):
            for n in range(per_world):
                s = _seed(seed, fam_id, mi, wi, n)
                try:
                    case = make_case(CaseSpec(n, w, mode, 2, s), cfg)
                except FusionkitError as exc:
                    skipped.append(f"{family} {w.name} case {n}: {exc}")
                    continue
                if not case.linked[1]:
                    skipped.append(f"{family} {w.name} case {n}: the two maps do not overlap enough")
                    continue
                out.append({"family": family, "world": building(w.name), "source": w.name,
                            "mode": mode, "case_seed": s, "a": case.grids[0], "b": case.grids[1],
                            "scans_a": case.scans[0], "scans_b": case.scans[1],
                            "truth": case.truth[0].inverse @ case.truth[1]})
    return out


def log_pairs(logs_dir: Path, splits, seed: int, tmp: Path, skipped: list) -> list[dict]:
    """Every two consecutive sessions of every log split into each K of ``splits``."""
    from fusionkit.errors import FusionkitError
    from fusionkit.io_carmen import import_carmen
    from fusionkit.pipeline import load_inputs
    from fusionkit.transform import Transform2D
    out = []
    for log in sorted(logs_dir.glob("*.log")):
        name = log.name.split(".")[0]
        for k in splits:
            d = tmp / f"{name}{k}"
            try:
                import_carmen(log, d, split=k)
            except FusionkitError as exc:
                skipped.append(f"logs {name} K={k}: {exc}")
                continue
            truth = json.loads((d / "truth.json").read_text())
            t = [Transform2D(**r["transform"]) for r in truth["robots"]]
            grids, scans = load_inputs([str(d / f"robot_{i + 1}.yaml") for i in range(k)])
            for i in range(k - 1):
                out.append({"family": "logs", "world": building(name), "source": f"{name} K={k} {i + 1}-{i + 2}",
                            "mode": "log", "case_seed": _seed(seed, 9, k, i), "a": grids[i], "b": grids[i + 1],
                            "scans_a": scans[i], "scans_b": scans[i + 1], "truth": t[i].inverse @ t[i + 1]})
    return out


def _apart_runs(real, runs: int, drift):
    """Every simulated run of :func:`apart_pairs`: ``(world, name, grid, robots, poses, drift,
    key, run)``, each world's grid loaded or generated once."""
    from fusionkit.bench.cases import load_world
    from fusionkit.worlds import make_world
    still = (0.0, 0.0)
    for wi, w in enumerate(real):
        g = load_world(w)
        for n in range(runs):
            for d in (still, drift):
                yield building(w.name), w.name, g, 6, 60, d, (wi, n, d != still), n
    for ki, kind in enumerate(("office", "warehouse")):
        for layout in range(4):
            for si, size in enumerate(((40.0, 30.0), (60.0, 40.0))):
                g = make_world(kind, layout, size, 0.1)
                name = f"{kind} layout {layout} {size[0]:g}x{size[1]:g} m"
                for poses in (60, 120):
                    for n in range(runs):
                        for d in (still, drift):
                            yield kind, name, g, 5, poses, d, (1000 + ki, layout, si, poses, n, d != still), n


def apart_pairs(real, runs: int, seed: int, fam_id: int, drift=(0.01, 0.001)) -> list[dict]:
    """Negatives within one building: maps of robots of one simulated run that never met (their
    known areas share at most 2 % of the smaller one). Six robots, 60 poses each, explore every
    real floor ``runs`` times without drift and ``runs`` times with ``drift``; the repetitive
    worlds (``office``, ``warehouse``, layouts 0-3, 40 x 30 m and 60 x 40 m) are explored by five
    robots with 60 and 120 poses, ``runs`` times each way. Every placement of such a pair is
    wrong (they share no wall to be placed by); their world is the building, left out with it."""
    from fusionkit.bench.cases import _overlaps
    from fusionkit.resample import resample
    from fusionkit.simulate import MotionConfig, SimulationConfig, simulate
    out = []
    for world, name, g, robots, poses, d, key, run in _apart_runs(real, runs, drift):
        s = _seed(seed, fam_id, *[int(k) for k in key])
        sim = simulate(g, SimulationConfig(robots=robots, poses=poses, seed=s,
                                           motion=MotionConfig(drift_xy=d[0], drift_theta=d[1])))
        ov = _overlaps([resample(r.grid, r.transform, g).known_mask() & g.known_mask()
                        for r in sim.robots])
        walls = [int(r.grid.occupied_mask().sum()) for r in sim.robots]
        for i, j in itertools.combinations(range(robots), 2):
            if ov[i, j] > 0.02 or min(walls[i], walls[j]) < 50:
                continue
            a, b = sim.robots[i], sim.robots[j]
            out.append({"family": "apart", "world": world, "other": world,
                        "source": f"{name} {poses} poses{' drift' if d[0] else ''} run {run} {i + 1}-{j + 1}",
                        "mode": "explore", "case_seed": _seed(s, i, j), "a": a.grid, "b": b.grid,
                        "scans_a": a.scans, "scans_b": b.scans, "truth": None})
    return out


def negatives(pos: list[dict], ratio: float, seed: int, fam_id: int) -> list[dict]:
    """First maps of the family's pairs against second maps of pairs of other worlds."""
    rng = np.random.default_rng(_seed(seed, 100 + fam_id))
    out = []
    count = int(round(ratio * len(pos)))
    if len({p["world"] for p in pos}) < 2:
        return out
    for n in range(count):
        p = pos[n % len(pos)]
        others = [q for q in pos if q["world"] != p["world"]]
        q = others[int(rng.integers(len(others)))]
        out.append({"family": p["family"], "world": p["world"], "other": q["world"],
                    "source": f"{p['source']} / {q['source']}", "mode": p["mode"],
                    "case_seed": _seed(seed, 200 + fam_id, n), "a": p["a"],
                    "b": _rescale(q["b"], p["a"].resolution), "scans_a": p["scans_a"],
                    "scans_b": q["scans_b"], "truth": None})
    return out


def draw_pairs(st: dict, real, builtin, logs_dir: Path, tmp: Path, skipped: list):
    """``(family, pair)`` for every pair of a draw, in the order a record holds them: ``st``
    holds the command's sizes (``seed``, ``families``, ``crops``, ``explore``, ``drift_cases``,
    ``drift``, ``drift_theta``, ``repetitive``, ``splits``, ``apart``, ``negatives``), as the
    record's ``settings`` do."""
    for fid, fam in enumerate(FAMILIES):
        if fam not in st["families"]:
            continue
        if fam == "crop":
            pos = case_pairs(fam, real, st["crops"], st["seed"], fid, modes=("crop",), skipped=skipped)
        elif fam == "explore":
            pos = case_pairs(fam, real, st["explore"], st["seed"], fid, modes=("explore",), skipped=skipped)
        elif fam == "drift":
            pos = case_pairs(fam, real, st["drift_cases"], st["seed"], fid, modes=("explore",),
                             drift=(st["drift"], st["drift_theta"]), skipped=skipped)
        elif fam == "repetitive":
            pos = case_pairs(fam, builtin, st["repetitive"], st["seed"], fid, modes=("crop", "explore"),
                             skipped=skipped)
        elif fam == "logs":
            pos = log_pairs(logs_dir, st["splits"], st["seed"], tmp, skipped)
        if fam == "apart":
            pos, neg = [], apart_pairs(real, st["apart"], st["seed"], fid)
        else:
            neg = negatives(pos, st["negatives"], st["seed"], fid)
        for p in pos + neg:
            yield fam, p


# ---------------------------------------------------------------------------------------------
# Running the methods on one pair
# ---------------------------------------------------------------------------------------------
def _outcome(t, truth, b) -> str:
    """``"right"``, ``"wrong"`` or ``"refused"`` (a negative's placement is always wrong)."""
    if t is None:
        return "refused"
    if truth is None:
        return "wrong"
    d, r = _error(t, truth, b)
    return "right" if d <= 3 and r <= 2.0 else "wrong"


def _error(t, truth, b) -> tuple[float, float]:
    """How far (cells) ``t`` puts the moving map's known-area centroid from the truth, and its
    rotation error (degrees)."""
    from fusionkit.methods.peers import placement_error
    d, r = placement_error(t, truth, b)
    return d / b.resolution, math.degrees(r)


def _err(t, truth, b):
    if t is None or truth is None:
        return None
    return [round(v, 2) for v in _error(t, truth, b)]


def run_pair(p: dict, peers, with_peers: bool) -> dict:
    """Estimate one pair with the consensus method (and the peers): a plain record."""
    from fusionkit.errors import FusionkitError
    from fusionkit.methods.consensus import ConsensusConfig, estimate_pair, prepare_maps, verify
    from fusionkit.methods.consensus._pair import corners
    from fusionkit.methods.consensus._verify import DEFAULT_GATES, displacement, refine_icp
    from fusionkit.pipeline import MergeConfig, merge
    cfg = ConsensusConfig()
    a, b, truth = p["a"], p["b"], p["truth"]
    seed = p["case_seed"] % 10_000
    rec = {k: p.get(k) for k in ("family", "world", "other", "source", "mode", "case_seed")}
    rec.update(kind="pos" if truth is not None else "neg", resolution=a.resolution,
               shape_a=list(a.data.shape), shape_b=list(b.data.shape))
    t0 = time.perf_counter()
    est = estimate_pair(a, b, scans_a=p["scans_a"], scans_b=p["scans_b"], config=cfg, seed=seed)
    sec = time.perf_counter() - t0
    pr = est.diagnostics["pair"]
    lg = pr.diagnostics.get("log10_nfa", math.inf)
    best = pr.best.transform if pr.best is not None else None
    rec["consensus"] = {
        "log10_nfa_model": (lg - cfg.calibration) if math.isfinite(lg) else None,
        "rivals": int(pr.diagnostics.get("rivals", int(pr.ambiguous))),
        "ambiguous": bool(pr.ambiguous), "accepted": bool(pr.accepted),
        "best": _outcome(best, truth, b) if best is not None else "refused",
        "best_error": _err(best, truth, b),
        "best_transform": [best.x, best.y, best.theta] if best is not None else None,
        "seconds": round(sec, 4), "reason": pr.reason}
    ia, ib = prepare_maps([a, b], [p["scans_a"], p["scans_b"]], config=cfg, seed=seed)
    rec["consensus"]["cross_wall_m"] = best_cross_wall(pr, ia, ib)
    placed = {}
    if with_peers:
        for m in peers:
            try:
                t1 = time.perf_counter()
                res = merge([a, b], scans=[p["scans_a"], p["scans_b"]],
                            config=MergeConfig(method=m, seed=seed))
                s = (time.perf_counter() - t1 - res.seconds.get("confidence", 0.0)
                     - res.seconds.get("fuse", 0.0))
                t = res.transforms[1]
                rec[m] = {"outcome": _outcome(t, truth, b), "error_cells_deg": _err(t, truth, b),
                          "seconds": round(s, 4)}
                placed[m] = t
            except FusionkitError as exc:
                rec[m] = {"outcome": "refused", "seconds": None, "error": str(exc)}
    if truth is not None:
        # resolvable: no distinct placement found by any method fits at least as well as the truth
        box = corners(ib)
        ev_truth = verify(ia, ib, truth).evidence()
        polished = refine_icp(ia, ib.refine_points, truth, gates=DEFAULT_GATES[-2:])
        if displacement(polished, truth, box) <= 3 * a.resolution:
            ev_truth = max(ev_truth, verify(ia, ib, polished).evidence())
        distinct = cfg.distinct_cells * a.resolution
        rival, by = -math.inf, ""
        for c in pr.refined:
            if displacement(c.transform, truth, box) > distinct and c.check.evidence() > rival:
                rival, by = c.check.evidence(), "consensus search"
        for m, t in placed.items():
            if t is not None and displacement(t, truth, box) > distinct:
                e = verify(ia, ib, t).evidence()
                if e > rival:
                    rival, by = e, m
        rec["truth_evidence"] = ev_truth
        rec["rival_evidence"] = rival if math.isfinite(rival) else None
        rec["rival_by"] = by
        rec["resolvable"] = bool(rival < ev_truth)
    return rec


def best_cross_wall(pr, ia, ib) -> float | None:
    """``cross_wall_m`` of the pair's best placement (None without one): the estimate's own
    where it measured it (only at a placement the test takes), measured on the pair's indexes
    ``ia, ib`` otherwise, as a record is judged again at other offsets."""
    if pr.best is None:
        return None
    m = pr.diagnostics.get("cross_wall_m")
    if m is None:
        from fusionkit.methods.consensus._slide import cross_wall
        m = cross_wall(ia, ib, pr.best.transform)
    return round(float(m), 4)


def _measured(records: list[dict]) -> bool:
    """Whether any of ``records`` carries the one-way measure (``cross_wall_m``)."""
    return any(r.get("consensus", r).get("cross_wall_m") is not None for r in records)


def _key(rec: dict) -> tuple:
    return (rec["family"], rec["source"], rec["case_seed"], rec["kind"])


def with_earlier_peers(rec: dict, earlier: dict, peers) -> dict:
    """``rec`` (the consensus method alone) with the peers' results of the same pair in an
    earlier record: their outcomes, and the truth's rival when a peer's placement was it (the
    peers' placements are not recorded, so whether the pair is resolvable is the earlier
    record's when a peer found its rival). A pair the earlier record lacks is left as it is."""
    old = earlier.get(_key(rec))
    if old is None:
        return rec
    for m in peers:
        if m in old:
            rec[m] = old[m]
    if (rec["kind"] == "pos" and old.get("rival_by") in peers
            and (rec["rival_evidence"] is None or old["rival_evidence"] > rec["rival_evidence"])):
        rec.update(rival_evidence=old["rival_evidence"], rival_by=old["rival_by"],
                   resolvable=bool(old["rival_evidence"] < rec["truth_evidence"]))
    return rec


# ---------------------------------------------------------------------------------------------
# Tables
# ---------------------------------------------------------------------------------------------
def merged(rec: dict, offset: float, eps: float, *, rivals: bool = True) -> bool:
    """Whether the consensus decision merges the pair with ``offset`` (decades); without
    ``rivals``, the test alone, before the rival test (the one-way check, :func:`slides`,
    still applies: it does not depend on the offset either)."""
    c = rec["consensus"]
    return (c["log10_nfa_model"] is not None and c["log10_nfa_model"] + offset <= math.log10(eps)
            and not (rivals and c["rivals"]) and not slides(rec))


def slides(rec: dict, least: float | None = None) -> bool:
    """Whether the consensus decision refuses the pair's best placement as free to slide along
    its walls (``cross_wall_m`` under ``least``, the shipped ``ConsensusConfig.cross_wall`` by
    default): ``rec`` a record of ``--out`` or of ``benchmarks/calibrate_consensus.py --out``;
    records made before the check have no measure and never slide."""
    m = rec.get("consensus", rec).get("cross_wall_m")
    if least is None:
        least = _shipped_cross_wall() if CROSS_WALL is None else CROSS_WALL
    return m is not None and m < least


@functools.cache
def _shipped_cross_wall() -> float:
    """``ConsensusConfig().cross_wall``, read once (the tables ask for it per pair and offset)."""
    from fusionkit.methods.consensus import ConsensusConfig
    return ConsensusConfig().cross_wall


def least_offset(merges, margin: float = MARGIN, least: float = -math.inf) -> float:
    """The least offset of ``GRID`` (from ``least``) at which ``merges(offset)`` is false, plus
    ``margin`` decades; ``inf`` when there is none."""
    for c in GRID:
        if c >= least and not merges(float(c)):
            return float(c) + margin
    return math.inf


def choose_offset(negs: list[dict], eps: float, rivals: bool = True, margin: float = MARGIN) -> float:
    """The least offset (quarter decades) at which none of ``negs`` is merged, plus ``margin``
    decades: merged by the whole decision (the test and the rival test), as the shipped constant
    is chosen, or without ``rivals`` by the test alone."""
    return least_offset(lambda c: any(merged(r, c, eps, rivals=rivals) for r in negs), margin)


def consensus_outcome(rec: dict, offset: float, eps: float) -> str:
    if not merged(rec, offset, eps):
        return "refused"
    return "wrong" if rec["kind"] == "neg" else rec["consensus"]["best"]


def lowo(records: list[dict], eps: float, rivals: bool = True, margin: float = MARGIN) -> dict:
    """Per world left out, the offset chosen on the negatives of the other worlds; and the offset
    chosen on every world (in sample)."""
    worlds = sorted({r["world"] for r in records} | {r["other"] for r in records if r.get("other")})
    # the offset is chosen on maps of two buildings; the maps of one building that share no wall
    # (``apart``) are judged with it, never chosen on (the known failure, BENCHMARKS.md)
    negs = [r for r in records if r["kind"] == "neg" and r["family"] != "apart"]
    offsets = {w: choose_offset([r for r in negs if w not in (r["world"], r["other"])], eps, rivals,
                                margin)
               for w in worlds}
    return {"offsets": offsets, "in_sample": choose_offset(negs, eps, rivals, margin)}


def pooled(draws: dict, crops: list[dict], eps: float, margin: float = MARGIN) -> str:
    """The offsets chosen as the shipped constant is, on every draw at once: for each world left
    out, the least offset at which the whole decision merges none of the negatives of two
    buildings of *every* draw given (``draws``: name -> record of ``--out``) and of the crop draws
    of ``benchmarks/calibrate_consensus.py --out`` (``crops``) that do not show it, plus
    ``margin`` decades; each draw's pairs of that world judged with it. The shipped constant is
    the highest of the draws' own choices, which is this choice with no world left out."""
    def row(r):  # (world, other, model, refused at every offset) of a negative of two buildings
        if "consensus" in r:
            return (r["world"], r["other"], r["consensus"]["log10_nfa_model"],
                    bool(r["consensus"]["rivals"]) or slides(r))
        return r["world"], r["other"], r["log10_nfa_model"], bool(r["ambiguous"]) or slides(r)
    negs = [row(r) for d in draws.values() for r in d["pairs"]
            if r["kind"] == "neg" and r["family"] != "apart"] + [row(r) for r in crops if r["kind"] == "neg"]

    def choose(rows):
        worst = min((m for _, _, m, rival in rows if m is not None and not rival), default=math.inf)
        return least_offset(lambda c: worst + c <= math.log10(eps), margin)
    worlds = sorted({r[k] for d in draws.values() for r in d["pairs"] for k in ("world", "other") if r.get(k)})
    offs = {w: choose([n for n in negs if w not in n[:2]]) for w in worlds}
    ins = choose(negs)
    lines = [f"Offsets chosen on the negatives of two buildings of {len(draws)} draws"
             + (f" and {sum(r['kind'] == 'neg' for r in crops)} of the crop draws" if crops else "")
             + f", per world left out: {min(offs.values()):.2f} to {max(offs.values()):.2f} decades"
             + "".join(f"; {w} {o:.2f}" for w, o in sorted(offs.items()) if o != ins)
             + f"; every other world and in sample {ins:.2f}.", "",
             "| draw | resolvable placed, out of sample | at the in-sample offset | negative judgements "
             "merged, out of sample | `apart` merged, out of sample |", "|---|---|---|---|---|"]
    tot = [0] * 7
    for name, d in draws.items():
        pos = [r for r in d["pairs"] if r["kind"] == "pos" and r.get("resolvable")]
        jud = _judgements([r for r in d["pairs"] if r["kind"] == "neg" and r["family"] != "apart"])
        apart = [r for r in d["pairs"] if r["family"] == "apart"]
        got = [sum(consensus_outcome(r, offs[r["world"]], eps) == "right" for r in pos), len(pos),
               sum(consensus_outcome(r, ins, eps) == "right" for r in pos),
               sum(merged(r, offs[w], eps) for r, w in jud), len(jud),
               sum(merged(r, offs[r["world"]], eps) for r in apart), len(apart)]
        tot = [t + g for t, g in zip(tot, got)]
        lines.append(f"| {name} | {got[0]} / {got[1]} | {got[2]} | {got[3]} / {got[4]} | {got[5]} / {got[6]} |")
    lines.append(f"| **all** | **{tot[0]} / {tot[1]} ({100 * tot[0] / max(tot[1], 1):.1f} %)** | {tot[2]} "
                 f"| {tot[3]} / {tot[4]} | {tot[5]} / {tot[6]} |")
    return "\n".join(lines)


def _judgements(negs: list[dict]) -> list[tuple]:
    """``(negative, world left out)``: a negative once per world of it (once when both maps show
    one building)."""
    return [(r, w) for r in negs for w in dict.fromkeys((r["world"], r["other"]))]


def _count(outcomes) -> tuple[int, int, int]:
    outcomes = list(outcomes)
    return (sum(o == "right" for o in outcomes), sum(o == "wrong" for o in outcomes),
            sum(o == "refused" for o in outcomes))


def _cell(outcomes) -> str:
    r, w, f = _count(outcomes)
    n = r + w + f
    return f"{r} / {w} / {f}" + (f" ({100 * r / n:.0f} %)" if n else "")


def tables(data: dict) -> str:
    """The Markdown report of a run (records and settings as recorded)."""
    records, eps = data["pairs"], data["max_false_merge"]
    default = data["default_offset"]
    peers = [m for m in data["peers"] if any(m in r for r in records)]
    ch = lowo(records, eps)
    offs, ins = ch["offsets"], ch["in_sample"]
    pos = [r for r in records if r["kind"] == "pos"]
    negs = [r for r in records if r["kind"] == "neg"]

    def oos(r):
        return consensus_outcome(r, offs[r["world"]], eps)

    lines = []
    head = ["consensus out of sample", "in sample", f"default ({default:g})"] + peers
    lines.append("Placed right / wrong / refused (share placed right) per family, positives:")
    lines.append("")
    lines.append("| family | pairs (resolvable) | " + " | ".join(head) + " |")
    lines.append("|---|---|" + "---|" * len(head))
    groups = [(f, [r for r in pos if r["family"] == f]) for f in FAMILIES]
    groups += [("**all pairs**", pos), ("**resolvable pairs**", [r for r in pos if r.get("resolvable")])]
    for name, rs in groups:
        if not rs:
            continue
        cells = [_cell(oos(r) for r in rs), _cell(consensus_outcome(r, ins, eps) for r in rs),
                 _cell(consensus_outcome(r, default, eps) for r in rs)]
        cells += [_cell(r[m]["outcome"] for r in rs if m in r) for m in peers]
        nres = sum(bool(r.get("resolvable")) for r in rs)
        lines.append(f"| {name} | {len(rs)} ({nres}) | " + " | ".join(cells) + " |")
    lines.append("")
    # how far off the positives placed outside the bounds are: a near miss or another place
    for m in ["consensus"] + peers:
        errs = {}
        for r in pos:
            if m == "consensus":
                if oos(r) == "wrong" and r["consensus"].get("best_error"):
                    errs.setdefault(r["family"], []).append(r["consensus"]["best_error"])
            elif m in r and r[m]["outcome"] == "wrong" and r[m].get("error_cells_deg"):
                errs.setdefault(r["family"], []).append(r[m]["error_cells_deg"])
        if errs:
            lines.append(f"- {m}{' (out of sample)' if m == 'consensus' else ''}, placed outside the "
                         "bounds: " + "; ".join(
                             f"{f} {len(e)}, median {statistics.median(x[0] for x in e):.1f} cells, "
                             f"largest {max(x[0] for x in e):.1f} cells and {max(x[1] for x in e):.1f} deg"
                             for f, e in errs.items()))
    lines.append("")
    # negatives: each is judged once with each of its worlds left out
    jud = _judgements(negs)
    passing = [(r, w) for r, w in jud if merged(r, offs[w], eps)]
    lines.append("Negatives (pairs of two worlds, or, in `apart`, of one building that share no wall; "
                 "each judged once with each of its worlds left out):")
    lines.append("")
    lines.append("| family | negatives | merged out of sample (of the judgements) | merged in sample | merged at the default |"
                 + "".join(f" {m} placed |" for m in peers))
    lines.append("|---|---|---|---|---|" + "---|" * len(peers))
    for f in FAMILIES + ("**all**",):
        rs = negs if f == "**all**" else [r for r in negs if r["family"] == f]
        if not rs:
            continue
        j = _judgements(rs)
        cells = [f"{sum(merged(r, offs[w], eps) for r, w in j)} / {len(j)}",
                 f"{sum(merged(r, ins, eps) for r in rs)} / {len(rs)}",
                 f"{sum(merged(r, default, eps) for r in rs)} / {len(rs)}"]
        cells += [(f"{sum(r[m]['outcome'] == 'wrong' for r in rs if m in r)} / {sum(m in r for r in rs)}"
                   if any(m in r for r in rs) else "not run") for m in peers]
        lines.append(f"| {f} | {len(rs)} | " + " | ".join(cells) + " |")
    if passing:
        lines.append("")
        lines.append("Negatives merged out of sample: " + "; ".join(
            f"{r['source']} ({r['family']}, offset {offs[w]:.2f} chosen without {w})" for r, w in passing))
    lines.append("")
    vals = sorted(offs.values())
    moved = [f"{w} {o:.2f}" for w, o in sorted(offs.items()) if o != ins]
    lines.append(f"Offset chosen per world left out: {vals[0]:.2f} to {vals[-1]:.2f} decades "
                 f"(median {statistics.median(vals):.2f}"
                 + (f"; {', '.join(moved)}, every other world {ins:.2f}" if moved else "")
                 + f"); in sample {ins:.2f}; default {default:g}. Negatives below the default "
                 f"threshold refused only by the rival test: "
                 f"{sum(merged(r, default, eps, rivals=False) and not merged(r, default, eps) for r in negs)}"
                 f" / {len(negs)}.")
    lines.append("")
    # the same, the offset chosen so that the test alone refuses every negative (the rival test
    # not counted on): stricter
    ch2 = lowo(records, eps, rivals=False)
    o2, i2 = ch2["offsets"], ch2["in_sample"]
    lines.append("The offset chosen instead so that no negative passes the test alone (the rival "
                 f"test not counted on; in sample {i2:.2f}, per world left out "
                 f"{min(o2.values()):.2f} to {max(o2.values()):.2f}):")
    lines.append("")
    lines.append("| pairs | consensus out of sample | in sample | negatives merged out of sample |")
    lines.append("|---|---|---|---|")
    for name, rs in groups[-2:]:
        lines.append(f"| {name.strip('*')} | {_cell(consensus_outcome(r, o2[r['world']], eps) for r in rs)} | "
                     f"{_cell(consensus_outcome(r, i2, eps) for r in rs)} | "
                     + (f"{sum(merged(r, o2[w], eps) for r, w in jud)} / {len(jud)}" if name == "**all pairs**" else "")
                     + " |")
    lines.append("")
    # time per pair, positives, every method on the same pairs
    lines.append("Time per pair (positives; seconds are only comparable within the run):")
    lines.append("")
    lines.append("| method | median s / pair | ratio of the medians to map-merge | median of the per-pair ratios |")
    lines.append("|---|---|---|---|")
    # peers taken from an earlier record (--peers-from) ran in another process, at another load:
    # their seconds are not compared with this run's
    other_run = bool(data.get("settings", {}).get("peers_from"))
    methods = ["consensus"] + ([] if other_run else peers)
    timed = [r for r in pos if all(m in r and r[m].get("seconds") is not None for m in methods)]

    def secs(r, m):
        return r[m]["seconds"]
    if timed:
        ref = "map-merge" if "map-merge" in methods else None
        for m in methods:
            med = statistics.median(secs(r, m) for r in timed)
            if ref:
                rm = statistics.median(secs(r, ref) for r in timed)
                pr = statistics.median(secs(r, m) / max(secs(r, ref), 1e-6) for r in timed)
                lines.append(f"| {m} | {med:.3f} | {med / max(rm, 1e-9):.2f}x | {pr:.2f}x |")
            else:
                lines.append(f"| {m} | {med:.3f} | | |")
        lines.append("")
        lines.append(f"({len(timed)} positives on which every method ran"
                     + (f"; the peers' seconds are of the run of {data['settings']['peers_from']}, "
                        "not compared)" if other_run and peers else ".)"))
    unres = [r for r in pos if not r.get("resolvable")]
    if unres:
        lines.append("")
        lines.append("Unresolvable positives (a distinct placement fits at least as well as the truth): "
                     + "; ".join(f"{r['source']} ({r['family']}, by {r['rival_by']})" for r in unres))
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
def _write(path: Path, data: dict) -> None:
    from fusionkit._atomic import write_text_atomic
    write_text_atomic(path, json.dumps(data, indent=1))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--maps", default=str(HERE.parent / "shared" / "maps" / "real"))
    ap.add_argument("--logs", default=str(HERE.parent / "shared" / "logs" / "real"))
    ap.add_argument("--seed", type=int, default=1, help="seed of the case draw")
    ap.add_argument("--crops", type=int, default=5, help="crop pairs per real floor")
    ap.add_argument("--explore", type=int, default=2, help="explorations without drift per real floor")
    ap.add_argument("--drift-cases", type=int, default=2, help="explorations with drift per real floor")
    ap.add_argument("--drift", type=float, default=0.01, help="odometry drift, m per sqrt(m)")
    ap.add_argument("--drift-theta", type=float, default=0.001, help="heading drift, rad per sqrt(m)")
    ap.add_argument("--repetitive", type=int, default=6,
                    help="crops and explorations per repetitive world (office, warehouse), each")
    ap.add_argument("--splits", nargs="*", type=int, default=[2, 3, 4], help="K for the logs")
    ap.add_argument("--apart", type=int, default=1,
                    help="simulated runs per world (each without and with drift) whose robots that "
                         "never met are the negatives within one building")
    ap.add_argument("--negatives", type=float, default=1.0, help="negatives per positive, per family")
    ap.add_argument("--peers", nargs="*", default=None,
                    help=f"peers run on the same pairs (default: {' '.join(PEERS)}; none: --peers alone)")
    ap.add_argument("--peers-on-negatives", action="store_true", help="run the peers on the negatives too")
    ap.add_argument("--peers-from", default=None, metavar="RECORD",
                    help="take the peers' results from this earlier record of the same draw "
                         "instead of running them (the consensus method alone runs again)")
    ap.add_argument("--families", nargs="+", default=list(FAMILIES), choices=FAMILIES)
    ap.add_argument("--max-false-merge", type=float, default=None,
                    help="risk the decision is judged at (default: ConsensusConfig's)")
    ap.add_argument("--quick", action="store_true",
                    help="a smoke run: 4 floors, one pair each, K = 2 logs, no spectral-pso")
    ap.add_argument("--out", default=None, help="record every pair (JSON) here")
    ap.add_argument("--from", dest="source", default=None, help="redo the tables from a record")
    ap.add_argument("--pooled", nargs="+", default=None, metavar="RECORD",
                    help="records of several draws: each world's offset chosen on the negatives of all of them")
    ap.add_argument("--crop-records", nargs="*", default=[], metavar="RECORD",
                    help="with --pooled: records of benchmarks/calibrate_consensus.py --out, chosen on too")
    ap.add_argument("--cross-wall", type=float, default=None, metavar="M",
                    help="with --from or --pooled: judge the records as if ConsensusConfig.cross_wall were M")
    args = ap.parse_args(argv)
    global CROSS_WALL
    CROSS_WALL = None
    try:
        return _main(args, argv)
    finally:
        CROSS_WALL = None


def _main(args, argv) -> int:
    global CROSS_WALL
    if args.cross_wall is not None:
        if not (math.isfinite(args.cross_wall) and args.cross_wall >= 0):
            print(f"lowo: --cross-wall is metres >= 0, got {args.cross_wall}", file=sys.stderr)
            return 2
        if not (args.pooled or args.source):
            print("lowo: --cross-wall judges recorded pairs: give it with --from or --pooled", file=sys.stderr)
            return 2
        CROSS_WALL = args.cross_wall
    if args.pooled:
        try:
            draws = {Path(f).stem: json.loads(Path(f).read_text()) for f in args.pooled}
            crops = [r for f in args.crop_records for r in json.loads(Path(f).read_text())]
            if CROSS_WALL is not None and not _measured([r for d in draws.values() for r in d["pairs"]]):
                print("lowo: --cross-wall: these records were made before the one-way check and carry no "
                      "cross_wall_m; give records of the shipped code", file=sys.stderr)
                return 2
            eps = {d["max_false_merge"] for d in draws.values()}
            if len(eps) != 1:
                print("lowo: --pooled records were judged at different --max-false-merge; give records of one",
                      file=sys.stderr)
                return 2
            print(pooled(draws, crops, eps.pop()))
        except (OSError, ValueError, KeyError, TypeError) as exc:
            print(f"lowo: --pooled/--crop-records: not records written by --out ({exc}); give those", file=sys.stderr)
            return 2
        return 0
    if args.source:
        try:
            data = json.loads(Path(args.source).read_text())
            if CROSS_WALL is not None and not _measured(data["pairs"]):
                print(f"lowo: --cross-wall: {args.source} was made before the one-way check and carries no "
                      "cross_wall_m; give a record of the shipped code", file=sys.stderr)
                return 2
            print(tables(data))
        except (OSError, ValueError, KeyError, TypeError) as exc:
            print(f"lowo: {args.source}: not a record written by --out ({exc}); give one", file=sys.stderr)
            return 2
        return 0

    from fusionkit.bench import find_worlds
    from fusionkit.errors import FusionkitError
    from fusionkit.methods import METHODS
    from fusionkit.methods.consensus import ConsensusConfig
    cfg = ConsensusConfig()
    eps = args.max_false_merge if args.max_false_merge is not None else cfg.max_false_merge
    if args.peers_from and args.peers is not None:
        print("lowo: --peers-from takes the peers of its record; give it without --peers", file=sys.stderr)
        return 2
    if args.peers is None:
        args.peers = list(PEERS)
    bad = [m for m in args.peers if m not in METHODS or m == "consensus"]
    if bad:
        print(f"lowo: unknown peer {bad[0]!r}; choose from {', '.join(m for m in METHODS if m != 'consensus')}",
              file=sys.stderr)
        return 2
    if min(args.crops, args.explore, args.drift_cases, args.repetitive, args.apart) < 0 or args.negatives < 0:
        print("lowo: case counts and --negatives must be >= 0", file=sys.stderr)
        return 2
    if not 0 < eps < 1:
        print(f"lowo: --max-false-merge is a risk in (0, 1), got {eps}", file=sys.stderr)
        return 2
    if any(k < 2 for k in args.splits):
        print("lowo: --splits are numbers of sessions, each >= 2", file=sys.stderr)
        return 2
    earlier = {}
    if args.peers_from:
        try:
            prev = json.loads(Path(args.peers_from).read_text())
            earlier = {_key(r): r for r in prev["pairs"]}
            draw = ("seed", "crops", "explore", "drift_cases", "drift", "drift_theta", "repetitive",
                    "splits", "apart", "negatives", "quick")
            other = [k for k in draw if prev["settings"].get(k) != vars(args).get(k)]
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
            print(f"lowo: --peers-from {args.peers_from}: not a record written by --out ({exc}); give one",
                  file=sys.stderr)
            return 2
        if other:
            print(f"lowo: --peers-from {args.peers_from} is of another draw (differing: {', '.join(other)}); "
                  "give the record of the same --seed and sizes", file=sys.stderr)
            return 2
        args.peers = list(prev["peers"])
    if args.quick:
        args.crops, args.explore, args.drift_cases, args.repetitive, args.apart = 1, 1, 1, 1, 0
        args.splits = [2]
        args.peers = [m for m in args.peers if m != "spectral-pso"]
    try:
        real, skipped_worlds = find_worlds([args.maps])
        builtin, _ = find_worlds([], ["office", "warehouse"])
    except FusionkitError as exc:
        print(f"lowo: {exc}", file=sys.stderr)
        return 2
    logs_dir = Path(args.logs)
    if "logs" in args.families and not logs_dir.is_dir():
        print(f"lowo: {logs_dir}: no such folder of CARMEN logs; give --logs or leave out the logs family",
              file=sys.stderr)
        return 2
    if args.quick:
        real = real[:: max(1, len(real) // 4)][:4]
    skipped = [f"world {n}: {why}" for n, why in skipped_worlds]
    settings = {k: v for k, v in vars(args).items() if k not in ("source",)}
    data = {"settings": settings, "command": " ".join(["python", "benchmarks/lowo.py"] + list(argv or sys.argv[1:])),
            "max_false_merge": eps, "default_offset": cfg.calibration, "peers": list(args.peers),
            "pairs": [], "skipped": skipped}
    out = Path(args.out) if args.out else None
    t_start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for fam, p in draw_pairs(vars(args), real, builtin, logs_dir, Path(tmp), skipped):
                if args.peers_from:
                    rec = with_earlier_peers(run_pair(p, (), False), earlier, args.peers)
                else:
                    rec = run_pair(p, args.peers, with_peers=p["truth"] is not None or args.peers_on_negatives)
                data["pairs"].append(rec)
                c = rec["consensus"]
                print(f"{fam:10} {rec['kind']} {rec['source'][:48]:48} model {c['log10_nfa_model'] if c['log10_nfa_model'] is None else round(c['log10_nfa_model'], 2)!s:>7} "
                      f"best {c['best']:7} " + " ".join(f"{m}={rec[m]['outcome'][0]}" for m in args.peers if m in rec)
                      + ("" if rec["kind"] == "neg" else f" resolvable={rec['resolvable']}"),
                      file=sys.stderr, flush=True)
                if out:
                    _write(out, data)
    data["seconds"] = round(time.perf_counter() - t_start, 1)
    if out:
        _write(out, data)
    print(tables(data))
    print()
    print(f"{len(data['pairs'])} pairs in {data['seconds']:.0f} s; skipped: {len(skipped)}"
          + "".join(f"\n  {s}" for s in skipped))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
