"""The operator's terminal UI of fusionkit: pick robot maps, watch PSO converge, export.

Start it with ``fusionkit tui [DIR or MAP.yaml ...]`` or build it with :func:`make_app`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Sequence

from textual.app import App
from textual.binding import Binding

from .runner import initial_selection
from .screens.main import MainScreen

__all__ = ["FusionkitApp", "make_app"]


class FusionkitApp(App):
    """Fuse a team's maps from a terminal.

    Parameters
    ----------
    root : Path
        Directory the map browser starts in.
    selected : list of Path
        Maps selected at start, reference first.
    """

    TITLE = "fusionkit"
    SUB_TITLE = "multi-robot map fusion"
    CSS_PATH = "app.tcss"
    ENABLE_COMMAND_PALETTE = False
    #: Ctrl-C quits as in every other command (exit status 130), not Textual's hint to press q
    BINDINGS = [("ctrl+q", "quit", "Quit"),
                Binding("ctrl+c", "interrupt", "Quit", show=False, priority=True)]

    def __init__(self, root: Path, selected: Sequence[Path] = ()) -> None:
        super().__init__()
        self._root = Path(root)
        self._selected = [Path(p) for p in selected]
        #: Called (no arguments) after Ctrl-C asked the app to exit while a worker still runs;
        #: ``fusionkit tui`` uses it to end the process without waiting for that worker.
        self.on_interrupt: Callable[[], None] | None = None

    def action_interrupt(self) -> None:
        """Quit at once, a running merge with it, with the exit status of an interrupt."""
        self.exit(return_code=130)
        if self.on_interrupt is not None and any(w.is_running for w in self.workers):
            self.on_interrupt()

    def get_default_screen(self) -> MainScreen:
        return MainScreen(self._root, self._selected)

    @property
    def main(self) -> MainScreen:
        """The main screen (also while a dialog is open above it)."""
        return next(s for s in self.screen_stack if isinstance(s, MainScreen))


def make_app(paths: Sequence = ()) -> FusionkitApp:
    """The app for the command-line arguments ``paths``.

    No path: browse the current directory. One directory (a simulated run, say): browse it with
    its robot maps selected. Map YAML files: those maps selected, browsing their directory.

    Raises
    ------
    InputError
        A path that does not exist or is neither a directory nor a map YAML.
    """
    root, selected = initial_selection(paths)
    return FusionkitApp(root, selected)
