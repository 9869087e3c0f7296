"""The main screen: four tabs (Maps, Settings, Run, Result), the merge worker and the export."""

from __future__ import annotations

import time
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
                      map_labels, output_guard, run_merge, truth_beside)
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
        Binding("r", "run", "Run"),
        # ctrl+r runs from anywhere, also while a setting is typed (the form shows it then)
        Binding("ctrl+r", "run_anywhere", "Run", show=False),
        Binding("escape", "cancel", "Cancel"),
        Binding("e", "export", "Export"),
        Binding("m", "map_view", "Map"),
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
        #: The names the result shows for its inputs (shortest unique ends of their paths).
        self.labels: list[str] = []
        self._said_unreadable: set = set()   # the unreadable maps the last warning named
        #: When the last run did not end well: why ("cancelled", "failed"), so that the result
        #: still held is known to be an earlier one.
        self.last_run_outcome: str | None = None
        self.result_time: str = ""
        #: The maps chosen (the reference first) when the result's run started, and when the
        #: running one did: a result of other maps than those chosen now is said to be earlier.
        self.result_selection: list[Path] = []
        self._running_selection: list[Path] = []

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

    def _typing(self) -> bool:
        """A text field has the keyboard (printable keys type into it)."""
        return isinstance(self.focused, Input)

    def check_action(self, action: str, parameters: tuple) -> bool | None:
        typing = self._typing()
        if action == "cancel":
            return True if self.merging else False  # shown only while there is a run to cancel
        if action == "run":
            # while a field is typed into, r is a letter: the footer offers ctrl+r instead
            return False if typing else None if self.merging else True
        if action == "run_anywhere":
            return None if self.merging else True
        if action in ("quit", "map_view", "export") and typing:
            return False  # the key types into the field
        if action == "export":
            return True if self.result is not None and not self.merging else None
        return True

    def on_key(self, event) -> None:
        # a key the footer shows dimmed does not run its action: say why instead of nothing
        if self._typing():
            return
        if event.key == "e" and self.check_action("export", ()) is None:
            event.stop()
            self.action_export()
        elif event.key in ("r", "ctrl+r") and self.merging:
            event.stop()
            self.action_run()

    def on_descendant_focus(self, event) -> None:
        self.refresh_bindings()

    def on_descendant_blur(self, event) -> None:
        self.refresh_bindings()

    # -- tabs and help ---------------------------------------------------------------------------
    def action_show_tab(self, tab: str) -> None:
        self.query_one(TabbedContent).active = tab
        self._focus_tab(tab)

    def _focus_tab(self, tab: str) -> None:
        if tab == "maps":
            self.query_one(MapTree).focus()
        elif tab == "settings":
            # the form, not a field: keys stay the app's until a field is clicked or tabbed into
            self.settings.focus()
        elif tab == "result":
            self.query_one("#placements", DataTable).focus()
        else:
            self.set_focus(None)

    def on_screen_suspend(self) -> None:
        # a dialog opens: what was shown comes back when it closes (the first focusable widget,
        # the map tree, focused when nothing else was, as on the Run tab, showed the Maps tab)
        self._before_dialog = (self.query_one(TabbedContent).active, self.focused)
        self.AUTO_FOCUS = None

    def on_screen_resume(self) -> None:
        before = getattr(self, "_before_dialog", None)
        if before is not None:
            self.call_after_refresh(self._back_to, *before)

    def _back_to(self, tab: str, widget) -> None:
        tabs = self.query_one(TabbedContent)
        if tabs.active != tab:
            tabs.active = tab
        if widget is not None and widget.is_attached and tabs.get_pane(tab) in widget.ancestors:
            widget.focus()
        else:
            self._focus_tab(tab)

    @on(TabbedContent.TabActivated)
    def _on_tab(self, event: TabbedContent.TabActivated) -> None:
        if event.pane.id and (self.focused is None or event.pane not in self.focused.ancestors):
            self._focus_tab(event.pane.id)

    def action_help(self) -> None:
        self.app.push_screen(HelpScreen())

    def action_quit(self) -> None:
        self.app.exit()

    def action_map_view(self) -> None:
        """The fused map on the whole screen (on the Maps tab: the map being previewed)."""
        from .map_view import MapScreen

        tab = self.query_one(TabbedContent).active
        if tab == "maps" or self.result is None:
            preview = self.maps.query_one("#preview")
            if preview.grid is None:
                self.notify("no map to show: highlight a map, or run a merge", severity="warning")
                return
            title = self.maps.previewing_label()
            self.app.push_screen(MapScreen(preview.grid, title, legend=self.result_panel.plain_legend()))
            return
        self.app.push_screen(MapScreen(self.result.grid, self.result_panel.title(),
                                       self.result_panel.owner(), self.result_panel.legend()))

    # -- merge -----------------------------------------------------------------------------------
    def action_run_anywhere(self) -> None:
        self.action_run()

    def action_run(self) -> None:
        if self.merging:
            self.notify("a merge is running; escape cancels it", severity="warning")
            return
        maps = self.maps.usable()
        bad = self.maps.unreadable
        said, self._said_unreadable = self._said_unreadable, set(bad)
        if bad and set(bad) != said:   # said once for the same maps, not at every r
            self.notify("; ".join(f"{why}" for why in list(bad.values())[:2])
                        + ("; ..." if len(bad) > 2 else ""),
                        title=f"{len(bad)} unreadable map{'s' if len(bad) > 1 else ''} left out",
                        severity="warning", timeout=8)
        if len(maps) < 2:
            self.notify(f"select at least two readable maps to merge ({len(maps)} selected): "
                        f"highlight a map and press space, or press a on a directory", severity="error",
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
        self._running_selection = list(maps)   # the readable maps chosen, reference first
        if self.result is not None:   # the Result tab keeps the last merge meanwhile: said so
            self.result_panel.mark_earlier(f"a merge is running; this is the merge of "
                                           f"{self.result_time}", running=True)
        self.run_panel.begin(len(maps), config.pso.iterations, config.method)
        self.action_show_tab("run")
        # named as the Maps tab names them: among every chosen map, the unreadable ones too
        every = self.maps.selected
        named = dict(zip(every, map_labels(every)))
        self._merge(list(maps), config, [named.get(p, n) for p, n in zip(maps, map_labels(maps))])

    @work(thread=True, exclusive=True, group="merge", exit_on_error=False)
    def _merge(self, inputs: list[Path], config: MergeConfig, labels: list[str]) -> None:
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
            result = run_merge(inputs, config, callback, labels)
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
        self.post_message(MergeFinished(result, inputs, evaluation, evaluation_error, labels))

    def action_cancel(self) -> None:
        if not self.merging:
            return
        self.workers.cancel_group(self, "merge")
        self.run_panel.stopped("cancelling...", ended=False)

    @on(MergeProgress)
    def _on_progress(self, msg: MergeProgress) -> None:
        if self.merging:
            self.run_panel.update_progress(msg)

    @on(MergeFinished)
    def _on_finished(self, msg: MergeFinished) -> None:
        self.merging = False
        self.result, self.inputs, self.evaluation = msg.result, list(msg.inputs), msg.evaluation
        self.labels = list(msg.labels) if msg.labels else map_labels(msg.inputs)
        self.exported = None
        self.last_run_outcome = None
        self.result_time = time.strftime("%H:%M:%S")
        self.result_selection = self._running_selection
        r = msg.result
        merged = sum(p.merged for p in r.placements)
        summary = f"done: {merged} of {len(r.placements)} maps merged"
        if msg.evaluation is not None:
            summary += f"; completeness {msg.evaluation.metrics.completeness:.1f} %, " \
                       f"precision {msg.evaluation.metrics.precision:.1f} %"
        self.run_panel.finish(summary)
        self.result_panel.show(r, self.labels, msg.evaluation, msg.evaluation_error)
        if self._selection_changed():   # changed while it ran
            self.result_panel.mark_earlier(f"the maps chosen have changed since this merge "
                                           f"started; it is the merge of those chosen then")
        seconds = r.seconds.get("total", 0.0)
        self.notify(f"{merged} of {len(r.placements)} maps merged in {seconds:.1f} s; e exports",
                    title="Merge done", severity="information" if r.all_merged else "warning")
        if msg.evaluation_error:
            self.notify(msg.evaluation_error, severity="warning")
        self.action_show_tab("result")

    def _earlier(self) -> str:
        """Words for the result still held after a run that did not end well."""
        if self.result is None:
            return ""
        return f" (the result of the earlier merge at {self.result_time} is kept)"

    def _selection_changed(self) -> bool:
        """Whether the readable maps chosen now (reference first) are not those of the result."""
        if self.result is None:
            return False
        bad = self.maps.unreadable   # as a merge leaves them out
        return [p for p in self.maps.selected if p not in bad] != self.result_selection

    @on(MapsPane.Changed)
    def _on_selection(self, msg: MapsPane.Changed) -> None:
        # the Result tab shows the merge of the maps chosen then: said when they are no longer
        # those chosen (another reference, a map added or taken away)
        if self.merging or self.result is None or self.last_run_outcome is not None:
            return
        if self._selection_changed():
            self.result_panel.mark_earlier(f"the maps chosen have changed since this merge of "
                                           f"{self.result_time}")
        else:
            self.result_panel.clear_earlier()

    @on(MergeStopped)
    def _on_stopped(self, msg: MergeStopped) -> None:
        # said on the run panel only: a toast would cover the plot's axis
        self.merging = False
        self.run_panel.stopped(f"cancelled{self._earlier()}")
        if self.result is not None:
            self.last_run_outcome = "was cancelled"
            self.result_panel.mark_earlier(f"the last run was cancelled; this is the merge of "
                                           f"{self.result_time}")

    @on(MergeFailed)
    def _on_failed(self, msg: MergeFailed) -> None:
        self.merging = False
        self.run_panel.stopped(f"failed: {msg.error}")
        self.notify(msg.error + self._earlier(), title="Merge failed", severity="error", timeout=10)
        if self.result is not None:
            self.last_run_outcome = "failed"
            self.result_panel.mark_earlier(f"the last run failed; this is the merge of "
                                           f"{self.result_time}")

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
        self.app.push_screen(ExportScreen(self.default_export_path(), output_guard(self.inputs),
                                          note=self._export_note(), groups=len(self.result.groups)),
                             self._export_to)

    def _export_note(self) -> str:
        """What the export dialog says of the result it writes when it is not the merge of the
        maps chosen now ("" when it is)."""
        merged = sum(p.merged for p in self.result.placements)
        if self.last_run_outcome is not None:
            return (f"The last run {self.last_run_outcome}: this exports the EARLIER result, the "
                    f"merge of {self.result_time} ({merged} of {len(self.result.placements)} maps "
                    f"merged).")
        if self._selection_changed():
            return (f"The maps chosen have changed since the merge of {self.result_time}: this "
                    f"exports that merge ({merged} of {len(self.result.placements)} maps merged); "
                    f"escape, then r, merges the maps chosen now.")
        return ""

    def _export_to(self, path: str | None) -> None:
        if path is None:
            return
        try:
            paths = export_paths(path, len(self.result.groups))
        except InputError as exc:
            self.notify(str(exc), severity="error")
            return
        existing = paths.existing()
        if existing:
            def answered(yes: bool | None) -> None:
                if yes:
                    self.export(path)
                    return
                # kept: the dialog again with the path, for another name (escape leaves), so
                # that the keys typed next edit the path rather than run commands
                self.app.push_screen(ExportScreen(path, output_guard(self.inputs), note=self._export_note(),
                                                  groups=len(self.result.groups),
                                                  until_edit="Those files are kept: change the path, or "
                                                             "escape to write nothing."),
                                     self._export_to)

            self.app.push_screen(ConfirmScreen(overwrite_question(existing)), answered)
        else:
            self.export(path)

    def export(self, path: str) -> ExportPaths | None:
        """Write the result to ``path`` (YAML + PGM + report) now, replacing existing files."""
        try:
            paths = export_result(self.result, [str(p) for p in self.inputs], path)
        except (FusionkitError, OSError) as exc:
            why = describe_error(exc)
            self.notify(why, title="Export failed", severity="error", timeout=10)
            # the dialog again, with the path typed, so that a key pressed next edits it rather
            # than being taken as a command of the main screen
            self.app.push_screen(ExportScreen(path, output_guard(self.inputs), note=self._export_note(),
                                              until_edit=f"Export failed: {why}. Change the path, or "
                                                         f"escape.", groups=len(self.result.groups)),
                                 self._export_to)
            return None
        self.exported = paths
        groups = (f", group maps {', '.join(g.name for g in paths.groups)}" if paths.groups else "")
        self.notify(f"map {paths.yaml} (+ {paths.image.name}){groups}, report {paths.report}",
                    title="Exported", timeout=8)
        return paths
