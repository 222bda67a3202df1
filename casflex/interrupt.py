"""Ctrl-C, and the signals that ask a program to end, that no library can swallow.

Python raises KeyboardInterrupt wherever the interpreter happens to be when SIGINT arrives,
and some places swallow it: CasADi turns one inside a solver into a failed solve, and Python
only prints "Exception ignored" for one raised in a weakref callback or finalizer (matplotlib
runs code there). :func:`guard` installs a handler that counts every signal before raising,
and the long loops of casflex (HHT chunks, figures, animation frames) call :func:`check`
between their pieces, which raises again if a signal was received. Outside :func:`guard`
(plain Python use), :func:`check` does nothing and Ctrl-C behaves as Python's default.

SIGTERM (``kill``, ``timeout``, batch schedulers) and SIGHUP (a closed terminal) are guarded
alike: they raise :class:`Terminated`, a KeyboardInterrupt, so a command stops on them as on
Ctrl-C, cleans up and exits with 128 + the signal's number (130, 143, 129).
"""

from __future__ import annotations

import contextlib
import signal
import sys
from collections.abc import Iterator

__all__ = ["Guard", "Terminated", "SIGNALS", "EXIT_STATUSES", "guard", "check", "exit_status", "describe", "tell",
           "skip_final_collection",
           "progress"]

#: The guarded signals: Ctrl-C; the polite "end now" of kill, timeout and batch schedulers; a closed
#: terminal (SIGHUP does not exist on Windows).
SIGNALS: tuple[int, ...] = tuple(
    getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name)
)


def exit_status(signum: int) -> int:
    """The exit status of a command stopped by ``signum``: 128 + its number, as a shell reports a
    process the signal killed (130 for SIGINT, 143 for SIGTERM, 129 for SIGHUP)."""
    return 128 + int(signum)


#: The exit statuses of a stopped command (casflex's own statuses are 0, 1 and 2).
EXIT_STATUSES = frozenset(exit_status(s) for s in SIGNALS)


def describe(signum: int) -> str:
    """What the one line on stderr says when ``signum`` stopped a command."""
    if signum == signal.SIGINT:
        return "interrupted; nothing was written"
    return f"terminated ({signal.Signals(signum).name}); nothing was written"


def tell(line: str) -> None:
    """Write ``line`` to stderr; a terminal already closed (SIGHUP) is no reason to fail."""
    try:
        sys.stderr.write(line + "\n")
        sys.stderr.flush()
    except (OSError, ValueError):
        pass


_shown = [-1]  # the quarter of the loop that :func:`progress` last showed (not on a terminal); -1: none yet


def progress(text: str, done: int, total: int, *, each: bool = False) -> None:
    """Show a long loop's progress ``text`` at step ``done`` of ``total`` on stderr: on a terminal one line
    rewritten in place (carriage return), ended at the last step; elsewhere (a log file, a pipe, a batch job's
    output) whole lines only, so a log holds no carriage returns: every step's where ``each`` (each says what
    finished: a study's runs), else at the first step, each quarter and the last (a counter's)."""
    try:
        if getattr(sys.stderr, "isatty", lambda: False)():
            sys.stderr.write(f"\r{text}" + ("\n" if done >= total else ""))
        elif each:
            sys.stderr.write(text.rstrip() + "\n")
        elif (quarter := min(4 * done // max(total, 1), 4)) > _shown[0]:
            sys.stderr.write(text.rstrip() + "\n")
            _shown[0] = -1 if done >= total else quarter  # the loop's end: the next loop starts afresh
        sys.stderr.flush()
    except (OSError, ValueError):  # a terminal already closed (SIGHUP)
        pass


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP, raised where Ctrl-C raises KeyboardInterrupt. A subclass of it, so that
    everything that already stops cleanly on Ctrl-C (the simulation's loop, a sweep, the command's
    handler) stops on these the same way; ``signum`` says which signal it was."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def _raised(signum: int) -> KeyboardInterrupt:
    return KeyboardInterrupt() if signum == signal.SIGINT else Terminated(signum)


class Guard:
    """The signals as a guarded block sees them: ``count`` received, ``signum`` the first of them
    (SIGINT until one arrives); while ``armed`` each one raises KeyboardInterrupt (SIGINT) or
    :class:`Terminated` (disarm it once the block's work is done, and for its clean-up)."""

    def __init__(self) -> None:
        self.count = 0
        self.signum: int = signal.SIGINT
        self.armed = True

    def handler(self, signum: int, frame: object) -> None:
        if not self.count:  # the first signal stopped the block; a later one only hurries it
            self.signum = signum
        self.count += 1
        if self.armed:
            raise _raised(self.signum)

    def stopped_by(self, exc: BaseException | None = None) -> int:
        """The signal that stopped the block: the first one received, else the one ``exc`` names."""
        return self.signum if self.count else getattr(exc, "signum", signal.SIGINT)


_active: list[Guard] = []


def check() -> None:
    """Raise KeyboardInterrupt (or :class:`Terminated`) if the innermost active :func:`guard`
    received a signal (one that was swallowed where it was first raised); a no-op outside any
    guard or once disarmed."""
    if _active and _active[-1].count and _active[-1].armed:
        raise _raised(_active[-1].signum)


def _install(handler) -> dict[int, object]:
    """Install ``handler`` for the guarded signals; returns the previous handlers. SIGTERM and
    SIGHUP stay ignored where the caller ignores them (``nohup`` ignores SIGHUP so that a run
    outlives its terminal); SIGINT is taken as before, ignored or not."""
    previous = {}
    for signum in SIGNALS:
        if signum != signal.SIGINT and signal.getsignal(signum) is signal.SIG_IGN:
            continue
        old = signal.signal(signum, handler)
        previous[signum] = signal.SIG_DFL if old is None else old  # None: a handler not set from Python
    return previous


@contextlib.contextmanager
def guard(to_exit: bool = False) -> Iterator[Guard]:
    """Count SIGINT, SIGTERM and SIGHUP and raise for them in the block (main thread only:
    elsewhere the handlers cannot be installed and the block runs with Python's default behaviour).

    ``to_exit``: the block is the whole process (the ``casflex`` entry point). On leaving it the
    guarded signals are ignored to the process's end instead of the previous handlers restored: a
    signal during the interpreter's shut-down (up to a few hundred ms, after the outputs were moved
    into place) no longer kills it, so the exit status says what was done (0 and the outputs
    written), never "killed by SIGTERM" over files that were replaced. Ignored, not handled:
    CPython's finalisation puts a Python handler back to the default action, it keeps SIG_IGN.

    Re-entrant: inside an active guard the same :class:`Guard` is yielded, so a signal swallowed
    by an import before the command's own block began (the ``casflex`` entry point opens the
    outer guard first) is still counted by the guard the command consults."""
    if _active:
        yield _active[-1]
        return
    g = Guard()
    try:
        previous = _install(g.handler)
    except ValueError:  # not the main thread
        yield g
        return
    hook = sys.unraisablehook

    def quiet(unraisable) -> None:
        # A swallowed interrupt is counted and honoured later: no report. Once one arrived, the
        # finalizers of objects it left half-built (an import it cut short) fail too: a consequence
        # of the signal already reported in one line, not news for the user.
        if not (g.count or issubclass(unraisable.exc_type, KeyboardInterrupt)):
            hook(unraisable)

    sys.unraisablehook = quiet
    _active.append(g)
    try:
        yield g
    finally:
        _active.remove(g)
        sys.unraisablehook = hook
        for signum, old in previous.items():
            signal.signal(signum, signal.SIG_IGN if to_exit else old)


def skip_final_collection() -> None:
    """A process that is done (the command, a study's worker, the fork server): the interpreter's last garbage
    collection at exit skipped. It walks every object the process made (CasADi's, numpy's, matplotlib's, dask's):
    1-2 s of a study's command on a loaded machine after its last output, half a second of a worker's exit, for
    which the nanny waits at the cluster's close, for memory the process's end frees anyway. Objects still go
    away as at any exit (files flushed and closed, the exit handlers run, threads joined): only the cycle collector
    no longer looks at them."""
    import gc

    gc.disable()
    gc.freeze()
