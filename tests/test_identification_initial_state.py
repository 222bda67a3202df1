"""Estimated initial states: the kinematic guess, the slow modes and the slow manifold."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import casflex
from casflex.data import MeasurementSet
from casflex.identification.initial_state import initial_guess, initial_state_of, slow_modes
from casflex.identification.measurement import Experiment
from casflex.simulate import Stepping, simulate


@pytest.fixture(scope="module")
def twobar():
    return casflex.assemble(casflex.load_scene("twobar"))


def _bars(model, q):
    return [float(np.hypot(*(q[3 * b:3 * b + 2] - q[3 * a:3 * a + 2]))) for a, b in ((1, 2), (3, 4))]


def test_slow_modes_split_at_the_cut(twobar):
    B = slow_modes(twobar, twobar.q0, twobar.p_nominal, np.pi / 0.01)  # 100 Hz sampling
    M = np.array(twobar.mass(twobar.q0, twobar.p_nominal))[3:, 3:]
    assert B.shape == (12, 6)  # 6 of the 12 free motions below 50 Hz: pendulum and joint modes
    np.testing.assert_allclose(B.T @ M @ B, np.eye(6), atol=1e-10)  # M-orthonormal
    assert slow_modes(twobar, twobar.q0, twobar.p_nominal, 1e9).shape == (12, 12)


def test_the_slow_manifold_keeps_steel_bars_at_their_length(twobar):
    exp = Experiment(MeasurementSet(np.array([0.0, 0.01]), ("x5",), np.array([[1.0], [1.0]]), None, None),
                     initial_state="estimate")
    st = initial_state_of(twobar, exp, twobar.p_nominal, (twobar.q0, twobar.qd0))
    a = np.array([0.3, -0.2, 0.1, 0.05, 0.1, -0.1])  # centimetres of slow motion
    q0, qd0 = st.state(np.concatenate([a, np.ones(6)]))
    # 1e-6 m: the quasi-static stretch of a bar pulled by its springs (measured 3e-8 m); a linear
    # correction along the same modes stretches bar 4 by 4.7 mm
    np.testing.assert_allclose(_bars(twobar, q0), [0.9, 0.9], atol=1e-6)
    q_lin = twobar.q0.copy()
    q_lin[3:] += st.basis @ a
    assert max(abs(b - 0.9) for b in _bars(twobar, q_lin)) > 1e-3
    # velocities tangent to the manifold: the bars' length rates vanish
    for i, j in ((1, 2), (3, 4)):
        d = q0[3 * j:3 * j + 2] - q0[3 * i:3 * i + 2]
        v = qd0[3 * j:3 * j + 2] - qd0[3 * i:3 * i + 2]
        assert abs(d @ v) / np.linalg.norm(d) < 1e-6 * np.linalg.norm(v)
    # the Jacobian against central differences (1e-6: truncation ~1e-12, the Newton tolerance 1e-13)
    xi = np.concatenate([a, np.ones(6)])
    dq, dqd = st.jacobian(xi)
    for k in range(12):
        e = 1e-6 * np.eye(12)[k]
        (qp, qdp), (qm, qdm) = st.state(xi + e), st.state(xi - e)
        np.testing.assert_allclose(dq[:, k], (qp - qm) / 2e-6, atol=1e-6)
        np.testing.assert_allclose(dqd[:, k], (qdp - qdm) / 2e-6, atol=1e-6)


def _first_bar():
    """twobar's first bar alone: joint 1 (spring1, torsion1) and bar 2, hanging from the clamped node 1."""
    import dataclasses

    scene, kept = casflex.load_scene("twobar"), {"1", "2", "3"}

    def within(items: tuple) -> tuple:
        return tuple(e for e in items if set(e.nodes) <= kept)

    return casflex.assemble(dataclasses.replace(
        scene, nodes=tuple(n for n in scene.nodes if n.name in kept), springs=within(scene.springs),
        torsion_springs=within(scene.torsion_springs), beams=within(scene.beams), loads=(),
        parameters=tuple(p for p in scene.parameters if p.target.split(".")[0] in ("spring1", "torsion1"))))


def test_the_slow_manifold_compiles_to_c():
    """A compiled NLP (multiple shooting, estimated states) holds the slow manifold's Newton solve:
    CasADi's plain 'newton' cannot be generated as C (gcc: '#error Code generation not supported
    for Newton'); the codegen variant compiles and gives the same state and Jacobian. On twobar's
    first bar (3 slow modes of 6 free motions): the whole twobar's Jacobian is 2.3 MB of C (12 s of
    CPU at -O0, the test 35 s), the bar's 0.29 MB; the rootfinder and its derivatives are the same code."""
    from casflex.codegen import compiled
    from casflex.identification.initial_state import slow_manifold

    bar = _first_bar()
    exp = Experiment(MeasurementSet(np.array([0.0, 0.01]), ("x3",), np.array([[1.0], [1.0]]), None, None),
                     initial_state="estimate")
    st = initial_state_of(bar, exp, bar.p_nominal, (bar.q0, bar.qd0))
    assert st.k == 3  # the pendulum and the joint's two slow modes: a manifold of the bar's stiff ones
    args = st._args(np.concatenate([[0.1, -0.05, 0.05], np.ones(3)]))
    for ref, c in zip(slow_manifold(bar, st.k), slow_manifold(bar, st.k, codegen=True), strict=True):
        # gcc -O0: whether the C generates and compiles, and its numbers, do not depend on the optimisation (no
        # fast-math at any level).
        # 1e-12 m: both Newton solves stop at |KKT| <= 1e-13 (scaled rows), from the same start
        for a, b in zip(ref(*args), compiled(c, optimise="-O0")(*args), strict=True):
            assert np.abs(np.array(a)).max() > 0  # not a check of 0 = 0
            np.testing.assert_allclose(np.array(b), np.array(a), rtol=0, atol=1e-12)


def test_the_kinematic_guess_of_a_recording_mid_motion(twobar):
    # exact positions of nodes 3 and 5 from 0.5 s on: node 2 and the rotations follow from the bars
    tr = simulate(twobar, 0.6, stepping=Stepping(dt=1e-3))
    rows = np.arange(500, 601, 10)
    names = ("x3", "y3", "x5", "y5")
    data = MeasurementSet(tr.t[rows], names, tr.q[np.ix_(rows, [twobar.dof(c) for c in names])], None, None)
    q0, qd0 = initial_guess(twobar, Experiment(data, initial_state="estimate"))
    np.testing.assert_array_equal(q0[[twobar.dof(c) for c in names]], data.q[0])
    np.testing.assert_allclose(_bars(twobar, q0), [0.9, 0.9], atol=1e-6)
    # the springs' dynamic stretch is not a kinematic quantity: the guess is off by centimetres there
    # (the fit corrects it), but the measured nodes' velocities come from the samples: 2 % here
    for c in names:
        i = twobar.dof(c)
        assert abs(qd0[i] - tr.qd[500, i]) < 0.02 * np.abs(tr.qd[500, [twobar.dof(n) for n in names]]).max()


def test_the_first_guess_reaches_a_large_motion_without_a_local_minimum():
    # threelink 1 s into Exudyn's motion (tests/data): its last link has turned by -1.1 rad from the
    # scene's configuration. Fitted in one step from there, the guess ended in a local minimum of the
    # elastic energy (the last joint stretched by 8 cm, its rotation 5.8 rad off, and every fit of the
    # study's mid-motion window failed to run); the paths of first_fit find the true one.
    model = casflex.assemble(casflex.load_scene("threelink"))
    z = np.load(Path(__file__).resolve().parent / "data" / "threelink_exudyn.npz")
    channels = [str(c) for c in z["channels"]]
    names = ("x3", "y3", "x5", "y5", "x7", "y7")
    rows = np.arange(1000, 1041, 10)
    data = MeasurementSet(z["t"][rows], names, z["q"][np.ix_(rows, [channels.index(c) for c in names])], None, None)
    q0, _ = initial_guess(model, Experiment(data, initial_state="estimate"))
    truth = z["q"][1000, [channels.index(d) for d in model.dof_names]]
    rot = np.asarray(model.is_rotation)
    # the joints' dynamic stretch and the bars' bending are not kinematic (the fit corrects the guess
    # there; measured 3.9 mm at joint 1, 0.0105 rad): bounds well below the local minimum's 8 cm, 0.43 rad
    assert np.abs(q0 - truth)[~rot].max() < 0.01
    assert np.abs(q0 - truth)[rot].max() < 0.05
