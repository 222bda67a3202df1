"""The load each joint applies to the part beyond it, by cutting the body (casflex.muscles.cut), against the rigid
inverse dynamics' multipliers: an independent route to the same net intersegmental loads."""

from __future__ import annotations

from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from casflex.inverse import Trial, inverse_dynamics, inverse_model, kinematic_tree
from casflex.muscles.cut import distal_nodes, joint_loads
from casflex.scene.from_osim import scene_from_osim

DATA = Path(__file__).parent / "data" / "lab"
LEG, TRC = DATA / "hamner_subject02_leg.osim", DATA / "hamner_running_stride.trc"
GRF = DATA / "hamner_running_stride_grf.mot"
#: N, N m: both routes solve the same equations exactly; 1e-9 is round-off on loads of up to 2000 N (measured 5e-13)
EXACT = 1e-9


@pytest.fixture(scope="module")
def stride():
    scene = scene_from_osim(LEG).scene
    res = inverse_dynamics(LEG, Trial(TRC, grf=GRF, plates={"calcn_r": "ground_"}))
    return scene, res, joint_loads(scene, res.dof_names, res.q, res.qd, res.qdd, res.t, res.plates)


def test_the_distal_part_of_each_hinge_is_what_it_separates_from_the_root():
    scene = scene_from_osim(LEG).scene
    part = distal_nodes(scene, "pelvis")
    assert part["ankle_r"] == {"talus_r", "calcn_r", "toes_r"}
    assert part["hip_r"] == part["knee_r"] | {"femur_r"} and "pelvis" not in part["hip_r"]
    assert distal_nodes(scene, "toes_r")["ankle_r"] == {"pelvis", "femur_r", "tibia_r"}  # seen from the toes


def test_the_cut_gives_the_intersegmental_forces_and_moments_of_inverse_dynamics(stride):
    scene, res, loads = stride
    for hinge in ("hip_r", "knee_r", "ankle_r"):
        assert loads[hinge][:, :2] == pytest.approx(np.column_stack([res.loads[f"{hinge}.fx"],
                                                                     res.loads[f"{hinge}.fy"]]), abs=EXACT)
    for hinge in ("hip_r", "ankle_r"):  # centres fixed in both segments: the moment is the net joint moment
        assert loads[hinge][:, 2] == pytest.approx(res.loads[f"{hinge}.moment"], abs=EXACT)


def test_at_a_coupled_knee_the_moment_and_the_sliding_centre_make_the_generalised_force(stride):
    """Q = M_P + F . dP/dpsi: the knee's centre slides with its angle (Hamner's knee), so its physical moment
    differs from the generalised force (measured: by up to 16 N m in this stride), and the two agree through the
    centre's slide, taken here from the tree's forward kinematics by AD."""
    scene, res, loads = stride
    tree = kinematic_tree(inverse_model(scene))
    z = ca.MX.sym("z", tree.n)
    i, k = res.dof_names.index("xtibia_r"), tree.names.index("knee_r.angle")
    slide = ca.Function("slide", [z], [ca.jacobian(tree.forward(z)[i:i + 2], z)[:, k]])
    dP = np.array(slide.map(res.z.shape[0])(res.z.T)).T
    knee = loads["knee_r"]
    assert np.abs(knee[:, 2] - res.loads["knee_r.moment"]).max() > 1.0  # the two differ ...
    assert knee[:, 2] + np.sum(knee[:, :2] * dP, axis=1) == pytest.approx(res.loads["knee_r.moment"], abs=EXACT)
