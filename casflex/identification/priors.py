"""Uncertain scene properties estimated with their priors (issue 37): the maximum a posteriori stage of
:func:`casflex.identification.estimate.estimate`.

A property the scene knows only within an uncertainty (``[[uncertain]]``, :mod:`casflex.scene.uncertain`: an
anthropometric table's mass, a beam's density) is a nuisance unknown beside the parameters, with the Gaussian
prior N(mean, sd^2). The fit minimises

    sum_i r_i^2 / s^2 + sum_j ((p_j - mean_j) / sd_j)^2

(r the data's residuals in the fit's weights, s their standard deviation there): the priors' rows join the
residuals (:class:`~.output_error.OutputError`), their information sd^-2 joins the Gauss-Newton matrix, and a
direction the data cannot see (all masses and stiffnesses together) falls back on the priors instead of being
fixed at the scene's values. Every parameter's covariance is then the posterior's, and carries what the
uncertain properties leave open.

The procedure: the fit without them (today's, the properties at their scene values) brings the start and s;
each experiment's noise is then taken to be what that fit shows (declared noise is kept as declared), so the
data's rows are in standard deviations like the priors'; the fit with them starts there (Gauss-Newton steps),
and is repeated while the residuals' standard deviation in those units moves by more than NOISE_TOL.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Mapping

import numpy as np

from casflex.identification.form import Alternative
from casflex.identification.initial_state import initial_states
from casflex.identification.measurement import Experiment
from casflex.identification.output_error import Budget, Fit, OutputError, fit
from casflex.identification.problem import ParameterMap, bound_flags, gauss_newton_statistics
from casflex.model import Model, assembled
from casflex.scene import Scene
from casflex.scene.uncertain import declared_uncertain, nuisance_names, with_uncertain_estimated

__all__ = ["map_fit", "prior_report", "forms_with_nuisance", "NOISE_TOL", "CONFLICT_SD"]

#: The fit with the priors is repeated while the data's residual standard deviation (in the noise taken) is
#: further than this from 1: the priors' weight against the data is then off by less than 10 %
NOISE_TOL = 0.05
#: Rounds of that repetition at most; model runs each may take (it starts at the last answer)
NOISE_ROUNDS, MAP_RUNS = 3, 30
#: A property the data move further than this many prior standard deviations contradicts its declaration
CONFLICT_SD = 3.0


def forms_with_nuisance(forms: list[tuple[Alternative, Model]], scene: Scene) -> list[tuple[Alternative, Model]]:
    """The alternative forms (:mod:`.form`) with the uncertain properties of ``scene`` estimated in each too,
    with the same priors: forms are compared at their maximum a posteriori fits."""
    out = []
    for alt, m in forms:
        alt_scene = with_uncertain_estimated(declared_uncertain(dataclasses.replace(alt.scene, uncertain=()),
                                                                scene.uncertain))
        out.append((dataclasses.replace(alt, scene=alt_scene), assembled(alt_scene, inertia=m.inertia)))
    return out


def _noise_taken(problem: OutputError, f: Fit, declared: list, floor: float) -> tuple[list[Experiment], float]:
    """The experiments with the noise the fit ``f`` shows where none is declared: each experiment's weights
    scaled by its residuals' standard deviation in them (channel ratios kept), and the largest change."""
    out, worst = [], 0.0
    n_share = problem.n_unknowns / max(problem.row_offsets[-1], 1)
    for e, exp in enumerate(problem.experiments):
        if declared[e] is not None:
            out.append(exp)
            continue
        r = f.r[problem.row_offsets[e]:problem.row_offsets[e + 1]]
        s = math.sqrt(float(r @ r) / max(r.size * (1 - n_share), 1.0))
        worst = max(worst, abs(s - 1.0))
        if isinstance(exp.noise, Mapping):
            noise = {c: max(v * s, floor) for c, v in exp.noise.items()}
        else:
            noise = max((1.0 if exp.noise is None else exp.noise) * s, floor)
        out.append(dataclasses.replace(exp, noise=noise))
    return out, worst


def map_fit(model: Model, scene: Scene, problem: OutputError, f: Fit, p0: np.ndarray, declared: list, setup: dict,
            budget: Budget, t_solve: float, verbose: bool) -> tuple[Model, OutputError, Fit, dict]:
    """The maximum a posteriori fit (module docstring) from the fit ``f`` of ``problem`` without the nuisance
    unknowns: (the model with them, its problem, its fit, a record of the rounds). ``scene``: the model's scene
    with its uncertain properties; ``p0``: the parameters' start, where a parameter that fit ended on a bound
    starts again (the properties' freedom may explain what drove it there: twobar with bar 2 5 % denser sent kt1
    and kt3 to 0 with the densities held, and the fit with them stayed there from that answer);
    ``declared``: each experiment's declared noise (None: estimated)."""
    model_u = assembled(with_uncertain_estimated(scene), inertia=model.inertia)
    pmap = ParameterMap.of(model_u, setup["pmap"].transform)
    floor = 1e-9 * model.length_scale
    p_hat = problem.pmap.p(f.w[:model.n_p])
    on_bound = np.array(list(bound_flags(model, p_hat, problem.pmap.scale).values()), dtype=bool)
    p = np.concatenate([np.where(on_bound, p0, p_hat), model_u.p_nominal[model.n_p:]])
    states = [problem.state(f.w, e) for e in range(len(problem.experiments))]
    experiments, change = _noise_taken(problem, f, declared, floor)
    rounds: list[dict] = []
    prob, g, runs = problem, f, problem.evaluations  # model runs of every stage so far
    for _ in range(NOISE_ROUNDS):
        runs += prob.evaluations if prob is not problem else 0
        left = budget.max_time - (time.perf_counter() - t_solve)
        prob = OutputError(model_u, experiments, **{**setup, "pmap": pmap,
                                                     "initial": initial_states(model_u, experiments, p, states)})
        g = fit(prob, prob.pack(pmap.theta(p)), Budget(min(MAP_RUNS, budget.max_iterations), max(left, 1e-3)),
                verbose=verbose, near=True)
        p = pmap.p(g.w[:model_u.n_p])
        states = [prob.state(g.w, e) for e in range(len(experiments))]
        experiments, change = _noise_taken(prob, g, declared, floor)
        rounds.append({"runs": g.iterations, "status": g.status, "noise_change": change})
        if not g.converged or change <= NOISE_TOL:
            break
    prob.evaluations += runs  # the result counts every model run and iteration, the stages' before it too
    g = dataclasses.replace(g, iterations=f.iterations + sum(r["runs"] for r in rounds), solve_s=f.solve_s + g.solve_s)
    declared = [dataclasses.asdict(u) for u in scene.uncertain if u.name in nuisance_names(scene)]
    return model_u, prob, g, {"rounds": rounds, "nuisance": list(nuisance_names(scene)), "declared": declared}


def prior_report(problem: OutputError, f: Fit, se_noise: np.ndarray, n_params: int) -> tuple[dict, list[str], dict]:
    """What the data say of each uncertain property (its prior, the estimate, its standard error, how far the
    data moved it in prior standard deviations and what is left of its prior spread), the reasons for a
    conflict (a property moved beyond CONFLICT_SD or onto an end of its range), and each parameter's standard
    error with the properties held at their estimates (the part the uncertain properties add is the rest)."""
    model = problem.model
    names = model.parameter_names
    p = problem.pmap.p(f.w[:model.n_p])
    report, reasons = {}, []
    for j in range(n_params, model.n_p):
        par = model.parameters[j]
        mean, sd = par.prior
        moved = (p[j] - mean) / sd
        report[par.target] = {"prior_mean": mean, "prior_sd": sd, "estimate": float(p[j]),
                              "std_error": float(se_noise[j]), "moved_sd": float(moved),
                              "left_of_prior": float(se_noise[j] / sd)}
        on_end = min(abs(p[j] - par.lower), abs(p[j] - par.upper)) <= 1e-8 * max(abs(p[j]), sd)
        if abs(moved) > CONFLICT_SD or on_end:
            where = "to an end of its declared range" if on_end else f"{abs(moved):.1f} prior standard deviations"
            reasons.append(f"the data contradict the declared uncertainty of {par.target}: they move it from "
                           f"{mean:.4g} to {p[j]:.4g}, {where}; correct the scene's value or widen its uncertainty")
    # the parameters' noise standard errors with the uncertain properties held (their columns and rows out)
    keep = np.r_[0:n_params, model.n_p:problem.n_unknowns]
    data = slice(0, problem.row_offsets[-1])
    held = gauss_newton_statistics(f.J[data][:, keep], f.r[data], n_params, names[:n_params],
                                   problem.pmap.dp_dtheta(f.w[:model.n_p])[:n_params], p[:n_params])
    return report, reasons, held["std_errors"]
