"""fusionkit's terminal UI (Textual): pick robot maps, set the merge, watch the PSO converge,
inspect the fused map and export it. ``fusionkit tui`` starts it; :func:`make_app` builds it."""

from .app import FusionkitApp, make_app

__all__ = ["FusionkitApp", "make_app"]
