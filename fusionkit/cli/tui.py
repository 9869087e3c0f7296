"""``fusionkit tui``: the operator's terminal UI (pick maps, run and watch the merge, export)."""

from __future__ import annotations

import os
import sys
import threading
import time

from ..errors import InputError


def register(sub) -> None:
    p = sub.add_parser(
        "tui", help="terminal UI: pick robot maps, watch the PSO converge, export the merged map",
        description="Fuse robot maps interactively in the terminal (works over SSH at 80x24). "
                    "Browse to the maps, select two or more, adjust the settings, run the merge "
                    "and watch each alignment's PSO converge, inspect the fused map, each map's "
                    "transform and confidence (and the paper's Table 1 metrics when a truth.json "
                    "stands beside the maps), and export the merged map (YAML + PGM) with its "
                    "report. Press ? inside for the keys. Set NO_COLOR to draw maps without colour.")
    p.add_argument("paths", nargs="*", metavar="DIR or MAP.yaml",
                   help="a directory to open with its robot maps selected (a simulated run, for "
                        "instance), or map YAML files to select; default: browse the current "
                        "directory with nothing selected")
    p.set_defaults(func=run)


def run(args) -> int:
    try:
        from fusionkit_tui import make_app
    except ImportError as exc:  # the UI package ships beside fusionkit; say what is missing
        raise InputError(f"the terminal UI cannot start ({exc}); reinstall fusionkit with its "
                         f"dependencies (textual, textual-plotext)") from None
    app = make_app(args.paths)
    if not (sys.stdin.isatty() and sys.stdout.isatty()):
        # started from a script or with its output in a file, it drew into the file and read
        # an input at its end over and over: a core busy until it was killed
        raise InputError("the terminal UI needs a terminal for its input and output; run it in "
                         "one (over SSH: ssh -t), not from a pipe or with its output in a file")
    said = threading.Lock()  # the line of an interrupt is said once, by whoever gets there first

    def say_interrupted() -> None:
        if said.acquire(blocking=False):
            print(INTERRUPTED, file=sys.stderr, flush=True)

    def leave_when_closed() -> None:
        # Ctrl-C while a merge is busy in a kernel: Textual restores the terminal, then waits
        # for the worker thread, which looks at its cancel flag only between steps (minutes on
        # a large map). The merge writes no file (an export runs in the UI thread), so once
        # the UI is closed the process ends here, without waiting.
        deadline = time.monotonic() + 10.0
        while getattr(app, "_loop", None) is not None and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.5)  # the worker may yet stop by itself, and the command end as usual
        say_interrupted()
        os._exit(130)

    app.on_interrupt = lambda: threading.Thread(target=leave_when_closed, daemon=True).start()
    app.run()
    if app.return_code == 130:  # Ctrl-C: one line, as every command says it
        say_interrupted()
    return int(app.return_code or 0)


INTERRUPTED = "fusionkit tui: interrupted; no output was left half-written"
