"""Short, unambiguous names for map files on a screen or in a table.

Two runs both write ``robot_1.yaml``; a map is therefore known by its path, shown as the
shortest trailing part of the path that tells it apart from the other maps on show
(``a/robot_1`` and ``b/robot_1``, but plain ``robot_1`` when it is the only one).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Sequence

__all__ = ["unique_labels", "clip_left", "clip_column", "fixed", "count"]

_MAP_SUFFIXES = (".yaml", ".yml")


def _parts(path) -> tuple[str, ...]:
    p = Path(os.path.abspath(os.fspath(path)))
    parts = list(p.parts)
    if p.suffix.lower() in _MAP_SUFFIXES:
        parts[-1] = p.stem
    return tuple(parts)


def unique_labels(paths: Sequence, *, keep_suffix: bool = False) -> list[str]:
    """The shortest trailing part of each path that no other path of ``paths`` ends with.

    Parameters
    ----------
    paths : sequence of str or os.PathLike
        Map files (relative paths are taken from the current directory).
    keep_suffix : bool
        Keep the ``.yaml`` ending (default: drop it, as a map's name is its file's stem).

    Returns
    -------
    list of str
        One label per path, in order, with ``/`` between directories. The same file given
        twice gets the same label.

    Examples
    --------
    >>> unique_labels(["runs/a/robot_1.yaml", "runs/b/robot_1.yaml", "runs/b/robot_2.yaml"])
    ['a/robot_1', 'b/robot_1', 'robot_2']
    """
    parts = [_parts(p) for p in paths]
    out = []
    for k, mine in enumerate(parts):
        others = {q for j, q in enumerate(parts) if j != k and q != mine}
        n = 1
        while n < len(mine) and any(q[-n:] == mine[-n:] for q in others):
            n += 1
        label = "/".join(mine[-n:]).replace("//", "/")
        if keep_suffix:
            label += Path(os.fspath(paths[k])).suffix if Path(os.fspath(paths[k])).suffix.lower() \
                in _MAP_SUFFIXES else ""
        out.append(label)
    return out


def clip_left(text: str, width: int) -> str:
    """``text`` cut to ``width`` characters at its start, marked with an ellipsis (``…``).

    >>> clip_left("runs/demo/robot_1.yaml", 16)
    '…mo/robot_1.yaml'
    """
    text = str(text)
    if width < 1:
        return ""
    if len(text) <= width:
        return text
    return "…" + text[len(text) - width + 1:]


def clip_column(names: Sequence, width: int) -> tuple[list[str], int]:
    """``names`` cut to ``width`` (:func:`clip_left`) and the column's width; whole, and the
    column as wide as the longest, when two that differ only where they were cut would read
    alike."""
    names = [str(n) for n in names]
    shown = [clip_left(n, width) for n in names]
    if len(set(shown)) < len(set(names)):
        return names, max(map(len, names))
    return shown, width


def fixed(value: float, width: int, digits: int) -> str:
    """``value`` right-aligned in ``width`` characters with ``digits`` decimals, never "-0.0"
    (a value that rounds to zero prints as 0)."""
    return f"{round(float(value), digits) + 0.0:{width}.{digits}f}"


def count(n: int, noun: str) -> str:
    """``n`` and ``noun``, plural unless ``n`` is 1: ``1 case``, ``2 cases``."""
    return f"{n} {noun}{'' if n == 1 else 's'}"
