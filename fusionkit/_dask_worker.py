"""Imported first by every worker process of a Dask cluster fusionkit starts (its ``preload``).

A Ctrl-C at the terminal reaches every process of its group: the fusionkit process, not each
worker, stops the run and closes the cluster, so a worker ignores it (it also starts with the
terminal's signals blocked, :mod:`fusionkit._dask`).
"""

import logging
import signal
import threading

if threading.current_thread() is threading.main_thread():
    signal.signal(signal.SIGINT, signal.SIG_IGN)

# What a worker logs goes to the terminal of the fusionkit command that started the cluster:
# when the run is stopped, its transfers and heartbeats cut short by the closing scheduler
# ("failed during get data", "Failed to communicate with scheduler") were printed with their
# tracebacks around the command's one line. A task's own failure reaches the command as its
# exception, not through this log.
logging.getLogger("distributed").setLevel(logging.CRITICAL)


def dask_setup(worker):  # noqa: ARG001 - the preload's entry point; the import did the work
    """Nothing more to do: importing this module made the worker ignore Ctrl-C and quiet."""
