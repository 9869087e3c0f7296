"""The ``fusionkit`` command line.

Each subcommand lives in its own module of this package with a ``register(subparsers)``
function; errors the user can fix (:class:`fusionkit.errors.FusionkitError`, and any OS error
such as a read-only folder) print one line on stderr and exit with status 2; SIGINT exits 130
and SIGTERM 143, each with one line.

Only the module of the command being run is imported (the others load numba, SciPy or
Textual, which takes a second): ``fusionkit --help`` lists the commands from :data:`COMMANDS`.
"""

from __future__ import annotations

import argparse
import importlib
import re
import sys

from .. import _signals
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
    "ros2": ("ros2", "ROS 2: a live merge node (drop-in for multirobot_map_merge), a run player"),
}

#: The subcommand modules, in listing order.
COMMAND_MODULES = tuple(module for module, _ in COMMANDS.values())


#: The kinds of the subcommands that have kinds (``fusionkit import carmen``), as their
#: modules register them: an interrupt while those load names the command whole.
KINDS = {"import": ("carmen", "rosbag"), "export": ("rosbag",), "ros2": ("merge-node", "play")}


def _command_of(argv) -> str | None:
    """The subcommand named in ``argv`` (its first word that is not an option), if any."""
    for word in argv:
        if not word.startswith("-"):
            return word if word in COMMANDS else None
    return None


def _named(argv) -> str | None:
    """The subcommand named in ``argv`` with its kind, if given ("import carmen")."""
    command = _command_of(argv)
    if command not in KINDS:
        return command
    words = [w for w in argv if not w.startswith("-")]
    kind = words[1] if len(words) > 1 else None
    return f"{command} {kind}" if kind in KINDS[command] else command


class _Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line, ending with where the options are
    explained (its subcommands' parsers are of this class too)."""

    def parse_known_args(self, args=None, namespace=None):
        # the words this (sub)command was given, to name a mistyped option in an error
        self._given = list(sys.argv[1:] if args is None else args)
        return super().parse_known_args(args, namespace)

    def error(self, message: str):
        unknown = self._unknown_options()
        if unknown and message.startswith("the following arguments are required"):
            # a mistyped option (--ouput) leaves the one it meant missing: name the typo
            message = f"unrecognized arguments: {' '.join(unknown)}"
        if message.startswith("unrecognized arguments:"):
            message += self._did_you_mean(unknown)
        _say(f"{self.prog}: error: {_one_line(message)}; see {self.prog} --help")
        raise SystemExit(2)

    def _unknown_options(self) -> list[str]:
        """The words given to this parser that look like options it does not have (before
        any ``--``; negative numbers and abbreviations argparse accepts are not counted)."""
        known = set(self._option_string_actions)
        unknown = []
        for word in getattr(self, "_given", []):
            if word == "--":
                break
            name = word.split("=", 1)[0]
            if (not word.startswith("-") or word == "-" or name in known or name[:2] in known
                    or _NUMBER.fullmatch(word)
                    or (name.startswith("--") and self.allow_abbrev
                        and any(k.startswith(name) for k in known))):
                continue
            unknown.append(name)
        return unknown

    def _did_you_mean(self, unknown: list[str]) -> str:
        import difflib

        options = sorted(k for k in self._option_string_actions if k.startswith("--"))
        hints = [m[0] for name in unknown
                 if (m := difflib.get_close_matches(name, options, n=1, cutoff=0.7))]
        return f" (did you mean {' or '.join(hints)}?)" if hints else ""


#: a negative number given as an option's value (``--seed -1``)
_NUMBER = re.compile(r"-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")


def build_parser(argv=None) -> argparse.ArgumentParser:
    """The parser of the command line.

    With ``argv``, only the subcommand it names is set up in full (the others are listed by
    name and help); without, every subcommand is.
    """
    parser = _Parser(
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
    """Run one command; return its exit status.

    0 done (3: some maps left out of a merge), 2 bad input (one line on stderr, no
    traceback), 130 interrupted by SIGINT (Ctrl-C), 143 stopped by SIGTERM. An interrupted
    command leaves its outputs as they were before it started.
    """
    if argv is None:   # the program itself: once its command is done, a Ctrl-C is too late
        try:
            with _signals.watching():
                return _main(None)
        finally:
            # Python restores SIGINT's default action as it shuts down: a Ctrl-C in the
            # 0.1 s that takes killed a command that had finished, with no word
            _quiet_signals()
    with _signals.watching():
        return _main(argv)


def _main(argv) -> int:
    command = "fusionkit"
    atomic = sys.modules.get("fusionkit._atomic")
    if atomic is not None:   # what an earlier command of this process wrote is not ours
        atomic.COMMITTED.clear()
    try:
        _signals.install()
        argv = sys.argv[1:] if argv is None else list(argv)
        named = _named(argv)
        if named:   # an interrupt while the command's modules load still names it
            command = f"fusionkit {named}"
        parser = build_parser(argv)
        args, extra = parser.parse_known_args(argv)
        if extra:   # said by the (sub)command they were given to
            _innermost(parser, args, argv, extra).error(f"unrecognized arguments: {' '.join(extra)}")
        # named as its parser names it in a usage error: "fusionkit import carmen"
        command = " ".join(["fusionkit", args.command] + [
            str(v) for v in (getattr(args, k, None) for k in ("kind", "ros2_command")) if v])
        code = int(args.func(args) or 0)
        lost = _signals.swallowed()   # a Ctrl-C a library swallowed: said, not lost
        return code if lost is None else _interrupted(command, argv, lost)
    except KeyboardInterrupt as exc:  # SIGINT, or SIGTERM as _signals.Terminated
        return _interrupted(command, argv, exc)
    except SystemError as exc:
        # a compiled function (a numba kernel's dispatcher) that was running Python code when
        # the signal's exception was raised there reports it as its own failure, the
        # interrupt as its cause
        cause = exc.__cause__ or exc.__context__
        if not isinstance(cause, KeyboardInterrupt):
            raise
        return _interrupted(command, argv, cause)
    except FusionkitError as exc:
        _say(f"{command}: error: {_one_line(exc)}")
        return 2
    except BrokenPipeError:  # the reader of our output went away (e.g. `| head`)
        _quiet_stdout()
        return 0
    except OSError as exc:
        from .._atomic import show

        where = f"{show(str(exc.filename), 200)}: " if exc.filename else ""
        _say(f"{command}: error: {where}{exc.strerror or exc.__class__.__name__}; check the path, "
             f"its permissions and the free disk space")
        return 2
    except MemoryError:
        _say(f"{command}: error: out of memory; give smaller inputs")
        return 2
    except RecursionError:
        _say(f"{command}: error: an input is nested too deeply to read; check the files given")
        return 2
    except RuntimeError as exc:
        loop = re.fullmatch(r"Symlink loop from '?(.+?)'?", str(exc))   # pathlib's resolve()
        if loop is not None:
            _say(f"{command}: error: {loop.group(1)}: a loop of symbolic links; check the path")
            return 2
        lost = _signals.swallowed()
        if lost is None:
            raise
        return _interrupted(command, argv, lost)
    except Exception:
        # an interrupt a library turned into its own error while it loaded (numba's "Error
        # calling __set_name__", an ImportError) is the interrupt
        lost = _signals.swallowed()
        if lost is None:
            raise
        return _interrupted(command, argv, lost)


def _interrupted(command: str, argv, exc: KeyboardInterrupt) -> int:
    """Say that ``command`` was stopped by SIGINT, SIGTERM or SIGHUP (``exc``) and what it
    left; its exit status."""
    _quiet_signals()
    _signals.forget()
    if _command_of(sys.argv[1:] if argv is None else list(argv)) == "ros2":
        # the ROS 2 commands run until stopped and write nothing: stopped while they start
        # up, they end as they do once running, with exit 0
        return 0
    how = ("hung up" if isinstance(exc, _signals.HungUp) else
           "terminated" if isinstance(exc, _signals.Terminated) else "interrupted")
    atomic = sys.modules.get("fusionkit._atomic")
    written = list(atomic.COMMITTED) if atomic is not None else []
    if written:   # the signal came after a set of outputs was committed: that one is new
        _say(f"{command}: {how} after writing {_one_line(written[-1])} (its set of outputs is "
             f"whole and new); nothing was left half-written")
    else:
        _say(f"{command}: {how}; no output was left half-written")
    return _signals.exit_status(exc)


def _innermost(parser: argparse.ArgumentParser, args, argv, extra) -> argparse.ArgumentParser:
    """The parser of the (sub)command the ``extra`` words were given to: the innermost one
    ``args`` were parsed by (``fusionkit import carmen``'s, not ``fusionkit``'s), or an outer one
    when they stand before the name of the command inside it."""
    pos = 0
    while True:
        subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        name = getattr(args, subs[0].dest, None) if subs and subs[0].dest else None
        if name not in (subs[0].choices if subs else {}) or name not in argv[pos:]:
            return parser
        at = argv.index(name, pos)
        if any(word in extra for word in argv[pos:at]):
            return parser
        parser, pos = subs[0].choices[name], at + 1


def _one_line(exc) -> str:
    text = str(exc).replace("\x00", "\\x00")
    text = " ".join(text.split("\n"))
    return text if len(text) <= 2000 else text[:1000] + " ... " + text[-500:]


def _say(line: str) -> None:
    try:
        print(line, file=sys.stderr, flush=True)
    except (OSError, ValueError):
        pass


def _quiet_signals() -> None:
    """Ignore further Ctrl-C, SIGTERM or SIGHUP while the process exits (no second traceback)."""
    import signal

    for s in _signals._SIGNALS:
        try:
            signal.signal(s, signal.SIG_IGN)
        except (ValueError, OSError):
            pass


def _quiet_stdout() -> None:
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass
