"""The ``casflex`` command's entry point: nothing heavy is imported before Ctrl-C is caught, so an
interrupt while CasADi, numpy and matplotlib load exits with 130 and one line, as any other."""

import atexit
import os
import sys

INTERRUPTED = 130


def _exit_interrupted() -> None:
    """Exit with 130 for certain. A KeyboardInterrupt that crossed code an extension module ran at
    import (CPython's run_eval_code_obj) is recorded by CPython as unhandled, and at exit CPython
    then kills itself with SIGINT although casflex caught it: run the exit handlers, flush, and
    end here instead."""
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(INTERRUPTED)


def main() -> int:
    from casflex import interrupt  # light: signal and contextlib only (casflex/__init__ is lazy)

    # One guard for the whole process, opened before any heavy import: an interrupt that an
    # extension swallows while numpy, CasADi or matplotlib load is counted, and the command's
    # own guard (the same object) honours it.
    with interrupt.guard():
        try:
            from casflex.cli import main as cli_main

            interrupt.check()
            code = cli_main()
        except KeyboardInterrupt:  # before the command's own handler runs (it catches every later one)
            sys.stderr.write("\ncasflex: interrupted; nothing was written\n")
            code = INTERRUPTED
        if code == INTERRUPTED:  # inside the guard: its hook keeps finalizer noise off stderr to the end
            _exit_interrupted()
    return code
