"""The NLP transcription's pieces (casflex.identification.shooting_*): the interval Function mapped
over the intervals, the starts' Jacobians and the Gauss-Newton blocks assembled from them, checked
against CasADi differentiating the NLP's own graph; the generated code's size does not grow with
the number of intervals."""

from __future__ import annotations

import re

import casadi as ca
import numpy as np
import pytest

import casflex
from casflex.data import MeasurementSet
from casflex.identification import shooting_nlp as sn
from casflex.identification.options import Solver
from casflex.identification.shooting_intervals import Transcription
from casflex.identification.shooting_starts import slow_start_functions
from casflex.simulate import simulated_set


@pytest.fixture(scope="module")
def twobar():
    return casflex.assemble(casflex.load_scene("twobar"))


@pytest.fixture(scope="module")
def sampled(twobar):
    """Every dof at 100 Hz (every tenth HHT step carries a sample)."""
    sim = simulated_set(twobar, t_end=0.1, tol=1e-12)
    return MeasurementSet(sim.t[::10], sim.channels, sim.q[::10], sim.qd[::10], sim.qdd[::10], None, None)


def _transcription(model, data, horizon, *, interval=None, transcription="multiple-shooting", residue="positions",
                   initial_state="scene", transform="linear", dofs=("x3", "y3", "x5", "y5"), in_c=False):
    opts = Solver(transform=transform).nlp_options("test")
    s = sn._set_up(model, data, horizon, list(dofs), (1.0, 0.5, 0.25), residue, 0.0, 1e-3, 0.8, 1e-12, opts)
    lengths, starts = sn._interval_starts(s, interval, transcription, initial_state)
    tr = Transcription(model, s.integ, s.channels, s.step_data, lengths, s.h, s.t0, s.d, starts, s.pmap, in_c)
    w0 = np.concatenate([s.pmap.theta(s.p0), *[x.xi0 for x in starts if x is not None]])
    return tr, w0


@pytest.mark.parametrize("case", [
    # unequal intervals (8, 7, ..., 7 steps), the first start estimated, log parameters
    {"interval": 7, "initial_state": "estimate", "transform": "log"},
    # one interval: single shooting on positions, velocities and accelerations
    {"transcription": "single-shooting", "residue": "full"},
])
def test_gauss_newton_blocks_are_the_derivatives_of_the_nlp(twobar, sampled, case):
    tr, w0 = _transcription(twobar, sampled, 0.05, **case)
    assert tr.M == (1 if case.get("transcription") == "single-shooting" else 7)
    w = ca.MX.sym("w", tr.n_w)
    r, g = tr.value(w)
    r = ca.vec(r)
    J = ca.jacobian(r, w)
    ref = ca.Function("ref", [w], [0.5 * ca.sumsqr(r), g, ca.mtimes(J.T, r), ca.jacobian(g, w), ca.mtimes(J.T, J)])
    w1 = w0 + 1e-3 * np.random.default_rng(1).normal(size=w0.size)
    want = [np.array(ca.densify(v)) for v in ref(w1)]
    got = [np.array(ca.densify(v)) for v in tr.gauss_newton(1.0, False)(w1)]
    for name, a, b in zip(["f", "g", "grad_f", "jac_g", "JtJ"], got, want, strict=True):
        assert a.shape == b.shape, name
        assert b.size == 0 or np.abs(a - b).max() <= 1e-9 * max(np.abs(b).max(), 1e-300), name
    # the upper triangle for IPOPT
    upper = np.array(ca.densify(tr.gauss_newton(1.0, True)(w1)[4]))
    np.testing.assert_array_equal(upper, np.triu(got[4]))
    # the single-shooting residue: the first interval's start, the intervals chained
    u = w1[:tr.n_u]
    z, Jz, X, res = sn.SingleShooting(tr.single_shooting(), tr, 1.0).evaluate(u)
    tr1, _ = _transcription(twobar, sampled, 0.05, **{**case, "transcription": "single-shooting"})
    uu = ca.MX.sym("u", tr1.n_u)
    n_o = tr1.Y.shape[0]
    keep = (tr1.data.order[:, 1] * n_o + tr1.data.order[:, 0]).tolist()  # (quantity, sample, channel)
    r1 = ca.vec(tr1.value(uu)[0])[keep]
    zr, Jr = (np.array(v) for v in ca.Function("z", [uu], [r1, ca.jacobian(r1, uu)])(u))
    np.testing.assert_allclose(z, zr.ravel(), rtol=1e-12, atol=1e-14 * np.abs(zr).max())
    assert np.abs(Jz - Jr).max() <= 1e-9 * np.abs(Jr).max()
    assert X.shape == (tr.integ.nx, 50) and res < 1e-8


def test_slow_start_jacobian_is_the_value_functions(twobar, sampled):
    tr, w0 = _transcription(twobar, sampled, 0.05, interval=10)
    s = tr.starts[2]
    value, jac = slow_start_functions(twobar, tr.integ, s.k, False)
    xi, p = ca.MX.sym("xi", s.size), ca.MX.sym("p", twobar.n_p)
    x = value(xi, p, *s.constants())
    ref = ca.Function("ref", [xi, p], [x, ca.jacobian(x, xi), ca.jacobian(x, p)])
    args = [s.xi0 + 0.1, twobar.p_nominal * 0.9]
    for a, b in zip(jac(args[0], args[1], *s.constants()), ref(*args), strict=True):
        a, b = np.array(a), np.array(b)
        assert np.abs(a - b).max() <= 1e-9 * np.abs(b).max()


def test_held_steps_keep_the_state(twobar, sampled):
    tr, _ = _transcription(twobar, sampled, 0.05, interval=7)
    integ, K = tr.integ, tr.K
    qdd, lam = integ.initial(twobar.q0, twobar.qd0, tr.t0, twobar.p_nominal)
    x0 = np.concatenate([twobar.q0, twobar.qd0, np.array(qdd).ravel(), np.array(lam).ravel()])
    t = tr.t0 + tr.h * np.arange(K)
    act = (np.arange(K) < K - 1).astype(float)
    X, res, _, _ = tr.fns.value(x0, twobar.p_nominal, act, t, tr.h, tr.d, np.zeros((4, K)), np.zeros((4, K)),
                                *[np.zeros((tr.k_max, len(tr.free))), np.zeros(len(tr.free)), np.ones(tr.k_max),
                                  np.ones(tr.k_max)])
    Xt, _ = integ.trajectory(K - 1)(x0, tr.t0, twobar.p_nominal, tr.h, tr.d)
    np.testing.assert_array_equal(np.array(X)[:, :K - 1], np.array(Xt))  # the same steps, bit for bit
    np.testing.assert_array_equal(np.array(X)[:, K - 1], np.array(Xt)[:, -1])
    assert float(res[K - 1]) == 0.0


def _body_lines(f: ca.Function, tmp_path, stem: str) -> int:
    """Lines of the generated C's function bodies (constants and sparsity patterns left out)."""
    cg = ca.CodeGenerator(f"{stem}.c")
    cg.add(f)
    cg.generate(str(tmp_path) + "/")
    text = (tmp_path / f"{stem}.c").read_text()
    return len(text[re.search(r"^/\* \S+:\(", text, re.M).start():].splitlines())


def test_generated_code_does_not_grow_with_the_intervals(twobar, sampled, tmp_path):
    # 0.04 s and 0.08 s in intervals of 10 steps: 4 and 8 intervals, the same code
    short, _ = _transcription(twobar, sampled, 0.04, interval=10, in_c=True)
    long, _ = _transcription(twobar, sampled, 0.08, interval=10, in_c=True)
    assert (short.M, long.M) == (4, 8)
    a = _body_lines(short.gauss_newton(1.0, True), tmp_path, "short")
    b = _body_lines(long.gauss_newton(1.0, True), tmp_path, "long")
    assert abs(a - b) <= 0.01 * a, (a, b)
