"""Guards of every output: never an input, checked before any work, errors in one bounded line.

:func:`check_not_input` (an output is never an input, compared after resolving links, hard
links too), :func:`check_distinct` (two outputs of one command are never one file),
:func:`check_writable` and :func:`check_out_dir` (a missing, read-only or wrong-kind folder is
refused before the work starts), and :func:`show` (a value from a file or the command line,
quoted in a message, never unbounded and never with a raw control character).
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
from pathlib import Path
from typing import Sequence

from .errors import InputError

__all__ = ["show", "describe_os_error", "check_not_input", "check_distinct", "check_writable",
           "check_out_dir", "make_out_dir", "made_out_dir"]


def show(value, limit: int = 80) -> str:
    """``repr`` of a value from a file or the command line, cut to ``limit`` characters (control
    characters escaped): safe in a one-line message whatever the input holds."""
    if isinstance(value, (str, bytes)) and len(value) > 4 * limit:
        value = value[:4 * limit]
    elif isinstance(value, (list, tuple)) and len(value) > limit:
        value = type(value)(value[:limit])
    elif isinstance(value, dict) and len(value) > limit:
        value = dict(list(value.items())[:limit])
    try:
        text = repr(value)
    except (RecursionError, ValueError):
        text = f"<{type(value).__name__}>"
    return text if len(text) <= limit else text[:limit - 4] + " ..."


def describe_os_error(exc: OSError) -> str:
    """The reason of an OSError in words, without the path (the caller names the file)."""
    return exc.strerror or exc.__class__.__name__


def _write_error(path: Path, exc: OSError) -> InputError:
    hint = {errno.EACCES: "check the folder's permissions or choose another output",
            errno.EPERM: "check the folder's permissions or choose another output",
            errno.EROFS: "the file system is read-only; choose another output",
            errno.ENOSPC: "free some disk space or choose another output",
            errno.EDQUOT: "free some disk space or choose another output",
            errno.ENAMETOOLONG: "use a shorter file name",
            errno.EISDIR: "it is a folder; give a file name",
            errno.ENOTDIR: "a part of the path is a file, not a folder"}.get(
        exc.errno, "check the path and the disk")
    return InputError(f"{_short(path)}: cannot be written ({describe_os_error(exc)}); {hint}")


def _short(path) -> str:
    """A path for a message: very long names are cut in the middle."""
    s = str(path)
    return s if len(s) <= 160 else s[:70] + "..." + s[-70:]



def _parent(path: Path) -> Path:
    return path.parent if str(path.parent) else Path(".")


def _check_target(path: Path) -> None:
    if len(os.fsencode(path.name)) > 200:
        raise InputError(f"{_short(path)}: the file name is {len(os.fsencode(path.name))} bytes long; "
                         f"use a name of at most 200 bytes")
    parent = _parent(path)
    if not parent.is_dir():
        if parent.exists():
            raise InputError(f"{_short(path)}: {_short(parent)} is a file, not a folder; "
                             f"choose another output")
        raise InputError(f"{_short(path)}: the output folder {_short(parent)} does not exist; "
                         f"create it first")
    if path.is_dir():
        raise InputError(f"{_short(path)}: is an existing folder; give a file name for the output")



def check_writable(paths) -> None:
    """Refuse, before any work, outputs that cannot be written: a missing or read-only folder,
    a target that is a folder, an overlong name (one :class:`InputError` line)."""
    for p in paths:
        if p is None:
            continue
        p = Path(p)
        _check_target(p)
        parent = _parent(p)
        if not os.access(parent, os.W_OK | os.X_OK):
            raise InputError(f"{_short(p)}: the folder {_short(parent)} is not writable; check its "
                             f"permissions or choose another output")


def check_out_dir(directory) -> Path:
    """Refuse, before any work, an output folder that is a file or cannot be created or written
    (one :class:`InputError` line); returns it as a Path. Nothing is created here."""
    d = Path(directory)
    if len(os.fsencode(d.name)) > 255:
        raise InputError(f"{_short(d)}: the folder name is too long; use a shorter name")
    if d.exists() and not d.is_dir():
        raise InputError(f"{_short(d)}: is a file, not a folder; give a folder for the outputs")
    probe = d
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    if not probe.is_dir():
        raise InputError(f"{_short(d)}: {_short(probe)} is a file, not a folder; give another "
                         f"output folder")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise InputError(f"{_short(d)}: the folder {_short(probe)} is not writable; check its "
                         f"permissions or choose another output folder")
    return d


def make_out_dir(directory) -> Path:
    """Create the output folder (and its parents) after :func:`check_out_dir`."""
    d = check_out_dir(directory)
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _write_error(d, exc) from None
    return d


@contextlib.contextmanager
def made_out_dir(directory):
    """:func:`make_out_dir` for the writes in the ``with`` block: when they fail or are
    interrupted, the folders it created are removed again (those left empty), so that a failed
    command leaves the file system as it found it."""
    d = Path(directory)
    missing = []
    probe = d
    while not probe.exists() and probe != probe.parent:
        missing.append(probe)
        probe = probe.parent
    make_out_dir(d)
    try:
        yield d
    except BaseException:
        for folder in missing:  # deepest first
            try:
                folder.rmdir()
            except OSError:
                break
        raise



# ---------------------------------------------------------------------------------------------
# Inputs are never outputs
# ---------------------------------------------------------------------------------------------
def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def check_not_input(outputs, inputs, *, what: str = "the input") -> None:
    """Raise :class:`InputError` when any output path is one of the input files.

    fusionkit never overwrites an input; paths are compared after resolving links (hard links
    too). ``what`` names the files of ``inputs`` in the message.
    """
    resolved = {}
    for p in inputs:
        if p is not None:
            resolved.setdefault(Path(p).resolve(), str(p))
    for out in outputs:
        if out is None:
            continue
        r = Path(out).resolve()
        hit = resolved.get(r)
        if hit is None and Path(out).exists():
            hit = next((s for q, s in resolved.items() if _same_file(q, r)), None)
        if hit is not None:
            raise InputError(
                f"{_short(out)}: this output would overwrite {what} {_short(hit)}; "
                f"choose another output path")


def check_distinct(named_outputs: Sequence[tuple[str, os.PathLike | str]]) -> None:
    """Raise :class:`InputError` when two outputs of one command are the same file
    (``named_outputs``: ``(what, path)`` pairs, e.g. ``("--report", "r.json")``)."""
    seen: dict[str, str] = {}
    for what, p in named_outputs:
        if p is None:
            continue
        r = os.path.realpath(p)
        if r in seen:
            raise InputError(f"{_short(p)}: {what} and {seen[r]} are the same file; "
                             f"give them different paths")
        seen[r] = what


#: The temporary folder of a ROS bag export (``.NAME.PID.XXXXXXXX.tmp``, ``tempfile.mkdtemp``'s)
_EXPORT_TMP = re.compile(r"\..+\.(\d+)\.[A-Za-z0-9_]+\.tmp")


def dead_export(folder: Path, name: str) -> bool:
    """Whether ``folder / name`` is the temporary folder of a bag export whose process is gone
    (killed before it could remove it)."""
    m = _EXPORT_TMP.fullmatch(name)
    if m is None or os.path.islink(folder / name) or not os.path.isdir(folder / name):
        return False
    try:
        os.kill(int(m.group(1)), 0)
    except ProcessLookupError:
        return True
    except (PermissionError, OverflowError):   # another user's process, or no PID at all
        return False
    return False
