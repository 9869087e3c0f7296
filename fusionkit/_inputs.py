"""Reading untrusted input files: regular files only, bounded in size, never a hang.

A FIFO, a device or a socket given where a file is expected would block a read forever (or
stream without end); these helpers open with ``O_NONBLOCK``, check that the descriptor is a
regular file, and only then read, at most a stated number of bytes.
"""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path

from ._atomic import _short
from .errors import InputError

__all__ = ["path_arg", "regular_file", "read_bytes", "read_json", "MAX_JSON_BYTES", "MAX_JSON_DEPTH"]

#: A truth.json or a report is a few kilobytes; anything this large is not one.
MAX_JSON_BYTES = 16 << 20
#: Nesting deeper than this is refused before the JSON parser can run out of stack.
MAX_JSON_DEPTH = 64


def path_arg(value, what: str, error=InputError) -> Path:
    """``value`` as a Path, or one ``error`` when it is not a path (None, a grid, a number:
    pathlib's TypeError said nothing of which argument)."""
    if not isinstance(value, (str, bytes, os.PathLike)):
        raise error(f"{what} must be a path (str or pathlib.Path), got {type(value).__name__}")
    return Path(os.fsdecode(value))


def regular_file(path, what: str, error=InputError) -> Path:
    """``path`` as a Path after checking it names an existing regular file (not a folder, FIFO,
    device or socket); raise ``error`` with one line naming the file otherwise."""
    path = path_arg(path, f"the {what}", error)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        noun = what if "file" in what.split() else f"{what} file"
        raise error(f"{_short(path)}: no such {noun}; check the path") from None
    except OSError as exc:
        raise error(f"{_short(path)}: the {what} cannot be read ({exc.strerror or exc}); "
                    f"check the path and its permissions") from None
    if stat.S_ISDIR(st.st_mode):
        raise error(f"{_short(path)}: is a directory, not a {what}; give the file's path")
    if not stat.S_ISREG(st.st_mode):
        raise error(f"{_short(path)}: is not a regular file (a pipe, device or socket); "
                    f"give the {what} as an ordinary file")
    return path


def read_bytes(path, what: str, limit: int, error=InputError) -> bytes:
    """The bytes of a regular file of at most ``limit`` bytes."""
    path = regular_file(path, what, error)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as exc:
        raise error(f"{_short(path)}: the {what} cannot be read ({exc.strerror or exc}); "
                    f"check its permissions") from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):  # swapped after the check above
            raise error(f"{_short(path)}: is not a regular file; give the {what} as an ordinary file")
        with os.fdopen(fd, "rb", closefd=False) as fh:
            data = fh.read(limit + 1)
    except OSError as exc:
        raise error(f"{_short(path)}: the {what} cannot be read ({exc.strerror or exc})") from None
    finally:
        os.close(fd)
    if len(data) > limit:
        raise error(f"{_short(path)}: is larger than {_size(limit)}, too large for a {what}; "
                    f"check that this is the right file")
    return data


def _size(n: int) -> str:
    for unit in ("bytes", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:g} {unit}" if unit == "bytes" else f"{n:.0f} {unit}"
        n /= 1024
    return str(n)


def _depth(text: str) -> int:
    """Deepest nesting of ``[``/``{`` outside strings (a linear scan, no recursion)."""
    depth = top = 0
    in_str = esc = False
    for ch in text:
        if in_str:
            if esc:
                esc = False
            elif ch == "\\":
                esc = True
            elif ch == '"':
                in_str = False
        elif ch == '"':
            in_str = True
        elif ch in "[{":
            depth += 1
            top = max(top, depth)
        elif ch in "]}":
            depth -= 1
    return top


def read_json(path, what: str, error=InputError, limit: int = MAX_JSON_BYTES):
    """Parse a JSON file of bounded size and nesting; one-line ``error`` on any fault."""
    data = read_bytes(path, what, limit, error)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise error(f"{_short(path)}: the {what} is not UTF-8 text; check that this is the right file") from None
    if ("[" in text or "{" in text) and _depth(text) > MAX_JSON_DEPTH:
        raise error(f"{_short(path)}: the {what} is nested more than {MAX_JSON_DEPTH} levels deep; "
                    f"it is not a fusionkit file")
    try:
        return json.loads(text)
    except (ValueError, RecursionError) as exc:
        msg = exc.msg if isinstance(exc, json.JSONDecodeError) else "invalid JSON"
        where = f" at line {exc.lineno}, column {exc.colno}" if isinstance(exc, json.JSONDecodeError) else ""
        raise error(f"{_short(path)}: the {what} is not valid JSON ({msg}{where}); fix or regenerate it") from None
