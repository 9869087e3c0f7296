"""Where independent tasks run: in this process, in local processes, or on a Dask cluster.

The pair stage of :func:`fusionkit.pipeline.merge` (consensus method) and the cases of
:func:`fusionkit.bench.run_bench` are lists of independent tasks. Each is a plain function
``fn(shared, task)``: ``shared`` is data every task reads (a fleet's prepared maps), sent to each
worker once; ``task`` is small and carries everything else, seeds included. Results come back in
task order whatever finishes first, so a run gives the same results, bit for bit, on every back
end and any number of workers.

Back ends:

:class:`InProcess`
    Serial (``threads=1``, the default) or on a thread pool in this process.
:class:`LocalProcesses`
    A pool of fresh interpreters on this machine (``spawn``; each worker runs one thread).
:class:`DaskExecutor`
    ``dask.distributed`` (the optional ``[dask]`` extra): a ``LocalCluster`` of ``workers``
    processes, or the scheduler at ``address`` (``tcp://HOST:PORT``) of an existing cluster whose
    workers have fusionkit installed. ``shared`` is scattered to every worker once.

:func:`make_executor` builds one from the command line's ``--backend/--workers/--scheduler``;
:func:`using` makes an executor the one :func:`fusionkit.pipeline.merge` uses.
"""

from __future__ import annotations

import contextlib
import contextvars
import multiprocessing
import os
import signal
import threading
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, ThreadPoolExecutor, wait
from typing import Iterator

from . import _signals
from ._executor_base import Executor, check_local_workers, exit_with_parent, worker_setup
from .errors import InputError

__all__ = ["Executor", "InProcess", "LocalProcesses", "DaskExecutor", "make_executor", "using",
           "current_executor", "BACKENDS", "worker_setup"]

#: Back-end names accepted by :func:`make_executor`.
BACKENDS = ("inprocess", "processes", "dask")

# per worker process: shared data by token (LocalProcesses sets it in the pool's initializer)
_SHARED: dict = {}


def _ordered(submit, tasks, progress, workers) -> list:
    """Submit with at most ``2 * workers`` tasks in flight; gather in task order."""
    total = len(tasks)
    out: list = [None] * total
    pending: dict = {}
    nxt = done = 0
    if progress is not None:
        progress(0, total)
    while done < total:
        while nxt < total and len(pending) < 2 * workers:
            pending[submit(tasks[nxt])] = nxt
            nxt += 1
        finished, _ = wait(list(pending), return_when=FIRST_COMPLETED)
        for f in finished:
            out[pending.pop(f)] = f.result()
            done += 1
        if progress is not None:
            progress(done, total)
    return out


class InProcess(Executor):
    """Tasks in this process: one after the other (``threads=1``) or on ``threads`` threads
    (the numba and OpenCV kernels release the interpreter)."""

    name = "inprocess"

    def __init__(self, threads: int = 1):
        self.workers = check_local_workers(threads, "threads")

    def map(self, fn, tasks, *, shared=None, progress=None):
        tasks = list(tasks)
        if self.workers == 1 or len(tasks) <= 1:
            out = []
            if progress is not None:
                progress(0, len(tasks))
            for t in tasks:
                out.append(fn(shared, t))
                if progress is not None:
                    progress(len(out), len(tasks))
            return out
        with ThreadPoolExecutor(max_workers=self.workers) as pool:
            return _ordered(lambda t: pool.submit(fn, shared, t), tasks, progress, self.workers)


def _process_init(token, shared, parent):
    exit_with_parent(parent)
    worker_setup()
    _SHARED.clear()
    _SHARED[token] = shared


def _process_call(fn, token, task):
    return fn(_SHARED[token], task)


@contextlib.contextmanager
def _sigint_held() -> Iterator[None]:
    """SIGINT (and SIGTERM) held back for the block (the main thread only; delivered as usual,
    a KeyboardInterrupt, right after it).

    A pool starts a worker when a task is submitted and none is idle. The worker keeps the
    blocked signal for its life (the mask goes through ``exec``): a Ctrl-C at the terminal
    reaches every process of its group, and this process, not each worker, is the one to stop
    the run (each worker printed a traceback). And an interrupt can no longer land in the
    middle of starting a worker, which left workers that nobody told to end (the exit waited
    for them for ever) or raised from deep inside the import of the task's data.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    # blocked in this thread, for the worker to inherit; held back by the handler too, for a
    # signal sent to the process is taken by any thread that does not block it
    before = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        with _signals.deferred():
            yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, before)


class LocalProcesses(Executor):
    """A pool of ``workers`` fresh interpreters (``spawn``: forking a process whose numba
    kernels started threads is unsafe). ``shared`` is sent to each worker once, when the pool
    starts; the pool serves every :meth:`map` with the same ``shared`` object until
    :meth:`close`."""

    name = "processes"

    def __init__(self, workers: int = 2):
        self.workers = check_local_workers(workers)
        self._token = 0
        self._pool = None
        self._pool_shared = None
        self._children_before: set = set()

    def map(self, fn, tasks, *, shared=None, progress=None):
        tasks = list(tasks)
        try:
            if self._pool is None or self._pool_shared is not shared:
                # a pool per shared data: its workers received it once, when they started
                self.close()
                self._token += 1
                self._children_before = set(multiprocessing.active_children())
                ctx = multiprocessing.get_context("spawn")
                self._pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=ctx,
                                                 initializer=_process_init,
                                                 initargs=(self._token, shared, os.getpid()))
                self._pool_shared = shared
            pool, token = self._pool, self._token

            def submit(t):
                with _sigint_held():
                    return pool.submit(_process_call, fn, token, t)

            return _ordered(submit, tasks, progress, self.workers)
        except BaseException:
            # Ctrl-C, SIGTERM or a failed task: the workers are stopped, not waited for. An
            # interrupt that lands while the pool starts its workers leaves workers that no
            # one tells to end, and the interpreter's exit then waits for them for ever.
            self._stop_workers()
            raise

    def _stop_workers(self) -> None:
        pool, self._pool, self._pool_shared = self._pool, None, None
        if pool is None:
            return
        # the pool's workers, and children started since the pool was (a worker being
        # spawned is not yet in the pool's table)
        procs = set((getattr(pool, "_processes", None) or {}).values())
        procs |= set(multiprocessing.active_children()) - self._children_before
        manager = getattr(pool, "_executor_manager_thread", None)
        for p in procs:
            p.terminate()
        for p in procs:
            p.join(5)
            if p.is_alive():
                p.kill()
                p.join(5)
        pool.shutdown(wait=False, cancel_futures=True)
        if manager is not None:
            # the pool's thread sees its workers gone and ends; joined here, it is not woken
            # again at exit through a pipe it has closed ("Bad file descriptor")
            manager.join(10)

    def close(self) -> None:
        if self._pool is not None:
            try:
                self._pool.shutdown(wait=True, cancel_futures=True)
            except BaseException:   # interrupted while the workers end: they are stopped
                self._stop_workers()
                raise
            self._pool = None
            self._pool_shared = None


def __getattr__(name: str):
    # the Dask back end is a module of its own, read only when it is used
    if name == "DaskExecutor":
        from ._dask import DaskExecutor
        return DaskExecutor
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def make_executor(backend: str | None = None, *, workers: int | None = None,
                  scheduler: str | None = None, timeout: float = 10.0,
                  dashboard: bool = True) -> Executor:
    """The executor the command line asks for.

    ``scheduler`` implies Dask; ``workers`` alone gives local processes unless ``backend`` is
    ``"dask"``; nothing gives :class:`InProcess` (serial).
    """
    if backend is not None and backend not in BACKENDS:
        raise InputError(f"unknown back end {backend!r}; choose one of {', '.join(BACKENDS)}")
    from ._dask import DaskExecutor

    if scheduler is not None:
        if backend not in (None, "dask"):
            raise InputError(f"--scheduler is a Dask scheduler; it cannot be used with --backend {backend}")
        return DaskExecutor(address=scheduler, timeout=timeout)
    if workers is not None:
        check_local_workers(workers)
    if backend == "dask":
        return DaskExecutor(workers or os.cpu_count() or 1, timeout=timeout, dashboard=dashboard)
    if backend == "processes" or (backend is None and workers is not None and workers > 1):
        return LocalProcesses(workers or os.cpu_count() or 1)
    return InProcess(workers or 1)


_CURRENT: contextvars.ContextVar = contextvars.ContextVar("fusionkit_executor", default=None)


def current_executor() -> Executor | None:
    """The executor set by :func:`using`, or None."""
    return _CURRENT.get()


@contextlib.contextmanager
def using(executor: Executor | None) -> Iterator[Executor | None]:
    """Within this block, :func:`fusionkit.pipeline.merge` runs its pair stage on ``executor``
    (``None``: in this process). The choice holds in the thread (or asyncio task) that entered
    the block: a merge called from another thread runs in that thread, one pair after another."""
    if executor is not None and not isinstance(executor, Executor):
        # using("processes") failed deep in the merge: 'str' object has no attribute 'map'
        raise InputError(f"using() takes an Executor or None, got {executor!r}; make one with "
                         f"make_executor('processes', workers=2), for example")
    token = _CURRENT.set(executor)
    try:
        yield executor
    finally:
        _CURRENT.reset(token)
