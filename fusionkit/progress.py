"""A progress bar for long work on the command line: done of total, rate and time left.

Drawn on a stream (stderr by default) only when that stream is a terminal, so that a run in a
pipe or a log file stays quiet. The library itself never prints: the commands make a bar and
hand its ``update`` to the work as a callback.
"""

from __future__ import annotations

import sys
import time

__all__ = ["ProgressBar", "format_duration"]


def format_duration(seconds: float) -> str:
    """``"42 s"``, ``"3:05"`` (minutes:seconds) or ``"1:02:03"``."""
    s = max(0, int(round(seconds)))
    if s < 60:
        return f"{s} s"
    h, rest = divmod(s, 3600)
    m, s = divmod(rest, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m}:{s:02d}"


class ProgressBar:
    """``title [#####-----] done/total unit, rate/s, time left``, redrawn in place.

    Parameters
    ----------
    title : str
        What is running (``"bench"``, ``"merge"``).
    unit : str
        What is counted (``"cases"``, ``"pairs"``).
    stream : file, optional
        Where to draw (stderr by default).
    enabled : bool, optional
        Force drawing on or off; by default drawn only when ``stream`` is a terminal.
    min_interval : float
        Least seconds between two redraws (the last step is always drawn).
    """

    def __init__(self, title: str, *, unit: str = "", stream=None, enabled: bool | None = None,
                 min_interval: float = 0.1, clock=time.monotonic):
        self.title = title
        self.unit = unit
        self.stream = stream if stream is not None else sys.stderr
        if enabled is None:
            isatty = getattr(self.stream, "isatty", None)
            enabled = bool(isatty()) if isatty is not None else False
        self.enabled = enabled
        self.min_interval = min_interval
        self._clock = clock
        self._t0 = clock()
        self._start_done: int | None = None
        self._t_start = self._t0
        self._last = -float("inf")
        self._drawn = False
        self._width = 0

    def line(self, done: int, total: int, label: str = "") -> str:
        """The text of the bar for ``done`` of ``total`` (without drawing it)."""
        now = self._clock()
        if self._start_done is None or done < self._start_done:
            self._start_done, self._t_start = done, now
        frac = 0.0 if total <= 0 else min(1.0, max(0.0, done / total))
        width = 24
        fill = int(frac * width)
        unit = f" {self.unit}" if self.unit else ""
        text = f"{self.title} [{'#' * fill}{'-' * (width - fill)}] {done}/{total}{unit}"
        elapsed = now - self._t_start
        counted = done - self._start_done
        if counted > 0 and elapsed > 0:
            rate = counted / elapsed
            text += f", {rate:.2f}/s" if rate < 10 else f", {rate:.0f}/s"
            if done < total:
                text += f", {format_duration((total - done) / rate)} left"
        if done >= total > 0:
            text += f", {format_duration(now - self._t0)}"
        if label:
            text += f"  {label}"
        return text[:118]

    def update(self, done: int, total: int, label: str = "") -> None:
        """Redraw for ``done`` of ``total`` (at most every ``min_interval`` seconds)."""
        text = self.line(done, total, label)
        if not self.enabled:
            return
        now = self._clock()
        if done < total and now - self._last < self.min_interval:
            return
        self._last = now
        pad = max(0, self._width - len(text))
        self.stream.write("\r" + text + " " * pad)
        self.stream.flush()
        self._width = len(text)
        self._drawn = True

    __call__ = update

    def note(self, text: str) -> None:
        """Print a line above the bar (on a terminal or not)."""
        if self._drawn and self.enabled:
            self.stream.write("\r" + " " * self._width + "\r")
        self.stream.write(text + "\n")
        self.stream.flush()
        self._drawn = False
        self._width = 0

    def close(self) -> None:
        """End the bar's line (the bar stays visible with its final count)."""
        if self.enabled and self._drawn:
            self.stream.write("\n")
            self.stream.flush()
        self._drawn = False
