"""The built-in scenes hamner_leg and hamner_leg_flexible (written by tests/hamner_leg.py from OpenSim's
scaled Hamner subject 02): their masses, centres and joint centres against the model's XML read here
on its own (tests/data/lab/hamner_subject02_leg.osim), the flexible segments against the rigid ones
through the assembled mass matrices, and the markers against one running stride of the trial."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

import casflex
from casflex.lab import Plane, markers_in_plane, read_sto, read_trc

LAB = Path(__file__).resolve().parent / "data" / "lab"
OSIM, TRC = LAB / "hamner_subject02_leg.osim", LAB / "hamner_running_stride.trc"
GRF, IK = LAB / "hamner_running_stride_grf.mot", LAB / "hamner_running_stride_ik.mot"
BODIES = {"pelvis": ("pelvis",), "thigh": ("femur_r",), "shank": ("tibia_r",),
          "foot": ("talus_r", "calcn_r", "toes_r")}
LEG = ("thigh", "shank", "foot")


# -- the OpenSim model's default pose from its XML --------------------------------------------------------

def _fmm_spline(xs: list[float], ys: list[float], t: float) -> float:
    """A cubic spline through (xs, ys) whose third derivative at each end is that of the cubic through the
    four end points (Forsythe, Malcolm and Moler's end conditions: OpenSim's SimmSpline), at t."""
    x, y = np.asarray(xs, float), np.asarray(ys, float)
    n, h = len(x), np.diff(x)
    d = np.diff(y) / h

    def third(i: int) -> float:  # the third divided difference of the points i..i+3
        d2 = [(d[k + 1] - d[k]) / (x[k + 2] - x[k]) for k in (i, i + 1)]
        return (d2[1] - d2[0]) / (x[i + 3] - x[i])

    A, r = np.zeros((n, n)), np.zeros(n)  # unknowns: the second derivatives at the knots
    for i in range(1, n - 1):
        A[i, i - 1:i + 2] = h[i - 1], 2 * (h[i - 1] + h[i]), h[i]
        r[i] = 6 * (d[i] - d[i - 1])
    A[0, :2], r[0] = (-1 / h[0], 1 / h[0]), 6 * third(0)
    A[-1, -2:], r[-1] = (-1 / h[-1], 1 / h[-1]), 6 * third(n - 4)
    s = np.linalg.solve(A, r)
    i = int(np.clip(np.searchsorted(x, t) - 1, 0, n - 2))
    a, b = x[i + 1] - t, t - x[i]
    return float((s[i] * a**3 + s[i + 1] * b**3) / (6 * h[i]) + (y[i] / h[i] - s[i] * h[i] / 6) * a
                 + (y[i + 1] / h[i] - s[i + 1] * h[i] / 6) * b)


def _at_zero(fn: ET.Element) -> float:
    """An OpenSim function of one coordinate at 0."""
    kind = fn.tag
    if kind == "Constant":
        return float(fn.findtext("value"))
    if kind == "LinearFunction":
        return float(fn.findtext("coefficients").split()[1])
    if kind == "MultiplierFunction":
        return float(fn.findtext("scale")) * _at_zero(next(iter(fn.find("function"))))
    if kind == "SimmSpline":
        return _fmm_spline([float(v) for v in fn.findtext("x").split()], [float(v) for v in fn.findtext("y").split()],
                           0.0)
    raise AssertionError(f"unexpected function {kind}")


def _vec(text: str) -> np.ndarray:
    return np.array([float(v) for v in text.split()])


def _osim() -> dict:
    """Body origins, masses, centres of mass and Izz, and marker positions of the model in its default
    pose (every coordinate 0), in the lab's 3-D axes."""
    model = ET.parse(OSIM).getroot().find("Model")
    origin = {"ground": np.zeros(3)}
    for joint in model.find("JointSet/objects"):
        for c in joint.iter("Coordinate"):
            assert float(c.findtext("default_value")) == 0.0
        frames = {f.get("name"): f for f in joint.find("frames")}
        parent, child = frames[joint.findtext("socket_parent_frame")], frames[joint.findtext("socket_child_frame")]
        assert not _vec(parent.findtext("orientation")).any() and not _vec(child.findtext("orientation")).any()
        shift = np.zeros(3)
        for axis in joint.find("SpatialTransform"):
            value = _at_zero(axis.find("*[@name='function']"))
            if axis.get("name").startswith("rotation"):
                assert value == 0.0  # every body's axes the lab's
            else:
                shift += value * _vec(axis.findtext("axis"))
        body = child.findtext("socket_parent").split("/")[-1]
        origin[body] = (origin[parent.findtext("socket_parent").split("/")[-1]] + _vec(parent.findtext("translation"))
                        + shift - _vec(child.findtext("translation")))
    bodies = {}
    for b in model.find("BodySet/objects"):
        inertia = _vec(b.findtext("inertia"))
        assert not inertia[3:].any()
        bodies[b.get("name")] = (float(b.findtext("mass")), origin[b.get("name")] + _vec(b.findtext("mass_center")),
                                 inertia[2])
    markers = {m.get("name"): origin[m.findtext("socket_parent_frame").split("/")[-1]] + _vec(m.findtext("location"))
               for m in model.find("MarkerSet/objects")}
    return {"origin": origin, "bodies": bodies, "markers": markers}


def _segment(parts: list[tuple[float, np.ndarray, float]]) -> tuple[float, np.ndarray, float]:
    """Mass, (x, y) centre and Izz about it of rigidly joined parts (mass, 3-D centre, own Izz)."""
    m = sum(p[0] for p in parts)
    c = sum(p[0] * p[1][:2] for p in parts) / m
    return m, c, sum(p[2] + p[0] * float(np.sum((p[1][:2] - c) ** 2)) for p in parts)


@pytest.fixture(scope="module")
def osim():
    return _osim()


@pytest.fixture(scope="module")
def models():
    return {name: casflex.assemble(casflex.load_scene(name)) for name in ("hamner_leg", "hamner_leg_flexible")}


# -- the segments --------------------------------------------------------------------------------------------

def _from_mass_matrix(model, nodes: list[str]) -> tuple[float, np.ndarray, float]:
    """Mass, centre and Izz of the nodes' part of the model from its mass matrix at q0: the kinetic energy
    of the part translating along x, y and turning about the origin (everything else at rest)."""
    M = np.array(model.mass(model.q0, model.p_nominal))
    ux, uy, ut = (np.zeros(model.n_dof) for _ in range(3))
    for n in nodes:
        i, j, k = model.dof(f"x{n}"), model.dof(f"y{n}"), model.dof(f"theta{n}")
        x, y = model.q0[i], model.q0[j]
        ux[i] = uy[j] = ut[k] = 1.0
        ut[i], ut[j] = -y, x  # turning at 1 rad/s about the origin
    m = ux @ M @ ux
    assert uy @ M @ uy == pytest.approx(m, rel=1e-12)
    c = np.array([uy @ M @ ut, -(ux @ M @ ut)]) / m
    return m, c, ut @ M @ ut - m * float(c @ c)


SEGMENT_NODES = {"hamner_leg": {"pelvis": ["pelvis"], "thigh": ["hip"], "shank": ["knee"], "foot": ["ankle"]},
                 "hamner_leg_flexible": {"pelvis": ["pelvis"], "foot": ["ankle"],
                                         "thigh": ["hip", "thigh_1", "thigh_2", "thigh_3", "knee_t"],
                                         "shank": ["knee", "shank_1", "shank_2", "shank_3", "ankle_s"]}}


def test_both_scenes_load_and_assemble_as_a_floating_leg_on_three_hinges(models):
    rigid, flexible = models["hamner_leg"], models["hamner_leg_flexible"]
    assert rigid.n_dof == 12 and flexible.n_dof == 36 and rigid.n_con == flexible.n_con == 6  # 3 hinges, no support
    assert not rigid.scene.supports and rigid.scene.gravity == (0.0, -9.80665)
    for m in models.values():
        phi, _ = m.constraint(m.q0)
        assert np.abs(np.array(phi)).max() < 1e-15  # the hinges closed in the default pose
    assert {b.name: b.elements for b in flexible.scene.beams} == {f"{s}_bone_{k}": 1 for s in ("thigh", "shank")
                                                                  for k in (1, 2, 3, 4)}


def test_masses_centres_joints_and_markers_are_the_osim_s(osim, models):
    rigid = models["hamner_leg"].scene
    nodes = {n.name: np.array([n.x, n.y]) for n in rigid.nodes}
    o = osim["origin"]
    for node, body in {"pelvis": "pelvis", "hip": "femur_r", "knee": "tibia_r", "ankle": "talus_r"}.items():
        # the joint centres: OpenSim placed them on the machine that wrote the scene, here sums of a few
        # terms and the knee's spline (a LAPACK solve): a few ulps of 1 m (1e-15) apart; 1e-12 m is 1e3 x that
        np.testing.assert_allclose(nodes[node], o[body][:2], rtol=0, atol=1e-12)
    # the knee: the tibia's origin at knee angle 0, 0.4186 m below the hip (the knee spline's value)
    assert np.linalg.norm(nodes["knee"] - nodes["hip"]) == pytest.approx(0.41859, abs=1e-5)
    want = {s: _segment([osim["bodies"][b] for b in bs]) for s, bs in BODIES.items()}
    for b in rigid.bodies:
        m, c, izz = want[b.name]
        np.testing.assert_allclose([b.mass, b.com_x, b.com_y, b.inertia], [m, *c, izz], rtol=1e-12, atol=1e-15)
    total = sum(osim["bodies"][b][0] for bs in BODIES.values() for b in bs)
    leg_m, leg_c, _ = _segment([osim["bodies"][b] for s in LEG for b in BODIES[s]])
    assert total == pytest.approx(23.104357, abs=1e-6)  # kg: pelvis and right leg of the 65.9 kg model
    for name, model in models.items():  # from the assembled mass matrix
        parts = {s: _from_mass_matrix(model, n) for s, n in SEGMENT_NODES[name].items()}
        assert sum(p[0] for p in parts.values()) == pytest.approx(total, rel=1e-9)
        assert sum(parts[s][0] for s in LEG) == pytest.approx(leg_m, rel=1e-9)
        c = sum(parts[s][0] * parts[s][1] for s in LEG) / leg_m
        np.testing.assert_allclose(c, leg_c, rtol=1e-9)
        scene = model.scene  # and straight from the file: the bodies and the beams (rho A L)
        at = {n.name: np.array([n.x, n.y]) for n in scene.nodes}
        m_file = sum(b.mass for b in scene.bodies) + sum(
            bm.rho * bm.A * np.linalg.norm(at[bm.nodes[1]] - at[bm.nodes[0]]) for bm in scene.beams)
        assert m_file == pytest.approx(total, rel=1e-12)
    for mk in rigid.markers:
        # OpenSim's placement on the writer's machine against sums here, as the joint centres: 1e-12 m
        np.testing.assert_allclose([mk.x, mk.y], osim["markers"][mk.label][:2], rtol=0, atol=1e-12)


def test_the_flexible_segments_are_the_rigid_ones_undeformed(models):
    """Per segment, beams and bodies together have the rigid body's mass, centre and Izz (from the
    assembled mass matrices); the markers sit where the rigid scene has them."""
    from conftest import assert_scenes_close
    from hamner_leg import flexible_scene

    from casflex.model.markers import marker_positions

    rigid, flexible = models["hamner_leg"], models["hamner_leg_flexible"]
    # what tests/hamner_leg.py writes, to 1e-12 relative: its point masses come from a norm (BLAS) and a 3 x 3
    # solve (LAPACK), whose kernels differ between CPUs: recomputed on another CPU than the file's, or under
    # OpenBLAS's other kernels, its masses differ by up to 9.5e-16 relative, and the inputs moved by 2 ulps
    # move them by up to 2.3e-14 (the remainder's Izz is a difference): 1e-12 is 40 x that. beta, rounded from an
    # eigenvalue to 3 digits (0.025020, 1e-3 from a rounding edge), comes out the file's 0.025
    assert_scenes_close(flexible.scene, flexible_scene(rigid.scene), 1e-12)
    for seg in BODIES:
        m0, c0, i0 = _from_mass_matrix(rigid, SEGMENT_NODES["hamner_leg"][seg])
        m1, c1, i1 = _from_mass_matrix(flexible, SEGMENT_NODES["hamner_leg_flexible"][seg])
        b = next(b for b in rigid.scene.bodies if b.name == seg)
        np.testing.assert_allclose([m0, *c0, i0], [b.mass, b.com_x, b.com_y, b.inertia], rtol=1e-12)
        np.testing.assert_allclose([m1, *c1, i1], [m0, *c0, i0], rtol=1e-9)
    for seg in ("thigh", "shank"):  # a point mass on each of the bone's five nodes, all positive
        on = {b.node: b for b in flexible.scene.bodies if b.name.startswith(f"{seg}_mass_")}
        assert list(on) == SEGMENT_NODES["hamner_leg_flexible"][seg]
        assert all(b.mass > 0.0 and b.inertia == 0.0 for b in on.values())
    bones = flexible.scene.beams
    assert len(bones) == 8 and {(bm.E, bm.rho, bm.beta) for bm in bones} == {(17e9, 1900.0, 0.025)}
    # the markers: where the rigid scene has them in the default pose, each thigh or shank one on the beam
    # of the four that holds its projection on the bone
    np.testing.assert_allclose(marker_positions(flexible, flexible.q0), marker_positions(rigid, rigid.q0),
                               rtol=0, atol=1e-9)
    on = {mk.name: mk.on for mk in flexible.scene.markers}
    assert {n: on[n] for n in on if "Thigh" in n or "Shank" in n} == {
        "R_Thigh_Upper": "thigh_bone_2", "R_Thigh_Front": "thigh_bone_3", "R_Thigh_Rear": "thigh_bone_3",
        "R_Shank_Upper": "shank_bone_1", "R_Shank_Front": "shank_bone_2", "R_Shank_Rear": "shank_bone_2"}
    assert [(mk.x, mk.y, mk.label) for mk in flexible.scene.markers] == [(mk.x, mk.y, mk.label)
                                                                         for mk in rigid.scene.markers]


def test_the_held_flexible_leg_s_lowest_mode_is_damped_as_the_soft_tissue():
    """Pelvis clamped and hinges locked (what the flexible inverse's drives hold): the lowest bending mode
    at 3.8 Hz with the damping ratio 0.3 the header chooses, the next ones overdamped."""
    from hamner_leg import held_modes

    md = held_modes(casflex.load_scene("hamner_leg_flexible"))
    np.testing.assert_allclose(md["hz"], [3.817, 18.37, 45.94, 84.65], rtol=1e-3)
    assert md["zeta_1"] == pytest.approx(0.3, abs=1e-3) and md["zeta"][0] == pytest.approx(md["zeta_1"], abs=1e-3)
    assert (md["zeta"][1:] > 1.0).all()


# -- the running stride ------------------------------------------------------------------------------------

def _kabsch(model_xy: np.ndarray, lab_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """R, t, RMS residual of the least-squares rigid motion R model + t of the points onto lab_xy."""
    cm, cl = model_xy.mean(axis=0), lab_xy.mean(axis=0)
    u, _, vt = np.linalg.svd((model_xy - cm).T @ (lab_xy - cl))
    R = vt.T @ np.diag([1.0, np.linalg.det(vt.T @ u.T)]) @ u.T
    res = lab_xy - ((model_xy - cm) @ R.T + cl)
    return R, cl - R @ cm, float(np.sqrt(np.mean(np.sum(res**2, axis=1))))


def test_the_stride_files():
    lab, grf, ik = read_trc(TRC), read_sto(GRF), read_sto(IK)
    assert lab.rate == 60.0 and lab.units == "mm" and lab.xyz.shape == (44, 13, 3) and np.isfinite(lab.xyz).all()
    assert lab.t[0] == pytest.approx(0.4) and lab.t[-1] == pytest.approx(1.117)
    np.testing.assert_array_equal(grf.t, lab.t)  # the same frames (times rounded to ms in both sources)
    np.testing.assert_allclose(ik.t, lab.t, atol=1e-3)
    assert ik.in_degrees and grf.names == ("ground_force_vx", "ground_force_vy", "ground_force_vz", "ground_force_px",
                                           "ground_force_py", "ground_force_pz", "ground_torque_x",
                                           "ground_torque_y", "ground_torque_z")
    on = grf.column("ground_force_vy") > 20.0  # N: heel strike to heel strike, one stance then the swing
    assert on[0] and on[-1] and not on[-2]
    changes = np.flatnonzero(np.diff(on.astype(int)))
    assert len(changes) == 2 and lab.t[changes[0] + 1] == pytest.approx(0.667)  # toe-off: 0.267 s of stance
    assert 2.0 < grf.column("ground_force_vy").max() / (65.9 * 9.80665) < 2.5  # body weights: 2.25 at mid-stance


def test_each_segment_s_markers_fit_the_stride_rigidly(models):
    """Per frame, each segment's markers (as the scene places them) fitted to the trial's, projected on
    (X, Y), by the least-squares rigid motion. Measured: RMS residual over the stride 3.1 mm (thigh),
    3.0 (shank), 8.2 (pelvis), 7.7 (foot), the worst frame 14 mm; with the scaled model's generic markers
    (subject02_scaled.osim) 80-100 mm on thigh and shank. Skin markers move on the bone by a cm or so, and
    the projection adds the segments' turning out of the plane: the pelvis' rotation moves the ASIS
    markers 13 cm from its midline forward and back, the foot's markers sit 2-6 cm off its long axis.
    Bounds: 5 mm RMS (thigh, shank), 12 mm (pelvis, foot), 20 mm in any frame."""
    scene = models["hamner_leg"].scene
    data = markers_in_plane(read_trc(TRC), {m.name: m.label for m in scene.markers}, Plane.parse("X,Y"))
    ik = read_sto(IK)
    nodes = {n.name: np.array([n.x, n.y]) for n in scene.nodes}
    fits, rms = {}, {}
    for seg in BODIES:
        ms = [m for m in scene.markers if m.on == seg]
        assert len(ms) >= 3
        xy = np.array([[m.x, m.y] for m in ms])
        cols = [[data.channels.index(f"{a}{m.name}") for a in "xy"] for m in ms]
        fits[seg] = [_kabsch(xy, np.array([row[c] for c in cols])) for row in data.q]
        r = np.array([f[2] for f in fits[seg]])
        rms[seg] = float(np.sqrt(np.mean(r**2)))
        assert r.max() < 0.020, (seg, r.max())
    assert max(rms["thigh"], rms["shank"]) < 0.005 and max(rms["pelvis"], rms["foot"]) < 0.012, rms

    def point(seg: str, p: np.ndarray) -> np.ndarray:  # a point of the scene's segment, where its fit puts it
        return np.array([R @ p + t for R, t, _ in fits[seg]])

    # each joint centre where the segments on both sides put it: 2 cm apart (median), 3.4 cm at worst
    for joint, (a, b) in {"hip": ("pelvis", "thigh"), "knee": ("thigh", "shank"), "ankle": ("shank", "foot")}.items():
        gap = np.linalg.norm(point(a, nodes[joint]) - point(b, nodes[joint]), axis=1)
        assert np.median(gap) < 0.03 and gap.max() < 0.045, (joint, gap.max())
    # the thigh from the pelvis' hip to the shank's knee, the shank from the thigh's knee to the foot's ankle:
    # the model's lengths (0.419 and 0.477 m) to within 10 % at every frame (measured 4.4 % and 7.6 %)
    for a, b, pa, pb in (("pelvis", "shank", "hip", "knee"), ("thigh", "foot", "knee", "ankle")):
        length = np.linalg.norm(nodes[pb] - nodes[pa])
        seen = np.linalg.norm(point(b, nodes[pb]) - point(a, nodes[pa]), axis=1)
        assert np.abs(seen / length - 1).max() < 0.10
    # the planar joint angles (rotation differences, the default pose's 0) follow OpenSim's 3-D inverse
    # kinematics of the same trial: measured 4-6 degrees RMS, the knee flexing to 107 degrees in swing
    angle = {seg: np.unwrap([np.arctan2(R[1, 0], R[0, 0]) for R, _, _ in fits[seg]]) for seg in BODIES}
    for column, rel in {"pelvis_tilt": angle["pelvis"], "hip_flexion_r": angle["thigh"] - angle["pelvis"],
                        "knee_angle_r": angle["shank"] - angle["thigh"],
                        "ankle_angle_r": angle["foot"] - angle["shank"]}.items():
        diff = np.degrees(rel) - ik.column(column)
        assert np.sqrt(np.mean(diff**2)) < 8.0 and np.abs(diff).max() < 13.0, (column, diff)
    assert np.degrees(angle["shank"] - angle["thigh"]).min() < -90.0
