"""Starting and stopping ROS 2 from the command line: a missing install, bad ``--ros-args`` or
an unreadable parameter file is one line and exit 2; Ctrl-C (or SIGTERM) ends cleanly."""

from __future__ import annotations

import contextlib
import os
import re
from pathlib import Path

from .. import InputError

__all__ = ["require_rclpy", "ros_context", "ros_argv", "check_params_file"]


def require_rclpy():
    """The ``rclpy`` module, or an InputError saying how to install it."""
    try:
        import rclpy
        import nav_msgs.msg  # noqa: F401
        import geometry_msgs.msg  # noqa: F401
        import std_msgs.msg  # noqa: F401
    except ImportError as exc:
        raise InputError(f"ROS 2 for Python is not installed ({exc}); install it with "
                         f"pip install -e \".[ros2]\" (wheels, no ROS installation needed)") from None
    return rclpy


#: The largest parameter file read (a parameter file is a few lines of YAML)
MAX_PARAMS_BYTES = 16 * 2**20


def check_params_file(path) -> None:
    """Refuse, in one line that says what to fix, a parameter file rcl would refuse in its own
    words (a C source path, the whole ``--ros-args``) or would read as no parameters at all:
    missing, a folder, not YAML, YAML aliases (rcl does not read them), not a mapping."""
    import yaml

    from .._inputs import read_bytes

    path = Path(path)
    if path.is_dir():
        raise InputError(f"{path}: is a folder, not a parameter file; give a ROS 2 parameter "
                         f"YAML (NODE_NAME: ros__parameters: ...)")
    if not path.is_file():
        raise InputError(f"{path}: parameter file not found; give a ROS 2 parameter YAML "
                         f"(NODE_NAME: ros__parameters: ...)")
    text = read_bytes(path, "parameter file", MAX_PARAMS_BYTES)
    try:
        if any(isinstance(ev, yaml.AliasEvent) for ev in yaml.parse(text, Loader=yaml.SafeLoader)):
            raise InputError(f"{path}: uses YAML aliases (*name), which ROS 2 does not read; "
                             f"write the values out")
        doc = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        what = getattr(exc, "problem", None) or type(exc).__name__
        raise InputError(f"{path}: not valid YAML{where} ({what}); fix the parameter file") from None
    if not isinstance(doc, dict):
        held = ("nothing" if doc is None else "a list" if isinstance(doc, list) else
                "a text" if isinstance(doc, str) else "a value")
        raise InputError(f"{path}: a parameter file maps node names to 'ros__parameters:' "
                         f"(map_merge: ros__parameters: ...); this one holds {held}")


def ros_argv(prog: str, ros_args=(), params_files=()) -> list[str]:
    """The argument list for ``rclpy.init``: ``--ros-args`` then every parameter file (each
    checked by :func:`ros_context`, as one given inside ``ros_args`` is)."""
    argv = [prog, "--ros-args", *ros_args]
    for f in params_files:
        argv += ["--params-file", os.fspath(f)]
    return argv


@contextlib.contextmanager
def _stderr_held():
    """Hold what C code writes on stderr (rcl logs its own line before raising); let it out
    only when the block succeeds, so that a bad argument is reported in one line."""
    import sys
    import tempfile

    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as held:
        os.dup2(held.fileno(), 2)
        ok = False
        try:
            yield
            ok = True
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            if ok:
                held.seek(0)
                text = held.read()
                if text:
                    os.write(2, text)


def _params_files(argv) -> list[str]:
    """The parameter files of an ``rclpy`` argument list (each after ``--params-file``)."""
    if argv and argv[-1] == "--params-file":
        raise InputError("--params-file: give the parameter file after it")
    return [b for a, b in zip(argv, argv[1:]) if a == "--params-file"]


@contextlib.contextmanager
def ros_context(argv):
    """``rclpy`` initialised with ``argv``; shut down on the way out however it is left
    (Ctrl-C and SIGTERM end the block without a traceback)."""
    rclpy = require_rclpy()
    from rclpy.executors import ExternalShutdownException

    for f in _params_files(argv):
        check_params_file(f)
    try:
        with _stderr_held():
            rclpy.init(args=list(argv))
    except Exception as exc:  # noqa: BLE001 - rcl reports bad arguments as RCLError
        why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        why = re.sub(r",? at /\S+:\d+", "", why)  # rcl's C source places say nothing to the user
        raise InputError(f"ROS arguments {' '.join(argv[1:])!r} not understood: {why}") from None
    try:
        yield rclpy
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        rclpy.try_shutdown()


def unapplied_params_files(paths, node_name: str) -> list[str]:
    """The parameter files among ``paths`` with no section for the node ``node_name`` (its
    fully qualified name, ``/map_merge``): rcl applies none of their parameters, silently (a file
    written for another node, or for a node renamed since). Sections are found as rcl reads them:
    the names leading to a ``ros__parameters:`` key, nested names joined by ``/``, with the
    wildcards ``*`` (one name) and ``/**`` (any names)."""
    import yaml

    def sections(doc, prefix=""):
        if isinstance(doc, dict):
            for k, v in doc.items():
                if k == "ros__parameters":
                    yield prefix or "/"
                elif isinstance(k, str):
                    yield from sections(v, f"{prefix}/{k.strip('/')}")

    def applies(section: str) -> bool:
        rx = re.escape(section).replace(r"/\*\*", r"(?:/.*)?").replace(r"\*", r"[^/]*")
        return re.fullmatch(rx, node_name) is not None

    out = []
    for p in paths:
        try:
            doc = yaml.safe_load(Path(p).read_text(encoding="utf-8"))
        except (OSError, ValueError, yaml.YAMLError):
            continue   # refused before the node starts (check_params_file)
        if not any(applies(s) for s in sections(doc)):
            out.append(str(p))
    return out
