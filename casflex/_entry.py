"""The ``casflex`` command's entry point: nothing heavy is imported before the signals are caught, so
Ctrl-C, SIGTERM or SIGHUP while CasADi, numpy and matplotlib load exits with 130, 143 or 129 and one
line, as at any other moment."""

import atexit
import os
import signal
import sys

_spawned = sys.modules.get("multiprocessing.process")
if _spawned is not None and getattr(_spawned.current_process(), "_inheriting", False):
    # A process the command spawned (its local dask workers), which multiprocessing prepares by running the
    # parent's script, this entry point, first. Ctrl-C at a terminal reaches the whole process group; the
    # command takes it and closes its workers, which printed a KeyboardInterrupt's traceback each. Ignored here,
    # from the child's first moment after Python's own start-up (the workers' preload, casflex.study._worker,
    # does it where the command ran as python -m casflex, whose script multiprocessing does not run again).
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    import logging  # and its failed heartbeats at the close are no traceback of the user's (casflex.study._worker)

    logging.getLogger("distributed").setLevel(logging.CRITICAL)


def _exit_interrupted(code: int, hurried: bool = False) -> None:
    """Exit with ``code`` for certain. A KeyboardInterrupt (Terminated is one) that crossed code an
    extension module ran at import (CPython's run_eval_code_obj) is recorded by CPython as
    unhandled, and at exit CPython then kills itself with SIGINT although casflex caught it: run
    the exit handlers, flush, and end here instead.

    dask's exit handler is not run: it closes again, for up to 10 s, a local cluster the signal cut short in
    its start or its close (its worker processes end with this one: each watches a pipe from its parent).
    ``hurried`` (a second signal came while the command stopped): no exit handler is run, as the user asks to
    be out now. Outputs are discarded before."""
    spec = sys.modules.get("distributed.deploy.spec")
    if spec is not None and hasattr(spec, "close_clusters"):
        atexit.unregister(spec.close_clusters)
    if not hurried:
        atexit._run_exitfuncs()
    elif "multiprocessing.util" in sys.modules:  # its quick finalizers only (semaphores, queues' closing): else
        sys.modules["multiprocessing.util"]._run_finalizers(0)  # its resource tracker warns of "leaked" ones
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(code)


def main() -> int:
    from casflex import interrupt  # light: signal and contextlib only (casflex/__init__ is lazy)

    # One guard for the whole process, opened before any heavy import: a signal that an extension
    # swallows while numpy, CasADi or matplotlib load is counted, and the command's own guard (the
    # same object) honours it. It stays to the process's end: once the command's outcome is decided, a
    # signal during the shut-down no longer changes the exit status (interrupt.guard's to_exit).
    with interrupt.guard(to_exit=True) as signals:
        try:
            from casflex.cli import main as cli_main

            interrupt.check()
            code = cli_main()
        except KeyboardInterrupt as exc:  # Terminated too: before the command's handler runs (it catches later ones)
            signals.armed = False  # a second signal does not cut the one line short
            signum = signals.stopped_by(exc)
            interrupt.tell(f"\ncasflex: {interrupt.describe(signum)}")
            code = interrupt.exit_status(signum)
        if code in interrupt.EXIT_STATUSES:  # inside the guard: its hook keeps finalizer noise off stderr to the end
            _exit_interrupted(code, hurried=signals.count > 1)
        interrupt.skip_final_collection()
    return code
