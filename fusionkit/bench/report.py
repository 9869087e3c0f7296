"""Reporting: the summary of a suite's results, its table (text and Markdown), its JSON and
the figure of one case per method.
"""

from __future__ import annotations

import io
import json
import os
import statistics
from dataclasses import asdict
from pathlib import Path

import numpy as np

from .._atomic import check_not_input, hidden_copies, recover_set, write_set
from .._guards import _same_file
from ..grid import OccupancyGrid
from ..labels import count
from ..resample import resample
from ..transform import Transform2D
from .config import OVERLAP_BINS
from .runner import BenchResult

__all__ = ["summarize", "format_markdown", "write_outputs"]


def _median(values) -> float | None:
    v = [x for x in values if x is not None]
    return round(float(statistics.median(v)), 4) if v else None


def _bin_label(ov: float) -> str:
    edges = list(OVERLAP_BINS) + [1.0001]
    for lo, hi in zip(edges[:-1], edges[1:]):
        if lo <= ov < hi:
            return f"{lo:.2f}-{min(hi, 1.0):.2f}"
    return "?"


def _tally(entries) -> dict:
    linked = [e for e in entries if e["linked"]]
    n = len(linked)
    succ = sum(e["status"] == "success" for e in linked)
    wrong = sum(e["status"] == "wrong" for e in entries)
    refused = sum(e["status"] == "refused" for e in linked)
    return {"pairs": n, "success": succ, "wrong": wrong, "refused": refused,
            "success_rate": round(100.0 * succ / n, 1) if n else None,
            "unlinked": len(entries) - n,
            "unlinked_refused": sum(e["status"] == "refused" for e in entries if not e["linked"])}


def summarize(result: BenchResult) -> dict:
    """Per-method totals and the breakdowns by world, mode, K and overlap."""
    methods = result.config.methods
    summary = {"methods": {}, "by": {"world": {}, "mode": {}, "robots": {}, "overlap": {}}}
    for m in methods:
        entries, times, t1, errs = [], [], [], 0
        for rec in result.cases:
            r = rec["methods"][m]
            for e in r["maps"]:
                entries.append(dict(e, world=rec["world"], mode=rec["mode"], robots=rec["robots"]))
            times.append(r["seconds_per_pair"])
            if r["table1"] is not None:
                t1.append(r["table1"])
            errs += bool(r["error"])
        tally = _tally(entries)
        merged = [e for e in entries if e["status"] != "refused"]
        tally.update(
            median_rot_err_deg=_median(e["rot_err_deg"] for e in merged),
            median_trans_err_cells=_median(e["trans_err_cells"] for e in merged),
            median_rot_err_success_deg=_median(e["rot_err_deg"] for e in merged if e["status"] == "success"),
            median_trans_err_success_cells=_median(e["trans_err_cells"] for e in merged
                                                   if e["status"] == "success"),
            median_seconds_per_pair=_median(times),
            errors=errs,
            table1={k: _median(t[k] for t in t1) for k in ("completeness", "accuracy", "precision",
                                                            "efficiency", "precision_tol1")})
        summary["methods"][m] = tally
        for key, fn in (("world", lambda e: e["world"]), ("mode", lambda e: e["mode"]),
                        ("robots", lambda e: f"K={e['robots']}"),
                        ("overlap", lambda e: _bin_label(e["overlap"]))):
            groups: dict = {}
            for e in entries:
                groups.setdefault(fn(e), []).append(e)
            for g, es in sorted(groups.items()):
                summary["by"][key].setdefault(g, {})[m] = _tally(es)
    oracle = [rec["oracle"] for rec in result.cases]
    summary["oracle_table1"] = {k: _median(t[k] for t in oracle) for k in (
        "completeness", "accuracy", "precision", "efficiency", "precision_tol1")}
    return summary


def _fmt(v, suffix="") -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.2f}{suffix}" if abs(v) < 100 else f"{v:.1f}{suffix}"
    return f"{v}{suffix}"


def _pct(v) -> str:
    return "-" if v is None else f"{v:.1f}%"


def format_table(result: BenchResult, summary: dict | None = None) -> str:
    """The main per-method table (markdown)."""
    s = summary or summarize(result)
    head = ("| method | pairs | success | wrong merges | refusals | median rot err (deg) | "
            "median trans err (cells) | Compl | Acc | Prec | Eff | median s / pair |")
    lines = [head, "|" + "---|" * 12]
    for m, t in s["methods"].items():
        t1 = t["table1"]
        lines.append(
            f"| {m} | {t['pairs']} | {t['success']} ({_pct(t['success_rate'])}) | {t['wrong']} | "
            f"{t['refused']} | {_fmt(t['median_rot_err_deg'])} | {_fmt(t['median_trans_err_cells'])} | "
            f"{_fmt(t1['completeness'])} | {_fmt(t1['accuracy'])} | {_fmt(t1['precision'])} | "
            f"{_fmt(t1['efficiency'])} | {_fmt(t['median_seconds_per_pair'])} |")
    o = s["oracle_table1"]
    lines.append(f"| oracle (true transforms) | | | | | | | {_fmt(o['completeness'])} | "
                 f"{_fmt(o['accuracy'])} | {_fmt(o['precision'])} | {_fmt(o['efficiency'])} | |")
    return "\n".join(lines)


def format_markdown(result: BenchResult, summary: dict | None = None) -> str:
    """The whole report: settings, main table, breakdowns, unlinked maps."""
    s = summary or summarize(result)
    cfg = result.config
    modes = {}
    for rec in result.cases:
        modes[rec["mode"]] = modes.get(rec["mode"], 0) + 1
    # the worlds the cases were drawn on: a log is always split; --cases below the number of
    # map worlds leaves the rest of them unused
    used = [w.name for w in result.worlds if any(rec["world"] == w.name for rec in result.cases)]
    unused = len(result.worlds) - len(used)
    maps = sum(w.log is None for w in result.worlds)
    lines = [
        "# fusionkit bench",
        "",
        f"{count(len(result.cases), 'case')} ({', '.join(f'{n} {m}' for m, n in modes.items())}) on "
        f"{count(len(used), 'world')} ({', '.join(used)})"
        + (f", {unused} more not drawn on (--cases {cfg.cases} draws on {maps - unused} of the "
           f"{maps} map worlds)" if unused else "") + "; K = "
        f"{', '.join(str(k) for k in cfg.robots)} maps per case; pair overlap >= {cfg.min_overlap:g}; "
        f"seed {cfg.seed}; wall time {result.seconds:.0f} s.",
        "",
    ]
    if result.command:
        lines += ["Command:", "", "```", result.command, "```", ""]
    if result.skipped:
        lines += ["Maps and logs not used: " + "; ".join(f"{n} ({w})" for n, w in result.skipped) + ".", ""]
    lines += [
        f"A pair is a non-reference map of a case. Success: merged with rotation error < "
        f"{cfg.max_rotation_deg:g} deg and its known-cell centroid < {cfg.max_cells:g} cells from "
        f"the truth; wrong merge: merged outside those bounds; refusal: not merged. Median errors "
        f"over merged pairs; Table 1 metrics (%) are medians over cases of the fused map against "
        f"the world; time is a merge's wall time over K - 1.",
        "",
        format_table(result, s),
        "",
    ]
    for key, title in (("mode", "By mode"), ("robots", "By number of maps"),
                       ("overlap", "By overlap of the pair"), ("world", "By world")):
        lines += [f"## {title}", "",
                  "| " + key + " | " + " | ".join(cfg.methods) + " |",
                  "|---|" + "---|" * len(cfg.methods)]
        for g, per in s["by"][key].items():
            cells = []
            for m in cfg.methods:
                t = per.get(m)
                if t is None or t["pairs"] == 0:
                    cells.append("-")
                else:
                    cells.append(f"{t['success']}/{t['pairs']} ({_pct(t['success_rate'])}), "
                                 f"{t['wrong']} wrong")
            if any(c != "-" for c in cells):
                lines.append(f"| {g} | " + " | ".join(cells) + " |")
        lines.append("")
    unl = {m: (t["unlinked"], t["unlinked_refused"]) for m, t in s["methods"].items()}
    if any(u for u, _ in unl.values()):
        lines += ["Maps that no overlap >= the minimum links to the reference, or that hold no walls "
                  "(right answer: refuse): "
                  + ", ".join(f"{m} refused {r} of {u}" for m, (u, r) in unl.items()) + ".", ""]
    errs = {m: t["errors"] for m, t in s["methods"].items() if t["errors"]}
    if errs:
        lines += ["Merges that raised an error (counted as refusals): "
                  + ", ".join(f"{m} {n}" for m, n in errs.items()) + ".", ""]
    return "\n".join(lines)


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o).__name__)


#: Pixels across the map in a bench picture (7 inches at 90 dpi, less the margins)
_PIXELS = 560


def _pooled(img: np.ndarray, pixels: int) -> np.ndarray:
    """``img`` (labels ranked so that the higher one should show) shrunk to at most ``pixels``
    across by keeping each block's highest label: walls one cell wide stay in the picture of a
    floor of thousands of cells, where drawing every ``k``-th cell drops most of them. A block
    holding walls on the truth and off it shows them on it: a map a cell or two off looks
    right at this scale (the tables give its error)."""
    k = -(-max(img.shape) // pixels)
    if k <= 1:
        return img
    r, c = -(-img.shape[0] // k) * k, -(-img.shape[1] // k) * k
    pad = np.zeros((r, c), img.dtype)
    pad[:img.shape[0], :img.shape[1]] = img
    return pad.reshape(r // k, k, c // k, k).max(axis=(1, 3))


def picture_title(showcase: dict, method: str, record: dict) -> str:
    """A bench picture's title: the case and its maps numbered as in ``bench.json`` (the
    case's ``index``, each map's ``map``; the reference is map 0)."""
    st = [f"map {e['map']} {e['status']}" for e in record["maps"]]
    return (f"{method}: case {showcase['index']} of bench.json ({record.get('world', '')}; the "
            f"same case for every method)\n{', '.join(st)} (map 0 the reference)\nblack: walls "
            f"on the truth, red: walls off the truth, blue: truth walls not mapped")


def _render(showcase: dict, method: str, record: dict) -> bytes:
    """One picture of the showcase case for ``method``: its fused map placed in the world by
    the reference's true transform, over the world's walls."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap

    w = showcase["world"]
    world = OccupancyGrid(w["data"], w["resolution"], tuple(w["origin"]))
    f = showcase["fused"][method]
    fused = OccupancyGrid(f["data"], f["resolution"], tuple(f["origin"]))
    placed = resample(fused, Transform2D.from_dict(showcase["ref_true"]), world).data
    img = np.zeros(world.shape, np.int8)                # 0 unknown in both
    img[world.data >= 0] = 1                            # world known
    img[placed == 0] = 2                                # fused free
    img[world.data >= 50] = 3                           # world walls
    img[placed >= 50] = 4                               # fused walls
    img[(placed >= 50) & (world.data >= 50)] = 5        # fused walls on world walls
    known = np.nonzero((world.data >= 0) | (placed >= 0))
    r0, r1 = known[0].min(), known[0].max() + 1
    c0, c1 = known[1].min(), known[1].max() + 1
    cmap = ListedColormap(["#d0d0d0", "#f4f4f4", "#ffffff", "#9ab0d8", "#d62728", "#1a1a1a"])
    fig, ax = plt.subplots(figsize=(7, 7 * (r1 - r0) / max(c1 - c0, 1) + 0.8))
    ax.imshow(_pooled(img[r0:r1, c0:c1], _PIXELS), origin="lower", cmap=cmap, vmin=-0.5,
              vmax=5.5, interpolation="nearest")
    ax.set_title(picture_title(showcase, method, record), fontsize=9)
    ax.set_xticks([])
    ax.set_yticks([])
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    return buf.getvalue()


def output_files(out_dir: str | os.PathLike, methods) -> list[Path]:
    """The files :func:`write_outputs` writes into ``out_dir`` for ``methods``."""
    out = Path(out_dir)
    return [out / "bench.md", out / "bench.json"] + [out / f"bench_{m}.png" for m in methods]


def write_outputs(result: BenchResult, out_dir: str | os.PathLike, summary: dict | None = None,
                  inputs=()) -> list[Path]:
    """Write ``bench.md``, ``bench.json`` and ``bench_<method>.png`` into ``out_dir``, as one set
    (:func:`fusionkit._atomic.write_set`, ``bench.json`` written last): an interrupted write
    leaves the earlier run's files whole, never new tables beside old pictures. Pictures of
    methods this run did not have are removed with it, but never a file of ``inputs`` (the
    maps, their images and the logs the bench read): one of those among the outputs is
    refused (:class:`~fusionkit.errors.InputError`)."""
    inputs = [Path(p) for p in inputs]
    check_not_input(output_files(out_dir, result.config.methods), inputs)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    # a write here that a kill cut short is finished or undone first, so that the pictures it
    # hid are in view when the stale ones are listed
    recover_set(out / "bench.json", hidden_copies(r"bench_[^/]+\.png"))
    s = summary or summarize(result)
    files = []
    if result.showcase is not None:
        rec = dict(result.cases[result.showcase["index"]])
        for m in result.config.methods:
            files.append((out / f"bench_{m}.png",
                          _render(result.showcase, m, dict(rec["methods"][m], world=rec["world"]))))
    files.append((out / "bench.md", (format_markdown(result, s) + "\n").encode("utf-8")))
    doc = {"config": asdict(result.config), "command": result.command,
           "worlds": [asdict(w) for w in result.worlds], "skipped": [list(x) for x in result.skipped],
           "seconds": round(result.seconds, 2), "summary": s, "cases": list(result.cases)}
    commit = (out / "bench.json", (json.dumps(doc, indent=1, default=_json_default) + "\n").encode("utf-8"))
    new = {p for p, _ in files}
    stale = [p for p in sorted(out.glob("bench_*.png"))
             if p not in new and p.is_file() and not any(_same_file(q, p) for q in inputs)]
    write_set(files + [(p, None) for p in stale], commit)
    return [out / "bench.md", out / "bench.json"] + [p for p, _ in files if p.suffix == ".png"]
