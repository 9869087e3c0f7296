"""The help screen: every key of the app, grouped by where it applies."""

from __future__ import annotations

from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import VerticalScroll
from textual.screen import ModalScreen
from textual.widgets import Label, Static

__all__ = ["HelpScreen", "KEYS"]

#: Every key of the app, by where it applies: (keys, what it does).
KEYS = (
    ("Everywhere", (
        ("1 2 3 4", "show the Maps, Settings, Run or Result tab"),
        ("r  ctrl+r", "run the merge (ctrl+r also while typing a setting)"),
        ("escape", "cancel the running merge"),
        ("e", "export the merged map (YAML + PGM) and the report"),
        ("m", "the fused (on Maps: previewed) map, full screen"),
        ("? f1", "this help"),
        ("tab shift+tab", "move between the parts of a tab"),
        ("q  ctrl+q", "quit (a running merge is cancelled)"),
        ("ctrl+c", "quit the same way, with exit status 130"),
    )),
    ("Maps: directory tree", (
        ("up down", "move; a highlighted map is previewed"),
        ("enter space", "select / unselect a map; open / close a directory"),
        ("a", "add every robot map of the directory"),
        ("u backspace", "go up to the parent directory"),
    )),
    ("Maps: selected maps", (
        ("delete x", "remove the map from the selection"),
        ("f", "make it the reference (the merged frame)"),
    )),
    ("Settings", (
        ("tab shift+tab", "into a field and between fields (or click one)"),
        ("escape enter", "leave the field (its value is checked)"),
    )),
    ("Result", (
        ("up down", "pick a map: why it was merged or not"),
        ("v", "fused map in robot colours / plain states"),
    )),
)


class HelpScreen(ModalScreen[None]):
    """The keys, grouped by where they apply."""

    DEFAULT_CSS = """
    HelpScreen {
        align: center middle;
    }
    HelpScreen > VerticalScroll {
        width: 76;
        max-width: 100%;
        height: auto;
        max-height: 100%;
        border: round $accent;
        background: $panel;
        padding: 0 1;
    }
    HelpScreen #help-title {
        text-style: bold;
        width: 100%;
        content-align: center middle;
    }
    """

    BINDINGS = [Binding("escape,question_mark,f1,q,enter", "close", "Close")]

    def compose(self) -> ComposeResult:
        text = Text()
        for g, (group, keys) in enumerate(KEYS):
            if g:
                text.append("\n")
            text.append(f"{group}\n", style="bold underline")
            for k, what in keys:
                text.append(f"  {k:<15}", style="bold")
                text.append(f"{what}\n")
        with VerticalScroll():
            yield Label("fusionkit: keys (escape closes)", id="help-title")
            text.rstrip()
            yield Static(text)
            yield Static(Text("The mouse works too: click tabs, maps and buttons. "
                              "escape closes this help.", style="dim"))

    def action_close(self) -> None:
        self.dismiss(None)
