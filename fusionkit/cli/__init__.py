"""The ``fusionkit`` command line.

Each subcommand lives in its own module of this package with a ``register(subparsers)``
function; errors the user can fix (:class:`fusionkit.errors.FusionkitError`) print one line on
stderr and exit with status 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from ..errors import FusionkitError

__all__ = ["main", "build_parser"]

#: Subcommand modules, in the order ``fusionkit --help`` lists them.
COMMAND_MODULES = ("run", "simulate", "merge", "evaluate", "importer", "export", "tui", "bench",
                   "ros2")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="fusionkit",
        description="Multi-robot occupancy-grid map fusion: simulate robots, find the rigid "
                    "transforms between their maps, fuse them and measure the result.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    from .. import __version__
    parser.add_argument("--version", action="version", version=f"fusionkit {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMAND_MODULES:
        importlib.import_module(f".{name}", __name__).register(sub)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        code = args.func(args)
    except FusionkitError as exc:
        print(f"fusionkit {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"fusionkit {args.command}: interrupted", file=sys.stderr)
        return 130
    return int(code or 0)
