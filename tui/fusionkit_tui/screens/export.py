"""Exporting the merged map: the path dialog and the overwrite confirmation."""

from __future__ import annotations

import os
from pathlib import Path

from textual import on
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.screen import ModalScreen
from textual.widgets import Button, Input, Static

from fusionkit._atomic import check_writable
from fusionkit.errors import InputError

from ..runner import export_paths

__all__ = ["ExportScreen", "ConfirmScreen", "overwrite_question"]


class ExportScreen(ModalScreen[str | None]):
    """Ask for the map YAML to write; dismisses with the typed path, or None when cancelled.

    ``guard`` (:func:`..runner.output_guard`) holds the files the export must not replace
    (the input maps, images and scans, the ground truth of their run): a path that would is
    refused in the dialog, as is a directory that does not exist or a target that is a folder.
    ``groups`` is the number of group maps the result has, written beside the map. ``note``
    stays; ``until_edit`` (why the path given was not written) goes once the path is changed.
    """

    DEFAULT_CSS = """
    ExportScreen {
        align: center middle;
    }
    ExportScreen > Vertical {
        width: 72;
        max-width: 100%;
        height: auto;
        border: round $accent;
        background: $panel;
        padding: 0 1;
    }
    ExportScreen Input {
        margin: 1 0 0 0;
    }
    ExportScreen #export-files {
        color: $text-muted;
        height: auto;
    }
    ExportScreen #export-note {
        color: $text-warning;
        text-style: bold;
        height: auto;
        margin-top: 1;
    }
    ExportScreen #export-until-edit {
        color: $text-error;
        height: auto;
        margin-top: 1;
    }
    ExportScreen #export-error {
        color: $text-error;
        height: auto;
    }
    ExportScreen Horizontal {
        height: auto;
        align-horizontal: right;
    }
    ExportScreen Button {
        margin-left: 1;
    }
    """

    BINDINGS = [Binding("escape", "cancel", "Cancel")]

    def __init__(self, default: str, guard=None, note: str = "", groups: int = 0,
                 until_edit: str = "") -> None:
        super().__init__()
        self._default = default
        self._guard = guard
        self._note = note
        self._groups = groups
        self._until_edit = until_edit

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Static("Export the merged map (ROS map_server YAML + PGM) and the merge report",
                         id="export-title")
            if self._until_edit:
                yield Static(self._until_edit, id="export-until-edit")
            if self._note:
                yield Static(self._note, id="export-note")
            yield Input(self._default, id="export-path", placeholder="path/to/merged.yaml")
            yield Static("", id="export-files")
            yield Static("", id="export-error")
            with Horizontal():
                yield Button("Save", id="save", variant="primary")
                yield Button("Cancel", id="cancel")

    def on_mount(self) -> None:
        self._describe(self._default)
        inp = self.query_one(Input)
        inp.focus()
        inp.cursor_position = len(inp.value)

    def _describe(self, text: str) -> bool:
        files = self.query_one("#export-files", Static)
        error = self.query_one("#export-error", Static)
        try:
            p = export_paths(text, self._groups)
        except InputError as exc:
            files.update("")
            error.update(str(exc))
            return False
        where = p.yaml.parent
        names = [p.yaml.name, p.image.name, p.report.name]
        if p.groups:
            names.insert(2, f"the map of each group ({', '.join(g.name for g in p.groups)})")
        files.update(f"writes {', '.join(names[:-1])} and {names[-1]} in {where}; enter saves, "
                     f"escape cancels")
        if not where.is_dir():
            # a path through a file ("robot_1.pgm/x.yaml") names no folder that can be made
            through = next((q for q in [where, *where.parents] if q.exists() and not q.is_dir()), None)
            error.update(f"{through} is a file, not a folder; choose another path" if through else
                         f"the directory {where} does not exist; create it or choose another")
            return False
        if not os.access(where, os.W_OK | os.X_OK):
            error.update(f"the directory {where} is not writable; choose another")
            return False
        try:
            check_writable(p.all)   # a target that is a folder: refused here, not after "overwrite?"
            if self._guard is not None:
                self._guard.check(p.all)
        except InputError as exc:
            error.update(str(exc))
            return False
        error.update("")
        return True

    @on(Input.Changed)
    def _on_changed(self, event: Input.Changed) -> None:
        if self._until_edit and event.value != self._default:
            self._until_edit = ""          # said of the path given, not of the one typed now
            self.query_one("#export-until-edit", Static).remove()
        self._describe(event.value)

    @on(Input.Submitted)
    @on(Button.Pressed, "#save")
    def _save(self) -> None:
        text = self.query_one(Input).value
        if self._describe(text):
            self.dismiss(text.strip())

    @on(Button.Pressed, "#cancel")
    def action_cancel(self) -> None:
        self.dismiss(None)


class ConfirmScreen(ModalScreen[bool]):
    """A yes / no question; dismisses with True for yes."""

    DEFAULT_CSS = """
    ConfirmScreen {
        align: center middle;
    }
    ConfirmScreen > Vertical {
        width: 64;
        max-width: 100%;
        height: auto;
        border: round $warning;
        background: $panel;
        padding: 0 1;
    }
    ConfirmScreen #question {
        height: auto;
        margin-bottom: 1;
    }
    ConfirmScreen Horizontal {
        height: auto;
        align-horizontal: right;
    }
    ConfirmScreen Button {
        margin-left: 1;
    }
    """

    BINDINGS = [
        Binding("y", "answer(True)", "Yes"),
        Binding("n,escape", "answer(False)", "No"),
    ]

    def __init__(self, question: str) -> None:
        super().__init__()
        self._question = question

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Static(self._question, id="question")
            with Horizontal():
                yield Button("Overwrite (y)", id="yes", variant="warning")
                yield Button("Keep them (n)", id="no")

    def on_mount(self) -> None:
        self.query_one("#no", Button).focus()

    @on(Button.Pressed)
    def _pressed(self, event: Button.Pressed) -> None:
        self.dismiss(event.button.id == "yes")

    def action_answer(self, yes: bool) -> None:
        self.dismiss(yes)


def overwrite_question(existing: list[Path]) -> str:
    """The confirmation text for replacing ``existing`` files."""
    names = "\n".join(f"  {p}" for p in existing)
    return f"These files exist and will be replaced:\n{names}\nOverwrite them?"
