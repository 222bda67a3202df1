"""casflex.muscles.reaction: a two-segment leg's knee in closed form, and OpenSim 4.6's JointReaction on
Hamner's subject 02 run with its SO forces (tests/data/muscles/README_opensim_runs.md)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from casflex.lab import read_sto
from casflex.muscles.reaction import JointReaction, joint_reactions
from casflex.muscles.static_optimization import StaticOptimization, solve_static_optimization

DATA = Path(__file__).parent / "data" / "muscles"

G = 9.81
CHILDREN, PARENTS = ("femur_r", "tibia_r", "talus_r"), ("pelvis", "femur_r", "tibia_r")


def _leg(phi: float):
    """A shank of mass 3 kg hanging from the knee (at the origin) at angle phi from the ground's x, its centre of
    mass 0.2 m along it, held still by one muscle from the thigh's point (0, 0.3) to the shank's point 0.05 m
    along it. Returns the net load on the shank at the knee (fx, fy, mz), the muscle's unit load and points."""
    e = np.array([np.cos(phi), np.sin(phi)])
    com, q, p = 0.2 * e, 0.05 * e, np.array([0.0, 0.3])
    weight = np.array([0.0, -3.0 * G])
    net = np.array([0.0, 3.0 * G, -(com[0] * weight[1] - com[1] * weight[0])])  # holds the shank still
    u = (p - q) / np.linalg.norm(p - q)  # the muscle pulls the shank towards the thigh
    unit = np.array([u[0], u[1], q[0] * u[1] - q[1] * u[0]])
    return net, unit, weight, q, com


@pytest.mark.parametrize("phi", [-np.pi / 2, -0.3, 0.4])
def test_a_single_muscle_across_the_knee_leaves_the_joint_the_rest_in_equilibrium(phi):
    net, unit, weight, q, com = _leg(phi)
    so = solve_static_optimization(net[None, 2:], unit[None, 2:, None], [[4000.0]],
                                   options=StaticOptimization(activation_bounds=(0.0, 1.0)))
    tension = so.forces[0, 0]
    assert tension * unit[2] == pytest.approx(net[2], rel=1e-8)  # the muscle carries the whole moment
    r = joint_reactions(net[None, None, :], unit[None, :, None], so.forces, options=JointReaction(frame="ground"))
    force, moment = r.loads[0, 0, :2], r.loads[0, 0, 2]
    # the shank's equilibrium: the joint's force + the muscle's + its weight = 0; moments about the knee likewise
    assert force + tension * unit[:2] + weight == pytest.approx([0.0, 0.0], abs=1e-9)
    assert moment == pytest.approx(0.0, abs=1e-9)  # a frictionless hinge bears no moment once the muscle carries it
    assert r.muscles[0, 0] == pytest.approx(tension * unit, rel=1e-12)
    assert r.unit == "N" and r.on == "child"


def test_parent_child_frames_and_body_weights():
    net, unit, *_ = _leg(-0.3)
    net, unit, f = net[None, None, :], unit[None, :, None], np.array([[500.0]])
    ground = joint_reactions(net, unit, f, options=JointReaction(frame="ground")).loads[0, 0]
    child = joint_reactions(net, unit, f, [[-0.3]], [[0.1]], JointReaction(frame="child")).loads[0, 0]
    c, s = np.cos(-0.3), np.sin(-0.3)
    assert child[:2] == pytest.approx([c * ground[0] + s * ground[1], -s * ground[0] + c * ground[1]], rel=1e-12)
    assert child[2] == pytest.approx(ground[2])
    parent = joint_reactions(net, unit, f, [[-0.3]], [[0.1]], JointReaction(on="parent", frame="parent")).loads[0, 0]
    c, s = np.cos(0.1), np.sin(0.1)
    assert parent[:2] == pytest.approx([-(c * ground[0] + s * ground[1]), -(-s * ground[0] + c * ground[1])])
    assert parent[2] == pytest.approx(-ground[2])
    bw = joint_reactions(net, unit, f, [[-0.3]], options=JointReaction(body_weight=700.0))
    assert bw.loads[0, 0] == pytest.approx(child / 700.0) and bw.unit == "BW"


def test_opensims_joint_reactions_from_its_net_loads_and_so_forces():
    """OpenSim's JR of SO's forces on hip_r, knee_r, ankle_r (on the child, in the child) against casflex's
    formula fed OpenSim's net loads (its JR with the muscles' generalized forces moved into the reserves), its
    muscles' unit loads (their paths' point force directions) and the child bodies' angles."""
    d = np.load(DATA / "hamner_run_inputs.npz")
    so, jr = read_sto(DATA / "hamner_run_so_force.sto"), read_sto(DATA / "hamner_run_jr.sto")
    forces = np.column_stack([so.column(m) for m in d["muscles"]])
    r = joint_reactions(d["net"], d["units"], forces, d["child"], d["parent"])
    for h, (joint, body) in enumerate(zip(d["joints"], CHILDREN, strict=True)):
        theirs = np.column_stack([jr.column(f"{joint}_on_{body}_in_{body}_{w}") for w in ("fx", "fy")])
        peak = np.abs(theirs).max()
        # 2 % of peak is the brief's bar; the same model, states and forces give 1.5e-9 of peak (the files' 9 digits)
        assert np.abs(r.loads[:, h, :2] - theirs).max() < 1e-5 * peak, joint
        mz = jr.column(f"{joint}_on_{body}_in_{body}_mz")
        assert np.abs(r.loads[:, h, 2] - mz).max() < 1e-3  # N m; peaks 15, 66, 53: the reserves


def test_opensims_joint_reactions_from_casflexs_rigid_inverse_dynamics():
    """The same with casflex's own net loads (its rigid inverse dynamics of the model's planar scene on the same
    trial, stored by the reference's script): the knee's generalized force turned into the moment about the
    tibia's origin by the coupled knee's lever."""
    d = np.load(DATA / "hamner_run_inputs.npz")
    so, jr = read_sto(DATA / "hamner_run_so_force.sto"), read_sto(DATA / "hamner_run_jr.sto")
    forces = np.column_stack([so.column(m) for m in d["muscles"]])
    r = joint_reactions(d["casflex_net"], d["units"], forces, d["child"], lever=d["lever"])
    plain = joint_reactions(d["casflex_net"], d["units"], forces, d["child"])
    for h, (joint, body) in enumerate(zip(d["joints"], CHILDREN, strict=True)):
        theirs = np.column_stack([jr.column(f"{joint}_on_{body}_in_{body}_{w}") for w in ("fx", "fy", "mz")])
        peak = np.abs(theirs[:, :2]).max()
        # 2 % of peak is the brief's bar; two inverse dynamics of one model and trial agree to 4e-6 of peak
        assert np.sqrt(np.mean((r.loads[:, h] - theirs) ** 2, axis=0)).max() < 2e-4 * peak, joint
        assert np.abs(r.loads[:, h, 2] - theirs[:, 2]).max() < 0.2  # N m
    assert np.abs(plain.loads[:, 1, 2] - r.loads[:, 1, 2]).max() > 2.0  # N m: without the lever the knee is off


def test_opensims_joint_reactions_on_the_parent_in_the_parent():
    """OpenSim's JR on the parent (pelvis, femur_r, tibia_r) in the parent's frame: the opposite load, its moment
    about the parent joint frame's origin, which for the knee is the femur's origin at the hip, 0.44 m away."""
    d = np.load(DATA / "hamner_run_inputs.npz")
    so, jr = read_sto(DATA / "hamner_run_so_force.sto"), read_sto(DATA / "hamner_run_jr_parent.sto")
    forces = np.column_stack([so.column(m) for m in d["muscles"]])
    on = JointReaction(on="parent", frame="parent")
    r = joint_reactions(d["net"], d["units"], forces, d["child"], d["parent"], on, offset=d["offset"])
    plain = joint_reactions(d["net"], d["units"], forces, d["child"], d["parent"], on)
    for h, (joint, body) in enumerate(zip(d["joints"], PARENTS, strict=True)):
        theirs = np.column_stack([jr.column(f"{joint}_on_{body}_in_{body}_{w}") for w in ("fx", "fy", "mz")])
        assert np.abs(r.loads[:, h, :2] - theirs[:, :2]).max() < 1e-5 * np.abs(theirs[:, :2]).max(), joint
        assert np.abs(r.loads[:, h, 2] - theirs[:, 2]).max() < 1e-3, joint  # N m
    assert np.abs(plain.loads[:, 1, 2] - r.loads[:, 1, 2]).max() > 50.0  # N m: the knee's moment about the hip


def test_the_hip_reaction_moment_is_the_reserves():
    d = np.load(DATA / "hamner_run_inputs.npz")
    so = read_sto(DATA / "hamner_run_so_force.sto")
    r = joint_reactions(d["net"], d["units"], np.column_stack([so.column(m) for m in d["muscles"]]), d["child"])
    assert r.loads[:, 0, 2] == pytest.approx(so.column("hip_flexion_r_reserve"), abs=1e-4)  # a pin: mobility force


@pytest.mark.parametrize("options, message", [
    (dict(on="femur"), "on: expected 'child' or 'parent'"),
    (dict(frame="pelvis"), "frame: expected 'child', 'parent' or 'ground'"),
    (dict(body_weight=-700.0), "body_weight: expected a positive number"),
])
def test_options_refuse_bad_values(options, message):
    with pytest.raises(ValueError, match=message):
        JointReaction(**options)


def test_bad_inputs_are_refused():
    net, unit, f = np.zeros((2, 1, 3)), np.zeros((2, 3, 4)), np.zeros((2, 4))
    with pytest.raises(ValueError, match=r"unit: expected \(2, 3, muscles\)"):
        joint_reactions(net, np.zeros((2, 6, 4)), f)
    with pytest.raises(ValueError, match=r"forces: expected shape \(2, 4\)"):
        joint_reactions(net, unit, np.zeros((2, 3)))
    with pytest.raises(ValueError, match="child: the child bodies' angles are needed"):
        joint_reactions(net, unit, f)
    with pytest.raises(ValueError, match=r"net: not finite at \(1, 0, 2\)"):
        joint_reactions(np.where(np.arange(6).reshape(2, 1, 3) == 5, np.nan, 0.0), unit, f)
