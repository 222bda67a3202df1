"""Statics and modes against closed-form or independently computed truths.

Every tolerance carries a one-line reason. Units SI. Reference solutions are computed here
(circle/polygon geometry, the elastica by RK4 shooting, Euler-Bernoulli frequencies, the
physical pendulum), never by casflex.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from conftest import STEEL, cantilever, pendulum, translated

import casflex
from casflex import Load, Node, Scene, Spring, TorsionSpring
from casflex.statics import ModesError, StabilityWarning, StaticsError, equilibrium, modes
from casflex.statics.problem import problem_for

E, A, I, RHO, L = STEEL["E"], STEEL["A"], STEEL["I"], STEEL["rho"], 1.0
EI = E * I
G = 9.81


def chain(n: int, beam: str = "beam", first: str = "root", last: str = "tip") -> list[str]:
    """Node names along a meshed beam, from ``first`` to ``last``."""
    return [first] + [f"{beam}.{k}" for k in range(1, n)] + [last]


def nodal(model, q: np.ndarray, names: list[str]) -> np.ndarray:
    """(x, y, theta) of the named nodes, shape (len(names), 3)."""
    return np.array([q[model.dof(f"x{nm}"):model.dof(f"x{nm}") + 3] for nm in names])


def reaction(model, lam: np.ndarray, support: str) -> np.ndarray:
    """Reaction (-lambda) of the support on its node, per fixed dof."""
    return np.array([-lam[i] for i, c in enumerate(model.constraint_names) if c.startswith(f"{support}.")])


# -- end moment: circle and circular arc ------------------------------------------------------


@pytest.mark.parametrize("n", [16, 32])
def test_end_moment_closes_the_beam_into_a_circle(n):
    # M = 2 pi EI / L: the exact beam is a full circle. Each co-rotational element carries the
    # constant moment with zero axial force, so its chord stays at L0 and the nodes form an exact
    # regular n-gon: vertex j at rho (sin 2j phi, 1 - cos 2j phi), rho = L0 / (2 sin phi),
    # phi = pi / n, node rotation 2 j phi; the tip returns exactly to the root.
    # With the default options: the full moment at once, no load steps to choose.
    M = 2 * math.pi * EI / L
    model = casflex.assemble(cantilever(n, L, E, A, I, load=(0.0, 0.0, M)))
    res = equilibrium(model)
    assert res.success and res.load_factors == (1.0,) and res.stable
    xyz = nodal(model, res.q, chain(n))
    phi, L0 = math.pi / n, L / n
    rho = L0 / (2 * math.sin(phi))
    j = np.arange(n + 1)
    polygon = np.column_stack([rho * np.sin(2 * j * phi), rho * (1 - np.cos(2 * j * phi)), 2 * j * phi])
    # Exact polygon up to the solver: measured max error 4e-15 m; 1e-9 allows for round-off
    # amplified by the slender-beam conditioning (scaled tangent condition ~1e10).
    assert np.max(np.abs(xyz - polygon)) <= 1e-9 * L
    assert np.hypot(*xyz[-1, :2]) <= 1e-9 * L  # the tip closes onto the root
    assert abs(xyz[-1, 2] - 2 * math.pi) <= 1e-9  # one full turn, no 2 pi wrap in the dof
    # Clamp reaction: the moment -M, no force (global equilibrium; round-off only).
    assert np.allclose(reaction(model, res.lam, "clamp"), [0.0, 0.0, -M], rtol=1e-9, atol=1e-9 * M / L)


def test_end_moment_arc_converges_at_second_order():
    # M L / EI = 1.5 rad: exact tip of the circular arc R (sin a, 1 - cos a), R = EI / M. The
    # discrete solution is the inscribed polygon (see above), whose tip lies on the exact chord
    # direction at distance phi / sin(phi) times the exact chord, phi = a / (2 n): the error is
    # chord * (phi / sin phi - 1) ~ chord phi^2 / 6, second order in 1/n.
    a = 1.5
    M = a * EI / L
    R = EI / M
    exact = np.array([R * math.sin(a), R * (1 - math.cos(a))])
    chord = float(np.hypot(*exact))
    errors = []
    for n in (16, 32):
        model = casflex.assemble(cantilever(n, L, E, A, I, load=(0.0, 0.0, M)))
        res = equilibrium(model)
        tip = nodal(model, res.q, ["tip"])[0]
        phi = a / (2 * n)
        polygon = chord * phi / math.sin(phi) * exact / chord
        assert np.max(np.abs(tip[:2] - polygon)) <= 1e-9 * L  # exact discrete solution, round-off only
        assert abs(tip[2] - a) <= 1e-9  # node rotation = M L / EI exactly (constant curvature)
        err = float(np.hypot(*(tip[:2] - exact)))
        assert 0 < err <= 1.01 * chord * phi**2 / 6  # the polygon error bound (1 % for the higher terms)
        errors.append(err)
    assert 3.9 <= errors[0] / errors[1] <= 4.1  # second order: halving h quarters the error


# -- tip-load elastica ---------------------------------------------------------------------------


def _shoot(alpha: float, k0: float, N: int) -> tuple[float, float, float, float]:
    """RK4 on theta'' = alpha cos(theta), x' = cos(theta), y' = sin(theta), s in [0, 1], from
    theta(0) = 0, theta'(0) = k0. Returns theta, theta', x, y at s = 1 (lengths in units of L)."""
    h = 1.0 / N
    th, k, x, y = 0.0, k0, 0.0, 0.0
    for _ in range(N):
        c1, s1 = math.cos(th), math.sin(th)
        t2, k2 = th + 0.5 * h * k, k + 0.5 * h * alpha * c1
        c2, s2 = math.cos(t2), math.sin(t2)
        t3, k3 = th + 0.5 * h * k2, k + 0.5 * h * alpha * c2
        c3, s3 = math.cos(t3), math.sin(t3)
        t4, k4 = th + h * k3, k + h * alpha * c3
        c4, s4 = math.cos(t4), math.sin(t4)
        th += h / 6 * (k + 2 * k2 + 2 * k3 + k4)
        k += h / 6 * alpha * (c1 + 2 * c2 + 2 * c3 + c4)
        x += h / 6 * (c1 + 2 * c2 + 2 * c3 + c4)
        y += h / 6 * (s1 + 2 * s2 + 2 * s3 + s4)
    return th, k, x, y


def elastica(alpha: float, N: int = 1000) -> tuple[float, float, float]:
    """Inextensible cantilever under a downward tip load, alpha = P L^2 / EI.

    Moment balance EI theta'(s) = -P (x_tip - x(s)) gives theta'' = alpha cos(theta) with
    theta(0) = 0 (clamp) and theta'(1) = 0 (free end); the secant method finds theta'(0).
    Returns (L - x_tip) / L, -y_tip / L and the tip rotation -theta(1) (rad).
    """
    k0, k1 = -alpha, -0.5 * alpha
    f0, f1 = _shoot(alpha, k0, N)[1], _shoot(alpha, k1, N)[1]
    for _ in range(50):
        k0, k1, f0 = k1, k1 - f1 * (k1 - k0) / (f1 - f0), f1
        f1 = _shoot(alpha, k1, N)[1]
        if abs(f1) < 1e-14 * alpha:
            break
    th, _, x, y = _shoot(alpha, k1, N)
    return 1.0 - x, -y, -th


def test_elastica_reference_is_converged_and_matches_the_literature():
    ref = np.array(elastica(1.0))
    # RK4 with h = 1e-3 is converged: doubling N changes nothing beyond 1e-12 (measured 5e-15).
    assert np.max(np.abs(ref - np.array(elastica(1.0, 2000)))) <= 1e-12
    # Bisshopp & Drucker (1945) for P L^2/EI = 1: 0.05643, 0.30172, 0.46135 rad (5 digits).
    assert np.allclose(ref, [0.05643, 0.30172, 0.46135], atol=1e-5)


@pytest.mark.parametrize("alpha", [1.0, 2.0])
def test_tip_load_elastica(alpha):
    # A deep section (A L^2 / I = 1e8) makes the axial stretch (~ alpha I / (A L^2) = 1e-8)
    # negligible next to the discretisation error, so the inextensible elastica is the truth.
    A_deep = 0.1
    ref = np.array(elastica(alpha))
    got = {}
    for n in (8, 16):
        model = casflex.assemble(cantilever(n, L, E, A_deep, I, load=(0.0, -alpha * EI / L**2, 0.0)))
        res = equilibrium(model)
        x, y, th = nodal(model, res.q, ["tip"])[0]
        got[n] = np.array([1 - x / L, -y / L, -th])
    e8, e16 = np.abs(got[8] - ref), np.abs(got[16] - ref)
    # Co-rotational discretisation error, second order: measured 1.6e-4 (alpha = 2) at n = 16.
    assert np.max(e16) <= 3e-4
    assert np.all((e8 / e16 > 3.5) & (e8 / e16 < 4.5))  # O(h^2): measured ratios 3.9-4.0
    # Richardson extrapolation removes the h^2 term, leaving O(h^4): measured 2.3e-7 (alpha = 1)
    # and 1.3e-6 (alpha = 2), i.e. the mesh converges to the exact elastica, not to something nearby.
    assert np.max(np.abs((4 * got[16] - got[8]) / 3 - ref)) <= 3e-6


def test_small_tip_load_is_linear_beam_theory():
    # P L^2 / EI = 1e-6: geometric nonlinearity is O(1e-12) relative and cubic Hermite elements
    # are nodally exact for a tip load, so deflection P L^3 / 3EI and rotation P L^2 / 2EI hold
    # to round-off (measured 1e-13); checked to 1e-6 relative as asked.
    P = 1e-6 * EI / L**2
    for n in (1, 4):
        model = casflex.assemble(cantilever(n, L, E, A, I, load=(0.0, -P, 0.0)))
        x, y, th = nodal(model, equilibrium(model).q, ["tip"])[0]
        assert y == pytest.approx(-P * L**3 / (3 * EI), rel=1e-6)
        assert th == pytest.approx(-P * L**2 / (2 * EI), rel=1e-6)


@pytest.mark.parametrize(("E_", "L_"), [(1e-2, 1e-2), (1e-2, 1e2), (1e15, 1e-2), (1e15, 1e2)])
def test_convergence_test_is_scale_invariant(E_, L_):
    # Element stiffnesses EA/L0 from 1e-7 to 1e14 N/m, EI/L^3 from 1e-13 to 1e8 N/m: the same
    # dimensionless elastica (P L^2/EI = 1) must give the same normalised tip and the same
    # Newton path as the steel reference; differences are round-off (measured 3e-16).
    def solve(E_, L_):
        A_, I_ = A * L_**2, I * L_**4
        model = casflex.assemble(cantilever(8, L_, E_, A_, I_, load=(0.0, -E_ * I_ / L_**2, 0.0)))
        res = equilibrium(model)
        return nodal(model, res.q, ["tip"])[0] / [L_, L_, 1.0], res.iterations

    tip, its = solve(E_, L_)
    tip_ref, its_ref = solve(E, L)
    assert np.max(np.abs(tip - tip_ref)) <= 1e-10
    assert abs(its - its_ref) <= 1


# -- modes: clamped-free beam ------------------------------------------------------------------

BETA_L = np.array([1.875104068711961, 4.694091132974175, 7.854757438237613, 10.995540734875467])


def _split_modes(res) -> tuple[np.ndarray, np.ndarray]:
    """Bending and axial frequencies, by the share of x in the translational mode shape."""
    S = res.shapes
    sx = np.sum(S[0::3] ** 2, axis=0)
    sy = np.sum(S[1::3] ** 2, axis=0)
    axial = sx / (sx + sy) > 0.5
    return res.freq_hz[~axial], res.freq_hz[axial]


def test_cantilever_frequencies_euler_bernoulli():
    f_bend = BETA_L**2 / (2 * math.pi * L**2) * math.sqrt(EI / (RHO * A))
    k_ax = (2 * np.arange(1, 3) - 1) * math.pi / (2 * L)  # axial wavenumbers (1/m)
    f_ax = k_ax / (2 * math.pi) * math.sqrt(E / RHO)  # = (2k - 1) / (4 L) sqrt(E / rho)
    err = {}
    for n in (16, 32):
        res = modes(casflex.assemble(cantilever(n, L, E, A, I, RHO)))
        bend, ax = _split_modes(res)
        h = L / n
        eb = bend[:4] / f_bend - 1
        ea = ax[:2] / f_ax - 1
        # Consistent mass is Rayleigh-Ritz: frequencies converge from above. Hermite cubics
        # with consistent mass err by (beta h)^4 / 1440 to leading order (measured 0.976-1.002
        # of it); 5 % covers the higher-order terms.
        assert np.all(eb > 0)
        assert np.all(eb <= 1.05 * (BETA_L / L * h) ** 4 / 1440)
        # Linear bar elements with consistent mass: (k h)^2 / 24 (measured 1.000-1.001 of it).
        assert np.all(ea > 0)
        assert np.all(ea <= 1.05 * (k_ax * h) ** 2 / 24)
        err[n] = eb
    assert np.all((err[16] / err[32] > 14) & (err[16] / err[32] < 17))  # O(h^4): ratio -> 16
    # n = 16 accuracy in absolute terms (measured 1.3e-7, 5.1e-6, 4.0e-5, 1.5e-4):
    assert np.all(err[16] <= [2e-7, 6e-6, 5e-5, 2e-4])


def test_mode_shapes_are_mass_normalised_and_admissible():
    model = casflex.assemble(casflex.load_scene("twobar"))
    st = equilibrium(model)
    res = modes(model, q=st.q, count=5)
    M = np.asarray(model.mass(st.q, model.p_nominal))
    _, B = model.constraint(st.q)
    assert res.shapes.shape == (model.n_dof, 5) and res.dof_names == model.dof_names
    assert np.allclose(res.shapes.T @ M @ res.shapes, np.eye(5), atol=1e-9)  # round-off of eigh
    assert np.max(np.abs(np.asarray(B) @ res.shapes)) <= 1e-12  # exactly in the null space of B
    assert np.all(np.diff(res.freq_hz) > 0) and res.freq_hz[0] > 0  # ascending, stable hanging chain
    assert np.allclose(res.omega, 2 * math.pi * res.freq_hz, rtol=1e-15)


# -- pendulum ---------------------------------------------------------------------------------------


def _pendulum_mass(A_: float = 1e-3) -> float:
    return RHO * A_ * L


def test_hanging_rod_statics():
    # Started hanging, the rod only stretches under its own weight: tip drop rho g L^2 / (2E)
    # exactly (linear bar elements with consistent loads are nodally exact in 1-D; the
    # co-rotational stretch is exactly linear in pure extension). Measured 4e-11 relative.
    model = casflex.assemble(pendulum(8))
    res = equilibrium(model)
    x, y, th = nodal(model, res.q, ["end"])[0]
    assert y + L == pytest.approx(-RHO * G * L**2 / (2 * E), rel=1e-8)
    assert abs(x) <= 1e-12 * L and th == pytest.approx(-math.pi / 2, abs=1e-12)
    # The reaction carries the round-off of the rod's axial force, eps EA = 4.7e-8 N (measured 2.2e-8 N).
    assert np.allclose(reaction(model, res.lam, "pin"), [0.0, _pendulum_mass() * G], rtol=0.0, atol=1e-7)


@pytest.mark.parametrize("angle", [math.pi / 6, -1.0])
def test_pendulum_released_off_vertical_finds_the_hanging_equilibrium(angle):
    # Stress-free at an angle, the pin joint is a mechanism with a singular tangent: statics
    # must still reach the unique stable equilibrium, the same as from the hanging start.
    hanging = equilibrium(casflex.assemble(pendulum(8))).q
    model = casflex.assemble(pendulum(8, angle=angle))
    q = equilibrium(model).q
    xy = slice(None), slice(0, 2)
    names = chain(8, "rod", "pivot", "end")
    # Same configuration up to the solver tolerance (update <= 1e-7 L, measured 1e-16 m).
    assert np.max(np.abs(nodal(model, q, names)[xy] - nodal(model, hanging, names)[xy])) <= 1e-9 * L
    th = nodal(model, q, names)[:, 2]
    assert np.max(np.abs(np.angle(np.exp(1j * (th + math.pi / 2))))) <= 1e-9  # pointing down, mod 2 pi


def test_pendulum_mode_about_the_hanging_equilibrium():
    om_rigid = math.sqrt(_pendulum_mass() * G * (L / 2) / (_pendulum_mass() * L**2 / 3))  # sqrt(m g d / J_pivot)
    errs = []
    for I_ in (1e-7, 1e-6):
        model = casflex.assemble(pendulum(4, I=I_))
        st = equilibrium(model)
        res = modes(model, q=st.q, count=2)
        errs.append(abs(res.omega[0] / om_rigid - 1))
        assert res.omega[1] > 100 * res.omega[0]  # the rod's own (bending) modes are far above
        # About the unstressed start the same motion has no stiffness at all: the pendulum's
        # restoring stiffness is purely the geometric stiffness of the gravity preload. The start
        # is not an equilibrium (the rod has not stretched yet), and modes say so.
        with pytest.warns(StabilityWarning, match="not a static equilibrium"):
            free = modes(model, count=1)
        assert abs(free.omega[0]) <= 1e-2 * om_rigid  # measured 4e-4 of it
    # The rod is not rigid: flexural coupling (order rho A g L^3 / EI ~ 4e-3 for I = 1e-7) and
    # stretch (rho g L / E ~ 4e-7) lower the frequency slightly; measured 2.3e-6.
    assert errs[0] <= 1e-5
    assert errs[1] < errs[0] / 4  # and it shrinks for a stiffer rod (measured 3.6e-7)


def test_pendulum_above_horizontal_hangs_by_default_and_nearest_finds_the_inverted_one():
    # From 2 rad off vertical the stable equilibrium (hanging) is found by default: the total
    # potential is minimised. Plain Newton (seek="nearest") converges to the nearest equilibrium,
    # the inverted one; the result says it is unstable, warns, and modes flag it with
    # omega = -sqrt(m g d / J) (measured 2e-6 off).
    model = casflex.assemble(pendulum(4, angle=2.0))
    st = equilibrium(model)
    x, y, _ = nodal(model, st.q, ["end"])[0]
    assert st.stable and abs(x) <= 1e-9 * L and y == pytest.approx(-L, rel=1e-5)  # stretch is 1.8e-7 L
    with pytest.warns(StabilityWarning, match="UNSTABLE"):
        st = equilibrium(model, seek="nearest")
    x, y, _ = nodal(model, st.q, ["end"])[0]
    assert abs(x) <= 1e-9 * L and y == pytest.approx(L, rel=1e-5)
    assert not st.stable and st.stability.negative == 1
    res = modes(model, q=st.q, count=1)
    assert res.omega[0] == pytest.approx(-math.sqrt(1.5 * G / L), rel=1e-5)


def test_pendulum_pushed_sideways():
    # A horizontal end force F: a rigid rod would hang at tan(phi) = 2 F / (m g); the stiff rod
    # bends by a relative ~ m g L^2 / (E I) * 1e-2 (measured 5.6e-5), hence 1e-3. Started from
    # the stressed hanging equilibrium, whose tension gives the tangent its pendulum stiffness.
    F = 10.0
    hanging = equilibrium(casflex.assemble(pendulum(8))).q
    model = casflex.assemble(pendulum(8, load=(F, 0.0, 0.0)))
    res = equilibrium(model, steps=2, q_start=hanging)
    x, y, _ = nodal(model, res.q, ["end"])[0]
    m = _pendulum_mass()
    assert math.atan2(x, -y) == pytest.approx(math.atan(2 * F / (m * G)), rel=1e-3)
    # Global force balance: the internal forces sum to zero in any configuration (translation
    # invariance), so the reactions balance the loads up to the sum of what the free rows leave
    # unbalanced at the converged state (measured 3e-9 and 6e-9 N; 1e-10 of the reaction was one
    # machine's last digits). That sum cancels to the round-off of adding ~30 internal-force terms
    # of ~80 N (30 eps 80 N = 5e-13 N; measured 2e-14), hence 1e-11 N.
    r = np.array(problem_for(model).residual(res.q, res.lam, 1.0, 0.0, model.p_nominal)[0]).ravel()[:model.n_dof]
    unbalanced = [sum(r[i] for i, d in enumerate(model.dof_names) if d.startswith(k)) for k in ("x", "y")]
    assert np.allclose(reaction(model, res.lam, "pin") - [-F, m * G], np.negative(unbalanced), rtol=0, atol=1e-11)


# -- error paths -----------------------------------------------------------------------------------


def test_statics_error_flags_a_singular_tangent():
    # No supports and a net load: no equilibrium exists; the tangent has rigid-body null space.
    sc = cantilever(2, load=(0.0, -1.0, 0.0))
    sc = dataclasses.replace(sc, supports=())
    with pytest.raises(StaticsError, match="singular"):
        equilibrium(casflex.assemble(sc))


def test_argument_errors():
    model = casflex.assemble(cantilever(2))
    with pytest.raises(ValueError, match="steps"):
        equilibrium(model, steps=0)
    with pytest.raises(ValueError, match="q_start"):
        equilibrium(model, q_start=np.zeros(2))
    with pytest.raises(ValueError, match="count"):
        modes(model, count=100)


def test_modes_error_names_massless_dofs():
    # Node "m" hangs on massless springs only: no inertia, the eigenproblem is singular.
    sc = cantilever(2)
    sc = Scene(
        name="massless", nodes=sc.nodes + (Node("m", 1.5, 0.0),), beams=sc.beams, supports=sc.supports,
        springs=(Spring("s", ("tip", "m"), k=100.0),), torsion_springs=(TorsionSpring("t", ("tip", "m"), kt=1.0),),
        gravity=(0.0, 0.0),
    )
    with pytest.raises(ModesError, match=r"\['xm', 'ym', 'thetam'\]"):
        modes(casflex.assemble(sc))


def test_loads_and_parameters_are_used():
    # A declared parameter (the tip load) and p: doubling P doubles the small deflection.
    sc = cantilever(2, load=(0.0, -1e-3, 0.0))
    sc = dataclasses.replace(sc, loads=(Load("tipload", "tip", fy=-1e-3),),
                             parameters=(casflex.Parameter("P", "tipload.fy", lower=-1.0, upper=0.0),))
    model = casflex.assemble(sc)
    y1 = equilibrium(model).q[model.dof("ytip")]
    y2 = equilibrium(model, p={"P": -2e-3}).q[model.dof("ytip")]
    assert y1 == pytest.approx(-1e-3 * L**3 / (3 * EI), rel=1e-9)  # linear regime, round-off
    assert y2 == pytest.approx(2 * y1, rel=1e-9)


def test_a_scene_far_from_the_origin_reaches_equilibrium():
    # 1000 km away the residual's round-off (~eps 1e6 / l) is above tol = 1e-10: accepted at that floor
    base = casflex.load_scene("twobar")
    near = equilibrium(casflex.assemble(base))
    far = equilibrium(casflex.assemble(translated(base, 1e6)))
    dq = far.q - near.q
    dq[0::3] -= 1e6
    assert np.abs(dq).max() < 1e-8  # measured 7e-11 m; the coordinates' own round-off is 2e-10 m
