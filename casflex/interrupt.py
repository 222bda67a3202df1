"""Ctrl-C that no library can swallow.

Python raises KeyboardInterrupt wherever the interpreter happens to be when SIGINT arrives,
and some places swallow it: CasADi turns one inside a solver into a failed solve, and Python
only prints "Exception ignored" for one raised in a weakref callback or finalizer (matplotlib
runs code there). :func:`guard` installs a handler that counts every SIGINT before raising,
and the long loops of casflex (HHT chunks, figures, animation frames) call :func:`check`
between their pieces, which raises again if a signal was received. Outside :func:`guard`
(plain Python use), :func:`check` does nothing and Ctrl-C behaves as Python's default.
"""

from __future__ import annotations

import contextlib
import signal
import sys
from collections.abc import Iterator

__all__ = ["Guard", "guard", "check"]


class Guard:
    """SIGINT as a guarded block sees it: ``count`` signals received; while ``armed`` each one
    raises KeyboardInterrupt (disarm it once the block's work is done)."""

    def __init__(self) -> None:
        self.count = 0
        self.armed = True

    def handler(self, signum: int, frame: object) -> None:
        self.count += 1
        if self.armed:
            raise KeyboardInterrupt


_active: list[Guard] = []


def check() -> None:
    """Raise KeyboardInterrupt if the innermost active :func:`guard` received a SIGINT (one that
    was swallowed where it was first raised); a no-op outside any guard or once disarmed."""
    if _active and _active[-1].count and _active[-1].armed:
        raise KeyboardInterrupt


@contextlib.contextmanager
def guard() -> Iterator[Guard]:
    """Count SIGINT and raise KeyboardInterrupt for the block (main thread only: elsewhere the
    handler cannot be installed and the block runs with Python's default behaviour).

    Re-entrant: inside an active guard the same :class:`Guard` is yielded, so a signal swallowed
    by an import before the command's own block began (the ``casflex`` entry point opens the
    outer guard first) is still counted by the guard the command consults."""
    if _active:
        yield _active[-1]
        return
    g = Guard()
    try:
        previous = signal.signal(signal.SIGINT, g.handler)
    except ValueError:  # not the main thread
        yield g
        return
    hook = sys.unraisablehook

    def quiet(unraisable) -> None:
        # A swallowed interrupt is counted and honoured later: no report. Once one arrived, the
        # finalizers of objects it left half-built (an import it cut short) fail too: a consequence
        # of the Ctrl-C already reported in one line, not news for the user.
        if not (g.count or issubclass(unraisable.exc_type, KeyboardInterrupt)):
            hook(unraisable)

    sys.unraisablehook = quiet
    _active.append(g)
    try:
        yield g
    finally:
        _active.remove(g)
        sys.unraisablehook = hook
        signal.signal(signal.SIGINT, previous)
