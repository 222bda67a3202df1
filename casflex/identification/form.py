"""The model-form part of an output-error fit's uncertainty (issue 27): how far the parameters move
between models of another form that fit the data as well.

A model's form -- whether its beams carry their section's rotary inertia, a property the scene
states but nobody measured to the digit, another scene altogether -- is not among the fitted
parameters, and the parameters absorb what the form gets wrong: twobar recorded by a code whose
beams have rotary inertia, fitted without it, gave kt3 20 % off at 8.5 standard errors with a
residual at 1.3 x the noise. Every alternative form is fitted to the same data from the fit's answer
and compared with it by Akaike's information criterion (AIC = chi^2 + 2 n, n the unknowns):

- chi^2 is each channel's sum of squared residuals over that channel's noise variance, estimated from
  the better-fitting model of the two (s_c^2 = SSR_c / (m_c - n m_c / m)); so a difference is
  measured against noise the data show, per channel, whatever the declared noise;
- divided by the residuals' long-run variance ratio kappa >= 1 (Bartlett, the bandwidth of
  :func:`.statistics.bartlett_bandwidth`): correlated residuals hold fewer independent samples.

Each comparison's verdict, with Burnham and Anderson's (2002) reading of AIC differences (a model
:data:`DECISIVE` units behind has essentially no support): ``rejected`` (the alternative fits worse
by more than that), ``better`` (it fits better by more than that: the data reject the scene's form,
and success is not claimed), ``as well`` (in between), ``not compared`` (its fit did not converge,
or its model does not run; said in the result).

The model-form part of a parameter's standard error (:func:`form_part`) is the Akaike-weighted RMS of
its moves between the forms, the between-model term of Burnham and Anderson's unconditional variance:
no cut-off, so a form the data barely disfavour counts a little and one they rule out not at all.
Success is not claimed when it exceeds the parameter's noise standard error: the parameters then
move by more than their noise standard error between models that fit the data about equally well.

The alternatives (:func:`alternatives_of`):

- ``form="auto"``: the choice casflex makes where a scene is silent, the beam theory: beams without
  the section's rotary inertia (the default) are refitted with it, and beams with it without;
- ``vary={target: (lower, upper)}``: a property at each end of its declared range;
- ``alternatives``: scenes the user gives (other bodies, joints, meshes), declaring every parameter.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from casflex.identification.choices import FORMS
from casflex.identification.initial_state import initial_states
from casflex.identification.measurement import Experiment, check_against_scene
from casflex.identification.output_error import Budget, Fit, OutputError, chord_fit, fit
from casflex.identification.problem import ParameterMap
from casflex.identification.statistics import bartlett_bandwidth
from casflex.model import Model, assembled
from casflex.scene import Scene, SceneError

__all__ = ["FORMS", "DECISIVE", "Alternative", "declared_alternatives", "alternatives_of", "compare_forms",
           "form_part", "form_reasons"]

#: AIC units: a model this far behind has essentially no support (Burnham and Anderson 2002, Sec. 2.6)
DECISIVE = 10.0
#: model runs an alternative's refit may take (it starts at the fit's answer; twobar's beam theory: 2-4)
REFIT_RUNS = 30
#: An alternative's refit stops once it is within REJECT_SE standard errors of its solution and behind by
#: more than REJECT_AIC even after the fall its Gauss-Newton step promises: an Akaike weight below
#: exp(-20), whose sqrt (4.5e-5) leaves nothing of a move of even 1000 SE in the model-form part.
REJECT_SE, REJECT_AIC = 2.0, 40.0


@dataclass(frozen=True)
class Alternative:
    """A model of another form: its name (what differs) and its scene."""

    name: str
    scene: Scene


def _beam_theory(scene: Scene) -> list[Alternative]:
    if not scene.beams:
        return []
    rotary = not all(b.rotary_inertia for b in scene.beams)
    beams = tuple(dataclasses.replace(b, rotary_inertia=rotary) for b in scene.beams)
    what = "with" if rotary else "without"
    return [Alternative(f"beams {what} the section's rotary inertia (rotary_inertia = {str(rotary).lower()})",
                        dataclasses.replace(scene, beams=beams))]


def _varied(scene: Scene, vary: Mapping[str, tuple[float, float]]) -> list[Alternative]:
    fitted = {p.target: p.name for p in scene.parameters}
    out = []
    for target, bounds in vary.items():
        if target in fitted:
            raise ValueError(f"vary {target}: it is parameter {fitted[target]!r}, fitted, not a form to vary")
        value = scene.property_value(target, where=f"vary {target}")  # an unknown target: SceneError naming it
        try:
            lo, hi = (float(v) for v in bounds)
        except (TypeError, ValueError):
            raise ValueError(f"vary {target}: expected (lower, upper), got {bounds!r}") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ValueError(f"vary {target}: expected finite lower < upper, got ({lo:g}, {hi:g})")
        if not lo <= value <= hi:  # the fit itself runs at the scene's value: the declaration contradicts it
            raise ValueError(f"vary {target}: the range {lo:g}..{hi:g} excludes the scene's value {value:g}, at which "
                             "the parameters are fitted; set the scene's value inside the range or widen it")
        for v in (lo, hi):
            try:
                out.append(Alternative(f"{target} = {v:g}", scene.with_property(target, v)))
            except SceneError as exc:
                raise ValueError(f"vary {target}: {v:g}: {exc}") from None
    return out


def _given(model: Model, scenes: Sequence[Scene | str | os.PathLike[str]]) -> list[Alternative]:
    from casflex.scene.io import load_scene

    out = []
    for s in scenes:
        try:
            scene = s if isinstance(s, Scene) else load_scene(s)
        except (OSError, ValueError) as exc:
            raise ValueError(f"alternatives: {exc}") from None
        missing = [n for n in model.parameter_names if n not in {p.name for p in scene.parameters}]
        if missing:
            raise ValueError(f"alternatives: scene {scene.name!r} does not declare the parameter(s) "
                             f"{', '.join(missing)}; an alternative form fits the same parameters")
        out.append(Alternative(f"scene {scene.name}", scene))
    return out


def declared_alternatives(model: Model, *, form: str = "auto", vary: Mapping[str, tuple[float, float]] | None = None,
                          alternatives: Sequence[Scene | str | os.PathLike[str]] = ()) -> list[Alternative]:
    """The alternative forms (module docstring), their scenes checked (a ValueError names the offending
    option, target, value or scene); nothing assembled."""
    if form not in FORMS:
        raise ValueError(f"form: expected one of {FORMS}, got {form!r}")
    return (_beam_theory(model.scene) if form == "auto" else []) + _varied(model.scene, vary or {}) \
        + _given(model, alternatives)


def alternatives_of(model: Model, experiments: Sequence[Experiment], *, form: str = "auto",
                    vary: Mapping[str, tuple[float, float]] | None = None,
                    alternatives: Sequence[Scene | str | os.PathLike[str]] = ()) -> list[tuple[Alternative, Model]]:
    """The alternative forms with their models, every one checked against the data before any fit."""
    out = []
    for alt in declared_alternatives(model, form=form, vary=vary, alternatives=alternatives):
        m = assembled(alt.scene, inertia=model.inertia)
        for e in experiments:
            try:
                check_against_scene(m, e)
            except ValueError as exc:
                raise ValueError(f"alternative {alt.name}: {exc}") from None
        out.append((alt, m))
    return out


def _long_run_ratio(x: np.ndarray) -> float:
    """Long-run over plain variance of a series (Bartlett weights, Andrews' bandwidth), at least 1."""
    x = x - x.mean()
    var = float(x @ x)
    if x.size < 3 or var == 0:
        return 1.0
    L = bartlett_bandwidth(x[:, None])
    acf = [float(x[k:] @ x[:-k]) / var for k in range(1, min(L, x.size - 1) + 1)]
    return max(1.0, 1.0 + 2.0 * sum((1 - k / (L + 1)) * a for k, a in enumerate(acf, start=1)))


def delta_aic(base: tuple[OutputError, np.ndarray], alt: tuple[OutputError, np.ndarray]) -> tuple[float, float]:
    """(AIC of alt minus AIC of base, kappa): module docstring; each argument is (problem, residuals)."""
    sb, sa = base[0].channel_residuals(base[1]), alt[0].channel_residuals(alt[1])
    keys = [k for k in sb if k in sa and sb[k].size == sa[k].size]
    m = sum(sb[k].size for k in keys)
    nb, na = base[0].n_unknowns, alt[0].n_unknowns
    chi_b = chi_a = kappa_num = m_noisy = 0.0
    for k in keys:
        ssr_b, ssr_a = float(sb[k] @ sb[k]), float(sa[k] @ sa[k])
        best, n = (sb[k], nb) if ssr_b <= ssr_a else (sa[k], na)
        s2 = min(ssr_b, ssr_a) / max(best.size * (1 - n / m), 1.0)
        if s2 <= 0:  # one model reproduces the channel exactly: any residual of the other rules it out
            chi_b, chi_a = chi_b + (math.inf if ssr_b > 0 else 0.0), chi_a + (math.inf if ssr_a > 0 else 0.0)
            continue
        chi_b, chi_a = chi_b + ssr_b / s2, chi_a + ssr_a / s2
        kappa_num += best.size * _long_run_ratio(best)
        m_noisy += best.size
    kappa = kappa_num / m_noisy if m_noisy else 1.0
    d = 0.0 if chi_a == chi_b else (chi_a - chi_b) / kappa  # inf - inf: both exact somewhere, neither ruled out
    return d + 2.0 * (na - nb), kappa


def _refit(alt_model: Model, problem: OutputError, first: Fit, p_hat: dict[str, float], setup: dict,
           budget: Budget, verbose: bool) -> tuple[OutputError, Fit]:
    """The alternative fitted from the fit's answer (its states too, where its dofs are the model's)."""

    pmap = ParameterMap.of(alt_model, setup["transform"])
    p0 = np.array([p_hat.get(n, v) for n, v in zip(alt_model.parameter_names, alt_model.p_nominal, strict=True)])
    same = alt_model.dof_names == problem.model.dof_names
    states = [problem.state(first.w, e) for e in range(len(problem.experiments))] if same else None
    prob = OutputError(alt_model, problem.experiments, dt=problem.dt, alpha=setup["alpha"], pmap=pmap,
                       compiled=problem.compiled, newton_tol=setup["newton_tol"], vary=dict(problem.vary or ()),
                       refit=True, initial=initial_states(alt_model, problem.experiments, p0, states))

    def rejected(r: np.ndarray, offset: float) -> bool:
        """Ruled out for good (REJECT_SE, REJECT_AIC): at its solution chi^2 is lower by about offset^2,
        allowed four times over."""
        return offset <= REJECT_SE and delta_aic((problem, first.r), (prob, r))[0] - 4 * offset**2 > REJECT_AIC

    w0 = prob.pack(pmap.theta(p0))
    if prob.n_unknowns == problem.n_unknowns == alt_model.n_p and same:
        # ruled out for good with the fit's own Jacobian and model runs without sensitivities (chord steps, a
        # third of the cost); any other verdict rests on the alternative's exact fit, its moves and AIC
        quick = chord_fit(prob, w0, first.J, budget, enough=rejected)
        if quick is not None and quick.status == "within_se":
            return prob, quick
    return prob, fit(prob, w0, budget, verbose=verbose, near=True, enough=rejected)


def compare_forms(problem: OutputError, first: Fit, alternatives: list[tuple[Alternative, Model]], *, setup: dict,
                  budget: Budget, verbose: bool = False) -> list[dict]:
    """Refit every alternative and compare it with the fit (module docstring): one record each, with
    ``name``, ``verdict``, ``delta_aic``, ``kappa``, ``parameters``, ``moves`` {name: p_alt - p}, ``runs``,
    ``offset_se``, the refit's distance to its own solution in standard errors (up to REJECT_SE for
    an alternative ruled out for good), and ``chord``: ruled out by chord steps with the fit's Jacobian
    (:func:`.output_error.chord_fit`), the offset measured with it."""
    model, t0 = problem.model, time.perf_counter()
    p_hat = dict(zip(model.parameter_names, problem.pmap.p(first.w[:model.n_p]).tolist(), strict=True))
    records = []
    for alt, alt_model in alternatives:
        rec = {"name": alt.name, "verdict": "not compared"}
        left = budget.max_time - (time.perf_counter() - t0)
        try:
            prob, f = _refit(alt_model, problem, first, p_hat, setup,
                             Budget(min(REFIT_RUNS, budget.max_iterations), max(left, 1e-3)), verbose)
        except ValueError as exc:  # the alternative does not run from the fit's answer
            records.append(rec | {"why": str(exc)})
            continue
        p_alt = dict(zip(alt_model.parameter_names, prob.pmap.p(f.w[:alt_model.n_p]).tolist(), strict=True))
        d, kappa = delta_aic((problem, first.r), (prob, f.r))
        rec |= {"delta_aic": d, "kappa": kappa, "parameters": p_alt, "runs": f.iterations, "offset_se": f.offset,
                "chord": f.J is first.J,  # ruled out by chord steps with the fit's Jacobian
                "moves": {n: p_alt[n] - v for n, v in p_hat.items()}}
        if d > DECISIVE:
            rec["verdict"] = "rejected"
        elif not f.converged and d >= -DECISIVE:  # might fit better with more runs: no conclusion
            rec["why"] = f.message or f"its fit stopped without converging ({f.status})"
        else:
            rec["verdict"] = "better" if d < -DECISIVE else "as well"
        records.append(rec)
    return records


def akaike_weights(records: list[dict]) -> np.ndarray:
    """Akaike weights of the scene's form and of each compared alternative (0 for one not compared):
    exp(-delta AIC / 2), normalised (Burnham and Anderson 2002, Sec. 2.9)."""
    d = np.array([0.0] + [r["delta_aic"] if r["verdict"] != "not compared" else np.inf for r in records])
    # an exact fit of a channel (delta -inf) takes all the weight
    d = np.where(d == d.min(), 0.0, d - d.min()) if np.isinf(d.min()) else d - d.min()
    w = np.exp(-d / 2)
    return w / w.sum()


def form_part(records: list[dict], names: Sequence[str]) -> np.ndarray:
    """The model-form part of each parameter's standard error: the Akaike-weighted RMS of its moves
    between the scene's form and the alternatives, sqrt(sum_i w_i (p_i - p)^2), the between-model term
    of Burnham and Anderson's unconditional variance (2002, Sec. 4.3.2), taken about the reported
    estimate p. An alternative the data rule out weighs nothing; one as good as the scene's form gives
    0.71 of its move; one far better, all of it."""
    w = akaike_weights(records)
    var = np.zeros(len(names))
    for wi, r in zip(w[1:], records, strict=True):
        if wi > 0:
            var += wi * np.array([r["moves"][n] for n in names]) ** 2
    return np.sqrt(var)


def form_reasons(records: list[dict], names: Sequence[str], se_noise: np.ndarray) -> tuple[list[str], list[str]]:
    """(why success is not claimed, notes): an alternative that fits the data decisively better; a
    model-form part above a parameter's noise standard error (the answer depends on the form more than
    on the noise), naming the alternative that moves it most; the alternatives not compared."""
    reasons, notes = [], [f"the alternative form {r['name']} could not be compared: {r['why']}" for r in records
                          if r["verdict"] == "not compared"]
    compared = [r for r in records if r["verdict"] != "not compared"]

    def worst_move(r: dict) -> tuple[str, float]:
        z = {n: abs(r["moves"][n]) / s for n, s in zip(names, se_noise, strict=True) if s > 0}
        return max(z.items(), key=lambda kv: kv[1]) if z else ("", 0.0)

    for r in compared:
        if r["verdict"] == "better":
            n, z = worst_move(r)
            reasons.append(f"the data reject the scene's form: {r['name']} fits them better (AIC lower by "
                           f"{-r['delta_aic']:.0f}) and moves {n} by {z:.1f} noise standard errors; fit that form, "
                           "or find what else the scene misses")
    part = form_part(compared, names)
    over = [(j, f / s) for j, (f, s) in enumerate(zip(part, se_noise, strict=True)) if s > 0 and f > s]
    if over and not reasons:
        j, ratio = max(over, key=lambda kv: kv[1])
        n = names[j]
        r = max(compared, key=lambda r: abs(r["moves"][n]) * math.exp(-max(r["delta_aic"], 0.0) / 2))
        reasons.append(f"the answer depends on the model's form more than on the noise: {n}'s model-form error is "
                       f"{ratio:.1f} x its noise standard error ({r['name']} fits the data about as well, AIC "
                       f"{r['delta_aic']:+.1f}, and moves {n} by {abs(r['moves'][n]) / se_noise[j]:.1f} noise "
                       "standard errors); settle the form, or record motion that tells the forms apart")
    return reasons, notes
