"""The growing horizon of output-error fits: windows that double, shorten where the model stops running,
and stages before the last anchored to the start within a capped budget."""

from __future__ import annotations

from types import SimpleNamespace

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


MODEL = SimpleNamespace(n_p=1)


def _fit_that_fails(bad, windows: list[float], status: str = "cost_tolerance"):
    """A stand-in for fit: fails to start where ``bad(window)``; records the windows tried; stages
    before the last end with ``status``."""
    def fake_fit(problem, w, budget, verbose=False, near=False, tol_se=None):
        windows.append(round(problem.window, 3))
        if bad(problem.window):
            raise StartDoesNotRun("the model does not run at the start: stand-in")
        last = not isinstance(problem, est._Anchored)
        return Fit(w + 1, np.zeros(1 if last else 2), np.zeros((1 if last else 2, 1)),
                   "cost_tolerance" if last else status, True, 3, 0.0, "")
    return fake_fit


def test_windows_double_to_the_whole_recording(monkeypatch):
    windows: list[float] = []
    monkeypatch.setattr(est, "OutputError", _Stage)
    monkeypatch.setattr(est, "fit", _fit_that_fails(lambda w: False, windows))
    problem, f = est._fit_growing(MODEL, [_experiment(1.6)], np.zeros(1), Budget(), verbose=False)
    assert windows == [0.25, 0.5, 1.0, 1.6] and f.converged and f.iterations == 12


def test_a_window_the_model_does_not_run_through_is_shortened(monkeypatch):
    # the 0.5 s window fails: the growth is halved (0.375 s), then doubling goes on from there
    windows: list[float] = []
    monkeypatch.setattr(est, "OutputError", _Stage)
    monkeypatch.setattr(est, "fit", _fit_that_fails(lambda w: abs(w - 0.5) < 1e-9, windows))
    problem, f = est._fit_growing(MODEL, [_experiment(1.0)], np.zeros(1), Budget(), verbose=False)
    assert windows == [0.25, 0.5, 0.375, 0.75, 1.0] and f.converged


def test_the_fit_ends_where_the_horizon_cannot_grow(monkeypatch):
    windows: list[float] = []
    monkeypatch.setattr(est, "OutputError", _Stage)
    monkeypatch.setattr(est, "fit", _fit_that_fails(lambda w: w > 0.2505, windows))
    problem, f = est._fit_growing(MODEL, [_experiment(1.0)], np.zeros(1), Budget(), verbose=False)
    assert len(windows) == 2 + est.MAX_CUTS and problem.window == 0.25
    assert not f.converged and "stopped at 0.25 s" in f.message


def test_a_start_that_does_not_run_is_the_users(monkeypatch):
    monkeypatch.setattr(est, "OutputError", _Stage)
    monkeypatch.setattr(est, "fit", _fit_that_fails(lambda w: True, []))
    with pytest.raises(StartDoesNotRun, match="does not run at the start"):
        est._fit_growing(MODEL, [_experiment(1.0)], np.zeros(1), Budget(), verbose=False)


def test_stages_before_the_last_go_on_when_they_run_out(monkeypatch):
    # a stage before the last only brings a start: at its cap of model runs the horizon still grows
    windows: list[float] = []
    monkeypatch.setattr(est, "OutputError", _Stage)
    monkeypatch.setattr(est, "fit", _fit_that_fails(lambda w: False, windows, status="iteration_limit"))
    problem, f = est._fit_growing(MODEL, [_experiment(1.0)], np.zeros(1), Budget(), verbose=False)
    assert windows == [0.25, 0.5, 1.0] and f.converged


class _Linear:
    """r = A w - y with a second column felt 1e4 times less than the first (1e8 in information)."""

    evaluations = 0
    A = np.array([[1.0, 1e-4], [1.0, -1e-4], [1.0, 0.0]])
    y = np.array([1.501, 1.499, 1.5])  # least squares: w = (1.5, 10)

    def bounds(self):
        return np.full(2, -np.inf), np.full(2, np.inf)

    def evaluate(self, w, jacobian=True):
        return self.A @ w - self.y, self.A


def test_the_anchor_holds_what_the_window_cannot_tell():
    stage = est._Anchored(_Linear(), np.array([0.0, 3.0]))
    r, J = stage.evaluate(np.array([1.0, 1.0]))
    weight = np.sqrt(est.ANCHOR * 3.0)  # ANCHOR x the largest column's information, |A[:, 0]|^2 = 3
    assert np.allclose(r[3:], weight * (np.array([1.0, 1.0]) - [0.0, 3.0]))
    assert np.allclose(J[3:], weight * np.eye(2)) and stage.bounds()[0].size == 2
    w = np.linalg.lstsq(J, -r + J @ [1.0, 1.0], rcond=None)[0]
    # the well-felt unknown takes the data's value (1.5) to ANCHOR, the weak one stays near its start 3
    # (it would be 10: moved by 7 x its information over the anchor's, 2e-8 / 3e-6)
    assert abs(w[0] - 1.5) < 1e-5 and abs(w[1] - 3.0) < 0.1


def test_transfer_state_puts_every_mesh_node_where_the_coarse_beam_has_it():
    # a beam of 2 elements on a fine mesh of 4: its mesh node "bar.1" is the midpoint in the coarse
    # model and the quarter point in the fine one (copying it by name put the fine model's quarter
    # node at the midpoint, and the refit for the model error failed at its first step)
    from casflex import Beam, Node, Scene, Support, assemble

    scene = Scene(name="bar", nodes=(Node("a", 0.0, 0.0), Node("b", 2.0, 1.0, vy=0.4)),
                  beams=(Beam("bar", ("a", "b"), E=2e11, A=1e-4, I=1e-8, rho=7800.0, elements=2),),
                  supports=(Support("clamp", "a", "clamp"),))
    model = assemble(scene)
    fine = est.refined(model)
    q, qd = est.transfer_state(model, fine, model.q0, model.qd0 + np.arange(model.n_dof))
    for k in range(1, 4):
        assert q[fine.dof(f"xbar.{k}")] == pytest.approx(0.5 * k)
        assert q[fine.dof(f"ybar.{k}")] == pytest.approx(0.25 * k)
    # velocities: linear along the coarse chain, between the coarse nodes' values
    mid = model.qd0[model.dof("ybar.1")] + model.dof("ybar.1")
    assert qd[fine.dof("ybar.2")] == pytest.approx(mid)
    assert q[fine.dof("yb")] == model.q0[model.dof("yb")]


def _exudyn_twobar(span: float):
    """Exudyn's twobar (8 ANCF elements per bar), nodes 3 and 5 at 100 Hz with 0.5 mm of noise, and casflex's
    model of it (1 element per bar): a real model error."""
    from pathlib import Path

    import casflex

    z = np.load(Path(__file__).resolve().parent / "data" / "twobar_exudyn.npz")
    names, rows = ("x3", "y3", "x5", "y5"), np.arange(0, int(round(1000 * span)) + 1, 10)
    ch = [str(c) for c in z["channels"]]
    q = z["q"][np.ix_(rows, [ch.index(c) for c in names])]
    data = MeasurementSet(z["t"][rows], names, q + np.random.default_rng(0).normal(0, 5e-4, q.shape), None, None)
    return casflex.assemble(casflex.load_scene("twobar")), Experiment(data, noise=5e-4)


def test_each_stage_of_the_growing_horizon_goes_on_from_the_last_ones_run(monkeypatch):
    from casflex.identification import ModelRun, Uncertainty, identify_indirect
    from casflex.identification import output_error as oe

    model, exp = _exudyn_twobar(1.0)
    steps: list[int] = []
    real = oe.run_sensitivities
    monkeypatch.setattr(oe, "run_sensitivities", lambda *a, **k: steps.append(a[5]) or real(*a, **k))

    def run():
        steps.clear()
        r = identify_indirect(model, exp, start=0.8, run=ModelRun(dt=1e-3),
                              uncertainty=Uncertainty(model_error="none", form="none"))
        return r, list(steps)

    (fast, s_fast) = run()
    monkeypatch.setattr(oe, "CONTINUE_STAGES", False)
    (slow, s_slow) = run()
    # the same model runs (the same steps, Newton scaling and step times): the same answer to the last digits
    assert fast.parameters == pytest.approx(slow.parameters, rel=1e-12)
    assert fast.std_errors == pytest.approx(slow.std_errors, rel=1e-9)
    assert fast.iterations == slow.iterations
    # each stage's first run carries on the last stage's: 0.25 + 0.5 s of the stages 0.5 s and 1 s not run again
    assert sum(s_slow) - sum(s_fast) == 750, (s_fast, s_slow)


def test_the_model_error_refit_by_chord_steps_gives_the_exact_refits_error(monkeypatch):
    from casflex.identification import ModelRun, Uncertainty, identify_indirect

    model, exp = _exudyn_twobar(1.0)

    def run():
        return identify_indirect(model, exp, start=0.8, run=ModelRun(dt=1e-3), uncertainty=Uncertainty(form="none"))

    fast = run()
    from casflex.identification import output_error as oe

    monkeypatch.setattr(oe, "CHORD_STEPS", False)  # the exact refit, with sensitivities
    exact = run()
    assert fast.extra["uncertainty"]["model_error_refit"]["status"] == "chord"
    assert exact.extra["uncertainty"]["model_error_refit"]["status"] != "chord"
    se = fast.extra["uncertainty"]["noise"]
    me_fast, me_exact = (r.extra["uncertainty"]["model_error"] for r in (fast, exact))
    assert max(me_exact[k] / se[k] for k in se) > 0.05  # an error the standard errors feel
    # to the fit's own tolerance (OFFSET_TOL = 0.01 SE): the refit's answer and so the reported errors
    assert all(abs(me_fast[k] - me_exact[k]) <= 0.01 * se[k] for k in se), (me_fast, me_exact, se)
    assert all(abs(fast.std_errors[k] - exact.std_errors[k]) <= 0.01 * se[k] for k in se)


def _parallel_springs(tmp_path):
    """twobar with a second spring beside spring1 (both parameters, 600 + 100 N/m): only their sum moves anything."""
    from importlib.resources import files

    text = (files("casflex.scene") / "builtin" / "twobar.toml").read_text()
    i = text.index("[[torsion_springs]]")
    text = (text[:i].replace("k = 700.0", "k = 600.0", 1) + '[[springs]]\nname = "spring1b"\nnodes = ["1", "2"]\n'
            'k = 100.0\nrest_length = 0.1\n\n' + text[i:] + '\n[[parameters]]\nname = "k1b"\ntarget = "spring1b.k"\n'
            'unit = "N/m"\nlower = 0.0\n')
    path = tmp_path / "parallel.toml"
    path.write_text(text)
    import casflex

    return casflex.assemble(casflex.load_scene(path))


def test_parameters_the_data_cannot_separate_do_not_succeed(tmp_path):
    # two springs in parallel: before, success (exit 0) with k1 = 600 +- inf and k1b = 100 +- inf, the start's split
    from pathlib import Path

    from casflex.identification import Uncertainty, identify_indirect

    model = _parallel_springs(tmp_path)
    z = np.load(Path(__file__).parent / "data" / "twobar_exudyn.npz")
    names, rows = ("x3", "y3", "x5", "y5"), np.arange(0, 501, 10)
    q = z["q"][np.ix_(rows, [[str(c) for c in z["channels"]].index(n) for n in names])]
    data = MeasurementSet(z["t"][rows], names, q + np.random.default_rng(0).normal(0, 5e-4, q.shape), None, None)
    r = identify_indirect(model, data, uncertainty=Uncertainty(model_error="none", form="none"))
    assert np.isinf(r.std_errors["k1"]) and np.isinf(r.std_errors["k1b"]) and np.isfinite(r.std_errors["k3"])
    assert not r.success and "k1, k1b are not determined by the data" in r.message
    assert "-0.71 k1 +0.71 k1b" in r.message and "hardly separable" in r.summary()
    assert r.parameters["k1"] + r.parameters["k1b"] == pytest.approx(700, rel=1e-3)  # their sum is determined


def test_undetermined_reasons_name_the_parameters_and_their_combination():
    from casflex.identification.problem import undetermined_reasons

    assert undetermined_reasons({"k1": 1.0, "kt1": 0.1}, {"k1": 1.0, "kt1": 0.0}) == []
    (one,) = undetermined_reasons({"k1": 1.0, "kt1": np.inf}, {"k1": 0.0, "kt1": 1.0})
    assert one.startswith("kt1 is not determined by the data") and "does not depend on it" in one
    (two,) = undetermined_reasons({"k1": np.inf, "k1b": np.inf}, {"k1": -0.71, "k1b": 0.71})
    assert two.startswith("k1, k1b are not determined") and "-0.71 k1 +0.71 k1b" in two
