"""Map quality against the ground truth: the paper's Table 1 metrics made exact (CONTRACTS 7).

The fused map F is placed in the ground-truth frame and sampled onto the ground-truth grid G
by nearest neighbour; ``known(X)`` are the cells of X that are not unknown. Then, in percent::

    completeness = |known(F) & known(G)| / |known(G)|
    accuracy     = |{c in known(G) : F(c) = G(c)}| / |known(G)|
    precision    = |{c : F(c) = occupied and G(c) = occupied}| / |{c : F(c) = occupied}|
    efficiency   = completeness x precision

Beside the strict, cell-exact precision, ``precision_tol1`` counts an occupied cell of F as
correct when G has an occupied cell within one cell of it (its 3 x 3 neighbourhood): a wall
drawn one cell off is then not counted as wrong.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from numbers import Real

import numpy as np

from ._validate import digits_arg
from .errors import InputError
from .grid import OccupancyGrid
from .resample import resample
from .transform import Transform2D

__all__ = [
    "MapMetrics", "evaluate_map", "TransformError", "transform_errors", "table1", "Table1Row",
    "PAPER_TABLE1", "table1_label", "format_table1",
]


@dataclass(frozen=True)
class MapMetrics:
    """The paper's Table 1 metrics of one map, with the cell counts behind them.

    Attributes
    ----------
    completeness, accuracy, precision, efficiency : float
        CONTRACTS section 7, in percent. ``precision`` is 0.0 when F has no occupied cell on
        G's grid (nothing drawn, nothing right), and ``efficiency`` follows it.
    precision_tol1 : float
        Precision counting an occupied F cell correct when an occupied G cell is within one
        cell (8-neighbourhood), in percent (0.0 when F has no occupied cell).
    known_truth : int
        ``|known(G)|``.
    known_fused : int
        ``|known(F)|`` on G's grid (F cells outside G's extent are not counted anywhere).
    known_both : int
        ``|known(F) & known(G)|``.
    correct : int
        Cells of known(G) where F has the same state.
    occupied_fused : int
        Occupied cells of F on G's grid.
    occupied_correct : int
        Occupied in both F and G.
    occupied_correct_tol1 : int
        Occupied in F with an occupied G cell within one cell.
    occupied_truth : int
        Occupied cells of G.
    """

    completeness: float
    accuracy: float
    precision: float
    efficiency: float
    precision_tol1: float
    known_truth: int
    known_fused: int
    known_both: int
    correct: int
    occupied_fused: int
    occupied_correct: int
    occupied_correct_tol1: int
    occupied_truth: int

    def as_dict(self, digits: int | None = 4) -> dict:
        """Plain ``{name: value}`` (percentages rounded to ``digits`` unless ``None``)."""
        d = asdict(self)
        digits = digits_arg(digits)
        if digits is not None:
            for k, v in d.items():
                if isinstance(v, float):
                    d[k] = round_percent(v, digits)
        return d


def round_percent(value: float, digits: int = 2) -> float:
    """``value`` (percent) rounded to ``digits``, but never to 0 or 100 unless it is exactly that:
    99.997 is 99.99 at two digits, not 100.00, and 0.001 is 0.01, not 0.00."""
    r = round(float(value), digits)
    step = 10.0 ** -digits
    if r >= 100.0 and value < 100.0:
        return round(100.0 - step, digits)
    if r <= 0.0 and value > 0.0:
        return round(step, digits)
    return r


def format_percent(value: float, digits: int = 2, width: int = 0) -> str:
    """``value`` (percent) as text by :func:`round_percent`, right-aligned to ``width``."""
    return f"{round_percent(value, digits):{width}.{digits}f}"


def _dilate8(mask: np.ndarray) -> np.ndarray:
    """``mask`` grown by one cell in all 8 directions."""
    p = np.pad(mask, 1)
    rows, cols = mask.shape
    out = np.zeros_like(mask)
    for dr in range(3):
        for dc in range(3):
            out |= p[dr:dr + rows, dc:dc + cols]
    return out


def _pct(num: int, den: int) -> float:
    return 100.0 * num / den if den else 0.0


def evaluate_map(fused: OccupancyGrid, truth: OccupancyGrid,
                 transform: Transform2D = Transform2D.identity()) -> MapMetrics:
    """Score a map against the ground truth (CONTRACTS section 7, the paper's Table 1).

    Parameters
    ----------
    fused : OccupancyGrid
        The map to score (F).
    truth : OccupancyGrid
        The ground-truth map (G); its cells are the cells counted.
    transform : Transform2D
        Maps F's map frame into G's map frame (m, rad); identity when they share a frame.

    Returns
    -------
    MapMetrics

    Raises
    ------
    InputError
        When G has no known cell (completeness is then undefined).

    Notes
    -----
    F is sampled onto G's grid by nearest neighbour (the F cell under each G cell centre);
    F cells that fall outside G's extent are dropped. Probabilities count as occupied from 50.
    """
    if not isinstance(fused, OccupancyGrid) or not isinstance(truth, OccupancyGrid):
        raise InputError("evaluate_map needs two OccupancyGrid values (fused, truth)")
    if not isinstance(transform, Transform2D):
        raise InputError(f"transform must be a Transform2D, got {type(transform).__name__}")
    f = resample(fused, transform, truth)
    f_known, f_occ = f.known_mask(), f.occupied_mask()
    g_known, g_occ = truth.known_mask(), truth.occupied_mask()
    known_truth = int(g_known.sum())
    if known_truth == 0:
        name = f" {truth.name}" if truth.name else ""
        raise InputError(f"the ground-truth map{name} has no known cell; nothing to score against")
    known_both = int((f_known & g_known).sum())
    # the same state: both occupied, or both free
    same = (f_occ & g_occ) | (f.free_mask() & truth.free_mask())
    correct = int(same.sum())
    occupied_fused = int(f_occ.sum())
    occupied_correct = int((f_occ & g_occ).sum())
    occupied_correct_tol1 = int((f_occ & _dilate8(g_occ)).sum())

    completeness = _pct(known_both, known_truth)
    precision = _pct(occupied_correct, occupied_fused)
    return MapMetrics(
        completeness=completeness,
        accuracy=_pct(correct, known_truth),
        precision=precision,
        efficiency=completeness * precision / 100.0,
        precision_tol1=_pct(occupied_correct_tol1, occupied_fused),
        known_truth=known_truth,
        known_fused=int(f_known.sum()),
        known_both=known_both,
        correct=correct,
        occupied_fused=occupied_fused,
        occupied_correct=occupied_correct,
        occupied_correct_tol1=occupied_correct_tol1,
        occupied_truth=int(g_occ.sum()),
    )


@dataclass(frozen=True)
class TransformError:
    """How far an estimated transform is from the true one.

    Attributes
    ----------
    translation_m : float
        Distance between the translations (m).
    translation_cells : float
        The same in cells of the given resolution.
    rotation_deg : float
        Absolute rotation difference, wrapped to ``[0, 180]`` (degrees).
    """

    translation_m: float
    translation_cells: float
    rotation_deg: float

    def as_dict(self, digits: int | None = 4) -> dict:
        d, digits = asdict(self), digits_arg(digits)
        return {k: round(v, digits) for k, v in d.items()} if digits is not None else d


def transform_errors(estimated: Transform2D, true: Transform2D, resolution: float) -> TransformError:
    """Translation (m and cells) and rotation (degrees) error of ``estimated`` against ``true``.

    Parameters
    ----------
    estimated, true : Transform2D
        Two transforms between the same pair of frames.
    resolution : float
        Cell size (m) used to express the translation error in cells.
    """
    if not isinstance(resolution, Real) or isinstance(resolution, bool) or not (
            math.isfinite(resolution) and resolution > 0):
        raise InputError(f"resolution must be a positive number of metres, got {resolution!r}")
    dt, dr = estimated.error_to(true)
    return TransformError(float(dt), float(dt / resolution), math.degrees(dr))


def table1(steps, truth: OccupancyGrid,
           transform: Transform2D = Transform2D.identity()) -> list[MapMetrics]:
    """The rows of the paper's Table 1: metrics of ``M1``, ``M1,2``, ... against the truth.

    Parameters
    ----------
    steps : sequence of OccupancyGrid, or a FusedMap
        The fused map after each map was added (``FusedMap.steps``, from ``fuse_maps(...,
        keep_steps=True)`` or a merge result's ``fused``), all in one frame.
    truth : OccupancyGrid
        The ground-truth map.
    transform : Transform2D
        Maps the steps' frame into the truth's frame.
    """
    from .fusion import FusedMap

    if isinstance(steps, FusedMap):
        if not steps.steps:
            raise InputError("this fused map kept no steps: fuse with keep_steps=True for Table 1")
        steps = steps.steps
    if isinstance(steps, OccupancyGrid) or not all(isinstance(s, OccupancyGrid) for s in steps):
        raise InputError("table1 takes the fused map after each step (FusedMap.steps, a list of "
                         "OccupancyGrid); for one map, use evaluate_map")
    return [evaluate_map(s, truth, transform) for s in steps]


@dataclass(frozen=True)
class Table1Row:
    """One row of the paper's Table 1 (percent)."""

    label: str
    completeness: float
    accuracy: float
    precision: float
    efficiency: float


#: The paper's Table 1 ("Fusion results of the 5 maps"), as published.
PAPER_TABLE1: tuple[Table1Row, ...] = (
    Table1Row("M1", 79.55, 68.77, 58.60, 46.51),
    Table1Row("M1,2", 88.94, 77.82, 60.94, 54.06),
    Table1Row("M1,2,3", 89.97, 78.96, 61.59, 55.54),
    Table1Row("M1,2,3,4", 96.87, 85.57, 63.85, 62.29),
    Table1Row("M1,2,3,4,5", 96.91, 86.41, 68.70, 66.67),
)


def table1_label(k: int) -> str:
    """Label of the ``k``-th Table 1 row (0-based): ``M1``, ``M1,2``, ``M1,2,3``, ..."""
    return "M" + ",".join(str(i) for i in range(1, k + 2))


def _cells(m, keys) -> list[str]:
    if m is None:
        return ["" for _ in keys]
    return [format_percent(getattr(m, k)) for k in keys]


def format_table1(rows, paper: bool = True, oracle=None) -> str:
    """Table 1 as text: this map's rows beside the oracle's and the paper's.

    Parameters
    ----------
    rows : sequence of MapMetrics
        One per fusion step (``M1``, ``M1,2``, ...).
    paper : bool
        Add the paper's published values (:data:`PAPER_TABLE1`).
    oracle : sequence of MapMetrics, optional
        The same steps fused with the true transforms (the ceiling a method can reach).

    Returns
    -------
    str
        A fixed-width table; columns in percent; ``Prec1`` is the one-cell-tolerance precision.
    """
    rows = list(rows)
    ours_keys = ("completeness", "accuracy", "precision", "efficiency", "precision_tol1")
    paper_keys = ("completeness", "accuracy", "precision", "efficiency")
    heads = ["Compl", "Acc", "Prec", "Eff", "Prec1"]
    groups = [("fusionkit", rows, ours_keys, heads)]
    if oracle is not None:
        groups.append(("oracle (true transforms)", list(oracle), ours_keys, heads))
    if paper:
        groups.append(("paper Table 1", list(PAPER_TABLE1), paper_keys, heads[:4]))
    n = max(len(g[1]) for g in groups)
    labels = [table1_label(k) for k in range(n)]
    lw = max(len("Maps"), *(len(s) for s in labels)) if labels else len("Maps")
    cw = 7

    def group_width(keys):
        return cw * len(keys)

    top = " " * lw + "".join(" | " + title.center(group_width(keys)) for title, _, keys, _ in groups)
    sub = "Maps".ljust(lw) + "".join(" | " + "".join(h.rjust(cw) for h in hs)
                                     for _, _, _, hs in groups)
    lines = [top.rstrip(), sub, "-" * len(sub)]
    for k in range(n):
        line = labels[k].ljust(lw)
        for _, data, keys, _ in groups:
            m = data[k] if k < len(data) else None
            line += " | " + "".join(c.rjust(cw) for c in _cells(m, keys))
        lines.append(line.rstrip())
    return "\n".join(lines)
