"""A map on the whole terminal: the fused map (or the map being previewed) as large as it fits."""

from __future__ import annotations

from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.screen import ModalScreen
from textual.widgets import Static

from ..widgets.map_preview import MapPreview

__all__ = ["MapScreen"]


class MapScreen(ModalScreen[None]):
    """``grid`` drawn on the whole screen, with a title line and a legend line.

    Parameters
    ----------
    grid : OccupancyGrid
    title : str
        What the map is (first line).
    owner : (rows, cols) int array, optional
        Colour each cell by the map that contributed it (a fused map).
    legend : rich Text or str
        Shown on the last line.
    """

    DEFAULT_CSS = """
    MapScreen {
        background: $surface;
    }
    MapScreen #map-title, MapScreen #map-legend {
        height: 1;
        width: 100%;
        text-wrap: nowrap;
        text-overflow: ellipsis;
        padding: 0 1;
    }
    MapScreen #map-title {
        text-style: bold;
        color: $text-accent;
    }
    MapScreen #map-legend {
        color: $text-muted;
    }
    MapScreen MapPreview {
        height: 1fr;
        width: 100%;
    }
    """

    BINDINGS = [Binding("escape,m,q,enter", "close", "Close")]

    def __init__(self, grid, title: str, owner=None, legend: Text | str = "") -> None:
        super().__init__()
        self._grid, self._title, self._owner, self._legend = grid, title, owner, legend

    def compose(self) -> ComposeResult:
        yield Static(f"{self._title}  (escape, m or q closes)", id="map-title")
        yield MapPreview(id="map-full")
        yield Static(self._legend, id="map-legend")

    def on_mount(self) -> None:
        self.query_one(MapPreview).show(self._grid, self._owner)

    def action_close(self) -> None:
        self.dismiss(None)
