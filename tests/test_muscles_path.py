"""casflex.muscles.path: muscle lengths, moment arms and unit loads on the kinematic tree, exact by AD: closed
forms on two segments about one hinge (law of cosines, the moment arm by hand), AD against central differences,
a conditional point switched at its range's bound, a moving point, the unit loads' moment against the moment arm
(virtual work), and the 1000-frame evaluation. The model is a hand-written OpenSim file (two segments, a knee)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from casflex.inverse import inverse_model, kinematic_tree
from casflex.muscles.path import MusclePaths
from casflex.scene.coordinates import from_lab
from casflex.scene.from_osim import scene_from_osim

GAIT = Path(__file__).parent / "data" / "muscles" / "gait10dof18musc.osim"
THIGH = 0.4  # the knee's centre below the thigh's origin, m

BODY = """<Body name="{name}"><mass>5</mass><mass_center>0 -0.2 0</mass_center><inertia>0.1 0.1 0.1 0 0 0</inertia>
<WrapObjectSet><objects>{wraps}</objects></WrapObjectSet></Body>"""
MODEL = """<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="40000"><Model name="two">
<BodySet><objects>{thigh}{shank}</objects></BodySet>
<JointSet><objects>
<PlanarJoint name="free"><socket_parent_frame>ground_offset</socket_parent_frame>
<socket_child_frame>thigh_offset</socket_child_frame>
<coordinates><Coordinate name="rz"><default_value>0</default_value></Coordinate>
<Coordinate name="tx"><default_value>0</default_value></Coordinate>
<Coordinate name="ty"><default_value>1</default_value></Coordinate></coordinates>
<frames><PhysicalOffsetFrame name="ground_offset"><socket_parent>/ground</socket_parent></PhysicalOffsetFrame>
<PhysicalOffsetFrame name="thigh_offset"><socket_parent>/bodyset/thigh</socket_parent></PhysicalOffsetFrame></frames>
</PlanarJoint>
<PinJoint name="knee"><socket_parent_frame>thigh_knee</socket_parent_frame>
<socket_child_frame>shank_knee</socket_child_frame>
<coordinates><Coordinate name="knee_angle"><default_value>{knee0}</default_value>{knee_range}
</Coordinate>{extra_coordinate}</coordinates>
<frames><PhysicalOffsetFrame name="thigh_knee"><socket_parent>/bodyset/thigh</socket_parent>
<translation>0 -{length} 0</translation></PhysicalOffsetFrame>
<PhysicalOffsetFrame name="shank_knee"><socket_parent>/bodyset/shank</socket_parent></PhysicalOffsetFrame></frames>
</PinJoint>
</objects></JointSet>
<ForceSet><objects>{muscles}</objects></ForceSet>
</Model></OpenSimDocument>
"""


def point(name: str, body: str, x: float, y: float, z: float = 0.0, extra: str = "", kind: str = "PathPoint") -> str:
    inner = "" if kind == "MovingPathPoint" else f"<location>{x} {y} {z}</location>"
    return (f'<{kind} name="{name}"><socket_parent_frame>/bodyset/{body}</socket_parent_frame>{inner}{extra}'
            f"</{kind}>")


def muscle(name: str, points: str, kind: str = "Thelen2003Muscle", numbers: str = "", wraps: str = "") -> str:
    return (f'<{kind} name="{name}"><GeometryPath name="path"><PathPointSet><objects>{points}</objects>'
            f"</PathPointSet><PathWrapSet><objects>{wraps}</objects></PathWrapSet></GeometryPath>"
            f"<max_isometric_force>1000</max_isometric_force><optimal_fiber_length>0.1</optimal_fiber_length>"
            f"<tendon_slack_length>0.2</tendon_slack_length>{numbers}</{kind}>")


def model(tmp_path: Path, muscles: str, knee0: float = 0.0, wraps: str = "", extra_coordinate: str = "",
          name: str = "two.osim", knee_range: str = "<range>-2 0.2</range>") -> Path:
    path = tmp_path / name
    path.write_text(MODEL.format(thigh=BODY.format(name="thigh", wraps=wraps),
                                 shank=BODY.format(name="shank", wraps=""),
                                 muscles=muscles, knee0=knee0, extra_coordinate=extra_coordinate, length=THIGH,
                                 knee_range=knee_range))
    return path


def paths(path: Path):
    s = scene_from_osim(path, muscles=True)
    tree = kinematic_tree(inverse_model(s.scene))
    return s, tree, MusclePaths(tree, s.muscles)


def knee_z(tree, scene, knee: float) -> np.ndarray:
    """The tree's coordinates z with the knee at ``knee`` (rad, lab value), the rest at the default pose."""
    z = tree.coordinates(tree.model.q0)
    c = next(c for c in scene.coordinates if c.name == "knee_angle")
    z[tree.names.index(c.scene_coordinate())] = from_lab(scene, c, knee)
    return z


A, B = np.array([0.05, 0.15, 0.02]), np.array([0.04, -0.1, -0.01])  # origin (thigh, from the knee), insertion


def _simple(tmp_path: Path, extra: str = "", knee0: float = 0.0, name: str = "two.osim") -> Path:
    pts = point("o", "thigh", A[0], A[1] - THIGH, A[2]) + extra + point("i", "shank", *B)
    return model(tmp_path, muscle("m", pts), knee0=knee0, name=name)


@pytest.mark.parametrize("knee0", [0.0, -0.5])  # the default pose straight, and bent (the frames then turned)
def test_length_and_moment_arm_of_two_points_about_one_hinge_are_the_law_of_cosines(tmp_path, knee0):
    s, tree, mp = paths(_simple(tmp_path, knee0=knee0))
    ci = [c.name for c in s.scene.coordinates].index("knee_angle")
    for q in (-1.7, -0.6, 0.0, 0.15):
        Bq = np.array([math.cos(q) * B[0] - math.sin(q) * B[1], math.sin(q) * B[0] + math.cos(q) * B[1]])
        L = math.hypot(math.dist(A[:2], Bq), A[2] - B[2])
        arm = -(A[0] * Bq[1] - A[1] * Bq[0]) / L  # -dL/dq = -(A x B)_z / L
        z = knee_z(tree, s.scene, q)
        assert float(mp.length(z)) == pytest.approx(L, abs=1e-14)  # rounding only
        r = np.array(mp.moment_arms(z)).ravel()
        assert r[ci] == pytest.approx(arm, abs=1e-14)
        assert np.abs(np.delete(r, ci)).max() < 1e-14  # the root moves both points alike: no arm about it


def test_moment_arms_are_minus_the_central_differences_of_the_length_on_gait10dof18musc():
    s, tree, mp = paths(GAIT)
    rng = np.random.default_rng(3)
    z0 = tree.coordinates(tree.model.q0)
    h = 1e-6
    for _ in range(3):
        z = z0 + rng.uniform(-0.6, 0.3, tree.n) * np.r_[0, 0, np.ones(tree.n - 2)]
        r = np.array(mp.moment_arms(z))
        for k, c in enumerate(s.scene.coordinates):
            dz = np.zeros(tree.n)
            dz[tree.names.index(c.scene_coordinate())] = c.sign * h
            fd = -(np.array(mp.length(z + dz)) - np.array(mp.length(z - dz))).ravel() / (2 * h)
            assert np.abs(r[:, k] - fd).max() < 1e-8  # central differences' truncation and rounding: ~1e-10
        assert np.abs(r).max() > 0.03  # some muscle has a real arm here


def test_a_conditional_point_switches_at_its_ranges_bound_with_opensims_tolerance(tmp_path):
    cond = point("c", "thigh", 0.1, -THIGH, 0.0, kind="ConditionalPathPoint",
                 extra="<socket_coordinate>/jointset/knee/knee_angle</socket_coordinate><range>-1 -0.5</range>")
    s, tree, mp = paths(_simple(tmp_path, cond))
    C = np.array([0.1, 0.0, 0.0])  # the conditional point from the knee

    def expect(q: float, on: bool) -> float:
        Bq = np.array([math.cos(q) * B[0] - math.sin(q) * B[1], math.sin(q) * B[0] + math.cos(q) * B[1], B[2]])
        return float(np.linalg.norm(A - C) + np.linalg.norm(C - Bq)) if on else float(np.linalg.norm(A - Bq))

    for q, on in ((-0.5 + 0.9e-5, True), (-0.5 + 1.1e-5, False), (-1 - 0.9e-5, True), (-1 - 1.1e-5, False),
                  (-0.7, True), (0.0, False)):
        assert float(mp.length(knee_z(tree, s.scene, q))) == pytest.approx(expect(q, on), abs=1e-14), q


def test_a_moving_point_follows_its_function_of_the_coordinate_clamped_to_its_range(tmp_path):
    fx = "<x_location><LinearFunction><coefficients>0.02 0.04</coefficients></LinearFunction></x_location>"
    fy = ("<y_location><SimmSpline><x>-2 -1 0 0.2</x><y>-0.1 -0.12 -0.1 -0.09</y></SimmSpline></y_location>"
          "<z_location><Constant><value>0.01</value></Constant></z_location>")
    sock = "".join(f"<socket_{a}_coordinate>/jointset/knee/knee_angle</socket_{a}_coordinate>" for a in "xy")
    pts = point("o", "thigh", A[0], A[1] - THIGH, A[2]) + point("i", "shank", 0, 0, extra=sock + fx + fy,
                                                                    kind="MovingPathPoint")
    s, tree, mp = paths(model(tmp_path, muscle("m", pts)))
    spline = s.muscles[0].path[1].moving[1][2]
    for q in (-1.5, -0.3, 0.1, 0.5):  # 0.5 beyond the range's 0.2: OpenSim clamps the coordinate
        qc = min(q, 0.2)
        Bl = np.array([0.02 * qc + 0.04, float(spline(qc)), 0.01])
        Bq = np.array([math.cos(q) * Bl[0] - math.sin(q) * Bl[1], math.sin(q) * Bl[0] + math.cos(q) * Bl[1], Bl[2]])
        assert float(mp.length(knee_z(tree, s.scene, q))) == pytest.approx(np.linalg.norm(A - Bq), abs=1e-14)


def test_unit_loads_moment_is_the_moment_arm_about_the_hinge_angle():
    """Virtual work: a unit tension's moment on the distal part about a fixed hinge centre is -dL/d(own angle),
    sign times the lab coordinate's moment arm; at a coupled hinge (the knee rolls) the generalised force adds
    (fx, fy) . d(centre)/d(angle), and a moving point's own motion adds its pull along it (not checked here)."""
    import casadi as ca

    s, tree, mp = paths(GAIT)
    z = tree.coordinates(tree.model.q0) + np.r_[0, 0, 0.1, 0.4, -0.3, 0.1, -0.9, -0.4, 0.2, -0.1]
    U, r = np.array(mp.unit_loads(z)), np.array(mp.moment_arms(z))
    fixed = [i for i, m in enumerate(s.muscles) if not any(p.moving for p in m.path)]
    for h, name in enumerate(tree.hinges):
        c = next(c for c in s.scene.coordinates if c.scene_coordinate() == f"{name}.angle")
        k = tree.names.index(f"{name}.angle")
        dC = np.array(ca.Function("c", [mp.z], [ca.jacobian(mp._centre(name), mp.z)])(z))[:, k]
        Q = U[3 * h + 2] + dC @ U[3 * h: 3 * h + 2]
        assert np.abs(Q - c.sign * r[:, s.scene.coordinates.index(c)])[fixed].max() < 1e-14  # rounding
        if not np.any(dC):
            assert np.abs(U[3 * h + 2] - c.sign * r[:, s.scene.coordinates.index(c)]).max() < 1e-14
    hip = tree.hinges.index("hip_r")
    assert np.abs(U[3 * hip + 2]).max() > 0.03 and np.abs(U[3 * hip: 3 * hip + 2]).max() > 0.5


def test_a_muscle_not_crossing_a_hinge_puts_no_load_on_its_distal_part(tmp_path):
    s, tree, mp = paths(GAIT)
    U = np.array(mp.unit_loads(tree.coordinates(tree.model.q0)))
    back = tree.hinges.index("back")
    assert np.abs(U[3 * back: 3 * back + 3]).max() == 0.0  # no muscle of the model crosses the lumbar joint


def test_evaluate_gives_lengths_speeds_and_moment_arms_over_many_frames():
    s, tree, mp = paths(GAIT)
    rng = np.random.default_rng(1)
    z = tree.coordinates(tree.model.q0) + rng.uniform(-0.3, 0.3, (50, tree.n))
    zd = rng.normal(size=(50, tree.n))
    out = mp.evaluate(z, zd)
    assert out["lengths"].shape == (50, 18) and out["moment_arms"].shape == (50, 18, 10)
    for k in (0, 17, 49):
        assert np.array_equal(out["lengths"][k], np.array(mp.length(z[k])).ravel())
        assert np.array_equal(out["moment_arms"][k], np.array(mp.moment_arms(z[k])))
        h = 1e-6
        fd = (np.array(mp.length(z[k] + h * zd[k])) - np.array(mp.length(z[k] - h * zd[k]))).ravel() / (2 * h)
        assert np.abs(out["speeds"][k] - fd).max() < 1e-8  # central differences' truncation: ~1e-10 m/s


def test_a_condition_on_a_coordinate_the_scene_lacks_is_refused(tmp_path):
    import dataclasses

    s = scene_from_osim(_simple(tmp_path, point("c", "thigh", 0.1, -THIGH, kind="ConditionalPathPoint",
                                                extra="<socket_coordinate>/jointset/knee/knee_angle"
                                                "</socket_coordinate><range>-1 0</range>")), muscles=True)
    tree = kinematic_tree(inverse_model(s.scene))
    p = s.muscles[0].path[1]
    bad = dataclasses.replace(s.muscles[0], path=(s.muscles[0].path[0], dataclasses.replace(
        p, condition=("hip", -1.0, 0.0)), s.muscles[0].path[2]))
    with pytest.raises(ValueError, match=r"^muscle 'm' path point 'c': follows 'hip', no coordinate of the scene"):
        MusclePaths(tree, [bad])
    gone = dataclasses.replace(s.muscles[0], path=(dataclasses.replace(p, node="calf"), *s.muscles[0].path[1:]))
    with pytest.raises(ValueError, match=r"^muscle 'm' path point 'c': node 'calf' is no node of the scene"):
        MusclePaths(tree, [gone])


def test_two_points_at_one_place_give_finite_moment_arms_and_loads(tmp_path):
    """A path's two points at one place on one body (a model's repeated via point): the zero-length segment adds
    nothing, where its direction 0/0 made the moment arms and the loads NaN."""
    s, tree, mp = paths(_simple(tmp_path, point("o2", "thigh", A[0], A[1] - THIGH, A[2])))
    z = knee_z(tree, s.scene, -0.8)
    _, _, plain = paths(_simple(tmp_path, name="plain.osim"))
    r, U = np.array(mp.moment_arms(z)), np.array(mp.unit_loads(z))
    assert np.isfinite(r).all() and np.isfinite(U).all()
    assert np.array_equal(r, np.array(plain.moment_arms(z))) and np.array_equal(U, np.array(plain.unit_loads(z)))


def test_a_moving_point_on_a_coordinate_without_range_is_clamped_to_opensims_default_range(tmp_path):
    """OpenSim's Coordinate has the range [-10, 10] where the file gives none, and clamps a MovingPathPoint's
    coordinate to it: the point stops at 10 while the knee turns on."""
    fx = "<x_location><LinearFunction><coefficients>0.01 0</coefficients></LinearFunction></x_location>"
    sock = "<socket_x_coordinate>/jointset/knee/knee_angle</socket_x_coordinate>"
    pts = point("o", "thigh", 0.0, 0.0) + point("i", "thigh", 0, 0, extra=sock + fx, kind="MovingPathPoint")
    s, tree, mp = paths(model(tmp_path, muscle("m", pts), knee_range=""))
    for q, x in ((3.0, 0.03), (10.5, 0.1), (-12.0, -0.1)):
        assert float(mp.length(knee_z(tree, s.scene, q))) == pytest.approx(abs(x), abs=1e-15)
