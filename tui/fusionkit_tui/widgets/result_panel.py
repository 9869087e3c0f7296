"""The merge result: the fused map coloured by contributing robot, each map's placement, and
the paper's Table 1 metrics when the ground truth is known."""

from __future__ import annotations

import math

from rich.text import Text
from textual import on
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.widgets import DataTable, Label, Static

from fusionkit.labels import clip_left
from fusionkit.metrics import table1_label

from .map_preview import MapPreview, robot_colour

__all__ = ["ResultPanel"]


def merged_because(p, method: str) -> str:
    """Why a merged map was taken, in the terms of the method that placed it."""
    if method == "spectral-pso":
        if p.overlap_cells > 0:
            return (f"{100 * p.confidence:.0f}% of {p.overlap_cells} overlapping wall cells agree "
                    "with the maps fused before it")
        return "the first map of the fusion order (the reference was aligned to it)"
    if method == "consensus":
        return (f"confidence {p.confidence:.2f}: the chance that no wrong placement of these maps "
                "fits as well")
    return f"confidence {p.confidence:.2f} by the consensus test (one 0-1 scale for every method)"


#: Widest map name in the metrics table at 80 columns: the panel's 40 columns less four
#: numbers' columns (28)
_METRICS_LABEL = 12
_METRICS_NUMBERS = 28


def metrics_label_width(names, screen_width: int) -> int:
    """The width of the metrics table's first column: the longest name's ("+ " and all), on a
    screen wider than 80 columns taking up to half the columns over 80 (at most 30), so that
    names told apart by their folders (``demo/robot_1``, ``default/robot_1``) are not cut to
    ``…o/robot_1`` and ``…t/robot_1``."""
    needed = max((len(n) + 2 for n in names), default=0)
    room = _METRICS_LABEL + max(0, screen_width - 80) // 2
    return max(_METRICS_LABEL, min(needed, room, 30))


class ResultPanel(Vertical):
    """Shows a :class:`~fusionkit.pipeline.MergeResult` (and its evaluation, if any)."""

    DEFAULT_CSS = """
    ResultPanel {
        height: 1fr;
        padding: 0 1;
    }
    ResultPanel #bottom {
        height: 1fr;
    }
    ResultPanel #fused {
        width: 1fr;
    }
    ResultPanel #scores {
        width: 40;
        padding-left: 1;
    }
    ResultPanel .heading {
        color: $text-accent;
        text-style: bold;
        width: 1fr;
    }
    ResultPanel #legend, ResultPanel #why, ResultPanel #no-metrics {
        height: auto;
        color: $text-muted;
    }
    ResultPanel DataTable {
        height: auto;
        max-height: 8;
        background: $surface;
    }
    """

    BINDINGS = [Binding("v", "toggle_view", "Colours")]

    def __init__(self, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self._result = None
        self._names: list[str] = []
        self._by_robot = True
        #: why the result shown is an earlier one (None when it is not): said under the table
        #: and as " (earlier run)" in the heading
        self._earlier_why: Text | None = None

    def compose(self) -> ComposeResult:
        yield Label("Maps: transform into the reference frame", classes="heading")
        yield DataTable(id="placements", cursor_type="row")
        yield Static("", id="why")
        with Horizontal(id="bottom"):
            with Vertical(id="fused"):
                yield Label("Fused map", id="fused-heading", classes="heading")
                yield MapPreview(id="fused-map")
                yield Static("", id="legend")
            with Vertical(id="scores"):
                yield Label("Table 1 metrics (%)", id="metrics-heading", classes="heading")
                yield DataTable(id="metrics", cursor_type="none")
                yield Static("", id="no-metrics")

    def on_mount(self) -> None:
        self.query_one("#fused-map", MapPreview).clear("no merge yet: press r to run")
        self.query_one("#metrics").display = False
        # said under the first heading too: the map's own words need room to show
        self.query_one("#why", Static).update("no merge yet: choose two or more maps (1 Maps) "
                                              "and press r to run")

    @property
    def result(self):
        return self._result

    def show(self, result, names: list[str], evaluation=None, evaluation_error: str | None = None) -> None:
        """Show ``result``; ``names`` are the input maps' names in input order (the shortest
        unique ends of their paths)."""
        self._result, self._names = result, list(names)
        self._earlier_why = None
        self._draw_map()
        table = self.query_one("#placements", DataTable)
        table.clear(columns=True)
        cols = ["map", "merged", "conf", "x (m)", "y (m)", "θ (°)"]
        if evaluation is not None:
            cols += ["error (m)", "error (°)"]
        table.add_columns(*cols)
        for p in result.placements:
            name = Text(self._names[p.index], style=robot_colour(p.index) if p.merged else "dim")
            if p.transform is None:
                # a map of another group is placed, in its group's map (exported beside)
                merged = f"group {p.group}" if p.group else "no"
                row = [name, merged, f"{p.confidence:.2f}", "-", "-", "-"]
            else:
                t = p.transform
                row = [name, "yes", f"{p.confidence:.2f}", f"{t.x:.2f}", f"{t.y:.2f}",
                       f"{math.degrees(t.theta):.1f}"]
            if evaluation is not None:
                e = evaluation.errors[p.index]
                row += (["-", "-"] if e is None else [f"{e.translation_m:.2f}", f"{e.rotation_deg:.1f}"])
            table.add_row(*row, key=str(p.index))
        self._explain(0)
        metrics = self.query_one("#metrics", DataTable)
        note = self.query_one("#no-metrics", Static)
        metrics.clear(columns=True)
        if evaluation is None:
            metrics.display = False
            note.update(evaluation_error or "no truth.json beside the maps: no ground truth to score against")
            return
        metrics.display = True
        note.update(f"against {evaluation.truth}, in the frame of its {evaluation.reference}")
        metrics.add_columns("maps", "compl", "acc", "prec", "eff")
        order = list(result.fused.order)  # the maps in the fused map, in the order they were added
        width = metrics_label_width([self._names[i] for i in order], self.app.size.width)
        self.query_one("#scores").styles.width = width + _METRICS_NUMBERS
        for k, m in enumerate(evaluation.steps):
            # row k is the fused map after the (k+1)-th map of the fusion order was added
            # the end of a long name (the map's own), so that the four columns fit the panel
            label = (clip_left(self._names[order[k]], width) if k == 0 else
                     "+ " + clip_left(self._names[order[k]], width - 2)) \
                if k < len(order) else clip_left(table1_label(k), width)
            metrics.add_row(label, f"{m.completeness:.1f}",
                            f"{m.accuracy:.1f}",
                            f"{m.precision:.1f}", f"{m.efficiency:.1f}")

    def owner(self):
        """Per cell of the fused map, the input that gave it (None in the plain view)."""
        return self._result.fused.owner if self._result is not None and self._by_robot else None

    def plain_legend(self) -> Text:
        """What the states look like in a plain map."""
        return Text("█ wall  ░ free  (blank) unknown" if getattr(self.app, "no_color", False)
                    else "white wall, blue free, black unknown")

    def legend(self, width: int | None = None) -> Text:
        """The fused map's legend: each merged map's colour, or the states. With ``width``, in
        lines of at most that many columns, an entry never cut in two (a colour ended one line
        and its name began the next)."""
        if self._result is None or not self._by_robot or getattr(self.app, "no_color", False):
            return self.plain_legend()
        legend = Text()
        used = 0
        for p in self._result.placements:
            if not p.merged:
                continue
            name = self._names[p.index]
            size = 2 + len(name)
            if used and width and used + 2 + size > width:
                legend.append("\n")
                used = 0
            elif used:
                legend.append("  ")
                used += 2
            legend.append("█ ", style=robot_colour(p.index))
            legend.append(name)
            used += size
        return legend

    def on_resize(self) -> None:
        if self._result is not None:
            self._show_legend()

    def _show_legend(self) -> None:
        shown = self.query_one("#legend", Static)
        shown.update(self.legend(shown.size.width or self.size.width or None))

    def title(self) -> str:
        """The fused map's heading."""
        r = self._result
        merged = sum(p.merged for p in r.placements)
        return (f"Fused map ({r.config.method}): {merged} of {len(r.placements)} maps, "
                f"{r.grid.cols}x{r.grid.rows} cells"
                f"{' (earlier run)' if self._earlier_why is not None else ''}")

    def mark_earlier(self, why: str, *, running: bool = False) -> None:
        """Say that the result shown is an earlier one: the last run was cancelled or failed,
        or (``running``) one is running."""
        if self._result is None:
            return
        hint = "" if running else "; e exports it, r runs again"
        # kept over the rows' explanations (a row highlighted as the table fills came after it)
        self._earlier_why = Text(why + hint, style="bold yellow")
        self.query_one("#why", Static).update(self._earlier_why)
        self._draw_map()

    def clear_earlier(self) -> None:
        """Take back :meth:`mark_earlier`: the result shown is that of the maps chosen."""
        if self._result is None or self._earlier_why is None:
            return
        self._earlier_why = None
        self._explain(self.query_one("#placements", DataTable).cursor_row)
        self._draw_map()

    def _draw_map(self) -> None:
        if self._result is None:
            return
        r = self._result
        preview = self.query_one("#fused-map", MapPreview)
        preview.show(r.grid, self.owner())
        self._show_legend()
        self.query_one("#fused-heading", Label).update(self.title())

    def _explain(self, row: int) -> None:
        why = self.query_one("#why", Static)
        if self._earlier_why is not None:
            why.update(self._earlier_why)
            return
        if self._result is None or not 0 <= row < len(self._result.placements):
            why.update("")
            return
        p = self._result.placements[row]
        name = self._names[p.index]
        if p.index == self._result.config.reference:
            why.update(f"{name}: the reference; the merged map is in its frame")
        elif p.merged:
            why.update(f"{name}: merged, {merged_because(p, self._result.config.method)}")
        else:
            why.update(Text(f"{name}: not merged: {p.reason}", style="yellow"))

    @on(DataTable.RowHighlighted, "#placements")
    def _on_row(self, event: DataTable.RowHighlighted) -> None:
        self._explain(event.cursor_row)

    def action_toggle_view(self) -> None:
        """Switch the fused map between robot colours and plain states."""
        # said, not silently nothing
        if self._result is None:
            self.notify("no merged map yet: press r to merge the maps", severity="warning")
            return
        if getattr(self.app, "no_color", False):
            self.notify("without colour (NO_COLOR) the fused map shows its states only",
                        severity="warning")
            return
        self._by_robot = not self._by_robot
        self._draw_map()
