"""The built-in scene ``leg``: what its header documents (Winter's segment masses, the joints, the
pelvis's path) is what the model holds."""

from __future__ import annotations

import numpy as np
import pytest

import casflex
from casflex.scene_io import dumps_scene, loads_scene

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
