"""casflex.muscles.static_optimization: closed forms, and OpenSim 4.6's own SO on Hamner's subject 02 run given
OpenSim's moment arms, forces at full activation and inverse dynamics (tests/data/muscles/README_opensim_runs.md)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from casflex.lab import read_sto
from casflex.muscles.static_optimization import StaticOptimization, solve_static_optimization

DATA = Path(__file__).parent / "data" / "muscles"

#: OpenSim 4.6's SO on Hamner's subject 02 run (tests/data/muscles/README_opensim_runs.md): the coordinates the
#: muscles and the reserves carry (the pelvis' three are the residuals' alone: the muscles are internal forces there,
#: moment arms 0 to 3e-16 m; no muscle crosses the arms' four)
JOINTS = ("hip_flexion_r", "knee_angle_r", "ankle_angle_r", "hip_flexion_l", "knee_angle_l", "ankle_angle_l",
          "lumbar_extension", "arm_flex_r", "elbow_flex_r", "arm_flex_l", "elbow_flex_l")
ARMS = slice(7, 11)
LOOSE = StaticOptimization(activation_bounds=(0.0, 1.0))


def _reference():
    d = np.load(DATA / "hamner_run_inputs.npz")
    cols = [list(d["coordinates"]).index(c) for c in JOINTS]
    moments = np.column_stack([np.interp(d["t"], d["id_t"], d["id_moments"][:, c]) for c in cols])
    act = read_sto(DATA / "hamner_run_so_activation.sto")
    return d, cols, moments, act


def _solved(d) -> np.ndarray:
    """The frames OpenSim's SO solved (10 of the 61 it logged as failed: its IPOPT at 100 iterations)."""
    return np.array([np.abs(d["failed"] - t).min() > 1e-6 for t in d["t"]])


def test_opensims_activations_from_its_own_moment_arms_forces_and_moments():
    d, cols, moments, act = _reference()
    r = solve_static_optimization(moments, d["arms"][:, :, cols], d["active"], reserves=np.ones(len(JOINTS)),
                                  coordinates=JOINTS)
    ok = _solved(d)
    assert ok.sum() >= 45
    theirs = np.column_stack([act.column(m) for m in d["muscles"]])
    force = (r.activations[ok] - theirs[ok]) * d["active"][ok]
    rms, peak = np.sqrt(np.mean(force ** 2, axis=0)), (theirs[ok] * d["active"][ok]).max(axis=0)
    big = peak >= 50.0  # N
    assert big.sum() >= 80
    # 2 % of each muscle's peak force: the brief's bar (measured 0.45 %: OpenSim's IPOPT stops at its criterion
    # 1e-4); the muscles of smaller peak sit at the 0.01 activation floor, where OpenSim's interior point stops above
    # the bound: within 1 N RMS (measured 0.33 N)
    assert (rms[big] < 0.02 * peak[big]).all(), {m: e for m, e, b in zip(d["muscles"], rms / peak, big, strict=True)
                                                  if b and e >= 0.02}
    assert rms[~big].max() < 1.0, rms[~big].max()
    reserves = np.column_stack([act.column(f"{c}_reserve") for c in JOINTS])
    assert np.abs(r.reserve_controls[ok, :7] - reserves[ok, :7]).max() < 0.05  # N m: the legs' and lumbar's
    assert r.reserve_controls[:, ARMS] == pytest.approx(moments[:, ARMS], abs=1e-6)  # no muscle crosses the arms
    assert r.reserve_share[ARMS] == pytest.approx(1.0)
    # running saturates the legs' muscles (activation 1 at some frames): the leg reserves take up to 55 N m there,
    # as OpenSim's do (their 0.05 N m agreement above); the lumbar muscles carry the trunk alone
    assert r.reserve_share[6] < 1e-3 and np.abs(reserves[ok, :6]).max() > 10.0
    assert np.abs(r.violation).max() < 1e-6  # N m
    forces = np.column_stack([read_sto(DATA / "hamner_run_so_force.sto").column(m) for m in d["muscles"]])
    assert np.allclose(forces, theirs * d["active"], rtol=1e-6, atol=1e-6)  # SO's force is a times "active"


def test_one_muscle_one_joint_carries_the_moment_alone():
    m, r, f = np.array([[20.0], [35.0]]), 0.05, 1000.0
    res = solve_static_optimization(m, np.full((2, 1, 1), r), np.full((2, 1), f), options=LOOSE)
    assert res.activations[:, 0] == pytest.approx(m[:, 0] / (r * f), rel=1e-8)
    assert res.forces[:, 0] == pytest.approx(m[:, 0] / r, rel=1e-8)
    assert res.success and res.report == ""


def test_two_identical_muscles_share_equally():
    res = solve_static_optimization([[30.0]], np.full((1, 2, 1), 0.04), np.full((1, 2), 800.0), options=LOOSE)
    assert res.activations[0, 0] == pytest.approx(res.activations[0, 1], rel=1e-8)
    assert res.activations[0, 0] == pytest.approx(30.0 / (2 * 0.04 * 800.0), rel=1e-8)


def test_p2_without_active_bounds_is_the_least_norm_solution():
    rng = np.random.default_rng(3)
    arms = rng.uniform(0.01, 0.06, (1, 6, 3))
    active = rng.uniform(500.0, 3000.0, (1, 6))
    G = (arms[0] * active[0][:, None]).T  # (n_c, n_m): generalized force per unit activation
    a_true = rng.uniform(0.1, 0.5, 6)
    a_true = G.T @ np.linalg.solve(G @ G.T, G @ a_true)  # Lagrange: a = G^T (G G^T)^-1 tau
    assert a_true.min() > 0.0  # the bounds then do not act
    res = solve_static_optimization((G @ a_true)[None, :], arms, active, options=LOOSE)
    assert res.activations[0] == pytest.approx(a_true, rel=1e-7)


def test_p3_activations_go_as_the_square_root_of_their_strength():
    g = np.array([0.03 * 1000.0, 0.05 * 2000.0])  # r F, N m per unit activation
    res = solve_static_optimization([[40.0]], np.array([[[0.03], [0.05]]]), [[1000.0, 2000.0]],
                                    options=StaticOptimization(exponent=3.0, activation_bounds=(0.0, 1.0)))
    a = np.sqrt(g) * 40.0 / (g @ np.sqrt(g))  # KKT: 3 a_i^2 = lambda g_i
    assert res.activations[0] == pytest.approx(a, rel=1e-6)


def test_a_reserve_takes_what_the_muscles_cannot():
    m = np.array([[5.0], [25.0]])  # N m; the muscle carries at most 0.05 * 200 = 10 N m
    res = solve_static_optimization(m, np.full((2, 1, 1), 0.05), np.full((2, 1), 200.0), reserves=[1.0],
                                    options=LOOSE)
    assert res.activations[1, 0] == pytest.approx(1.0, abs=1e-7)
    assert res.reserve_moments[1, 0] == pytest.approx(15.0, rel=1e-6)
    # frame 0: cost a^2 + u^2 with 10 a + u = 5: a = 50/101, u = 5/101
    assert res.activations[0, 0] == pytest.approx(50.0 / 101.0, rel=1e-7)
    assert res.reserve_share[0] == pytest.approx(np.sqrt(np.mean(res.reserve_moments[:, 0] ** 2))
                                                 / np.sqrt(np.mean(m[:, 0] ** 2)))


def _weak():
    m = np.array([[4.0, 1.0], [12.0, 1.0], [6.0, -1.0]])  # frame 1's knee needs 12 N m; the muscle gives 10
    arms = np.zeros((3, 2, 2))
    arms[:, 0, 0], arms[:, 1, 1] = 0.05, 0.02
    return m, arms, np.full((3, 2), 200.0)


def test_an_unsatisfiable_frame_is_refused_naming_the_coordinate_and_the_shortfall():
    m, arms, active = _weak()
    with pytest.raises(ValueError, match=r"frame 1: knee: no activation within the bounds carries its moment of "
                                         r"12 N m: 2 N m out of reach; frame 2: hip: .* of -1 N m: 1 N m out of reach"):
        solve_static_optimization(m, arms, active, coordinates=("knee", "hip"),
                                  options=StaticOptimization(activation_bounds=(0.0, 1.0), tolerance=1e-9))


def test_report_keeps_the_frames_it_can_and_says_which_it_cannot():
    m, arms, active = _weak()
    res = solve_static_optimization(m, arms, active, coordinates=("knee", "hip"),
                                    options=StaticOptimization(activation_bounds=(0.0, 1.0), infeasible="report"))
    assert not res.success
    assert [(f, c) for f, c, _ in res.infeasible] == [(1, "knee"), (2, "hip")]
    assert [s for _, _, s in res.infeasible] == pytest.approx([2.0, -1.0], abs=1e-5)
    assert "frame 1: knee" in res.report
    assert res.activations[1, 0] == pytest.approx(1.0, abs=1e-6)
    assert res.violation[1] == pytest.approx([-2.0, 0.0], abs=1e-5)  # carried minus required
    assert res.activations[0] == pytest.approx([0.4, 0.25], rel=1e-6)  # the satisfiable frames are exact


def test_moments_reached_only_at_the_bounds_are_carried():
    """Moments the muscles carry only at a bound (0 with a lower bound 0; 10 N m at full activation): the QP's
    feasible set has no interior there, and the solve falls back to IPOPT's relaxed bounds."""
    res = solve_static_optimization([[10.0, 0.0], [4.0, 0.0]], np.array([[[0.05, 0.0], [0.0, 0.02]]] * 2),
                                    np.full((2, 2), 200.0), options=LOOSE)
    assert res.success
    assert res.activations == pytest.approx(np.array([[1.0, 0.0], [0.4, 0.0]]), abs=1e-7)


def test_a_coordinate_nothing_acts_on_must_need_nothing():
    arms = np.zeros((3, 1, 2))
    arms[:, 0, 0], arms[:, 0, 1] = 0.05, 1e-17  # the second: a root's coordinate, the muscle internal to it
    m = np.array([[5.0, 0.0], [6.0, 0.0], [7.0, 0.0]])
    res = solve_static_optimization(m, arms, np.full((3, 1), 400.0), options=LOOSE)
    assert res.activations[:, 0] == pytest.approx(m[:, 0] / 20.0, rel=1e-8)
    m[2, 1] = 3.0
    with pytest.raises(ValueError, match="frame 2: pelvis_tx: .* of 3 N m: 3 N m out of reach"):
        solve_static_optimization(m, arms, np.full((3, 1), 400.0), coordinates=("knee", "pelvis_tx"), options=LOOSE)


def test_passive_forces_as_known_forces_and_max_isometric_without_curves():
    arms, active = np.full((1, 1, 1), 0.05), np.full((1, 1), 500.0)
    res = solve_static_optimization([[10.0]], arms, active, passive=[[40.0]],
                                    options=StaticOptimization(passive=True, activation_bounds=(0.0, 1.0)))
    assert res.activations[0, 0] == pytest.approx((10.0 - 0.05 * 40.0) / (0.05 * 500.0), rel=1e-7)
    assert res.forces[0, 0] == pytest.approx(10.0 / 0.05, rel=1e-7)  # a F + P carries the moment
    res = solve_static_optimization([[10.0]], arms, active, max_isometric=[1000.0],
                                    options=StaticOptimization(force_length_velocity=False,
                                                               activation_bounds=(0.0, 1.0)))
    assert res.activations[0, 0] == pytest.approx(10.0 / 50.0, rel=1e-7)


@pytest.mark.parametrize("options, message", [
    (dict(exponent=0.5), "exponent: expected a number >= 1"),
    (dict(activation_bounds=(0.5, 0.2)), "activation_bounds: expected 0 <= lower < upper"),
    (dict(activation_bounds=(-0.1, 1.0)), "activation_bounds"),
    (dict(reserve_bounds=(1.0, 2.0)), "reserve_bounds: expected lower <= 0 <= upper"),
    (dict(tolerance=0.0), "tolerance"),
    (dict(max_iterations=0), "max_iterations"),
    (dict(infeasible="ignore"), "infeasible: expected 'raise' or 'report'"),
    (dict(passive="yes"), "passive: expected True or False"),
    # an activation above 1 (the command wrote 2.88 with --activation-bounds 0.01:5, exit 0)
    (dict(activation_bounds=(0.01, 5.0)), r"activation_bounds: expected 0 <= lower < upper <= 1 \(an activation"),
    # IPOPT stopped at p = 20 on Hamner's run (Maximum_Iterations): a RuntimeError's traceback from the command
    (dict(exponent=20.0), r"exponent: expected a number >= 1 and at most 10 \(OpenSim's activation_exponent\), "
                          r"got 20.0"),
])
def test_options_refuse_bad_values(options, message):
    with pytest.raises(ValueError, match=message):
        StaticOptimization(**options)


@pytest.mark.parametrize("change, message", [
    (dict(arms=np.zeros((2, 3))), r"arms: expected \(2, muscles, 1\)"),
    (dict(active=np.full((2, 1), np.nan)), r"active: not finite at \(0, 0\)"),
    (dict(active=np.full((2, 1), -5.0)), "active: a muscle's force at full activation is negative"),
    (dict(reserves=[-1.0]), "reserves: an optimal force is negative"),
    (dict(moments=np.zeros(2)), r"moments: expected \(frames, coordinates\)"),
    (dict(arms=np.full((2, 1, 1), 50.0)), r"arms: 50 m at \(frame, muscle, coordinate\) \(0, 0, 0\): .* mm or cm\?"),
])
def test_bad_inputs_are_refused_before_any_work(change, message):
    args = dict(moments=np.ones((2, 1)), arms=np.full((2, 1, 1), 0.05), active=np.full((2, 1), 100.0), reserves=None)
    args.update(change)
    with pytest.raises(ValueError, match=message):
        solve_static_optimization(args["moments"], args["arms"], args["active"], reserves=args["reserves"])


def test_without_max_isometric_the_option_is_refused():
    with pytest.raises(ValueError, match="max_isometric: needed with force_length_velocity=False"):
        solve_static_optimization([[1.0]], np.full((1, 1, 1), 0.05), [[100.0]],
                                  options=StaticOptimization(force_length_velocity=False))


def test_near_solves_on_the_active_set_where_it_holds_and_by_the_qp_where_it_changed():
    """OpenSim's inputs of Hamner's run, the moments moved by 1 % and by 30 %: ``near=`` (the nominal solution's
    active set in closed form, the QP for the frames where that set is not optimal) against the plain QP: each
    frame's objective within 1e-8 and the activations within 1e-4 (two interior-point solves of one frame, the
    trial's and the changed frames', end up to 2.4e-5 apart in a muscle 2e-5 above its 0.01 floor: a bound
    nearly but not quite active, where IPOPT's iterate stops at about sqrt(mu) from it; the objectives 2e-9
    apart); the frames kept in closed form: 87 % at 1 %, 5 % at 30 % (running saturates muscles)."""
    d, cols, moments, _ = _reference()
    args = (d["arms"][:, :, cols], d["active"])
    opts = {"reserves": np.ones(len(JOINTS)), "coordinates": JOINTS}
    base = solve_static_optimization(moments, *args, **opts)
    kept = []
    for scale in (1.01, 1.3):
        moved = moments * scale
        plain = solve_static_optimization(moved, *args, **opts)
        near = solve_static_optimization(moved, *args, **opts, near=base)
        assert np.abs(near.activations - plain.activations).max() < 1e-4
        cost = [(r.activations ** 2).sum(axis=1) + (r.reserve_controls ** 2).sum(axis=1) for r in (near, plain)]
        assert np.abs(cost[0] - cost[1]).max() < 1e-8 * cost[1].max()
        assert np.abs(near.violation).max() < 1e-6  # N m
        kept.append(near.stats["kept"].mean())
    assert kept[0] > 0.8 and kept[1] < kept[0], kept


def test_the_block_diagonal_is_scipys_with_its_zeros_kept():
    """The constraints' matrix built in numpy (issue 49) against scipy's COO -> CSC and row selection, which it
    replaced: the same compressed columns (explicit zeros kept: the solvers see the same structure) and values,
    on random frames with zero arms and left-out rows."""
    import scipy.sparse as sp

    from casflex.muscles.static_optimization import _block_diagonal

    rng = np.random.default_rng(1)
    for _ in range(20):
        k, n_c, n_v = (int(v) for v in rng.integers(1, 6, 3))
        full = rng.normal(size=(k, n_c, n_v)) * (rng.random((k, n_c, n_v)) > 0.4)
        keep = rng.random(k * n_c) > 0.3
        rows = np.arange(k * n_c).reshape(k, n_c, 1).repeat(n_v, axis=2)
        cols = (np.arange(k)[:, None, None] * n_v + np.arange(n_v)[None, None, :]).repeat(n_c, axis=1)
        want = sp.csc_matrix((full.ravel(), (rows.ravel(), cols.ravel())), shape=(k * n_c, k * n_v))[keep].tocsc()
        want.sort_indices()
        got = _block_diagonal(full, keep.reshape(k, n_c))
        assert got.shape == want.shape and np.array_equal(got.indptr, want.indptr)
        assert np.array_equal(got.indices, want.indices) and np.array_equal(got.data, want.data)


def test_muscles_with_no_force_anywhere_leave_every_frame_refused_by_name():
    """A path shorter than its tendon's slack length gives no active force: nothing acts on any row; the frames are
    refused naming the coordinate and the moment (a CasADi error on an empty problem before)."""
    k = 3
    with pytest.raises(ValueError, match=r"frame 0: knee: no activation within the bounds carries its moment of 5 N m"):
        solve_static_optimization(np.full((k, 1), 5.0), np.full((k, 1, 1), 0.05), np.zeros((k, 1)),
                                  coordinates=["knee"])


def test_each_muscle_within_its_own_bounds_in_the_qp_ipopt_and_the_active_set():
    """Two identical muscles on one joint, the first bounded by 0.3 (OpenSim's per-muscle max_control): the
    second carries the rest; the QP (p = 2), IPOPT (p = 3) and the active-set solve of ``near`` agree."""
    import dataclasses

    m = np.array([[10.0], [30.0], [40.0]])  # N m: 0.16, 0.47, 0.63 of both muscles' full activation together
    arms, active = np.full((3, 2, 1), 0.04), np.full((3, 2), 800.0)
    opts = StaticOptimization(activation_bounds=(0.0, 1.0), muscle_bounds=((0.0, 0.3), (0.0, 1.0)))
    for p in (2.0, 3.0):
        r = solve_static_optimization(m, arms, active, options=dataclasses.replace(opts, exponent=p))
        a = r.activations
        assert r.success and a[:, 0].max() == pytest.approx(0.3, abs=1e-8)  # held at its own bound
        assert a[0, 0] == pytest.approx(a[0, 1], rel=1e-6)  # below it: shared equally
        assert np.allclose(a.sum(axis=1) * 0.04 * 800.0, m[:, 0], rtol=1e-8)
    near = solve_static_optimization(m * 0.999, arms, active, options=opts)
    again = solve_static_optimization(m, arms, active, options=opts, near=near)
    qp = solve_static_optimization(m, arms, active, options=opts)
    assert again.stats["kept"].all() and np.allclose(again.activations, qp.activations, atol=1e-8)
    with pytest.raises(ValueError, match=r"^muscle_bounds: expected 2 pairs \(one per muscle\), got 1$"):
        solve_static_optimization(m, arms, active, options=dataclasses.replace(opts, muscle_bounds=((0.0, 1.0),)))
    with pytest.raises(ValueError, match=r"^muscle_bounds\[0\]: expected 0 <= lower < upper <= 1, got \(0.0, 2.0\)"):
        StaticOptimization(muscle_bounds=((0.0, 2.0),))


def test_ipopt_stopping_short_names_the_frame_that_fails_alone():
    """p = 3 with IPOPT held to 30 iterations on OpenSim's inputs of Hamner's run: the whole trial stops short
    (a RuntimeError before, naming no frame); each frame alone converges but the one at 0.883 s."""
    from casflex.muscles.static_optimization import StaticOptimizationError

    d, cols, moments, _ = _reference()
    with pytest.raises(StaticOptimizationError, match=r"^static optimization \(exponent 3\): IPOPT stopped "
                       r"\(Maximum_Iterations_Exceeded\) at t = 0.883333 s \(frame 41\), on moments the activations "
                       r"can carry: try exponent 2") as info:
        solve_static_optimization(moments, d["arms"][:, :, cols], d["active"], reserves=np.ones(len(JOINTS)),
                                  options=StaticOptimization(exponent=3.0, max_iterations=30), coordinates=JOINTS,
                                  times=d["t"])
    assert info.value.frames == (41,)


def test_a_shortfall_ipopt_stopped_on_is_no_refusal_of_moments_out_of_reach():
    """p = 3 with IPOPT held to 5 iterations: the least-shortfall problem stops short too, and its iterate was taken
    as what the activations cannot carry ("frame 0: knee_angle_l: ... 115.432 N m out of reach", moments the
    reserves carry); now its stop is said as IPOPT's, not as the moments'."""
    from casflex.muscles.static_optimization import StaticOptimizationError

    d, cols, moments, _ = _reference()
    with pytest.raises(StaticOptimizationError, match=r"^static optimization \(exponent 3\): IPOPT stopped "
                       r"\(Maximum_Iterations_Exceeded\) at t = 0.2 s \(frame 0\), .* finding what the activations "
                       r"cannot carry: try exponent 2"):
        solve_static_optimization(moments, d["arms"][:, :, cols], d["active"], reserves=np.ones(len(JOINTS)),
                                  options=StaticOptimization(exponent=3.0, max_iterations=5), coordinates=JOINTS,
                                  times=d["t"])
