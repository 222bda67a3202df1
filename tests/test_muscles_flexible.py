"""Muscles on flexible segments (casflex.muscles.flexible, issue 47 item 6): Hamner's subject 02 muscles
(tests/data/muscles/hamner_subject02_planar_muscles.osim) carried onto the built-in pelvis and right leg, rigid
(hamner_leg) and with beams for bones (hamner_leg_flexible): the same subject, default pose and joint centres."""

from __future__ import annotations

from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from casflex import load_scene
from casflex.inverse import inverse_model
from casflex.inverse.tree import kinematic_tree
from casflex.muscles.flexible import FlexiblePaths, carried_muscles
from casflex.muscles.path import MusclePaths
from casflex.scene.from_osim import scene_from_osim

MODEL = Path(__file__).parent / "data" / "muscles" / "hamner_subject02_planar_muscles.osim"
COORDINATES = {"hip_flexion_r": ("hip", 1.0, 0.0), "knee_angle_r": ("knee", 1.0, 0.0),
               "ankle_angle_r": ("ankle", 1.0, 0.0)}
FOOT = {"pelvis": "pelvis", "talus_r": "ankle", "calcn_r": "ankle", "toes_r": "ankle"}
RIGID = FOOT | {"femur_r": "hip", "tibia_r": "knee"}
FLEXIBLE = FOOT | {"femur_r": tuple(f"thigh_bone_{i}" for i in range(1, 5)),
                   "tibia_r": tuple(f"shank_bone_{i}" for i in range(1, 5))}
HIP_ONLY = ("glut_max1_r", "glut_med2_r", "iliacus_r", "psoas_r", "add_long_r", "pect_r")  # pelvis to femur


@pytest.fixture(scope="module")
def osim():
    return scene_from_osim(MODEL, muscles=True)


def _paths(scene_name: str, osim, bodies, names=None):
    sc = load_scene(scene_name)
    tree = kinematic_tree(inverse_model(sc, "pelvis"), "pelvis")
    muscles = [m for m in carried_muscles(osim, bodies)[0] if names is None or m.name in names]
    return tree, FlexiblePaths(tree, muscles, bodies, COORDINATES)


def _poses(n: int, seed: int = 1) -> np.ndarray:
    """(n, 6): pelvis x, y, theta, hip, knee, ankle angles, a runner's range."""
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(-0.5, 0.5, n), rng.uniform(0.8, 1.0, n), rng.uniform(-0.3, 0.3, n),
                            rng.uniform(-0.5, 1.2, n), rng.uniform(-1.5, 0.0, n), rng.uniform(-0.4, 0.4, n)])


def test_on_rigid_segments_the_paths_are_the_models(osim):
    """The hip's muscles (an iliacus' and psoas' conditional point on the hip angle among them) on the rigid leg:
    lengths and hip moment arms equal casflex's paths on the whole-body model at the same pelvis and hip."""
    tree, paths = _paths("hamner_leg", osim, RIGID, HIP_ONLY)
    assert tree.names == ("pelvis.x", "pelvis.y", "pelvis.theta", "hip.angle", "knee.angle", "ankle.angle")
    whole = kinematic_tree(inverse_model(osim.scene, "pelvis"), "pelvis")
    ref = MusclePaths(whole, paths.muscles)
    z = _poses(20)
    zw = np.zeros((len(z), whole.n))
    for k, name in enumerate(("pelvis.x", "pelvis.y", "pelvis.theta", "hip_r.angle")):
        zw[:, whole.names.index(name)] = z[:, k]
    q = np.array(tree.forward.map(len(z))(z.T)).T
    got = paths.evaluate(q, np.zeros_like(q))
    want = ref.evaluate(zw)
    hip = [c.name for c in osim.scene.coordinates].index("hip_flexion_r")
    assert np.abs(got["lengths"] - want["lengths"]).max() < 1e-12  # the same points and sums, to round-off
    assert np.abs(got["unit"][:, 2, :] - want["moment_arms"][:, :, hip]).max() < 1e-12


def test_an_undeformed_flexible_leg_gives_the_rigid_legs_paths(osim):
    """The flexible leg moved as a rigid one (its tree's rigid motion of each beam chain): every muscle's length,
    speed and unit loads equal the rigid leg's: the shape functions carry the points rigidly when the beams do not
    bend."""
    rt, rigid = _paths("hamner_leg", osim, RIGID)
    ft, flex = _paths("hamner_leg_flexible", osim, FLEXIBLE)
    assert ft.names == rt.names and len(flex.muscles) == 43
    z, zd = _poses(12), _poses(12, seed=2)
    out = []
    for tree, paths in ((rt, rigid), (ft, flex)):
        q, qd, _ = (np.array(a).T for a in tree.rates.map(len(z))(z.T, zd.T, 0 * z.T))
        out.append(paths.evaluate(q, qd))
    for key in ("lengths", "speeds", "unit"):
        assert np.abs(out[0][key] - out[1][key]).max() < 1e-10, key  # round-off of the chord's atan2 and norms


def test_on_a_bent_femur_the_hip_moment_is_the_paths_rate_of_turning_the_leg(osim):
    """The thigh's beams bent (its inner nodes moved off the line and turned): the moment a unit tension puts on the
    hip's distal part about the hip's centre is -dL/d(angle) of turning that whole part about the centre, the
    deformation held (virtual work: the moment arm with the bone as it is)."""
    ft, flex = _paths("hamner_leg_flexible", osim, FLEXIBLE)
    z = _poses(1, seed=3)[0]
    q = np.array(ft.forward(z)).ravel()
    idx = ft.model.node_names.index
    for k, (dx, dth) in enumerate(((0.004, 0.02), (0.007, 0.0), (0.004, -0.02))):  # a bow of 7 mm
        i = idx(f"thigh_{k + 1}")
        q[3 * i] += dx
        q[3 * i + 2] += dth
    distal = sorted(flex._distal("hip"))


    C = np.array(ca.Function("c", [flex.q], [flex.centre("hip")])(q)).ravel()

    def turned(d: float) -> np.ndarray:
        out = q.copy()
        c, s = np.cos(d), np.sin(d)
        for n in distal:
            p = q[3 * n: 3 * n + 2] - C
            out[3 * n: 3 * n + 2] = C + np.array([c * p[0] - s * p[1], s * p[0] + c * p[1]])
            out[3 * n + 2] += d
        return out

    h = 1e-6
    L = [np.asarray(flex.rates(turned(d), np.zeros_like(q))[0]).ravel() for d in (h, -h)]
    dL = (L[0] - L[1]) / (2 * h)
    U = flex.evaluate(q[None], np.zeros((1, q.size)))["unit"][0]
    crossing = np.abs(U[2]) > 0
    assert crossing.sum() > 20  # the hip's muscles, the thigh's biarticular ones among them
    assert np.abs(U[2] + dL).max() < 1e-8  # central difference at h = 1e-6: error h^2 L''' ~ 1e-12, round-off 1e-10


def test_a_body_no_node_or_beam_carries_is_refused_naming_the_muscle(osim):
    sc = load_scene("hamner_leg_flexible")
    tree = kinematic_tree(inverse_model(sc, "pelvis"), "pelvis")
    femur = next(m for m in osim.muscles if m.name == "glut_max1_r")
    with pytest.raises(ValueError, match="muscle 'glut_max1_r' path point .*: on 'femur_r', which no node or beam"):
        FlexiblePaths(tree, [femur], FOOT, COORDINATES)
    with pytest.raises(ValueError, match="bodies: femur_r: beam 'thigh_bone_3' does not start where the one"):
        FlexiblePaths(tree, [femur], FOOT | {"femur_r": ("thigh_bone_1", "thigh_bone_3")}, COORDINATES)


def test_a_point_on_a_bent_element_follows_its_shape_functions(osim):
    """One element of the thigh bent to a constant curvature kappa (its end rotations +-kappa L0 / 2 from its chord):
    a point on its axis at xi lies off the chord by the Hermite cubic, kappa L0^2 xi (1 - xi) / 2 (the cubic is
    then that parabola), and a point 2 cm off the axis turns with the section by kappa L0 (xi - 1/2)."""
    ft, flex = _paths("hamner_leg_flexible", osim, FLEXIBLE)
    idx = ft.model.node_names.index
    a, b = idx("thigh_1"), idx("thigh_2")
    xa, xb = flex.q0[3 * a: 3 * a + 2], flex.q0[3 * b: 3 * b + 2]
    chord = xb - xa
    L0 = float(np.linalg.norm(chord))
    n = np.array([-chord[1], chord[0]]) / L0
    kappa, xi = 0.5, 0.3  # 1/m: a radius of 2 m
    q = flex.q0.copy()
    q[3 * a + 2] += kappa * L0 / 2
    q[3 * b + 2] -= kappa * L0 / 2
    from casflex.muscles.flexible import BeamSite

    site = BeamSite(a, b, xi)
    for off in (0.0, 0.02):
        P0 = np.array([*(xa + xi * chord + off * n), 0.0])
        got = np.array(ca.Function("p", [flex.q], [flex._on_beam(site, ca.DM(P0))])(q)).ravel()
        turn = kappa * L0 * (0.5 - xi)  # v'(xi) = kappa L0 (1/2 - xi): the section's turn from the chord
        want = xa + xi * chord + kappa * L0 ** 2 * xi * (1 - xi) / 2 * n + off * (np.cos(turn) * n + np.sin(turn)
                                                                                   * -chord / L0)
        assert np.abs(got - want).max() < 1e-15  # the same arithmetic, rounded differently
