"""``fusionkit merge``: fuse robot maps into one (report format: docs/formats.md)."""

from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass, replace
from pathlib import Path

from .._atomic import check_distinct, check_not_input, check_writable, show
from ..errors import InputError
from ..labels import clip_column, fixed
from ._common import Progress, add_merge_options, int_range, merge_config_from_args
from ._executor import add_executor_options, executor_from_args

EXIT_ALL_MERGED = 0
EXIT_SOME_LEFT_OUT = 3


def register(sub) -> None:
    from ..methods.consensus import ConsensusConfig
    p = sub.add_parser(
        "merge", help="fuse several robots' maps into the first map's frame",
        description="Find the rigid transform of each map into the reference map's frame and fuse "
                    "them (ROS map_server YAML in, YAML + PGM out). A NAME.scans.npz beside a map is "
                    "used when present; without, the default method places the map by its walls alone "
                    "and spectral-pso casts virtual scans in the map's free space. "
                    "Exit status: 0 all maps merged, 3 some left out (not confidently placed), "
                    "2 bad input. Maps linked among themselves but not to the reference are "
                    "fused group by group into MERGED.group1.yaml, ... (listed in the report). "
                    "Report and file formats: docs/formats.md.")
    p.add_argument("maps", nargs="+", metavar="MAP.yaml", help="robot maps (two or more)")
    p.add_argument("-o", "--output", required=True, metavar="MERGED.yaml",
                   help="where to write the fused map (YAML + PGM beside it)")
    p.add_argument("--report", metavar="REPORT.json",
                   help="merge report (JSON); default: MERGED.report.json beside the output")
    p.add_argument("--reference", metavar="MAP.yaml",
                   help="the map whose frame is the merged frame (default: the first map)")
    add_merge_options(p)
    p.add_argument("--candidates", type=int_range(0, 100000), default=None, metavar="M",
                   help="consensus method: estimate in full only each map's M best-ranked others "
                        "(by a cheap signature of its scans) and the pairs that close loops, so "
                        "a large fleet costs about linearly in its size; 0: every pair "
                        f"(default {ConsensusConfig().candidates})")
    add_executor_options(p, what="pairs")
    p.add_argument("--quiet", action="store_true", help="print nothing on success")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..executor import using
    from ..methods.consensus import ConsensusConfig
    from ..pipeline import MergeResult, merge
    from ..progress import ProgressBar

    out = Path(args.output)
    if out.suffix.lower() not in (".yaml", ".yml"):   # (M.YAML too, as maps are read)
        raise InputError(f"{show(str(out), 200)}: the output must be a map YAML path ending in .yaml "
                         f"(or .yml)")
    if args.report is not None and not str(args.report).strip():
        raise InputError("--report is empty: give the report's path, or leave --report out for "
                         f"{out.stem}.report.json beside the map")
    report_path = Path(args.report) if args.report else out.with_name(out.stem + ".report.json")
    image_path = out.with_suffix(".pgm")
    if len(args.maps) < 2:
        if len(args.maps) == 1 and not os.path.lexists(args.maps[0]):
            # most often a shell pattern that matched nothing, passed on as it was written
            raise InputError(f"{show(args.maps[0], 200)}: no such map file (a pattern such as "
                             f"robot_*.yaml that matches no file is passed on as it is); give at "
                             f"least two maps to merge")
        raise InputError("give at least two maps to merge")
    inputs = list(args.maps)
    check_writable([out, image_path, report_path])
    check_distinct([("-o", out), ("the output's image", image_path), ("--report", report_path)])
    check_no_truth_world(inputs)
    guard = OutputGuard.of(inputs)
    guard.check([out, image_path, report_path])
    if report_path.suffix.lower() in (".yaml", ".yml", ".pgm", ".png", ".npz"):
        # a map's or a scan log's name: most likely a slip, and the file it names would be lost
        raise InputError(f"--report {show(str(report_path), 200)}: the report is JSON; give it a name "
                         f"ending in .json (e.g. {out.stem}.report.json)")
    reference = 0
    if args.reference is not None:
        # the same file however it is written (./B.yaml for B.yaml, an absolute path)
        same = [k for k, m in enumerate(inputs)
                if os.path.realpath(m) == os.path.realpath(args.reference)]
        if not same:
            raise InputError(f"--reference {show(args.reference, 200)} is not one of the maps given")
        reference = same[0]
    config = merge_config_from_args(args, reference=reference)
    if args.candidates is not None:
        config = replace(config, consensus=replace(config.consensus or ConsensusConfig(),
                                                   candidates=args.candidates))
    progress = Progress("merging", enabled=None if not args.quiet else False)
    pairs_bar = ProgressBar("merge", unit="pairs", enabled=None if not args.quiet else False)

    last: list = []

    def callback(ev):
        if config.method == "consensus":
            if ev.stage == "align":                        # the pairs: the long part
                pairs_bar(ev.step, ev.total)
                last[:] = [ev.total]
            elif last:                                     # the pairs are done
                pairs_bar(last[0], last[0])
                last.clear()
        elif ev.stage == "align" and ev.pso is not None:
            progress(ev.step, ev.total, f"{ev.label} it {ev.pso.iteration}")
        elif ev.stage != "align":
            progress(0, 1, ev.stage)

    with executor_from_args(args) as executor, using(executor):
        if not args.quiet and executor.name != "inprocess":
            pairs_bar.note(executor.describe())
        result: MergeResult = merge(inputs, config=config, callback=callback)
        pairs_bar.close()
        progress.close()
    group_paths = write_result(result, inputs, out, report_path, guard=guard,
                               output_name=args.output)
    if not args.quiet:
        print(format_placements(result, inputs))
        print(f"fused map: {out} ({result.grid.cols}x{result.grid.rows} cells); report: {report_path}")
        for group, path in zip(result.groups, group_paths):
            print(f"group {group.number} ({', '.join(str(inputs[k]) for k in group.members)}), "
                  f"not linked to the reference: {path}")
    return EXIT_ALL_MERGED if result.all_merged else EXIT_SOME_LEFT_OUT


def write_result(result, inputs, out, report_path, *, guard=None, output_name=None) -> list[Path]:
    """Write a merge's files as one set: the fused map ``out`` (YAML and PGM), each group's map
    beside it (``NAME.group1.yaml``, ...) and the report, written last as the commit point.
    Group maps of an earlier merge into ``out`` that this one does not write go with it.

    None of them may replace a file the merge read or the ground truth of the inputs' run
    (``guard``, :meth:`OutputGuard.of` the inputs when not given). The report names the output
    ``output_name`` (default ``out``) and the inputs as given. Returns the group maps' paths.
    """
    from .._atomic import hidden_copies, recover_set
    from ..mapio import GROUP_SUFFIX, group_map_files, map_digest, merge_reports, save_maps
    from ..pipeline import group_output_paths

    out = Path(out)
    guard = OutputGuard.of(inputs) if guard is None else guard
    # a write to this output that a kill cut short is finished or undone first, so that the
    # files it hid are in view when the stale ones are listed
    recover_set(report_path, hidden_copies(re.escape(out.stem) + GROUP_SUFFIX + r"\.(yaml|yml|pgm|png)"),
                [out])
    group_paths = group_output_paths(out, len(result.groups))
    group_files = group_paths + [q.with_suffix(".pgm") for q in group_paths]
    new = set(group_files)
    stale = [q for q in group_map_files(out) if q not in new]
    # a report of an earlier merge into ``out`` under another name (the default one, when this
    # merge gives --report) describes a map this one replaces: evaluate took it for this one's
    stale += [q for q, doc in merge_reports(out.parent)
              if Path(str(doc["output"])).name == out.name
              and os.path.realpath(q) != os.path.realpath(report_path)]
    guard.check([out, out.with_suffix(".pgm"), report_path, *group_files, *stale])
    report = result.report([str(p) for p in inputs], output=str(out if output_name is None else output_name))
    for entry, path in zip(report["maps"], inputs):   # which files were merged, for evaluate
        entry["sha256"] = map_digest(path)
    save_maps([(result.grid, out)] + [(g.grid, q) for g, q in zip(result.groups, group_paths)],
              (report_path, json.dumps(report, indent=2) + "\n"), inputs=guard.inputs, remove=stale)
    return group_paths


@dataclass(frozen=True)
class OutputGuard:
    """The files a merge's outputs must never replace: every file it reads (``inputs``) and
    the ground truth of the inputs' run (``truth``, :func:`run_truth`)."""

    inputs: tuple
    truth: tuple

    @classmethod
    def of(cls, maps) -> "OutputGuard":
        """The guard of a merge of the map YAML files ``maps``."""
        return cls(tuple(protected_inputs(maps)), tuple(run_truth(maps)))

    def check(self, outputs) -> None:
        """Raise :class:`InputError` when an output path is one of the guarded files."""
        check_not_input(outputs, self.inputs)
        check_not_input(outputs, self.truth, what=TRUTH_FILE)


def protected_inputs(inputs) -> list[Path]:
    """Every file a merge reads: each map YAML, the image it names and its scan log."""
    from ..mapio import _protected
    from ..scanlog import scans_path_for

    # (a path with no name of its own, "." or "/", is no map: refused as a folder when read)
    return _protected(inputs) + [scans_path_for(m) for m in inputs if Path(m).name]


#: How :func:`check_not_input` names a file of :func:`run_truth`
TRUTH_FILE = "a file of the ground truth of the inputs' run,"


def run_truth(inputs) -> list[Path]:
    """The ground truth of each run an input map stands in (a ``truth.json`` beside it): that
    file, the world map it names and the run's robot maps, with their images. A merge written
    over one of them would spoil the run's evaluation (``fusionkit evaluate``)."""
    from ..mapio import _protected
    from .evaluate import _map_of

    out: list[Path] = []
    for truth, t in _truths_beside(inputs):
        out.append(truth)
        if t is not None:   # (not a run's truth after all: only the file itself is kept)
            out += _protected([t.world, *(_map_of(t, name) for name in t.robots)])
    return out


def _truths_beside(inputs):
    """``(path, Truth or None)`` of each ``truth.json`` beside an input map, once per folder
    (None when it cannot be read as a run's truth)."""
    from ..errors import FusionkitError
    from .evaluate import read_truth

    for folder in dict.fromkeys(Path(m).parent for m in inputs):
        truth = folder / "truth.json"
        if not truth.is_file():
            continue
        try:
            yield truth, read_truth(truth)
        except (FusionkitError, OSError):
            yield truth, None


def check_no_truth_world(inputs) -> None:
    """Refuse a map that is the ground-truth world of a run an input stands in (the ``world``
    of a ``truth.json`` beside any input, wherever that world lies) and none of its robots'
    maps: fused in, it fills the merged map with the truth, and the run's evaluation cannot
    score the merge (``fusionkit evaluate`` knows it as no robot's map)."""
    from .evaluate import _map_of, _same_file

    for truth, t in _truths_beside(inputs):
        if t is None:
            continue   # not a run's truth: nothing to tell the world by
        robots = [_map_of(t, name) for name in t.robots]
        for m in inputs:
            if (Path(m).name and _same_file(Path(m), Path(t.world))
                    and not any(_same_file(Path(m), r) for r in robots)):
                raise InputError(f"{show(str(m), 200)}: the ground-truth map of a run "
                                 f"({show(str(truth), 200)} names it as the world), not a robot's "
                                 f"map: leave it out of the merge (the robots' maps are the ones "
                                 f"{truth.name} names)")


def format_placements(result, names) -> str:
    """A table of each map's placement, for the terminal."""
    # two paths that differ only where they were clipped printed as the same map: whole
    shown, width = clip_column(names, 28)
    lines = [f"{'map':<{width}} {'merged':<7} {'conf':>5} {'x (m)':>8} {'y (m)':>8} {'theta (deg)':>11}"]
    for p in result.placements:
        name = shown[p.index]
        if p.transform is None:
            lines.append(f"{name:<{width}} {'no':<7} {p.confidence:5.2f} {'-':>8} {'-':>8} {'-':>11}  "
                         f"{p.reason}")
        else:
            t = p.transform
            lines.append(f"{name:<{width}} {'yes':<7} {p.confidence:5.2f} {fixed(t.x, 8, 2)} "
                         f"{fixed(t.y, 8, 2)} {fixed(math.degrees(t.theta), 11, 1)}")
    order = ", ".join(f"{names[a]} + {names[b]}" for a, b in result.fusion_order) or "(none)"
    lines.append(f"fusion order: {order}")
    unsure = [p for p in result.placements
              if p.merged and p.index != result.config.reference and p.confidence < 0.5]
    if unsure and result.config.method != "consensus":
        # merged by the method's own rule, where the common test cannot tell it from chance
        lines.append(f"note: {len(unsure)} map{'s' if len(unsure) > 1 else ''} merged by "
                     f"{result.config.method}'s own rule at confidence under 0.50, where the test "
                     f"cannot tell {'them' if len(unsure) > 1 else 'it'} from a wrong placement: "
                     + ", ".join(str(names[p.index]) for p in unsure))
    lines.append(f"method: {result.config.method}; time: "
                 + ", ".join(f"{k} {v:.2f} s" for k, v in result.seconds.items()))
    return "\n".join(lines)
