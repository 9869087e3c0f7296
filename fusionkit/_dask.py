"""The Dask back end of :mod:`fusionkit.executor`: a ``LocalCluster`` on this machine's loopback
interface, or the cluster of a scheduler given by its address (the optional ``[dask]`` extra)."""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
import re
import signal
import socket
import threading
import time
from urllib.parse import urlsplit

from .errors import InputError
from ._executor_base import Executor, check_local_workers, worker_setup

__all__ = ["DaskExecutor"]


def _answers(url: str, timeout: float = 2.0) -> bool:
    """Whether ``url`` answers an HTTP GET with a page (not 404)."""
    import urllib.error
    import urllib.request

    try:
        with urllib.request.urlopen(url, timeout=timeout) as r:   # noqa: S310 - the user's scheduler
            # a scheduler without bokeh serves a page that says the dashboard needs it
            return 200 <= r.status < 400 and b"needs bokeh" not in r.read(4096)
    except (urllib.error.URLError, OSError, ValueError):
        return False


class _NotCancelled(logging.Filter):
    """Drops a Dask worker's warning that a task ended cancelled: a run stopped by Ctrl-C
    cancels the tasks in flight on purpose, and its one line says so."""

    def filter(self, record: logging.LogRecord) -> bool:
        return "CancelledError" not in record.getMessage()


def _quiet_dask() -> None:
    """Stopped by Ctrl-C or SIGTERM, the run ends with its one line: what the scheduler and
    its event loop log of the tasks and transfers cut short (errors, tracebacks) is not said."""
    for name in ("distributed", "distributed.client", "asyncio", "tornado"):   # (the client's
        # level is set apart by Dask's configuration)
        logging.getLogger(name).setLevel(logging.CRITICAL + 1)


#: Signals a terminal sends to every process of its foreground group, which fusionkit turns into
#: a clean stop (:mod:`fusionkit._signals`).
_TERMINAL_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGHUP") if hasattr(signal, n))


def _hold_terminal_signals():
    """Block the terminal's signals in this thread (from the main thread only, where Python
    runs its handlers); the mask before, for :func:`_release`, or None."""
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        return None
    held = signal.pthread_sigmask(signal.SIG_BLOCK, _TERMINAL_SIGNALS)
    try:
        # Python's resource tracker (a process the workers' start needs) unblocks SIGINT in
        # the thread that first starts it: started here, with the signals blocked, then
        # blocked again
        from multiprocessing import resource_tracker
        resource_tracker.ensure_running()
        signal.pthread_sigmask(signal.SIG_BLOCK, _TERMINAL_SIGNALS)
    except BaseException:
        _release(held)
        raise
    return held


def _release(held) -> None:
    if held is not None:
        signal.pthread_sigmask(signal.SIG_SETMASK, held)


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
            _check_address(address)
            _probe(address, float(timeout))
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
            # workers started elsewhere may lack fusionkit: said now, not as a task's traceback
            # (exec is Python's own, so it reaches a worker without fusionkit)
            failed = [e for e in self._client.run(exec, "import fusionkit", on_error="return").values()
                      if isinstance(e, BaseException)]
            if failed:
                self.close()
                raise InputError(f"the Dask workers at {address} cannot import fusionkit "
                                 f"({failed[0]}); install the same fusionkit (with its "
                                 f"dependencies) on every worker") from None
            # asked by value (Python's eval of this module's source): a worker's older
            # fusionkit has no such function to call
            answers = self._client.run(eval, _INSTALLED_CALL, on_error="return").values()
            other = _differences([a if isinstance(a, tuple) else (("fusionkit", repr(a)),)
                                  for a in answers])
            if other:
                self.close()
                raise InputError(f"the Dask workers at {address} run {other}; install this "
                                 f"fusionkit and the versions of its constraints.txt on every "
                                 f"worker (the same seed gives the same result only on the "
                                 f"same code)") from None
            self.workers = max(1, sum(w.get("nthreads", 1) for w in
                                      self._client.scheduler_info().get("workers", {}).values()))
            self._dashboard = True
        else:
            self.workers = check_local_workers(workers)
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
            from distributed.deploy.spec import SpecCluster
            before = set(SpecCluster._instances)
            # the terminal's signals (Ctrl-C, a hang-up) are held back while the cluster
            # starts: every thread it starts (Dask's event loop, which spawns the workers and
            # Python's resource tracker) and every process those start inherit them blocked,
            # so only this process stops the run and closes the cluster; a worker still loading
            # Dask printed a traceback, and a hang-up killed the resource tracker, whose
            # successor printed one per worker. A signal that came meanwhile arrives once
            # the mask is restored, inside this try.
            held = _hold_terminal_signals()
            try:
                self._cluster = LocalCluster(n_workers=workers, threads_per_worker=1,
                                             processes=True, host="127.0.0.1",
                                             dashboard_address="127.0.0.1:0",
                                             worker_dashboard_address=None,
                                             preload=["fusionkit._dask_worker"],
                                             scheduler_kwargs={"dashboard": bool(dashboard)})
                self._client = Client(self._cluster, set_as_default=False)
                _release(held)
                held = None
            except BaseException as exc:
                if isinstance(exc, KeyboardInterrupt):
                    _quiet_dask()
                self.close()
                # a cluster stopped half-way through its start is closed here, not by Dask's
                # exit hook, which fails on it with a traceback
                for cluster in set(SpecCluster._instances) - before:
                    with contextlib.suppress(Exception):
                        cluster.close(timeout=10)
                    cluster.shutdown_on_close = False
                _release(held)   # last: a signal held back arrives once all is closed
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
        from distributed.client import FutureCancelledError
        from distributed.comm import CommClosedError
        tasks = list(tasks)
        total = len(tasks)
        if progress is not None:
            progress(0, total)
        if not total:
            return []
        client = self._client
        out: list = [None] * total
        done = 0
        futures: list = []
        try:
            # the shared data goes to every worker once (and stays there for the next map with
            # the same object); tasks refer to it
            if shared is not self._shared_of:
                self._drop_shared()
                self._shared = client.scatter(shared, broadcast=True, hash=False) \
                    if shared is not None else None
                self._shared_of = shared
            handle = self._shared
            futures = client.map(_dask_call, [fn] * total, [handle] * total, tasks, pure=False)
            index = {f.key: n for n, f in enumerate(futures)}
            for f in as_completed(futures, loop=client.loop):
                out[index[f.key]] = f.result()
                done += 1
                if progress is not None:
                    progress(done, total)
        except (FutureCancelledError, CommClosedError) as exc:
            # the scheduler gone: the futures cancelled, or a transfer cut (a task's own error
            # is neither, and goes on as it is)
            why = getattr(exc, "reason", None) or type(exc).__name__
            if isinstance(exc, FutureCancelledError) and "connection" not in str(why):
                raise
            _quiet_dask()   # the client's reconnection, cut short by the close, is not said
            raise InputError(f"the Dask scheduler at {client.scheduler.address} was lost after "
                             f"{done} of {total} tasks ({why}); nothing was written: check the "
                             f"scheduler and run again") from None
        except Exception as exc:
            # workers of a cluster started elsewhere without fusionkit (or a package it needs):
            # the task, or the data sent to them, cannot be unpickled there
            missing = re.search(r"No module named '([\w.]+)'", f"{exc} {exc.__cause__}")
            if missing is None:
                raise
            who = "scheduler" if "task graph" in str(exc) else "workers"
            raise InputError(f"the Dask {who} at {client.scheduler.address} cannot import "
                             f"{missing.group(1)}; install the same fusionkit (with its "
                             f"dependencies) {'beside it' if who == 'scheduler' else 'on every worker'}") \
                from None
        finally:
            with contextlib.suppress(Exception):   # nothing to cancel on a scheduler gone
                client.cancel(futures)
        return out

    def _drop_shared(self) -> None:
        if self._shared is not None and self._client is not None:
            self._client.cancel([self._shared])
        self._shared = None
        self._shared_of = None

    def __exit__(self, kind, *exc):
        if kind is not None and issubclass(kind, KeyboardInterrupt):
            _quiet_dask()
            self._stop_workers()
        self.close()

    def _stop_workers(self, wait: float = 0.5) -> None:
        """Stop the workers of the cluster this executor started, each given ``wait`` s to end
        its task before it is killed (a close gives them 4 s: a Ctrl-C waited for them). What
        they compute is thrown away; they write nothing."""
        cluster = self._cluster
        if cluster is None:
            return
        nannies = list(getattr(cluster, "workers", {}).values())

        async def stop():
            await asyncio.gather(*(n.close(timeout=wait / 0.8) for n in nannies
                                   if hasattr(n, "close")), return_exceptions=True)

        with contextlib.suppress(Exception):
            cluster.sync(stop)

    def close(self) -> None:
        from ._signals import deferred

        # a worker slow to exit is killed by its nanny: expected here, not worth a warning
        log = logging.getLogger("distributed")
        level = log.level
        log.setLevel(logging.ERROR)
        # a Ctrl-C during the close takes effect after it: cut short, the close left the
        # cluster to Dask's exit hook, which closed it seconds later
        try:
            with deferred():
                with contextlib.suppress(Exception):   # a scheduler lost: nothing to drop
                    self._drop_shared()
                if self._client is not None:
                    with contextlib.suppress(Exception):   # (TimeoutError, a scheduler lost)
                        self._client.close(timeout=5)
                    self._client = None
                if self._cluster is not None:
                    self._cluster.close()
                    self._cluster = None
        finally:
            log.setLevel(level)


#: the libraries whose versions change a merge's numbers
_RESULT_LIBRARIES = ("numpy", "scipy", "cv2", "numba")


#: What a run's results depend on, as a process has it: a digest of fusionkit's own code (a
#: worker may hold another checkout of the same version) and the libraries' versions, as
#: ``result``. Source, so that a worker runs it whatever fusionkit it holds.
_INSTALLED = f"""
import hashlib, importlib, pathlib
import fusionkit
root = pathlib.Path(fusionkit.__file__).parent
digest = hashlib.sha256()
for path in sorted(root.rglob("*.py")):
    digest.update(path.relative_to(root).as_posix().encode() + bytes(1) + path.read_bytes())
result = (("fusionkit", digest.hexdigest()[:12]),) + tuple(
    (name, importlib.import_module(name).__version__) for name in {_RESULT_LIBRARIES!r})
"""

#: One expression that runs :data:`_INSTALLED` and gives its ``result`` (for ``eval``)
_INSTALLED_CALL = f"(lambda ns: (exec({_INSTALLED!r}, ns), ns['result'])[1])({{}})"


@functools.cache
def _installed() -> tuple:
    """:data:`_INSTALLED`'s ``result`` in this process."""
    return eval(_INSTALLED_CALL)   # noqa: S307 - this module's own source


def _differences(theirs) -> str:
    """What the workers' ``_installed()`` answers differ in from this process's, in words
    ('' when none does)."""
    mine = dict(_installed())
    said = []
    for answer in theirs:
        for name, version in answer:
            if version != mine.get(name):
                text = ("another fusionkit (its code differs from this one's)" if name == "fusionkit"
                        else f"{'opencv' if name == 'cv2' else name} {version} (here {mine.get(name)})")
                if text not in said:
                    said.append(text)
    return ", ".join(said)


#: The schemes a Dask scheduler listens on (tls:// and wss:// with the certificates of Dask's
#: configuration, ``distributed.comm.tls``; ucx:// with UCX installed)
_SCHEMES = ("tcp", "tls", "ws", "wss", "ucx")


def _probe(address: str, timeout: float) -> None:
    """Ask the scheduler at ``address`` who it is, all within ``timeout`` seconds: a port that
    takes the connection and never answers (the dashboard's, given as tcp://) held Dask's
    client for good. Asked from a daemon thread of its own, so that a caller's running event
    loop (a notebook's) is not in the way, and neither a Ctrl-C nor the process's exit waits
    for it (a name lookup cannot be cut short)."""
    import queue

    from distributed.comm import connect
    from distributed.security import Security

    # tls:// and wss:// take their certificates from Dask's configuration, as Client does
    security = Security().get_connection_args("client")
    if address.startswith(("tls", "wss")) and security.get("ssl_context") is None:
        raise InputError(f"{address}: a TLS scheduler needs the client's certificates in Dask's "
                         f"configuration (distributed.comm.tls.ca-file, .client.cert, "
                         f".client.key)")

    async def ask():
        # a plain TCP connection first (ucx:// is not TCP), tried again while it is refused (a
        # scheduler still starting): Dask's connect said of a refused one only that it had
        # timed out
        if not address.startswith("ucx"):
            parts = urlsplit(address)
            while True:
                try:
                    _, writer = await asyncio.open_connection(parts.hostname, parts.port)
                    break
                except ConnectionRefusedError:
                    if time.monotonic() > given_up:
                        raise
                    await asyncio.sleep(0.2)
            writer.close()
        comm = await connect(address, timeout=timeout, **security)
        try:
            await comm.write({"op": "identity", "n_workers": 0, "reply": True})
            return await comm.read()
        finally:
            comm.abort()

    answers: queue.Queue = queue.Queue()

    def run():
        try:
            answers.put((True, asyncio.run(asyncio.wait_for(ask(), timeout))))
        except BaseException as exc:   # noqa: BLE001 - handed to the caller
            answers.put((False, exc))

    given_up = time.monotonic() + timeout - 0.5
    threading.Thread(target=run, name="fusionkit-dask-probe", daemon=True).start()
    late = (f"the Dask scheduler at {address} did not answer within {timeout:g} s; check the "
            f"address (the scheduler's port, 8786 by default, not the dashboard's), that the "
            f"scheduler is running, and for a busy one a longer --scheduler-timeout")
    try:
        ok, answer = answers.get(timeout=timeout + 1.0)
    except queue.Empty:
        raise InputError(late) from None
    if not ok:
        if isinstance(answer, (TimeoutError, asyncio.TimeoutError)):
            raise InputError(late)
        # refused, reset, closed, UCX missing: Dask's comm errors are OSErrors or not
        why = (f"the connection was refused for {timeout:g} s: nothing listens on that port"
               if isinstance(answer, ConnectionRefusedError) or "refused" in str(answer).lower()
               else f"no host is named {urlsplit(address).hostname!r}"
               if isinstance(answer, socket.gaierror)
               else str(answer).splitlines()[0][:120] if str(answer).strip()
               else type(answer).__name__)
        raise InputError(f"no Dask scheduler answered at {address} ({why}); check the address "
                         f"and that the scheduler is running")
    if not isinstance(answer, dict) or "n_workers" not in answer:
        raise InputError(f"{address} answers, but not as a Dask scheduler; give the scheduler's "
                         f"address (tcp://HOST:8786 by default), not a worker's")


def _check_address(address) -> None:
    """Refuse a scheduler address Dask cannot connect to (the dashboard's ``http://HOST:8787``,
    no host, a port out of range) with one line that says how to give it."""
    fix = f"scheduler address {address!r}: give it as tcp://HOST:PORT"
    if not isinstance(address, str) or "://" not in address:
        raise InputError(fix)
    try:
        parts = urlsplit(address)
        port = parts.port
    except ValueError:
        raise InputError(f"{fix} (the port is a number from 1 to 65535)") from None
    if parts.scheme not in _SCHEMES:
        hint = " (http is the dashboard's; the scheduler's own port is 8786 by default)" \
            if parts.scheme in ("http", "https") else ""
        raise InputError(f"{fix}{hint}")
    if port is None:
        raise InputError(f"{fix} (the port is missing: the scheduler's is 8786 by default)")
    if not parts.hostname or port == 0 or parts.path not in ("", "/"):
        raise InputError(fix)
