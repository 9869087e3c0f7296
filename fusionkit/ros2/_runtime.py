"""Starting and stopping ROS 2 from the command line: a missing install, bad ``--ros-args`` or
an unreadable parameter file is one line and exit 2; Ctrl-C (or SIGTERM) ends cleanly."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

from .. import InputError

__all__ = ["require_rclpy", "ros_context", "ros_argv"]


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


def ros_argv(prog: str, ros_args=(), params_files=()) -> list[str]:
    """The argument list for ``rclpy.init``: ``--ros-args`` then every parameter file."""
    argv = [prog, "--ros-args", *ros_args]
    for f in params_files:
        path = Path(f)
        if not path.is_file():
            raise InputError(f"{path}: parameter file not found; give a ROS 2 parameter YAML "
                             f"(NODE_NAME: ros__parameters: ...)")
        argv += ["--params-file", os.fspath(path)]
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


@contextlib.contextmanager
def ros_context(argv):
    """``rclpy`` initialised with ``argv``; shut down on the way out however it is left
    (Ctrl-C and SIGTERM end the block without a traceback)."""
    rclpy = require_rclpy()
    from rclpy.executors import ExternalShutdownException

    for i, a in enumerate(argv):
        if a == "--params-file" and (i + 1 >= len(argv) or not Path(argv[i + 1]).is_file()):
            raise InputError(f"--params-file {argv[i + 1] if i + 1 < len(argv) else ''}: "
                             f"parameter file not found")
    try:
        with _stderr_held():
            rclpy.init(args=list(argv))
    except Exception as exc:  # noqa: BLE001 - rcl reports bad arguments as RCLError
        raise InputError(f"ROS arguments {' '.join(argv[1:])!r} not understood: "
                         f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None
    try:
        yield rclpy
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        rclpy.try_shutdown()
