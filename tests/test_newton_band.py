"""The HHT step's Newton update on a mapped mesh, assembled straight into the banded LU's storage
(casflex.integrators.newton_band): Newton's update with the scaled Jacobian, whatever the scene."""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pytest

import casflex
from casflex.integrators.hht import HHT
from casflex.model.assembly import scatter, scatter_add
from casflex.simulate.run import initial_state


def _twobar(elements: int):
    scene = casflex.load_scene("twobar")
    return casflex.assemble(dataclasses.replace(scene, beams=tuple(dataclasses.replace(b, elements=elements)
                                                                  for b in scene.beams)))


@pytest.mark.parametrize("scene, alpha", [("twobar", 0.0), ("twobar", -0.1), ("slidercrank", -0.05)])
def test_the_band_update_is_newtons_update_with_the_scaled_jacobian(scene, alpha):
    """z1 = z0 - (dG/dz)^-1 G from the mapped kernels assembled into the band, unscaled, against a dense solve
    with the sparse scaled Jacobian of hht_jacobian; slidercrank has joints (multipliers solved for)."""
    model = _twobar(3) if scene == "twobar" else casflex.assemble(casflex.load_scene(scene))
    integ = HHT(model, alpha=alpha, expand=False)
    p, n, h = model.params(None), model.n_dof, 1e-3
    x0 = initial_state(integ, p)
    d = np.array(integ.scale(x0[:n], x0[n:2 * n], p, h)).ravel()
    z0, prm = integ.prepare(x0, 0.0, p, h, d)
    z = np.array(z0).ravel() + 1e-3 * np.random.default_rng(1).normal(size=z0.numel())  # off the guess
    J, G = integ._fn["jacobian"](z, prm)
    G = np.array(G).ravel()
    expected = z - np.linalg.solve(np.array(ca.densify(J)), G)
    z1, g, _ = integ._fn["update"](z, prm)
    # 1e-12: the same update up to round-off of the two eliminations (one scaled, one not), |z| ~ 1
    np.testing.assert_allclose(np.array(z1).ravel(), expected, rtol=0, atol=1e-12 * max(1.0, np.abs(expected).max()))
    assert float(g) == np.abs(G).max()  # the residual beside the band is hht_jacobian's, bitwise
    G_band, r = integ._fn["rhs"](z, prm)  # the residual alone, scaled and not: the same G
    np.testing.assert_allclose(np.array(G_band).ravel(), np.array(integ.residual(z, prm)).ravel(), rtol=0, atol=0)
    assert np.abs(np.array(r)).max() > np.abs(G).max()  # unscaled: forces in N, not scaled by M / (beta h^2)


def test_mapped_and_flat_steps_agree():
    """The step on the band (mapped) and the flat one: the same trajectory to round-off (positions)."""
    model = _twobar(3)
    p, n = model.params(None), model.n_dof
    states = []
    for expand in (False, True):
        integ = HHT(model, alpha=0.0, expand=expand)
        x0 = initial_state(integ, p)
        d = np.array(integ.scale(x0[:n], x0[n:2 * n], p, 1e-3)).ravel()
        X, res = integ.trajectory(50)(x0, 0.0, p, 1e-3, d)
        assert float(np.max(res)) <= 1e-12  # every step converged to tol
        states.append(np.array(X)[:n])
    # 1e-13 m: both solve each step to tol = 1e-12 of the length scale (0.1 m), round-off apart
    np.testing.assert_allclose(states[0], states[1], rtol=0, atol=1e-13)


def test_scatter_add_is_base_plus_scatter_bitwise():
    """A group that reaches few entries (twobar's springs) is added in place, the beams over all: the same
    numbers as base + scatter either way."""
    model = _twobar(8)
    n, rng = model.n_dof, np.random.default_rng(2)
    base = ca.MX.sym("base", n)
    for grp in model.groups:
        vals = ca.MX.sym("v", grp.spec.n_dof, grp.n)
        f = ca.Function("f", [base, vals], [scatter_add(base, vals, grp), base + scatter(vals, grp, n)])
        a, b = f(rng.normal(size=n), rng.normal(size=(grp.spec.n_dof, grp.n)))
        assert np.array_equal(np.array(a), np.array(b)), grp.kind
