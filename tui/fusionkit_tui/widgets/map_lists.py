"""The two lists of the Maps tab: the directory tree of map files and the chosen maps."""

from __future__ import annotations

from pathlib import Path

from rich.text import Text
from textual.binding import Binding
from textual.message import Message
from textual.widgets import DataTable, DirectoryTree

from fusionkit._atomic import recover_folder

from ..runner import is_map_file

__all__ = ["MapTree", "SelectedMaps"]


class MapTree(DirectoryTree):
    """A directory tree that lists only directories and map YAML files, marking chosen maps."""

    DEFAULT_CSS = """
    MapTree {
        height: 1fr;
        background: $surface;
    }
    """

    BINDINGS = [
        Binding("space", "toggle_map", "Select"),
        Binding("a", "add_directory", "Add dir"),
        Binding("u,backspace", "parent", "Up dir"),
    ]

    class Toggle(Message):
        """Select or unselect the map at ``path``."""

        def __init__(self, path: Path) -> None:
            super().__init__()
            self.path = path

    class AddDirectory(Message):
        """Add every robot map of the directory ``path``."""

        def __init__(self, path: Path) -> None:
            super().__init__()
            self.path = path

    def __init__(self, path, *, id: str | None = None) -> None:
        super().__init__(path, id=id)
        self.chosen: set[Path] = set()
        #: Maps found unreadable (resolved path -> why): marked with a cross.
        self.unreadable: dict[Path, str] = {}

    def filter_paths(self, paths: Iterable[Path]) -> Iterable[Path]:
        paths = list(paths)
        if paths and recover_folder(paths[0].parent, wait=False):
            # a write a kill cut short there was finished or undone: list what is there now
            paths = list(paths[0].parent.iterdir())
        return [p for p in paths
                if not p.name.startswith(".") and (self._safe_is_dir(p) or is_map_file(p))]

    def render_label(self, node, base_style, style) -> Text:
        text = super().render_label(node, base_style, style)
        entry = node.data
        if entry is not None and not node.allow_expand:
            where = entry.path.resolve()
            if where in self.unreadable:
                text = Text.assemble(("✗ ", "bold red"), text)
            else:
                mark = "✓ " if where in self.chosen else "  "
                text = Text.assemble((mark, "bold"), text)
        return text

    def mark(self, chosen: Iterable[Path], unreadable: dict | None = None) -> None:
        """Show a check mark beside the files in ``chosen``, a cross beside ``unreadable`` ones."""
        self.chosen = {Path(p).resolve() for p in chosen}
        if unreadable is not None:
            self.unreadable = dict(unreadable)
        self._invalidate()

    def _cursor_path(self) -> Path | None:
        node = self.cursor_node
        return None if node is None or node.data is None else node.data.path

    def action_toggle_map(self) -> None:
        path = self._cursor_path()
        if path is None:
            return
        if self._safe_is_dir(path):
            self.action_toggle_node()
        else:
            self.post_message(self.Toggle(path))

    def action_add_directory(self) -> None:
        path = self._cursor_path()
        if path is None:
            path = Path(self.path)
        self.post_message(self.AddDirectory(path if self._safe_is_dir(path) else path.parent))

    class WentUp(Message):
        """The tree now lists ``path``, the folder above the one it listed."""

        def __init__(self, path: Path) -> None:
            super().__init__()
            self.path = path

    async def watch_path(self) -> None:
        await super().watch_path()
        if not str(self.root.label):     # the file system's root has no name of its own
            self.root.set_label(str(self.path))

    def action_parent(self) -> None:
        here = Path(self.path).resolve()
        if here.parent != here:
            self.path = here.parent
            self.post_message(self.WentUp(here.parent))


#: What x and f say with no map selected
_NONE_SELECTED = ("no map is selected: choose one in the tree with space or enter (a adds a "
                  "whole folder)")


class SelectedMaps(DataTable):
    """The chosen maps, in merge order; the first is the reference."""

    DEFAULT_CSS = """
    SelectedMaps {
        height: auto;
        max-height: 9;
        background: $surface;
    }
    """

    BINDINGS = [
        Binding("delete,x", "remove", "Remove"),
        Binding("f", "reference", "Reference"),
    ]

    class Remove(Message):
        def __init__(self, index: int) -> None:
            super().__init__()
            self.index = index

    class MakeReference(Message):
        def __init__(self, index: int) -> None:
            super().__init__()
            self.index = index

    def __init__(self, *, id: str | None = None) -> None:
        super().__init__(id=id, cursor_type="row", zebra_stripes=False)

    def on_mount(self) -> None:
        self.add_columns("", "map", "cells", "m/cell", "scans")

    def show(self, entries: list[tuple[Path, dict | None]], cursor: int | None = None,
             unreadable: dict | None = None) -> None:
        """List ``(path, map_info)`` entries (info None: the map cannot be read; ``unreadable``
        maps resolved paths to the reason). Maps are named by the shortest unique end of
        their path."""
        from ..runner import map_labels

        unreadable = unreadable or {}
        self.clear()
        labels = map_labels([p for p, _ in entries])
        usable = 0
        for k, ((path, info), label) in enumerate(zip(entries, labels)):
            if info is None or path.resolve() in unreadable:
                self.add_row(Text("✗", style="bold red"), Text(label, style="red"),
                             Text("unreadable", style="red"), "", "", key=str(k))
                continue
            self.add_row("ref" if usable == 0 else f"{usable + 1}", label,
                         f"{info['cols']}x{info['rows']}", f"{info['resolution']:g}",
                         "yes" if info["has_scans"] else "no", key=str(k))
            usable += 1
        if entries and cursor is not None:
            self.move_cursor(row=max(0, min(cursor, len(entries) - 1)))

    def action_remove(self) -> None:
        if self.row_count:
            self.post_message(self.Remove(self.cursor_row))
        else:   # said, not silently nothing
            self.notify(_NONE_SELECTED)

    def action_reference(self) -> None:
        if self.row_count:
            self.post_message(self.MakeReference(self.cursor_row))
        else:
            self.notify(_NONE_SELECTED)
