"""Element kernels: the HHT residual and tangent of one element against Lagrange's equations by
plain AD of its energies, and the tangent against finite differences along the Newmark relations."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from conftest import newmark_fd

from casflex.elements.beam import BeamElement
from casflex.elements.kernels import hht_kernel, kernel

PROPS = [0.8, -1.05, -1.0, 7.0e10, 1e-4, 1e-8, 2700.0]  # L0, offsets, E, A, I, rho (an aluminium element)
G = [0.3, -9.81]


def _reference(alpha: float, form: str, rotary: bool) -> ca.Function:
    """r = M(qa) qdd + (1 + alpha)(h + dV/dq), h from Lagrange's equations by plain AD of T."""
    q, qd, qdd, qa = (ca.SX.sym(k, 6) for k in ("q", "qd", "qdd", "qa"))
    el = BeamElement("e", *PROPS[:1], tuple(PROPS[1:3]), *PROPS[3:], rotary_inertia=rotary)
    T = el.kinetic_energy(q, qd)
    dT = ca.gradient(T, qd)
    h = ca.jtimes(dT, q, qd) - (ca.gradient(T, q) if form == "lagrange" else 0)
    Ma = ca.jacobian(ca.gradient(el.kinetic_energy(qa, qd), qd), qd)
    r = ca.mtimes(Ma, qdd) + (1 + alpha) * (h + ca.gradient(el.strain_energy(q) + el.gravity_energy(q, G), q))
    return ca.Function("ref", [q, qd, qdd, qa], [r])


def _state(rng) -> list[np.ndarray]:
    c, s = math.cos(2.2), math.sin(2.2)  # a turned, bent and stretched element
    q = np.array([0.1, 0.2, 2.2 + 1.05 + 0.05, 0.1 + 0.8 * c * 1.001, 0.2 + 0.8 * s * 1.001, 2.2 + 1.0 - 0.03])
    return [q + 1e-3 * rng.normal(size=6), rng.normal(size=6), rng.normal(size=6)]


@pytest.mark.parametrize("alpha", [0.0, -0.1])
@pytest.mark.parametrize("form", ["lagrange", "seed"])
@pytest.mark.parametrize("rotary", [False, True])
def test_beam_hht_kernel_is_lagranges_equations(alpha, form, rotary):
    f = hht_kernel("beam", alpha, form, True)
    ref = _reference(alpha, form, rotary)
    rng = np.random.default_rng(7)
    c = np.array([2.0e3, 4.0e6])  # gamma / (beta h), 1 / (beta h^2) at h = 1e-3
    for _ in range(4):
        q, qd, qdd = _state(rng)
        qa = q + (0.0 if alpha == 0 else 1e-3 * rng.normal(size=6))
        props = [*PROPS, 1.0 if rotary else 0.0]
        args = [q, qd, qdd] + ([] if alpha == 0 else [qa]) + [props, G, c]
        r, K = (np.array(v) for v in f(*args))
        r_ref = np.array(ref(q, qd, qdd, qa)).ravel()
        # the same numbers computed in another order: round-off of the largest term (EA/L0 ~ 1e7 N/m)
        np.testing.assert_allclose(r.ravel(), r_ref, rtol=0, atol=1e-12 * np.abs(r_ref).max())
        # K = dr/dq along the Newmark relations: dqd/dq = c0, dqdd/dq = c1, dqa/dq = 1 + alpha
        fd = newmark_fd(ref, q, qd, qdd, qa, c, alpha)
        # central differences: truncation ~e^2 r''' and round-off eps |r| / e ~ 1e-10 |K|
        np.testing.assert_allclose(K, fd, rtol=0, atol=1e-7 * np.abs(K).max())


def test_model_kernels_agree_with_the_element():
    rng = np.random.default_rng(3)
    q, qd, _ = _state(rng)
    el = BeamElement("e", *PROPS[:1], tuple(PROPS[1:3]), *PROPS[3:])
    props = [*PROPS, 0.0]
    T, V, Vg = (float(v) for v in kernel("beam", "energy")(q, qd, props, G))
    qs = ca.SX.sym("q", 6)
    assert T == pytest.approx(float(ca.Function("T", [qs], [el.kinetic_energy(qs, ca.DM(qd))])(q)), rel=1e-14)
    assert V == pytest.approx(float(ca.Function("V", [qs], [el.strain_energy(qs)])(q)), rel=1e-14)
    assert Vg == pytest.approx(float(ca.Function("Vg", [qs], [el.gravity_energy(qs, G)])(q)), rel=1e-14)


@pytest.mark.parametrize("kind", ["beam", "spring", "torsion"])
def test_padded_hht_kernel_is_the_kernel_with_0_and_1_after_K(kind):
    """The padded tangent kernel (its map's output holds the constants the band assembly gathers): vec(K), 0, 1,
    bitwise the unpadded kernel's K and r."""
    f, fp = hht_kernel(kind, -0.1, "lagrange", True), hht_kernel(kind, -0.1, "lagrange", True, True)
    rng = np.random.default_rng(5)
    args = [rng.normal(size=f.size_in(i)) for i in range(f.n_in())]
    (r, K), (rp, Kp) = f(*args), fp(*args)
    assert np.array_equal(np.array(rp), np.array(r))
    assert np.array_equal(np.array(Kp).ravel(), np.concatenate([np.array(K).ravel(order="F"), [0.0, 1.0]]))
