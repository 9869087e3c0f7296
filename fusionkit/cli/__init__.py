"""The ``fusionkit`` command line.

Each subcommand lives in its own module of this package with a ``register(subparsers)``
function; errors the user can fix (:class:`fusionkit.errors.FusionkitError`) print one line on
stderr and exit with status 2.

Only the module of the command being run is imported (the others load numba, SciPy or
Textual, which takes a second): ``fusionkit --help`` lists the commands from :data:`COMMANDS`.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from ..errors import FusionkitError

__all__ = ["main", "build_parser", "COMMANDS"]

#: Each subcommand, in the order ``fusionkit --help`` lists them: its module in this package
#: and its one-line help (the same words the module's ``register`` gives).
COMMANDS = {
    "run": ("run", "simulate the default scenario, merge the robots' maps and print Table 1"),
    "simulate": ("simulate", "simulate robots exploring a world; write their maps, scans and truth.json"),
    "merge": ("merge", "fuse several robots' maps into the first map's frame"),
    "evaluate": ("evaluate", "score a merged map against the simulation's ground truth"),
    "import": ("importer", "convert a real robot log (CARMEN, ROS bag) into robot logs and maps"),
    "export": ("export", "write a simulated run as a ROS bag"),
    "tui": ("tui", "terminal UI: pick robot maps, watch the PSO converge, export the merged map"),
    "bench": ("bench", "compare merging methods on seeded cases made from ground-truth maps"),
}

#: The subcommand modules, in listing order.
COMMAND_MODULES = tuple(module for module, _ in COMMANDS.values())


def _command_of(argv) -> str | None:
    """The subcommand named in ``argv`` (its first word that is not an option), if any."""
    for word in argv:
        if not word.startswith("-"):
            return word if word in COMMANDS else None
    return None


def build_parser(argv=None) -> argparse.ArgumentParser:
    """The parser of the command line.

    With ``argv``, only the subcommand it names is set up in full (the others are listed by
    name and help); without, every subcommand is.
    """
    parser = argparse.ArgumentParser(
        prog="fusionkit",
        description="Multi-robot occupancy-grid map fusion: simulate robots, find the rigid\n"
                    "transforms between their maps, fuse them and measure the result.\n"
                    "File formats (maps, scan logs, truth.json, merge report, metrics):\n"
                    "docs/formats.md. Each command explains itself: fusionkit COMMAND --help.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    from .. import __version__
    parser.add_argument("--version", action="version", version=f"fusionkit {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    wanted = None if argv is None else _command_of(argv)
    for name, (module, help_text) in COMMANDS.items():
        if argv is None or name == wanted:
            importlib.import_module(f".{module}", __name__).register(sub)
        else:
            sub.add_parser(name, help=help_text)
    return parser


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(argv)
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
