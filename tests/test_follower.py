"""Follower loads (a force that turns with its node): the follower cantilever against the extensible
elastica, Beck's column flutter against the continuum, the load stiffness against finite differences,
the energy balance with the power they supply, and what statics refuses."""

from __future__ import annotations

import dataclasses
import warnings

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq, fsolve

from casflex import Beam, Load, Node, Parameter, Scene, SceneError, Support, assemble
from casflex.elements.kernels import kernel
from casflex.scene.io import dumps_scene, loads_scene
from casflex.simulate import Stepping, simulate
from casflex.statics import StaticsError, critical_load, equilibrium, equilibrium_path, modes

EI, EA, MU = 1.0, 1e6, 1.0  # N m^2, N, kg/m: a unit column, L = 1 m, stiff in tension (P / EA <= 5e-6)


def column(elements: int, *, fx: float = 0.0, fy: float = 0.0, follower: bool = True, parameter: bool = False,
           ea: float = EA) -> Scene:
    """A cantilever of length 1 along x, clamped at a, with a tip load at b (node-frame components)."""
    A = ea * 1e-4 / EI  # I = 1e-4 m^4, E = EI / I
    return Scene(name="column", nodes=(Node("a", 0.0, 0.0), Node("b", 1.0, 0.0)),
                 beams=(Beam("c", ("a", "b"), E=EI / 1e-4, A=A, I=1e-4, rho=MU / A, elements=elements),),
                 supports=(Support("clamp", "a"),), loads=(Load("tip", "b", fx=fx, fy=fy, follower=follower),),
                 parameters=(Parameter("P", "tip.fx"),) if parameter else (), gravity=(0.0, 0.0))


def elastica(P: float) -> tuple[float, float, float]:
    """Tip x, y, rotation of the extensible elastica (EI, EA, L = 1) clamped along x under a follower
    force P perpendicular to its tip, by shooting on the curvature at the root and the tip angle."""
    def shoot(z):
        k0, th_l = z
        F = P * np.array([-np.sin(th_l), np.cos(th_l)])

        def rhs(s, u):
            th, k = u[2], u[3]
            stretch = 1.0 + (F @ [np.cos(th), np.sin(th)]) / EA
            return [stretch * np.cos(th), stretch * np.sin(th), k,
                    -stretch * (np.cos(th) * F[1] - np.sin(th) * F[0]) / EI]
        return solve_ivp(rhs, (0.0, 1.0), [0.0, 0.0, 0.0, k0], rtol=1e-12, atol=1e-13).y[:, -1]

    z = fsolve(lambda z: [shoot(z)[3], shoot(z)[2] - z[1]], [0.5 * P, 0.5 * P], xtol=1e-13)
    x, y, th, _ = shoot(z)
    return x, y, th


@pytest.mark.parametrize("P", [1.0, 2.0, 5.0])
def test_follower_cantilever_against_the_elastica(P):
    # issue 13: P L^2 / EI = 1, 2, 5; the tip converges at order 2 in the element length
    ref = np.array(elastica(P))
    err = []
    for n in (8, 16):
        m = assemble(column(n, fy=P))
        q = equilibrium(m, seek="nearest").q
        tip = np.array([q[m.dof("xb")], q[m.dof("yb")], q[m.dof("thetab")]])
        tip[2] = ref[2] + np.angle(np.exp(1j * (tip[2] - ref[2])))  # a node's rotation is known modulo 2 pi
        err.append(np.abs(tip - ref).max())
    assert err[1] < err[0] / 3.5, err  # order 2: a factor 4 per halving
    assert err[1] < 2e-3, err  # measured 1.3e-3 at P = 5 (rotation 2.1 rad), 2.6e-5 at P = 1


def beck_reference() -> tuple[float, float]:
    """Beck's column (1952) from the continuum: the load p = P L^2 / EI at which the first two roots
    Omega^2 = omega^2 mu L^4 / EI of the characteristic determinant merge, and that Omega."""
    def det(p, w2):
        s = np.sqrt(p * p + 4 * w2)
        a, b = np.sqrt((s - p) / 2), np.sqrt((s + p) / 2)
        return np.linalg.det([[1, 0, 1, 0], [0, a, 0, b],
                              [a * a * np.cosh(a), a * a * np.sinh(a), -b * b * np.cos(b), -b * b * np.sin(b)],
                              [a**3 * np.sinh(a), a**3 * np.cosh(a), b**3 * np.sin(b), -b**3 * np.cos(b)]])

    def roots(p, n=2000):
        w = np.linspace(1e-6, 200.0, n)
        d = np.array([det(p, x) for x in w])
        return [brentq(lambda x: det(p, x), w[i], w[i + 1]) for i in range(n - 1) if d[i] * d[i + 1] < 0]

    lo, hi = 19.0, 21.0
    while hi - lo > 1e-6:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if len(roots(mid)) >= 2 else (lo, mid)
    return lo, float(np.sqrt(np.mean(roots(lo, 20000)[:2])))


def test_becks_column_flutter_converges_to_the_continuum():
    p_ref, omega_ref = beck_reference()
    assert abs(p_ref - 20.05) < 0.01  # Beck's published 20.05
    found = []
    for n in (8, 16, 32):
        c = critical_load(assemble(column(n, fx=-1.0, parameter=True)), "P", -30.0, start=0.0, points=15)
        assert c.kind == "flutter"
        found.append((-c.value, c.omega))
    err = [abs(v - p_ref) for v, _ in found]
    assert err[1] < err[0] / 3 and err[2] < err[1] / 3, found  # order 2 (measured ratios 4.0, 3.8)
    assert err[2] < 2e-3 * p_ref, found  # measured 0.17 % at 32 elements
    assert abs(found[2][1] - omega_ref) < 2e-3 * omega_ref, (found, omega_ref)  # measured 0.08 %


def test_modes_of_a_follower_column_are_real_below_flutter_and_a_pair_above():
    m = assemble(column(8, fx=-1.0, parameter=True))
    below = modes(m, q=equilibrium(m, p={"P": -15.0}, seek="nearest").q, p={"P": -15.0}, count=3)
    above = modes(m, q=equilibrium(m, p={"P": -25.0}, seek="nearest").q, p={"P": -25.0}, count=3)
    assert not below.flutter and np.all(np.abs(below.omega2.imag) == 0.0)
    assert above.flutter and abs(above.omega2[0].imag) > 1.0 and np.isclose(above.omega2[0], above.omega2[1].conj())


def test_follower_load_stiffness_against_finite_differences():
    f = kernel("follower", "forces")
    q0, pr = np.array([0.3, -0.2, 0.7]), np.array([2.0, -3.0])
    h = lambda q: np.asarray(f(q, np.zeros(3), pr, np.zeros(2))[0]).ravel()  # noqa: E731
    x = ca.SX.sym("q", 3)
    J = np.asarray(ca.Function("j", [x], [ca.jacobian(f(x, ca.DM.zeros(3), pr, ca.DM.zeros(2))[0], x)])(q0))
    fd = np.column_stack([(h(q0 + e) - h(q0 - e)) / 2e-6 for e in 1e-6 * np.eye(3)])
    assert np.allclose(J, fd, atol=1e-8)  # central differences: error h^2 |F| ~ 1e-11
    assert np.allclose(-h(q0)[:2], [np.cos(0.7) * 2 + np.sin(0.7) * 3, np.sin(0.7) * 2 - np.cos(0.7) * 3])


def test_energy_balance_with_the_power_a_follower_load_supplies():
    # a cantilever pushed by a follower tip load (not conservative): E - E0 = W (its work), to order 2;
    # axially soft (EA = 1e3 N) so that the steps resolve every mode (highest omega dt ~ 0.4)
    scene = column(2, fy=0.5, ea=1e3)
    err = []
    for dt in (4e-3, 2e-3):
        tr = simulate(assemble(scene), 0.5, stepping=Stepping(dt=dt))
        err.append(np.abs(tr.energies["balance_error"]).max())
        assert tr.energies["work_external"][-1] > 0.09  # the load did work (0.098 J)
    assert err[0] / err[1] > 3.5, err  # at least order 2 (measured 4.9: 1.8e-5 J, then 3.8e-6 J)


def test_what_statics_refuses_with_follower_loads():
    m = assemble(column(2, fy=1.0))
    with pytest.raises(StaticsError, match="seek='nearest'"):
        equilibrium(m)
    with pytest.raises(StaticsError, match="follower loads"):
        equilibrium_path(m, seek="nearest")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no stability warning for a non-conservative equilibrium
        equilibrium(m, seek="nearest")


def test_scene_checks_and_round_trip():
    with pytest.raises(SceneError, match="follower"):
        Load("f", "b", fx=1.0, follower="yes")
    with pytest.raises(SceneError, match="not a table"):
        Load("f", "b", table=((0.0, 1.0, 0.0, 0.0),), follower=True)
    scene = column(2, fy=1.0)
    assert loads_scene(dumps_scene(scene)) == scene
    assert "follower = true" in dumps_scene(scene)
    plain = dataclasses.replace(scene, loads=(dataclasses.replace(scene.loads[0], follower=False),))
    assert [g.kind for g in assemble(plain).groups] == ["beam"]


def test_cli_reports_flutter_and_asks_for_newton(tmp_path, capsys):
    from casflex.cli import main
    from casflex.scene.io import save_scene

    path = save_scene(column(8, fx=-25.0), tmp_path / "beck.toml")  # above the flutter load 20.05
    assert main(["modes", str(path), "--about", "equilibrium", "--count", "2"]) == 2
    assert "--seek nearest" in capsys.readouterr().err
    assert main(["modes", str(path), "--about", "equilibrium", "--seek", "nearest", "--count", "2"]) == 0
    out = capsys.readouterr().out
    assert out.count("flutter: grows at") == 2 and "stability not assessed" in out
