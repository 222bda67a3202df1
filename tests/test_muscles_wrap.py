"""casflex.muscles.wrap: a path segment over a cylinder about the plane's normal (a circle), OpenSim's
WrapCylinder rules, and the wrapped paths' moment arms (exact by AD: equal to -dL/dq by finite differences). OpenSim's
own numbers beside casflex's: tests/test_peers_opensim_muscles.py."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from casflex.inverse import inverse_model, kinematic_tree
from casflex.muscles.path import MusclePaths
from casflex.muscles.wrap import circle_wrap
from casflex.scene.coordinates import from_lab
from casflex.scene.from_osim import scene_from_osim
from casflex.scene.osim import read_osim

RAJAGOPAL = Path(__file__).parent / "data" / "muscles" / "rajagopal_planar_wraps.osim"


def _wrap(a, b, r=0.03, axis=0, sign=0):
    x = ca.SX.sym("x", 6)
    w = circle_wrap(x[:3], x[3:], r, axis, sign)
    f = ca.Function("f", [x], [w.code, w.length, w.r1, w.r2, w.arc])
    return [np.array(v).ravel() for v in f(np.r_[a, b])]


def test_a_line_through_the_circle_wraps_over_the_tangents_and_the_arc():
    d, e, r = 0.1, 0.01, 0.03
    code, L, r1, r2, arc = _wrap([-d, e, 0], [d, e, 0], r)
    assert code[0] == 2  # mandatory: the straight line passes through the circle
    rho = math.hypot(d, e)  # over the +y side: the angle between the points less the two tangents' angles
    theta = math.pi - 2 * math.atan(e / d) - 2 * math.acos(r / rho)
    assert abs(L[0] - (2 * math.sqrt(rho * rho - r * r) + r * theta)) < 1e-15
    assert abs(arc[0] - r * theta) < 1e-15 and r1[1] > 0 and r2[1] > 0
    assert abs(np.hypot(*r1[:2]) - r) < 1e-15 and abs(np.hypot(*r2[:2]) - r) < 1e-15
    assert abs(np.dot(r1[:2], r1[:2] - [-d, e])) < 1e-15  # tangent: the radius is normal to the line
    code, L, *_ = _wrap([-d, 0.05, 0], [d, 0.06, 0], r)  # the line misses the circle (5.5 cm from its centre)
    assert code[0] == 0


def test_a_point_inside_the_circle_does_not_wrap_and_its_derivative_is_not_nan():
    x = ca.SX.sym("x", 6)
    w = circle_wrap(x[:3], x[3:], 0.03)
    J = ca.Function("J", [x], [ca.jacobian(ca.if_else(w.code > 0, w.length, 0), x)])
    assert np.isfinite(np.array(J([0.01, 0, 0, 0.1, 0.01, 0]))).all()
    assert _wrap([0.01, 0, 0], [0.1, 0.01, 0])[0][0] == 0


def test_a_constrained_quadrant_wraps_only_over_its_side():
    # '+y': the line through the circle, both points below it: wraps, the tangents on the active (+y) side
    code, L, r1, r2, _ = _wrap([-0.1, -0.05, 0], [0.1, -0.05, 0], axis=1, sign=1)
    assert code[0] == 1 and r1[1] > 0 and r2[1] > 0
    # both points on the active side with the line missing the circle: no wrap
    assert _wrap([-0.1, 0.05, 0], [0.1, 0.05, 0], axis=1, sign=1)[0][0] == 0
    # the line through the circle, one point on each side: must wrap
    assert _wrap([-0.1, 0.01, 0], [0.1, -0.01, 0], axis=1, sign=1)[0][0] == 2


def test_points_at_two_depths_take_the_shortest_path_round_the_cylinder():
    flat = _wrap([-0.1, 0.001, 0.0], [0.1, 0.001, 0.0])
    deep = _wrap([-0.1, 0.001, 0.0], [0.1, 0.001, 0.04])
    assert abs(deep[1][0] - math.hypot(flat[1][0], 0.04)) < 1e-15  # the unrolled cylinder: a straight line
    assert abs(deep[4][0] - math.hypot(flat[4][0], deep[3][2] - deep[2][2])) < 1e-15


@pytest.fixture(scope="module")
def paths():
    s = scene_from_osim(RAJAGOPAL, muscles=True)
    tree = kinematic_tree(inverse_model(s.scene))
    return s, tree, MusclePaths(tree, s.muscles)


def _random_z(s, tree, n, seed=47):
    """n poses, each lab coordinate uniform in the model's range (the pelvis's translations within 0.5 m)."""
    rng = np.random.default_rng(seed)
    ranges = {c.name: c.range for j in read_osim(RAJAGOPAL).joints for c in j.coordinates}
    z = np.zeros((n, tree.n))
    for c in s.scene.coordinates:
        lo, hi = ranges[c.name]
        lo, hi = (max(lo, -0.5), min(hi, 0.5)) if c.name in ("pelvis_tx", "pelvis_ty") else (lo, hi)
        z[:, tree.names.index(c.scene_coordinate())] = [from_lab(s.scene, c, v) for v in rng.uniform(lo, hi, n)]
    return z


def test_wrapped_moment_arms_are_minus_dl_dq_by_finite_differences(paths):
    s, tree, mp = paths
    z = _random_z(s, tree, 12)
    out = mp.evaluate(z)
    plain = MusclePaths(tree, [dataclasses.replace(m, wraps=()) for m in s.muscles]).evaluate(z)["lengths"]
    wrapped = np.abs(out["lengths"] - plain) > 1e-6
    assert wrapped[:, :4].any(axis=0).all() and not wrapped.all()  # each wrapping muscle wraps at some poses only
    h = 1e-6
    for k in range(len(z)):
        for c_idx, c in enumerate(mp.coordinates):
            j = tree.names.index(c.scene_coordinate())
            zp, zm = z[k].copy(), z[k].copy()
            zp[j] += h
            zm[j] -= h
            fd = -c.sign * (np.array(mp.length(zp)) - np.array(mp.length(zm))).ravel() / (2 * h)
            # central differences of m-sized lengths at h = 1e-6: truncation ~1e-12, rounding ~1e-10
            assert np.abs(fd - out["moment_arms"][k, :, c_idx]).max() < 1e-8


def test_the_unit_loads_are_the_moment_arms_by_virtual_work(paths):
    """The wrapped path pulls the cylinder's body at the tangent points: the moment a unit tension puts on a hinge's
    distal part is its coordinate's sign times the moment arm (the hinges here are not coupled)."""
    s, tree, mp = paths
    z = _random_z(s, tree, 6, seed=3)
    r = mp.evaluate(z)["moment_arms"]
    for k in range(len(z)):
        loads = np.array(mp.unit_loads(z[k]))
        for h_idx, h in enumerate(tree.hinges):
            c = next((c for c in mp.coordinates if c.scene_coordinate() == h), None)
            if c is None or s.scene.item(h).shift_x or s.scene.item(h).shift_y:
                continue
            ci = mp.coordinates.index(c)
            assert np.abs(loads[3 * h_idx + 2] - c.sign * r[k, :, ci]).max() < 1e-12
