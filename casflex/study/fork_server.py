"""The fork server that a sweep's local clusters fork their workers from (:func:`fork_server`): multiprocessing's
forkserver, started once per process with what the workers import (:data:`WORKER_MODULES`), so that each worker
starts with them, where a spawned worker imported them itself (1.3 s of CPU a worker before its first run)."""

from __future__ import annotations

import os
import signal
import threading

__all__ = ["WORKER_MODULES", "fork_server", "changed_env"]

#: what a local cluster's worker processes import before their first run, once, in the fork server they are forked from
#: (:func:`fork_server`): the SIGINT guard first, dask's worker (dask, tornado, msgpack, numpy, ...: 0.8 s of CPU), the
#: lab path's modules that a study's calibrations and trials import (CasADi, casflex's model, scene, inverse and
#: study modules: 0.5 s). Spawned, each worker imported them itself (1.3 s a worker, before its first run). A
#: module missing here is imported by the worker at its first use, as before.
WORKER_MODULES = ("casflex.study._worker", "distributed", "casflex.inverse.calibrate", "casflex.inverse.passive",
                  "casflex.study.runner", "casflex.study.events", "casflex.study.direction")


def fork_server() -> bool:
    """Start multiprocessing's fork server with :data:`WORKER_MODULES` (once per process: it serves every local
    cluster of the process), where the local clusters start their workers by dask's default, spawn; True where
    they are forked from it (:func:`casflex.study.sweep._local_cluster`). Returns at once: the server imports the
    modules on its own (on an idle core, while this process goes on), and a worker's start waits for it only as
    long as it imports.

    Started with dask's environment for its workers (``distributed.nanny.pre-spawn-environ``: one BLAS thread,
    the allocator's trim threshold), which the nanny would set in this process before each spawn: a forked
    worker inherits the server's. The server ignores SIGINT, as its workers do (casflex.study._worker, its first
    module); it ends with this process (multiprocessing's own: it watches a pipe from here)."""
    import importlib.util
    import multiprocessing
    from multiprocessing import forkserver

    if importlib.util.find_spec("distributed") is None:
        return False  # dask's distributed missing: its import says so, as without a fork server
    if "forkserver" not in multiprocessing.get_all_start_methods() or _start_method() != "spawn":
        return False  # no fork server here (Windows), or a start method the user chose: dask's as configured
    import dask

    # as distributed.nanny.Nanny makes it (the variables set here take precedence; its fixed hash seed)
    spawn_env = {k: os.environ.get(k, str(v)) for k, v in dask.config.get("distributed.nanny.pre-spawn-environ").items()
                 if v is not None}
    if spawn_env.get("PYTHONHASHSEED") in (None, "0"):
        spawn_env["PYTHONHASHSEED"] = "6640"
    os.environ.update(spawn_env)
    if getattr(forkserver._forkserver, "_forkserver_pid", None) is None:
        _SERVER_ENV.clear()
        _SERVER_ENV.update(os.environ)
    forkserver.set_forkserver_preload(list(WORKER_MODULES))  # for its start (again, where it died)
    # SIGINT blocked while the server is started, as multiprocessing starts its resource tracker: the server starts
    # with it blocked until casflex.study._worker ignores it (a Ctrl-C in its first 50 ms printed its traceback);
    # a Ctrl-C meanwhile reaches this process as soon as it is unblocked
    from multiprocessing import resource_tracker

    resource_tracker.ensure_running()  # first: starting it unblocks SIGINT after its own start (its way to block it)
    main = threading.current_thread() is threading.main_thread() and hasattr(signal, "pthread_sigmask")
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT}) if main else None
    try:
        forkserver.ensure_running()
    finally:
        if mask is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)
    return True


#: the environment the fork server started with, which its workers inherit (:func:`changed_env`)
_SERVER_ENV: dict[str, str] = {}


def changed_env() -> dict[str, str]:
    """The variables of this process's environment set or changed since the fork server started (a long-lived
    process's, a notebook's): given to the forked workers as a spawned worker inherits them (dask's nanny sets them
    in its worker; ``distributed.nanny.environ``'s keep their precedence; a variable removed stays in the workers)."""
    import dask

    configured = dask.config.get("distributed.nanny.environ", None) or {}
    return {k: v for k, v in os.environ.items() if _SERVER_ENV.get(k) != v and k not in configured}


def _start_method() -> str:
    """dask's start method for its workers' processes (``distributed.worker.multiprocessing-method``, "spawn" by
    default), read before distributed is imported: its defaults added to dask's configuration as distributed
    adds them at its import (the same defaults: a user's settings and DASK_ variables take precedence)."""
    import dask

    key = "distributed.worker.multiprocessing-method"
    if dask.config.get(key, None) is None:
        import importlib.util

        import yaml  # dask's own dependency

        (where,) = importlib.util.find_spec("distributed").submodule_search_locations
        with open(os.path.join(where, "distributed.yaml")) as f:
            dask.config.update_defaults(yaml.safe_load(f))
    return dask.config.get(key)
