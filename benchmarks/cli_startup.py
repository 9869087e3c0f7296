"""Start-up time of the command line: ``fusionkit --help`` against a bare Python start.

Each command runs in a fresh process, ``--repeat`` times, interleaved so that a busy machine
slows them alike; the median wall time of each is printed, and its ratio to the bare start
(``python -c pass``) of the same run. ``fusionkit simulate --help`` loads the simulator (numba,
SciPy), as every command did before the command line imported its subcommands lazily.

Run::

    .venv/bin/python benchmarks/cli_startup.py [--repeat 15]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time

COMMANDS = {
    "python -c pass": [sys.executable, "-c", "pass"],
    "fusionkit --help": [sys.executable, "-c", "import sys; from fusionkit.cli import main; "
                         "sys.argv[0] = 'fusionkit'; main(['--help'])"],
    "fusionkit simulate --help": [sys.executable, "-c", "import sys; from fusionkit.cli import main; "
                                  "sys.argv[0] = 'fusionkit'; main(['simulate', '--help'])"],
}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=15, help="runs of each command (default 15)")
    args = ap.parse_args(argv)
    times: dict[str, list[float]] = {k: [] for k in COMMANDS}
    for name, cmd in COMMANDS.items():  # warm the file cache once
        subprocess.run(cmd, stdout=subprocess.DEVNULL, check=True)
    for _ in range(args.repeat):
        for name, cmd in COMMANDS.items():
            t0 = time.perf_counter()
            subprocess.run(cmd, stdout=subprocess.DEVNULL, check=True)
            times[name].append(time.perf_counter() - t0)
    base = statistics.median(times["python -c pass"])
    print(f"{'command':<28} {'median (s)':>10} {'x bare python':>14}")
    for name, ts in times.items():
        med = statistics.median(ts)
        print(f"{name:<28} {med:>10.3f} {med / base:>14.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
