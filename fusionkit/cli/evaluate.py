"""``fusionkit evaluate``: score a merged map against the simulation's ground truth.

The merged map is in the frame of the merge's reference map; truth.json gives every robot's
transform into the world map's frame (docs/formats.md has both formats), so the merged
map is placed in the world frame by the reference robot's transform and scored with the
metrics of docs/formats.md. With the merge report, each map's
estimated transform is also compared with the true one, ``inv(T_ref) @ T_k``. The fused map of
a group of maps not linked to the reference (``NAME.groupK.yaml``, listed in the report under
``group_outputs``) is scored the same way in the frame of the group's first map, with its
maps' ``group_transform``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

from .._atomic import show
from .._inputs import read_json
from ..errors import InputError
from ..labels import clip_column, fixed
from ..mapio import map_digest
from ..transform import Transform2D

__all__ = ["register", "run", "Truth", "read_truth", "robot_of", "find_report", "read_report", "evaluate_files"]


def register(sub) -> None:
    p = sub.add_parser(
        "evaluate", help="score a merged map against the simulation's ground truth",
        description="Place MERGED.yaml in the world frame of truth.json and print the paper's "
                    "Table 1 metrics in percent (completeness, accuracy, precision, efficiency, "
                    "and the precision with a one-cell tolerance). When the merge report is "
                    "found, also print each map's transform error against the truth; maps are "
                    "matched to truth.json's robots by path (robot NAME is the NAME.yaml beside "
                    "truth.json), so a map of another run is refused, not scored against this "
                    "one. Formats and metrics: docs/formats.md. Exit status: 0 done, 2 bad input.")
    p.add_argument("merged", metavar="MERGED.yaml",
                   help="the merged map (map_server YAML), or the map of a group of maps not "
                        "linked to the reference that the merge wrote beside it "
                        "(NAME.groupK.yaml), scored in the frame of the group's first map")
    p.add_argument("--truth", required=True, metavar="truth.json",
                   help="ground truth written by 'fusionkit simulate': the world map (its path "
                        "relative to truth.json's directory, else to the current directory) and "
                        "each robot's transform into the world frame")
    p.add_argument("--report", metavar="REPORT.json",
                   help="the merge report that made MERGED.yaml (default: MERGED.report.json "
                        "beside it, else, for a group's map NAME.groupK.yaml, NAME.report.json, "
                        "else report.json beside it, else the one JSON report beside it of any "
                        "name, when its 'output' names MERGED.yaml or it "
                        "lists it under 'group_outputs'; without one, only the map metrics are "
                        "printed, and a group's map needs --reference)")
    p.add_argument("--reference", metavar="NAME",
                   help="robot name in truth.json whose map frame the merged map is in, used "
                        "when there is no report (default: the robot whose map MERGED.yaml is, "
                        "else the first robot in truth.json); "
                        "with a report it must agree with the report's reference (for a "
                        "group's map, the group's first map)")
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
    maps : dict[str, Path]
        Robot name -> its map file: the robot's ``map`` (relative to truth.json's directory),
        else ``NAME.yaml`` beside truth.json.
    """

    path: Path
    world: Path
    robots: dict
    maps: dict = field(default_factory=dict)


def _read_json(path: Path, what: str):
    """A JSON file: regular, bounded in size and nesting; one-line errors (see _inputs)."""
    return read_json(path, f"{what} file")


def read_truth(path) -> Truth:
    """Read and check a truth.json (docs/formats.md).

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
    maps: dict[str, Path] = {}
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
        m = r.get("map")
        maps[name] = path.parent / (m if isinstance(m, str) and m.strip() else f"{name}.yaml")
    world_path = Path(world.strip())
    if not world_path.is_absolute():
        beside = path.parent / world_path
        world_path = beside if beside.exists() or not world_path.exists() else world_path
    if not world_path.exists():
        raise InputError(f"{path}: the world map {show(world)} was not found beside the truth file "
                         f"or in the current directory; fix 'world' or restore the map")
    return Truth(path=path, world=world_path, robots=robots, maps=maps)


def _names_merged(report: dict, merged: Path) -> bool:
    out = report.get("output")
    return not isinstance(out, str) or Path(out).name == merged.name


def _group_number(merged: Path) -> int | None:
    """K when ``merged`` is named like the map of group K of a merge (``NAME.groupK.yaml``)."""
    base, dot, tail = merged.stem.rpartition(".")
    if dot and base and tail.startswith("group") and tail[5:].isdigit():
        return int(tail[5:])
    return None


def _group_of(report: dict, merged: Path) -> int | None:
    """The group (1, 2, ...) whose fused map ``merged`` is, by the file names the report lists
    under ``group_outputs`` (``NAME.group1.yaml``, ...); None when it lists no such map."""
    outs = report.get("group_outputs")
    if not isinstance(outs, list):
        return None
    for k, g in enumerate(outs, start=1):
        if isinstance(g, str) and Path(g).name == merged.name:
            return k
    return None


def find_report(merged, report=None) -> Path | None:
    """The merge report for ``merged``: ``report`` when given, else ``<stem>.report.json``
    beside it, else (for a group's map ``NAME.groupK.yaml``) ``NAME.report.json``, else
    ``report.json`` beside it, each only when its ``output`` names ``merged`` (same file name)
    or it lists ``merged`` under ``group_outputs``; else the one merge report beside it (any
    name) that does; ``None`` when there is none, or more than one."""
    merged = Path(merged)
    if report is not None:
        return Path(report)
    if not merged.name:     # "." or "/": a folder, refused as such when the map is read
        return None
    cands = [merged.with_name(merged.stem + ".report.json"), merged.with_name("report.json")]
    if _group_number(merged) is not None:
        cands.insert(1, merged.with_name(merged.stem.rpartition(".")[0] + ".report.json"))
    for cand in cands:
        if cand.is_file():
            try:
                doc = read_json(cand, "merge report")
            except InputError:
                continue
            if isinstance(doc, dict) and (
                    (isinstance(doc.get("output"), str) and _names_merged(doc, merged))
                    or _group_of(doc, merged) is not None):
                return cand
    # a report of another name (merge --report R.json): the one report beside it that names it
    from ..mapio import merge_reports

    named = [q for q, doc in merge_reports(merged.parent)
             if _names_merged(doc, merged) or _group_of(doc, merged) is not None]
    return named[0] if len(named) == 1 else None


def _map_of(truth: Truth, name: str) -> Path:
    """Robot ``name``'s map file: its ``map`` in truth.json, else ``NAME.yaml`` beside it."""
    return truth.maps.get(name, truth.path.parent / f"{name}.yaml")


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and a.samefile(b)
    except OSError:
        return False


def robot_of(truth: Truth, path_text: str, *, bases=(), others=()) -> str:
    """The robot of ``truth`` whose map is the file ``path_text``, matched by path.

    A robot of a truth.json is the map its ``map`` names, else ``NAME.yaml`` beside truth.json
    (the layout ``fusionkit simulate`` writes). ``path_text`` is a map's path as a merge report gives it: relative to
    the directory the merge was run in, tried from the current directory and from each of
    ``bases`` (the first place it is found decides). When the file is found, it must be one of the truth's robot maps: two runs both
    have a ``robot_1.yaml``, and a map of another run has no true transform here. When it is
    found nowhere (the maps were moved), the file name decides, unless another map of
    ``others`` has the same name.

    Raises
    ------
    InputError
        The map is another run's, or is named like no robot of the truth file, or cannot be told
        apart from another map of the same name.
    """
    given = Path(path_text)
    candidates = [given] if given.is_absolute() else [given, *(Path(b) / given for b in bases)]
    found = next((c for c in candidates if c.is_file()), None)
    robots = ", ".join(truth.robots)
    if found is not None:
        for name in truth.robots:
            if _same_file(found, _map_of(truth, name)):
                return name
        raise InputError(f"map {path_text} ({found.resolve()}) is not in the run of {truth.path}: its "
                         f"robots ({robots}) are the robot maps beside it; give the truth.json of "
                         f"the run this map came from")
    name = given.stem
    if any(Path(o).stem == name and o != path_text for o in others):
        raise InputError(f"map {path_text}: cannot be told apart from another map named {given.name} "
                         f"(neither file is found from here); run evaluate from the directory the "
                         f"merge was run in")
    if name not in truth.robots:
        raise InputError(f"map {path_text} is robot {name!r}, which is not in {truth.path} "
                         f"(robots: {robots}); give the matching truth file")
    return name


def _transform(path: Path, m: dict, key: str) -> Transform2D | None:
    t = m.get(key)
    try:
        return None if t is None else Transform2D.from_dict(t)
    except ValueError:
        raise InputError(f"{path}: map {show(m['input'])} has a {key.replace('_', ' ')} without "
                         f"numeric x, y, theta: {show(t)}") from None


def read_report(path, merged) -> dict:
    """Read and check a merge report (docs/formats.md) that made ``merged``.

    Returns the report with ``maps`` entries checked: ``input`` (str), ``merged`` (bool),
    ``confidence`` (number or None), ``transform`` (:class:`Transform2D` or None). When
    ``merged`` is the fused map of group K of the report (``group_outputs``), ``group`` is K,
    ``reference`` the group's first map and ``maps`` the group's maps, each with its
    ``group_transform`` as ``transform`` (into that map's frame, the group map's frame).
    """
    path, merged = Path(path), Path(merged)
    doc = _read_json(path, "merge report")
    if not isinstance(doc, dict) or not isinstance(doc.get("reference"), str) \
            or not isinstance(doc.get("maps"), list):
        raise InputError(f"{path}: not a merge report (it needs 'reference' and 'maps'); give the "
                         f"report 'fusionkit merge' wrote")
    group = _group_of(doc, merged)
    if group is None and not _names_merged(doc, merged):
        raise InputError(f"{path}: this report is for {show(doc['output'])}, not {merged}; give the "
                         f"report of this merged map with --report")
    for i, m in enumerate(doc["maps"]):
        if not isinstance(m, dict) or not isinstance(m.get("input"), str):
            raise InputError(f"{path}: map entry {i + 1} has no 'input' path")
    if group is not None:
        members = [m for m in doc["maps"] if isinstance(m.get("group"), int)
                   and not isinstance(m.get("group"), bool) and m["group"] == group]
        refs = {m.get("group_reference") for m in members}
        if not members or len(refs) != 1 or not isinstance(members[0].get("group_reference"), str) \
                or members[0]["group_reference"] not in {m["input"] for m in members}:
            raise InputError(f"{path}: lists {merged.name} as the map of group {group} but not the "
                             f"maps of that group with one 'group_reference' among them; give the "
                             f"report 'fusionkit merge' wrote")
        maps = []
        for m in members:
            t = _transform(path, m, "group_transform")
            maps.append({"input": m["input"], "merged": t is not None,
                         "confidence": _confidence(m), "transform": t, "sha256": m.get("sha256")})
        return {**doc, "reference": members[0]["group_reference"], "maps": maps, "group": group}
    maps = []
    for m in doc["maps"]:
        t = _transform(path, m, "transform")
        maps.append({"input": m["input"], "merged": bool(m.get("merged", t is not None)) and t is not None,
                     "confidence": _confidence(m), "transform": t, "sha256": m.get("sha256")})
    return {**doc, "maps": maps, "group": None}


def _confidence(m: dict) -> float | None:
    conf = m.get("confidence")
    return float(conf) if isinstance(conf, (int, float)) and not isinstance(conf, bool) else None


# -- evaluation ----------------------------------------------------------------------------------
def evaluate_files(merged, truth, *, report=None, reference: str | None = None) -> dict:
    """Score ``merged`` against ``truth`` (paths); see the command's description.

    Returns
    -------
    dict
        ``merged``, ``truth``, ``world``, ``report`` (path or None), ``reference`` (robot
        name), ``group`` (K for a group's map, else None), ``metrics``
        (:meth:`MapMetrics.as_dict`) and ``maps`` (per map of the report, or of the group:
        ``input``, ``robot``, ``merged`` (in ``merged``: for a group's map, in the group's
        map), ``confidence``, ``transform`` and ``true_transform`` as ``{x, y, theta}`` into
        the frame of ``merged``, and ``error`` in m, cells and degrees).
    """
    from ..mapio import load_map
    from ..metrics import evaluate_map, transform_errors

    merged = Path(merged)
    truth_info = read_truth(truth)
    report_path = find_report(merged, report)
    rep = read_report(report_path, merged) if report_path is not None else None
    robots = truth_info.robots

    guessed = False   # the frame taken as the first robot's, for want of a report or --reference
    if rep is not None:
        # a report names its inputs relative to the folder merge ran in: most often the
        # output's folder or one above it (merge a/b/robot_1.yaml ... -o a/b/merged.yaml)
        bases = (report_path.parent, *report_path.parent.resolve().parents)
        inputs = [m["input"] for m in rep["maps"]]
        try:
            ref = robot_of(truth_info, rep["reference"], bases=bases, others=inputs)
        except InputError as exc:
            raise InputError(f"{report_path}: the reference: {exc}") from None
        if reference is not None and reference != ref:
            whose = (f"whose group {rep['group']} is in the frame of" if rep["group"]
                     else "whose reference is")
            raise InputError(f"--reference {reference} disagrees with the report {report_path}, "
                             f"{whose} {rep['reference']} ({ref}); drop --reference")
    else:
        if reference is None and _group_number(merged) is not None and Path(merged).exists():
            raise InputError(f"{merged} is named like the map of a group of a merge, but no merge "
                             f"report beside it lists it under 'group_outputs', so its frame is "
                             f"unknown; give the merge report with --report, or the robot whose "
                             f"frame it is in with --reference")
        # a robot's own map is in its own frame; any other map, without a report, in the first
        # robot's (the frame a merge of the run in order is in)
        own = next((name for name in robots if _same_file(merged, _map_of(truth_info, name))), None)
        ref = reference if reference is not None else own if own is not None else next(iter(robots))
        guessed = reference is None and own is None
        if ref not in robots:
            raise InputError(f"--reference {ref}: no such robot in {truth_info.path}; choose one of "
                             f"{', '.join(robots)}")

    fused = load_map(merged)
    if not fused.known_mask().any():
        raise InputError(f"{merged}: the map holds no known cell (all unknown), so there is nothing "
                         "to evaluate; give the fused map of a merge")
    world = load_map(truth_info.world)
    t_ref = robots[ref]
    metrics = evaluate_map(fused, world, t_ref)

    rows = []
    for m in rep["maps"] if rep is not None else []:
        try:
            name = robot_of(truth_info, m["input"], bases=bases, others=inputs)
        except InputError as exc:
            raise InputError(f"{report_path}: {exc}") from None
        mine = _map_of(truth_info, name)
        if isinstance(m.get("sha256"), str) and mine.is_file() and map_digest(mine) != m["sha256"]:
            raise InputError(f"{report_path}: map {show(m['input'])} is not the file that was merged: "
                             f"{mine} has changed since (a new run written into its folder?); merge "
                             f"that run's maps again")
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
        "group": rep["group"] if rep is not None else None, "frame_guessed": guessed,
        "metrics": metrics.as_dict(), "maps": rows,
    }


def format_evaluation(result: dict) -> str:
    """The evaluation as tables for the terminal."""
    from ..metrics import format_percent

    m = result["metrics"]
    lines = [
        f"merged map {result['merged']} in the frame of {result['reference']}, "
        f"scored against {result['world']}",
        "",
        f"  {'completeness':<26}{format_percent(m['completeness'], 2, 7)} %",
        f"  {'accuracy':<26}{format_percent(m['accuracy'], 2, 7)} %",
        f"  {'precision':<26}{format_percent(m['precision'], 2, 7)} %",
        f"  {'efficiency':<26}{format_percent(m['efficiency'], 2, 7)} %",
        f"  {'precision (within 1 cell)':<26}{format_percent(m['precision_tol1'], 2, 7)} %",
        f"  cells: {m['known_truth']} known in the truth, {m['known_both']} of them known in the "
        f"merged map, {m['occupied_fused']} occupied in the merged map",
    ]
    if result["report"] is None:
        lines += ["", "no merge report found: give --report for per-map transform errors"]
        if result.get("frame_guessed"):
            lines.append(f"the map was taken to be in the frame of {result['reference']}, the first "
                         f"robot of the truth: give --reference ROBOT if it is in another's")
        return "\n".join(lines)
    where = (f"group {result['group']} of the report {result['report']}; transforms into that "
             f"group's map" if result.get("group") else
             f"report {result['report']}; transforms into the merged frame")
    # of a group's map, whether the map is in it (the report has each of them left out of the
    # merged map)
    column = "in map" if result.get("group") else "merged"
    # the map column as wide as the names, up to 40 characters; names cut there that would
    # read alike are shown whole (as merge's table does)
    names = [str(r["input"]) for r in result["maps"]]
    labels, width = clip_column(names, max(24, min(40, max(map(len, names), default=0))))
    lines += ["", f"per map ({where}):",
              f"  {'map':<{width}} {column:<6} {'conf':>5} {'x (m)':>8} {'y (m)':>8} {'th (deg)':>8}"
              f" {'true x':>8} {'true y':>8} {'true th':>8} {'err (m)':>8} {'cells':>6} {'deg':>6}"]
    for k, r in enumerate(result["maps"]):
        t, tt, e = r["transform"], r["true_transform"], r["error"]
        conf = f"{r['confidence']:5.2f}" if r["confidence"] is not None else f"{'-':>5}"
        est = (f"{fixed(t['x'], 8, 2)} {fixed(t['y'], 8, 2)} {fixed(math.degrees(t['theta']), 8, 1)}"
               if t is not None else f"{'-':>8} {'-':>8} {'-':>8}")
        err = (f"{e['translation_m']:8.3f} {e['translation_cells']:6.1f} {e['rotation_deg']:6.2f}"
               if e is not None else f"{'-':>8} {'-':>6} {'-':>6}")
        lines.append(f"  {labels[k]:<{width}} {'yes' if r['merged'] else 'no':<6} {conf} {est} "
                     f"{fixed(tt['x'], 8, 2)} {fixed(tt['y'], 8, 2)} "
                     f"{fixed(math.degrees(tt['theta']), 8, 1)} {err}")
    return "\n".join(lines)


def run(args) -> int:
    result = evaluate_files(args.merged, args.truth, report=args.report, reference=args.reference)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(format_evaluation(result))
    return 0
