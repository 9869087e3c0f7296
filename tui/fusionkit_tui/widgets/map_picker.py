"""Choosing the robot maps: a directory tree of map files, the selection, and a preview."""

from __future__ import annotations

from collections import OrderedDict
from pathlib import Path
from typing import Iterable

from rich.text import Text
from textual import on, work
from textual.app import ComposeResult
from textual.containers import Horizontal, Vertical
from textual.message import Message
from textual.widgets import DataTable, DirectoryTree, Label, Static
from textual.worker import get_current_worker

from fusionkit.errors import FusionkitError

from ..runner import describe_error, find_maps, is_map_file
from .map_lists import MapTree, SelectedMaps
from .map_preview import MapPreview

__all__ = ["MapTree", "SelectedMaps", "MapsPane", "format_info"]


def format_info(info: dict) -> str:
    """One line about a map file, from :func:`fusionkit.mapio.map_info`."""
    scans = ("scans: yes" if info["has_scans"] else
             "scans: none (placed by its walls; spectral-pso casts virtual scans)")
    return (f"{info['name']}: {info['cols']} x {info['rows']} cells, {info['resolution']:g} m/cell "
            f"({info['width_m']:.1f} x {info['height_m']:.1f} m), {scans}")


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
        max-height: 3;   /* a map with no scans says how it is placed: 3 lines at 80 columns */
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
        self._entries: list[tuple[Path, dict | None]] = []
        self._grids: OrderedDict = OrderedDict()
        self._previewing: Path | None = None
        #: Resolved paths of maps that cannot be read, with the reason.
        self._unreadable: dict[Path, str] = {}
        #: Resolved paths of chosen maps read whole without error.
        self._checked: set[Path] = set()

    @property
    def selected(self) -> list[Path]:
        """The chosen map files, reference first (unreadable ones included)."""
        return [p for p, _ in self._entries]

    @property
    def unreadable(self) -> dict[Path, str]:
        """Chosen maps that cannot be read (path as chosen -> why)."""
        return {p: self._unreadable[p.resolve()] for p, _ in self._entries
                if p.resolve() in self._unreadable}

    def usable(self) -> list[Path]:
        """The chosen maps a merge can use, reference first: each read whole now if it was not
        yet; the unreadable ones are left out (see :attr:`unreadable`)."""
        from ..runner import check_map

        out = []
        for p, _ in self._entries:
            where = p.resolve()
            if where not in self._checked and where not in self._unreadable:
                try:
                    info, grid = check_map(p)
                except (FusionkitError, OSError) as exc:
                    self._mark_unreadable(p, describe_error(exc))
                    continue
                self._cache(p, grid, info)
                self._checked.add(where)
            if where not in self._unreadable:
                out.append(p)
        return out

    def previewing_label(self) -> str:
        """The map being previewed, named by the shortest unique end of its path."""
        from ..runner import map_labels

        if self._previewing is None:
            return ""
        return map_labels([*self.selected, self._previewing])[-1]

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
        self._report(self._add(self._initial))
        if self._entries:
            self._preview(self._entries[0][0])
        else:
            self._preview_nothing()

    # -- selection -------------------------------------------------------------------------------
    def _info(self, path: Path) -> dict:
        from fusionkit.mapio import map_info

        return map_info(path)

    def _add(self, paths: Iterable[Path]) -> list[str]:
        """Add maps not chosen yet, each checked in the background; return one message per map
        that cannot be read (it is listed as unreadable, and left out of a merge)."""
        have = {p.resolve() for p, _ in self._entries}
        errors = []
        for p in paths:
            p = Path(p)
            if p.resolve() in have:
                continue
            try:
                info = self._info(p)
            except (FusionkitError, OSError) as exc:
                info = None
                errors.append(describe_error(exc))
                self._unreadable[p.resolve()] = errors[-1]
            self._entries.append((p, info))
            have.add(p.resolve())
            if info is not None and p.resolve() not in self._checked:
                self._check(p)
        self._changed()
        return errors

    @work(thread=True, group="check", exit_on_error=False)
    def _check(self, path: Path) -> None:
        """Read a chosen map whole (a corrupt image shows only then)."""
        from ..runner import check_map

        try:
            info, grid = check_map(path)
        except (FusionkitError, OSError) as exc:
            self.app.call_from_thread(self._mark_unreadable, path, describe_error(exc))
            return
        self.app.call_from_thread(self._mark_readable, path, grid, info)

    def _mark_readable(self, path: Path, grid, info: dict) -> None:
        self._checked.add(path.resolve())
        self._cache(path, grid, info)

    def _mark_unreadable(self, path: Path, why: str) -> None:
        where = path.resolve()
        if self._unreadable.get(where) == why:
            return
        self._unreadable[where] = why
        self._checked.discard(where)
        chosen = any(p.resolve() == where for p, _ in self._entries)
        if chosen:
            self._changed()
            self.notify(f"{why}; it is left out of the merge", title="Unreadable map",
                        severity="error", timeout=8)
        else:
            self.query_one(MapTree).mark(self.selected, self._unreadable)
        if self._previewing is not None and self._previewing.resolve() == where:
            self._show_error(path, why)

    def _report(self, errors: list[str]) -> None:
        for e in errors[:3]:
            self.notify(f"{e}; it is left out of the merge", title="Unreadable map",
                        severity="error", timeout=8)
        if len(errors) > 3:
            self.notify(f"{len(errors) - 3} more maps could not be read", severity="error")

    def _changed(self, cursor: int | None = None) -> None:
        table = self.query_one(SelectedMaps)
        table.show(self._entries, cursor if cursor is not None else table.cursor_row, self._unreadable)
        self.query_one(MapTree).mark(self.selected, self._unreadable)
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
        errors = self._add(maps)
        self._report(errors)
        added = len(self._entries) - before
        if not maps:
            self.notify(f"no map YAML files in {directory}", severity="warning")
        elif not added:
            self.notify(f"the {len(maps)} map{'s' if len(maps) != 1 else ''} of {directory} "
                        f"{'are' if len(maps) != 1 else 'is'} selected already")
        else:
            bad = f" ({len(errors)} unreadable, left out of a merge)" if errors else ""
            self.notify(f"added {added} map{'s' if added != 1 else ''} from {directory}{bad}")
        return added

    def clear_selection(self) -> None:
        self._entries.clear()
        self._changed()
        self._preview_nothing()

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
            if not self._entries:  # no row is left to highlight, so none shows the map removed
                self._preview_nothing()

    @on(SelectedMaps.MakeReference)
    def _on_reference(self, event: SelectedMaps.MakeReference) -> None:
        if 0 < event.index < len(self._entries):
            path = self._entries[event.index][0]
            if path.resolve() in self._unreadable:
                self.notify(f"{path} cannot be read, so it cannot be the reference",
                            severity="error")
                return
            self._entries.insert(0, self._entries.pop(event.index))
            self._changed(cursor=0)
            self.notify(f"{path} is the reference: the merged map is in its frame")

    # -- preview ---------------------------------------------------------------------------------
    @on(DirectoryTree.NodeHighlighted)
    def _on_tree_highlight(self, event) -> None:
        entry = event.node.data
        if entry is not None and is_map_file(entry.path):
            self._preview(entry.path)
        elif entry is not None and event.node is not event.node.tree.root and entry.path.is_dir():
            self._show_folder(entry.path)

    @on(MapTree.WentUp)
    def _on_went_up(self, event: MapTree.WentUp) -> None:
        self._show_folder(event.path)     # the cursor is on the new top folder

    def _show_folder(self, path: Path) -> None:
        # not the last map's preview (or its "cannot read") beside a highlighted folder
        self._previewing = None
        self.query_one("#info", Static).update(f"{path.name or path}{'/' if path.name else ''}: a folder")
        self.query_one(MapPreview).clear("a folder: enter expands it, a adds its maps")

    @on(DataTable.RowHighlighted)
    def _on_row_highlight(self, event: DataTable.RowHighlighted) -> None:
        # only as the selection is walked: a change made from the tree redraws the table, and
        # its row under the cursor took the preview from the map under the tree's cursor
        if not event.data_table.has_focus:
            return
        if 0 <= event.cursor_row < len(self._entries):
            self._preview(self._entries[event.cursor_row][0])

    def on_descendant_focus(self, event) -> None:
        # into the selection: the map under its cursor (the tree's was shown)
        table = self.query_one(SelectedMaps)
        if event.widget is table and 0 <= table.cursor_row < len(self._entries):
            self._preview(self._entries[table.cursor_row][0])

    def _preview(self, path: Path) -> None:
        path = Path(path)
        if self._previewing is not None and path.resolve() == self._previewing.resolve():
            return
        self._previewing = path
        why = self._unreadable.get(path.resolve())
        if why is not None:
            self._show_error(path, why)
            return
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
                self.app.call_from_thread(self._mark_unreadable, path, describe_error(exc))
                self.app.call_from_thread(self._show_error, path, describe_error(exc))
            return
        if not worker.is_cancelled:
            self.app.call_from_thread(self._loaded, path, grid, info)

    def _cache(self, path: Path, grid, info: dict) -> None:
        self._grids[path.resolve()] = (grid, info)
        while len(self._grids) > self._CACHE_SIZE:
            self._grids.popitem(last=False)

    def _loaded(self, path: Path, grid, info: dict) -> None:
        self._cache(path, grid, info)
        if self._previewing is not None and self._previewing.resolve() == path.resolve():
            self._show(path, grid, info)

    def _show(self, path: Path, grid, info: dict) -> None:
        from ..runner import map_labels

        labels = map_labels([*self.selected, path])
        self.query_one("#info", Static).update(format_info({**info, "name": labels[-1]}))
        self.query_one(MapPreview).show(grid)

    def _preview_nothing(self) -> None:
        self._previewing = None
        self.query_one("#info", Static).update("")
        self.query_one(MapPreview).clear("no map selected: highlight or select a .yaml")

    def _show_error(self, path: Path, message: str) -> None:
        if self._previewing is not None and self._previewing.resolve() == path.resolve():
            self.query_one("#info", Static).update(Text(f"unreadable: {path.name}; it is left out "
                                                        f"of a merge", style="bold red"))
            self.query_one(MapPreview).clear(message)   # the whole reason, wrapped: room enough
