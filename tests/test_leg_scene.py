"""The built-in scene ``leg``: what its header documents (Winter's segment masses, the joints, the
pelvis's path) is what the model holds."""

from __future__ import annotations

import numpy as np
import pytest

import casflex
from casflex.identification import Experiment, ModelRun, Uncertainty
from casflex.scene.io import dumps_scene, loads_scene

BODY = 75.0  # kg: the subject of the scene's header


def test_leg_holds_winters_segment_masses_and_a_walking_pelvis():
    scene = casflex.load_scene("leg")
    assert loads_scene(dumps_scene(scene)) == scene
    model = casflex.assemble(scene)
    assert model.moving and list(model.parameter_names) == ["kt_hip", "ct_hip", "kt_knee", "ct_knee"]
    # a rigid translation along x: u^T M u is the mass that moves with it, thigh + shank + foot
    M = np.array(model.mass(model.q0, model.p_nominal))
    u = np.array([1.0 if d.startswith("x") else 0.0 for d in model.dof_names])
    u[[c.dof for c in model.constraints]] = 0.0  # the pelvis is a support: no mass of its own
    assert u @ M @ u == pytest.approx((0.100 + 0.0465 + 0.0145) * BODY, rel=1e-12)
    # segment lengths 0.245 H and 0.246 H (H = 1.75 m)
    q = model.q0
    for (a, b), share in ((("hip", "knee"), 0.245), (("knee_s", "ankle"), 0.246)):
        length = np.hypot(q[model.dof("x" + b)] - q[model.dof("x" + a)], q[model.dof("y" + b)] - q[model.dof("y" + a)])
        assert length == pytest.approx(share * 1.75, rel=1e-12)
    # the pelvis walks forward at 1.2 m/s on average over a stride (1.1 s), back at its height
    v0, v1 = (np.array(model.prescribed(t)[0]).ravel() for t in (0.0, 1.1))
    assert (v1[0] - v0[0]) / 1.1 == pytest.approx(1.2, rel=1e-9)
    assert v1[1] == pytest.approx(v0[1], abs=1e-5)


def test_state_guessed_from_the_markers_mid_stride_does_not_wind_a_node():
    # the leg 0.55 s into its stride, from its five markers alone: the beams cannot tell a node turned
    # by whole turns, the knee's torsion spring can. Before fit_step, IPOPT landed with the shank's knee
    # node three turns off (1528 J of elastic energy instead of 6).
    from casflex.data import MeasurementSet
    from casflex.identification.initial_state import _elastic_energy, initial_guess
    from casflex.identification.measurement import Experiment
    from casflex.model.markers import marker_channels, marker_positions
    from casflex.simulate import Stepping, simulate

    model = casflex.assemble(casflex.load_scene("leg"))
    tr = simulate(model, 0.6, stepping=Stepping(dt=1e-3))
    rows = np.arange(550, 601, 10)  # 100 Hz from 0.55 s
    data = MeasurementSet(tr.t[rows], marker_channels(model), marker_positions(model, tr.q[rows]), None, None)
    q_g, _ = initial_guess(model, Experiment(data, initial_state="estimate"))
    rot = model.is_rotation
    assert np.abs(q_g[rot] - tr.q[550, rot]).max() < 0.01  # rad (measured 6e-4 on the finer model's motion)
    energy = _elastic_energy(model)
    assert float(energy(q_g)) <= float(energy(tr.q[550])) * 1.001  # least energy through the markers


def test_rigid_leg_is_the_leg_derived_and_its_stiffened_bones_limit():
    """leg_rigid is what tests/leg_rigid.py derives from leg; the flexible leg with bones E times
    stiffer converges to it at the rate of the bones' compliance, 1 / E."""
    import dataclasses

    from conftest import assert_scenes_close
    from leg_rigid import rigid_leg

    from casflex.model.markers import marker_positions
    from casflex.simulate import Stepping, simulate

    leg, rigid = casflex.load_scene("leg"), casflex.load_scene("leg_rigid")
    # the bodies' masses and Izz: math.hypot (within an ulp, not the same bits everywhere) and a few products:
    # a few ulps (1e-15) between the file and this machine; 1e-12 relative is 1e3 x that
    assert_scenes_close(rigid, rigid_leg(leg), 1e-12)
    model = casflex.assemble(rigid)
    assert model.n_dof == 9 and list(model.parameter_names) == ["kt_hip", "ct_hip", "kt_knee", "ct_knee"]
    M = np.array(model.mass(model.q0, model.p_nominal))
    u = np.array([1.0 if d.startswith("x") else 0.0 for d in model.dof_names])
    u[[c.dof for c in model.constraints]] = 0.0
    assert u @ M @ u == pytest.approx((0.100 + 0.0465 + 0.0145) * BODY, rel=1e-12)  # Winter's masses, as leg

    def markers(scene) -> np.ndarray:
        m = casflex.assemble(scene)
        return marker_positions(m, simulate(m, 0.4, stepping=Stepping(dt=1e-3, alpha=-0.05)).q)

    y_rigid = markers(rigid)
    gaps = [np.abs(markers(dataclasses.replace(leg, beams=tuple(dataclasses.replace(b, E=b.E * s) for b in leg.beams)))
                   - y_rigid).max() for s in (10.0, 100.0)]
    # first order in the compliance: the gap shrinks tenfold per tenfold stiffness (measured 10.5)
    assert 8.0 < gaps[0] / gaps[1] < 12.0, gaps
    assert gaps[1] < 2e-5  # m: with 100 x stiffer bones the markers move within 7.6 um of the rigid links' (measured)


def test_leg_identified_from_its_markers_mid_stride():
    """The hip use case: the four joint parameters from the five markers at 100 Hz with 1 mm of
    noise, a stride that starts mid-swing (initial state estimated), recorded by a finer model. The
    kinematic fit follows the markers in the least-squares sense: exact marker constraints bent the
    bones to follow the noise (a guess 0.2 m and 10 rad off) and 2 of 3 seeds failed."""
    import dataclasses

    from casflex.data import MeasurementSet
    from casflex.identification import identify_indirect
    from casflex.model.markers import marker_channels, marker_positions
    from casflex.simulate import Stepping, simulate

    leg = casflex.load_scene("leg")
    fine = casflex.assemble(dataclasses.replace(leg, beams=tuple(dataclasses.replace(b, elements=2)
                                                                 for b in leg.beams)))
    tr = simulate(fine, 1.65, stepping=Stepping(dt=5e-4))
    rows = np.arange(1100, tr.t.size, 20)  # 100 Hz from 0.55 s
    y = marker_positions(fine, tr.q[rows])
    data = MeasurementSet(tr.t[rows], marker_channels(fine), y + np.random.default_rng(0).normal(0, 1e-3, y.shape),
                          None, None)
    model = casflex.assemble(leg)
    # form="none": the other beam theory's refit (rotary inertia) compiled a second 1 MB sensitivity library (12-20 s
    # of gcc, half the test's CPU) and moved the standard errors by 0-5 % (err/se 1.77-1.88 with it, 1.86-1.89
    # without: measured); the form refit has its own tests (test_identification_form, test_cli_identify's forms)
    r = identify_indirect(model, Experiment(data, initial_state="estimate"), start=0.7, run=ModelRun(dt=1e-3),
                          uncertainty=Uncertainty(model_error="none", form="none"))
    assert r.success, r.message
    se = np.array([r.std_errors[k] for k in model.parameter_names])
    assert np.all(np.abs(r.p - model.p_nominal) < 3 * se), (r.p, se)
