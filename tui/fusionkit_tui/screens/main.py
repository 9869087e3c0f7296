"""The main screen: four tabs (Maps, Settings, Run, Result), the merge worker and the export."""

from __future__ import annotations

from pathlib import Path

from textual import on, work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.reactive import reactive
from textual.screen import Screen
from textual.widgets import DataTable, Footer, Input, TabbedContent, TabPane
from textual.worker import get_current_worker

from fusionkit.errors import FusionkitError, InputError
from fusionkit.pipeline import MergeCancelled, MergeConfig, MergeEvent

from ..messages import MergeFailed, MergeFinished, MergeProgress, MergeStopped
from ..runner import (ExportPaths, describe_error, evaluate_result, export_paths, export_result,
                      protected_files, run_merge, truth_beside)
from ..widgets.map_picker import MapsPane, MapTree
from ..widgets.result_panel import ResultPanel
from ..widgets.run_panel import RunPanel
from ..widgets.settings_form import SettingsForm
from .export import ConfirmScreen, ExportScreen, overwrite_question
from .help import HelpScreen

__all__ = ["MainScreen", "TABS"]

#: Tab ids in key order (keys 1 to 4).
TABS = ("maps", "settings", "run", "result")


class MainScreen(Screen):
    """Pick maps, set parameters, run and watch, inspect, export."""

    DEFAULT_CSS = """
    MainScreen TabbedContent {
        height: 1fr;
    }
    MainScreen TabbedContent > ContentSwitcher {
        height: 1fr;
    }
    MainScreen TabPane {
        padding: 0;
        height: 1fr;
    }
    """

    BINDINGS = [
        Binding("r,ctrl+r", "run", "Run", key_display="r"),
        Binding("escape", "cancel", "Cancel"),
        Binding("e", "export", "Export"),
        Binding("question_mark,f1", "help", "Help", key_display="?"),
        Binding("q", "quit", "Quit"),
        Binding("1", "show_tab('maps')", "Maps", show=False),
        Binding("2", "show_tab('settings')", "Settings", show=False),
        Binding("3", "show_tab('run')", "Run", show=False),
        Binding("4", "show_tab('result')", "Result", show=False),
    ]

    AUTO_FOCUS = "MapTree"

    merging: reactive[bool] = reactive(False, bindings=True)
    """A merge is running (from the run until its worker has stopped)."""

    def __init__(self, root: Path, selected: list[Path]) -> None:
        super().__init__()
        self._root = root
        self._selected = selected
        self.result = None
        self.inputs: list[Path] = []
        self.evaluation = None
        self.exported: ExportPaths | None = None

    def compose(self) -> ComposeResult:
        with TabbedContent(initial="maps"):
            with TabPane("1 Maps", id="maps"):
                yield MapsPane(self._root, self._selected, id="maps-pane")
            with TabPane("2 Settings", id="settings"):
                yield SettingsForm(id="settings-form")
            with TabPane("3 Run", id="run"):
                yield RunPanel(id="run-panel")
            with TabPane("4 Result", id="result"):
                yield ResultPanel(id="result-panel")
        yield Footer()

    # -- parts -----------------------------------------------------------------------------------
    @property
    def maps(self) -> MapsPane:
        return self.query_one(MapsPane)

    @property
    def settings(self) -> SettingsForm:
        return self.query_one(SettingsForm)

    @property
    def run_panel(self) -> RunPanel:
        return self.query_one(RunPanel)

    @property
    def result_panel(self) -> ResultPanel:
        return self.query_one(ResultPanel)

    def check_action(self, action: str, parameters: tuple) -> bool | None:
        if action == "cancel":
            return True if self.merging else None
        if action == "run":
            return None if self.merging else True
        if action == "export":
            return True if self.result is not None and not self.merging else None
        return True

    # -- tabs and help ---------------------------------------------------------------------------
    def action_show_tab(self, tab: str) -> None:
        self.query_one(TabbedContent).active = tab
        self._focus_tab(tab)

    def _focus_tab(self, tab: str) -> None:
        if tab == "maps":
            self.query_one(MapTree).focus()
        elif tab == "settings":
            self.query_one("#set-theta", Input).focus()
        elif tab == "result":
            self.query_one("#placements", DataTable).focus()
        else:
            self.set_focus(None)

    @on(TabbedContent.TabActivated)
    def _on_tab(self, event: TabbedContent.TabActivated) -> None:
        if event.pane.id and (self.focused is None or event.pane not in self.focused.ancestors):
            self._focus_tab(event.pane.id)

    def action_help(self) -> None:
        self.app.push_screen(HelpScreen())

    def action_quit(self) -> None:
        self.app.exit()

    # -- merge -----------------------------------------------------------------------------------
    def action_run(self) -> None:
        if self.merging:
            self.notify("a merge is running; escape cancels it", severity="warning")
            return
        maps = self.maps.selected
        if len(maps) < 2:
            self.notify(f"select at least two maps to merge ({len(maps)} selected): highlight a "
                        f"map and press space, or press a on a directory", severity="error",
                        title="Nothing to merge")
            self.action_show_tab("maps")
            return
        try:
            config = self.settings.config(reference=0)
        except InputError as exc:
            self.notify(str(exc), title="Check the settings", severity="error", timeout=8)
            self.action_show_tab("settings")
            return
        self.merging = True
        self.run_panel.begin(len(maps), config.pso.iterations, config.method)
        self.action_show_tab("run")
        self._merge(list(maps), config)

    @work(thread=True, exclusive=True, group="merge", exit_on_error=False)
    def _merge(self, inputs: list[Path], config: MergeConfig) -> None:
        """Run the merge off the UI thread; talk to the UI only through messages."""
        worker = get_current_worker()

        def callback(ev: MergeEvent) -> bool:
            if worker.is_cancelled:
                return True
            pso = ev.pso
            self.post_message(MergeProgress(ev.stage, ev.step, ev.total, ev.label,
                                            None if pso is None else pso.iteration,
                                            None if pso is None else float(pso.best_cost),
                                            ev.pair))
            return False

        try:
            result = run_merge(inputs, config, callback)
        except MergeCancelled:
            self.post_message(MergeStopped())
            return
        except (FusionkitError, OSError, MemoryError) as exc:
            self.post_message(MergeFailed(describe_error(exc)))
            return
        except Exception as exc:  # a bug must not take the operator's UI down
            self.post_message(MergeFailed(f"the merge failed unexpectedly: {describe_error(exc)}"))
            return
        evaluation, evaluation_error = None, None
        truth = truth_beside(inputs[config.reference])
        if truth is not None and not worker.is_cancelled:
            try:
                evaluation = evaluate_result(result, inputs, truth)
            except (FusionkitError, OSError) as exc:
                evaluation_error = f"no metrics: {describe_error(exc)}"
        if worker.is_cancelled:
            self.post_message(MergeStopped())
            return
        self.post_message(MergeFinished(result, inputs, evaluation, evaluation_error))

    def action_cancel(self) -> None:
        if not self.merging:
            return
        self.workers.cancel_group(self, "merge")
        self.run_panel.stopped("cancelling...")

    @on(MergeProgress)
    def _on_progress(self, msg: MergeProgress) -> None:
        if self.merging:
            self.run_panel.update_progress(msg)

    @on(MergeFinished)
    def _on_finished(self, msg: MergeFinished) -> None:
        self.merging = False
        self.result, self.inputs, self.evaluation = msg.result, list(msg.inputs), msg.evaluation
        self.exported = None
        r = msg.result
        merged = sum(p.merged for p in r.placements)
        summary = f"done: {merged} of {len(r.placements)} maps merged"
        if msg.evaluation is not None:
            summary += f"; completeness {msg.evaluation.metrics.completeness:.1f} %, " \
                       f"precision {msg.evaluation.metrics.precision:.1f} %"
        self.run_panel.finish(summary)
        self.result_panel.show(r, [p.stem for p in msg.inputs], msg.evaluation, msg.evaluation_error)
        seconds = r.seconds.get("total", 0.0)
        self.notify(f"{merged} of {len(r.placements)} maps merged in {seconds:.1f} s; e exports",
                    title="Merge done", severity="information" if r.all_merged else "warning")
        if msg.evaluation_error:
            self.notify(msg.evaluation_error, severity="warning")
        self.action_show_tab("result")

    @on(MergeStopped)
    def _on_stopped(self, msg: MergeStopped) -> None:
        self.merging = False
        kept = " (the previous result is kept)" if self.result is not None else ""
        self.run_panel.stopped(f"cancelled{kept}")
        self.notify(f"merge cancelled{kept}", severity="warning")

    @on(MergeFailed)
    def _on_failed(self, msg: MergeFailed) -> None:
        self.merging = False
        self.run_panel.stopped(f"failed: {msg.error}")
        self.notify(msg.error, title="Merge failed", severity="error", timeout=10)

    # -- export ----------------------------------------------------------------------------------
    def default_export_path(self) -> str:
        """``merged.yaml`` beside the reference map (or the last export)."""
        if self.exported is not None:
            return str(self.exported.yaml)
        base = Path(self.inputs[0]).parent if self.inputs else Path(".")
        return str(base / "merged.yaml")

    def action_export(self) -> None:
        if self.merging:
            self.notify("wait for the merge to finish (or cancel it) before exporting", severity="warning")
            return
        if self.result is None:
            self.notify("nothing to export yet: run a merge first (r)", severity="warning")
            return
        self.app.push_screen(ExportScreen(self.default_export_path(), protected_files(self.inputs)),
                             self._export_to)

    def _export_to(self, path: str | None) -> None:
        if path is None:
            return
        try:
            paths = export_paths(path)
        except InputError as exc:
            self.notify(str(exc), severity="error")
            return
        existing = paths.existing()
        if existing:
            def answered(yes: bool | None) -> None:
                if yes:
                    self.export(path)
                else:
                    self.notify("nothing written", severity="warning")

            self.app.push_screen(ConfirmScreen(overwrite_question(existing)), answered)
        else:
            self.export(path)

    def export(self, path: str) -> ExportPaths | None:
        """Write the result to ``path`` (YAML + PGM + report) now, replacing existing files."""
        try:
            paths = export_result(self.result, [str(p) for p in self.inputs], path)
        except (FusionkitError, OSError) as exc:
            self.notify(describe_error(exc), title="Export failed", severity="error", timeout=10)
            return None
        self.exported = paths
        self.notify(f"map {paths.yaml} (+ {paths.image.name}), report {paths.report}",
                    title="Exported", timeout=8)
        return paths
