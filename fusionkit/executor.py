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
import logging
import multiprocessing
import os
import signal
import threading
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, ThreadPoolExecutor, wait
from typing import Any, Callable, Iterator, Sequence

from . import _signals
from .errors import InputError

__all__ = ["Executor", "InProcess", "LocalProcesses", "DaskExecutor", "make_executor", "using",
           "current_executor", "BACKENDS", "worker_setup"]

#: Back-end names accepted by :func:`make_executor`.
BACKENDS = ("inprocess", "processes", "dask")

Progress = Callable[[int, int], None]


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
# per worker process: shared data by token (LocalProcesses sets it in the pool's initializer)
_SHARED: dict = {}


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
        if not isinstance(threads, int) or threads < 1:
            raise InputError(f"threads must be a whole number >= 1, got {threads!r}")
        self.workers = threads

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


def _process_init(token, shared):
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
        if not isinstance(workers, int) or workers < 1:
            raise InputError(f"workers must be a whole number >= 1, got {workers!r}")
        self.workers = workers
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
                                                 initargs=(self._token, shared))
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


def _answers(url: str, timeout: float = 2.0) -> bool:
    """Whether ``url`` answers an HTTP GET with a page (not 404)."""
    import urllib.error
    import urllib.request

    try:
        with urllib.request.urlopen(url, timeout=timeout) as r:   # noqa: S310 - the user's scheduler
            return 200 <= r.status < 400
    except (urllib.error.URLError, OSError, ValueError):
        return False


class _NotCancelled(logging.Filter):
    """Drops a Dask worker's warning that a task ended cancelled: a run stopped by Ctrl-C
    cancels the tasks in flight on purpose, and its one line says so."""

    def filter(self, record: logging.LogRecord) -> bool:
        return "CancelledError" not in record.getMessage()


def _dask_call(fn, shared, task):
    worker_setup()
    log = logging.getLogger("distributed.worker.state_machine")
    if not any(isinstance(f, _NotCancelled) for f in log.filters):
        log.addFilter(_NotCancelled())
    return fn(shared, task)


class DaskExecutor(Executor):
    """Tasks on a ``dask.distributed`` cluster.

    Parameters
    ----------
    workers : int, optional
        Start a ``LocalCluster`` of this many worker processes (one thread each) on the
        loopback interface.
    address : str, optional
        Connect to the scheduler at ``tcp://HOST:PORT`` instead (its workers must have the same
        fusionkit installed).
    timeout : float
        Seconds to wait for the scheduler to answer.
    dashboard : bool
        Serve the dashboard of a ``LocalCluster`` (on a free port; needs ``bokeh``).

    Raises
    ------
    InputError
        Dask is not installed, or the scheduler does not answer within ``timeout``.
    """

    name = "dask"

    def __init__(self, workers: int | None = None, *, address: str | None = None,
                 timeout: float = 10.0, dashboard: bool = True):
        if (workers is None) == (address is None):
            raise InputError("give the Dask back end either a number of workers or a scheduler address")
        try:
            import dask  # noqa: F401
            from distributed import Client, LocalCluster
        except ImportError:
            raise InputError("the Dask back end needs dask and distributed: "
                             "pip install 'fusionkit[dask]'") from None
        self._cluster = None
        self._answered: dict = {}   # dashboard link -> whether it serves pages
        self._client = None
        self._dashboard = False
        self._shared = None
        self._shared_of = None
        if address is not None:
            if not isinstance(address, str) or "://" not in address:
                raise InputError(f"scheduler address {address!r}: give it as tcp://HOST:PORT")
            try:
                self._client = Client(address, timeout=f"{float(timeout)}s", set_as_default=False)
            except (OSError, TimeoutError) as exc:
                raise InputError(f"no Dask scheduler answered at {address} within {timeout:g} s "
                                 f"({type(exc).__name__}); check the address and that the "
                                 f"scheduler is running") from None
            try:
                self._client.wait_for_workers(1, timeout=float(timeout))
            except (OSError, TimeoutError):
                self.close()
                raise InputError(f"the Dask scheduler at {address} has no workers (waited "
                                 f"{timeout:g} s); start some with dask worker {address}") from None
            self.workers = max(1, sum(w.get("nthreads", 1) for w in
                                      self._client.scheduler_info().get("workers", {}).values()))
            self._dashboard = True
        else:
            if not isinstance(workers, int) or workers < 1:
                raise InputError(f"workers must be a whole number >= 1, got {workers!r}")
            self.workers = workers
            if dashboard:
                try:
                    import bokeh  # noqa: F401
                except ImportError:
                    dashboard = False
            # everything on the loopback interface, on free ports (the scheduler's small HTTP
            # server too, which serves the dashboard when asked for and bokeh is installed)
            # a Ctrl-C at the terminal reaches every process of its group: this process (its
            # handler kept while the cluster starts), not each worker, stops the run and closes
            # the cluster; the workers ignore it from their first import on (_dask_worker)
            try:
                self._cluster = LocalCluster(n_workers=workers, threads_per_worker=1,
                                             processes=True, host="127.0.0.1",
                                             dashboard_address="127.0.0.1:0",
                                             worker_dashboard_address=None,
                                             preload=["fusionkit._dask_worker"],
                                             scheduler_kwargs={"dashboard": bool(dashboard)})
                self._client = Client(self._cluster, set_as_default=False)
            except BaseException:
                self.close()
                raise
            self._dashboard = bool(dashboard)

    @property
    def client(self):
        """The ``distributed.Client``."""
        return self._client

    @property
    def dashboard(self) -> str | None:
        if self._client is None or not self._dashboard:
            return None
        if "dashboard" not in self._client.scheduler_info().get("services", {}):
            return None                                   # bokeh is not installed there
        link = self._client.dashboard_link or None
        if link is not None and self._cluster is None:
            # a scheduler started elsewhere serves its HTTP port without the dashboard pages
            # when bokeh is missing or --no-dashboard was given: asked once
            if link not in self._answered:
                self._answered[link] = _answers(link)
            return link if self._answered[link] else None
        return link

    def describe(self) -> str:
        where = self._client.scheduler.address if self._client is not None else "closed"
        dash = self.dashboard
        return (f"dask: {self.workers} worker{'s' if self.workers != 1 else ''} at {where}; "
                f"dashboard: {dash if dash else 'none (install bokeh for one)'}")

    def map(self, fn, tasks, *, shared=None, progress=None):
        from distributed import as_completed
        tasks = list(tasks)
        total = len(tasks)
        if progress is not None:
            progress(0, total)
        if not total:
            return []
        client = self._client
        # the shared data goes to every worker once (and stays there for the next map with the
        # same object); tasks refer to it
        if shared is not self._shared_of:
            self._drop_shared()
            self._shared = client.scatter(shared, broadcast=True, hash=False) \
                if shared is not None else None
            self._shared_of = shared
        handle = self._shared
        futures = client.map(_dask_call, [fn] * total, [handle] * total, tasks, pure=False)
        index = {f.key: n for n, f in enumerate(futures)}
        out: list = [None] * total
        done = 0
        try:
            for f in as_completed(futures, loop=client.loop):
                out[index[f.key]] = f.result()
                done += 1
                if progress is not None:
                    progress(done, total)
        finally:
            client.cancel(futures)
        return out

    def _drop_shared(self) -> None:
        if self._shared is not None and self._client is not None:
            self._client.cancel([self._shared])
        self._shared = None
        self._shared_of = None

    def close(self) -> None:
        # a worker slow to exit is killed by its nanny: expected here, not worth a warning
        log = logging.getLogger("distributed")
        level = log.level
        log.setLevel(logging.ERROR)
        try:
            self._drop_shared()
            if self._client is not None:
                self._client.close()
                self._client = None
            if self._cluster is not None:
                self._cluster.close()
                self._cluster = None
        finally:
            log.setLevel(level)


def make_executor(backend: str | None = None, *, workers: int | None = None,
                  scheduler: str | None = None, timeout: float = 10.0,
                  dashboard: bool = True) -> Executor:
    """The executor the command line asks for.

    ``scheduler`` implies Dask; ``workers`` alone gives local processes unless ``backend`` is
    ``"dask"``; nothing gives :class:`InProcess` (serial).
    """
    if backend is not None and backend not in BACKENDS:
        raise InputError(f"unknown back end {backend!r}; choose one of {', '.join(BACKENDS)}")
    if scheduler is not None:
        if backend not in (None, "dask"):
            raise InputError(f"--scheduler is a Dask scheduler; it cannot be used with --backend {backend}")
        return DaskExecutor(address=scheduler, timeout=timeout)
    if workers is not None and (not isinstance(workers, int) or workers < 1):
        raise InputError(f"workers must be a whole number >= 1, got {workers!r}")
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
    """Within this block, :func:`fusionkit.pipeline.merge` runs its pair stage on ``executor``."""
    token = _CURRENT.set(executor)
    try:
        yield executor
    finally:
        _CURRENT.reset(token)
