"""Indirect (output-error) identification (Eqs. 15-17): the model simulated from each recording's
first sample is compared with the measured motion.

Two transcriptions (``docs/identification.md`` compares them on data from another code):

- ``single-shooting`` (default), ``solver="gauss-newton"``: Gauss-Newton on exact forward
  sensitivities, on a growing horizon, with the initial state of each recording from the scene or
  estimated, the model's error estimated by refinement and autocorrelation-consistent standard
  errors (:mod:`.estimate`). Samples at any times, several recordings at once.
- ``multiple-shooting``, or any CasADi NLP solver (``solver="ipopt"``, ...), or the full residue
  of Eq. 17: the seed paper's NLP (:mod:`.shooting_nlp`), for solver comparisons; samples on the
  step grid, the scene's initial state, one recording. For Eq. 16 its answer is polished and its
  statistics computed by the default procedure, so that every result is reported alike.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping, Sequence
from typing import Unpack

import numpy as np

from casflex.data import MeasurementSet
from casflex.identification.estimate import MODEL_ERRORS, estimate
from casflex.identification.measurement import INITIAL_STATES, Experiment
from casflex.identification.output_error import Budget
from casflex.identification.problem import GAUSS_NEWTON, NLPKeywords, NLPOptions, merge_options, require_no_uncertain
from casflex.identification.result import IdentificationResult
from casflex.identification.shooting_nlp import RESIDUES, TRANSCRIPTIONS, identify_nlp
from casflex.model import Model
from casflex.scene import Scene, Uncertain

__all__ = ["identify_indirect", "RESIDUES", "TRANSCRIPTIONS", "INITIAL_STATES", "MODEL_ERRORS", "Budget"]

#: The default solver of single shooting on Eq. 16: not a CasADi plugin but scipy's trust-region
#: Gauss-Newton on forward sensitivities.


def _experiments(data: MeasurementSet | Experiment | Sequence[Experiment], horizon: float | None,
                 initial_state: str, dofs: Sequence[str] | None, noise: float | None) -> list[Experiment]:
    """The recordings to fit: ``data`` as one Experiment (with the options) or the given ones,
    each cut to [t0, t0 + horizon] when a horizon is given."""
    if isinstance(data, MeasurementSet):
        exps = [Experiment(data, initial_state=initial_state, channels=None if dofs is None else tuple(dofs),
                           noise=noise)]
    elif isinstance(data, Experiment):
        exps = [data]
    else:
        exps = list(data)
        if not exps or not all(isinstance(e, Experiment) for e in exps):
            raise ValueError("data: expected a MeasurementSet, an Experiment or a list of Experiments")
    if horizon is None:
        return exps
    if not (np.isfinite(horizon) and horizon > 0):
        raise ValueError(f"horizon: must be a positive number of seconds, got {horizon!r}")
    out = []
    for e in exps:
        t0 = float(e.data.t[0])
        if horizon > e.data.t[-1] - t0 + 1e-9:
            raise ValueError(f"horizon: {horizon:g} s goes beyond the data ({e.data.t[-1] - t0:g} s from its first "
                             "sample)")
        out.append(dataclasses.replace(e, data=e.data.window(t0, t0 + horizon)))
    return out


def identify_indirect(
    model: Model,
    data: MeasurementSet | Experiment | Sequence[Experiment],
    horizon: float | None = None,
    *,
    transcription: str = "single-shooting",
    initial_state: str = "scene",
    dofs: Sequence[str] | None = None,
    noise: float | None = None,
    residue: str = "positions",
    weights: tuple[float, float, float] = (1.0, 1.0, 1.0),
    alpha: float | None = None,
    dt: float | None = None,
    interval: int | None = None,
    start: float | dict[str, float] | np.ndarray | None = None,
    newton_tol: float = 1e-12,
    polish: int = 3,
    budget: Budget | None = None,
    model_error: str = "refine",
    form: str = "auto",
    vary: Mapping[str, tuple[float, float]] | None = None,
    alternatives: Sequence[Scene | str | os.PathLike[str]] = (),
    loss: str = "linear",
    uncertain: Sequence[Uncertain] | None = None,
    check_data: bool = True,
    **options: Unpack[NLPKeywords],
) -> IdentificationResult:
    """Output-error identification of the model's parameters from measured motion.

    Parameters
    ----------
    model : Model
        Its declared parameters are the unknowns, with their bounds.
    data : MeasurementSet, Experiment or list of Experiment
        The recording(s): positions (m, rad) of some dofs at their own times; NaN marks a missing
        sample. A MeasurementSet is one experiment with ``initial_state``, ``dofs``, ``noise``.
    horizon : float, s, optional
        Compare [t0, t0 + horizon] of each recording (t0: its first sample); default all of it.
    transcription : {"single-shooting", "multiple-shooting"}
    initial_state : {"scene", "velocities", "estimate"}
        The state at the first sample: the scene's, the scene's positions with estimated
        velocities, or estimated (:mod:`.initial_state`; the NLP transcription: "scene" or "estimate").
    dofs : names of the compared dofs; default every channel of the data.
    noise : float, optional
        The measurement noise's standard deviation (m, rad), if known (weights and checks).
    residue : {"positions", "full"}
        Eq. 16 or Eq. 17 (velocities and accelerations too; the NLP transcription).
    weights : (xi, psi, phi), Eq. 15 (residue "full").
    alpha, dt : HHT parameter and step (s) of the model; default the scene's run settings, never
        the spacing of the samples.
    interval : int, steps per multiple-shooting interval (default 20).
    start : factor, dict or array, optional
        Starting parameters (a number multiplies the nominal values).
    newton_tol : float
        Tolerance of the HHT Newton iterations inside the model (scaled, see HHT).
    polish : Gauss-Newton steps after an NLP solver (see :func:`.shooting_nlp.identify_nlp`).
    budget : Budget, optional
        Gauss-Newton iterations and wall time (default 100 per stage, 600 s); for an NLP solver
        the wall time is IPOPT's ``max_wall_time`` too, unless ``solver_options`` set it.
    model_error : {"refine", "none"}
        Estimate the model's discretisation error in the parameters by a refit on a refined model.
    form : {"auto", "none"}
        "auto": refit with casflex's own alternative form too, the other beam theory (:mod:`.form`).
    vary : {target: (lower, upper)}, optional
        Scene properties (``"<element>.<field>"``) known only within a range: refit at each end.
    alternatives : scenes (or their files), optional
        Other forms of the model, each declaring the same parameters. Every alternative that fits
        the data as well adds its move of the parameters to their standard errors (the model-form
        part); one that fits better, or as well but moves a parameter by more than its noise
        standard error, withholds success.
    loss : {"linear", "huber"}
        Least squares, or Huber's loss, robust to marker artefacts (iteratively reweighted from
        the least-squares answer; single shooting by Gauss-Newton).
    uncertain : list of :class:`casflex.scene.Uncertain`, optional
        Scene properties known only within an uncertainty (a mass from an anthropometric table), besides
        the scene's own ``[[uncertain]]``: estimated with their priors beside the parameters, whose
        standard errors then carry what they leave open (:mod:`.priors`; single shooting by Gauss-Newton).
    check_data : bool
        Stop when the data cannot belong to the scene (units, times, initial state).
    **options : solver, solver_options, transform, hessian, compiled, verbose (:class:`.problem.NLPOptions`)
        ``solver`` is "gauss-newton" (default for single shooting on Eq. 16) or a CasADi nlpsol
        plugin (default ipopt otherwise); ``transform`` applies to both. ``compiled``: generate
        and compile C (cached on disk, see :mod:`casflex.codegen`), the sensitivities (default
        True) or the NLP's functions (default False).
    """
    default = GAUSS_NEWTON if transcription == "single-shooting" and residue == "positions" else "ipopt"
    opts = NLPOptions.of("identify_indirect", options, solver=default)
    solver, transform, verbose = opts.solver, opts.transform, opts.verbose
    unused = [k for k in ("solver_options", "hessian") if solver == GAUSS_NEWTON and options.get(k) is not None]
    if unused:
        raise ValueError(f"{unused[0]}: an NLP solver's option, and the solver is {GAUSS_NEWTON!r} (single shooting "
                         "on Eq. 16, the default); set solver='ipopt' (or another nlpsol) or leave it out (the "
                         "Gauss-Newton budget is budget=)")
    if transcription not in TRANSCRIPTIONS:
        raise ValueError(f"transcription: expected one of {TRANSCRIPTIONS}, got {transcription!r}")
    if residue not in RESIDUES:
        raise ValueError(f"residue: expected one of {RESIDUES}, got {residue!r}")
    if len(weights) != 3 or not all(np.isfinite(w) and w >= 0 for w in weights):
        raise ValueError(f"weights: expected three numbers >= 0 (xi, psi, phi), got {weights!r}")
    if initial_state not in INITIAL_STATES:
        raise ValueError(f"initial_state: expected one of {INITIAL_STATES}, got {initial_state!r}")
    run = model.scene.run
    alpha = float(run.alpha if alpha is None else alpha)
    dt = float(run.dt if dt is None else dt)
    experiments = _experiments(data, horizon, initial_state, dofs, noise)
    if solver == GAUSS_NEWTON:
        if transcription != "single-shooting" or residue != "positions":
            raise ValueError(f"solver {GAUSS_NEWTON!r}: single shooting on positions (Eq. 16) only; use an NLP solver "
                             "(e.g. ipopt) for multiple shooting or residue 'full'")
        return estimate(model, experiments, dt=dt, alpha=alpha, start=start, transform=transform, budget=budget,
                        compiled=True if opts.compiled is None else opts.compiled, newton_tol=newton_tol,
                        model_error=model_error, form=form, vary=vary, alternatives=alternatives, loss=loss,
                        uncertain=uncertain, check_data=check_data, verbose=verbose)
    if len(experiments) > 1 or experiments[0].initial_state == "velocities" or (
            experiments[0].initial_state == "estimate" and residue != "positions"):
        raise ValueError(f"solver {solver!r} ({transcription}): one recording, from the scene's initial state or an "
                         f"estimated one (residue 'positions'); use solver {GAUSS_NEWTON!r} (single shooting) for "
                         "several recordings or estimated velocities")
    if residue == "full":
        require_no_uncertain(model, "the full residue (Eq. 17)", uncertain)
    exp = experiments[0]
    solver_options = opts.solver_options
    if solver == "ipopt":  # the budget's time holds for IPOPT too: no one waits unboundedly for a failure
        solver_options = merge_options({"ipopt": {"max_wall_time": (budget or Budget()).max_time}},
                                       solver_options or {})
    r = identify_nlp(model, exp.data, float(exp.data.t[-1] - exp.data.t[0]), transcription=transcription,
                     residue=residue, dofs=exp.channels, weights=weights, alpha=alpha, dt=dt, interval=interval,
                     start=start, initial_state=exp.initial_state, noise=exp.noise, newton_tol=newton_tol,
                     polish=polish,
                     **{**dataclasses.asdict(opts), "solver_options": solver_options})
    if residue == "full":
        return r
    # Eq. 16: the default procedure polishes the NLP's answer and reports it as every result is
    final = estimate(model, experiments, dt=dt, alpha=alpha, start=r.extra["solver_parameters"], transform=transform,
                     budget=budget, compiled=True, newton_tol=newton_tol, model_error=model_error, form=form,
                     vary=vary, alternatives=alternatives, loss=loss, uncertain=uncertain,
                     check_data=check_data, verbose=verbose)
    # the NLP's own answer is the start of the reported one: its solver's convergence and bounds count; its fit
    # to the recording is judged again on the reported answer
    nlp_why = r.extra["refusal"]["other"]
    reasons = [m for m in (f"the NLP solver did not succeed ({r.status}: {'; '.join(nlp_why)})" if nlp_why else "",
                           final.message) if m]
    extra = {**final.extra, "transcription": transcription, "intervals": r.extra["intervals"],
             "hessian": opts.hessian, "nlp": {k: r.extra[k] for k in ("solver_s", "solver_parameters",
                                                                  "constraint_violation", "refusal")},
             "nlp_status": r.status, "nlp_iterations": r.iterations}
    return dataclasses.replace(final, solver=solver, status=r.status, iterations=r.iterations,
                               success=not nlp_why and final.success, message="; ".join(reasons),
                               wall_build_s=r.wall_build_s + final.wall_build_s,
                               wall_solve_s=r.wall_solve_s + final.wall_solve_s, extra=extra)
