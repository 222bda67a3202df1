"""Element and assembly checks: AD derivatives against finite differences, rigid-body
invariance, consistent mass and gravity load, and the two inertia forms.

Finite differences (FD) are central: f_i ~ (U(q + h e_i) - U(q - h e_i)) / 2h, with error
h^2 U'''/6 + eps U / h, so h ~ 1e-5 (relative to the dof's size) gives ~1e-10 relative; the
asked 1e-6 leaves a wide margin. Errors are normwise (infinity norm) relative to the AD value.
"""

from __future__ import annotations

import dataclasses
import math

import casadi as ca
import numpy as np
import pytest
from conftest import cantilever

import casflex
from casflex.elements import BeamElement, LinearSpring, TorsionalSpring

RNG_SEED = 20240607
E, A, I, RHO = 7.0e10, 1.0e-4, 1.0e-8, 2700.0  # aluminium-like (Pa, m^2, m^4, kg/m^3)
L0, BETA0 = 0.5, 0.3  # element length (m) and chord angle (rad) of the reference element
XA, YA = 0.1, 0.2
X0 = (XA, YA, XA + L0 * math.cos(BETA0), YA + L0 * math.sin(BETA0))
THETA0 = (0.4, -0.2)  # nodal rotations (rad) at which the element is stress-free
GRAV = (0.3, -9.81)  # m/s^2, deliberately not vertical
MASS = RHO * A * L0


def beam(rotary_inertia: bool = False) -> BeamElement:
    return BeamElement.between("b", X0, THETA0, E=E, A=A, I=I, rho=RHO, rotary_inertia=rotary_inertia)


def beam_functions(el: BeamElement) -> dict[str, ca.Function]:
    q, qd = ca.SX.sym("q", 6), ca.SX.sym("qd", 6)
    U = el.strain_energy(q)
    T = el.kinetic_energy(q, qd)
    Vg = el.gravity_energy(q, GRAV)
    f = ca.gradient(U, q)
    return {
        "U": ca.Function("U", [q], [U]),
        "f": ca.Function("f", [q], [f]),
        "K": ca.Function("K", [q], [ca.jacobian(f, q)]),
        "T": ca.Function("T", [q, qd], [T]),
        "M": ca.Function("M", [q], [ca.hessian(T, qd)[0]]),
        "Vg": ca.Function("Vg", [q], [Vg]),
        "g": ca.Function("g", [q], [-ca.gradient(Vg, q)]),
    }


@pytest.fixture(scope="module")
def fb():
    return beam_functions(beam())


def q_ref() -> np.ndarray:
    return np.array([X0[0], X0[1], THETA0[0], X0[2], X0[3], THETA0[1]])


def rigid(q: np.ndarray, alpha: float, shift=(0.0, 0.0), about=(0.0, 0.0)) -> np.ndarray:
    """Nodal dofs (x, y, theta per node) moved rigidly: rotation alpha about ``about``, then shift."""
    c, s = math.cos(alpha), math.sin(alpha)
    out = np.array(q, dtype=float).copy()
    for k in range(len(q) // 3):
        dx, dy = q[3 * k] - about[0], q[3 * k + 1] - about[1]
        out[3 * k] = about[0] + c * dx - s * dy + shift[0]
        out[3 * k + 1] = about[1] + s * dx + c * dy + shift[1]
        out[3 * k + 2] = q[3 * k + 2] + alpha
    return out


def bent(tha: float, thb: float, stretch: float = 0.0) -> np.ndarray:
    """The reference element deformed: local end rotations tha, thb (rad), chord stretched (m)."""
    q = q_ref()
    q[3] += stretch * math.cos(BETA0)
    q[4] += stretch * math.sin(BETA0)
    q[2] += tha
    q[5] += thb
    return q


def random_configurations(rng, count: int) -> list[np.ndarray]:
    """Large rigid motion (any angle) + moderate deformation: strain ~1e-3, local rotations ~0.3 rad."""
    out = []
    for _ in range(count):
        q = bent(*rng.uniform(-0.3, 0.3, 2), stretch=rng.uniform(-1e-3, 1e-3) * L0)
        q[[0, 1, 3, 4]] += rng.uniform(-1e-4, 1e-4, 4)  # a little extra shear of the chord
        out.append(rigid(q, rng.uniform(-2 * math.pi, 2 * math.pi), shift=rng.uniform(-1, 1, 2)))
    return out


def dof_steps(n: int, length: float) -> np.ndarray:
    """FD step per dof: 1e-5 of ``length`` (m) for translations, 1e-5 rad for rotations."""
    return np.array([1e-5 * (1.0 if i % 3 == 2 else length) for i in range(n)])


def fd_gradient(fun, x: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Central differences of a scalar (or vector) function, one column per variable."""
    cols = []
    for i in range(len(x)):
        e = np.zeros_like(x)
        e[i] = h[i]
        diff = np.asarray(fun(x + e), dtype=float) - np.asarray(fun(x - e), dtype=float)
        cols.append(diff.reshape(-1) / (2 * h[i]))
    return np.column_stack(cols)


def rel_err(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))) / np.max(np.abs(np.asarray(b))))


# -- beam element --------------------------------------------------------------------------------


def test_beam_forces_and_tangent_match_finite_differences(fb):
    rng = np.random.default_rng(RNG_SEED)
    h = dof_steps(6, L0)
    for q in random_configurations(rng, 8):
        f = np.asarray(fb["f"](q)).reshape(-1)
        assert rel_err(fd_gradient(lambda x: float(fb["U"](x)), q, h).reshape(-1), f) <= 1e-6
        K = np.asarray(fb["K"](q))
        assert rel_err(fd_gradient(lambda x: fb["f"](x), q, h), K) <= 1e-6
        assert rel_err(K, K.T) <= 1e-12  # a Hessian: symmetric to round-off
        g = np.asarray(fb["g"](q)).reshape(-1)
        assert rel_err(-fd_gradient(lambda x: float(fb["Vg"](x)), q, h).reshape(-1), g) <= 1e-6


def test_beam_mass_is_the_hessian_of_kinetic_energy(fb):
    # T is quadratic in qd: the second difference is exact up to round-off eps T / h^2 ~ 1e-12.
    rng = np.random.default_rng(RNG_SEED + 1)
    for q in random_configurations(rng, 4):
        qd = rng.normal(size=6)
        M = np.asarray(fb["M"](q))
        H = np.zeros((6, 6))
        d = 1e-2
        for i in range(6):
            for j in range(6):
                ei, ej = np.eye(6)[i] * d, np.eye(6)[j] * d
                H[i, j] = (float(fb["T"](q, qd + ei + ej)) - float(fb["T"](q, qd + ei - ej))
                           - float(fb["T"](q, qd - ei + ej)) + float(fb["T"](q, qd - ei - ej))) / (4 * d * d)
        assert rel_err(H, M) <= 1e-6
        assert float(fb["T"](q, qd)) == pytest.approx(0.5 * qd @ M @ qd, rel=1e-12)
        assert np.all(np.linalg.eigvalsh(M) > 0)  # consistent mass: positive definite


ANGLES = sorted({*np.linspace(-4 * math.pi, 4 * math.pi, 33).tolist(),
                 # the chord angle BETA0 + alpha passes +-pi (and -pi - 2 pi) here:
                 *(s * math.pi - BETA0 + e for s in (-3, -1, 1, 3) for e in (-1e-9, 0.0, 1e-9)),
                 math.pi, 2 * math.pi, -2 * math.pi})


def test_rigid_motion_is_strain_free(fb):
    # Translation + any rotation, including past pi, full turns and the chord crossing +-pi:
    # zero strain energy and internal force up to round-off (|L - L0| ~ eps L0).
    for alpha in ANGLES:
        q = rigid(q_ref(), alpha, shift=(0.7, -1.3), about=(0.25, -0.4))
        assert abs(float(fb["U"](q))) <= 1e-20 * E * A * L0  # round-off ~ EA L0 eps^2
        f = np.asarray(fb["f"](q)).reshape(-1)
        assert np.max(np.abs(f[[0, 1, 3, 4]])) <= 1e-9 * E * A  # N, as asked
        assert np.max(np.abs(f[[2, 5]])) <= 1e-9 * E * A * L0  # N m


def test_local_rotation_is_continuous_through_full_turns(fb):
    # A bent, stretched element turned rigidly through [0, 4 pi]: strain energy constant and
    # forces rotating with it (objectivity); atan2 of triad and chord means no branch jump.
    q0 = bent(0.2, -0.1, stretch=1e-4)
    U0 = float(fb["U"](q0))
    f0 = np.asarray(fb["f"](q0)).reshape(-1)
    for alpha in np.linspace(0.0, 4 * math.pi, 161):
        q = rigid(q0, alpha, about=(XA, YA))
        assert float(fb["U"](q)) == pytest.approx(U0, rel=1e-10)  # round-off in cos/sin of alpha
        c, s = math.cos(alpha), math.sin(alpha)
        R = np.kron(np.eye(2), np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]))
        assert rel_err(np.asarray(fb["f"](q)).reshape(-1), R @ f0) <= 1e-9


@pytest.mark.parametrize("rotary_inertia", [False, True])
def test_rigid_motion_kinetic_energy_is_exact(rotary_inertia):
    # Hermite interpolation reproduces rigid velocity fields, so the consistent mass gives
    # T = m v_c^2 / 2 + J_c omega^2 / 2 exactly, J_c = m L^2 / 12 (+ rho I L for the section's
    # rotary inertia); checked to round-off.
    fn = beam_functions(beam(rotary_inertia))
    rng = np.random.default_rng(RNG_SEED + 2)
    Jc = MASS * L0**2 / 12 + (RHO * I * L0 if rotary_inertia else 0.0)
    for alpha in (*rng.uniform(-2 * math.pi, 2 * math.pi, 5), math.pi - BETA0, 2 * math.pi):
        q = rigid(q_ref(), alpha, shift=rng.uniform(-1, 1, 2))
        xc, yc = 0.5 * (q[0] + q[3]), 0.5 * (q[1] + q[4])
        vc, om = rng.normal(size=2), rng.normal()
        qd = np.array([vc[0] - om * (q[1] - yc), vc[1] + om * (q[0] - xc), om,
                       vc[0] - om * (q[4] - yc), vc[1] + om * (q[3] - xc), om])
        assert float(fn["T"](q, qd)) == pytest.approx(0.5 * MASS * vc @ vc + 0.5 * Jc * om**2, rel=1e-12)


def test_consistent_gravity_load_on_a_horizontal_beam():
    # Uniform weight w = m g / L on a straight horizontal element: end forces m g / 2 and end
    # moments -/+ m g L / 12 (the consistent load of Hermite cubics), exactly.
    el = BeamElement.between("h", (0.0, 0.0, L0, 0.0), (0.0, 0.0), E=E, A=A, I=I, rho=RHO)
    q = ca.SX.sym("q", 6)
    g = ca.Function("g", [q], [-ca.gradient(el.gravity_energy(q, (0.0, -9.81)), q)])
    w = MASS * 9.81
    expected = [0.0, -w / 2, -w * L0 / 12, 0.0, -w / 2, w * L0 / 12]
    assert np.allclose(np.asarray(g([0.0, 0.0, 0.0, L0, 0.0, 0.0])).reshape(-1), expected, rtol=1e-14, atol=1e-14 * w)
    # The same through the assembled model (one-element cantilever under gravity).
    model = casflex.assemble(cantilever(1, L0, E, A, I, RHO, gravity=(0.0, -9.81)))
    _, _, gm = model.forces(model.q0, np.zeros(6), model.p_nominal)
    assert np.allclose(np.asarray(gm).reshape(-1), expected, rtol=1e-14, atol=1e-14 * w)


# -- springs -------------------------------------------------------------------------------------------


def spring_functions(rest: float):
    qa, qb = ca.SX.sym("qa", 3), ca.SX.sym("qb", 3)
    q = ca.vertcat(qa, qb)
    lin = LinearSpring("s", 700.0, rest)
    tor = TorsionalSpring("t", 0.5, 0.3)
    out = {}
    for key, U in (("lin", lin.strain_energy(qa, qb)), ("tor", tor.strain_energy(qa[2], qb[2]))):
        f = ca.gradient(U, q)
        out[key] = (ca.Function("U", [q], [U]), ca.Function("f", [q], [f]), ca.Function("K", [q], [ca.jacobian(f, q)]))
    return out


@pytest.mark.parametrize("rest", [0.1, 0.0])
def test_springs_forces_and_tangent_match_finite_differences(rest):
    rng = np.random.default_rng(RNG_SEED + 3)
    fns = spring_functions(rest)
    h = dof_steps(6, 0.1)
    for _ in range(6):
        q = np.concatenate([rng.uniform(-0.2, 0.2, 3), rng.uniform(-0.2, 0.2, 3) + [0.12, 0.0, 0.5]])
        for U, f, K in fns.values():
            fa = np.asarray(f(q)).reshape(-1)
            assert rel_err(fd_gradient(lambda x, U=U: float(U(x)), q, h).reshape(-1), fa) <= 1e-6
            assert rel_err(fd_gradient(lambda x, f=f: f(x), q, h), np.asarray(K(q))) <= 1e-6


def test_springs_are_objective():
    # A stretched linear spring and a twisted torsion spring moved rigidly (rotations past pi):
    # the energies do not change.
    fns = spring_functions(0.1)
    q = np.array([0.0, 0.0, 0.1, 0.13, 0.02, 0.9])
    U0 = {k: float(v[0](q)) for k, v in fns.items()}
    assert U0["lin"] > 0 and U0["tor"] > 0
    for alpha in np.linspace(-3 * math.pi, 3 * math.pi, 19):
        qr = rigid(q, alpha, shift=(1.0, -2.0))
        for k, v in fns.items():
            assert float(v[0](qr)) == pytest.approx(U0[k], rel=1e-12)


# -- assembled model (twobar) ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def twobar():
    scene = casflex.load_scene("twobar")
    return casflex.assemble(scene, inertia="lagrange"), casflex.assemble(scene, inertia="seed")


def twobar_states(model, rng, count: int):
    """Random configurations about q0 (cm-size moves, 0.2 rad turns) and random velocities."""
    out = []
    for _ in range(count):
        dq = np.where(model.is_rotation, rng.uniform(-0.2, 0.2, model.n_dof), rng.uniform(-0.01, 0.01, model.n_dof))
        out.append((model.q0 + dq, rng.normal(size=model.n_dof)))
    return out


def test_twobar_forces_tangent_and_mass_match_finite_differences(twobar):
    model, _ = twobar
    p = model.p_nominal
    n = model.n_dof
    h = dof_steps(n, model.length_scale)
    zero = np.zeros(n)

    def energy(i):
        return lambda x: float(model.energy(x, zero, p)[i])

    def f_int(x):
        return model.forces(x, zero, p)[1]

    rng = np.random.default_rng(RNG_SEED + 4)
    for q, qd in twobar_states(model, rng, 3):
        _, fi, g = (np.asarray(v).reshape(-1) for v in model.forces(q, qd, p))
        assert rel_err(fd_gradient(energy(1), q, h).reshape(-1), fi) <= 1e-6
        assert rel_err(-fd_gradient(energy(2), q, h).reshape(-1), g) <= 1e-6
        Kfd = fd_gradient(f_int, q, h)
        qs = ca.SX.sym("q", n)
        K = np.asarray(ca.Function("K", [qs], [ca.jacobian(model.forces(qs, zero, p)[1], qs)])(q))
        assert rel_err(Kfd, K) <= 1e-6
        # M = d2T/dqd2: T quadratic in qd, so FD of dT/dqd = M qd along each unit vector is exact.
        M = np.asarray(model.mass(q, p))
        Mfd = fd_gradient(lambda v, q=q: fd_gradient(lambda w: float(model.energy(q, w, p)[0]), v, np.ones(n)), qd,
                          np.ones(n))
        assert rel_err(Mfd, M) <= 1e-6


def test_twobar_inertia_forms_differ_by_dT_dq(twobar):
    # lagrange: h = Mdot qd - dT/dq; seed: h = Mdot qd. Their difference is -dT/dq (FD), and the
    # seed form is Mdot qd = (d/de) M(q + e qd) qd (FD along qd).
    lag, seed = twobar
    p = lag.p_nominal
    n = lag.n_dof
    h = dof_steps(n, lag.length_scale)
    rng = np.random.default_rng(RNG_SEED + 5)
    for q, qd in twobar_states(lag, rng, 3):
        hl = np.asarray(lag.forces(q, qd, p)[0]).reshape(-1)
        hs = np.asarray(seed.forces(q, qd, p)[0]).reshape(-1)
        dT_dq = fd_gradient(lambda x, qd=qd: float(lag.energy(x, qd, p)[0]), q, h).reshape(-1)
        assert rel_err(hl - hs, -dT_dq) <= 1e-6
        e = 1e-6
        Mdot_qd = (np.asarray(lag.mass(q + e * qd, p)) - np.asarray(lag.mass(q - e * qd, p))) @ qd / (2 * e)
        assert rel_err(hs, Mdot_qd) <= 1e-6


def test_twobar_equilibrium_function_is_eq1(twobar):
    # r = M qdd + h + f_int + B^T lam - f_ext - g, assembled from the model's own pieces.
    model, _ = twobar
    p = model.p_nominal
    rng = np.random.default_rng(RNG_SEED + 6)
    for q, qd in twobar_states(model, rng, 2):
        qdd, lam, t = rng.normal(size=model.n_dof), rng.normal(size=model.n_con), 0.3
        r, phi = (np.asarray(v).reshape(-1) for v in model.equilibrium(q, qd, qdd, lam, t, p))
        hh, fi, g = (np.asarray(v).reshape(-1) for v in model.forces(q, qd, p))
        ph, B = (np.asarray(v) for v in model.constraint(q))
        fe = np.asarray(model.load(t, p)).reshape(-1)
        expected = np.asarray(model.mass(q, p)) @ qdd + hh + fi + B.T @ lam - fe - g
        assert rel_err(r, expected) <= 1e-12 and np.allclose(phi, ph.reshape(-1), rtol=0, atol=1e-15)


def test_springs_are_massless_in_the_assembly(twobar):
    # Node 1 of twobar touches only spring1 and torsion1: its rows and columns of M are zero.
    # A uniform x velocity of every node then carries exactly the two bars' mass.
    model, _ = twobar
    p = model.p_nominal
    M = np.asarray(model.mass(model.q0, p))
    node1 = [model.dof(d) for d in ("x1", "y1", "theta1")]
    assert np.all(M[node1, :] == 0.0) and np.all(M[:, node1] == 0.0)
    scene = model.scene
    m_bars = sum(b.rho * b.A * scene.distance(*b.nodes) for b in scene.beams)
    ux = np.where(np.arange(model.n_dof) % 3 == 0, 1.0, 0.0)
    assert float(model.energy(model.q0, ux, p)[0]) == pytest.approx(0.5 * m_bars, rel=1e-12)


def test_assembled_free_beam_rigid_motion_is_force_free():
    # A meshed free beam (no supports) moved rigidly, including full turns: f_int = 0.
    scene = dataclasses.replace(cantilever(4, 1.0, E, A, I, RHO, angle=2.5), supports=())
    model = casflex.assemble(scene)
    zero = np.zeros(model.n_dof)
    for alpha in (0.5, math.pi - 2.5, math.pi, 2 * math.pi, 3.7 * math.pi, -2.2 * math.pi):
        q = rigid(model.q0, alpha, shift=(0.3, 0.4), about=(0.1, -0.2))
        _, fi, _ = model.forces(q, zero, model.p_nominal)
        assert float(model.energy(q, zero, model.p_nominal)[1]) <= 1e-20 * E * A
        assert np.max(np.abs(np.asarray(fi))) <= 1e-9 * E * A  # N and N m per metre of the 1 m beam


def test_zero_length_spring_outputs_are_finite_when_nodes_coincide():
    import casflex as cf

    scene = cf.Scene(
        name="zero", nodes=(cf.Node("a", 0.0, 0.0), cf.Node("b", 0.0, 0.0)),
        springs=(cf.Spring("s", ("a", "b"), k=10.0, rest_length=0.0),),
        supports=(cf.Support("c", "a", "clamp"), cf.Support("t", "b", "theta")), gravity=(0.0, 0.0),
    )
    m = cf.assemble(scene)
    y = np.array(m.outputs(m.q0, m.qd0, np.zeros(m.n_con), m.p_nominal)).ravel()
    assert np.isfinite(y).all()
    q = m.q0.copy()
    q[3:5] = [0.3, -0.4]  # force on b is -k (xb - xa)
    y = dict(zip(m.output_names, np.array(m.outputs(q, m.qd0, np.zeros(m.n_con), m.p_nominal)).ravel(), strict=True))
    assert y["s.fx"] == pytest.approx(-3.0) and y["s.fy"] == pytest.approx(4.0) and y["s.force"] == pytest.approx(5.0)
