"""The growing horizon of output-error fits: windows that double, and shorten where the model stops running."""

from __future__ import annotations

import numpy as np
import pytest

from casflex.data import MeasurementSet
from casflex.identification import estimate as est
from casflex.identification.measurement import Experiment
from casflex.identification.output_error import Budget, Fit, StartDoesNotRun


def _experiment(span: float) -> Experiment:
    t = np.arange(0.0, span + 1e-9, 0.001)
    return Experiment(MeasurementSet(t, ("x5",), np.zeros((t.size, 1)), None, None), "scene")


class _Stage:
    """A stand-in for OutputError: remembers its window (the span of its data)."""

    def __init__(self, model, experiments, **setup):
        e = experiments[0]
        self.window = float(e.data.t[-1] - e.data.t[0])


def _fit_that_fails(bad, windows: list[float]):
    """A stand-in for fit: fails to start where ``bad(window)``; records the windows tried."""
    def fake_fit(problem, w, budget, verbose=False):
        windows.append(round(problem.window, 3))
        if bad(problem.window):
            raise StartDoesNotRun("the model does not run at the start: stand-in")
        return Fit(w + 1, np.zeros(1), np.zeros((1, 1)), "cost_tolerance", True, 3, 0.0, "")
    return fake_fit


def test_windows_double_to_the_whole_recording(monkeypatch):
    windows: list[float] = []
    monkeypatch.setattr(est, "OutputError", _Stage)
    monkeypatch.setattr(est, "fit", _fit_that_fails(lambda w: False, windows))
    problem, f = est._fit_growing(None, [_experiment(1.6)], np.zeros(1), Budget(), verbose=False)
    assert windows == [0.25, 0.5, 1.0, 1.6] and f.converged and f.iterations == 12


def test_a_window_the_model_does_not_run_through_is_shortened(monkeypatch):
    # the 0.5 s window fails: the growth is halved (0.375 s), then doubling goes on from there
    windows: list[float] = []
    monkeypatch.setattr(est, "OutputError", _Stage)
    monkeypatch.setattr(est, "fit", _fit_that_fails(lambda w: abs(w - 0.5) < 1e-9, windows))
    problem, f = est._fit_growing(None, [_experiment(1.0)], np.zeros(1), Budget(), verbose=False)
    assert windows == [0.25, 0.5, 0.375, 0.75, 1.0] and f.converged


def test_the_fit_ends_where_the_horizon_cannot_grow(monkeypatch):
    windows: list[float] = []
    monkeypatch.setattr(est, "OutputError", _Stage)
    monkeypatch.setattr(est, "fit", _fit_that_fails(lambda w: w > 0.2505, windows))
    problem, f = est._fit_growing(None, [_experiment(1.0)], np.zeros(1), Budget(), verbose=False)
    assert len(windows) == 2 + est.MAX_CUTS and problem.window == 0.25
    assert not f.converged and "stopped at 0.25 s" in f.message


def test_a_start_that_does_not_run_is_the_users(monkeypatch):
    monkeypatch.setattr(est, "OutputError", _Stage)
    monkeypatch.setattr(est, "fit", _fit_that_fails(lambda w: True, []))
    with pytest.raises(StartDoesNotRun, match="does not run at the start"):
        est._fit_growing(None, [_experiment(1.0)], np.zeros(1), Budget(), verbose=False)
