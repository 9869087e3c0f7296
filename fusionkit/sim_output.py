"""Writing a simulated run to disk (CONTRACTS section 5), crash-safe."""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

from ._atomic import check_not_input, check_out_dir, made_out_dir, recover_set, write_set
from .errors import FusionkitError, InputError
from .mapping import MappingConfig

__all__ = ["write_run", "check_run_dir", "merges_of_run", "replaced_run_files"]


_RUN_SUFFIXES = (".yaml", ".pgm", ".scans.npz")
#: Names a simulation writes; only files of these names are ever removed from a run folder.
_ROBOT_NAME = re.compile(r"robot_[1-9][0-9]{0,3}")


#: Temporary and backup files of a killed write of a run (``.robot_3.pgm.<token>.tmp``) and
#: of its journal
_LEFTOVER = re.compile(r"\.(robot_[1-9][0-9]{0,3}(\.yaml|\.pgm|\.scans\.npz)|world\.(yaml|pgm)"
                       r"|truth\.json)\.[0-9a-f]{12}(\.tmp|\.bak|\.journal\.tmp)")


def _previous_robot_files(out: Path) -> list[Path]:
    """Robot files an earlier run in ``out`` wrote: ``robot_K`` files that its truth.json lists.

    Only names of the form a simulation writes count: whatever else a truth.json names (a
    hand-edited or hostile one) is never removed.
    """
    from ._inputs import read_json

    try:
        doc = read_json(out / "truth.json", "truth.json")
        names = [r["name"] for r in doc.get("robots", [])]
    except (FusionkitError, TypeError, KeyError, AttributeError):
        return []
    files = []
    for n in names:
        if isinstance(n, str) and _ROBOT_NAME.fullmatch(n):
            files += [out / (n + s) for s in _RUN_SUFFIXES]
    return files


def merges_of_run(out: Path) -> list[Path]:
    """The files of merges of an earlier run's robot maps that stand in its folder ``out``: for
    each merge report there whose inputs are all maps named as a simulation names them
    (``robot_K.yaml``), the report, the merged map it names (YAML and image) and its group maps.
    A new run into ``out`` makes them wrong: they would be scored against the new truth."""
    from .mapio import merge_reports

    found: list[Path] = []
    for report, doc in merge_reports(out):
        try:
            inputs = [Path(m["input"]).name for m in doc["maps"]]
            outputs = [Path(doc["output"]).name, *(Path(g).name for g in doc.get("group_outputs") or [])]
        except (TypeError, KeyError):
            continue
        if not inputs or not all(_ROBOT_NAME.fullmatch(n.removesuffix(".yaml")) for n in inputs):
            continue
        found.append(report)
        for name in outputs:
            if name.endswith((".yaml", ".yml")) and not _ROBOT_NAME.fullmatch(name.rsplit(".", 1)[0]):
                found += [out / name, (out / name).with_suffix(".pgm")]
    return [p for p in dict.fromkeys(found) if p.is_file()]


def replaced_run_files(out: Path, keep, inputs=(), more=()) -> list[Path]:
    """The files of an earlier run in ``out`` that a new run writing ``keep`` there makes
    wrong: its robot files the new run does not write, the merges of its robots
    (:func:`merges_of_run`) and ``more``; never a file of ``keep`` nor of ``inputs``."""
    if not out.is_dir():
        return []
    # a write of a run killed mid-way is finished or undone first: its truth.json, taken away
    # at the kill, names the robots whose files are then left over
    recover_set(out / "truth.json", _LEFTOVER)
    kept = {Path(q).resolve() for q in [*keep, *inputs]}
    return [p for p in dict.fromkeys([*_previous_robot_files(out), *map(Path, more),
                                      *merges_of_run(out)])
            if p.is_file() and p.resolve() not in kept]


def check_run_dir(out_dir) -> Path:
    """Refuse, before any work, a run folder :func:`write_run` would not write: a file, a folder
    that is not writable, or a non-empty folder without the truth.json of an earlier run."""
    out = check_out_dir(out_dir)
    # a write of a run killed mid-way is finished or undone first (then judged as it stands)
    recover_set(out / "truth.json", _LEFTOVER)
    try:
        nonempty = out.is_dir() and any(out.iterdir())
    except OSError as exc:
        raise InputError(f"{out}: the folder cannot be listed ({exc.strerror or exc}); check its "
                         f"permissions") from None
    if nonempty and not (out / "truth.json").is_file():
        raise InputError(
            f"{out}: the directory is not empty and holds no truth.json of an earlier run; "
            f"choose a new or empty directory")
    return out


def write_run(sim, out_dir, *, world_path=None, stale=()) -> Path:
    """Write a simulation as CONTRACTS section 5 lays it out, and return the truth.json path.

    Files, in ``out_dir``: per robot ``robot_k.yaml`` + ``robot_k.pgm`` (its map, own frame)
    and ``robot_k.scans.npz`` (its scan log, own frame); ``world.yaml`` + ``world.pgm`` (the
    ground truth); ``truth.json`` with ``world`` (``"world.yaml"``, relative to truth.json),
    ``seed``, ``robots`` (per robot ``name``, ``map``, ``transform`` own frame -> world,
    ``poses``, ``path_length_m``), ``config`` (every setting) and, when ``world_path`` is
    given, ``world_source``.

    Parameters
    ----------
    sim : Simulation
    out_dir : str or os.PathLike
        Must not exist, be empty, or hold an earlier run (a ``truth.json``): that run's files
        are replaced (its ``robot_K`` files that the new run does not write are removed; no
        other file is ever removed).
    world_path : str or os.PathLike, optional
        The map file the world was loaded from; it is recorded, and never overwritten or
        removed (nor the image it names, nor a scan log beside it).
    stale : paths, optional
        More files made from the earlier run that the new run makes wrong; removed with the
        same commit, as are the merges of its robots that stand in the folder
        (:func:`merges_of_run`).

    Raises
    ------
    InputError
        ``out_dir`` is a file, or a non-empty directory without a ``truth.json``, or writing
        would overwrite or remove ``world_path``, or the folder cannot be written.

    Notes
    -----
    The run is one set of files (:func:`fusionkit._atomic.write_set`) with ``truth.json`` as
    its commit point: on a failure or an interrupt the folder is left as it was; after a crash
    the next write to it finishes or undoes the interrupted one.
    """
    from .mapio import _protected, encode_map
    from .scanlog import encode_scans, scans_path_for
    if not all(hasattr(sim, a) for a in ("robots", "world", "config")):
        raise InputError(f"write_run needs a Simulation, got {type(sim).__name__}")
    out = check_run_dir(out_dir)
    names = [r.name for r in sim.robots]
    files = [n + s for n in names for s in _RUN_SUFFIXES] + ["world.yaml", "world.pgm", "truth.json"]
    protected: list[Path] = []
    if world_path is not None:
        protected = _protected([world_path]) + [scans_path_for(world_path)]
    check_not_input([out / f for f in files], protected)
    stale = replaced_run_files(out, [out / f for f in files], protected, stale)

    payloads = []
    yamls = []
    robots = []
    for r in sim.robots:
        image, pixels, text = encode_map(r.grid, out / f"{r.name}.yaml")
        payloads += [(image, pixels), (out / f"{r.name}.yaml", text),
                     (out / f"{r.name}.scans.npz", encode_scans(r.scans))]
        yamls.append(out / f"{r.name}.yaml")
        robots.append({"name": r.name, "map": f"{r.name}.yaml",
                       "transform": r.transform.as_dict(digits=9),
                       "poses": int(r.scans.n_scans),
                       "path_length_m": round(r.path_length, 3)})
    world = sim.world.with_data(sim.world.trinary(), name="world")
    image, pixels, text = encode_map(world, out / "world.yaml")
    payloads += [(image, pixels), (out / "world.yaml", text)]
    yamls.append(out / "world.yaml")
    truth = {"world": "world.yaml", "seed": sim.config.seed, "robots": robots}
    if world_path is not None:
        truth["world_source"] = str(world_path)
    cfg = dataclasses.asdict(sim.config)
    if sim.config.mapping is None:
        cfg["mapping"] = dataclasses.asdict(MappingConfig(resolution=sim.world.resolution))
    truth["config"] = cfg
    # Images before the YAMLs that name them (the YAMLs are taken away first), truth.json last.
    order = sorted(payloads, key=lambda f: f[0].suffix in (".yaml", ".yml"))
    with made_out_dir(out):
        write_set(order + [(p, None) for p in stale],
                  (out / "truth.json", (json.dumps(truth, indent=2) + "\n").encode("utf-8")),
                  hide_first=yamls)
    return out / "truth.json"
