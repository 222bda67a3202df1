"""Forward sensitivities of HHT trajectories against finite differences; compiled and interpreted agree."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_same_numbers

import casflex
from casflex.identification.sensitivity import run_sensitivities, run_states
from casflex.simulate import Stepping, initial_state, integrator_for, simulate


@pytest.fixture(scope="module")
def setup():
    model = casflex.assemble(casflex.load_scene("twobar"))
    integ = integrator_for(model, alpha=0.0)
    x0 = initial_state(integ, model.p_nominal)
    return model, integ, x0


def test_states_are_the_simulation_and_sensitivities_match_finite_differences(setup):
    model, integ, x0 = setup
    p, dt, n = model.p_nominal, 1e-3, 300
    run = run_sensitivities(integ, x0, p, 0.0, dt, n, np.array([0, 150, 300]))
    assert run.converged
    tr = simulate(model, n * dt, stepping=Stepping(dt=dt, alpha=0.0))
    assert_same_numbers(tr.q[[0, 150, 300]], run.X[:, :model.n_dof])  # the same steps (compiled: bitwise by default)
    # d q_300 / d p by central differences, step 1e-5 relative: each trajectory converged to the Newton
    # tolerance (1e-12, scaled), which after the division by 2h leaves ~1e-6 of the largest sensitivity
    # (measured 1.4e-6 on kt1)
    for j in range(model.n_p):
        h = 1e-5 * p[j]
        qs = [simulate(model, n * dt, stepping=Stepping(dt=dt, alpha=0.0),
                       p=p + s * h * np.eye(model.n_p)[j]).q[-1] for s in (1, -1)]
        fd = (qs[0] - qs[1]) / (2 * h)
        ad = run.S[-1, integ.nx + j, :model.n_dof]
        np.testing.assert_allclose(ad, fd, rtol=1e-5, atol=1e-5 * np.abs(fd).max())
    # d x_300 / d x_0 for a position: perturb y5 and re-step (the start need not be consistent for this map)
    i = model.dof("y5")
    h = 1e-7
    x_plus, x_minus = x0.copy(), x0.copy()
    x_plus[i] += h
    x_minus[i] -= h
    ends = [run_sensitivities(integ, x, p, 0.0, dt, n, np.array([n])).X[-1] for x in (x_plus, x_minus)]
    np.testing.assert_allclose(run.S[-1, i], (ends[0] - ends[1]) / (2 * h), rtol=1e-4,
                               atol=1e-6 * np.abs(run.S[-1, i]).max())


def test_compiled_and_interpreted_agree(setup):
    model, integ, x0 = setup
    keep = np.arange(0, 261, 13)  # beyond one compiled chunk of 250 steps, then single steps
    a = run_sensitivities(integ, x0, model.p_nominal, 0.0, 1e-3, 260, keep, compiled=True)
    b = run_sensitivities(integ, x0, model.p_nominal, 0.0, 1e-3, 260, keep, compiled=False)
    np.testing.assert_allclose(a.X, b.X, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.S, b.S, rtol=1e-9, atol=1e-9 * np.abs(b.S).max())


def test_seeded_directions_are_the_full_sensitivities_times_the_seed(setup):
    """A fit carries only its unknowns' directions E = (dx0/dw, dp/dw): by linearity, S E of the full run."""
    model, integ, x0 = setup
    rng = np.random.default_rng(1)
    E = rng.normal(size=(integ.nx + model.n_p, 3))
    keep = np.array([0, 40, 80])
    full = run_sensitivities(integ, x0, model.p_nominal, 0.0, 1e-3, 80, keep)
    seeded = run_sensitivities(integ, x0, model.p_nominal, 0.0, 1e-3, 80, keep, seed=(E[:integ.nx], E[integ.nx:]))
    want = np.einsum("kin,ij->kjn", full.S, E)
    # the same factorisations and sweeps in another order: round-off of the largest entry
    np.testing.assert_allclose(seeded.S, want, rtol=0, atol=1e-10 * np.abs(want).max())
    with pytest.raises(ValueError, match="seed"):
        run_sensitivities(integ, x0, model.p_nominal, 0.0, 1e-3, 3, keep[:1], seed=(E[:5], E[integ.nx:]))


def test_the_mapped_kernels_directions_agree_with_the_flat_ones(setup, monkeypatch):
    """Above EXPAND_DIRECTIONS elements the directional derivatives run through the mapped kernels' MX:
    the same numbers as the flat code (interpreted, 30 steps)."""
    from casflex.integrators import directions
    from casflex.integrators.hht import HHT

    model, integ, x0 = setup
    keep = np.array([30])
    flat = run_sensitivities(HHT(model, alpha=0.0), x0, model.p_nominal, 0.0, 1e-3, 30, keep, compiled=False)
    monkeypatch.setattr(directions, "EXPAND_DIRECTIONS", 0)
    mapped = run_sensitivities(HHT(model, alpha=0.0), x0, model.p_nominal, 0.0, 1e-3, 30, keep, compiled=False)
    np.testing.assert_allclose(mapped.S, flat.S, rtol=0, atol=1e-10 * np.abs(flat.S).max())


@pytest.mark.parametrize("compiled", [True, False])
def test_a_run_without_sensitivities_has_the_states_of_one_with_them(setup, compiled):
    # 260 steps: a compiled chunk of 250 and 10 single steps; the chord steps' model runs
    model, integ, x0 = setup
    keep = np.array([0, 7, 250, 251, 260])
    full = run_sensitivities(integ, x0, model.p_nominal, 0.0, 1e-3, 260, keep, compiled=compiled)
    plain = run_states(integ, x0, model.p_nominal, 0.0, 1e-3, 260, keep, compiled=compiled)
    assert plain.converged and plain.S.shape == (keep.size, 0, integ.nx)
    assert_same_numbers(plain.X, full.X)  # the same steps, Newton scaling and step times
    # a run that stops (parameters not numbers): the steps up to the failure, and which step failed
    bad = run_states(integ, x0, np.full(model.n_p, np.nan), 0.0, 1e-3, 260, keep, compiled=compiled)
    assert not bad.converged and bad.failed_step == 1 and list(bad.steps) == [0]
