"""Indirect (output-error) identification, Eqs. 15-17, single and multiple shooting, on casflex's
own simulated set (the method's consistency; data from another code: test_identification_realdata.py)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import translated

import casflex
from casflex.data import MeasurementSet
from casflex.identification import Experiment, ModelRun, Shooting, Solver, Uncertainty, identify_indirect
from casflex.simulate import simulated_set

H = 0.1  # horizon (s): short enough for CI, long enough that every parameter is felt
TOL = 1e-12  # the Newton tolerance of data and model (the default: one compiled library serves every test)


@pytest.fixture(scope="module")
def twobar():
    return casflex.assemble(casflex.load_scene("twobar"))


@pytest.fixture(scope="module")
def sim(twobar):
    return simulated_set(twobar, t_end=0.3, tol=TOL)


@pytest.mark.parametrize("transcription", ["single-shooting", "multiple-shooting"])
@pytest.mark.parametrize("start", [0.8, 1.2])
def test_recovers_truth_positions_only(twobar, sim, transcription, start):
    r = identify_indirect(twobar, sim, H, start=start, shooting=Shooting(transcription), run=ModelRun(newton_tol=TOL))
    assert r.success, (r.status, r.message)
    # 1e-6 (the bar): on 0.1 s the torsional springs are felt weakly; measured 1e-7..3e-7,
    # the floor set by the HHT Newton tolerance inside data and model
    np.testing.assert_allclose(r.p, twobar.p_nominal, rtol=1e-6)
    assert r.extra["transcription"] == transcription
    assert r.solver == ("gauss-newton" if transcription == "single-shooting" else "ipopt")
    if transcription == "multiple-shooting":
        assert r.extra["intervals"] == 5
    # multipliers over the window (t = 0 .. 0.1 s) are the clamp reactions of the simulation
    lam = np.array(r.multipliers)
    assert lam.shape == (101, twobar.n_con)
    np.testing.assert_allclose(lam, sim.meta["lam"][:101], rtol=1e-5, atol=1e-5 * np.abs(lam).max())


def test_full_residue_on_a_dof_subset_with_log_transform(twobar, sim):
    r = identify_indirect(twobar, Experiment(sim, channels=("x3", "y3", "x5", "y5")), H, start=0.5,
                          shooting=Shooting("single-shooting", residue="full"), solver=Solver(transform="log"),
                          run=ModelRun(newton_tol=TOL))
    assert r.success, r.status
    # 1e-5: measured 4.3e-6 on kt1 (IPOPT stops at its tolerance; over 0.1 s the torsion springs are felt
    # weakly, and the polish's steps on Eq. 17 are refused at the Newton floor)
    np.testing.assert_allclose(r.p, twobar.p_nominal, rtol=1e-5)
    assert r.extra["dofs"] == ["x3", "y3", "x5", "y5"] and r.extra["transform"] == "log"


def test_multiple_shooting_from_far(twobar, sim):
    r = identify_indirect(twobar, sim, H, start=2.0, shooting=Shooting("multiple-shooting", interval=10),
                          run=ModelRun(newton_tol=TOL))
    assert r.success, r.status
    assert r.extra["intervals"] == 10
    np.testing.assert_allclose(r.p, twobar.p_nominal, rtol=1e-6)


def test_noisy_positions_standard_errors_cover_truth(twobar, sim):
    rng = np.random.default_rng(7)
    sigma = 1e-5  # m, rad
    noisy = MeasurementSet(sim.t, sim.channels, sim.q + rng.normal(0, sigma, sim.q.shape), None, None)
    trans = [d for d in twobar.dof_names if not d.startswith("theta")]
    r = identify_indirect(twobar, Experiment(noisy, channels=tuple(trans)), 0.2, start=1.2,
                          shooting=Shooting("single-shooting"))
    assert r.success, r.status
    err = np.abs(r.p - twobar.p_nominal)
    se = np.array(list(r.std_errors.values()))
    assert np.all(se > 0)
    # 4 SE: a fixed-seed draw; each parameter's error is a ~N(0, SE) variable
    assert np.all(err <= 4 * se), (err, se)
    # the residual variance estimates the noise (residuals in m); 10 %: 2000 residuals give s to ~2 %
    s = np.sqrt(r.identifiability["residual_variance"])
    assert s == pytest.approx(sigma, rel=0.1)
    # over 0.2 s at 1e-5 m the torsion springs are not pinned down, and the result says so
    assert set(r.identifiability["weak"]) >= {"kt1", "kt3"}


@pytest.mark.parametrize(("kwargs", "match"), [
    (lambda sim: {"shooting": Shooting(residue="velocities")}, "residue"),
    (lambda sim: {"shooting": Shooting("collocation")}, "transcription"),
    (lambda sim: {"data": Experiment(sim, channels=("x9",))}, "unknown dof 'x9'"),
    (lambda sim: {"shooting": Shooting(weights=(1.0, -1.0, 0.0))}, "weights"),
    (lambda sim: {"solver": Solver(transform="sqrt")}, "transform"),
    (lambda sim: {"shooting": Shooting("multiple-shooting", interval=0)}, "interval"),
    (lambda sim: {"solver": Solver("no_such_solver")}, "solver 'no_such_solver'"),
    (lambda sim: {"start": -1.0}, "start"),
    (lambda sim: {"data": Experiment(sim, initial_state="guess")}, "initial_state"),
    (lambda sim: {"data": Experiment(sim, initial_state="velocities"), "solver": Solver("ipopt")},
     "from the scene's initial state or an estimated one"),
    (lambda sim: {"data": Experiment(sim, initial_state="estimate"), "solver": Solver("ipopt"),
                  "shooting": Shooting(residue="full")}, "an estimated one .residue 'positions'"),
    (lambda sim: {"solver": Solver("gauss-newton"), "shooting": Shooting(residue="full")},
     "single shooting on positions"),
])
def test_bad_options_are_named(twobar, sim, kwargs, match):
    with pytest.raises(ValueError, match=match):
        options = kwargs(sim)  # the option objects refuse their own bad values when made
        identify_indirect(twobar, options.pop("data", sim), 0.01, **options)


def test_bad_horizons_and_data(twobar, sim):
    with pytest.raises(ValueError, match="beyond the data"):
        identify_indirect(twobar, sim, 1.0)
    with pytest.raises(ValueError, match="whole number of steps"):  # the NLP's grid must hold the samples
        identify_indirect(twobar, sim, 0.01, shooting=Shooting("multiple-shooting"), run=ModelRun(dt=7e-4))
    pos = MeasurementSet(sim.t, sim.channels, sim.q, None, None)
    with pytest.raises(ValueError, match="residue 'full'"):
        identify_indirect(twobar, pos, 0.01, shooting=Shooting(residue="full"))
    part = MeasurementSet(sim.t, ("x5", "y5"), sim.q[:, [12, 13]], None, None)
    with pytest.raises(ValueError, match="'x3' is not in the data"):
        identify_indirect(twobar, Experiment(part, channels=("x3",)), 0.01)


@pytest.mark.parametrize("transcription", ["single-shooting", "multiple-shooting"])
def test_compiled_matches_interpreted(twobar, sim, transcription):
    # generated C for every function IPOPT calls: same iterates, same answer (multiple shooting's
    # compiled NLP: one interval Function mapped over the intervals, ~5 s to build; its slow
    # manifold's Newton solve is fast_newton in C, newton interpreted)
    kw = {"shooting": Shooting(transcription), "start": 0.8, "uncertainty": Uncertainty(model_error="none")}
    ref = identify_indirect(twobar, sim, 0.05, solver=Solver("ipopt"), **kw)
    r = identify_indirect(twobar, sim, 0.05, solver=Solver("ipopt", compiled=True), **kw)
    assert r.success and r.extra["compiled"]
    assert r.iterations == ref.iterations
    np.testing.assert_allclose(r.p, ref.p, rtol=1e-10)
    if transcription == "multiple-shooting":
        assert r.extra["intervals"] == 2
        np.testing.assert_allclose(list(r.extra["nlp"]["solver_parameters"].values()),
                                   list(ref.extra["nlp"]["solver_parameters"].values()), rtol=1e-8)


def test_exact_hessian_option(twobar, sim):
    r = identify_indirect(twobar, sim, 0.05, start=0.8, shooting=Shooting("single-shooting"),
                          solver=Solver("ipopt", hessian="exact"))
    assert r.success and r.extra["hessian"] == "exact" and r.solver == "ipopt"
    np.testing.assert_allclose(r.p, twobar.p_nominal, rtol=1e-5)


def test_multiple_shooting_full_residue_warns(twobar, sim):
    with pytest.warns(UserWarning, match="single shooting is recommended"), pytest.raises(ValueError, match="dofs"):
        identify_indirect(twobar, Experiment(sim, channels=("nope",)), 0.01,
                          shooting=Shooting("multiple-shooting", residue="full"))


def test_a_scene_far_from_the_origin_is_identified():
    # 10 km away the HHT residual cannot reach newton_tol = 1e-14 (round-off ~eps 1e4 / l); the
    # steps are accepted at that floor, so the identification is not declared failed
    far = casflex.assemble(translated(casflex.load_scene("twobar"), 1e4))
    data = simulated_set(far, 0.3)
    # (model_error and form "none": a scene 10 km away is a library of its own; its refined twin would be another,
    # and so would its other beam theory: two more compiled libraries, 12 s of gcc, for a check on the fit's steps)
    r = identify_indirect(far, data, 0.3, start=1.2, shooting=Shooting("single-shooting"),
                          uncertainty=Uncertainty(model_error="none", form="none"))
    assert r.success, r.message
    # measured 1.7e-7 (6e-11 at the origin): the data's positions carry the round-off of 1e4 m
    np.testing.assert_allclose(r.p, far.p_nominal, rtol=1e-5)


@pytest.mark.parametrize("scene", ["twobar", "threelink"])
def test_the_final_trajectory_compiles_only_a_library_that_is_built(scene, monkeypatch):
    # the fit's last simulation (its trajectory): a first run's few hundred steps interpreted, not 4-12 s of gcc;
    # with the HHT library built (in the process, or on disk) compiled; the same numbers either way
    import casflex.simulate.run as run
    from casflex import codegen

    model = casflex.assemble(casflex.load_scene(scene))
    data = simulated_set(model, t_end=0.3, tol=TOL)
    kw = {"run": ModelRun(newton_tol=TOL), "uncertainty": Uncertainty(model_error="none", form="none")}
    builds, real = [], run.compile_functions

    def refused(*args, **kwargs):
        builds.append(kwargs.get("stem"))
        raise AssertionError("the final simulation compiled the HHT library")

    monkeypatch.setattr(run, "_LIBRARIES", type(run._LIBRARIES)())  # nothing built in this process
    monkeypatch.setattr(run, "is_cached", lambda *a, **k: False)  # nor on disk: a first run
    monkeypatch.setattr(run, "compile_functions", refused)
    first = identify_indirect(model, data, H, **kw)
    assert first.success and builds == [] and not first.trajectories[0].meta["compiled"]
    assert first.extra["compiled"]  # the fit's own sensitivities stay compiled

    monkeypatch.setattr(run, "compile_functions", real)
    run.compiled_library(run.integrator_for(model, alpha=first.extra["alpha"], tol=TOL))  # built in the process
    built = identify_indirect(model, data, H, **kw).trajectories[0]
    monkeypatch.setattr(run, "_LIBRARIES", type(run._LIBRARIES)())
    monkeypatch.setattr(run, "is_cached", codegen.is_cached)  # on disk only (a later process)
    cached = identify_indirect(model, data, H, **kw).trajectories[0]
    assert built.meta["compiled"] and cached.meta["compiled"] and cached.meta["stats"]["compile_cached"]
    for tr in (built, cached):
        for key in ("q", "qd", "qdd", "lam"):
            if codegen.bitwise_expected():  # the default build flags: compiled runs are the interpreted ones
                np.testing.assert_array_equal(getattr(tr, key), getattr(first.trajectories[0], key))
            else:  # other flags: each step solves the same equations to the Newton tolerance
                np.testing.assert_allclose(getattr(tr, key), getattr(first.trajectories[0], key), rtol=1e-8,
                                           atol=1e-8 * np.abs(getattr(tr, key)).max())
