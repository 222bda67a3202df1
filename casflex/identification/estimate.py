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
   before the last only bring a start: they stop within STAGE_SE of their own standard errors of
   their least-squares solution, take at most STAGE_RUNS model runs and hold what their window
   cannot tell near the start (:class:`_Anchored`); every stage after the first starts with
   Gauss-Newton steps from the last one's answer (``fit(near=True)``). Then, where an experiment's
   noise is not declared, each channel's noise is estimated by its residual RMS; when the channels
   (in the fit's weights) differ by more than REWEIGHT, the fit is repeated from its answer with
   each channel weighted by its own noise (feasible weighted least squares), and every later step
   uses those weights.
4. Model error (``model_error="refine"``): the same fit on a refined model (every beam in twice
   the elements, half the step) from the first fit's answer. The model's error in the parameters
   is estimated as 4/3 of the change, Richardson's factor for a method of second order in element
   size and step: measured on twobar against data from Exudyn, the error of the fitted kt3 fell
   from 0.45 % (1 element, 1 ms) to 0.053 % (2, 0.5 ms) and 0.005 % (4, 0.25 ms).
5. Model form (:mod:`.form`): every alternative form (the other beam theory, the ends of declared
   ranges, scenes given) fitted from the first fit's answer and compared with it by AIC; the
   Akaike-weighted RMS of a parameter's moves is its model-form error.
6. Uncertainty: the noise part, the larger of the HAC standard error of the fit
   (:func:`.statistics.sandwich_covariance`: residuals correlated in time) and the plain Gauss-Newton
   one (a HAC below the plain error would rest on a bandwidth estimated from the same record, with no
   evidence of its own), the model error and the model-form error, added in quadrature: ``std_errors``.
   Every part is reported beside them. ``weak``: parameters whose total relative standard error exceeds 10 %.
7. Residual analysis per experiment and channel, and the success rule: the solver converged,
   no parameter ends on a bound, each experiment's fit (100 (1 - |y - y_model| / |y - mean y|)
   percent, the measure system identification toolboxes report, pooled over its channels in noise
   units, :func:`pooled_fit`) is at least 95 % or its residuals are white, the residual RMS is at most 3 times
   the declared noise (when declared), the identified model runs through every recording, no
   alternative form fits the data decisively better, and no model-form error exceeds its parameter's
   noise standard error. Otherwise ``success`` is False and ``message`` says why.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence

import numpy as np

from casflex.codegen import log
from casflex.identification.choices import MODEL_ERRORS  # noqa: F401 (re-exported)
from casflex.identification.form import alternatives_of, compare_forms, form_part, form_reasons
from casflex.identification.initial_state import initial_states
from casflex.identification.measurement import Experiment, check_against_scene
from casflex.identification.options import GAUSS_NEWTON, ModelRun, Solver, Uncertainty
from casflex.identification.output_error import Budget, Fit, OutputError, StartDoesNotRun, chord_fit, fit
from casflex.identification.pinned import pinned
from casflex.identification.plausibility import (  # noqa: F401 (FIT_THRESHOLD, pooled_fit re-exported)
    FIT_THRESHOLD,
    REWEIGHT,
    noise_record,
    pooled_fit,
    residual_reasons,
)
from casflex.identification.priors import forms_with_nuisance, map_fit, prior_report
from casflex.identification.problem import (
    ParameterMap,
    bound_flags,
    gauss_newton_statistics,
    start_values,
    undetermined_reasons,
)
from casflex.identification.result import IdentificationResult
from casflex.identification.statistics import residual_analysis, sandwich_covariance
from casflex.model import Model, assembled
from casflex.scene.uncertain import declared_uncertain, nuisance_names

__all__ = ["estimate", "MODEL_ERRORS", "FIT_THRESHOLD"]

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
#: A stage before the last stops within this many of its standard errors of its least-squares solution:
#: its answer is only the next stage's start (twobar from 0.8 x: 33 model runs to the full tolerance).
STAGE_SE = 1.0
#: Model runs the refit with the channels' estimated noise may take (it starts at the fit's answer)
REWEIGHT_RUNS = 30
#: Huber's tuning constant in robust standard deviations (1.4826 x the channel's median absolute residual): 95 %
#: of least squares' efficiency on Gaussian noise (Huber 1981)
HUBER_C = 1.345
#: Reweighting rounds of a robust loss at most, and the change of every weight below which they stop
ROBUST_ROUNDS, ROBUST_TOL = 6, 0.01


def _named(model: Model, experiments: Sequence[Experiment], check_data: bool) -> list[Experiment]:
    """The experiments, each with a name ("data", or "experiment k" of several), checked against the scene."""
    out = [e if e.name else dataclasses.replace(e, name=f"experiment {i + 1}" if len(experiments) > 1 else "data")
           for i, e in enumerate(experiments)]
    for e in out if check_data else ():
        check_against_scene(model, e)
    return out


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
            stage_problem = OutputError(model, stage, previous=problem, **setup)
            stage_fit = fit(stage_problem if last else _Anchored(stage_problem, w0[:model.n_p]), w, sub,
                            verbose=verbose, near=f is not None, tol_se=None if last else STAGE_SE)
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
    return assembled(dataclasses.replace(scene, beams=beams), inertia=model.inertia)


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


def _model_error(model: Model, experiments: list[Experiment], first: Fit, problem: OutputError, *, dt: float,
                 alpha: float, transform: str, budget: Budget, compiled: bool, newton_tol: float,
                 verbose: bool) -> tuple[np.ndarray, dict]:
    """The parameters' discretisation error (module docstring, step 4) and a record of the refit."""
    fine = refined(model)
    pmap = ParameterMap.of(fine, transform)
    p1 = problem.pmap.p(first.w[:model.n_p])
    states = [transfer_state(model, fine, *problem.state(first.w, e)) for e in range(len(experiments))]
    prob = OutputError(fine, experiments, dt=dt / 2, alpha=alpha, pmap=pmap, compiled=compiled, newton_tol=newton_tol,
                       initial=initial_states(fine, experiments, p1, states), forms=False)
    w0 = prob.pack(first.w[:model.n_p])
    sub = Budget(max_iterations=min(30, budget.max_iterations), max_time=budget.max_time)
    try:
        # the coarse fit's Jacobian serves the refined model (the same unknowns, the parameters only: estimated
        # initial states are slow-mode amplitudes of each mesh's own modes, not the same unknowns): plain model runs
        # of the refined model, a fifth of one with sensitivities; the exact refit where it does not contract
        same = problem.n_unknowns == prob.n_unknowns == model.n_p
        f = (chord_fit(prob, w0, first.J, sub) if same else None) \
            or fit(prob, w0, sub, verbose=verbose, near=True)
    except ValueError as exc:  # the refined model does not run from there
        return np.full(model.n_p, np.nan), {"error": str(exc)}
    p_coarse = problem.pmap.p(first.w[:model.n_p])
    p_fine = pmap.p(f.w[:model.n_p])
    err = RICHARDSON * np.abs(p_fine - p_coarse) if f.converged else np.full(model.n_p, np.nan)
    return err, {"parameters": dict(zip(model.parameter_names, p_fine.tolist(), strict=True)),
                 "elements": {b.name: b.elements for b in fine.scene.beams}, "dt": dt / 2,
                 "status": f.status, "iterations": f.iterations, "solve_s": f.solve_s}


def channel_noise(problem: OutputError, fitted: Fit) -> list[dict[str, float]]:
    """Per experiment, each channel's residual RMS at the fit (data units): the noise the fit implies."""
    out: list[dict[str, float]] = [{} for _ in problem.experiments]
    for (e, name), x in problem.channel_residuals(fitted.r).items():
        out[e][name] = float(np.sqrt(np.mean(x**2)))
    return out


def _reweighted(problem: OutputError, fitted: Fit) -> list[Experiment] | None:
    """The experiments with each channel's noise estimated from the fit (those of undeclared noise whose
    channels' weighted RMS differ by more than REWEIGHT), or None when no experiment needs it. Exact data
    (a channel's RMS below 1e-9 of the scene's size) is left alone."""
    noise, out, changed = channel_noise(problem, fitted), [], False
    floor = 1e-9 * problem.model.length_scale
    for e, exp in enumerate(problem.experiments):
        sm, rms = problem.maps[e], noise[e]
        weighted = [rms[c] / problem.sigma[e][sm.channel == k][0] for k, c in enumerate(sm.channels) if c in rms]
        if exp.noise is None and rms and min(rms.values()) > floor and max(weighted) > REWEIGHT * min(weighted):
            out.append(dataclasses.replace(exp, noise=dict(rms)))
            changed = True
        else:
            out.append(exp)
    return out if changed else None


def _refit_weighted(model: Model, experiments: list[Experiment], f: Fit, setup: dict, budget: Budget,
                    t_solve: float, verbose: bool) -> tuple[OutputError, Fit]:
    """The fit repeated from its answer with the channels weighted by their estimated noise (step 3)."""
    left = budget.max_time - (time.perf_counter() - t_solve)
    problem = OutputError(model, experiments, **setup)
    g = fit(problem, f.w, Budget(min(REWEIGHT_RUNS, budget.max_iterations), max(left, 1e-3)), verbose=verbose,
            near=True)
    return problem, dataclasses.replace(g, iterations=f.iterations + g.iterations, solve_s=f.solve_s + g.solve_s)


def _loss_weights(problem: OutputError, f: Fit) -> list[np.ndarray]:
    """Per experiment, Huber's weight of every (sample, compared channel) at the fit: the residual u in
    robust standard deviations of its channel, w = min(1, HUBER_C / |u|), the weights that make reweighted
    least squares minimise Huber's loss."""
    out = []
    for e, sm in enumerate(problem.maps):
        rows = slice(problem.row_offsets[e], problem.row_offsets[e + 1])
        r = f.r[rows] * problem.sigma[e]  # data units, as measured
        W = np.ones((problem.experiments[e].data.t.size, len(sm.channels)))
        for c in range(len(sm.channels)):
            sel = sm.channel == c
            scale = 1.4826 * float(np.median(np.abs(r[sel])))
            u = np.abs(r[sel]) / scale if scale > 0 else np.zeros(int(sel.sum()))
            W[sm.sample[sel], c] = np.minimum(1.0, HUBER_C / np.maximum(u, 1e-300))
        out.append(W)
    return out


def _huber_bread(problem: OutputError) -> np.ndarray | None:
    """The rows' bread factors psi'(u) / w(u) of Huber's loss (1 inside, 0 where a sample is weighted
    down), or None without a robust loss."""
    if all(e.loss_weights is None for e in problem.experiments):
        return None
    return np.concatenate([(e.loss_weights[sm.sample, sm.channel] >= 1.0).astype(float)
                           for e, sm in zip(problem.experiments, problem.maps, strict=True)]
                          + [np.ones(problem.n_prior)])  # the priors' rows: least squares


def _robust_fit(model: Model, problem: OutputError, f: Fit, setup: dict, budget: Budget, t_solve: float,
                loss: str, verbose: bool) -> tuple[list[Experiment], OutputError, Fit, dict]:
    """Iteratively reweighted least squares for a robust loss, each round from the last answer, until no
    weight changes by ROBUST_TOL (at most ROBUST_ROUNDS); the record of the weights."""
    experiments, rounds, change = problem.experiments, 0, np.inf
    while rounds < ROBUST_ROUNDS and change > ROBUST_TOL and f.converged:
        W = _loss_weights(problem, f)
        change = max(float(np.abs(w - (e.loss_weights if e.loss_weights is not None else 1.0)).max())
                     for w, e in zip(W, experiments, strict=True))
        experiments = [dataclasses.replace(e, loss_weights=w) for e, w in zip(experiments, W, strict=True)]
        problem, f = _refit_weighted(model, experiments, f, setup, budget, t_solve, verbose)
        rounds += 1
    low = []
    for e, sm in enumerate(problem.maps):
        w = experiments[e].loss_weights[sm.sample, sm.channel]
        low += [(float(w[j]), experiments[e].name, sm.channels[sm.channel[j]], float(sm.time[j]))
                for j in np.flatnonzero(w < 0.5)]
    n = sum(sm.y.size for sm in problem.maps)
    return experiments, problem, f, {
        "loss": loss, "c": HUBER_C, "rounds": rounds, "converged": change <= ROBUST_TOL,
        "below_half": len(low), "samples": n,
        "lowest": [{"weight": w, "experiment": x, "channel": c, "t": t} for w, x, c, t in sorted(low)[:1000]]}


def _channels(problem: OutputError, fitted: Fit, e: int, rows: np.ndarray, declared) -> dict:
    """Residual analysis (data units) and fit of every channel of experiment e (``declared``: its declared noise)."""
    sm = problem.maps[e]
    r = fitted.r[rows] * problem.sigma[e]
    order = np.argsort(sm.time, kind="stable")
    res = residual_analysis(r[order], sm.channel[order], sm.channels, [np.arange(r.size)], declared)
    for c, name in enumerate(sm.channels):
        if name in res:
            sel = sm.channel == c
            y = sm.y[sel]
            spread = np.linalg.norm(y - y.mean())
            # a channel that does not move (a supported dof) has no motion to reproduce: no fit measure
            still = spread <= 1e-9 * np.sqrt(y.size) * max(problem.model.length_scale, float(np.abs(y).max()))
            res[name]["fit"] = None if still else float(1 - np.linalg.norm(r[sel]) / spread)
            # motion and residual in the fit's weights (noise units): what the pooled fit of step 7 adds up
            yw = y / problem.sigma[e][sel]
            res[name]["motion_w"] = 0.0 if still else float(np.linalg.norm(yw - yw.mean()))
            res[name]["residual_w"] = float(np.linalg.norm(fitted.r[rows][sel]))
    return res


def _plausibility(problem: OutputError, fitted: Fit, channels: list[dict], at_bound: dict[str, bool]) -> list[str]:
    """Why the result is not a plausible answer (empty: it is)."""
    reasons = []
    if not fitted.converged:
        reasons.append(fitted.message or f"the solver stopped without converging ({fitted.status})")
    bound = [k for k, v in at_bound.items() if v]
    if bound:
        reasons.append(f"{', '.join(bound)} ended on a bound: the best fit lies outside the parameters' range, "
                       "or the fit left its start's basin (try other starts: --starts N, or start values nearer)")
    for e, res in enumerate(channels):
        reasons += residual_reasons(problem.experiments[e].name or f"experiment {e + 1}", res)
    return reasons


def _uncertainty(problem: OutputError, f: Fit, dp: np.ndarray, p_hat: np.ndarray, me: np.ndarray,
                 compared: list[dict]) -> tuple[dict, np.ndarray, dict, dict[str, np.ndarray]]:
    """Step 6 of the module docstring: the Gauss-Newton statistics (``weak`` by the total), the HAC
    covariance of all unknowns and its record, and the parts of the standard errors {"gauss_newton",
    "hac", "noise", "model_form", "total"} (the model error ``me`` is given)."""
    names, n_p = problem.model.parameter_names, problem.model.n_p
    gn = gauss_newton_statistics(f.J, f.r, n_p, names, dp, p_hat)
    bread, prior = _huber_bread(problem), problem.prior_information(f.w)
    C, hac = sandwich_covariance(f.J, f.r, problem.groups(), bread=bread, information=prior)
    se_gn = np.array([gn["std_errors"][k] for k in names])
    if bread is not None:  # Huber's loss: the plain part is the M-estimator's sandwich without lags (Huber 1981)
        C0, _ = sandwich_covariance(f.J, f.r, problem.groups(), bandwidth=0, bread=bread, information=prior)
        se_gn = np.where(np.isinf(se_gn), np.inf, np.sqrt(np.maximum(np.diag(C0)[:n_p], 0.0)) * np.abs(dp))
    se_hac = np.where(np.isinf(se_gn), np.inf, np.sqrt(np.maximum(np.diag(C)[:n_p], 0.0)) * np.abs(dp))
    # the noise part: HAC where it is the larger; never below the plain errors, since a HAC under them rests on a
    # bandwidth estimated from the same short record (a gait swing's 26 samples gave 15 against 51, issue 27)
    se_noise = np.fmax(se_hac, se_gn)
    se_form = form_part(compared, names)
    total = np.sqrt(se_noise**2 + np.nan_to_num(me, nan=0.0) ** 2 + se_form**2)
    rel = total / np.maximum(np.abs(p_hat), np.finfo(float).tiny)
    gn["weak"] = [k for k, v in zip(names, rel, strict=True) if not v <= 0.1]
    return gn, C, hac, {"gauss_newton": se_gn, "hac": se_hac, "noise": se_noise, "model_form": se_form,
                        "total": total}


def _experiment_records(problem: OutputError, f: Fit, C: np.ndarray, declared: list, p_hat: np.ndarray, *,
                        dt: float, alpha: float, compiled: bool, newton_tol: float) -> tuple[list, dict, list, list]:
    """Per experiment: the residual analysis, the record (states, noise, residuals), the identified
    model's trajectory and the samples for plots: (channels, records, trajectories, samples)."""
    from casflex.simulate import Start, Stepping, compile_pays, integrator_for, simulate

    model = problem.model
    # the trajectories at the answer: compiled only when the HHT library is built or compiling it pays (a first
    # fit's few thousand steps run interpreted in under a second against 4-12 s of gcc; the same numbers, bitwise at
    # the default build flags); the sensitivities the fit used are another library
    steps = sum(sm.n_steps for sm in problem.maps)
    compiled = compiled and compile_pays(integrator_for(model, alpha=alpha, tol=newton_tol), steps)
    rows, start_row, channels, records = [], 0, [], {}
    trajectories, samples = [], []
    for e, exp in enumerate(problem.experiments):
        sm = problem.maps[e]
        rows.append(np.arange(start_row, start_row + sm.y.size))
        start_row += sm.y.size
        channels.append(_channels(problem, f, e, rows[-1], declared[e]))
        samples.append({"name": exp.name, "channels": sm.channels, "t": sm.time, "channel": sm.channel,
                        "measured": sm.y, "model": sm.y + f.r[rows[-1]] * problem.sigma[e]})
        q0, qd0 = problem.state(f.w, e)
        tr = simulate(model, sm.n_steps * dt, stepping=Stepping(dt=dt, alpha=alpha, tol=newton_tol, compiled=compiled),
                      p=p_hat, start=Start(q0=q0, qd0=qd0, t0=sm.t0), raise_on_failure=False)
        trajectories.append(tr)
        rec = {"initial_state": exp.initial_state, "samples": int(sm.y.size), "t0": sm.t0,
               "t_end": sm.t0 + sm.n_steps * dt, "channels": list(sm.channels), "residuals": channels[-1],
               "noise": noise_record(declared[e], exp.noise is not None, channels[-1])}
        if exp.initial_state != "scene":
            se_q, se_qd = problem.state_errors(f.w, C, e)
            keys = ("q0", "qd0") if exp.initial_state == "estimate" else ("qd0",)
            for key, value, se in zip(("q0", "qd0"), (q0, qd0), (se_q, se_qd), strict=True):
                if key in keys:
                    rec[key] = {model.dof_names[i]: [float(value[i]), float(se[i])] for i in problem.free}
        records[exp.name] = rec
    return channels, records, trajectories, samples


def estimate(model: Model, experiments: Sequence[Experiment], *, run: ModelRun | None = None,
             solver: Solver | None = None, uncertainty: Uncertainty | None = None,
             start: float | dict[str, float] | np.ndarray | None = None,
             check_data: bool = True) -> IdentificationResult:
    """Identify the model's parameters (and the unknown initial states) from ``experiments``.

    run: the model's step (s), HHT alpha (default: the scene's run settings, never the samples' spacing) and
    Newton tolerance; solver: Gauss-Newton's transform, budget, loss and log, compiled sensitivities (default
    True); uncertainty: the model error, the alternative forms (:mod:`.form`) and the scene properties known
    within an uncertainty, besides the scene's own ``[[uncertain]]`` (:mod:`.priors`); the other options as in
    :func:`casflex.identification.identify_indirect`.
    """
    run, solver, uncertainty = run or ModelRun(), solver or Solver(), uncertainty or Uncertainty()
    if solver.name not in (None, GAUSS_NEWTON) or solver.options is not None or solver.hessian is not None:
        raise ValueError(f"solver {solver.name!r}: estimate is single shooting by {GAUSS_NEWTON!r}; an NLP solver "
                         "and its options are identify_indirect's")
    transform, budget, compiled, newton_tol = (solver.transform, solver.limits,
                                               True if solver.compiled is None else solver.compiled, run.newton_tol)
    loss, verbose, model_error = solver.loss, solver.verbose, uncertainty.model_error
    vary, uncertain = uncertainty.vary, uncertainty.uncertain
    if model.n_p == 0:
        raise ValueError("the scene declares no parameters to identify ([[parameters]] in the scene file)")
    dt, alpha = run.of(model.scene)
    t_build = time.perf_counter()
    experiments = _named(model, experiments, check_data)
    scene_u = declared_uncertain(model.scene, uncertain)
    both = sorted(set(vary or {}) & {u.target for u in scene_u.uncertain})
    if both:
        raise ValueError(f"vary {both[0]}: it is declared uncertain, estimated with its prior, not a form to vary")
    forms = alternatives_of(model, experiments, form=uncertainty.form, vary=vary,
                            alternatives=uncertainty.alternatives)
    pmap = ParameterMap.of(model, transform)
    p0 = start_values(model, start)
    setup = {"dt": dt, "alpha": alpha, "pmap": pmap, "compiled": compiled, "newton_tol": newton_tol,
             "initial": initial_states(model, experiments, p0), "vary": vary}
    problem = OutputError(model, experiments, **setup)
    w0 = problem.pack(pmap.theta(p0))
    build_s = time.perf_counter() - t_build

    t_solve = time.perf_counter()
    problem, f = _fit_growing(model, experiments, w0, budget, verbose=verbose, **setup)
    declared = [e.noise for e in experiments]
    if f.converged and (reweighted := _reweighted(problem, f)) is not None:  # step 3: each channel by its noise
        experiments, problem, f = reweighted, *_refit_weighted(model, reweighted, f, setup, budget, t_solve, verbose)
    robust, priors, n_params = {}, {}, model.n_p
    if loss != "linear":
        experiments, problem, f, robust = _robust_fit(model, problem, f, setup, budget, t_solve, loss, verbose)
    if nuisance_names(scene_u) and f.converged:  # the uncertain properties with their priors (.priors)
        model, problem, f, priors = map_fit(model, scene_u, problem, f, p0, declared, setup, budget, t_solve,
                                            verbose)
        priors["pinned"] = pinned(problem, f, scene_u) if f.converged else {}
        experiments, pmap, forms = problem.experiments, problem.pmap, forms_with_nuisance(forms, scene_u)
    p_hat = pmap.p(f.w[:model.n_p])
    me, refit = (_model_error(model, experiments, f, problem, dt=dt, alpha=alpha, transform=transform, budget=budget,
                              compiled=compiled, newton_tol=newton_tol, verbose=verbose)
                 if model_error == "refine" and f.converged else (np.zeros(model.n_p), {}))
    compared = (compare_forms(problem, f, forms, setup={"transform": transform, "alpha": alpha,
                                                        "newton_tol": newton_tol}, budget=budget, verbose=verbose)
                if forms and f.converged else [])
    solve_s = time.perf_counter() - t_solve
    if nuisance_names(scene_u) and not priors:
        priors = {"not estimated": "the fit without the uncertain properties did not converge"}
    return _result(problem, f, p0, p_hat, me, refit, compared, declared, priors, robust, n_params,
                   dt=dt, alpha=alpha, compiled=compiled, newton_tol=newton_tol, transform=transform, budget=budget,
                   model_error=model_error, build_s=build_s, solve_s=solve_s)


def _result(problem: OutputError, f: Fit, p0: np.ndarray, p_hat: np.ndarray, me: np.ndarray, refit: dict,
            compared: list, declared: list, priors: dict, robust: dict, n_params: int, *, dt: float, alpha: float,
            compiled: bool, newton_tol: float, transform: str, budget: Budget, model_error: str, build_s: float,
            solve_s: float) -> IdentificationResult:
    """The result of :func:`estimate` (steps 6-7 of the module docstring): the first ``n_params`` of the model's
    parameters are reported; those after them are the uncertain properties, reported in ``extra["uncertain"]``."""
    model, experiments, pmap = problem.model, problem.experiments, problem.pmap
    names, keep = model.parameter_names, slice(0, n_params)
    dp = pmap.dp_dtheta(f.w[:model.n_p])
    gn, C, hac, parts = _uncertainty(problem, f, dp, p_hat, me, compared)
    se_noise, total = parts["noise"], parts["total"]
    gn["weak"] = [k for k in gn["weak"] if k in names[keep]]
    channels, records, trajectories, samples = _experiment_records(
        problem, f, C, declared, p_hat, dt=dt, alpha=alpha, compiled=compiled, newton_tol=newton_tol)
    at_bound = bound_flags(model, p_hat, pmap.scale)
    reasons = _plausibility(problem, f, channels, {k: at_bound[k] for k in names[keep]})
    reasons += undetermined_reasons(dict(zip(names[keep], total[keep].tolist(), strict=True)),
                                    gn.get("weakest_direction"))
    reasons += [f"{exp.name}: the identified model does not run through the recording ({tr.message})"
                for exp, tr in zip(experiments, trajectories, strict=True) if not tr.success]
    notes: list[str] = []
    if model.n_p > n_params:  # the uncertain properties: what the data say of them, and their part of the errors
        nuisance, conflicts, held = prior_report(problem, f, se_noise, n_params)
        for target, pin in priors.get("pinned", {}).items():
            nuisance[target]["pinned_by"] = pin["by"]
            nuisance[target]["left_if_free"] = pin["left_if_free"]
            notes.append(f"{target} is pinned only against {', '.join(pin['by'])}, held at the scene's value: the "
                         f"data fix their ratio, not {target} itself, and the fit cannot separate them (as uncertain "
                         f"as it, {100 * pin['left_if_free']:.0f} % of its prior spread would be left); declare "
                         f"{' and '.join(pin['by'])} uncertain too")
        # the joint distribution of parameters and properties: what output bands draw from (.bands)
        joint = {"names": list(names), "values": p_hat.tolist(), "std_errors": total.tolist(),
                 "correlation": np.asarray(gn["correlation"]).tolist()}
        priors |= {"properties": nuisance, "held_std_errors": held, "joint": joint}
        parts["uncertain_properties"] = np.append(
            np.sqrt(np.maximum(parts["gauss_newton"][keep] ** 2 - np.array(list(held.values())) ** 2, 0.0)),
            np.full(model.n_p - n_params, np.nan))
        reasons += conflicts
    form_why, form_notes = form_reasons(compared, names, se_noise)
    notes += form_notes
    refusal = {"form": form_why, "other": reasons}  # why success is withheld: the model's form, or anything else
    reasons = reasons + form_why
    if model_error == "refine" and f.converged and not np.isfinite(me).all():
        notes.append("the model error could not be estimated (the refined model's fit did not converge): the "
                     "standard errors hold the HAC part only")
    if "not estimated" in priors:
        notes.append(f"the uncertain properties were not estimated: {priors['not estimated']}")
    first = trajectories[0]

    def named(values: np.ndarray) -> dict[str, float]:
        return dict(zip(names[keep], np.asarray(values)[keep].tolist(), strict=True))

    return IdentificationResult(
        method="indirect", solver="gauss-newton", parameters=named(p_hat), start=named(p0[:n_params]),
        success=not reasons, status=f.status, message="; ".join(reasons + notes), iterations=f.iterations,
        wall_build_s=build_s, wall_solve_s=solve_s, objective=0.5 * float(f.r @ f.r), std_errors=named(total),
        correlation=np.asarray(gn.pop("correlation"))[keep, keep].tolist(),
        at_bound={k: at_bound[k] for k in names[keep]},
        identifiability={k: v for k, v in gn.items() if k != "std_errors"},
        instants=first.t.tolist(), multipliers=first.lam.tolist(),
        extra={"transcription": "single-shooting", "residue": "positions", "dofs": list(problem.maps[0].channels),
               "transform": transform, "dt": dt,
               "alpha": alpha, "steps": int(sum(sm.n_steps for sm in problem.maps)), "compiled": compiled,
               "budget": dataclasses.asdict(budget), "model_runs": problem.evaluations, "offset_se": f.offset,
               "uncertainty": {**{k: named(parts[k]) for k in parts if k != "total"},
                               "model_error": named(me), "hac_bandwidth": hac["bandwidth"],
                               "model_error_refit": refit},
               "forms": compared, "refusal": refusal, "robust": robust, "uncertain": priors,
               "experiments": records, "solver_s": f.solve_s},
        trajectories=tuple(trajectories), samples=tuple(samples),
    )
