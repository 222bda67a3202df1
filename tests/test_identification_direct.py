"""Direct identification (Eqs. 11-13) against known truth."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import casflex
from casflex.data import MeasurementSet, measured_set
from casflex.identification import Solver, identify_direct
from casflex.simulate import simulated_set


@pytest.fixture(scope="module")
def twobar():
    return casflex.assemble(casflex.load_scene("twobar"))


@pytest.fixture(scope="module")
def sim(twobar):
    return simulated_set(twobar)  # alpha = 0, Newton tol 1e-14: Eq. 1 holds to ~1e-7 N


@pytest.mark.parametrize("t_i", [0.69, 2.83])
@pytest.mark.parametrize("start", [0.8, 1.2, 0.3, 3.0])
def test_recovers_truth_from_simulated_set(twobar, sim, t_i, start):
    r = identify_direct(twobar, sim, [t_i], start=start)
    assert r.success, r.status
    # 1e-8: the data satisfy Eq. 1 to the simulation's Newton tolerance (measured 6e-10)
    np.testing.assert_allclose(r.p, twobar.p_nominal, rtol=1e-8)
    lin = np.array(list(r.extra["linear_solution"].values()))
    np.testing.assert_allclose(lin, twobar.p_nominal, rtol=1e-8)
    assert r.identifiability["rank"] == r.identifiability["n_unknowns"] == 7
    # the multipliers are the clamp's reactions of the simulation
    np.testing.assert_allclose(r.multipliers[0], sim.meta["lam"][sim.index(t_i)], rtol=1e-6, atol=1e-6)


def test_several_instants_and_other_solver(twobar, sim):
    r = identify_direct(twobar, sim, [0.4, 1.1, 1.6], start=1.2,
                        solver=Solver("sqpmethod", options={
                            "qpsol": "qrqp", "qpsol_options": {"print_iter": False, "print_header": False},
                            "print_iteration": False, "print_header": False}))
    np.testing.assert_allclose(r.p, twobar.p_nominal, rtol=1e-8)
    assert r.solver == "sqpmethod" and len(r.multipliers) == 3


def test_standard_errors_cover_the_truth_with_noisy_accelerations(twobar, sim):
    rng = np.random.default_rng(3)
    noisy = MeasurementSet(sim.t, sim.channels, sim.q, sim.qd, sim.qdd + rng.normal(0, 1e-2, sim.qdd.shape))
    r = identify_direct(twobar, noisy, [0.5, 0.9, 1.3, 1.7, 2.1, 2.5])
    err = np.abs(r.p - twobar.p_nominal)
    se = np.array(list(r.std_errors.values()))
    assert np.all(se > 0)
    # 4 standard errors: a fixed seed, and the residual noise M * dqdd is only roughly i.i.d.
    assert np.all(err < 4 * se), (err, se)
    assert np.any(err > 0.05 * se)  # the noise really moved the estimate


def test_measured_set_direct_is_close_but_biased(twobar, sim):
    # the paper: "bad convergence even from p*"; with exact derivatives it converges, to a
    # biased value (central differences err by O(h^2) in qdd)
    r = identify_direct(twobar, measured_set(sim), [0.69])
    assert r.success
    rel = np.abs(r.p / twobar.p_nominal - 1)
    assert rel[[0, 2]].max() < 1e-4 and rel.max() < 5e-2


def test_bad_inputs(twobar, sim):
    partial = MeasurementSet(sim.t, ("x5", "y5"), sim.q[:, [12, 13]], sim.qd[:, [12, 13]], sim.qdd[:, [12, 13]])
    with pytest.raises(ValueError, match=r"needs every dof; the data lack \['x1'.*adapted direct method makes"):
        identify_direct(twobar, partial, [0.69])
    with pytest.raises(ValueError, match="no sample there"):
        identify_direct(twobar, sim, [7.0])
    with pytest.raises(ValueError, match="solver 'nosuch'"):
        identify_direct(twobar, sim, [0.69], solver=Solver("nosuch"))
    with pytest.raises(ValueError, match="start"):
        identify_direct(twobar, sim, [0.69], start=-1.0)
    with pytest.raises(ValueError, match="at least one time"):
        identify_direct(twobar, sim, [])


def test_result_json(twobar, sim, tmp_path):
    r = identify_direct(twobar, sim, [0.69])
    d = json.loads(r.save(tmp_path / "r.json").read_text())
    for key in ("parameters", "success", "status", "iterations", "wall_s", "solver", "method"):
        assert key in d
    assert d["method"] == "direct" and set(d["parameters"]) == {"k1", "kt1", "k3", "kt3"}
    assert "k1" in r.summary()


@pytest.mark.parametrize("options", [{"hessian": "gauss-newton"}, {"compiled": True},
                                     {"name": "sqpmethod", "hessian": "gauss-newton"}],
                         ids=["gauss-newton", "compiled", "sqpmethod-gauss-newton"])
def test_hessian_and_compiled_options_reach_the_same_answer(twobar, sim, options):
    ref = identify_direct(twobar, sim, [0.69], start=0.5)
    r = identify_direct(twobar, sim, [0.69], start=0.5, solver=Solver(**options))
    assert r.success, (r.status, options)
    np.testing.assert_allclose(r.p, ref.p, rtol=1e-9)
    assert r.extra["hessian"] == options.get("hessian", "exact")
    assert r.extra["compiled"] == options.get("compiled", False)


def test_bad_hessian_named(twobar, sim):
    with pytest.raises(ValueError, match="hessian: expected one of"):
        identify_direct(twobar, sim, [0.69], solver=Solver(hessian="bfgs"))


def test_solver_without_hessian_option_falls_back_with_a_warning(twobar, sim):
    with pytest.warns(UserWarning, match="takes no Hessian function") as rec:
        r = identify_direct(twobar, sim, [0.69], start=0.8, solver=Solver("sleqp", hessian="gauss-newton"))
    assert len(rec) == 1
    np.testing.assert_allclose(r.p, twobar.p_nominal, rtol=1e-6)


def test_objective_is_the_residual_at_the_reported_parameters(twobar, sim):
    # recomputed from Eq. 11 through the model at the reported p and multipliers, after the polish
    rng = np.random.default_rng(5)
    noisy = MeasurementSet(sim.t, sim.channels, sim.q, sim.qd, sim.qdd + rng.normal(0, 1e-2, sim.qdd.shape))
    instants = [0.5, 1.3, 2.1]
    r = identify_direct(twobar, noisy, instants)
    fs = r.extra["force_scale"]
    f = 0.0
    for t, lam in zip(instants, r.multipliers, strict=True):
        i = noisy.index(t)
        z, phi = (np.array(v).ravel() for v in twobar.equilibrium(noisy.q[i], noisy.qd[i], noisy.qdd[i], lam, t, r.p))
        f += 0.5 * float(z @ z) / fs**2 + 0.5 * float(phi @ phi)
    assert r.objective == pytest.approx(f, rel=1e-6)
    assert set(r.extra["solver_parameters"]) == set(r.parameters)
    assert 0.0 < r.extra["solver_s"] <= r.wall_solve_s


def test_positions_in_millimetres_are_refused_as_by_the_indirect_method(twobar, sim):
    # before: no check; a recording of every dof in mm (rotations in rad) gave success with k1 at 210 for 700
    mm = np.where([c.startswith("theta") for c in sim.channels], 1.0, 1000.0)
    data = MeasurementSet(sim.t, sim.channels, sim.q * mm, None, None)
    with pytest.raises(ValueError, match="look like millimetres"):
        identify_direct(twobar, data, [0.5])
    with pytest.raises(ValueError, match="look like milliseconds"):
        identify_direct(twobar, MeasurementSet(sim.t * 1000, sim.channels, sim.q, None, None), [500.0])


def test_a_fit_held_on_a_bound_by_the_interior_point_solver_does_not_succeed(twobar):
    # Exudyn's twobar, every dof at 100 Hz over 1 s with 0.1 mm noise: the least-squares kt3 is -0.50 (its SE 2.9),
    # IPOPT stops 8e-8 above the bound 0, 16 x the old 1e-8-of-scale test: success was claimed
    z = np.load(Path(__file__).parent / "data" / "twobar_exudyn.npz")
    names = tuple(f"{a}{i}" for i in range(1, 6) for a in ("x", "y", "theta"))
    rows = np.arange(0, 1001, 10)
    q = z["q"][np.ix_(rows, [[str(c) for c in z["channels"]].index(n) for n in names])]
    q = q + np.random.default_rng(0).normal(0, 1e-4, q.shape)
    r = identify_direct(twobar, MeasurementSet(z["t"][rows], names, q, None, None), [0.1, 0.3, 0.5, 0.7, 0.9],
                        solver=Solver(verbose=False))
    assert r.extra["linear_solution"]["kt3"] < 0 <= r.parameters["kt3"] < 1e-6
    assert r.at_bound["kt3"] and not r.success and "kt3 ended on a bound" in r.message
    assert not any(r.at_bound[k] for k in ("k1", "k3"))  # interior ones are not flagged


def test_pressed_on_bounds_needs_both_the_bound_and_a_step_beyond_it():
    from casflex.identification.problem import pressed_on_bounds

    J = np.eye(2)
    lb, ub = np.zeros(2), np.full(2, 10.0)
    # z = w - target: the unconstrained optimum is the target
    w = np.array([1e-7, 1e-7])
    assert pressed_on_bounds(J, w - np.array([-0.5, 0.5]), w, lb, ub).tolist() == [True, False]
    w = np.array([1.0, 10 - 1e-7])
    assert pressed_on_bounds(J, w - np.array([-0.5, 11.0]), w, lb, ub).tolist() == [False, True]  # far: no


def test_parameters_the_data_cannot_separate_do_not_succeed_directly(tmp_path):
    from test_identification_estimate import _parallel_springs

    model = _parallel_springs(tmp_path)
    r = identify_direct(model, simulated_set(model, t_end=0.7), [0.69], solver=Solver(verbose=False))
    assert not r.success and "k1, k1b are not determined by the data" in r.message


def test_a_channel_too_sparse_to_smooth_is_named(twobar, sim, tmp_path):
    # before: "smoothing: a channel has fewer than 5 samples", which of 15 unsaid
    from casflex.data import load_measurements, save_measurements

    q = sim.q[:200].copy()
    q[3:, sim.channels.index("y3")] = np.nan
    path = save_measurements(MeasurementSet(sim.t[:200], sim.channels, q, None, None), tmp_path / "rig.csv")
    with pytest.raises(ValueError, match=r"rig.csv: channel 'y3': smoothing: 3 finite samples, fewer than the 5"):
        identify_direct(twobar, load_measurements(path), [0.1])
