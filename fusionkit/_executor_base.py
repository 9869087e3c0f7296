"""What every back end of :mod:`fusionkit.executor` shares: the :class:`Executor` interface and
the set-up of a worker process (here so that the Dask back end, a module of its own, needs
nothing else of :mod:`fusionkit.executor`)."""

from __future__ import annotations

import os
import threading
import time
from typing import Any, Callable, Sequence

__all__ = ["Executor", "Progress", "worker_setup", "exit_with_parent", "check_local_workers"]

Progress = Callable[[int, int], None]

#: Most worker processes started on this machine, per core
WORKERS_PER_CORE = 8


def check_local_workers(workers, name: str = "workers", *, said: str | None = None,
                        cluster: str = "a scheduler's address") -> int:
    """``workers`` (the argument ``name``), a whole number from 1 to :data:`WORKERS_PER_CORE`
    a core of this machine, or :class:`InputError` (``said`` names it on a command line:
    ``"--workers 1000"``). A typo, 1000 for 10, started a thousand processes on two cores and
    took minutes to stop."""
    from .errors import InputError

    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise InputError(f"{name} must be a whole number >= 1, got {workers!r}")
    cores = os.cpu_count() or 1
    if workers > WORKERS_PER_CORE * cores:
        raise InputError(f"{said or f'{name}={workers}'} would start {workers} workers on this "
                         f"machine's {cores} cores; give at most {WORKERS_PER_CORE * cores} "
                         f"({WORKERS_PER_CORE} a core), or {cluster} for a cluster")
    return workers


def worker_setup() -> None:
    """Run once in every worker process: one thread per worker for numba and OpenCV, so that
    workers sharing the cores do not oversubscribe them (results do not depend on it)."""
    global _SET_UP
    if _SET_UP:
        return
    _SET_UP = True
    import cv2
    import numba
    numba.set_num_threads(1)
    cv2.setNumThreads(1)


_SET_UP = False


def exit_with_parent(parent: int, every: float = 0.5) -> None:
    """End this worker process when ``parent``, the process that started it (its pid, as the
    parent gave it: one killed before this worker started is not its parent any more), is gone
    (killed with ``kill -9``, it can tell its workers nothing: they ran on for good, blocked
    writing results to a pipe nobody reads). A daemon thread looks every ``every`` seconds."""
    if os.getppid() != parent:
        os._exit(1)

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(every)
        os._exit(1)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


class Executor:
    """Runs ``fn(shared, task)`` for every task and returns the results in task order.

    Attributes
    ----------
    name : str
        Back-end name (one of :data:`BACKENDS`).
    workers : int
        Tasks run at once.
    """

    name = "executor"
    workers = 1

    def map(self, fn: Callable[[Any, Any], Any], tasks: Sequence, *, shared: Any = None,
            progress: Progress | None = None) -> list:
        """``[fn(shared, t) for t in tasks]``, run on this back end.

        ``progress(done, total)`` is called in the calling thread as tasks finish. An exception
        raised by a task is raised here.
        """
        raise NotImplementedError

    @property
    def dashboard(self) -> str | None:
        """Address of a live dashboard, or None."""
        return None

    def describe(self) -> str:
        """One line for the terminal: back end, workers, and dashboard where there is one."""
        return f"{self.name}: {self.workers} worker{'s' if self.workers != 1 else ''}"

    def close(self) -> None:
        """Release workers and connections (idempotent)."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
