"""The merge as it runs: which stage, which pair is being aligned, what is left, and the
live convergence plot."""

from __future__ import annotations

from rich.text import Text
from textual.app import ComposeResult
from textual.containers import Vertical
from textual.widgets import ProgressBar, Static

from ..messages import STAGES, MergeProgress
from .convergence_plot import MONO_MARKERS, ConvergencePlot
from .map_preview import shade, robot_colour

__all__ = ["RunPanel", "overall_fraction"]

# Share of the progress bar per stage (alignment is most of the work).
_WEIGHTS = {"scans": 0.10, "unique_poses": 0.20, "pairing": 0.05, "align": 0.60, "fuse": 0.05}


#: The stages of the other methods (no scans' spectra, no pairing): the pairs placed, the fusion
PLACING_STAGES = (("align", "place pairs"), ("fuse", "fuse"))


def stages_of(method: str) -> tuple:
    """The stages a merge with ``method`` goes through, with the words the panel shows."""
    return STAGES if method == "spectral-pso" else PLACING_STAGES


def overall_fraction(stage: str, step: int, total: int, iteration: int | None = None,
                     iterations: int | None = None, stages=STAGES) -> float:
    """How far a merge is, in [0, 1], from a progress event (``stages``: the merge's own)."""
    names = [s for s, _ in stages]
    if stage == "done":
        return 1.0
    if stage not in names:
        return 0.0
    scale = sum(_WEIGHTS[s] for s in names)
    done = sum(_WEIGHTS[s] for s in names[: names.index(stage)]) / scale
    within = step / total if total > 0 else 0.0
    if stage == "align" and iteration is not None and iterations:
        within = (step + min(1.0, iteration / iterations)) / total if total > 0 else 0.0
    return min(1.0, done + _WEIGHTS[stage] / scale * within)


class RunPanel(Vertical):
    """Progress of the current (or last) merge."""

    DEFAULT_CSS = """
    RunPanel {
        height: 1fr;
        padding: 0 1;
    }
    RunPanel #stages {
        height: 1;
    }
    RunPanel ProgressBar {
        height: 1;
    }
    RunPanel ProgressBar Bar {
        width: 1fr;
    }
    RunPanel #legend {
        height: auto;
        max-height: 2;
    }
    RunPanel #no-swarm {
        height: auto;
        margin-top: 1;
        color: $text-muted;
    }
    RunPanel #detail, RunPanel #left {
        height: 1;
        color: $text-muted;
        text-wrap: nowrap;
        text-overflow: ellipsis;
    }
    RunPanel #detail.stopped {
        /* why a merge failed, whole: what to do is at its end */
        height: auto;
        max-height: 6;
        text-wrap: wrap;
    }
    """

    def __init__(self, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self._stage = ""
        self._iterations = 0
        self._step = -1
        self._phase = 0
        self._last_iteration = -1
        self._where = (0, 0)
        self._stage_list = STAGES

    def compose(self) -> ComposeResult:
        yield Static("", id="stages")
        yield ProgressBar(total=100, show_eta=False, id="bar")
        yield Static("", id="detail")
        yield Static("", id="left")
        yield Static("", id="legend")
        yield ConvergencePlot(id="plot")
        # said instead of an empty plot when the method has no swarm
        yield Static("", id="no-swarm")

    def on_mount(self) -> None:
        self.idle()

    @property
    def plot(self) -> ConvergencePlot:
        return self.query_one(ConvergencePlot)

    @property
    def _swarm(self) -> bool:
        """The merge is the paper's method's: alignments by a swarm, which the plot follows."""
        return self._stage_list is STAGES

    def _stages(self, current: str, step: int = 0, total: int = 0, final: str = "",
                stopped: bool = False) -> Text:
        names = [s for s, _ in self._stage_list]
        text = Text()
        idx = names.index(current) if current in names else (len(names) if current == "done" else -1)
        for k, (name, words) in enumerate(self._stage_list):
            if k:
                text.append("  ")
            if k < idx:
                text.append(f"✓ {words}", style="green")
            elif k == idx:
                more = f" {step + 1}/{total}" if name == "align" and total else ""
                if stopped:  # where the merge was when it was cancelled or failed
                    text.append(f"■ {words}{more} (stopped)", style="bold yellow")
                else:
                    text.append(f"▶ {words}{more}", style="bold")
            else:
                text.append(f"· {words}", style="dim")
        if final:
            text.append(f"   {final}", style="bold")
        return text

    def _legend(self) -> None:
        """One entry per line of the plot, in its colour, on at most two lines: an entry is never
        cut in two, and those that do not fit are counted ("+3 more")."""
        no_color = bool(getattr(self.app, "no_color", False))
        entries = []
        for k, ((label, _, _), colour) in enumerate(zip(self.plot.series, self.plot.colours)):
            if no_color:
                mark = MONO_MARKERS[k % len(MONO_MARKERS)]
                entries.append((f"{'⠒⠒' if mark == 'braille' else mark * 2} ", "", label))
            else:
                entries.append(("━━ ", colour or "", label))
        legend = self.query_one("#legend", Static)
        width = legend.size.width or self.size.width or 80

        def size(line) -> int:   # its marks and labels, two spaces between entries
            return sum(len(mark) + len(label) for mark, _, label in line) + 2 * (len(line) - 1)

        lines: list[list] = [[]]
        for entry in entries:
            if lines[-1] and size(lines[-1] + [entry]) > width:
                lines.append([])
            lines[-1].append(entry)
        if len(lines) > 2:   # two lines, the last ending in how many entries did not fit
            lines = lines[:2]
            left = len(entries) - len(lines[0]) - len(lines[1])
            while len(lines[1]) > 1 and size(lines[1] + [("", "", f"+{left} more")]) > width:
                lines[1].pop()
                left += 1
            lines[1].append(("", "", f"+{left} more"))
        text = Text()
        for i, line in enumerate(lines):
            if i:
                text.append("\n")
            for j, (mark, colour, label) in enumerate(line):
                if j:
                    text.append("  ")
                text.append(mark, style=colour)
                text.append(label)
        legend.update(text)

    def on_resize(self) -> None:
        if self.plot.series:
            self._legend()

    def idle(self) -> None:
        """Before any run."""
        self.query_one("#stages", Static).update(self._stages(""))
        self.query_one(ProgressBar).update(progress=0)
        detail = self.query_one("#detail", Static)
        detail.remove_class("stopped")
        detail.update("not run yet: select two or more maps and press r")
        self.query_one("#left", Static).update("")

    def begin(self, maps: int, iterations: int, method: str = "spectral-pso") -> None:
        """A merge of ``maps`` maps with up to ``iterations`` PSO iterations per alignment starts
        (with ``method``: only the paper's method reports its swarms)."""
        self._iterations = iterations
        self._stage, self._step, self._where = "", -1, (0, 0)
        self._stage_list = stages_of(method)
        if method != "spectral-pso":
            why_none = f"{method}: no swarm to watch (the paper's method, spectral-pso, has one)"
        elif not iterations:
            why_none = ("spectral-pso with 0 PSO iterations (Settings): its swarms do not move, so "
                        "there is no convergence to watch")
        else:
            why_none = ""
        swarm = not why_none
        self.plot.reset(why_none)
        self.plot.display = swarm
        note = self.query_one("#no-swarm", Static)
        note.update(self.plot.note)
        note.display = not swarm
        self._legend()
        self.query_one(ProgressBar).update(progress=0)
        self.query_one("#stages", Static).update(self._stages(self._stage_list[0][0]))
        detail = self.query_one("#detail", Static)
        detail.remove_class("stopped")
        detail.update(f"merging {maps} maps; escape cancels")
        self.query_one("#left", Static).update("")

    def update_progress(self, ev: MergeProgress) -> None:
        """Show one progress event of the worker."""
        if ev.stage == "done":
            return
        self.query_one("#stages", Static).update(self._stages(ev.stage, ev.step, ev.total))
        # never backwards: a refinement swarm restarts its iterations within the same step;
        # but a placing method's count of pairs grows (a fleet's later pairs, a map left out
        # searched again), and the bar follows the count as it is now
        bar = self.query_one(ProgressBar)
        done = 100 * overall_fraction(ev.stage, ev.step, ev.total, ev.iteration, self._iterations,
                                      self._stage_list)
        grew = ev.stage == "align" and self._stage == "align" and ev.total > self._where[1]
        bar.update(progress=done if grew else max(done, bar.progress or 0))
        detail = self.query_one("#detail", Static)
        left = self.query_one("#left", Static)
        if ev.stage == "align":
            colour = robot_colour(ev.pair[1]) if ev.pair else None
            if self._stage != "align" or ev.step != self._step:
                if self.plot.display:   # a swarm to plot: the paper's method's, with iterations
                    self.plot.start(ev.label, colour)
                    self._legend()
                self._step, self._phase, self._last_iteration = ev.step, 0, -1
            if ev.iteration is not None:
                if ev.iteration <= self._last_iteration:
                    # a second swarm of the same alignment (the local refinement): its own line
                    self._phase += 1
                    self.plot.start(f"{ev.label} refine" if self._phase == 1
                                    else f"{ev.label} ({self._phase + 1})",
                                    None if colour is None else shade(colour, 0.55))
                    self._legend()
                self._last_iteration = ev.iteration
                self.plot.add(ev.iteration, ev.best_cost)
                phase = "refining" if self._phase else "aligning"
                detail.update(f"{phase} {ev.label}: iteration {ev.iteration} of at most "
                              f"{self._iterations}, best cost {ev.best_cost:.5g}")
            else:
                detail.update(f"{'aligning' if self._swarm else 'placing'} "
                              f"{ev.label}")
            after = ev.total - ev.step - 1
            if self._swarm:
                left.update(f"alignment {ev.step + 1} of {ev.total}; " +
                            (f"{after} more after this, then fusion" if after > 0 else
                             "fusion after this"))
            else:   # more pairs may be added: loops of a fleet, a map left out searched again
                left.update(f"pair {ev.step + 1} of {ev.total} so far" +
                            (f"; {after} more after this" if after > 0 else ""))
        else:
            what = {"scans": "reading scans", "unique_poses": "finding unique poses (Algorithm 1)",
                    "pairing": "comparing unique poses (eq. 2)", "fuse": "fusing the placed maps"}
            detail.update(f"{what.get(ev.stage, ev.stage)}: {ev.label}")
            left.update(f"{ev.step + 1} of {ev.total}" if ev.total else "")
        self._stage = ev.stage
        self._where = (ev.step, ev.total)

    def finish(self, summary: str) -> None:
        """The merge ended well."""
        self.query_one("#stages", Static).update(self._stages("done", final=""))
        self.query_one(ProgressBar).update(progress=100)
        self.query_one("#detail", Static).update(summary)
        self.query_one("#left", Static).update("press 4 for the result, e to export")

    def stopped(self, why: str, *, ended: bool = True) -> None:
        """The merge was cancelled or failed: say so, keep the plot as it was. ``ended`` False:
        it is being cancelled (until it stops, another run cannot start)."""
        self.query_one("#stages", Static).update(self._stages(self._stage or self._stage_list[0][0],
                                                              *self._where,
                                                              stopped=True))
        detail = self.query_one("#detail", Static)
        detail.add_class("stopped")
        detail.update(Text(why, style="bold"))
        self.query_one("#left", Static).update("press r to run again" if ended else
                                               "r runs again once it has stopped")
