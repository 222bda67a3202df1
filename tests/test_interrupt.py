"""casflex.interrupt: a Ctrl-C that a library swallows is still honoured."""

from __future__ import annotations

import os
import signal

import pytest

from casflex import interrupt


def _swallowed_sigint() -> None:
    """SIGINT raised and swallowed, as an extension's ``except: pass`` (or PyErr_Clear) does."""
    try:
        os.kill(os.getpid(), signal.SIGINT)
        for _ in range(1000):  # the handler runs between bytecodes of this frame
            pass
    except KeyboardInterrupt:
        pass


def test_check_raises_after_a_swallowed_interrupt_and_is_quiet_outside_a_guard():
    # the handler before the guard: Python's default, or SIG_IGN when the suite was started as a
    # background job of a non-interactive shell (it then inherits SIGINT ignored)
    before = signal.getsignal(signal.SIGINT)
    interrupt.check()  # no guard: a no-op
    with interrupt.guard() as g:
        _swallowed_sigint()
        assert g.count == 1
        with pytest.raises(KeyboardInterrupt):
            interrupt.check()
        g.armed = False  # the work is done: a later Ctrl-C is counted, not raised
        interrupt.check()
    assert signal.getsignal(signal.SIGINT) is before  # the guard restores what it found


def test_a_nested_guard_is_the_outer_one():
    # the entry point opens the outer guard before the heavy imports; an interrupt an import
    # swallowed there must be seen by the command's own guard (CI once lost one at 0.26 s)
    with interrupt.guard() as outer:
        _swallowed_sigint()
        with interrupt.guard() as inner:
            assert inner is outer and inner.count == 1
            with pytest.raises(KeyboardInterrupt):
                interrupt.check()
        assert signal.getsignal(signal.SIGINT) == outer.handler  # the inner block left it installed


class _HalfBuilt:
    """An object whose finalizer fails, as one an interrupted import left half-built does
    (pyparsing's Forward once printed "Exception ignored in ... __del__" after a Ctrl-C in CI)."""

    def __del__(self) -> None:
        raise AttributeError("'_HalfBuilt' object has no attribute 'expr'")


def test_finalizer_failures_are_reported_until_an_interrupt_and_silent_after(monkeypatch):
    seen: list[type] = []
    monkeypatch.setattr("sys.unraisablehook", lambda u: seen.append(u.exc_type))
    with interrupt.guard():
        _HalfBuilt()  # no interrupt yet: a real bug, reported as Python would
        assert seen == [AttributeError]
        _swallowed_sigint()
        _HalfBuilt()  # after the Ctrl-C: a consequence of it, kept off stderr
        assert seen == [AttributeError]
    _HalfBuilt()  # the guard restored the hook it found
    assert seen == [AttributeError, AttributeError]


def test_sigterm_raises_terminated_a_keyboardinterrupt_and_an_ignored_sighup_stays_ignored():
    term = signal.getsignal(signal.SIGTERM)
    hup = signal.signal(signal.SIGHUP, signal.SIG_IGN)  # as nohup starts a command
    try:
        with interrupt.guard() as g:
            assert signal.getsignal(signal.SIGTERM) == g.handler
            assert signal.getsignal(signal.SIGHUP) is signal.SIG_IGN  # the run outlives its terminal, as asked
            with pytest.raises(interrupt.Terminated) as exc:
                os.kill(os.getpid(), signal.SIGTERM)
                for _ in range(1000):  # the handler runs between bytecodes of this frame
                    pass
            # a KeyboardInterrupt: whatever stops cleanly on Ctrl-C stops on SIGTERM alike
            assert isinstance(exc.value, KeyboardInterrupt) and exc.value.signum == signal.SIGTERM
            with pytest.raises(interrupt.Terminated):  # swallowed, it is raised again
                interrupt.check()
            assert interrupt.exit_status(g.stopped_by()) == 143
            assert interrupt.describe(g.stopped_by()) == "terminated (SIGTERM); nothing was written"
        assert signal.getsignal(signal.SIGTERM) == term  # the guard restores what it found
    finally:
        signal.signal(signal.SIGHUP, hup)


def test_progress_is_whole_lines_where_stderr_is_no_terminal(monkeypatch):
    import io
    import sys

    from casflex.interrupt import progress

    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    for stream, each in ((io.StringIO(), False), (io.StringIO(), True), (Terminal(), False)):
        monkeypatch.setattr(sys, "stderr", stream)
        for done in range(1, 11):
            progress(f"step {done}/10  ", done, 10, each=each)
        text = stream.getvalue()
        if isinstance(stream, Terminal):  # one line rewritten in place, ended at the last step
            assert text.count("\r") == 10 and text.endswith("step 10/10  \n") and text.count("\n") == 1
        else:  # a log: whole lines, every step's or the first, at each quarter and the end
            assert "\r" not in text and text.endswith("step 10/10\n")
            assert len(text.splitlines()) == (10 if each else 5), text  # 1/10, then 3/10, 5/10, 8/10, 10/10
