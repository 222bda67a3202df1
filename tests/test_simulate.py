"""simulate(): execution paths, results, failure as data, file round trip."""

from __future__ import annotations

import dataclasses
import shutil

import numpy as np
import pytest
from conftest import assert_same_numbers, translated

import casflex
from casflex.results import NPZ_KEYS, Trajectory
from casflex.simulate import ENERGY_GROWTH, SimulationError, Start, Stepping, simulate


@pytest.fixture(scope="module")
def twobar():
    return casflex.assemble(casflex.load_scene("twobar"))


def test_time_grid_and_shapes(twobar):
    tr = simulate(twobar, 0.05, stepping=Stepping(dt=1e-3))
    assert tr.t.shape == (51,) and tr.t[0] == 0.0 and tr.t[-1] == pytest.approx(0.05, abs=1e-15)
    assert tr.q.shape == tr.qd.shape == tr.qdd.shape == (51, 15)
    assert tr.lam.shape == (51, 3)
    assert tr.dof_names[:3] == ("x1", "y1", "theta1") and tr.dof_names[-1] == "theta5"
    assert tr.success and tr.status == "success"
    assert (tr.newton_iterations >= 1).all()


def test_initial_state_is_consistent(twobar):
    tr = simulate(twobar, 0.01, stepping=Stepping(dt=1e-3))
    # springs at rest length and at rest: every free node falls freely, the clamp carries nothing
    np.testing.assert_allclose(tr.qdd[0, 3::3], 0.0, atol=1e-6)
    np.testing.assert_allclose(tr.qdd[0, 4::3], -9.81, rtol=1e-9)
    np.testing.assert_allclose(tr.lam[0], 0.0, atol=1e-6)


@pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")
def test_compiled_matches_interpreted(twobar):
    # 0.6 s = 2 compiled chunks of 250 steps + 100 single compiled steps
    ti = simulate(twobar, 0.6, stepping=Stepping(dt=1e-3))
    tc = simulate(twobar, 0.6, stepping=Stepping(dt=1e-3, compiled=True))
    for a, b in ((ti.q, tc.q), (ti.qd, tc.qd), (ti.qdd, tc.qdd), (ti.lam, tc.lam), (ti.outputs, tc.outputs)):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-10 * max(1.0, np.abs(a).max()))


def test_reactions_balance_gravity_at_rest():
    # a clamped horizontal cantilever with no motion: the clamp carries the weight and its moment
    L, m_per_len = 2.0, 7800.0 * 1e-3
    scene = casflex.Scene(
        name="cantilever",
        nodes=(casflex.Node("a", 0.0, 0.0), casflex.Node("b", L, 0.0)),
        beams=(casflex.Beam("bar", ("a", "b"), E=2.1e11, A=1e-3, I=1e-6, rho=7800.0, elements=4),),
        supports=(casflex.Support("wall", "a", "clamp"),),
    )
    model = casflex.assemble(scene)
    from casflex.statics import equilibrium

    st = equilibrium(model)
    tr = simulate(model, 0.02, stepping=Stepping(dt=1e-3, alpha=-0.1), start=Start(q0=st.q))
    W = m_per_len * L * 9.81
    # the support exerts -lam: an upward force W and a counter-clockwise moment W L / 2
    assert tr.output("wall.y")[-1] == pytest.approx(W, rel=1e-6)
    assert tr.output("wall.theta")[-1] == pytest.approx(W * L / 2, rel=1e-4)  # deflected lever arm


def test_newton_failure_is_reported_with_time_iterations_and_residual(twobar):
    with pytest.raises(SimulationError) as exc:
        simulate(twobar, 3.0, stepping=Stepping(dt=0.3, max_iter=2))
    msg = str(exc.value)
    assert "Newton failed" in msg and "t = " in msg and "iterations" in msg and "residual" in msg
    assert "smaller dt" in msg
    tr = exc.value.trajectory
    assert not tr.success and tr.status == "newton_failed"
    assert np.isfinite(tr.q).all() and np.isfinite(tr.lam).all()  # no NaN reaches a result


def test_failure_as_data_without_raising(twobar):
    tr = simulate(twobar, 3.0, stepping=Stepping(dt=0.3, max_iter=2), raise_on_failure=False)
    assert not tr.success and "Newton failed" in tr.message
    assert len(tr.t) < 11


def _twobar_variant(*, e_scale: float = 1.0, shift: float = 0.0, elements: int = 1) -> casflex.Model:
    base = translated(casflex.load_scene("twobar"), shift)
    return casflex.assemble(dataclasses.replace(
        base, beams=tuple(dataclasses.replace(b, E=b.E * e_scale, elements=elements) for b in base.beams)))


@pytest.mark.parametrize("compiled", [False, True])
def test_an_element_bent_through_pi_stops_the_run(compiled):
    # E x 1e-6, one element per bar: bar 2 folds until its local rotation wraps at t = 0.542 s;
    # Newton converges through the wrap, the strain energy jumps, the result must not say success
    tr = simulate(_twobar_variant(e_scale=1e-6), 1.0, stepping=Stepping(dt=1e-3, compiled=compiled),
                  raise_on_failure=False)
    assert tr.status == "element_range" and not tr.success
    assert "bar2.1" in tr.message and "+-pi" in tr.message and "t = 0.541 s" in tr.message
    assert tr.t[-1] == pytest.approx(0.541)  # ends at the last state before the wrap
    assert abs(tr.energies["balance_error"]).max() < 1e-5 * tr.energies["kinetic"].max()  # sound up to there (1.5e-6)
    with pytest.raises(SimulationError, match="more elements"):
        simulate(_twobar_variant(e_scale=1e-6), 1.0, stepping=Stepping(dt=1e-3, compiled=compiled))


def test_the_same_bending_on_a_finer_mesh_does_not_stop():
    tr = simulate(_twobar_variant(e_scale=1e-6, elements=4), 0.7, stepping=Stepping(dt=1e-3, compiled=True),
                  raise_on_failure=False)
    assert tr.success, tr.message


def test_energy_growth_of_an_unstable_integration_stops_the_run():
    # springs x 1e3, E x 1e-3, dt = 0.05 s at alpha = 0: every Newton step converges while the
    # energy grows to ~10 x its physical scale (found by studies/extremes.py)
    model = _twobar_variant(e_scale=1e-3)
    tr = simulate(model, 3.0, stepping=Stepping(dt=0.05, alpha=0.0), p=1e3 * model.p_nominal, raise_on_failure=False)
    assert tr.status == "energy_growth" and "grew by" in tr.message and "smaller dt" in tr.message
    E = tr.energies
    in_motion = np.maximum.accumulate(E["kinetic"] + E["elastic"])
    assert (E["balance_error"] <= ENERGY_GROWTH * in_motion + 1e-9).all()  # the result stops before the growth
    # the damped integrator on the same case is sound
    assert simulate(model, 3.0, stepping=Stepping(dt=0.05, alpha=-1 / 3), p=1e3 * model.p_nominal,
                    raise_on_failure=False).success


def test_a_scene_far_from_the_origin_runs_to_the_round_off_floor(twobar):
    # 10 km from the origin the scaled residual cannot go below ~eps 1e4 = 2e-12 > tol = 1e-12
    far = simulate(_twobar_variant(shift=1e4), 0.5, stepping=Stepping(dt=1e-3))
    near = simulate(twobar, 0.5, stepping=Stepping(dt=1e-3))
    assert far.success
    dx = far.q - near.q
    dx[:, 0::3] -= 1e4
    assert np.abs(dx).max() < 1e-7  # the same motion, to the round-off of 1e4 m coordinates


@pytest.mark.parametrize("kw, match", [
    ({"dt": 0.0007}, "whole number of steps"),
    ({"dt": -1e-3}, "dt"),
    ({"alpha": 0.1}, "alpha"),
    ({"alpha": -0.5}, "alpha"),
    ({"p": {"k9": 1.0}}, "unknown parameter 'k9'"),
    ({"p": np.ones(3)}, "expected 4 values"),
    ({"q0": np.zeros(4)}, "q0: expected 15"),
    ({"qd0": np.r_[1.0, np.zeros(14)]}, "velocity constraint of support1.x"),
])
def test_bad_options_are_rejected_clearly(twobar, kw, match):
    kw = dict(kw)
    step = {"dt": 1e-3, **{k: kw.pop(k) for k in ("dt", "alpha") if k in kw}}
    start = {k: kw.pop(k) for k in ("q0", "qd0") if k in kw}
    with pytest.raises((ValueError, KeyError), match=match):
        simulate(twobar, 0.01, stepping=Stepping(**step), start=Start(**start), **kw)


@pytest.mark.parametrize("make, message", [
    (lambda: Stepping(dt=0.0), "dt: must be a positive number of seconds, got 0.0"),
    (lambda: Stepping(dt=float("nan")), "dt: must be a positive number of seconds, got nan"),
    (lambda: Stepping(alpha=0.1), r"alpha: must lie in \[-1/3, 0\], got 0.1"),
    (lambda: Stepping(alpha="-0.1"), r"alpha: must lie in \[-1/3, 0\], got '-0.1'"),
    (lambda: Stepping(tol=0.0), r"tol: expected a float in \(0, 1e-2\), got 0.0"),
    (lambda: Stepping(max_iter=0), "max_iter: expected an integer >= 1, got 0"),
    (lambda: Stepping(newton="quasi"), r"newton: expected one of \('exact', 'modified'\), got 'quasi'"),
    (lambda: Stepping(compiled="yes"), "compiled: expected True or False, got 'yes'"),
    (lambda: Start(t0=float("inf")), "t0: expected a finite time in s, got inf"),
])
def test_the_option_values_check_their_fields(make, message):
    # the messages simulate gave before it took these values (HHT's, step_count's), now said when they are made
    with pytest.raises(ValueError, match=f"^{message}$"):
        make()


def test_simulate_takes_the_option_values_only(twobar):
    with pytest.raises(ValueError,
                       match=r"^stepping: expected a casflex.simulate.Stepping\(...\), got \{'dt': 0.001\}$"):
        simulate(twobar, 0.01, stepping={"dt": 1e-3})
    with pytest.raises(ValueError, match=r"^start: expected a casflex.simulate.Start\(...\), got 0.5$"):
        simulate(twobar, 0.01, start=0.5)
    with pytest.raises(TypeError, match="dt"):
        simulate(twobar, 0.01, dt=1e-3)  # the former keywords are gone, not ignored


def test_the_defaults_are_the_scenes_run_settings(twobar):
    run = twobar.scene.run
    assert Stepping().of(twobar.scene) == (run.dt, run.alpha)
    assert Stepping(dt=2e-3, alpha=-0.1).of(twobar.scene) == (2e-3, -0.1)
    tr = simulate(twobar, 0.01)
    assert tr.meta["dt"] == run.dt and tr.meta["alpha"] == run.alpha and tr.meta["tol"] == 1e-12


def test_npz_round_trip(twobar, tmp_path):
    tr = simulate(twobar, 0.02, stepping=Stepping(dt=1e-3))
    path = tr.save(tmp_path / "run.npz")
    with np.load(path) as z:
        assert set(NPZ_KEYS) <= set(z.files)
    back = Trajectory.load(path)
    np.testing.assert_array_equal(back.q, tr.q)
    np.testing.assert_array_equal(back.outputs, tr.outputs)
    assert back.dof_names == tr.dof_names and back.output_names == tr.output_names
    assert back.meta["alpha"] == tr.meta["alpha"] and back.success
    assert [p.name for p in tmp_path.iterdir()] == ["run.npz"]  # no temporary file left
    with pytest.raises(ValueError, match="not a casflex trajectory"):
        (tmp_path / "bad.npz").write_bytes(b"junk")
        Trajectory.load(tmp_path / "bad.npz")


def test_parameters_change_the_motion(twobar):
    a = simulate(twobar, 0.3, stepping=Stepping(dt=1e-3))
    b = simulate(twobar, 0.3, stepping=Stepping(dt=1e-3), p={"k1": 900.0})
    assert np.abs(a.dof("y2") - b.dof("y2")).max() > 1e-3
    # spring force is k (L - L0): check the output against the dofs
    L = np.hypot(b.dof("x2"), b.dof("y2"))
    np.testing.assert_allclose(b.output("spring1.force"), 900.0 * (L - 0.1), rtol=1e-10, atol=1e-9)
    th = b.dof("theta2")
    np.testing.assert_allclose(b.output("torsion1.moment"), 0.5 * th, rtol=1e-12, atol=1e-15)


def test_modified_newton_keeps_the_factors_and_agrees_with_the_exact_one():
    model = casflex.assemble(casflex.load_scene("twobar"))
    exact = simulate(model, 0.5, stepping=Stepping(dt=2e-4, compiled=True))
    a = simulate(model, 0.5, stepping=Stepping(dt=2e-4, newton="modified"))
    b = simulate(model, 0.5, stepping=Stepping(dt=2e-4, newton="modified", compiled=True))
    assert a.success and b.success
    assert_same_numbers(a.q, b.q)  # compiled and interpreted: the same steps
    assert a.stats["jacobian_refreshes"] == b.stats["jacobian_refreshes"] < 0.5 * a.stats["steps"]  # measured 0.095
    # each step it accepts after a chord update holds up to cond(G_z) tol ~ 2.5e-9 of error (the exact Newton's
    # final update leaves ~1e-15): measured 2.5e-7 m over 0.5 s, as much as the step's own error at this dt
    # (2.5e-7 m against dt = 1e-4); 1e-6 m is four times that
    assert np.abs(a.q - exact.q).max() < 1e-6
    assert (a.newton_iterations >= 1).all()


def test_simulate_takes_at_most_eight_parameters():
    # docs/architecture.md "Choices are values": an entry point's choices are values, not a list of keywords
    import inspect

    assert list(inspect.signature(simulate).parameters) == ["system", "t_end", "stepping", "p", "start", "progress",
                                                             "raise_on_failure"]
