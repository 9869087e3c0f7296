"""``fusionkit evaluate``: score a merged map against the simulation's ground truth.

The merged map is in the frame of the merge's reference map (CONTRACTS section 4); truth.json
(CONTRACTS section 5) gives every robot's transform into the world map's frame, so the merged
map is placed in the world frame by the reference robot's transform and scored with the
metrics of CONTRACTS section 7. With the merge report (CONTRACTS section 6), each map's
estimated transform is also compared with the true one, ``inv(T_ref) @ T_k``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

from .._atomic import show
from .._inputs import read_json
from ..errors import InputError
from ..transform import Transform2D

__all__ = ["register", "run", "Truth", "read_truth", "find_report", "read_report", "evaluate_files"]


def register(sub) -> None:
    p = sub.add_parser(
        "evaluate", help="score a merged map against the simulation's ground truth",
        description="Place MERGED.yaml in the world frame of truth.json and print the paper's "
                    "Table 1 metrics in percent (completeness, accuracy, precision, efficiency, "
                    "and the precision with a one-cell tolerance). When the merge report is "
                    "found, also print each map's transform error against the truth. "
                    "Exit status: 0 done, 2 bad input.")
    p.add_argument("merged", metavar="MERGED.yaml", help="the merged map (map_server YAML)")
    p.add_argument("--truth", required=True, metavar="truth.json",
                   help="ground truth written by 'fusionkit simulate': the world map (its path "
                        "relative to truth.json's directory, else to the current directory) and "
                        "each robot's transform into the world frame")
    p.add_argument("--report", metavar="REPORT.json",
                   help="the merge report that made MERGED.yaml (default: MERGED.report.json "
                        "beside it, else report.json beside it when its 'output' names "
                        "MERGED.yaml; without one, only the map metrics are printed)")
    p.add_argument("--reference", metavar="NAME",
                   help="robot name in truth.json whose map frame the merged map is in, used "
                        "when there is no report (default: the first robot in truth.json); "
                        "with a report it must agree with the report's reference")
    p.add_argument("--json", action="store_true",
                   help='print one JSON object {"metrics": {...}, "maps": [...], ...} instead '
                        "of tables")
    p.set_defaults(func=run)


# -- inputs --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Truth:
    """The contents of a truth.json.

    Attributes
    ----------
    path : Path
        The truth.json file.
    world : Path
        The world map YAML, resolved.
    robots : dict[str, Transform2D]
        Robot name -> transform of its map frame into the world frame, in file order.
    """

    path: Path
    world: Path
    robots: dict


def _read_json(path: Path, what: str):
    """A JSON file: regular, bounded in size and nesting; one-line errors (see _inputs)."""
    return read_json(path, f"{what} file")


def read_truth(path) -> Truth:
    """Read and check a truth.json (CONTRACTS section 5).

    Raises
    ------
    InputError
        Missing or malformed file, no robots, a robot without a name or transform, a duplicate
        name, or a world map that cannot be found.
    """
    path = Path(path)
    doc = _read_json(path, "truth")
    if not isinstance(doc, dict):
        raise InputError(f"{path}: a truth file holds a JSON object with 'world' and 'robots'")
    world = doc.get("world")
    if not isinstance(world, str) or not world.strip():
        raise InputError(f"{path}: 'world' must be the path of the world map YAML")
    robots_doc = doc.get("robots")
    if not isinstance(robots_doc, list) or not robots_doc:
        raise InputError(f"{path}: 'robots' must be a non-empty list of {{name, transform}}; "
                         f"this truth file has no robots")
    robots: dict[str, Transform2D] = {}
    for i, r in enumerate(robots_doc):
        name = r.get("name") if isinstance(r, dict) else None
        if not isinstance(name, str) or not name:
            raise InputError(f"{path}: robot {i + 1} has no 'name'")
        if name in robots:
            raise InputError(f"{path}: robot name {show(name)} appears twice; names must be unique")
        try:
            robots[name] = Transform2D.from_dict(r.get("transform"))
        except ValueError:
            raise InputError(f"{path}: robot {show(name)} needs a 'transform' with numeric x, y, "
                             f"theta, got {show(r.get('transform'))}") from None
    world_path = Path(world.strip())
    if not world_path.is_absolute():
        beside = path.parent / world_path
        world_path = beside if beside.exists() or not world_path.exists() else world_path
    if not world_path.exists():
        raise InputError(f"{path}: the world map {show(world)} was not found beside the truth file "
                         f"or in the current directory; fix 'world' or restore the map")
    return Truth(path=path, world=world_path, robots=robots)


def _names_merged(report: dict, merged: Path) -> bool:
    out = report.get("output")
    return not isinstance(out, str) or Path(out).name == merged.name


def find_report(merged, report=None) -> Path | None:
    """The merge report for ``merged``: ``report`` when given, else ``<stem>.report.json``
    beside it, else ``report.json`` beside it, each only when its ``output`` names ``merged``
    (same file name); ``None`` when there is none."""
    merged = Path(merged)
    if report is not None:
        return Path(report)
    for cand in (merged.with_name(merged.stem + ".report.json"), merged.with_name("report.json")):
        if cand.is_file():
            try:
                doc = read_json(cand, "merge report")
            except InputError:
                continue
            if isinstance(doc, dict) and isinstance(doc.get("output"), str) and _names_merged(doc, merged):
                return cand
    return None


def _robot(path_text: str) -> str:
    return Path(path_text).stem


def read_report(path, merged) -> dict:
    """Read and check a merge report (CONTRACTS section 6) that made ``merged``.

    Returns the report with ``maps`` entries checked: ``input`` (str), ``merged`` (bool),
    ``confidence`` (number or None), ``transform`` (:class:`Transform2D` or None).
    """
    path, merged = Path(path), Path(merged)
    doc = _read_json(path, "merge report")
    if not isinstance(doc, dict) or not isinstance(doc.get("reference"), str) \
            or not isinstance(doc.get("maps"), list):
        raise InputError(f"{path}: not a merge report (it needs 'reference' and 'maps'); give the "
                         f"report 'fusionkit merge' wrote")
    if not _names_merged(doc, merged):
        raise InputError(f"{path}: this report is for {show(doc['output'])}, not {merged}; give the "
                         f"report of this merged map with --report")
    maps = []
    for i, m in enumerate(doc["maps"]):
        if not isinstance(m, dict) or not isinstance(m.get("input"), str):
            raise InputError(f"{path}: map entry {i + 1} has no 'input' path")
        t = m.get("transform")
        try:
            t = None if t is None else Transform2D.from_dict(t)
        except ValueError:
            raise InputError(f"{path}: map {show(m['input'])} has a transform without numeric x, y, "
                             f"theta: {show(m.get('transform'))}") from None
        conf = m.get("confidence")
        conf = float(conf) if isinstance(conf, (int, float)) and not isinstance(conf, bool) else None
        maps.append({"input": m["input"], "merged": bool(m.get("merged", t is not None)) and t is not None,
                     "confidence": conf, "transform": t})
    return {**doc, "maps": maps}


# -- evaluation ----------------------------------------------------------------------------------
def evaluate_files(merged, truth, *, report=None, reference: str | None = None) -> dict:
    """Score ``merged`` against ``truth`` (paths); see the command's description.

    Returns
    -------
    dict
        ``merged``, ``truth``, ``world``, ``report`` (path or None), ``reference`` (robot
        name), ``metrics`` (:meth:`MapMetrics.as_dict`) and ``maps`` (per map of the report:
        ``input``, ``robot``, ``merged``, ``confidence``, ``transform`` and ``true_transform``
        as ``{x, y, theta}`` into the merged frame, and ``error`` in m, cells and degrees).
    """
    from ..mapio import load_map
    from ..metrics import evaluate_map, transform_errors

    merged = Path(merged)
    truth_info = read_truth(truth)
    report_path = find_report(merged, report)
    rep = read_report(report_path, merged) if report_path is not None else None
    robots = truth_info.robots

    if rep is not None:
        ref = _robot(rep["reference"])
        if reference is not None and reference != ref:
            raise InputError(f"--reference {reference} disagrees with the report {report_path}, "
                             f"whose reference is {rep['reference']} ({ref}); drop --reference")
        if ref not in robots:
            raise InputError(f"{report_path}: the reference {rep['reference']} is robot {ref!r}, "
                             f"which is not in {truth_info.path} (robots: {', '.join(robots)})")
    else:
        ref = reference if reference is not None else next(iter(robots))
        if ref not in robots:
            raise InputError(f"--reference {ref}: no such robot in {truth_info.path}; choose one of "
                             f"{', '.join(robots)}")

    fused = load_map(merged)
    world = load_map(truth_info.world)
    t_ref = robots[ref]
    metrics = evaluate_map(fused, world, t_ref)

    rows = []
    for m in rep["maps"] if rep is not None else []:
        name = _robot(m["input"])
        if name not in robots:
            raise InputError(f"{report_path}: map {m['input']} is robot {name!r}, which is not in "
                             f"{truth_info.path} (robots: {', '.join(robots)}); give the matching "
                             f"truth file")
        true_rel = t_ref.inverse @ robots[name]
        est = m["transform"]
        err = transform_errors(est, true_rel, fused.resolution).as_dict() if est is not None else None
        rows.append({
            "input": m["input"], "robot": name, "merged": m["merged"], "confidence": m["confidence"],
            "transform": est.as_dict() if est is not None else None,
            "true_transform": true_rel.as_dict(), "error": err,
        })
    return {
        "merged": str(merged), "truth": str(truth_info.path), "world": str(truth_info.world),
        "report": str(report_path) if report_path is not None else None, "reference": ref,
        "metrics": metrics.as_dict(), "maps": rows,
    }


def format_evaluation(result: dict) -> str:
    """The evaluation as tables for the terminal."""
    m = result["metrics"]
    lines = [
        f"merged map {result['merged']} in the frame of {result['reference']}, "
        f"scored against {result['world']}",
        "",
        f"  {'completeness':<26}{m['completeness']:7.2f} %",
        f"  {'accuracy':<26}{m['accuracy']:7.2f} %",
        f"  {'precision':<26}{m['precision']:7.2f} %",
        f"  {'efficiency':<26}{m['efficiency']:7.2f} %",
        f"  {'precision (within 1 cell)':<26}{m['precision_tol1']:7.2f} %",
        f"  cells: {m['known_truth']} known in the truth, {m['known_both']} of them known in the "
        f"merged map, {m['occupied_fused']} occupied in the merged map",
    ]
    if result["report"] is None:
        lines += ["", "no merge report found: give --report for per-map transform errors"]
        return "\n".join(lines)
    lines += ["", f"per map (report {result['report']}); transforms into the merged frame:",
              f"  {'map':<24} {'merged':<6} {'conf':>5} {'x (m)':>8} {'y (m)':>8} {'th (deg)':>8}"
              f" {'true x':>8} {'true y':>8} {'true th':>8} {'err (m)':>8} {'cells':>6} {'deg':>6}"]
    for r in result["maps"]:
        t, tt, e = r["transform"], r["true_transform"], r["error"]
        conf = f"{r['confidence']:5.2f}" if r["confidence"] is not None else f"{'-':>5}"
        est = (f"{t['x']:8.2f} {t['y']:8.2f} {math.degrees(t['theta']):8.1f}" if t is not None
               else f"{'-':>8} {'-':>8} {'-':>8}")
        err = (f"{e['translation_m']:8.3f} {e['translation_cells']:6.1f} {e['rotation_deg']:6.2f}"
               if e is not None else f"{'-':>8} {'-':>6} {'-':>6}")
        lines.append(f"  {r['input'][-24:]:<24} {'yes' if r['merged'] else 'no':<6} {conf} {est} "
                     f"{tt['x']:8.2f} {tt['y']:8.2f} {math.degrees(tt['theta']):8.1f} {err}")
    return "\n".join(lines)


def run(args) -> int:
    result = evaluate_files(args.merged, args.truth, report=args.report, reference=args.reference)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(format_evaluation(result))
    return 0
