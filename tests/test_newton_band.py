"""The HHT step's Newton update on a mapped mesh, assembled straight into the banded LU's storage
(casflex.integrators.newton_band): Newton's update with the scaled Jacobian, whatever the scene."""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pytest

import casflex
from casflex.integrators.hht import HHT
from casflex.integrators.newton_band import _node_blocks as node_blocks
from casflex.integrators.newton_band import _node_dofs as node_dofs
from casflex.integrators.newton_band import _shared_entries as shared_entries
from casflex.model.assembly import gather, scatter, scatter_add
from casflex.simulate.run import initial_state


def _twobar(elements: int):
    scene = casflex.load_scene("twobar")
    return casflex.assemble(dataclasses.replace(scene, beams=tuple(dataclasses.replace(b, elements=elements)
                                                                  for b in scene.beams)))


@pytest.mark.parametrize("scene, alpha", [("twobar", 0.0), ("twobar", -0.1), ("slidercrank", -0.05),
                                          ("knee_pendulum", 0.0)])
def test_the_band_update_is_newtons_update_with_the_scaled_jacobian(scene, alpha):
    """z1 = z0 - (dG/dz)^-1 G from the mapped kernels assembled into the band, unscaled, against a dense solve
    with the sparse scaled Jacobian of hht_jacobian; slidercrank has joints (multipliers solved for), and
    knee_pendulum's largest element group, whose padded output the band is gathered from, is not its first."""
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
        assert float(np.max(np.array(res))) <= 1e-12  # every step converged to tol
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


@pytest.mark.parametrize("scene", ["twobar", "knee_pendulum", "slidercrank", "hamner_leg_flexible"])
def test_node_dofs_are_the_gathered_element_dofs_split_at_the_nodes(scene):
    """node_dofs (slices along a meshed bar, gathers elsewhere), its node blocks stacked, is gather's table of
    the element dofs, bitwise, for every element group; twobar's beams are read as slices, no index list.
    hamner_leg_flexible numbers each chain's nodes consecutively: an element's six dofs are one block and
    consecutive elements overlap (stride 3, not 6), so its beams take the gather, whose table was once read
    transposed (every mapped step on that scene failed)."""
    model = _twobar(8) if scene == "twobar" else casflex.assemble(casflex.load_scene(scene))
    v = ca.MX.sym("v", model.n_dof)
    x = np.random.default_rng(3).normal(size=model.n_dof)
    for grp in model.groups:
        parts = node_dofs(v, grp)
        assert [int(p.size1()) for p in parts] == [b - a for a, b in node_blocks(grp.dofs)], grp.kind
        a, b = ca.Function("f", [v], [ca.vertcat(*parts), gather(v, grp)])(x)
        assert np.array_equal(np.array(a), np.array(b)), grp.kind
    beams = next(g for g in _twobar(32).groups if g.kind == "beam")
    assert list(node_blocks(beams.dofs)) == [(0, 3), (3, 6)]
    read = str(node_dofs(ca.MX.sym("v", 201), beams)[0])
    assert read == "horzcat(v[3:6], reshape(v[15:108]), v[9:12], reshape(v[108:201]))", read


def test_modified_newton_on_the_band_reuses_the_unscaled_factors():
    """The modified Newton keeps the update's factors (of the unscaled matrix on the mapped path) and its chord
    updates converge most steps: a factor kept in the wrong scaling would refresh at every step."""
    model = _twobar(3)
    integ = HHT(model, alpha=0.0, expand=False, newton="modified")
    p, n, h = model.params(None), model.n_dof, 2e-4
    x0 = initial_state(integ, p)
    d = np.array(integ.scale(x0[:n], x0[n:2 * n], p, h)).ravel()
    F = np.array(integ.modified.factor_at(x0, 0.0, p, h, d)).ravel()
    x, xe, refreshes = x0, x0, 0
    for k in range(60):
        x, res, F, _, refreshed = integ.modified.step_interpreted(x, k * h, p, h, d, F)
        xe = np.array(integ.step(xe, k * h, p, h, d)[0]).ravel()
        refreshes += refreshed
        assert res <= 1e-12
    assert refreshes < 30  # measured 0 of 60 (twobar at dt = 2e-4, 3 elements per bar)
    # a chord step leaves up to cond(G_z) tol of error (modified.py); measured 2.7e-15 m over these 60 steps
    np.testing.assert_allclose(x[:n], xe[:n], rtol=0, atol=1e-11)


@pytest.mark.parametrize("expand", [False, True])
def test_a_step_ends_converged_exactly_when_its_residual_is_within_tol_or_the_roundoff_floor(expand):
    """finish_step's `done` (the floor's pass taken only above tol, a conditional branch) is res <= max(tol,
    floor) as HHT.tolerance says, on both sides of tol and of the floor: tol = 1e-16 lies below twobar's
    round-off floor (10 eps max|q / l|, about 1e-15), so residuals between them converge only through the floor."""
    model = _twobar(3)
    integ = HHT(model, tol=1e-16, expand=expand)
    p, n = model.params(None), model.n_dof
    x0 = initial_state(integ, p)
    d = np.array(integ.scale(x0[:n], x0[n:2 * n], p, 1e-3)).ravel()
    zg, prm = integ.prepare(x0, 0.0, p, 1e-3, d)
    z1 = np.array(integ._fn["update_step"](zg, prm)[0]).ravel()
    seen = []
    for s in [0.0, *np.logspace(-16, -6, 21)]:
        x1, res, done = integ._fn["finish_step"](z1 + s, prm)
        limit = float(integ.tolerance(np.array(x1).ravel()[:n]))
        assert bool(done) == (float(res) <= limit), (s, float(res), limit)
        seen.append((float(res) > integ.tol, bool(done)))
    assert (True, True) in seen and (True, False) in seen  # the floor's branch taken, and a step refused


@pytest.mark.parametrize("stiffer", [1.0, 2.0])
def test_kernel_constants_baked_only_where_every_element_has_them(stiffer):
    """The mapped kernels take a property row (and gravity) as constants written into their code only where
    every element of the group has the same number (newton_band._shared_entries): twobar's E, A, I, density
    and rotary inertia, not the element lengths and angles (which differ at round-off along the mesh); with
    one bar stiffer, E goes too. The step on the band then agrees with the flat step (numeric properties per
    element) to round-off: a constant taken from the first element for all of them would move the soft bar."""
    scene = casflex.load_scene("twobar")
    beams = tuple(dataclasses.replace(b, elements=2, E=b.E * (stiffer if i == 0 else 1.0))
                  for i, b in enumerate(scene.beams))
    model = casflex.assemble(dataclasses.replace(scene, beams=beams))
    beam = next(g for g in model.groups if g.kind == "beam")
    known, values = shared_entries(beam.props(ca.MX.sym("p", model.n_p)), beam.n)
    assert known.tolist() == [False, False, False, stiffer == 1.0, True, True, True, True]
    assert values[3] == (scene.beams[0].E if stiffer == 1.0 else values[3])
    assert shared_entries(None, beam.n, model.gravity)[0].all()  # twobar's gravity is no parameter
    p, n = model.params(None), model.n_dof
    states = []
    for expand in (False, True):
        integ = HHT(model, alpha=-0.1, expand=expand)
        x0 = initial_state(integ, p)
        d = np.array(integ.scale(x0[:n], x0[n:2 * n], p, 1e-3)).ravel()
        X, res = integ.trajectory(50)(x0, 0.0, p, 1e-3, d)
        assert float(np.max(np.array(res))) <= 1e-12
        states.append(np.array(X)[:n])
    # 1e-13 m: both solve each step to tol = 1e-12 of the length scale (0.1 m), round-off apart
    np.testing.assert_allclose(states[0], states[1], rtol=0, atol=1e-13)


def test_gravity_with_a_parameter_stays_an_input():
    """Gravity that depends on the parameters is not a constant of the kernels (it changes with p)."""
    p = ca.SX.sym("p", 2)
    assert shared_entries(None, 4, ca.Function("gravity", [p], [ca.vertcat(0, -p[1])])) is None
    assert shared_entries(ca.MX.sym("props", 8, 4), 4) is None  # a table with parameters in it
