"""Interrupts as exceptions: SIGINT raises :class:`KeyboardInterrupt`, SIGTERM :class:`Terminated`.

Both unwind the stack like any exception, so every ``with``/``finally`` that removes temporary
files or rolls back a half-done write runs before the process exits. :func:`deferred` holds
both signals back for the few system calls that must not be separated (a commit of an output
set), and :func:`pending` tells such code that the user asked to stop, so it can roll back
instead of committing.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Iterator

__all__ = ["Terminated", "HungUp", "install", "deferred", "pending", "signal_of", "exit_status",
           "check", "swallowed", "forget", "watching",
           "EXIT_SIGINT", "EXIT_SIGTERM", "EXIT_SIGHUP"]

#: Exit statuses of a command stopped by SIGINT (Ctrl-C), SIGTERM and SIGHUP (a closed
#: terminal, a dropped SSH link) (128 + signal number).
EXIT_SIGINT = 130
EXIT_SIGTERM = 143
EXIT_SIGHUP = 129

_SIGNALS = (signal.SIGINT, signal.SIGTERM) + ((signal.SIGHUP,) if hasattr(signal, "SIGHUP") else ())
_pending: list[int] = []
_deferring = 0
#: Signals whose exception was raised and has not reached the command's end: a library that
#: swallowed it (an optional import that fails with ImportError while it loads) or turned it
#: into another error lost the user's Ctrl-C (:func:`check`, :func:`swallowed`)
_received: list[int] = []
_watching = False   # a command of the command line runs (:func:`watching`)


class Terminated(KeyboardInterrupt):
    """The process received SIGTERM; unwinds like Ctrl-C (so cleanup code runs) and exits 143."""


class HungUp(Terminated):
    """The process received SIGHUP (its terminal closed, an SSH link dropped); unwinds as
    SIGTERM does and exits 129."""


def _raise(signum, frame):  # noqa: ARG001 (signal handler signature)
    if _deferring:
        _pending.append(signum)
        return
    if _watching:
        _received.append(signum)
    raise _exception(signum)


def _exception(signum: int) -> KeyboardInterrupt:
    if signum == signal.SIGTERM:
        return Terminated()
    if signum == getattr(signal, "SIGHUP", None):
        return HungUp()
    return KeyboardInterrupt()


def swallowed() -> KeyboardInterrupt | None:
    """The interrupt of a signal that arrived while :func:`install`'s handlers were in place and
    that was never handled (:func:`forget`), or None."""
    return _exception(_received[-1]) if _received else None


@contextlib.contextmanager
def watching() -> Iterator[None]:
    """Keep the interrupts that arrive inside the block for :func:`check` and
    :func:`swallowed` (a command of the command line); outside it (a notebook, a program using
    the library, after a command ended) an interrupt is the caller's to handle."""
    global _watching
    forget()
    _watching = True
    try:
        yield
    finally:
        _watching = False


def forget() -> None:
    """The interrupts so far are handled (the command said so and ends, or a new one starts)."""
    _received.clear()


def check() -> None:
    """Raise again an interrupt some library swallowed (see :data:`_received`): called before
    outputs are written, so that a Ctrl-C that came while modules loaded is not lost and the
    old outputs are not replaced."""
    exc = swallowed()
    if exc is not None and _watching and _in_place():
        _received.clear()
        raise exc


def signal_of(exc: KeyboardInterrupt) -> int:
    """The signal an interrupt raised by :func:`install`'s handlers stands for."""
    return (signal.SIGHUP if isinstance(exc, HungUp) else
            signal.SIGTERM if isinstance(exc, Terminated) else signal.SIGINT)


def exit_status(exc: KeyboardInterrupt) -> int:
    """The exit status of a command that ``exc`` stopped: 129, 130 or 143."""
    return (EXIT_SIGHUP if isinstance(exc, HungUp) else
            EXIT_SIGTERM if isinstance(exc, Terminated) else EXIT_SIGINT)


#: Seconds before a signal whose exception was swallowed is sent again.
_AGAIN_S = 0.01


def _unraisable(hook):
    """A ``sys.unraisablehook`` that gives an interrupt back to the program.

    Python ignores an exception raised where nothing can catch it: in a ctypes callback
    (numba's compiler calls some while it loads its cached kernels), a ``__del__``, a weakref
    callback. An interrupt raised there was lost and the command went on to the end. Its signal
    is sent again a moment later, when the main thread is most likely back in plain code (and
    again, should it land in such a place once more); anything else goes to ``hook``."""
    def unraisable(info):
        exc = info.exc_value
        if isinstance(exc, KeyboardInterrupt) and _in_place():
            if _received:   # sent again: kept when it comes, not now (a check would raise it
                _received.pop()   # while the signal is on its way, which then finds an exit)
            threading.Timer(_AGAIN_S, os.kill, (os.getpid(), signal_of(exc))).start()
            return
        hook(info)
    unraisable.installed = True
    return unraisable


#: The process was started with SIGHUP ignored (``nohup``: the run must outlive the terminal or
#: the SSH link that started it), as it was when this module was first imported
_HUP_IGNORED = hasattr(signal, "SIGHUP") and signal.getsignal(signal.SIGHUP) == signal.SIG_IGN


def _kept_ignored(s: int) -> bool:
    """A SIGHUP the process was started ignoring stays ignored."""
    return _HUP_IGNORED and s == signal.SIGHUP


def _in_place() -> bool:
    """Whether :func:`install`'s handlers hold every signal they take."""
    return all(signal.getsignal(s) is _raise or _kept_ignored(s) for s in _SIGNALS)


def install() -> None:
    """Turn SIGINT, SIGTERM and SIGHUP into exceptions (main thread only; elsewhere a no-op);
    a SIGHUP ignored at start (``nohup``) stays ignored."""
    if threading.current_thread() is not threading.main_thread():
        return
    for s in _SIGNALS:
        if not _kept_ignored(s):
            signal.signal(s, _raise)
    if not getattr(sys.unraisablehook, "installed", False):
        sys.unraisablehook = _unraisable(sys.unraisablehook)


def pending() -> bool:
    """True when SIGINT or SIGTERM arrived inside :func:`deferred` and is waiting."""
    return bool(_pending)


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """Hold SIGINT and SIGTERM back inside the block; deliver them when it ends.

    Only in the main thread with :func:`install` handlers in place; elsewhere the block runs
    unchanged (Python delivers signals to the main thread only, so a worker thread is never
    interrupted mid-block anyway).
    """
    global _deferring
    active = (threading.current_thread() is threading.main_thread()
              and _in_place())
    if not active:
        yield
        return
    _deferring += 1
    try:
        yield
    finally:
        _deferring -= 1
        if not _deferring and _pending:
            signum = _pending[0]
            _pending.clear()
            os.kill(os.getpid(), signum)  # delivered again, now to the raising handler
