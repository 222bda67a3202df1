"""A dask worker preload of the sweep's local clusters (:func:`casflex.study.sweep._local_cluster`): the worker
process ignores SIGINT from here on. A Ctrl-C at a terminal goes to the whole process group; the sweep's own
process takes it and closes its cluster, while a worker that took it too printed its KeyboardInterrupt's
traceback. Done at import, the earliest moment dask runs a preload in the worker (as the Worker is made);
SIGTERM, by which dask's nanny stops a worker, stays as it is."""

import logging
import signal

signal.signal(signal.SIGINT, signal.SIG_IGN)
# a worker whose scheduler the interrupted command closed first logs its failed heartbeat with a traceback on the
# command's stderr; a run's own failure reaches the command as its result, so the workers' logs say nothing more
logging.getLogger("distributed").setLevel(logging.CRITICAL)
