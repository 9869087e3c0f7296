"""Errors fusionkit raises for input a user can fix.

Every error that reaches a user carries one sentence that names the file or value at fault and
what to do about it; the command line prints that sentence alone (no traceback) and exits 2.
"""

from __future__ import annotations

__all__ = ["FusionkitError", "InputError", "MapFormatError", "ScanLogError"]


class FusionkitError(Exception):
    """Base class: a problem with the user's input or request, described in one line."""


class InputError(FusionkitError, ValueError):
    """A value, option or path given by the user is out of range or inconsistent."""


class MapFormatError(InputError):
    """A map file (YAML or its image) is missing, corrupt or not in the map_server format."""


class ScanLogError(InputError):
    """A ``NAME.scans.npz`` scan log is missing keys, has inconsistent shapes or bad ranges."""

