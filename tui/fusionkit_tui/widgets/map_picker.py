"""Choosing the robot maps: a directory tree of map files, the selection, and a preview."""

from __future__ import annotations

from collections import OrderedDict
from pathlib import Path
from typing import Iterable

from rich.text import Text
from textual import on, work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.message import Message
from textual.widgets import DataTable, DirectoryTree, Label, Static
from textual.worker import get_current_worker

from fusionkit.errors import FusionkitError

from ..runner import describe_error, find_maps, is_map_file
from .map_preview import MapPreview

__all__ = ["MapTree", "SelectedMaps", "MapsPane", "format_info"]


def format_info(info: dict) -> str:
    """One line about a map file, from :func:`fusionkit.mapio.map_info`."""
    scans = "scans: yes" if info["has_scans"] else "scans: none (virtual scans will be cast)"
    return (f"{info['name']}: {info['cols']} x {info['rows']} cells, {info['resolution']:g} m/cell "
            f"({info['width_m']:.1f} x {info['height_m']:.1f} m), {scans}")


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

    def filter_paths(self, paths: Iterable[Path]) -> Iterable[Path]:
        return [p for p in paths
                if not p.name.startswith(".") and (self._safe_is_dir(p) or is_map_file(p))]

    def render_label(self, node, base_style, style) -> Text:
        text = super().render_label(node, base_style, style)
        entry = node.data
        if entry is not None and not node.allow_expand:
            mark = "✓ " if entry.path.resolve() in self.chosen else "  "
            text = Text.assemble((mark, "bold"), text)
        return text

    def mark(self, chosen: Iterable[Path]) -> None:
        """Show a check mark beside the files in ``chosen``."""
        self.chosen = {Path(p).resolve() for p in chosen}
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

    def action_parent(self) -> None:
        here = Path(self.path).resolve()
        if here.parent != here:
            self.path = here.parent


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

    def show(self, entries: list[tuple[Path, dict]], cursor: int | None = None) -> None:
        """List ``(path, map_info)`` entries."""
        self.clear()
        for k, (path, info) in enumerate(entries):
            self.add_row("ref" if k == 0 else f"{k + 1}", info["name"],
                         f"{info['cols']}x{info['rows']}", f"{info['resolution']:g}",
                         "yes" if info["has_scans"] else "no", key=str(k))
        if entries and cursor is not None:
            self.move_cursor(row=max(0, min(cursor, len(entries) - 1)))

    def action_remove(self) -> None:
        if self.row_count:
            self.post_message(self.Remove(self.cursor_row))

    def action_reference(self) -> None:
        if self.row_count:
            self.post_message(self.MakeReference(self.cursor_row))


class MapsPane(Vertical):
    """Browse, choose and preview the maps to merge.

    ``selected`` holds the chosen map files in merge order; :class:`MapsPane.Changed` is posted
    whenever it changes.
    """

    DEFAULT_CSS = """
    MapsPane {
        height: 1fr;
    }
    MapsPane > Horizontal {
        height: 1fr;
    }
    MapsPane #browser {
        width: 2fr;
        min-width: 24;
        max-width: 48;
    }
    MapsPane #chosen {
        width: 3fr;
        padding-left: 1;
    }
    MapsPane .heading {
        color: $text-accent;
        text-style: bold;
        width: 1fr;
    }
    MapsPane #info {
        height: auto;
        max-height: 2;
        color: $text-muted;
    }
    """

    _CACHE_SIZE = 12

    class Changed(Message):
        """The selection changed."""

        def __init__(self, selected: list[Path]) -> None:
            super().__init__()
            self.selected = selected

    def __init__(self, root: Path, selected: Iterable[Path] = (), *, id: str | None = None) -> None:
        super().__init__(id=id)
        self._root = Path(root)
        self._initial = list(selected)
        self._entries: list[tuple[Path, dict]] = []
        self._grids: OrderedDict = OrderedDict()
        self._previewing: Path | None = None

    @property
    def selected(self) -> list[Path]:
        """The chosen map files, reference first."""
        return [p for p, _ in self._entries]

    def compose(self) -> ComposeResult:
        with Horizontal():
            with Vertical(id="browser"):
                yield Label("Browse: map YAML files", classes="heading")
                # "." would show as a bare dot: name the directory instead
                root = Path.cwd() if str(self._root) in ("", ".") else self._root
                yield MapTree(root, id="tree")
            with Vertical(id="chosen"):
                yield Label("Selected maps (ref = reference frame)", classes="heading")
                yield SelectedMaps(id="selected")
                yield Static("", id="info")
                yield MapPreview(id="preview")

    def on_mount(self) -> None:
        errors = self._add(self._initial)
        self._report(errors)
        if self._entries:
            self._preview(self._entries[0][0])
        else:
            self.query_one(MapPreview).clear("no map selected: highlight or select a .yaml")

    # -- selection -------------------------------------------------------------------------------
    def _info(self, path: Path) -> dict:
        from fusionkit.mapio import map_info

        return map_info(path)

    def _add(self, paths: Iterable[Path]) -> list[str]:
        """Add maps not chosen yet; return one message per map that cannot be read."""
        have = {p.resolve() for p, _ in self._entries}
        errors = []
        for p in paths:
            p = Path(p)
            if p.resolve() in have:
                continue
            try:
                info = self._info(p)
            except (FusionkitError, OSError) as exc:
                errors.append(describe_error(exc))
                continue
            self._entries.append((p, info))
            have.add(p.resolve())
        self._changed()
        return errors

    def _report(self, errors: list[str]) -> None:
        for e in errors[:3]:
            self.notify(e, title="Cannot use this map", severity="error", timeout=8)
        if len(errors) > 3:
            self.notify(f"{len(errors) - 3} more maps could not be read", severity="error")

    def _changed(self, cursor: int | None = None) -> None:
        table = self.query_one(SelectedMaps)
        table.show(self._entries, cursor if cursor is not None else table.cursor_row)
        self.query_one(MapTree).mark(self.selected)
        self.post_message(self.Changed(self.selected))

    def toggle(self, path: Path) -> None:
        """Choose ``path``, or drop it when already chosen."""
        path = Path(path)
        for k, (p, _) in enumerate(self._entries):
            if p.resolve() == path.resolve():
                del self._entries[k]
                self._changed()
                return
        self._report(self._add([path]))

    def add_directory(self, directory: Path) -> int:
        """Add the robot maps of ``directory``; return how many were added."""
        try:
            maps = find_maps(directory)
        except FusionkitError as exc:
            self.notify(str(exc), severity="error")
            return 0
        before = len(self._entries)
        self._report(self._add(maps))
        added = len(self._entries) - before
        if not maps:
            self.notify(f"no map YAML files in {directory}", severity="warning")
        else:
            self.notify(f"added {added} map{'s' if added != 1 else ''} from {directory}")
        return added

    def clear_selection(self) -> None:
        self._entries.clear()
        self._changed()

    @on(MapTree.Toggle)
    def _on_toggle(self, event: MapTree.Toggle) -> None:
        self.toggle(event.path)

    @on(DirectoryTree.FileSelected)
    def _on_file_selected(self, event: DirectoryTree.FileSelected) -> None:
        event.stop()
        self.toggle(event.path)

    @on(MapTree.AddDirectory)
    def _on_add_directory(self, event: MapTree.AddDirectory) -> None:
        self.add_directory(event.path)

    @on(SelectedMaps.Remove)
    def _on_remove(self, event: SelectedMaps.Remove) -> None:
        if 0 <= event.index < len(self._entries):
            del self._entries[event.index]
            self._changed()

    @on(SelectedMaps.MakeReference)
    def _on_reference(self, event: SelectedMaps.MakeReference) -> None:
        if 0 < event.index < len(self._entries):
            self._entries.insert(0, self._entries.pop(event.index))
            self._changed(cursor=0)
            self.notify(f"{self._entries[0][1]['name']} is the reference: the merged map is in its frame")

    # -- preview ---------------------------------------------------------------------------------
    @on(DirectoryTree.NodeHighlighted)
    def _on_tree_highlight(self, event) -> None:
        entry = event.node.data
        if entry is not None and is_map_file(entry.path):
            self._preview(entry.path)

    @on(DataTable.RowHighlighted)
    def _on_row_highlight(self, event: DataTable.RowHighlighted) -> None:
        if 0 <= event.cursor_row < len(self._entries):
            self._preview(self._entries[event.cursor_row][0])

    def _preview(self, path: Path) -> None:
        path = Path(path)
        if self._previewing is not None and path.resolve() == self._previewing.resolve():
            return
        self._previewing = path
        cached = self._grids.get(path.resolve())
        if cached is not None:
            self._show(path, *cached)
            return
        self.query_one("#info", Static).update(f"{path.name}: loading...")
        self._load(path)

    @work(thread=True, exclusive=True, group="preview", exit_on_error=False)
    def _load(self, path: Path) -> None:
        from fusionkit.mapio import load_map

        worker = get_current_worker()
        try:
            info = self._info(path)
            grid = load_map(path)
        except (FusionkitError, OSError) as exc:
            if not worker.is_cancelled:
                self.app.call_from_thread(self._show_error, path, describe_error(exc))
            return
        if not worker.is_cancelled:
            self.app.call_from_thread(self._loaded, path, grid, info)

    def _loaded(self, path: Path, grid, info: dict) -> None:
        self._grids[path.resolve()] = (grid, info)
        while len(self._grids) > self._CACHE_SIZE:
            self._grids.popitem(last=False)
        if self._previewing is not None and self._previewing.resolve() == path.resolve():
            self._show(path, grid, info)

    def _show(self, path: Path, grid, info: dict) -> None:
        self.query_one("#info", Static).update(format_info(info))
        self.query_one(MapPreview).show(grid)

    def _show_error(self, path: Path, message: str) -> None:
        if self._previewing is not None and self._previewing.resolve() == path.resolve():
            self.query_one("#info", Static).update(Text(message, style="bold red"))
            self.query_one(MapPreview).clear("cannot show this map")
