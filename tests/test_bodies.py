"""Rigid bodies on nodes: the kernel against Lagrange's equations by plain AD of T and against
finite differences, a compound pendulum against the elliptic-integral period, a free body's
centre of mass on the parabola of free fall while it spins, and bodies in scene files."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from conftest import newmark_fd
from scipy.special import ellipk

from casflex import Node, Parameter, RigidBody, Scene, SceneError, Support, assemble, dumps_scene, loads_scene
from casflex.elements.kernels import hht_kernel
from casflex.simulate import Stepping, simulate

PROPS = [2.0, 0.03, 0.15, -0.05]  # m (kg), J (kg m^2), rx, ry (m)
G = [0.3, -9.81]


def _reference(alpha: float) -> ca.Function:
    """r = M(qa) qdd + (1 + alpha)(d/dt dT/dqd - dT/dq + dV/dq) from T and V written out."""
    q, qd, qdd, qa = (ca.SX.sym(k, 3) for k in ("q", "qd", "qdd", "qa"))
    m, J, r = PROPS[0], PROPS[1], PROPS[2:]

    def com(qq):
        return qq[:2] + ca.vertcat(ca.cos(qq[2]) * r[0] - ca.sin(qq[2]) * r[1],
                                   ca.sin(qq[2]) * r[0] + ca.cos(qq[2]) * r[1])

    def T(qq, vv):
        return 0.5 * m * ca.sumsqr(ca.jtimes(com(qq), qq, vv)) + 0.5 * J * vv[2] ** 2

    dT = ca.gradient(T(q, qd), qd)
    h = ca.jtimes(dT, q, qd) - ca.gradient(T(q, qd), q)
    Ma = ca.jacobian(ca.gradient(T(qa, qd), qd), qd)
    V = -m * ca.dot(ca.DM(G), com(q))
    r_ = ca.mtimes(Ma, qdd) + (1 + alpha) * (h + ca.gradient(V, q))
    return ca.Function("ref", [q, qd, qdd, qa], [r_])


@pytest.mark.parametrize("alpha", [0.0, -0.1])
def test_body_kernel_is_lagranges_equations(alpha):
    f = hht_kernel("body", alpha, "lagrange", True)
    ref = _reference(alpha)
    rng = np.random.default_rng(2)
    c = np.array([2.0e3, 4.0e6])
    for _ in range(4):
        q, qd, qdd = rng.normal(size=3), rng.normal(size=3), rng.normal(size=3)
        qa = q + (0.0 if alpha == 0 else 1e-3 * rng.normal(size=3))
        args = [q, qd, qdd] + ([] if alpha == 0 else [qa]) + [PROPS, G, c]
        r, K = (np.array(v) for v in f(*args))
        r_ref = np.array(ref(q, qd, qdd, qa)).ravel()
        np.testing.assert_allclose(r.ravel(), r_ref, rtol=0, atol=1e-13 * np.abs(r_ref).max())  # round-off
        fd = newmark_fd(ref, q, qd, qdd, qa, c, alpha)
        # central differences: truncation ~e^2 and round-off eps |r| / e ~ 1e-10 |K|
        np.testing.assert_allclose(K, fd, rtol=0, atol=1e-7 * np.abs(K).max())


def compound_pendulum(theta0: float, d: float = 0.3, m: float = 1.5, J: float = 0.02) -> Scene:
    """A body hanging from a pinned node, its centre of mass d below the pin, turned by theta0."""
    return Scene(name="compound", nodes=(Node("pin", 0.0, 0.0, theta=theta0),),
                 bodies=(RigidBody("bob", "pin", mass=m, inertia=J, com_x=d * math.sin(theta0),
                                   com_y=-d * math.cos(theta0)),),
                 supports=(Support("hinge", "pin", "pin"),))


def test_compound_pendulum_period_against_the_elliptic_integral():
    th0, d, m, J = 1.0, 0.3, 1.5, 0.02
    tr = simulate(assemble(compound_pendulum(th0, d, m, J)), 3.0, stepping=Stepping(dt=1e-4, alpha=0.0))
    assert tr.success
    th = tr.q[:, 2]
    s = np.flatnonzero((th[:-1] > 0) & (th[1:] <= 0))  # downward zero crossings
    tc = tr.t[s] + th[s] / (th[s] - th[s + 1]) * (tr.t[s + 1] - tr.t[s])
    period = np.diff(tc).mean()
    exact = 4 * math.sqrt((J + m * d * d) / (m * 9.81 * d)) * ellipk(math.sin(th0 / 2) ** 2)
    # HHT's period error at alpha = 0 is ~(omega dt)^2 / 12 ~ 3e-8 here; linear interpolation of the crossings ~1e-7
    assert period == pytest.approx(exact, rel=1e-6)
    assert np.abs(tr.energies["balance_error"]).max() < 1e-6 * m * 9.81 * d


def test_a_free_body_falls_on_a_parabola_while_it_spins():
    """Centre of mass 0.2 m off the node: it follows the parabola (to second order in dt) and the
    body spins at a constant rate."""
    omega, v0 = 6.0, (1.0, 2.0)
    body = RigidBody("b", "n", mass=0.7, inertia=0.01, com_x=0.2, com_y=0.0)
    # the node moves so that the centre of mass has velocity v0: v_node = v0 - omega x r
    scene = Scene(name="free", nodes=(Node("n", 0.0, 0.0, vx=v0[0], vy=v0[1] - omega * 0.2, omega=omega),),
                  bodies=(body,))
    errors = []
    for dt in (1e-3, 5e-4):
        tr = simulate(assemble(scene), 1.0, stepping=Stepping(dt=dt, alpha=0.0))
        assert tr.success
        th, t = tr.q[:, 2], tr.t
        np.testing.assert_allclose(th, omega * t, rtol=0, atol=1e-9)  # theta'' = 0: Newmark is exact
        cx, cy = tr.q[:, 0] + 0.2 * np.cos(th), tr.q[:, 1] + 0.2 * np.sin(th)
        errors.append(np.hypot(cx - (0.2 + v0[0] * t), cy - (v0[1] * t - 0.5 * 9.81 * t**2)).max())
    # the node circles the centre of mass: a second-order error of the size r omega t (omega dt)^2 / 12
    # (3.6e-6 m at dt = 1e-3; measured 4.2e-6 m)
    assert errors[0] < 5e-6
    assert 1.9 < math.log2(errors[0] / errors[1]) < 2.1


def test_bodies_in_scene_files_and_as_parameters():
    scene = compound_pendulum(0.5)
    text = dumps_scene(scene)
    assert "[[bodies]]" in text and loads_scene(text) == scene
    with_p = Scene(name="p", nodes=scene.nodes, bodies=scene.bodies, supports=scene.supports,
                   parameters=(Parameter("m", "bob.mass"), Parameter("J", "bob.inertia")))
    assert assemble(with_p).n_p == 2
    with pytest.raises(SceneError, match="no numeric property 'com_z'"):
        Scene(name="p", nodes=scene.nodes, bodies=scene.bodies, supports=scene.supports,
              parameters=(Parameter("x", "bob.com_z"),))
    with pytest.raises(SceneError, match=r"rigid body 'b'.mass: must be > 0"):
        RigidBody("b", "pin", mass=0.0)
    with pytest.raises(SceneError, match=r"bodies\[0\] \(bob\).node: unknown node 'nowhere'"):
        Scene(name="p", nodes=scene.nodes, bodies=(RigidBody("bob", "nowhere", mass=1.0),))


@pytest.mark.parametrize("fields", [("com_x",), ("com_y",), ("com_x", "com_y", "mass")])
def test_a_centre_of_mass_as_a_parameter_is_the_scene_with_it_moved(fields):
    # on a node turned by 0.7 rad, the offset in the node's frame mixes com_x and com_y: the model with them as
    # parameters, at values moved off the scene's, must be the scene whose body sits at those values (to round-off)
    scene = compound_pendulum(0.7)
    with_p = Scene(name="p", nodes=scene.nodes, bodies=scene.bodies, supports=scene.supports,
                   parameters=tuple(Parameter(f, f"bob.{f}") for f in fields))
    model = assemble(with_p)
    moved = dict(zip(fields, (scene.property_value(f"bob.{f}") + d for f, d in zip(fields, (0.07, -0.04, 0.3),
                                                                                  strict=False)), strict=True))
    ref = scene
    for f, v in moved.items():
        ref = ref.with_property(f"bob.{f}", v)
    ref_model = assemble(ref)
    rng = np.random.default_rng(0)
    for _ in range(3):
        q, qd, qdd = (rng.normal(size=3) for _ in range(3))
        lam = rng.normal(size=model.n_con)
        r = np.array(model.equilibrium(q, qd, qdd, lam, 0.0, list(moved.values()))[0]).ravel()
        r_ref = np.array(ref_model.equilibrium(q, qd, qdd, lam, 0.0, [])[0]).ravel()
        np.testing.assert_allclose(r, r_ref, rtol=1e-12, atol=1e-12)
    # at the scene's own values, the scene's equations
    base = np.array([scene.property_value(f"bob.{f}") for f in fields])
    np.testing.assert_allclose(np.array(model.equilibrium(q, qd, qdd, lam, 0.0, base)[0]).ravel(),
                               np.array(assemble(scene).equilibrium(q, qd, qdd, lam, 0.0, [])[0]).ravel(),
                               rtol=1e-12, atol=1e-12)
