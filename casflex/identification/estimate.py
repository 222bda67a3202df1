"""Output-error identification from recordings: the procedure around :mod:`.output_error`.

1. Check every recording against the scene (:func:`.measurement.check_against_scene`).
2. Start: the parameters from ``start``; unknown initial states from :func:`.measurement.initial_guess`,
   corrected by the fit along the slow modes only (:func:`.measurement.slow_modes`).
3. Fit (:func:`.output_error.fit`) within the :class:`Budget`, on a growing horizon: the first
   :data:`FIRST_WINDOW` s of every recording, then windows twice as long, each stage starting
   from the last, up to the whole recording. Over a short window the motion depends almost
   linearly on the initial state and the parameters; over seconds a pendulum's does not, and a
   fit of the whole recording from a guessed initial state ends in a local minimum (twobar,
   0.5-2.5 s at 0.5 mm noise: 72 % fit without the stages; see the study realdata). The stages
   before the last only bring a start: they take at most STAGE_RUNS model runs and hold what
   their window cannot tell near the start (:class:`_Anchored`).
4. Model error (``model_error="refine"``): the same fit on a refined model (every beam in twice
   the elements, half the step) from the first fit's answer. The model's error in the parameters
   is estimated as 4/3 of the change, Richardson's factor for a method of second order in element
   size and step: measured on twobar against data from Exudyn, the error of the fitted kt3 fell
   from 0.45 % (1 element, 1 ms) to 0.053 % (2, 0.5 ms) and 0.005 % (4, 0.25 ms).
5. Uncertainty: the noise part, the larger of the HAC standard error of the fit
   (:func:`.statistics.sandwich_covariance`: residuals correlated in time) and the plain Gauss-Newton
   one (a HAC below the plain error would rest on a bandwidth estimated from the same record, with no
   evidence of its own), and the model error, added in quadrature: ``std_errors``. Both parts are
   reported beside them. ``weak``: parameters whose total relative standard error exceeds 10 %.
6. Residual analysis per experiment and channel, and the success rule: the solver converged,
   no parameter ends on a bound, every channel's fit (100 (1 - |y - y_model| / |y - mean y|)
   percent, the measure system identification toolboxes report) is at least 95 % or its residual
   is white (a channel that hardly moves beyond its noise), the residual RMS is at most 3 times
   the declared noise (when declared), and the identified model runs through every recording.
   Otherwise ``success`` is False and ``message`` says why.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence

import numpy as np

from casflex.codegen import log
from casflex.identification.choices import MODEL_ERRORS  # noqa: F401 (re-exported)
from casflex.identification.initial_state import initial_state_of
from casflex.identification.measurement import Experiment, check_against_scene
from casflex.identification.output_error import Budget, Fit, OutputError, StartDoesNotRun, fit
from casflex.identification.problem import (
    ParameterMap,
    bound_flags,
    gauss_newton_statistics,
    start_values,
)
from casflex.identification.result import IdentificationResult
from casflex.identification.statistics import residual_analysis, sandwich_covariance
from casflex.model import Model, assemble

__all__ = ["estimate", "MODEL_ERRORS", "FIT_THRESHOLD"]

#: A channel fitted below this fraction of its measured motion makes the result implausible.
FIT_THRESHOLD = 0.95
#: Richardson's factor for a second-order method refined by 2: error(h) = 4/3 (p(h) - p(h/2)).
RICHARDSON = 4.0 / 3.0
#: Length (s) of the first window of the growing horizon.
FIRST_WINDOW = 0.25
#: How often a window of the growing horizon may be shortened before the fit ends where it is.
MAX_CUTS = 4
#: Weight of the start in the stages before the last (:class:`_Anchored`), relative to the best-felt parameter.
ANCHOR = 1e-6
#: Model runs a stage before the last may take: it only has to bring a start for the next.
STAGE_RUNS = 20


def _cut(experiments: list[Experiment], window: float) -> list[Experiment]:
    """The experiments' first ``window`` s (an experiment with fewer than 2 samples there: whole)."""
    cut = []
    for e in experiments:
        t0 = float(e.data.t[0])
        data = e.data.window(t0, t0 + window)
        cut.append(dataclasses.replace(e, data=data) if data.t.size >= 2 else e)
    return cut


class _Anchored:
    """A stage of the growing horizon short of the whole recording, its parameters tied to the start.

    Rows sqrt(lam) (theta - theta_start) join the residuals, lam = ANCHOR times the largest
    diagonal entry of J^T J over the parameters at the stage's start: a direction that the window
    determines ANCHOR^(-1/2) = 1000 times worse (in standard errors) than the best one stays near
    the start instead of running off; the others are hardly touched. The last stage, the fit that
    is reported, has no anchor. Without it, twobar with dampers mid-motion (eight parameters and
    the initial state from 0.25 s of data) sent kt1 to 210 x its value and ran out of model runs
    in 7 of 10 seeds.
    """

    def __init__(self, problem: OutputError, theta0: np.ndarray):
        self.problem, self.theta0, self.weight = problem, np.asarray(theta0, dtype=float), None

    def __getattr__(self, name: str):  # bounds, evaluations, ...: the stage's own
        return getattr(self.problem, name)

    def evaluate(self, w: np.ndarray, jacobian: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        r, J = self.problem.evaluate(w, jacobian)
        n_p = self.theta0.size
        if self.weight is None:
            if J is None:
                _, J = self.problem.evaluate(w, True)
            self.weight = np.sqrt(ANCHOR * float(np.max(np.sum(J[:, :n_p] ** 2, axis=0), initial=0.0)))
        r = np.concatenate([r, self.weight * (w[:n_p] - self.theta0)])
        if J is not None:
            rows = np.zeros((n_p, J.shape[1]))
            rows[:, :n_p] = self.weight * np.eye(n_p)
            J = np.vstack([J, rows])
        return r, J


def _fit_growing(model: Model, experiments: list[Experiment], w0: np.ndarray, budget: Budget, *,
                 verbose: bool, **setup) -> tuple[OutputError, Fit]:
    """Fit on the growing horizon (module docstring, step 3); the budget covers all stages.

    A window at whose start (the last window's answer) the model does not run through is shortened
    toward the last one, halving the growth up to MAX_CUTS times (threelink mid-motion at 1 mm: the
    answer for 0.25 s did not run through 0.5 s in 2 of 10 seeds); then the fit ends there, reported
    as not converged, with the window it reached.
    """
    t_start = time.perf_counter()
    span = max(float(e.data.t[-1] - e.data.t[0]) for e in experiments)
    w, runs, reached, window, cuts = w0, 0, 0.0, FIRST_WINDOW, 0
    problem = f = None
    while True:
        last = window >= span * (1 - 1e-9)
        stage = experiments if last else _cut(experiments, window)
        left = budget.max_time - (time.perf_counter() - t_start)
        runs_left = max(1, budget.max_iterations - runs)
        sub = Budget(max_iterations=runs_left if last else min(runs_left, STAGE_RUNS), max_time=max(left, 1e-3))
        try:
            stage_problem = OutputError(model, stage, **setup)
            stage_fit = fit(stage_problem if last else _Anchored(stage_problem, w0[:model.n_p]), w, sub,
                            verbose=verbose)
        except StartDoesNotRun as exc:
            if f is None:  # the user's start: say so
                raise
            if cuts == MAX_CUTS:
                return problem, dataclasses.replace(
                    f, converged=False, iterations=runs, solve_s=time.perf_counter() - t_start,
                    message=f"the growing horizon stopped at {reached:.3g} s: with the parameters fitted to it {exc}")
            cuts += 1
            window = reached + (window - reached) / 2
            continue
        problem, f = stage_problem, stage_fit
        log.info("growing horizon to %.3g s: %s after %d model runs, %.1f s", window, f.status, f.iterations, f.solve_s)
        runs += f.iterations
        w, reached, cuts = f.w, window, 0
        if last:
            return problem, dataclasses.replace(f, iterations=runs, solve_s=time.perf_counter() - t_start)
        if f.status == "time_limit" or runs >= budget.max_iterations:  # out of budget before the whole recording
            why = f.message if f.status == "time_limit" else \
                f"stopped at the iteration limit ({budget.max_iterations} model runs)"
            n_p = model.n_p  # the anchor's rows off: the data's residuals and Jacobian
            return problem, dataclasses.replace(f, r=f.r[:-n_p], J=f.J[:-n_p], converged=False, iterations=runs,
                                                solve_s=time.perf_counter() - t_start,
                                                message=f"{why} (fitting the first {reached:.3g} s)")
        window = min(2 * window, span)


def refined(model: Model) -> Model:
    """The model with every beam meshed into twice its elements."""
    scene = model.scene
    beams = tuple(dataclasses.replace(b, elements=2 * b.elements) for b in scene.beams)
    return assemble(dataclasses.replace(scene, beams=beams), inertia=model.inertia)


def transfer_state(model: Model, fine: Model, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A state of ``model`` on the nodes of ``fine`` (same scene, finer mesh): shared nodes copied,
    the new mesh nodes interpolated linearly along their beam's nodes in ``model``."""
    out_q, out_qd = np.zeros(fine.n_dof), np.zeros(fine.n_dof)
    chains = {}
    for b in model.scene.beams:
        names = [b.nodes[0], *(f"{b.name}.{k}" for k in range(1, b.elements)), b.nodes[1]]
        chains[b.name] = (np.linspace(0.0, 1.0, b.elements + 1), names)
    fine_elements = {b.name: b.elements for b in fine.scene.beams}
    scene_nodes = {n.name for n in model.scene.nodes}
    for i, dof in enumerate(fine.dof_names):
        kind = next(k for k in ("theta", "x", "y") if dof.startswith(k))
        if dof[len(kind):] in scene_nodes:  # a mesh node's name ("<beam>.<k>") means another point in each mesh
            j = model.dof(dof)
            out_q[i], out_qd[i] = q[j], qd[j]
            continue
        beam, k = dof[len(kind):].rsplit(".", 1)
        s_all, names = chains[beam]
        s = int(k) / fine_elements[beam]
        a = int(np.clip(np.searchsorted(s_all, s, side="right") - 1, 0, len(names) - 2))
        u = (s - s_all[a]) / (s_all[a + 1] - s_all[a])
        ja, jb = model.dof(kind + names[a]), model.dof(kind + names[a + 1])
        out_q[i] = (1 - u) * q[ja] + u * q[jb]
        out_qd[i] = (1 - u) * qd[ja] + u * qd[jb]
    return out_q, out_qd


def initial_states(model: Model, experiments: list[Experiment], p: np.ndarray,
                   states: list[tuple[np.ndarray, np.ndarray]] | None = None) -> list:
    """Every experiment's :class:`~.initial_state.InitialState` at its guess (or the given states)."""
    return [initial_state_of(model, e, p, None if states is None else states[i]) for i, e in enumerate(experiments)]


def _model_error(model: Model, experiments: list[Experiment], first: Fit, problem: OutputError, *, dt: float,
                 alpha: float, transform: str, budget: Budget, compiled: bool, newton_tol: float,
                 verbose: bool) -> tuple[np.ndarray, dict]:
    """The parameters' discretisation error (module docstring, step 4) and a record of the refit."""
    fine = refined(model)
    pmap = ParameterMap.of(fine, transform)
    p1 = problem.pmap.p(first.w[:model.n_p])
    states = [transfer_state(model, fine, *problem.state(first.w, e)) for e in range(len(experiments))]
    prob = OutputError(fine, experiments, dt=dt / 2, alpha=alpha, pmap=pmap, compiled=compiled, newton_tol=newton_tol,
                       initial=initial_states(fine, experiments, p1, states))
    w0 = prob.pack(first.w[:model.n_p])
    sub = Budget(max_iterations=min(30, budget.max_iterations), max_time=budget.max_time)
    try:
        f = fit(prob, w0, sub, verbose=verbose)
    except ValueError as exc:  # the refined model does not run from there
        return np.full(model.n_p, np.nan), {"error": str(exc)}
    p_coarse = problem.pmap.p(first.w[:model.n_p])
    p_fine = pmap.p(f.w[:model.n_p])
    err = RICHARDSON * np.abs(p_fine - p_coarse) if f.converged else np.full(model.n_p, np.nan)
    return err, {"parameters": dict(zip(model.parameter_names, p_fine.tolist(), strict=True)),
                 "elements": {b.name: b.elements for b in fine.scene.beams}, "dt": dt / 2,
                 "status": f.status, "iterations": f.iterations, "solve_s": f.solve_s}


def _channels(problem: OutputError, fitted: Fit, e: int, rows: np.ndarray) -> dict:
    """Residual analysis (data units) and fit of every channel of experiment e."""
    sm, exp = problem.maps[e], problem.experiments[e]
    r = fitted.r[rows] * problem.sigma[e]
    order = np.argsort(sm.time, kind="stable")
    res = residual_analysis(r[order], sm.channel[order], sm.channels, [np.arange(r.size)], exp.noise)
    for c, name in enumerate(sm.channels):
        if name in res:
            y = sm.y[sm.channel == c]
            spread = np.linalg.norm(y - y.mean())
            # a channel that does not move (a supported dof) has no motion to reproduce: no fit measure
            still = spread <= 1e-9 * np.sqrt(y.size) * max(problem.model.length_scale, float(np.abs(y).max()))
            res[name]["fit"] = None if still else float(1 - np.linalg.norm(r[sm.channel == c]) / spread)
    return res


def _plausibility(problem: OutputError, fitted: Fit, channels: list[dict], at_bound: dict[str, bool]) -> list[str]:
    """Why the result is not a plausible answer (empty: it is)."""
    reasons = []
    if not fitted.converged:
        reasons.append(fitted.message or f"the solver stopped without converging ({fitted.status})")
    bound = [k for k, v in at_bound.items() if v]
    if bound:
        reasons.append(f"{', '.join(bound)} ended on a bound: the best fit lies outside the parameters' range")
    for e, res in enumerate(channels):
        exp = problem.experiments[e]
        label = exp.name or f"experiment {e + 1}"
        for name, ch in res.items():
            # a low fit with white residuals is a channel that hardly moves beyond its noise
            if ch["fit"] is not None and ch["fit"] < FIT_THRESHOLD and not ch["white"]:
                reasons.append(f"{label}: the model reproduces only {100 * ch['fit']:.0f} % of the measured motion "
                               f"of {name} and leaves a structured residual (a local minimum, a wrong scene or a "
                               "model that misses the physics)")
            if exp.noise is not None and ch["rms"] > 3 * exp.noise:
                reasons.append(f"{label}: the residual RMS of {name} is {ch['rms'] / exp.noise:.1f} x the declared "
                               "noise: the model does not explain the data to the noise level")
    return reasons


def estimate(model: Model, experiments: Sequence[Experiment], *, dt: float | None = None, alpha: float | None = None,
             start: float | dict[str, float] | np.ndarray | None = None, transform: str = "linear",
             budget: Budget | None = None, compiled: bool = True, newton_tol: float = 1e-12,
             model_error: str = "refine", check_data: bool = True, verbose: bool = False) -> IdentificationResult:
    """Identify the model's parameters (and the unknown initial states) from ``experiments``.

    dt, alpha: the model's step (s) and HHT alpha (default: the scene's run settings, never the
    samples' spacing); the other options as in :func:`casflex.identification.identify_indirect`.
    """
    from casflex.simulate import simulate

    if model_error not in MODEL_ERRORS:
        raise ValueError(f"model_error: expected one of {MODEL_ERRORS}, got {model_error!r}")
    if model.n_p == 0:
        raise ValueError("the scene declares no parameters to identify ([[parameters]] in the scene file)")
    run = model.scene.run
    dt = float(run.dt if dt is None else dt)
    alpha = float(run.alpha if alpha is None else alpha)
    budget = budget or Budget()
    experiments = list(experiments)
    t_build = time.perf_counter()
    for i, e in enumerate(experiments):
        if not e.name:
            experiments[i] = e = dataclasses.replace(e, name=f"experiment {i + 1}" if len(experiments) > 1 else "data")
        if check_data:
            check_against_scene(model, e)
    pmap = ParameterMap.of(model, transform)
    p0 = start_values(model, start)
    setup = {"dt": dt, "alpha": alpha, "pmap": pmap, "compiled": compiled, "newton_tol": newton_tol,
             "initial": initial_states(model, experiments, p0)}
    problem = OutputError(model, experiments, **setup)
    w0 = problem.pack(pmap.theta(p0))
    build_s = time.perf_counter() - t_build

    t_solve = time.perf_counter()
    problem, f = _fit_growing(model, experiments, w0, budget, verbose=verbose, **setup)
    n_p, names = model.n_p, model.parameter_names
    p_hat = pmap.p(f.w[:n_p])
    dp = pmap.dp_dtheta(f.w[:n_p])
    me, refit = (_model_error(model, experiments, f, problem, dt=dt, alpha=alpha, transform=transform, budget=budget,
                              compiled=compiled, newton_tol=newton_tol, verbose=verbose)
                 if model_error == "refine" and f.converged else (np.zeros(n_p), {}))
    solve_s = time.perf_counter() - t_solve

    gn = gauss_newton_statistics(f.J, f.r, n_p, names, dp, p_hat)
    C, hac = sandwich_covariance(f.J, f.r, problem.groups())
    se_gn = np.array([gn["std_errors"][k] for k in names])
    se_hac = np.where(np.isinf(se_gn), np.inf, np.sqrt(np.maximum(np.diag(C)[:n_p], 0.0)) * np.abs(dp))
    # the noise part: HAC where it is the larger; never below the plain errors, since a HAC under them rests on a
    # bandwidth estimated from the same short record (a gait swing's 26 samples gave 15 against 51, issue 27)
    se_noise = np.fmax(se_hac, se_gn)
    total = np.sqrt(se_noise**2 + np.nan_to_num(me, nan=0.0) ** 2)
    rel = total / np.maximum(np.abs(p_hat), np.finfo(float).tiny)
    gn["weak"] = [k for k, v in zip(names, rel, strict=True) if not v <= 0.1]

    rows, start_row, channels, records = [], 0, [], {}
    trajectories, samples = [], []
    for e, exp in enumerate(experiments):
        sm = problem.maps[e]
        rows.append(np.arange(start_row, start_row + sm.y.size))
        start_row += sm.y.size
        channels.append(_channels(problem, f, e, rows[-1]))
        samples.append({"name": exp.name, "channels": sm.channels, "t": sm.time, "channel": sm.channel,
                        "measured": sm.y, "model": sm.y + f.r[rows[-1]] * problem.sigma[e]})
        q0, qd0 = problem.state(f.w, e)
        tr = simulate(model, sm.n_steps * dt, dt=dt, alpha=alpha, p=p_hat, q0=q0, qd0=qd0, t0=sm.t0,
                      compiled=compiled, tol=newton_tol, raise_on_failure=False)
        trajectories.append(tr)
        rec = {"initial_state": exp.initial_state, "samples": int(sm.y.size), "t0": sm.t0,
               "t_end": sm.t0 + sm.n_steps * dt, "channels": list(sm.channels), "residuals": channels[-1]}
        if exp.initial_state != "scene":
            se_q, se_qd = problem.state_errors(f.w, C, e)
            keys = ("q0", "qd0") if exp.initial_state == "estimate" else ("qd0",)
            for key, value, se in zip(("q0", "qd0"), (q0, qd0), (se_q, se_qd), strict=True):
                if key in keys:
                    rec[key] = {model.dof_names[i]: [float(value[i]), float(se[i])] for i in problem.free}
        records[exp.name] = rec
    at_bound = bound_flags(model, p_hat, pmap.scale)
    reasons = _plausibility(problem, f, channels, at_bound)
    reasons += [f"{exp.name}: the identified model does not run through the recording ({tr.message})"
                for exp, tr in zip(experiments, trajectories, strict=True) if not tr.success]
    notes = []
    if model_error == "refine" and f.converged and not np.isfinite(me).all():
        notes.append("the model error could not be estimated (the refined model's fit did not converge): the "
                     "standard errors hold the HAC part only")
    first = trajectories[0]
    return IdentificationResult(
        method="indirect", solver="gauss-newton", parameters=dict(zip(names, p_hat.tolist(), strict=True)),
        start=dict(zip(names, p0.tolist(), strict=True)), success=not reasons, status=f.status,
        message="; ".join(reasons + notes), iterations=f.iterations, wall_build_s=build_s, wall_solve_s=solve_s,
        objective=0.5 * float(f.r @ f.r), std_errors=dict(zip(names, total.tolist(), strict=True)),
        correlation=gn.pop("correlation"), at_bound=at_bound,
        identifiability={k: v for k, v in gn.items() if k != "std_errors"},
        instants=first.t.tolist(), multipliers=first.lam.tolist(),
        extra={"transcription": "single-shooting", "residue": "positions", "dofs": list(problem.maps[0].channels),
               "transform": transform, "dt": dt,
               "alpha": alpha, "steps": int(sum(sm.n_steps for sm in problem.maps)), "compiled": compiled,
               "budget": dataclasses.asdict(budget), "model_runs": problem.evaluations, "offset_se": f.offset,
               "uncertainty": {"gauss_newton": dict(zip(names, se_gn.tolist(), strict=True)),
                               "hac": dict(zip(names, se_hac.tolist(), strict=True)),
                               "model_error": dict(zip(names, me.tolist(), strict=True)),
                               "hac_bandwidth": hac["bandwidth"], "model_error_refit": refit},
               "experiments": records, "solver_s": f.solve_s},
        trajectories=tuple(trajectories), samples=tuple(samples),
    )
