"""Springs and dampers whose ends are points off their nodes (``point_a``, ``point_b``): the
kernels' tangents against finite differences, a body hung by a stiff bushing at a point off its
node against the compound pendulum's elliptic-integral period, the energy balance with an
off-node damper, and the scene fields' checks."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import newmark_fd
from scipy.special import ellipk

from casflex import Node, RigidBody, Scene, SceneError, Spring, Support, assemble
from casflex.elements.kernels import AT_POINTS, KINDS, hht_kernel
from casflex.scene.io import dumps_scene, loads_scene
from casflex.simulate import Stepping, simulate

PLAIN_PROPS = {"spring": [40.0, 0.3], "spring0": [40.0], "damper": [3.0], "damper0": [3.0]}


@pytest.mark.parametrize("kind", list(AT_POINTS.values()))
def test_kernel_tangent_against_finite_differences(kind):
    f = hht_kernel(kind, -0.1, "lagrange", True)
    assert KINDS[kind].n_dof == 6
    rng = np.random.default_rng(3)
    q = np.array([0.1, -0.2, 0.7, 0.4, 0.5, -0.3]) + 1e-2 * rng.normal(size=6)
    qd, qdd = rng.normal(size=6), rng.normal(size=6)
    c = np.array([2.0e3, 4.0e6])
    plain = next(k for k, o in AT_POINTS.items() if o == kind)
    props = PLAIN_PROPS[plain] + [0.12, -0.05, -0.2, 0.07]  # offsets of the two points in their nodes' frames
    g = [0.0, -9.81]
    r, Kt = (np.array(v) for v in f(q, qd, qdd, q, props, g, c))
    fd = newmark_fd(lambda *x: f(*x, props, g, c)[0], q, qd, qdd, q, c, -0.1)
    np.testing.assert_allclose(Kt, fd, rtol=0, atol=1e-7 * np.abs(Kt).max())  # central differences: ~1e-10 |K|
    assert np.abs(r[[2, 5]]).max() > 0  # the points' forces turn the nodes


def hung_body(theta0: float, d: float, m: float, J: float, k: float, c: float = 0.0) -> Scene:
    """A body whose node sits at its centre of mass, hung from a fixed node by a zero-length bushing
    (stiffness k) at a point d from its centre: a compound pendulum turned by theta0."""
    x, y = d * math.sin(theta0), -d * math.cos(theta0)
    return Scene(name="hung", nodes=(Node("o", 0.0, 0.0), Node("b", x, y, theta=theta0)),
                 springs=(Spring("pin", ("o", "b"), k=k, rest_length=0.0, c=c, point_b=(0.0, 0.0)),),
                 bodies=(RigidBody("body", "b", mass=m, inertia=J),), supports=(Support("o", "o"),))


def test_body_hung_at_a_point_swings_as_a_compound_pendulum():
    th0, d, m, J, k = 1.0, 0.3, 1.5, 0.02, 1e9
    model = assemble(hung_body(th0, d, m, J, k))
    assert {g.kind for g in model.groups} == {"ospring0", "body"}
    tr = simulate(model, 1.75, stepping=Stepping(dt=2e-4, alpha=0.0, compiled=False))  # two downward crossings
    assert tr.success
    th = tr.q[:, model.dof("thetab")]
    s = np.flatnonzero((th[:-1] > 0) & (th[1:] <= 0))  # downward zero crossings
    tc = tr.t[s] + th[s] / (th[s] - th[s + 1]) * (tr.t[s + 1] - tr.t[s])
    exact = 4 * math.sqrt((J + m * d * d) / (m * 9.81 * d)) * ellipk(math.sin(th0 / 2) ** 2)
    # the bushing stretches by ~3 m g / k = 4e-8 m (3e-7 of d at the bottom of the swing); HHT's period
    # error at alpha = 0 ~(omega dt)^2 / 12 ~ 7e-8; the crossings' interpolation ~1e-7
    assert np.diff(tc).mean() == pytest.approx(exact, rel=2e-6)


def test_body_at_rest_on_a_point_hangs_on_its_weight():
    m, d, k = 1.5, 0.3, 1e6
    stretch = m * 9.81 / k  # the bushing's static stretch (m)
    scene = hung_body(0.0, d + stretch, m, 0.02, k)
    scene = Scene(name="rest", nodes=scene.nodes, bodies=scene.bodies, supports=scene.supports,
                  springs=(Spring("pin", ("o", "b"), k=k, rest_length=0.0, point_b=(0.0, -stretch)),))
    tr = simulate(assemble(scene), 0.05, stepping=Stepping(dt=1e-3))
    assert np.abs(tr.q - tr.q[0]).max() < 1e-12  # m: at rest from the start
    assert tr.output("pin.fy")[-1] == pytest.approx(m * 9.81, rel=1e-9)  # N, on the body: up
    assert tr.output("pin.length")[-1] == pytest.approx(stretch, rel=1e-9)


def test_energy_balance_with_a_damper_at_a_point():
    """E(t) - E(0) + W_dampers = O(dt^2) at alpha = 0, the damper taking a finite share."""
    scene = hung_body(0.6, 0.25, 1.0, 0.01, k=2e3, c=2.0)  # a soft bushing: its damper works

    def balance(dt: float):
        tr = simulate(assemble(scene), 0.5, stepping=Stepping(dt=dt, alpha=0.0, compiled=False))
        assert tr.success
        return np.abs(tr.energies["balance_error"]).max(), tr.energies["work_dampers"]

    (err1, _), (err2, wd) = balance(2e-4), balance(1e-4)
    assert wd[-1] > 0.01 and np.all(np.diff(wd) >= -1e-15)  # J: dissipated, never given back
    assert err2 < 1e-3 * wd[-1]
    assert 3.0 < err1 / err2 < 5.0, (err1, err2)  # second order: 4


def test_points_in_scene_files_and_their_checks():
    scene = hung_body(0.3, 0.2, 1.0, 0.01, k=1e5)
    assert loads_scene(dumps_scene(scene)) == scene
    assert "point_b = [0.0, 0.0]" in dumps_scene(scene)
    with pytest.raises(SceneError, match=r"spring 'pin'\.point_a: expected \[x, y\] in m"):
        Spring("pin", ("o", "b"), k=1.0, point_a=(1.0,))
    with pytest.raises(SceneError, match=r"springs\[0\] \(pin\)\.nodes: its ends coincide"):
        Scene(name="x", nodes=(Node("o", 0.0, 0.0), Node("b", 1.0, 0.0)),
              springs=(Spring("pin", ("o", "b"), k=1.0, point_b=(0.0, 0.0)),))
    # a point on its node is the plain spring
    plain = Scene(name="x", nodes=(Node("o", 0.0, 0.0), Node("b", 1.0, 0.0)), springs=(Spring("s", ("o", "b"), k=1.0),),
                  supports=(Support("o", "o"), Support("t", "b", "theta")))
    assert [g.kind for g in assemble(plain).groups] == ["spring"]
