"""What the terminal UI does, without the UI: find maps, run a merge, score it, export it.

Every step calls the same library functions as the command line (:func:`fusionkit.pipeline.merge`,
:func:`fusionkit.cli.merge.write_result`, :func:`fusionkit.cli.evaluate.read_truth`,
:func:`fusionkit.metrics.evaluate_map`), so a merge made here is the merge ``fusionkit merge``
would make with the same settings.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

from fusionkit.errors import FusionkitError, InputError
from fusionkit.mapio import GROUP_SUFFIX
from fusionkit.pipeline import MergeConfig, MergeEvent, MergeResult, merge

__all__ = ["MAP_SUFFIXES", "is_map_file", "find_maps", "truth_beside", "Evaluation",
           "evaluate_result", "ExportPaths", "export_paths", "export_result", "output_guard",
           "run_merge", "map_labels", "initial_selection", "describe_error", "check_map"]

#: File name endings the map picker lists (map_server YAML).
MAP_SUFFIXES = (".yaml", ".yml")


def is_map_file(path: Path) -> bool:
    """Whether ``path`` is named like a map YAML (its contents are not read)."""
    return path.suffix.lower() in MAP_SUFFIXES


def _world_of(directory: Path) -> Path | None:
    """The ground-truth world map named by ``directory/truth.json``, if there is one."""
    truth = directory / "truth.json"
    if not truth.is_file():
        return None
    try:
        doc = json.loads(truth.read_text(encoding="utf-8"))
    except (OSError, UnicodeError, json.JSONDecodeError):
        return None
    world = doc.get("world") if isinstance(doc, dict) else None
    if not isinstance(world, str) or not world.strip():
        return None
    p = Path(world.strip())
    return (p if p.is_absolute() else directory / p).resolve()


def find_maps(directory) -> list[Path]:
    """The robot maps of a directory, sorted by name.

    Every ``*.yaml`` / ``*.yml`` file directly in ``directory`` except those that are not
    inputs to a merge: a merged map (a ``<stem>.report.json`` stands beside it, or a merge
    report in the directory names it as its output), a group map of a merge
    (``NAME.group1.yaml`` of such a map) and the ground-truth world that a ``truth.json`` in
    the directory names. A run's folder (a ``truth.json`` naming robots) gives its robots'
    maps only.

    Parameters
    ----------
    directory : str or os.PathLike

    Raises
    ------
    InputError
        ``directory`` is not a readable directory.
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise InputError(f"{directory}: is not a directory; give a directory of map YAML files")
    world = _world_of(directory)
    try:
        entries = sorted(directory.iterdir())
    except OSError as exc:
        raise InputError(f"{directory}: cannot be listed ({exc.strerror or exc}); check its permissions") from None
    merged = _merge_outputs(directory)
    out = []
    for p in entries:
        if not p.is_file() or not is_map_file(p):
            continue
        if p.with_name(p.stem + ".report.json").exists() or p.name in merged:
            continue
        group = _GROUP_MAP.fullmatch(p.name)
        if group and (group[1] + p.suffix in merged
                      or p.with_name(group[1] + ".report.json").exists()):
            continue
        if world is not None and p.resolve() == world:
            continue
        out.append(p)
    robots = _run_robots(directory)
    if robots:   # a run's folder: its robots, whatever else was written there since
        out = [p for p in out if p.resolve() in robots]
    return out


def _run_robots(directory: Path) -> set:
    """The robot maps a ``truth.json`` in ``directory`` names (resolved), if it names any."""
    from fusionkit.cli.evaluate import _map_of, read_truth

    if not (directory / "truth.json").is_file():
        return set()
    try:
        truth = read_truth(directory / "truth.json")
    except (FusionkitError, OSError):
        return set()
    return {_map_of(truth, name).resolve() for name in truth.robots}


#: a group map a merge writes beside its output NAME.yaml: NAME.group1.yaml, ...
_GROUP_MAP = re.compile(r"(.+)" + GROUP_SUFFIX + r"\.(yaml|yml)")


def _merge_outputs(directory: Path) -> set[str]:
    """The names of the maps that merge reports in ``directory`` name as their output or group
    outputs: a report of ``fusionkit merge --report R.json`` need not be named after its map."""
    from fusionkit.mapio import merge_reports

    names = set()
    for _, doc in merge_reports(directory):
        outputs = [doc["output"], *(doc.get("group_outputs") or [])]
        names.update(Path(o).name for o in outputs if isinstance(o, str))
    return names


def initial_selection(paths: Sequence) -> tuple[Path, list[Path]]:
    """Where the picker starts and which maps are selected, from the command-line arguments.

    No argument: the current directory, nothing selected. One directory: that directory and
    its robot maps (:func:`find_maps`). Map files: their common directory and those maps.

    Raises
    ------
    InputError
        An argument that does not exist, a mix of directories and files, several directories,
        or a file that is not named like a map YAML.
    """
    paths = [Path(p) for p in paths]
    if not paths:
        return Path("."), []
    for p in paths:
        if not p.exists():
            raise InputError(f"{p}: no such file or directory; check the path")
    dirs = [p for p in paths if p.is_dir()]
    if dirs:
        if len(paths) > 1:
            raise InputError("give one directory, or map YAML files, not both or several directories")
        return dirs[0], find_maps(dirs[0])
    for p in paths:
        if not is_map_file(p):
            raise InputError(f"{p}: is not a map YAML (.yaml or .yml); give the map's YAML file")
    parents = {p.parent.resolve() for p in paths}
    root = paths[0].parent if len(parents) == 1 else Path(_common_parent(paths))
    return root, list(dict.fromkeys(paths))


def _common_parent(paths: Sequence[Path]) -> str:
    import os.path

    return os.path.commonpath([str(p.parent.resolve()) for p in paths])


def truth_beside(reference_map) -> Path | None:
    """The ``truth.json`` in the reference map's directory, if there is one."""
    p = Path(reference_map).parent / "truth.json"
    return p if p.is_file() else None


@dataclass(frozen=True)
class Evaluation:
    """The paper's Table 1 metrics of a merge, against a simulation's ground truth.

    Attributes
    ----------
    truth : Path
        The truth.json used.
    reference : str
        Robot name whose map frame is the merged frame.
    metrics : MapMetrics
        Of the fused map (docs/formats.md, metrics), in percent.
    steps : tuple of MapMetrics
        Of the fused map after each fusion step (``M1``, ``M1,2``, ...).
    errors : tuple of TransformError or None
        Per input map, its estimated transform against the true one (None when not merged or
        not in the truth file).
    """

    truth: Path
    reference: str
    metrics: object
    steps: tuple
    errors: tuple


def evaluate_result(result: MergeResult, inputs: Sequence, truth_path) -> Evaluation:
    """Score a merge against the ground truth in ``truth_path`` (see docs/formats.md).

    The merged frame is the reference map's frame, so the fused map goes into the world frame
    by the reference robot's transform; each map's true transform into the merged frame is
    ``inv(T_ref) @ T_k``. Maps are matched to the truth's robots by path (a robot ``NAME`` is
    the ``NAME.yaml`` beside truth.json): a map of another run, even one with the same file
    name, has no true transform here and gets no error (None).

    Raises
    ------
    InputError
        A malformed truth file, or a reference map that is not one of the truth's robots.
    """
    from fusionkit.cli.evaluate import read_truth, robot_of
    from fusionkit.mapio import load_map
    from fusionkit.metrics import evaluate_map, table1, transform_errors

    truth = read_truth(truth_path)
    robots = []
    for p in inputs:
        try:
            robots.append(robot_of(truth, str(p)))
        except InputError:
            robots.append(None)
    ref_path = inputs[result.config.reference]
    ref = robots[result.config.reference]
    if ref is None:
        raise InputError(f"{truth.path}: the reference map {ref_path} is not one of its robots "
                         f"({', '.join(truth.robots)}); no metrics for this merge")
    world = load_map(truth.world)
    t_ref = truth.robots[ref]
    metrics = evaluate_map(result.grid, world, t_ref)
    steps = tuple(table1(result.fused.steps, world, t_ref))
    errors = []
    for p, name in zip(result.placements, robots):
        if p.transform is None or name is None:
            errors.append(None)
        else:
            errors.append(transform_errors(p.transform, t_ref.inverse @ truth.robots[name],
                                           result.grid.resolution))
    return Evaluation(truth.path, ref, metrics, steps, tuple(errors))


def map_labels(inputs: Sequence) -> list[str]:
    """How the UI names each input map: the shortest unique end of its path (``a/robot_1``)."""
    from fusionkit.labels import unique_labels

    return unique_labels([str(p) for p in inputs])


def run_merge(inputs: Sequence, config: MergeConfig,
              callback: Callable[[MergeEvent], bool | None] | None = None,
              labels: Sequence[str] | None = None) -> MergeResult:
    """:func:`fusionkit.pipeline.merge` of the map files ``inputs`` (their scans beside them).

    Each map is named by ``labels`` (default :func:`map_labels`) in the progress events and the
    result, so that two ``robot_1.yaml`` of two runs stay apart.
    """
    from dataclasses import replace

    from fusionkit._merge_inputs import check_scans, scans_labels
    from fusionkit.cli.merge import check_no_truth_world
    from fusionkit.pipeline import load_inputs

    check_no_truth_world(inputs)
    labels = list(labels) if labels is not None else map_labels(inputs)
    grids, scans = load_inputs([str(p) for p in inputs])
    check_scans(grids, scans, scans_labels(inputs))   # named by their files, as merge names them
    grids = [replace(g, name=n) for g, n in zip(grids, labels)]
    return merge(grids, scans=scans, config=config, callback=callback)


@dataclass(frozen=True)
class ExportPaths:
    """The files an export writes: the map YAML, its image, the merge report and, for a merge
    that left groups of maps (CONTRACTS section 6), each group's map YAML (``groups``)."""

    yaml: Path
    image: Path
    report: Path
    groups: tuple = ()

    @property
    def all(self) -> tuple:
        return (self.yaml, self.image, self.report,
                *(f for g in self.groups for f in (g, g.with_suffix(".pgm"))))

    def existing(self) -> list[Path]:
        """Those of the files that already exist (an export would overwrite them), once a
        write a kill cut short in their folder is finished or undone (its files hidden, the
        list would be short of them)."""
        from fusionkit._atomic import recover_folder

        for folder in dict.fromkeys(p.parent for p in self.all):
            recover_folder(folder, wait=False)
        return [p for p in self.all if p.exists()]


def export_paths(yaml_path, groups: int = 0) -> ExportPaths:
    """The files written for the map ``yaml_path``: ``NAME.yaml``, ``NAME.pgm`` and
    ``NAME.report.json`` beside it (the names ``fusionkit merge`` and ``fusionkit evaluate`` use),
    and ``NAME.group1.yaml``, ... for a result with ``groups`` groups.

    Raises
    ------
    InputError
        An empty path, or one not ending in .yaml / .yml.
    """
    from fusionkit.pipeline import group_output_paths

    text = str(yaml_path).strip()
    if not text:
        raise InputError("type the path of the map YAML to write, e.g. merged.yaml")
    p = Path(text).expanduser()
    if not is_map_file(p):
        raise InputError(f"{p}: a map is saved as a .yaml file; end the name with .yaml")
    return ExportPaths(p, p.with_suffix(".pgm"), p.with_name(p.stem + ".report.json"),
                       tuple(group_output_paths(p, groups)))


def output_guard(inputs: Sequence):
    """The files an export must never replace (:class:`fusionkit.cli.merge.OutputGuard`): each
    input map, the image it names and its scans, and the ground truth of the inputs' run."""
    from fusionkit.cli.merge import OutputGuard

    return OutputGuard.of([str(p) for p in inputs])


def export_result(result: MergeResult, inputs: Sequence, yaml_path) -> ExportPaths:
    """Write the fused map (YAML + PGM), each group's map and the merge report (docs/formats.md),
    as ``fusionkit merge`` writes them (:func:`fusionkit.cli.merge.write_result`).

    The files are written as one set, the report last; no input map, image or scan log and no
    file of the run's ground truth is ever overwritten; existing output files are replaced (ask
    first).

    Parameters
    ----------
    result : MergeResult
    inputs : sequence of paths
        The input maps, in merge order, as the report should name them.
    yaml_path : str or os.PathLike
        The map YAML to write.

    Raises
    ------
    InputError
        A bad output name, a missing directory, or an output that is an input or a file of the
        run's ground truth.
    """
    from fusionkit import _atomic
    from fusionkit.cli.merge import write_result

    paths = export_paths(yaml_path, len(result.groups))
    inputs = [str(p) for p in inputs]
    # each export is a command of its own: stopped during this one, the app must not say that
    # an earlier export's set is the new one
    _atomic.COMMITTED.clear()
    write_result(result, inputs, paths.yaml, paths.report, guard=output_guard(inputs))
    return paths


def describe_error(exc: BaseException) -> str:
    """One line for a notification: the message of a fusionkit error, else the error's type."""
    if isinstance(exc, FusionkitError):
        return str(exc)
    if isinstance(exc, OSError):
        return f"{exc.filename or ''}: {exc.strerror or exc}".lstrip(": ")
    return f"{type(exc).__name__}: {exc}"


def check_map(path) -> tuple[dict, object]:
    """Read the map ``path`` whole: its :func:`~fusionkit.mapio.map_info` and its grid.

    Raises
    ------
    FusionkitError or OSError
        The map cannot be used (a bad YAML, a missing or corrupt image, ...): the message says why.
    """
    from fusionkit.mapio import load_map, map_info

    return map_info(path), load_map(path)
