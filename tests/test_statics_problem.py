"""The statics problem (casflex.statics.problem) and the trust-region step (casflex.statics.solve):
Functions built once per model, the assumptions checked, the exact subproblem solution."""

from __future__ import annotations

import dataclasses
import gc
import math
import weakref

import casadi as ca
import numpy as np
import pytest
from conftest import cantilever

import casflex
from casflex.statics import StaticsError, equilibrium, problem_for
from casflex.statics import problem as problem_module
from casflex.statics.problem import Scaled
from casflex.statics.solve import trust_step


def test_functions_are_built_once_per_model_and_freed_with_it(monkeypatch):
    built = []
    init = problem_module.StaticProblem.__init__

    def counting(self, model):
        built.append(model.scene.name)
        init(self, model)

    monkeypatch.setattr(problem_module.StaticProblem, "__init__", counting)
    model = casflex.assemble(cantilever(4, load=(0.0, -1.0, 0.0)))
    first = equilibrium(model)
    second = equilibrium(model, tol=1e-12)
    casflex.statics.modes(model, q=first.q)
    assert built == ["cantilever"] and problem_for(model) is problem_for(model)
    assert np.max(np.abs(first.q - second.q)) <= 1e-12  # same problem, tighter tol: same answer (round-off)
    assert model in problem_module._PROBLEMS
    alive = weakref.ref(model)  # (not the cache's length: other tests' garbage leaves it when the collector runs)
    del model, first, second
    gc.collect()
    assert alive() is None  # the cache does not keep models alive


def test_the_functions_are_named_and_exact():
    model = casflex.assemble(cantilever(3, load=(1.0, -2.0, 0.5), gravity=(0.0, -9.81)))
    prob = problem_for(model)
    assert prob.potential.name() == "statics_potential" and prob.tangent.name() == "statics_tangent"
    assert list(prob.potential.name_in()) == ["q", "factor", "t", "p"]
    assert prob.residual.name() == "statics_residual"
    q = model.q0 + 1e-3 * np.sin(np.arange(model.n_dof))
    s = 0.7
    pi, grad, load, _ = prob.evaluate(q, s, 0.0, model.p_nominal)
    # The gradient is the model's static residual f_int - s (f_ext + g): the same derivatives of the
    # same energies, equal to round-off (measured 5e-19 relative).
    _, f_int, g = (np.asarray(v).ravel() for v in model.forces(q, np.zeros(model.n_dof), model.p_nominal))
    f_ext = np.asarray(model.load(0.0, model.p_nominal)).ravel()
    assert np.max(np.abs(grad - (f_int - s * (f_ext + g)))) <= 1e-12 * np.abs(f_int).max()
    assert np.allclose(load, f_ext + g, rtol=1e-12, atol=1e-12)  # measured: equal
    # The general residual's force rows agree with the gradient for lam = 0 (measured: equal).
    r, _ = prob.residual(q, np.zeros(model.n_con), s, 0.0, model.p_nominal)
    assert np.allclose(np.asarray(r).ravel()[:model.n_dof], grad, rtol=1e-12, atol=1e-12 * np.abs(grad).max())
    # The tangent is the derivative of the gradient: central differences with h = 1e-6 err by
    # O(h^2) truncation plus eps |grad| / h round-off, ~1e-10 of max|K|; measured 1e-11.
    K = prob.hessian(q, s, 0.0, model.p_nominal)
    h = 1e-6
    for i in (0, 4, model.n_dof - 1):
        dq = np.zeros(model.n_dof)
        dq[i] = h
        fd = (prob.evaluate(q + dq, s, 0.0, model.p_nominal)[1] - prob.evaluate(q - dq, s, 0.0, model.p_nominal)[1])
        assert np.max(np.abs(K[:, i] - fd / (2 * h))) <= 1e-9 * np.abs(K).max()


def test_models_breaking_the_assumptions_are_refused():
    model = casflex.assemble(cantilever(2))

    @dataclasses.dataclass(frozen=True)
    class Hinge:  # a constraint that is not a fixed dof
        name: str = "hinge"
        dof: int = 0

    odd = dataclasses.replace(model, constraints=(Hinge(),))
    with pytest.raises(StaticsError, match="fix dofs.*'hinge' is a Hinge"):
        problem_for(odd)
    q, t, p = ca.SX.sym("q", model.n_dof), ca.SX.sym("t"), ca.SX.sym("p", 0)
    follower = ca.Function("load", [q, t, p], [ca.SX.zeros(model.n_dof)], ["q", "t", "p"], ["f_ext"])
    with pytest.raises(StaticsError, match="conservative loads"):
        problem_for(dataclasses.replace(model, load=follower))


def test_scaling_is_invariant_under_a_rotation_of_the_scene():
    # The residual scale averages x and y per node: a cantilever along x and one along y see the
    # same scaled problem (same diagonal, same residual), to round-off (measured: equal).
    a = Scaled(problem_for(m := casflex.assemble(cantilever(4))), m.p_nominal, 0.0, m.q0)
    b = Scaled(problem_for(n := casflex.assemble(cantilever(4, angle=math.pi / 2))), n.p_nominal, 0.0, n.q0)
    assert np.allclose(a.d, b.d, rtol=1e-14, atol=0.0)


# -- the trust-region subproblem ---------------------------------------------------------------


def model_value(lam, gam, y):
    return float(gam @ y + 0.5 * np.sum(lam * y**2))


def brute_force(lam, gam, radius, n=200001):
    """Minimum of the model on the boundary circle |y| = radius (2 dofs), by dense sampling."""
    phi = np.linspace(0.0, 2 * np.pi, n)
    y = radius * np.stack([np.cos(phi), np.sin(phi)])
    vals = gam @ y + 0.5 * (lam[:, None] * y**2).sum(axis=0)
    return float(vals.min())


def test_trust_step_interior_newton_step():
    lam, gam = np.array([1.0, 4.0]), np.array([-0.1, 0.2])
    y, mu = trust_step(lam, gam, 1.0, 1e-15)
    assert mu == 0.0 and np.allclose(y, -gam / lam, rtol=1e-15)  # the same division


@pytest.mark.parametrize("lam, gam", [
    (np.array([1.0, 4.0]), np.array([-3.0, 2.0])),  # convex, Newton step outside
    (np.array([-2.0, 3.0]), np.array([0.5, -1.0])),  # indefinite
    (np.array([-2.0, 3.0]), np.array([0.0, -1.0])),  # hard case: g orthogonal to the lowest mode
    (np.array([-2.0, 3.0]), np.array([1e-17, 1e-17])),  # a saddle, stationary to round-off
    (np.array([0.0, 3.0]), np.array([1.0, 0.0])),  # a mechanism pushed along its free motion
])
def test_trust_step_on_the_boundary_is_the_global_minimum(lam, gam):
    radius = 0.5
    y, mu = trust_step(lam, gam, radius, 1e-15)
    assert np.linalg.norm(y) == pytest.approx(radius, rel=1e-10)  # the secular equation is solved to 1e-12
    assert mu >= max(0.0, -lam[0]) - 1e-12  # H + mu I is positive semidefinite
    # Optimality: no point of the boundary is lower (2e5 samples: spacing 1.6e-5 on the circle, value
    # resolved to ~ max|lam| spacing^2 / 2 ~ 1e-9).
    assert model_value(lam, gam, y) <= brute_force(lam, gam, radius) + 1e-9
