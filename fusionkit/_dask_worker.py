"""Imported first by every worker process of a Dask cluster fusionkit starts (its ``preload``).

A Ctrl-C at the terminal reaches every process of its group: the fusionkit process, not each
worker, stops the run and closes the cluster, so a worker ignores it.
"""

import signal
import threading

if threading.current_thread() is threading.main_thread():
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def dask_setup(worker):  # noqa: ARG001 - the preload's entry point; the import did the work
    """Nothing more to do: importing this module made the worker ignore Ctrl-C."""
