"""Back ends: a merge and a bench give exactly the in-process results on a 2-worker Dask
LocalCluster (processes, loopback) and on local processes; tasks come back in order; a
scheduler that does not answer is one clear error line, exit 2; the progress bar draws on a
terminal only."""

from __future__ import annotations

import contextlib
import io
import signal
import socket
import sys
import re
import time

import numpy as np
import pytest

from fusionkit.bench import BenchConfig, WorldSpec, make_case, plan_cases, run_bench
from fusionkit.cli import main
from fusionkit.methods.consensus import ConsensusConfig
from fusionkit.errors import InputError
from fusionkit.executor import DaskExecutor, InProcess, LocalProcesses, make_executor, using
from fusionkit.pipeline import MergeConfig, merge
from fusionkit.progress import ProgressBar, format_duration
from test_bench import _strip

CAVE = WorldSpec("cave", builtin="cave")
OFFICE = WorldSpec("office", builtin="office")


@contextlib.contextmanager
def deadline(seconds: int):
    """Fail the test (instead of hanging) when the block runs longer than ``seconds``."""
    def expired(signum, frame):
        raise TimeoutError(f"took longer than {seconds} s")
    old = signal.signal(signal.SIGALRM, expired)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


@pytest.fixture(scope="module")
def cluster():
    """A 2-worker Dask LocalCluster on 127.0.0.1, dashboard off, closed by its handle."""
    with deadline(120):
        ex = DaskExecutor(2, dashboard=False)
    try:
        yield ex
    finally:
        with deadline(60):
            ex.close()


def _slow_square(shared, task):
    # later tasks finish first, so that gathering in order is tested
    time.sleep(0.02 * (5 - task % 5))
    return shared["offset"] + task * task


@pytest.mark.parametrize("make", [lambda: InProcess(), lambda: InProcess(3), lambda: LocalProcesses(2)],
                         ids=["serial", "threads", "processes"])
def test_results_come_back_in_task_order_with_the_shared_data(make):
    seen = []
    with deadline(120), make() as ex:
        out = ex.map(_slow_square, list(range(12)), shared={"offset": 7},
                     progress=lambda d, t: seen.append((d, t)))
    assert out == [7 + k * k for k in range(12)]
    assert seen[0] == (0, 12) and seen[-1] == (12, 12)
    assert [d for d, _ in seen] == sorted(d for d, _ in seen)


def test_dask_runs_tasks_in_order_and_reports_progress(cluster):
    seen = []
    with deadline(120):
        out = cluster.map(_slow_square, list(range(10)), shared={"offset": 1},
                          progress=lambda d, t: seen.append(d))
    assert out == [1 + k * k for k in range(10)]
    assert seen[0] == 0 and seen[-1] == 10
    assert cluster.workers == 2
    assert cluster.client.scheduler.address.startswith("tcp://127.0.0.1:")
    assert "dashboard: none" in cluster.describe()


def _fleet():
    """Four overlapping crops of the office (no scans): small and quick to merge."""
    cfg = BenchConfig(cases=1, robots=(4,), modes=("crop",), seed=11)
    case = make_case(plan_cases([OFFICE], cfg)[0], cfg)
    return list(case.grids)


def _same_merge(a, b):
    assert [None if t is None else (t.x, t.y, t.theta) for t in a.transforms] == \
           [None if t is None else (t.x, t.y, t.theta) for t in b.transforms]
    assert [p.confidence for p in a.placements] == [p.confidence for p in b.placements]
    assert np.array_equal(a.grid.data, b.grid.data)
    assert [(s.placed, s.new, s.confidence) for s in a.steps] == \
           [(s.placed, s.new, s.confidence) for s in b.steps]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_the_workers_of_a_local_cluster_never_take_the_terminals_signals(cluster):
    """A Ctrl-C or a hang-up while the workers were still loading Dask printed their
    tracebacks: they start with both signals blocked, and this process alone stops the run."""
    import os

    pids = cluster.client.run(os.getpid)
    assert len(pids) == 2
    for pid in pids.values():
        blocked = next(int(line.split()[1], 16) for line in
                       open(f"/proc/{pid}/status").read().splitlines() if line.startswith("SigBlk"))
        for sig in (signal.SIGINT, signal.SIGHUP):
            assert blocked & (1 << (sig - 1)), (pid, sig, hex(blocked))
    # and this process takes them as before
    assert not signal.pthread_sigmask(signal.SIG_BLOCK, []) & {signal.SIGINT, signal.SIGHUP}


def test_a_ctrl_c_while_the_cluster_closes_takes_effect_once_it_is_closed():
    """Cut short, the close left the cluster to Dask's exit hook, which closed it seconds
    after the command's last line."""
    import os

    from fusionkit import _signals

    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    _signals.install()
    try:
        with deadline(120):
            ex = DaskExecutor(2, dashboard=False)
        cluster, client = ex._cluster, ex._client
        real, sent = client.close, []

        def close_interrupted(*a, **k):
            if not sent:
                sent.append(os.kill(os.getpid(), signal.SIGINT))   # Ctrl-C in the middle of the close
            return real(*a, **k)

        client.close = close_interrupted
        with deadline(60), pytest.raises(KeyboardInterrupt):
            ex.close()
        assert ex._cluster is None and ex._client is None
        assert cluster.status.name == "closed", cluster.status
    finally:
        for s, h in saved.items():
            signal.signal(s, h)


def test_merge_on_a_local_cluster_equals_the_in_process_merge(cluster):
    grids = _fleet()
    # one candidate per map: the candidate, widening and loop-closing rounds all run remotely
    cfg = MergeConfig(consensus=ConsensusConfig(candidates=1))
    here = merge(grids, config=cfg)
    assert sum(t is not None for t in here.transforms) >= 3
    with deadline(300), using(cluster):
        there = merge(grids, config=cfg)
    _same_merge(here, there)


def test_merge_on_local_processes_equals_the_in_process_merge():
    grids = _fleet()
    here = merge(grids)
    with deadline(300), LocalProcesses(2) as ex, using(ex):
        there = merge(grids)
    _same_merge(here, there)


def test_bench_on_a_local_cluster_equals_the_in_process_bench(cluster):
    cfg = BenchConfig(methods=("consensus", "hough-spectrum"), modes=("crop",), robots=(2, 3),
                      cases=3, seed=4)
    here = run_bench([CAVE], cfg)
    with deadline(300):
        there = run_bench([CAVE], cfg, executor=cluster)
    assert _strip(there.cases) == _strip(here.cases)
    assert there.showcase["index"] == here.showcase["index"]
    assert np.array_equal(there.showcase["fused"]["consensus"]["data"],
                          here.showcase["fused"]["consensus"]["data"])


def test_a_bench_of_map_files_runs_on_workers_that_do_not_have_them(cluster, tmp_path, monkeypatch):
    """A cluster's workers were sent each case's map path, relative to where ``bench`` ran, and
    failed with "w/cave.yaml: no such map file"; the worlds now go with the cases. The workers
    here started in another folder, as on another machine."""
    from fusionkit.bench import find_worlds
    from fusionkit.mapio import save_map
    from fusionkit.worlds import make_world

    (tmp_path / "w").mkdir()
    save_map(make_world("cave", 0), tmp_path / "w" / "cave.yaml")
    monkeypatch.chdir(tmp_path)
    worlds, _ = find_worlds(["w"])
    cfg = BenchConfig(methods=("hough-spectrum",), modes=("crop",), robots=(2,), cases=2, seed=4)
    here = run_bench(worlds, cfg)
    with deadline(300):
        there = run_bench(worlds, cfg, executor=cluster)
    assert _strip(there.cases) == _strip(here.cases)


def _blocked_signals(shared, task):
    return sorted(int(s) for s in signal.pthread_sigmask(signal.SIG_BLOCK, []))


def test_local_workers_leave_ctrl_c_to_the_process_that_started_them():
    """A Ctrl-C at the terminal reaches every process of the group: each worker printed a
    KeyboardInterrupt traceback. The workers start with SIGINT blocked; this process is not
    left with it blocked."""
    ex = LocalProcesses(2)
    try:
        with deadline(120):
            masks = ex.map(_blocked_signals, range(4))
    finally:
        ex.close()
    assert all(int(signal.SIGINT) in m for m in masks)
    assert signal.SIGINT not in signal.pthread_sigmask(signal.SIG_BLOCK, [])


def test_an_interrupted_local_run_stops_its_workers():
    """Interrupted, the run stops its workers instead of waiting for them: an interrupt that
    landed while the pool started them left workers no one told to end, and the exit hung."""
    import multiprocessing

    before = set(multiprocessing.active_children())   # (a module's Dask cluster among them)
    ex = LocalProcesses(2)

    def interrupt(done, total):
        if done >= 1:
            raise KeyboardInterrupt

    with deadline(120), pytest.raises(KeyboardInterrupt):
        ex.map(_slow_square, range(20), shared={"offset": 0}, progress=interrupt)
    assert set(multiprocessing.active_children()) - before == set()
    ex.close()


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_scheduler_that_does_not_answer_is_one_clear_error_line(tmp_path, capsys):
    address = f"tcp://127.0.0.1:{_free_port()}"
    t0 = time.monotonic()
    with deadline(60):
        code = main(["bench", "--worlds", "cave", "--cases", "1", "--out", str(tmp_path / "b"),
                     "--scheduler", address, "--scheduler-timeout", "2"])
    assert code == 2
    assert time.monotonic() - t0 < 30
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and address in err[0] and "Traceback" not in err[0]
    assert not (tmp_path / "b" / "bench.json").exists()
    with pytest.raises(InputError, match="tcp://HOST:PORT"):
        make_executor(scheduler="127.0.0.1:1")


@pytest.mark.parametrize("server", ["silent", "http"])
def test_a_port_that_takes_the_connection_and_never_answers_is_one_line_within_the_timeout(
        tmp_path, capsys, server):
    """The dashboard's port given as tcp:// (an HTTP server waiting for the rest of a request),
    or any silent listener: the command hung for good, and Ctrl-C then printed a traceback."""
    import http.server
    import threading

    if server == "http":
        class Quiet(http.server.BaseHTTPRequestHandler):
            def log_message(self, *args):
                pass

        srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Quiet)
        port = srv.server_address[1]
        thread = threading.Thread(target=srv.serve_forever, daemon=True)
        thread.start()
        stop = srv.shutdown
        close = srv.server_close
    else:
        lsock = socket.socket()
        lsock.bind(("127.0.0.1", 0))
        lsock.listen(8)
        port = lsock.getsockname()[1]
        stop, close = (lambda: None), lsock.close
    address = f"tcp://127.0.0.1:{port}"
    try:
        t0 = time.monotonic()
        with deadline(60):
            code = main(["bench", "--worlds", "cave", "--cases", "1", "--out", str(tmp_path / "b"),
                         "--scheduler", address, "--scheduler-timeout", "2"])
        took = time.monotonic() - t0
    finally:
        stop()
        close()
    assert code == 2
    assert took < 20, took
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and address in err[0] and "within 2 s" in err[0], err
    assert not (tmp_path / "b").exists()


_PROBING = """
import os, signal, sys, threading
import fusionkit._dask as d
from fusionkit.cli import main
real = d._probe
def probing(address, timeout):   # Ctrl-C at the terminal while the scheduler is asked
    threading.Timer(1.0, os.kill, (os.getpid(), signal.SIGINT)).start()
    print("probing", flush=True)
    return real(address, timeout)
d._probe = probing
sys.exit(main(sys.argv[1:]))
"""


def test_ctrl_c_while_a_silent_scheduler_is_asked_ends_at_once(tmp_path):
    """The probe's thread was joined: a Ctrl-C waited out the whole --scheduler-timeout."""
    import subprocess

    lsock = socket.socket()
    lsock.bind(("127.0.0.1", 0))
    lsock.listen(8)
    address = f"tcp://127.0.0.1:{lsock.getsockname()[1]}"
    proc = subprocess.Popen([sys.executable, "-c", _PROBING, "bench", "--worlds", "cave", "--cases", "1",
                             "--out", str(tmp_path / "b"), "--scheduler", address,
                             "--scheduler-timeout", "60"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "probing"
        t0 = time.monotonic()
        code = proc.wait(timeout=50)   # the probe alone would take 60 s
        took = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
        lsock.close()
    assert code == 130 and took < 20, (code, took)
    assert proc.stderr.read().strip().splitlines() == [
        "fusionkit bench: interrupted; no output was left half-written"]


@pytest.mark.parametrize("host, said", [("127.0.0.1", "the connection was refused for 5 s: nothing listens"),
                                         ("nosuchhost.invalid", "no host is named 'nosuchhost.invalid'")])
def test_a_refused_connection_or_an_unknown_host_is_said_as_such(tmp_path, capsys, host, said):
    """Dask's client retries a refused connection until the timeout (a scheduler may be
    starting), then said only that it had timed out; the port is free, the host's name cannot
    exist (.invalid)."""
    address = f"tcp://{host}:{_free_port()}"
    err = _scheduler_error(tmp_path, capsys, address, timeout=5)
    assert f"no Dask scheduler answered at {address} ({said}" in err, err


def _scheduler_error(tmp_path, capsys, address: str, timeout: float = 2) -> str:
    """The one line of ``bench --scheduler address`` (exit 2 asserted)."""
    with deadline(60):
        code = main(["bench", "--worlds", "cave", "--cases", "1", "--out", str(tmp_path / "b"),
                     "--scheduler", address, "--scheduler-timeout", str(timeout)])
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in err[0], err
    return err[0]


@pytest.mark.parametrize("scheme", ["tls", "ucx"])
def test_a_scheme_this_machine_cannot_speak_is_one_line_and_exit_2(tmp_path, capsys, scheme):
    """tls:// without certificates in Dask's configuration, ucx:// without UCX: a traceback of
    60 lines and exit 1."""
    address = f"{scheme}://127.0.0.1:{_free_port()}"
    err = _scheduler_error(tmp_path, capsys, address)
    assert address in err, err
    if scheme == "tls":
        assert "certificates in Dask's configuration" in err, err


@pytest.mark.parametrize("address", ["http://127.0.0.1:8787", "tcp://", "tcp://:8786",
                                     "tcp://127.0.0.1:99999", "tcp://127.0.0.1:port",
                                     "tcp://127.0.0.1"])
def test_a_scheduler_address_dask_cannot_use_is_one_line_and_exit_2(tmp_path, capsys, address):
    """The dashboard's http://HOST:8787, an easy slip, or tcp:// with no host gave two
    tracebacks and exit 1."""
    assert "tcp://HOST:PORT" in _scheduler_error(tmp_path, capsys, address)
    with pytest.raises(InputError, match="back end"):
        make_executor("cluster")


def test_make_executor_picks_the_back_end():
    assert isinstance(make_executor(), InProcess) and make_executor().workers == 1
    assert isinstance(make_executor(workers=3), LocalProcesses)
    assert isinstance(make_executor("inprocess", workers=3), InProcess)
    with pytest.raises(InputError):
        make_executor(workers=0)


def test_progress_bar_shows_rate_and_time_left_on_a_terminal_only():
    now = [0.0]
    term = io.StringIO()
    bar = ProgressBar("bench", unit="cases", stream=term, enabled=True, min_interval=0.0,
                      clock=lambda: now[0])
    bar(0, 10)
    now[0] = 4.0
    bar(2, 10, "cave")
    text = term.getvalue().split("\r")[-1]
    assert "2/10 cases" in text and "0.50/s" in text and "16 s left" in text and "cave" in text
    now[0] = 20.0
    bar(10, 10)
    bar.close()
    assert term.getvalue().endswith("\n") and "10/10 cases" in term.getvalue()

    pipe = io.StringIO()                       # not a terminal: nothing drawn
    quiet = ProgressBar("bench", unit="cases", stream=pipe)
    quiet(3, 10)
    quiet.close()
    assert pipe.getvalue() == ""
    assert format_duration(42) == "42 s" and format_duration(185) == "3:05"
    assert format_duration(3723) == "1:02:03"


def _group_gone(pgid: int, seconds: float = 10.0) -> bool:
    """Whether every process of the group ``pgid`` has ended within ``seconds``."""
    import os
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.1)
    return False


@pytest.mark.parametrize("sig, code, said", [(signal.SIGINT, 130, "interrupted"),
                                              (signal.SIGHUP, 129, "hung up")],
                         ids=["Ctrl-C", "hang-up"])
def test_a_terminal_signal_stops_a_dask_run_with_one_line(tmp_path, sig, code, said):
    """Ctrl-C at a terminal, or its closing, reaches every process of its group, the cluster's
    workers too: the run ends with its one line, no worker's traceback or warning, no worker
    left. A hang-up killed Python's resource tracker, whose successor printed a traceback per
    worker."""
    import os
    import subprocess
    import sys
    env = dict(os.environ, NUMBA_THREADING_LAYER="threadsafe")
    proc = subprocess.Popen([sys.executable, "-c", "import sys; from fusionkit.cli import main; "
                             "sys.exit(main(sys.argv[1:]))", "bench", "--worlds", "cave", "--cases", "40",
                             "--backend", "dask", "--workers", "2", "--out", str(tmp_path / "sweep")],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, env=env,
                            # a hang-up ends it as at a terminal, even when the tests run
                            # under nohup (which starts every process with SIGHUP ignored)
                            preexec_fn=lambda: signal.signal(signal.SIGHUP, signal.SIG_DFL))
    try:
        first = proc.stderr.readline()  # "dask: 2 workers at ...": the cluster is up
        assert first.startswith("dask:"), first
        time.sleep(4)  # cases running on the workers
        os.killpg(proc.pid, sig)
        rest = proc.stderr.read()
        assert proc.wait(timeout=60) == code, rest
        left = not _group_gone(proc.pid)   # the workers go with the cluster, closed on the way out
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    assert rest.strip().splitlines() == [f"fusionkit bench: {said}; no output was left half-written"], rest
    assert not left, "a process of the run outlived it by 10 s"


_STARTING = """
import os, signal, sys
import distributed
from fusionkit.cli import main
real = distributed.LocalCluster
def starting(*a, **kw):   # Ctrl-C at the terminal while the cluster starts
    os.killpg(0, signal.SIGINT)
    return real(*a, **kw)
distributed.LocalCluster = starting
sys.exit(main(sys.argv[1:]))
"""


def test_ctrl_c_while_the_dask_cluster_starts_stops_the_run(tmp_path):
    """It was dropped: the run went on and wrote its outputs, exit 0."""
    import os
    import subprocess
    import sys
    env = dict(os.environ, NUMBA_THREADING_LAYER="threadsafe")
    out = tmp_path / "sweep"
    proc = subprocess.Popen([sys.executable, "-c", _STARTING, "bench", "--worlds", "cave",
                             "--cases", "4", "--backend", "dask", "--workers", "2", "--out",
                             str(out)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, start_new_session=True, env=env)
    try:
        err = proc.communicate(timeout=120)[1]
        left = not _group_gone(proc.pid)   # the workers go with the cluster, closed on the way out
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    assert proc.returncode == 130, err
    assert err.strip().splitlines() == [
        "fusionkit bench: interrupted; no output was left half-written"], err
    assert not out.exists()
    assert not left, "a process of the run outlived it by 10 s"


@contextlib.contextmanager
def _external_cluster(tmp_path, *scheduler_args, workers: int = 1, without_fusionkit: str = ""):
    """A scheduler and a worker on loopback, started as a user starts them; yields the
    scheduler's port and process. Both are stopped by their handles at the end.
    ``without_fusionkit`` ("worker" or "scheduler"): that one cannot import fusionkit;
    "other": the worker imports another copy of fusionkit, one line of its code changed and
    without ``fusionkit._dask._installed`` (as an older one)."""
    import os
    import subprocess
    from pathlib import Path

    port = _free_port()
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).parent))   # the tasks of this file
    if without_fusionkit in ("worker", "scheduler"):
        (tmp_path / "absent" / "fusionkit").mkdir(parents=True)
        (tmp_path / "absent" / "fusionkit" / "__init__.py").write_text(
            "raise ModuleNotFoundError(\"No module named 'fusionkit'\", name='fusionkit')\n")
    if without_fusionkit == "other":
        import shutil
        import fusionkit
        copy = tmp_path / "absent" / "fusionkit"
        shutil.copytree(Path(fusionkit.__file__).parent, copy,
                        ignore=shutil.ignore_patterns("__pycache__"))
        with open(copy / "transform.py", "a") as f:
            f.write("\n# another checkout\n")
        # an older checkout, without the function that says what a process runs
        dask_py = copy / "_dask.py"
        dask_py.write_text(dask_py.read_text().replace("def _installed(", "def _renamed("))
    bare = dict(env, PYTHONPATH=os.pathsep.join([str(tmp_path / "absent"), env["PYTHONPATH"]]))
    scheduler = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host",
                                  "127.0.0.1", "--port", str(port), *scheduler_args],
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=tmp_path,
                                 env=bare if without_fusionkit == "scheduler" else env)
    procs = [scheduler]
    try:
        procs.append(subprocess.Popen(
            [sys.executable, "-m", "distributed.cli.dask_worker", f"tcp://127.0.0.1:{port}",
             "--host", "127.0.0.1", "--nworkers", str(workers), "--nthreads", "1", "--no-dashboard"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=tmp_path,
            env=bare if without_fusionkit in ("worker", "other") else env))
        yield port, scheduler
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            try:
                p.wait(20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(10)


@pytest.mark.parametrize("pages", ["--no-dashboard", "without bokeh"])
def test_a_scheduler_without_dashboard_pages_is_said_to_have_none(tmp_path, pages):
    """A scheduler started with --no-dashboard still serves its HTTP port; the line said
    "dashboard: http://127.0.0.1:8787/status", a page that answers 404. Without bokeh, that
    page answers 200 and says the dashboard needs bokeh: the link was printed too."""
    http = _free_port()
    args = ["--dashboard-address", f"127.0.0.1:{http}"] + (["--no-dashboard"] if pages == "--no-dashboard" else [])
    with _external_cluster(tmp_path, *args) as (port, _):
        with deadline(120):
            ex = DaskExecutor(address=f"tcp://127.0.0.1:{port}", timeout=60)
            try:
                assert ex.dashboard is None
                assert ex.describe().endswith("dashboard: none (install bokeh for one)")
            finally:
                ex.close()


@pytest.mark.parametrize("where", ["worker", "scheduler"])
def test_a_cluster_without_fusionkit_is_one_clear_error(tmp_path, where):
    """A cluster whose workers lack fusionkit (its README says they need it) ended the command
    with a 70-line traceback ending in ModuleNotFoundError; a scheduler without it, with
    "Error during deserialization of the task graph"."""
    with _external_cluster(tmp_path, "--no-dashboard", without_fusionkit=where) as (port, _):
        said = rf"^the Dask {where}s? at tcp://127.0.0.1:{port} cannot import fusionkit.*; install the same"
        with deadline(120):
            if where == "worker":   # said when the cluster is reached, before any task
                with pytest.raises(InputError, match=said):
                    DaskExecutor(address=f"tcp://127.0.0.1:{port}", timeout=60)
                return
            ex = DaskExecutor(address=f"tcp://127.0.0.1:{port}", timeout=60)
            try:
                with pytest.raises(InputError, match=said):
                    ex.map(_pid_then_wait, [0.0, 0.0])
            finally:
                ex.close()


def test_workers_running_other_code_are_refused_before_any_task(tmp_path):
    """A worker with another checkout of fusionkit (or other numpy, OpenCV, numba) ran the
    tasks: its results could differ from a run here for the same seed, without a word."""
    with _external_cluster(tmp_path, "--no-dashboard", without_fusionkit="other") as (port, _):
        with deadline(120):
            with pytest.raises(InputError, match=rf"^the Dask workers at tcp://127.0.0.1:{port} "
                                                 r"run another fusionkit \(its code differs"):
                DaskExecutor(address=f"tcp://127.0.0.1:{port}", timeout=60)


def test_a_scheduler_lost_mid_run_is_one_clear_error_and_a_prompt_close(tmp_path, capfd):
    """A scheduler that went away mid-run gave 53 lines of tracebacks and exit 1."""
    with _external_cluster(tmp_path, "--no-dashboard", workers=2) as (port, scheduler):
        with deadline(120):
            ex = DaskExecutor(address=f"tcp://127.0.0.1:{port}", timeout=60)
            capfd.readouterr()

            def lose_it(done, total):
                if done == 1:
                    scheduler.kill()

            try:
                with pytest.raises(InputError, match=r"was lost after \d+ of 12 tasks"):
                    ex.map(_pid_then_wait, [0.2] + [3.0] * 11, progress=lose_it)
            finally:
                t0 = time.monotonic()
                ex.close()
                closed = time.monotonic() - t0
    assert closed < 10, closed
    err = capfd.readouterr().err
    assert "Traceback" not in err and "ERROR" not in err, err


_KILLED = """
import os, sys, time
from fusionkit.executor import LocalProcesses
from test_executor import _pid_then_wait
ex = LocalProcesses(2)
ex.map(_pid_then_wait, [0.3, 0.3, 0.3, 0.3])
print(*sorted(ex._pool._processes), flush=True)   # the pool's two workers, busy or not
ex.map(_pid_then_wait, [60.0] * 4)
"""


def _pid_then_wait(shared, seconds):
    time.sleep(seconds)
    return __import__("os").getpid()


def _gone(pid: int, seconds: float) -> bool:
    """Whether process ``pid`` has ended (a zombie counts as ended) within ``seconds``."""
    from pathlib import Path
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            if Path(f"/proc/{pid}/stat").read_text().split(") ")[-1].startswith(("Z", "X")):
                return True
        except (FileNotFoundError, ProcessLookupError):
            return True
        time.sleep(0.1)
    return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_workers_of_a_run_killed_with_kill_9_end_with_it():
    """``kill -9`` of a ``bench --workers 2`` left both workers running for good, blocked writing
    their results to a pipe nobody read."""
    import os
    import subprocess
    from pathlib import Path
    here = Path(__file__).parent
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(here), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-c", _KILLED], stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True, env=env, cwd=here)
    workers = []
    try:
        with deadline(120):
            workers = [int(p) for p in proc.stdout.readline().split()]
        assert len(workers) == 2
    finally:
        proc.kill()
        proc.wait(timeout=30)
        proc.stdout.close()
    try:
        assert all(_gone(pid, 15) for pid in workers)
    finally:
        for pid in workers:   # stopped by their handle if the run left them
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)


def test_a_worker_whose_parent_died_before_it_started_ends_at_once():
    """Killed 50 ms after starting its pool, the parent was gone before its workers read who
    their parent was: they took init (pid 1) for it and ran on for good."""
    import subprocess
    gone = subprocess.run([sys.executable, "-c",
                           "import os, time\n"
                           "from fusionkit._executor_base import exit_with_parent\n"
                           "exit_with_parent(os.getppid() + 10**6)\n"   # a parent not its own
                           "time.sleep(60)\n"], timeout=50)
    assert gone.returncode == 1
    stays = subprocess.run([sys.executable, "-c",
                            "import os\n"
                            "from fusionkit._executor_base import exit_with_parent\n"
                            "exit_with_parent(os.getppid())\n"
                            "print('ran')\n"], timeout=50, capture_output=True, text=True)
    assert stays.returncode == 0 and stays.stdout == "ran\n"


def test_far_more_workers_than_cores_or_a_using_of_no_executor_is_refused_from_python(monkeypatch):
    """The command line refused --workers 1000 on 2 cores; make_executor("dask", workers=1000)
    from Python started a process every 1.5 s, 550 of them in ten minutes. using("processes")
    failed deep in the merge: 'str' object has no attribute 'map'."""
    import os
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    said = ("workers=17 would start 17 workers on this machine's 2 cores; give at most 16 (8 a "
            "core), or a scheduler's address for a cluster")
    for make in (lambda: make_executor("dask", workers=17), lambda: DaskExecutor(17),
                 lambda: make_executor("processes", workers=17), lambda: LocalProcesses(17)):
        with pytest.raises(InputError, match=re.escape(said)):
            make()
    assert LocalProcesses(16).workers == 16
    with pytest.raises(InputError, match=r"^workers=17 would start 17 workers"):
        make_executor("inprocess", workers=17)       # 17 threads
    with pytest.raises(InputError, match=r"^threads=17 would start 17 workers"):
        InProcess(17)
    for wrong in (True, 2.0):
        with pytest.raises(InputError, match=r"^workers must be a whole number >= 1"):
            make_executor(workers=wrong)
    for wrong in ("processes", 4):
        with pytest.raises(InputError, match=r"^using\(\) takes an Executor or None, got"):
            with using(wrong):
                pass
