"""The ``--backend/--workers/--scheduler`` options of ``merge`` and ``bench``."""

from __future__ import annotations

from .._executor_base import check_local_workers
from ._common import float_range, int_range


def add_executor_options(p, *, what: str) -> None:
    """Options choosing where ``what`` (``"pairs"``, ``"cases"``) run."""
    from ..executor import BACKENDS
    g = p.add_argument_group("parallel back end")
    g.add_argument("--backend", choices=BACKENDS, default=None,
                   help=f"where the {what} run: inprocess (this process; the default without "
                        f"--workers), processes (local worker processes; the default with "
                        f"--workers) or dask (a Dask LocalCluster of --workers "
                        f"processes, or the cluster of --scheduler). Results are the same on "
                        f"every back end")
    g.add_argument("--workers", type=int_range(1, 1024), default=None, metavar="N",
                   help=f"run the {what} on N workers: N local processes (without --backend, or "
                        f"with --backend processes), N threads of this process (--backend "
                        f"inprocess) or a Dask LocalCluster of N processes on this machine "
                        f"(--backend dask)")
    g.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                   help=f"run the {what} on the Dask cluster whose scheduler is at this address "
                        f"(its workers need fusionkit installed)")
    g.add_argument("--scheduler-timeout", type=float_range(0, 3600, lo_open=True), default=None,
                   metavar="S", help="with --scheduler: seconds to wait for the scheduler to "
                                     "answer (default 10)")


def executor_from_args(args, *, jobs: int | None = None):
    """The executor the options ask for (``jobs``: a command's older process count)."""
    from ..errors import InputError
    from ..executor import make_executor
    workers = args.workers
    if jobs is not None and jobs > 1:
        if workers is not None and workers != jobs:
            raise InputError("--jobs and --workers disagree; give one of them")
        workers = jobs
    if args.scheduler is not None and workers is not None:
        raise InputError("--scheduler uses the cluster's workers; drop --workers (or --jobs)")
    if args.scheduler is None and args.scheduler_timeout is not None:
        raise InputError("--scheduler-timeout is how long to wait for --scheduler; give both, or "
                         "neither")
    if workers is not None:
        check_local_workers(workers, said=f"--workers {workers}", cluster="--scheduler")
    return make_executor(args.backend, workers=workers, scheduler=args.scheduler,
                         timeout=10.0 if args.scheduler_timeout is None else args.scheduler_timeout)
