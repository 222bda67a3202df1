"""simulate(): execution paths, results, failure as data, file round trip."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

import casflex
from casflex.results import NPZ_KEYS, Trajectory
from casflex.simulate import SimulationError, simulate


@pytest.fixture(scope="module")
def twobar():
    return casflex.assemble(casflex.load_scene("twobar"))


def test_time_grid_and_shapes(twobar):
    tr = simulate(twobar, 0.05, dt=1e-3)
    assert tr.t.shape == (51,) and tr.t[0] == 0.0 and tr.t[-1] == pytest.approx(0.05, abs=1e-15)
    assert tr.q.shape == tr.qd.shape == tr.qdd.shape == (51, 15)
    assert tr.lam.shape == (51, 3)
    assert tr.dof_names[:3] == ("x1", "y1", "theta1") and tr.dof_names[-1] == "theta5"
    assert tr.success and tr.status == "success"
    assert (tr.newton_iterations >= 1).all()


def test_initial_state_is_consistent(twobar):
    tr = simulate(twobar, 0.01, dt=1e-3)
    # springs at rest length and at rest: every free node falls freely, the clamp carries nothing
    np.testing.assert_allclose(tr.qdd[0, 3::3], 0.0, atol=1e-6)
    np.testing.assert_allclose(tr.qdd[0, 4::3], -9.81, rtol=1e-9)
    np.testing.assert_allclose(tr.lam[0], 0.0, atol=1e-6)


@pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")
def test_compiled_matches_interpreted(twobar):
    # 0.6 s = 2 compiled chunks of 250 steps + 100 single compiled steps
    ti = simulate(twobar, 0.6, dt=1e-3)
    tc = simulate(twobar, 0.6, dt=1e-3, compiled=True)
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
    tr = simulate(model, 0.02, dt=1e-3, q0=st.q, alpha=-0.1)
    W = m_per_len * L * 9.81
    # the support exerts -lam: an upward force W and a counter-clockwise moment W L / 2
    assert tr.output("wall.y")[-1] == pytest.approx(W, rel=1e-6)
    assert tr.output("wall.theta")[-1] == pytest.approx(W * L / 2, rel=1e-4)  # deflected lever arm


def test_newton_failure_is_reported_with_time_iterations_and_residual(twobar):
    with pytest.raises(SimulationError) as exc:
        simulate(twobar, 3.0, dt=0.3, max_iter=2)
    msg = str(exc.value)
    assert "Newton failed" in msg and "t = " in msg and "iterations" in msg and "residual" in msg
    assert "smaller dt" in msg
    tr = exc.value.trajectory
    assert not tr.success and tr.status == "newton_failed"
    assert np.isfinite(tr.q).all() and np.isfinite(tr.lam).all()  # no NaN reaches a result


def test_failure_as_data_without_raising(twobar):
    tr = simulate(twobar, 3.0, dt=0.3, max_iter=2, raise_on_failure=False)
    assert not tr.success and "Newton failed" in tr.message
    assert len(tr.t) < 11


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
    with pytest.raises((ValueError, KeyError), match=match):
        simulate(twobar, 0.01, **{"dt": 1e-3, **kw})


def test_npz_round_trip(twobar, tmp_path):
    tr = simulate(twobar, 0.02, dt=1e-3)
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
    a = simulate(twobar, 0.3, dt=1e-3)
    b = simulate(twobar, 0.3, dt=1e-3, p={"k1": 900.0})
    assert np.abs(a.dof("y2") - b.dof("y2")).max() > 1e-3
    # spring force is k (L - L0): check the output against the dofs
    L = np.hypot(b.dof("x2"), b.dof("y2"))
    np.testing.assert_allclose(b.output("spring1.force"), 900.0 * (L - 0.1), rtol=1e-10, atol=1e-9)
    th = b.dof("theta2")
    np.testing.assert_allclose(b.output("torsion1.moment"), 0.5 * th, rtol=1e-12, atol=1e-15)
