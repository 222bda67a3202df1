"""Markers' channels in every identification method: the NLP transcriptions of the indirect method
compare them through their kinematics, the direct methods turn them into nodes' dofs first. Data:
Exudyn's twobar with a marker on each bar (tests/data/twobar_markers_exudyn.npz, 8 ANCF elements per
bar, h = 1e-4 s), at 100 Hz with 0.1 mm of noise, fitted by casflex's one element per bar."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import casflex
from casflex.data import MeasurementSet
from casflex.identification import Experiment, ModelRun, Shooting, Uncertainty, identify_adapted_direct, identify_direct
from casflex.identification.estimate import FIT_THRESHOLD, pooled_fit
from casflex.identification.shooting_nlp import _channel_kinematics, identify_nlp
from casflex.model.markers import marker_channels, marker_states
from casflex.simulate import simulated_set

DATA = Path(__file__).resolve().parent / "data"
NOISE = 1e-4  # m


@pytest.fixture(scope="module")
def model():
    return casflex.assemble(casflex.load_scene(DATA / "twobar_markers.toml"))


def recording(names: tuple[str, ...], t_to: float, seed: int = 0) -> MeasurementSet:
    """Channels ``names`` of Exudyn's motion from 0 to t_to (s) at 100 Hz, with NOISE."""
    z = np.load(DATA / "twobar_markers_exudyn.npz")
    ch = [str(c) for c in z["channels"]]
    rows = np.arange(0, int(round(t_to * 1000)) + 1, 10)
    q = z["q"][np.ix_(rows, [ch.index(c) for c in names])]
    return MeasurementSet(z["t"][rows], names, q + np.random.default_rng(seed).normal(0, NOISE, q.shape), None, None)


def test_marker_rates_are_those_of_the_motion(model):
    # along a smooth path q(t), the channels' y' = J q' and y'' = J q'' + (dJ/dq q') q' against
    # central differences of y(q(t)); measured 7e-8 m/s and 2.4e-7 m/s^2 (truncation and round-off) on
    # accelerations of 13 m/s^2, of which the (dJ/dq q') q' term alone is 0.1 m/s^2
    rng = np.random.default_rng(1)
    a, b, c = (rng.normal(0, s, model.n_dof) for s in (1.0, 3.0, 5.0))

    def path(t: float) -> tuple[np.ndarray, ...]:
        return model.q0 + a * t + b * t**2 + c * t**3, a + 2 * b * t + 3 * c * t**2, 2 * b + 6 * c * t

    names = ["x3", "theta3", *marker_channels(model)]
    f = _channel_kinematics(model, names, 3)
    t, h = 0.1, 1e-4
    y, yd, ydd = (np.array(v).ravel() for v in f(*path(t)))
    ym, yp = (np.array(f(*path(t + s))[0]).ravel() for s in (-h, h))
    np.testing.assert_allclose(yd, (yp - ym) / (2 * h), atol=1e-6)
    np.testing.assert_allclose(ydd, (yp - 2 * y + ym) / h**2, atol=1e-5)


def test_multiple_shooting_on_nodes_and_markers(model):
    # node 3 and both markers (node 5 unrecorded), 0.5 s. The interval starts come from kinematic fits
    # through them: node 3 and m2 over-determine bar2, whose fit stretches it by the noise (3.6e-4,
    # 2e5 N) until the start is relaxed onto the slow manifold; before, IPOPT stopped 'acceptable'
    # with k3 55-92 % off (casflex's own data, seeds 0-2). Polished: |z| <= 1.9 (seeds 0-3)
    names = ("x3", "y3", "xm2", "ym2", "xm4", "ym4")
    # the model at 2 ms (intervals of 20 ms, as the default's at 1 ms): the same answers, half the time
    r = identify_nlp(model, Experiment(recording(names, 0.5), noise=NOISE), 0.5, start=0.8,
                     shooting=Shooting("multiple-shooting", interval=10),
                     run=ModelRun(dt=2e-3, alpha=0.0, newton_tol=1e-14))
    assert r.success, (r.status, r.message)
    assert r.extra["dofs"] == list(names) and r.extra["constraint_violation"] < 1e-8
    # the identified model through the recording: 99.9 % of the motion, white residuals at the noise (measured
    # 0.90-1.24 x; the wrong forms below: 3-540 x)
    res = r.extra["experiments"]["data"]["residuals"]
    assert pooled_fit(res) > 0.99 and all(ch["white"] and ch["noise_ratio"] < 1.5 for ch in res.values()), res
    for name, truth in zip(model.parameter_names, model.p_nominal, strict=True):
        own = r.extra["solver_parameters"][name]  # the transcription's own optimum, before the polish
        if not name.startswith("kt"):  # measured within 0.19 % (seeds 0-3); kt is weak over 0.5 s
            assert abs(own / truth - 1) < 5e-3, name
        assert abs(r.parameters[name] - truth) <= 3 * r.std_errors[name], name


def test_multiple_shooting_on_a_model_of_the_wrong_form_does_not_say_success():
    """Bar 2 twice as heavy as Exudyn's (bar 4 as it is: no stiffness makes up for it). IPOPT ends 'acceptable'
    with kt3 on its lower bound, kt1 135 x its value and an objective 900 x the right model's; before, that was
    success. Now, as the default path, a parameter on a bound withholds it and says why."""
    text = (DATA / "twobar_markers.toml").read_text().replace("rho = 7800.0", "rho = 15600.0", 1)
    heavy = casflex.assemble(casflex.loads_scene(text, base=DATA))
    names = ("x3", "y3", "xm2", "ym2", "xm4", "ym4")
    r = identify_nlp(heavy, recording(names, 0.5), 0.5, start=1.0, shooting=Shooting("multiple-shooting", interval=10),
                     run=ModelRun(dt=2e-3, alpha=0.0, newton_tol=1e-14))
    assert not r.success and any(r.at_bound.values()), (r.status, r.parameters)
    assert "ended on a bound: the best fit lies outside the parameters' range" in r.message
    # the bound alone withholds it: the identified model reproduces 98 % of the motion (measured 98.4 %), the
    # default path's rule (95 % or white residuals) passes it, though no channel's residual is white
    res = r.extra["experiments"]["data"]["residuals"]
    assert pooled_fit(res) > FIT_THRESHOLD and not any(ch["white"] for ch in res.values())
    assert r.extra["refusal"]["residuals"] == []


def _heavy_with_free_torsion_springs() -> casflex.Model:
    """twobar_markers with bar 2 twice Exudyn's density and the torsion springs' lower bounds at -1000 N m/rad
    (the defaults: 0), so that no bound stops the fit of the wrong model."""
    text = (DATA / "twobar_markers.toml").read_text().replace("rho = 7800.0", "rho = 15600.0", 1)
    for j in ("1", "3"):
        text = text.replace(f'target = "torsion{j}.kt"', f'target = "torsion{j}.kt"\nlower = -1000.0', 1)
    return casflex.assemble(casflex.loads_scene(text, base=DATA))


def test_multiple_shooting_on_a_model_of_the_wrong_form_within_its_bounds_does_not_say_success():
    """The heavy bar 2 over 1 s, no bound in reach: IPOPT ends 'acceptable' with kt1 136 (270 x), kt3 21, an objective
    1.2e5 x the right model's (0.090 against 7.6e-7), and said success. The identified model, simulated from the
    scene's state through the recording, reproduces 91 % of the measured motion (in noise units) with no channel's
    residual white: the default path's rule withholds success and names the experiment and the worst channel.
    (Over 0.5 s the same model fits 98 %: without a declared noise that passes, as in the default path.)"""
    names = ("x3", "y3", "xm2", "ym2", "xm4", "ym4")
    r = identify_nlp(_heavy_with_free_torsion_springs(), recording(names, 1.0), 1.0, start=1.0,
                     shooting=Shooting("multiple-shooting", interval=10),
                     run=ModelRun(dt=2e-3, alpha=0.0, newton_tol=1e-14))
    # converged, under either of IPOPT's labels (which one is round-off at its tolerance: see the test below)
    assert r.status in ("Solve_Succeeded", "Solved_To_Acceptable_Level"), (r.status, r.message)
    assert not any(r.at_bound.values()), r.parameters
    assert not r.success, r.parameters
    assert r.extra["refusal"]["other"] == []  # the residuals alone withhold it
    res = r.extra["experiments"]["data"]["residuals"]
    assert pooled_fit(res) < 0.93 and not any(ch["white"] for ch in res.values())  # measured 91.1 %
    assert r.extra["experiments"]["data"]["noise"]["source"].startswith("estimated from the residuals")
    assert set(res) == set(names) and all({"rms", "fit", "ljung_box_p", "motion_w", "residual_w"} <= set(ch)
                                          for ch in res.values())
    assert "data: the model reproduces only 91 % of the measured motion" in r.message
    assert "the largest on ym2" in r.message


def test_multiple_shooting_residuals_above_the_declared_noise_do_not_say_success():
    """The heavy bar 2 over 0.5 s: IPOPT converges (kt3 -1.6, kt1 89) and the model reproduces 98 % of the motion,
    which alone passes; with the recording's noise declared (0.1 mm), its residuals are 3-55 x it."""
    names = ("x3", "y3", "xm2", "ym2", "xm4", "ym4")
    r = identify_nlp(_heavy_with_free_torsion_springs(), Experiment(recording(names, 0.5), noise=NOISE), 0.5, start=1.0,
                     shooting=Shooting("multiple-shooting", interval=10),
                     run=ModelRun(dt=2e-3, alpha=0.0, newton_tol=1e-14))
    # IPOPT converges: which of its two converged labels it ends with is round-off at its tolerance on this wrong
    # model (a sum reordered in the band solver turned 'Solve_Succeeded' into 'Solved_To_Acceptable_Level' with the
    # same parameters to 1e-11 and the same objective to 1e-15)
    assert r.status in ("Solve_Succeeded", "Solved_To_Acceptable_Level"), (r.status, r.message)
    assert not any(r.at_bound.values()), r.parameters
    assert not r.success, r.parameters
    res = r.extra["experiments"]["data"]["residuals"]
    assert pooled_fit(res) > FIT_THRESHOLD  # measured 98.4 %
    assert r.extra["experiments"]["data"]["noise"] == {"source": "declared", "channels": dict.fromkeys(names, NOISE)}
    assert res["x3"]["noise_ratio"] > 50  # measured 54.6
    assert "data: the residual RMS of x3 is 54.6 x the declared noise" in r.message


def test_estimated_initial_state_from_nodes_and_markers(model):
    # the default method (Gauss-Newton single shooting) on the recording mid-motion (0.3-1 s): its
    # estimated initial state is linearised at the kinematic fit relaxed onto the slow manifold. When that was
    # added, linearised at the fit with bar2 stretched by the noise, seeds 1 and 2 of 0-3 stopped at a 78 % fit
    # with kt on its bounds. Measured 2026-11-29: today's fit passes seeds 1 and 2 with the relaxation skipped
    # too, so this test no longer guards the relaxation (an open gap, said in the note); it guards the
    # estimated initial state from nodes and markers
    from casflex.identification import identify_indirect

    names = ("x3", "y3", "xm2", "ym2", "xm4", "ym4")
    data = recording(names, 1.0, seed=1).window(0.3, 1.0)
    # form "none": the other beam theory's refit compiled a library of its own (6 s of CPU with gcc) and left every
    # estimate and standard error as they were (to 4 digits: measured); it has its own tests (test_identification_form)
    r = identify_indirect(model, Experiment(data, initial_state="estimate", noise=NOISE), start=0.8,
                          run=ModelRun(dt=1e-3), uncertainty=Uncertainty(model_error="none", form="none"))
    assert r.success, r.message
    for name, truth in zip(model.parameter_names, model.p_nominal, strict=True):
        assert abs(r.parameters[name] - truth) <= 3 * r.std_errors[name], name


BOTH = ("x3", "y3", "x5", "y5", "xm2", "ym2", "xm4", "ym4")  # a marker and a node on each bar
INSTANTS = [0.1 + 0.05 * i for i in range(17)]  # s


def test_direct_method_from_nodes_and_markers(model):
    # every dof from the kinematic fit through the channels at each sample, rates by smoothing. Measured
    # on seeds 0-3: k within 0.28 %, |z| <= 0.65 (from every node's x, y, theta instead: within 0.25 %);
    # kt is not seen by the direct method (standard errors 8-15 times its value), and may end on a bound
    r = identify_direct(model, recording(BOTH, 1.0), INSTANTS)
    assert r.extra["from_markers"]["markers"] == ["xm2", "ym2", "xm4", "ym4"]
    assert r.extra["from_markers"]["samples"] == 101
    assert "dofs from markers xm2, ym2, xm4, ym4 at 101 samples" in r.summary()
    for name in ("k1", "k3"):
        truth = model.p_nominal[model.parameter_names.index(name)]
        assert abs(r.parameters[name] / truth - 1) < 0.01, name
        assert abs(r.parameters[name] - truth) <= 3 * r.std_errors[name], name
    assert {"kt1", "kt3"} <= set(r.identifiability["weak"])


def test_adapted_direct_method_from_nodes_and_markers(model):
    # every node's translations from the kinematic fit, rotations as the method's cubics. Measured on
    # seeds 0-3: k within 0.15 %, kt within 1.1 % (standard errors of kt: 1e5 %, docs Known limits)
    r = identify_adapted_direct(model, recording(BOTH, 1.0), INSTANTS)
    assert r.success, r.message
    assert r.extra["from_markers"]["samples"] == 101 and r.extra["ignored_channels"] == []
    for name, truth in zip(model.parameter_names, model.p_nominal, strict=True):
        assert abs(r.parameters[name] / truth - 1) < (0.03 if name.startswith("kt") else 0.005), name


def test_too_few_markers_for_the_direct_methods(model):
    # a bar with one marker and no recorded node turns about it: its rotation is a slow mode no channel sees
    with pytest.raises(ValueError, match=r"determine 4 of the model's 6 slow modes .*too few markers for the direct"):
        identify_direct(model, recording(("xm2", "ym2", "xm4", "ym4"), 1.0), INSTANTS)
    with pytest.raises(ValueError, match=r"determine 5 of the model's 6 slow modes .*the adapted direct method"):
        identify_adapted_direct(model, recording(("x3", "y3", "xm2", "ym2", "xm4", "ym4"), 1.0), INSTANTS)


def test_full_residue_compares_markers_rates(model):
    # Eq. 17 on casflex's own motion (0.1 s), node 3 and both markers with their exact rates: the
    # transcription's marker rates are those of the motion (test above), so the truth comes back to the
    # HHT Newton floor, as from nodes (test_identification_indirect: measured 4.3e-6 there)
    sim = simulated_set(model, t_end=0.1, tol=1e-12)
    y, yd, J, Jd = marker_states(model, sim.q, sim.qd)
    ydd = np.einsum("kmn,kn->km", J, sim.qdd) + np.einsum("kmn,kn->km", Jd, sim.qd)
    cols = [sim.channels.index(c) for c in ("x3", "y3")]
    data = MeasurementSet(sim.t, ("x3", "y3", *marker_channels(model)),
                          *(np.hstack([a[:, cols], b]) for a, b in ((sim.q, y), (sim.qd, yd), (sim.qdd, ydd))))
    r = identify_nlp(model, data, 0.1, start=0.8, shooting=Shooting("single-shooting", residue="full"),
                     run=ModelRun(newton_tol=1e-12, dt=1e-3, alpha=0.0))
    assert r.success, r.status
    np.testing.assert_allclose(r.p, model.p_nominal, rtol=1e-5)
