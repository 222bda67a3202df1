"""Indirect identification as an NLP (Eqs. 15-17): single or multiple shooting for CasADi's NLP
solvers (IPOPT by default), the transcription of the seed paper and of :mod:`casflex.identification`'s
solver comparisons. The default, single shooting by Gauss-Newton on forward sensitivities, is in
:mod:`.estimate`; this transcription hands its answer to it for the final polish and the
statistics when the residue is Eq. 16.

The model is simulated by HHT-alpha from the scene's initial state at the first sample t0 over
[t0, t0 + horizon] and its kinematics are compared with the measured ones at every sample on
the step grid t0 + k dt:

    J = xi |q^ - q|^2 + psi |q'^ - q'|^2 + phi |q''^ - q''|^2                      (Eq. 15)

q being the compared channels: nodes' dofs, or markers' coordinates y(q) with their rates
y' = J q' and y'' = J q'' + (dJ/dq q') q' (J = dy/dq, :func:`casflex.model.markers.marker_kinematics`).

``residue="positions"`` is Eq. 16 (xi only), ``"full"`` Eq. 17. Each residue is made
dimensionless by the scene's length scale l (rotations by 1 rad), velocities by l / T and
accelerations by l / T^2 with T the horizon, so the weights (xi, psi, phi) compare like with like.

The initial state x_0 = [q0, q0', q0''(p), lambda_0(p)] takes the scene's q0, q0' and the
consistent accelerations and multipliers of Eq. 1, which move with p.

Transcriptions:

- ``single-shooting``: the unknowns are p only; the trajectory is one differentiable CasADi
  Function (HHT steps chained by ``mapaccum``, derivatives through the Newton rootfinder by the
  implicit-function theorem).
- ``multiple-shooting``: the horizon is cut into intervals of ``interval`` steps. Each interval
  after the first starts on the *slow manifold* (:mod:`.initial_state`) through the recording:
  the kinematic fit of the measured dofs and markers at the samples, a quadratic in time through
  the five nearest, gives (q_g, qd_g) at the interval's start, relaxed onto the slow manifold
  (the fit may stretch a bar by the noise where channels over-determine it); its modes below the
  samples' Nyquist frequency are the slow ones, and the decision variables are their amplitudes
  and rates (a, v). The fast components (the bars' stretching and bending, hundreds of hertz) take their
  quasi-static values, the accelerations and multipliers their consistent ones (Eq. 1). The end
  of an interval, projected on the next start's slow modes, must equal its (a, v) (equality
  constraints, scaled by the modal size of one length scale). Full HHT states as unknowns made
  the NLP as stiff as the bars' axial modes (accelerations respond to positions with ~1e8 s^-2)
  and IPOPT regularised its KKT matrix by 1e8-1e17 on 3 s of twobar; starts simulated at the
  starting parameters drifted from the data and IPOPT crawled. The transcription's optimum
  drops the fast modes' motion at each interval start, so it is near, not at, the
  single-shooting optimum: the Gauss-Newton polish (``polish``) and the statistics are single
  shooting's.

Both are built from ONE interval Function (the HHT steps of an interval chained by ``mapaccum``,
with its forward sensitivities in a second one) mapped over the intervals, single shooting being
one interval over the whole horizon (:mod:`.shooting_intervals`; the starts and their Jacobians:
:mod:`.shooting_starts`). The NLP solver gets the Gauss-Newton Hessian J_r^T J_r (r the residue,
exact first derivatives), the gradient and the constraint Jacobian assembled from the mapped
interval blocks (:mod:`.shooting_solver`), so the compiled NLP's code does not grow with the
number of intervals or the horizon: twobar's multiple shooting over 0.69 s (34 intervals) is a
51k-line C file, built in 4 s in a first process (gcc 3.3 s), where CasADi differentiating the
whole NLP made 709k lines and 146 s. For Eq. 17, Gauss-Newton steps on the single-shooting
problem polish p after the solver and the standard errors come from the same Jacobian.

:func:`identify_nlp` runs in stages: the checks and the set-up (:func:`_set_up`: grid, compared
quantities, integrator, starting simulation), the interval starts (:func:`_interval_starts`), the
transcription and its solver (:func:`_transcribe`), the solve and polish (:func:`_solve`), and the
statistics and result (:func:`_result`).

Success, as the default path's (:mod:`.estimate`, step 7): the solver converged, the identified
model runs through the recording, no parameter ends on a bound, and the identified model simulated
from its initial state through the whole recording (single shooting, whatever the transcription:
a local minimum of multiple shooting may keep its joins open) fits each channel's positions
(:mod:`.plausibility`: pooled fit >= 95 % in noise units or white residuals, RMS <= 3 x the
declared noise). On 1 s of Exudyn's twobar from markers, fitted with bar 2 twice as heavy and the
torsion springs free to go negative, IPOPT ended 'acceptable' off every bound (kt1 270 x its value,
the objective 1.2e5 x the right model's), the identified model reproducing 91 % of the motion with
structured residuals, and said success.
"""


from __future__ import annotations

import time
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np

from casflex import codegen
from casflex.data import MeasurementSet
from casflex.identification import plausibility as pl
from casflex.identification import problem as pb
from casflex.identification.choices import RESIDUES, TRANSCRIPTIONS  # noqa: F401 (re-exported)
from casflex.identification.measurement import Experiment
from casflex.identification.options import ModelRun, Shooting, Solver
from casflex.identification.problem import IdentificationResult
from casflex.identification.shooting_intervals import SingleShooting, StepData, Transcription
from casflex.identification.shooting_solver import gauss_newton_nlpsol
from casflex.identification.shooting_starts import SlowStart, data_states
from casflex.model import Model

if TYPE_CHECKING:
    from casflex.integrators.hht import HHT

__all__ = ["identify_nlp", "RESIDUES", "TRANSCRIPTIONS"]


def _grid(data: MeasurementSet, horizon: float, dt: float) -> tuple[float, int, np.ndarray]:
    """HHT step h (s), number of steps N, and the data row of each step 1..N from the first sample
    (-1: no sample), shape (N,)."""
    if data.t.size < 2:
        raise ValueError("data: the indirect method needs a time series (at least 2 samples)")
    h = float(dt)  # checked by ModelRun (or the scene's)
    if not (np.isfinite(horizon) and horizon > 0):
        raise ValueError(f"horizon: must be a positive number of seconds, got {horizon!r}")
    N = int(round(horizon / h))
    if N < 1 or abs(N * h - horizon) > 1e-6 * h:
        raise ValueError(f"horizon: {horizon:g} s is not a whole number of steps dt = {h:g} s")
    t0 = float(data.t[0])
    if horizon > data.t[-1] - t0 + 1e-9 * h:
        raise ValueError(f"horizon: {horizon:g} s goes beyond the data ({data.t[-1] - t0:g} s from its first sample)")
    k = (data.t - t0) / h
    on_grid = np.abs(k - np.round(k)) <= 1e-6
    rows = np.full(N, -1)
    for i in np.flatnonzero(on_grid):
        step = int(round(k[i]))
        if 1 <= step <= N:
            rows[step - 1] = i
    return h, N, rows


def _intervals(N: int, interval: int | None, transcription: str) -> list[int]:
    """Step counts of the shooting intervals (as equal as possible; the longer ones first)."""
    if transcription == "single-shooting":
        return [N]
    K = 20 if interval is None else interval  # checked by Shooting
    M = max(1, round(N / K))
    base, extra = divmod(N, M)
    return [base + 1] * extra + [base] * (M - extra)


def _channel_kinematics(model: Model, names: list[str], orders: int) -> ca.Function:
    """``channels(q, qd, qdd) -> (y, y', y'')[:orders]`` of the channels ``names``: a node's dof is
    its own value; a marker's coordinate its position y(q) (:func:`casflex.model.markers.marker_kinematics`),
    velocity y' = J qd and acceleration y'' = J qdd + (dJ/dq qd) qd, J = dy/dq."""
    from casflex.model.markers import channel_index, marker_kinematics

    q, qd, qdd = (ca.SX.sym(s, model.n_dof) for s in ("q", "qd", "qdd"))
    idx = [channel_index(model, c) for c in names]
    if max(idx) < model.n_dof:  # nodes' dofs only: plain selections
        out = [q[idx], qd[idx], qdd[idx]]
    else:
        y, yd, J, Jd = marker_kinematics(model)(q, qd)
        out = [ca.vertcat(q, y)[idx], ca.vertcat(qd, yd)[idx],
               ca.vertcat(qdd, ca.mtimes(J, qdd) + ca.mtimes(Jd, qd))[idx]]
    return ca.Function("channels", [q, qd, qdd], out[:orders])


def _state_channels(model: Model, nx: int, names: list[str], orders: int) -> ca.Function:
    """``channels_of_state(x) -> (y, dy/dx)``: the compared quantities (n_o = len(names) orders,) of
    an HHT state x = [q, qd, qdd, lam] (positions, then velocities, then accelerations) and their
    Jacobian (n_o, nx)."""
    n = model.n_dof
    x = ca.SX.sym("x", nx)
    y = ca.vertcat(*_channel_kinematics(model, names, orders).call([x[:n], x[n:2 * n], x[2 * n:3 * n]]))
    return ca.Function("channels_of_state", [x], [y, ca.jacobian(y, x)], ["x"], ["y", "dy_dx"])


def _step_data(model: Model, data: MeasurementSet, names: list[str], rows: np.ndarray, weights: Sequence[float],
               residue: str, T: float) -> StepData:
    """The measured quantities and weights per step (:class:`.shooting_intervals.StepData`): each
    residue dimensionless, a length by the scene's length scale l (rotations by 1 rad), a velocity
    by l / T, an acceleration by l / T^2 (T: the horizon, s), times sqrt of its weight."""
    steps = np.flatnonzero(rows >= 0)
    dcols = [data.channels.index(c) for c in names]
    sq = np.sqrt(np.asarray(weights, dtype=float))
    inv_l = 1.0 / np.array([1.0 if c in model.dof_names and model.is_rotation[model.dof(c)] else model.length_scale
                            for c in names])
    blocks = [(sq[0] * inv_l, data.q)]
    if residue == "full":
        blocks += [(sq[1] * T * inv_l, data.qd), (sq[2] * T**2 * inv_l, data.qdd)]
    nch, N = len(names), rows.size
    Y, W = np.zeros((nch * len(blocks), N)), np.zeros((nch * len(blocks), N))
    for b, (wgt, values) in enumerate(blocks):
        Y[b * nch:(b + 1) * nch, steps] = values[np.ix_(rows[steps], dcols)].T
        W[b * nch:(b + 1) * nch, steps] = wgt[:, None]
    order = np.array([(b * nch + c, k) for b in range(len(blocks)) for k in steps for c in range(nch)])
    return StepData(Y, W, order)


@dataclass
class _SetUp:
    """What the stages share: the step h (s), the number of steps N, the first sample t0 (s), the
    horizon T (s), the compared channels, the per-step data, the integrator and its Newton scaling
    d and accepted residual tol_acc, the parameters' map and start p0, the samples' Nyquist
    omega_cut (rad/s) and the length per dof ell."""

    model: Model
    data: MeasurementSet
    h: float
    N: int
    t0: float
    T: float
    names: list[str]
    step_data: StepData
    integ: HHT
    d: np.ndarray
    tol_acc: float
    pmap: pb.ParameterMap
    p0: np.ndarray
    omega_cut: float
    ell: np.ndarray
    channels: ca.Function
    samples: int
    noise: float | Mapping[str, float] | None


def _check_arguments(model: Model, data: MeasurementSet, residue: str, initial_state: str,
                     transcription: str) -> None:
    """ValueError for a combination of options this transcription does not take, before any work (each
    option's own values are checked by its object, :mod:`.options`)."""
    if model.n_p == 0:
        raise ValueError("the scene declares no parameters to identify ([[parameters]] in the scene file)")
    if initial_state not in ("scene", "estimate"):
        raise ValueError(f"initial_state: expected 'scene' or 'estimate' for the NLP transcription, got "
                         f"{initial_state!r}")
    if initial_state == "estimate" and residue != "positions":
        raise ValueError("initial_state 'estimate': with residue 'positions' (Eq. 16) only")
    if residue == "full" and (data.qd is None or data.qdd is None):
        raise ValueError("residue 'full' (Eq. 17) needs velocities and accelerations in the data")
    if transcription == "multiple-shooting" and residue == "full":
        warnings.warn("multiple shooting with residue 'full' (Eq. 17) is slow: on twobar 45 s for 0.69 s of data, "
                      "not done in 200 s for 3 s (docs/identification.md, Known limits); single shooting is "
                      "recommended for Eq. 17", stacklevel=3)


def _set_up(model: Model, data: MeasurementSet, horizon: float, dofs: Sequence[str] | None,
            weights: Sequence[float], residue: str, alpha: float, dt: float, start: Any, newton_tol: float,
            opts: pb.NLPOptions, noise: float | Mapping[str, float] | None = None) -> _SetUp:
    """The grid, compared channels and per-step data, the integrator, and a simulation at the start
    (its states' magnitudes set the accepted Newton residual)."""
    from casflex.simulate import Start, Stepping, integrator_for, simulate

    h, N, rows = _grid(data, horizon, dt)
    if not (rows >= 0).any():
        raise ValueError(f"data: no sample lies on the step grid k * {h:g} s within the horizon")
    # the compared channels, nodes' dofs and markers' coordinates, checked against model and data
    names = list(Experiment(data, channels=None if dofs is None else tuple(dofs), noise=noise).compared(model))
    integ = integrator_for(model, alpha=alpha, tol=newton_tol)
    pmap = pb.ParameterMap.of(model, opts.transform)
    pb.require_fixed_supports(model, "the NLP transcription (solver other than gauss-newton)")
    p0 = pb.start_values(model, start)
    T, t0 = N * h, float(data.t[0])
    guess = simulate(model, T, stepping=Stepping(dt=h, alpha=alpha, tol=newton_tol), p=p0, start=Start(t0=t0),
                     raise_on_failure=False)
    # a step converged when its residual is within newton_tol, or the round-off floor of the
    # scene's coordinates where that is higher (see HHT.tolerance)
    tol_acc = float(np.max(integ.tolerance(guess.q)))
    return _SetUp(model=model, data=data, h=h, N=N, t0=t0, T=T, names=names,
                  step_data=_step_data(model, data, names, rows, weights, residue, T), integ=integ,
                  d=np.array(integ.scale(model.q0, model.qd0, p0, h)).ravel(), tol_acc=tol_acc, pmap=pmap, p0=p0,
                  omega_cut=float(np.pi / np.median(np.diff(data.t))),  # the samples' Nyquist: faster modes alias
                  ell=np.where(model.is_rotation, 1.0, model.length_scale),
                  channels=_state_channels(model, integ.nx, names, 3 if residue == "full" else 1),
                  samples=int((rows >= 0).sum()), noise=noise)


def _interval_starts(s: _SetUp, interval: int | None, transcription: str, initial_state: str
                     ) -> tuple[list[int], list[SlowStart | None]]:
    """The intervals' step counts and starts: the scene's state (None) or, for the first with an
    estimated initial state and every later one, the slow manifold through the recording there."""
    lengths = _intervals(s.N, interval, transcription)
    first = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(int)
    est = initial_state == "estimate"
    # one pass of kinematic fits over the samples serves every start
    times = [s.t0] * est + [s.t0 + first[j] * s.h for j in range(1, len(lengths))]
    starts = [SlowStart(s.model, q_g, qd_g, t, s.p0, s.omega_cut, s.ell, s.T)
              for (q_g, qd_g), t in zip(data_states(s.model, s.data, s.names, times), times, strict=True)]
    return lengths, ([] if est else [None]) + starts


@dataclass
class _NLP:
    """The transcription and its solver: ``solver`` (nlpsol), ``ss`` the single-shooting residue,
    the start ``w0`` and bounds of the unknowns w = (theta, xi_0, ..., xi_(M-1)), ``n_u`` the
    single-shooting unknowns' count (theta, xi_0)."""

    tr: Transcription
    solver: ca.Function
    ss: SingleShooting
    w0: np.ndarray
    lbw: np.ndarray
    ubw: np.ndarray
    n_u: int


def _transcribe(s: _SetUp, lengths: list[int], starts: list[SlowStart | None], opts: pb.NLPOptions) -> _NLP:
    """The NLP on the interval Functions, its objective scaled to ~1 at the start (solver tolerances
    then mean the same on any data), its solver (compiled if asked) and the single-shooting residue."""
    tr = Transcription(s.model, s.integ, s.channels, s.step_data, lengths, s.h, s.t0, s.d, starts, s.pmap,
                       bool(opts.compiled))  # compiled: the slow manifold's Newton solve then one C code takes
    w0 = np.concatenate([s.pmap.theta(s.p0), *[x.xi0 for x in starts if x is not None]])
    lb_th, ub_th = s.pmap.bounds()
    n_xi = w0.size - s.model.n_p
    lbw, ubw = np.concatenate([lb_th, np.full(n_xi, -np.inf)]), np.concatenate([ub_th, np.full(n_xi, np.inf)])
    w = ca.MX.sym("w", tr.n_w)
    r, g = tr.value(w)
    r_start = np.array(ca.Function("residue", [w], [r])(w0)).ravel()
    f_scale = 1.0 / max(float(r_start @ r_start), 1e-30) if float(r_start @ r_start) > 0 else 1.0
    ss = tr.single_shooting()
    # IPOPT's dual infeasibility has a floor of ~1e-8 of its start from the HHT Newton tolerance
    # inside the model: it stops there and the Gauss-Newton polish finishes the job
    if opts.hessian == "exact":
        solver = opts.nlp("indirect", w, ca.vec(r), g, f_scale=f_scale, tol=1e-8)
        ss = codegen.compiled(ss) if opts.compiled else ss
    else:
        nlp = {"x": w, "f": 0.5 * f_scale * ca.sumsqr(r), "g": g}
        solver, extra = gauss_newton_nlpsol("indirect", opts.solver, nlp,
                                            lambda triu: tr.gauss_newton(f_scale, triu), compiled=bool(opts.compiled),
                                            verbose=opts.verbose, solver_options=opts.solver_options, tol=1e-8,
                                            extra=[ss])
        ss = extra[ss.name()]
    return _NLP(tr, solver, SingleShooting(ss, tr, s.tol_acc), w0, lbw, ubw, tr.n_u)


def _solve(nlp: _NLP, polish: int) -> dict[str, Any]:
    """The NLP solver from the start, then ``polish`` Gauss-Newton steps on single shooting: the
    solver's answer ``w``, the polished single-shooting unknowns ``u``, the steps taken, the
    solver's stats, the largest constraint violation and the times (s)."""
    t_solve = time.perf_counter()
    sol = nlp.solver(x0=nlp.w0, lbx=nlp.lbw, ubx=nlp.ubw, lbg=0.0, ubg=0.0)
    solver_s = time.perf_counter() - t_solve
    w = np.array(sol["x"]).ravel()
    n = nlp.n_u
    u, polished = pb.gauss_newton_polish(nlp.ss, w[:n], nlp.lbw[:n], nlp.ubw[:n], polish)
    g = np.array(sol["g"]).ravel()
    return {"w": w, "u": u, "polished": polished, "stats": nlp.solver.stats(), "solver_s": solver_s,
            "solve_s": time.perf_counter() - t_solve,
            "constraint_violation": float(np.abs(g).max()) if nlp.tr.M > 1 else 0.0}


def _residuals(s: _SetUp, X: np.ndarray, initial_state: str) -> tuple[list[str], dict[str, Any]]:
    """The identified model's positions of the compared channels against the recording, each channel in
    noise units (:mod:`.plausibility`, the default path's rules): why they withhold success, and the
    record of ``extra["experiments"]["data"]`` (as the default path's).

    X (nx, N): the states after steps 1..N simulated by single shooting from the identified initial
    state (not the transcription's intervals, whose joins a local minimum may leave open). Residue
    "full": its positions only, as the default path compares them."""
    nch, n = len(s.names), s.model.n_dof
    pos = s.step_data.order[s.step_data.order[:, 0] < nch]  # (channel, step - 1) of every position sample
    c, k = pos[:, 0], pos[:, 1]
    y = s.step_data.Y[c, k]
    model_y = np.array(_channel_kinematics(s.model, s.names, 1).map(s.N)(X[:n], X[n:2 * n], X[2 * n:3 * n]))
    r = model_y[c, k] - y
    ok = np.isfinite(y) & np.isfinite(r)
    c, k, y, r = c[ok], k[ok], y[ok], r[ok]
    record: dict[str, Any] = {"initial_state": initial_state, "samples": int(y.size), "t0": s.t0,
                              "t_end": s.t0 + s.N * s.h, "channels": list(s.names), "residuals": {}, "noise": None}
    if not np.isfinite(X).all():  # the model does not run through: said by the Newton check
        return [], record
    rms = {name: float(np.sqrt(np.mean(r[c == j] ** 2))) for j, name in enumerate(s.names) if (c == j).any()}
    rotation = np.array([name in s.model.dof_names and bool(s.model.is_rotation[s.model.dof(name)])
                         for name in s.names])
    sigma, estimated = pl.noise_units(s.names, rms, rotation, s.model.length_scale, s.noise)
    res = pl.channel_residuals(s.t0 + s.h * (k + 1), c, s.names, y, r, sigma, s.model.length_scale, s.noise)
    record.update(residuals=res, noise=pl.noise_record(s.noise, estimated, res))
    return pl.residual_reasons("data", res), record


def _result(s: _SetUp, nlp: _NLP, out: dict[str, Any], build_s: float, record: dict[str, Any]
            ) -> IdentificationResult:
    """The identified parameters with the Gauss-Newton statistics of the single-shooting residue (as
    computed, also where a step missed the Newton tolerance, then said in the message), the
    multipliers (joint reactions) over the window, and success only where the default path's rules
    hold (:func:`_residuals`)."""
    model, pmap, n, n_p = s.model, s.pmap, s.model.n_dof, s.model.n_p
    u = out["u"]
    p_hat = pmap.p(u[:n_p])
    z, J, X, newton_res = nlp.ss.evaluate(u)
    stats = pb.gauss_newton_statistics(J, z, n_p, model.parameter_names, pmap.dp_dtheta(u[:n_p]), p_hat)
    converged = bool(newton_res <= s.tol_acc and np.isfinite(X).all())
    st, pn = out["stats"], model.parameter_names
    at_bound = pb.bound_flags(model, p_hat, pmap.scale, pb.pressed_on_bounds(J, z, u, *pmap.bounds()))
    # as the default path (estimate): the solver converged, the model runs through, no parameter on a bound
    other = [] if st.get("success", False) else [f"the solver did not converge ({st.get('return_status')})"]
    if not converged:
        other.append(f"HHT Newton did not converge within the horizon at the identified parameters (largest scaled "
                     f"residual {newton_res:.3g} > tol {s.tol_acc:g}): the identified model does not run through "
                     "the recording")
    if bound := [k for k, v in at_bound.items() if v]:  # no optimum inside the range
        other.append(f"{', '.join(bound)} ended on a bound: the best fit lies outside the parameters' range (a "
                     "local minimum: try other starts, --starts N; a wrong scene or a model that misses the physics)")
    # and the identified model's own simulation fits the recording or leaves white residuals, within the noise
    residual, experiment = _residuals(s, X, record["initial_state"])
    reasons = other + residual + pb.undetermined_reasons(stats["std_errors"], stats["weakest_direction"])
    return IdentificationResult(
        method="indirect", solver=record.pop("solver"), parameters=dict(zip(pn, p_hat.tolist(), strict=True)),
        start=dict(zip(pn, s.p0.tolist(), strict=True)), success=not reasons,
        status=str(st.get("return_status", "unknown")), message="; ".join(reasons),
        iterations=int(st.get("iter_count", -1)), wall_build_s=build_s, wall_solve_s=out["solve_s"],
        objective=0.5 * float(z @ z), std_errors=stats.pop("std_errors"), correlation=stats.pop("correlation"),
        at_bound=at_bound, identifiability=stats,
        instants=(s.t0 + s.h * np.arange(1, s.N + 1)).tolist(), multipliers=X[3 * n:, :].T.tolist(),
        extra={**record, "steps": s.N, "dt": s.h, "intervals": nlp.tr.M,
               "samples": s.samples,
               "constraint_violation": out["constraint_violation"], "gauss_newton_polish": out["polished"],
               "solver_s": out["solver_s"], "experiments": {"data": experiment},
               "refusal": {"residuals": residual, "other": other},
               "solver_parameters": dict(zip(pn, pmap.p(out["w"][:n_p]).tolist(), strict=True))},
    )


def identify_nlp(
    model: Model,
    data: MeasurementSet | Experiment,
    horizon: float,
    *,
    shooting: Shooting | None = None,
    run: ModelRun | None = None,
    solver: Solver | None = None,
    start: float | dict[str, float] | np.ndarray | None = None,
) -> IdentificationResult:
    """Output-error identification over [t0, t0 + ``horizon``] s as an NLP (t0: the first sample).

    Parameters
    ----------
    model : Model
        Its declared parameters are the unknowns, with their bounds.
    data : MeasurementSet or Experiment
        Samples on the step grid t0 + k dt (others are ignored); positions for Eq. 16, plus
        velocities and accelerations for Eq. 17. An Experiment says which channels are compared (nodes'
        dofs and markers' coordinates, e.g. ``("x3", "y3", "xm2", "ym2")``; default every channel of the
        data; a marker is compared through its kinematics y(q), y' = J q', y'' = J q'' + (dJ/dq q') q',
        :mod:`casflex.model.markers`), its noise (for the residual checks of ``success``, module
        docstring; default estimated from the residuals) and its initial state: the scene's, or
        ``"estimate"``: on the slow manifold through the recording's first samples with its slow-mode
        amplitudes and rates as unknowns (as the interval starts of multiple shooting; residue positions only).
    horizon : float, s
        End of the compared window (a whole number of steps).
    shooting : Shooting, optional
        Transcription, steps per interval, residue (Eq. 16 or 17) and Eq. 15's weights; default multiple
        shooting on positions, 20 steps per interval.
    run : ModelRun, optional
        HHT step and alpha of the model and its Newton tolerance; default dt = 1e-3 s, alpha = 0, 1e-14.
    solver : Solver, optional
        How the NLP is solved (here IPOPT, the Gauss-Newton Hessian, not compiled by default;
        ``hessian="exact"`` means second derivatives through every HHT Newton solve, several times slower)
        and ``polish``: Gauss-Newton steps on the single-shooting problem after the solver (0: none).
    start : factor, dict or array, optional
        Starting parameters (a number multiplies the nominal values).

    Returns
    -------
    IdentificationResult
        ``parameters`` after the polish, standard errors from the single-shooting Jacobian,
        ``multipliers`` (N, n_con) after each step; ``extra`` holds the solver's own answer
        (``solver_parameters``), the intervals, the largest constraint violation, the times, the
        identified model's residual analysis (``experiments["data"]["residuals"]``, as the default
        path's) and why success is withheld (``refusal``: {"residuals", "other"}; module docstring).
    """
    shooting = shooting or Shooting("multiple-shooting")
    run = run or ModelRun(dt=1e-3, alpha=0.0, newton_tol=1e-14)
    solver = solver or Solver()
    opts = solver.nlp_options("the NLP transcription")
    exp = data if isinstance(data, Experiment) else None
    data = data.data if exp is not None else data
    initial_state, dofs, noise = ("scene", None, None) if exp is None else (exp.initial_state, exp.channels, exp.noise)
    transcription, residue, weights = shooting.transcription, shooting.residue, shooting.weights
    _check_arguments(model, data, residue, initial_state, transcription)
    dt, alpha = run.of(model.scene)
    t_build = time.perf_counter()
    s = _set_up(model, data, horizon, dofs, weights, residue, alpha, dt, start, run.newton_tol, opts, noise)
    nlp = _transcribe(s, *_interval_starts(s, shooting.interval, transcription, initial_state), opts)
    build_s = time.perf_counter() - t_build
    out = _solve(nlp, solver.polish)
    record = {"solver": opts.solver, **opts.record(), "transcription": transcription, "residue": residue,
              "dofs": s.names, "weights": list(weights), "initial_state": initial_state}
    return _result(s, nlp, out, build_s, record)
