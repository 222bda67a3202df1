"""casflex.scene.osim, casflex.scene.from_osim: OpenSim's UniversalJoint, GimbalJoint and BallJoint on a
hand-written two-body model. Their coordinates are body-fixed rotations about F's x, y (and z); a coordinate that
turns the child out of the plane is held at its default value and reported, one about the plane's normal is a
hinge (module docstring of from_osim). Default poses in closed form; then (a peer test, OpenSim 4.6 in a
subprocess: OpenSim and CasADi cannot share a process; skipped without OpenSim) where OpenSim puts the bodies and
markers at nonzero default values. The leg's ankle made such a joint: tests/test_osim.py, test_peers_opensim.py."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from casflex.scene import dumps_scene, loads_scene
from casflex.scene.from_osim import scene_from_osim

needs_opensim = pytest.mark.skipif(importlib.util.find_spec("opensim") is None, reason="OpenSim is not installed")

KINDS = {"UniversalJoint": 2, "GimbalJoint": 3, "BallJoint": 3}
#: The joint centre, F's origin, in the base's frame (m): the base sits at the ground's origin at the default pose.
CENTRE = np.array([0.1, 0.5, 0.0])
#: M's origin in the arm's frame (m); the arm's markers and centre of mass in it (m).
M_IN_ARM = np.array([0.0, 0.3, 0.0])
MARKERS = {"shoulder": M_IN_ARM, "arm_origin": np.zeros(3), "hand": np.array([0.2, 0.3, 0.0]),
           "elbow": np.array([0.05, -0.1, 0.07])}
ARM_COM = np.array([0.0, 0.15, 0.0])

#: Rotations by 90 deg about x, y, z (columns: the turned unit vectors), written out, not computed by casflex.
RX90 = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], dtype=float)
RY90 = np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], dtype=float)
RZ90 = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]], dtype=float)
RX180 = RX90 @ RX90


def _vector(v) -> str:
    return " ".join(repr(float(x)) for x in v)


def arm_model(tmp_path: Path, kind: str, defaults, *, locked=(), root=(0.0, 0.0, 0.0), parent_orientation=(0, 0, 0),
              child_orientation=(0, 0, 0)) -> Path:
    """A model file (format 4.x, as OpenSim 4.6 reads it): a base on a PlanarJoint to the ground (coordinates
    root_rz rad, root_tx, root_ty m at ``root``) and an arm on a ``kind`` joint 'shoulder' from the base's
    CENTRE to the arm's M_IN_ARM, the offset frames turned by ``parent_orientation`` / ``child_orientation``
    (X-Y-Z body-fixed, rad); its coordinates arm_rx, arm_ry (, arm_rz) have the ``defaults`` (rad), those
    named in ``locked`` locked. Markers: MARKERS on the arm, 'base_tip' on the base."""
    names = ["arm_rx", "arm_ry", "arm_rz"][:KINDS[kind]]
    coords = "".join(f"<Coordinate name='{n}'><default_value>{float(v)!r}</default_value><range>-3.2 3.2</range>"
                     f"<locked>{str(n in locked).lower()}</locked></Coordinate>"
                     for n, v in zip(names, defaults, strict=True))
    rc = "".join(f"<Coordinate name='{n}'><default_value>{float(v)!r}</default_value></Coordinate>"
                 for n, v in zip(("root_rz", "root_tx", "root_ty"), root, strict=True))
    markers = "".join(f"<Marker name='{n}'><socket_parent_frame>/bodyset/arm</socket_parent_frame><location>"
                      f"{_vector(p)}</location></Marker>" for n, p in MARKERS.items())
    text = f"""<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="40000"><Model name="arm3d"><gravity>0 -9.80665 0</gravity>
<BodySet><objects>
<Body name="base"><mass>2</mass><mass_center>0 0.25 0</mass_center><inertia>0.1 0.1 0.1 0 0 0</inertia></Body>
<Body name="arm"><mass>1</mass><mass_center>{_vector(ARM_COM)}</mass_center>
<inertia>0.01 0.02 0.03 0 0 0</inertia></Body>
</objects></BodySet>
<JointSet><objects>
<PlanarJoint name="ground_base"><socket_parent_frame>/ground</socket_parent_frame>
<socket_child_frame>/bodyset/base</socket_child_frame><coordinates>{rc}</coordinates></PlanarJoint>
<{kind} name="shoulder"><socket_parent_frame>base_offset</socket_parent_frame>
<socket_child_frame>arm_offset</socket_child_frame><coordinates>{coords}</coordinates><frames>
<PhysicalOffsetFrame name="base_offset"><socket_parent>/bodyset/base</socket_parent>
<translation>{_vector(CENTRE)}</translation><orientation>{_vector(parent_orientation)}</orientation>
</PhysicalOffsetFrame>
<PhysicalOffsetFrame name="arm_offset"><socket_parent>/bodyset/arm</socket_parent>
<translation>{_vector(M_IN_ARM)}</translation><orientation>{_vector(child_orientation)}</orientation>
</PhysicalOffsetFrame>
</frames></{kind}>
</objects></JointSet>
<MarkerSet><objects>{markers}<Marker name="base_tip"><socket_parent_frame>/bodyset/base</socket_parent_frame>
<location>0.3 0.9 -0.05</location></Marker></objects></MarkerSet>
</Model></OpenSimDocument>
"""
    path = tmp_path / f"{kind}.osim"
    path.write_text(text)
    return path


def _positions(scene) -> dict[str, np.ndarray]:
    """The scene's markers (by label) and nodes ('node:<name>') in the plane (m), and the arm's centre of mass."""
    out = {m.label: np.array([m.x, m.y]) for m in scene.markers}
    out |= {f"node:{n.name}": np.array([n.x, n.y]) for n in scene.nodes}
    arm = next(b for b in scene.bodies if b.node == "arm")
    return out | {"arm_com": np.array([arm.com_x, arm.com_y])}


def _expected(R: np.ndarray) -> dict[str, np.ndarray]:
    """Where the arm's points are (x, y; m) with the base at the ground's origin and X_FM's rotation R:
    p = CENTRE + R (p_arm - M_IN_ARM) (the offset frames unturned)."""
    out = {n: (CENTRE + R @ (p - M_IN_ARM))[:2] for n, p in MARKERS.items()}
    return out | {"node:arm": CENTRE[:2], "arm_com": (CENTRE + R @ (ARM_COM - M_IN_ARM))[:2]}


def _lines(osc, start: str) -> list[str]:
    return [line for line in osc.report if line.startswith(start)]


@pytest.mark.parametrize("kind", KINDS)
def test_at_zero_a_universal_is_a_weld_a_gimbal_s_or_ball_s_third_rotation_a_hinge(kind, tmp_path):
    """x and y turn the arm out of the plane: held at 0 and reported; a gimbal's or ball's z is the normal."""
    osc = scene_from_osim(arm_model(tmp_path, kind, [0.0] * KINDS[kind]))
    sc = osc.scene
    joint = next(j for j in sc.joints if j.name == "shoulder")
    hinge = KINDS[kind] == 3
    assert joint.kind == ("hinge" if hinge else "weld")
    said = f"joint 'shoulder' ({kind}): " + ("a hinge, coordinate 'arm_rz'" if hinge else "a weld")
    assert _lines(osc, said) == [said]
    assert _lines(osc, "joint 'shoulder': coordinate") == [
        "joint 'shoulder': coordinate 'arm_rx' (rotation about [1.0, 0.0, 0.0]) locked at its default value 0",
        "joint 'shoulder': coordinate 'arm_ry' (rotation about [0.0, 1.0, 0.0]) locked at its default value 0"]
    assert {c.name: c.of for c in sc.coordinates} == {
        "root_rz": "base.theta", "root_tx": "base.x", "root_ty": "base.y", **({"arm_rz": "shoulder"} if hinge else {})}
    got, want = _positions(sc), _expected(np.eye(3))
    for name, p in want.items():
        np.testing.assert_allclose(got[name], p, rtol=0, atol=1e-15, err_msg=name)  # sums of a few m-sized terms
    np.testing.assert_allclose(got["hand"], [0.3, 0.5], rtol=0, atol=1e-15)
    assert loads_scene(dumps_scene(sc)) == sc  # `casflex import` writes it out and reads it back the same


#: kind, default values (deg), the joint's rotation R = X_FM's (closed form), the coordinate that is a hinge (None:
#: a weld), the arm node's angle (deg; None: its x axis on the normal, no angle in the plane), the hand and elbow
#: (m). Body-fixed x, y, z: after x by 90 deg the new y is the ground's z, the normal (a hinge); after x by 180
#: deg it is -y and after y by 90 deg the new z is the ground's x (welds). Another order of the same angles puts
#: the hand or the elbow elsewhere (the space-fixed X-Y-Z, R = RZ RY RX: the hand at the centre in all six, the
#: elbow 0.14 m or more off in x).
CLOSED = [
    # RX90 RY90: the arm's x to the ground's y (the hand straight up), its y to z, its z to x
    ("UniversalJoint", (90, 90), RX90 @ RY90, "arm_ry", 90.0, (0.1, 0.7), (0.17, 0.55)),
    # RX90 RY90 RZ180: the arm's x to -y (the hand straight down), its y to -z, its z to x
    ("GimbalJoint", (90, 90, 180), RX90 @ RY90 @ RZ90 @ RZ90, "arm_ry", -90.0, (0.1, 0.3), (0.17, 0.45)),
    ("BallJoint", (90, 90, 180), RX90 @ RY90 @ RZ90 @ RZ90, "arm_ry", -90.0, (0.1, 0.3), (0.17, 0.45)),
    # RX180 RY90: the arm's x to z (the hand on the centre), its y to -y, its z to x
    ("UniversalJoint", (180, 90), RX180 @ RY90, None, None, (0.1, 0.5), (0.17, 0.9)),
    # RX180 RY90 RZ90: the arm's x to -y, its y to -z, its z to x
    ("GimbalJoint", (180, 90, 90), RX180 @ RY90 @ RZ90, None, -90.0, (0.1, 0.3), (0.17, 0.45)),
    ("BallJoint", (180, 90, 90), RX180 @ RY90 @ RZ90, None, -90.0, (0.1, 0.3), (0.17, 0.45))]


@pytest.mark.parametrize(("kind", "defaults", "R", "hinge", "theta", "hand", "elbow"), CLOSED)
def test_nonzero_default_values_turn_the_child_by_body_fixed_x_y_z_rotations(kind, defaults, R, hinge, theta, hand,
                                                                             elbow, tmp_path):
    osc = scene_from_osim(arm_model(tmp_path, kind, [math.radians(d) for d in defaults]))
    sc = osc.scene
    assert next(j for j in sc.joints if j.name == "shoulder").kind == ("hinge" if hinge else "weld")
    said = f"a hinge, coordinate {hinge!r}" if hinge else "a weld"
    assert _lines(osc, f"joint 'shoulder' ({kind}): ") == [f"joint 'shoulder' ({kind}): {said}"]
    held = [(line.split("'")[3], line.rsplit(" ", 1)[1]) for line in _lines(osc, "joint 'shoulder': coordinate")]
    assert held == [(f"arm_r{a}", f"{math.radians(d):g}") for a, d in zip("xyz", defaults, strict=False)
                    if f"arm_r{a}" != hinge]  # each held coordinate named with its value (rad)
    if hinge:
        c = next(c for c in sc.coordinates if c.name == hinge)
        assert (c.of, c.value0, c.sign) == ("shoulder", math.radians(defaults[1]), 1.0)  # the new y is +z
    got, want = _positions(sc), _expected(R)
    # cos(pi/2) is 6e-17 in doubles: the positions are the closed form's to a few 1e-17 m
    for name, p in (*want.items(), ("hand", hand), ("elbow", elbow)):
        np.testing.assert_allclose(got[name], p, rtol=0, atol=1e-15, err_msg=name)
    if theta is not None:
        node = next(n for n in sc.nodes if n.name == "arm")
        assert math.degrees(node.theta) == pytest.approx(theta, abs=1e-12)


def test_a_coordinate_the_file_locks_makes_the_would_be_hinge_a_weld_reported(tmp_path):
    osc = scene_from_osim(arm_model(tmp_path, "GimbalJoint", [0.0, 0.0, 0.4], locked=("arm_rz",)))
    assert next(j for j in osc.scene.joints if j.name == "shoulder").kind == "weld"
    assert "joint 'shoulder': coordinate 'arm_rz' (rotation about [0.0, 0.0, 1.0]) locked in the model file, " \
           "at 0.4" in osc.report
    assert "arm_rz" not in [c.name for c in osc.scene.coordinates]
    # turned 0.4 rad about the normal: the hand 0.2 m from the centre along (cos 0.4, sin 0.4)
    hand = _positions(osc.scene)["hand"]
    np.testing.assert_allclose(hand, CENTRE[:2] + 0.2 * np.array([math.cos(0.4), math.sin(0.4)]), rtol=0,
                               atol=1e-15)


def test_a_universal_joint_whose_x_is_the_normal_is_a_hinge_its_y_held(tmp_path):
    """F and M turned -90 deg about y: F's x is the ground's z, the flexion axis (a wrist's)."""
    turn = (0.0, -math.pi / 2, 0.0)
    osc = scene_from_osim(arm_model(tmp_path, "UniversalJoint", [0.0, 0.0], parent_orientation=turn,
                                    child_orientation=turn))
    assert "joint 'shoulder' (UniversalJoint): a hinge, coordinate 'arm_rx'" in osc.report
    assert [line.split("'")[3] for line in _lines(osc, "joint 'shoulder': coordinate")] == ["arm_ry"]
    got, want = _positions(osc.scene), _expected(np.eye(3))
    for name, p in want.items():
        np.testing.assert_allclose(got[name], p, rtol=0, atol=1e-15, err_msg=name)


# The peer cases: nonzero default values, turned offset frames, a root away from the origin. Welds (every axis
# off the normal), a locked coordinate, and hinges (a gimbal's z 14 deg off the normal, projected; a universal's x
# on it): at the default pose each is OpenSim's pose projected on the plane.
PEER = [("UniversalJoint", (0.7, -0.4), (), (0.1, -0.2, 0.3), (-0.3, 0.2, 0.1)),
        ("GimbalJoint", (0.7, -0.4, 1.1), (), (0.1, -0.2, 0.3), (-0.3, 0.2, 0.1)),
        ("BallJoint", (0.7, -0.4, 1.1), ("arm_ry",), (0.1, -0.2, 0.3), (-0.3, 0.2, 0.1)),
        ("GimbalJoint", (0.2, -0.15, 0.6), (), (0, 0, 0), (0, 0, 0)),
        ("UniversalJoint", (0.6, 0.3), (), (0.0, -math.pi / 2, 0.0), (0.2, -math.pi / 2, -0.1))]


@needs_opensim
@pytest.mark.parametrize(("kind", "defaults", "locked", "po", "co"), PEER)
def test_the_default_pose_is_opensim_s_projected(kind, defaults, locked, po, co, tmp_path):
    from casflex.peers.opensim import file_kinematics

    path = arm_model(tmp_path, kind, list(defaults), locked=locked, root=(0.3, 0.2, 0.9), parent_orientation=po,
                     child_orientation=co)
    osc = scene_from_osim(path)
    hinge = next(j for j in osc.scene.joints if j.name == "shoulder").kind == "hinge"
    assert hinge == ((kind, defaults) in {("GimbalJoint", (0.2, -0.15, 0.6)), ("UniversalJoint", (0.6, 0.3))})
    ref = {k: v[0] for k, v in file_kinematics(path, {}).items()}  # OpenSim's default state, in the ground (m)
    got = _positions(osc.scene)
    pairs = [(got[m], ref[f"marker:{m}"]) for m in (*MARKERS, "base_tip")]
    pairs += [(got["node:base"], ref["body:base"]), (got["node:arm"], ref["marker:shoulder"]),
              (got["arm_origin"], ref["body:arm"])]
    mine, theirs = np.array([p for p, _ in pairs]), np.array([q[:2] for _, q in pairs])
    # products of a few unit rotations and metre-sized offsets, summed in another order in Simbody than in casflex:
    # a few eps of 1 m apart (1.7e-16 m at most measured); 1e-12 m leaves room for that double rounding and still
    # tells any other order of the rotations (the space-fixed X-Y-Z: 2 to 7 cm off here)
    assert np.abs(mine - theirs).max() < 1e-12, np.abs(mine - theirs).max()


# The same joints as Hamner's ankle, moving: the hinge of a gimbal or ball away from its default too.
LEG = Path(__file__).parent / "data" / "lab" / "hamner_subject02_leg.osim"


def _euler_ankle(tmp_path: Path, kind: str, defaults: list[float]) -> Path:
    """The leg model with its ankle made a ``kind`` (UniversalJoint, GimbalJoint, BallJoint) whose coordinates
    ankle_x, ankle_y (, ankle_z) have the ``defaults`` (rad), on the ankle's own frames."""
    text = LEG.read_text()
    start, end = text.index('<CustomJoint name="ankle_r">'), text.index("</CustomJoint>", text.index(
        '<CustomJoint name="ankle_r">')) + len("</CustomJoint>")
    old = text[start:end]
    frames = old[old.index("<frames>"):old.index("</frames>") + len("</frames>")]
    coords = "".join(f"<Coordinate name='ankle_{a}'><default_value>{v!r}</default_value><range>-3 3</range>"
                     "</Coordinate>" for a, v in zip("xyz", defaults, strict=False))
    new = (f"<{kind} name='ankle_r'><socket_parent_frame>tibia_r_offset</socket_parent_frame><socket_child_frame>"
           f"talus_r_offset</socket_child_frame><coordinates>{coords}</coordinates>{frames}</{kind}>")
    path = tmp_path / f"{kind}.osim"
    path.write_text(text[:start] + new + text[end:])
    return path


def _euler_foot(tmp_path, kind: str, defaults: list[float], values: dict) -> tuple[np.ndarray, np.ndarray]:
    """The foot's markers (poses, markers, 2) by casflex and by OpenSim 4.6 on the leg whose ankle is a ``kind``
    with ``defaults`` (tests/test_osim.py), at the coordinates ``values`` (name -> (k,))."""
    from casflex.inverse.inputs import inverse_model
    from casflex.inverse.tree import kinematic_tree
    from casflex.peers.opensim import file_kinematics
    from casflex.scene.coordinates import from_lab
    from casflex.scene.from_osim import scene_from_osim

    path = _euler_ankle(tmp_path, kind, defaults)
    sc = scene_from_osim(path).scene
    tree = kinematic_tree(inverse_model(sc))
    by = {c.scene_coordinate(): c for c in sc.coordinates}
    k = len(values["pelvis_tilt"])
    z = np.array([[from_lab(sc, by[nm], values[by[nm].name][i]) for nm in tree.names] for i in range(k)])
    mine = np.array([np.array(tree.marker_fit(zi)[0]).reshape(-1, 2) for zi in z])
    ref = file_kinematics(path, values)
    return mine, np.stack([ref[f"marker:{m.label}"][:, :2] for m in sc.markers], axis=1)


@needs_opensim
@pytest.mark.parametrize(("kind", "n"), [("UniversalJoint", 2), ("GimbalJoint", 3), ("BallJoint", 3)])
def test_universal_gimbal_and_ball_joints_are_opensims_x_y_z_rotations(kind, n, tmp_path):
    """The leg's ankle made a ``kind``: ab-/adducted and turned out of the plane at its default values (held by
    casflex), the hip and knee at random values; then (a gimbal, a ball) x and y at zero, its third rotation,
    about the normal, at random values. The markers where OpenSim 4.6 puts them, to rounding (metre-sized sums
    of products of unit rotations, as the leg's own test)."""
    rng = np.random.default_rng(11)
    k = 8
    legs = {"pelvis_tilt": rng.uniform(-0.3, 0.3, k), "pelvis_tx": rng.uniform(-1, 1, k),
            "pelvis_ty": rng.uniform(0.8, 1.1, k), "hip_flexion_r": rng.uniform(-0.5, 1.2, k),
            "knee_angle_r": rng.uniform(-2.0, 0.0, k)}
    held = {"ankle_x": 0.25, "ankle_y": -0.2, "ankle_z": 0.0}  # rad: x then y (body-fixed) held there
    defaults = list(held.values())[:n]
    mine, theirs = _euler_foot(tmp_path, kind, defaults, {**legs, **{a: np.full(k, v) for a, v in
                                                                     list(held.items())[:n]}})
    assert np.abs(mine - theirs).max() < 1e-12
    if n == 3:  # the third rotation is the hinge (x, y at zero): about the normal
        mine, theirs = _euler_foot(tmp_path, kind, [0.0] * 3, {**legs, "ankle_x": np.zeros(k), "ankle_y": np.zeros(k),
                                                              "ankle_z": rng.uniform(-0.5, 0.5, k)})
        assert np.abs(mine - theirs).max() < 1e-12
