"""A dask worker preload of the sweep's local clusters (:func:`casflex.study.sweep._local_cluster`): the worker
process ignores SIGINT from here on. A Ctrl-C at a terminal goes to the whole process group; the sweep's own
process takes it and closes its cluster, while a worker that took it too printed its KeyboardInterrupt's
traceback. Done at import, the earliest moment dask runs a preload in a spawned worker (as the Worker is made),
and first of all in the fork server that forks the workers (:func:`casflex.study.fork_server`), whose
children start with its handlers; again in :func:`dask_setup`, as dask sets up each Worker (a forked worker has
the module from the server: its import does not run again). SIGTERM, by which dask's nanny stops a worker, stays
as it is. At exit, no last garbage collection (:func:`casflex.interrupt.skip_final_collection`)."""

import atexit
import logging
import signal
import threading


def _quiet() -> None:
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        if hasattr(signal, "pthread_sigmask"):  # the fork server starts with it blocked (fork_server): ignored now
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    # a worker whose scheduler the interrupted command closed first logs its failed heartbeat with a traceback on
    # the command's stderr; a run's own failure reaches the command as its result, so the workers' logs say nothing
    # more (after the nanny's own level for its worker, silence_logs, which it sets before the preloads run)
    logging.getLogger("distributed").setLevel(logging.CRITICAL)


def dask_setup(worker: object) -> None:
    """dask's hook, called as each Worker starts (in its process): :func:`_quiet` again."""
    _quiet()


_quiet()
from casflex.interrupt import skip_final_collection  # noqa: E402 (after SIGINT is ignored: casflex's imports)

atexit.register(skip_final_collection)
