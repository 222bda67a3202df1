"""Indirect (output-error) identification (Eqs. 15-17): the model simulated from each recording's
first sample is compared with the measured motion.

Two transcriptions (``docs/identification.md`` compares them on data from another code):

- ``single-shooting`` (default), ``Solver("gauss-newton")``: Gauss-Newton on exact forward
  sensitivities, on a growing horizon, with the initial state of each recording from the scene or
  estimated, the model's error estimated by refinement and autocorrelation-consistent standard
  errors (:mod:`.estimate`). Samples at any times, several recordings at once.
- ``multiple-shooting``, or any CasADi NLP solver (``Solver("ipopt")``, ...), or the full residue
  of Eq. 17: the seed paper's NLP (:mod:`.shooting_nlp`), for solver comparisons; samples on the
  step grid, the scene's initial state, one recording. For Eq. 16 its answer is polished and its
  statistics computed by the default procedure, so that every result is reported alike.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from casflex.data import MeasurementSet
from casflex.identification.estimate import MODEL_ERRORS, estimate
from casflex.identification.measurement import INITIAL_STATES, Experiment
from casflex.identification.options import GAUSS_NEWTON, Budget, ModelRun, Shooting, Solver, Uncertainty
from casflex.identification.problem import merge_options, require_no_uncertain
from casflex.identification.result import IdentificationResult
from casflex.identification.shooting_nlp import RESIDUES, TRANSCRIPTIONS, identify_nlp
from casflex.model import Model

__all__ = ["identify_indirect", "RESIDUES", "TRANSCRIPTIONS", "INITIAL_STATES", "MODEL_ERRORS", "Budget"]

def _experiments(data: MeasurementSet | Experiment | Sequence[Experiment], horizon: float | None) -> list[Experiment]:
    """The recordings to fit: ``data`` as one Experiment (a MeasurementSet alone: ``Experiment(data)``) or
    the given ones, each cut to [t0, t0 + horizon] when a horizon is given."""
    if isinstance(data, MeasurementSet):
        exps = [Experiment(data)]
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
    shooting: Shooting | None = None,
    solver: Solver | None = None,
    run: ModelRun | None = None,
    uncertainty: Uncertainty | None = None,
    start: float | dict[str, float] | np.ndarray | None = None,
    check_data: bool = True,
) -> IdentificationResult:
    """Output-error identification of the model's parameters from measured motion.

    Parameters
    ----------
    model : Model
        Its declared parameters are the unknowns, with their bounds.
    data : MeasurementSet, Experiment or list of Experiment
        The recording(s): positions (m, rad) of some dofs at their own times; NaN marks a missing
        sample. An Experiment says what is known of the state at its first sample (the scene's, the
        scene's positions with estimated velocities, or estimated, :mod:`.initial_state`; the NLP
        transcription: "scene" or "estimate"), its compared channels (default every channel of the data)
        and its noise's standard deviation (m, rad), if known (weights and checks). A MeasurementSet
        alone is ``Experiment(data)``.
    horizon : float, s, optional
        Compare [t0, t0 + horizon] of each recording (t0: its first sample); default all of it.
    shooting : Shooting, optional
        Transcription (default single shooting), steps per multiple-shooting interval (default 20),
        residue (Eq. 16 positions, default, or Eq. 17 full: the NLP transcription) and Eq. 15's weights.
    solver : Solver, optional
        ``name`` "gauss-newton" (default for single shooting on Eq. 16) or a CasADi nlpsol plugin (default
        ipopt otherwise); ``transform`` applies to both; ``compiled``: generate and compile C (cached on disk,
        see :mod:`casflex.codegen`), the sensitivities (default True) or the NLP's functions (default False);
        ``budget``: Gauss-Newton iterations and wall time (default 100 per stage, 600 s; for an NLP solver
        the wall time is IPOPT's ``max_wall_time`` too, unless ``options`` set it); ``polish``: Gauss-Newton
        steps after an NLP solver; ``loss``: least squares, or Huber's, robust to marker artefacts
        (iteratively reweighted from the least-squares answer).
    run : ModelRun, optional
        The model's HHT step and alpha (default the scene's run settings, never the spacing of the samples)
        and the tolerance of its Newton iterations (default 1e-12).
    uncertainty : Uncertainty, optional
        ``model_error`` "refine": estimate the model's discretisation error in the parameters by a refit on a
        refined model; ``form`` "auto": refit with casflex's own alternative form too, the other beam theory
        (:mod:`.form`); ``vary``: scene properties (``"<element>.<field>"``) known only within a range, refitted
        at each end; ``alternatives``: other forms of the model (scenes or files) declaring the same
        parameters. Every alternative that fits the data as well adds its move of the parameters to their
        standard errors (the model-form part); one that fits better, or as well but moves a parameter by more
        than its noise standard error, withholds success. ``uncertain``: scene properties known only within
        an uncertainty (:class:`casflex.scene.Uncertain`, besides the scene's own ``[[uncertain]]``),
        estimated with their priors beside the parameters, whose standard errors then carry what they leave
        open (:mod:`.priors`; single shooting by Gauss-Newton).
    start : factor, dict or array, optional
        Starting parameters (a number multiplies the nominal values).
    check_data : bool
        Stop when the data cannot belong to the scene (units, times, initial state).
    """
    shooting, solver = shooting or Shooting(), solver or Solver()
    run, uncertainty = run or ModelRun(), uncertainty or Uncertainty()
    name = solver.name or (GAUSS_NEWTON if shooting.gauss_newton else "ipopt")
    unused = [k for k, v in (("solver_options", solver.options), ("hessian", solver.hessian)) if v is not None]
    if name == GAUSS_NEWTON and unused:
        raise ValueError(f"{unused[0]}: an NLP solver's option, and the solver is {GAUSS_NEWTON!r} (single shooting "
                         "on Eq. 16, the default); give Solver('ipopt') (or another nlpsol) or leave it out (the "
                         "Gauss-Newton budget is Solver(budget=))")
    dt, alpha = run.of(model.scene)
    run = ModelRun(dt, alpha, run.newton_tol)
    experiments = _experiments(data, horizon)
    if name == GAUSS_NEWTON:
        if not shooting.gauss_newton:
            raise ValueError(f"solver {GAUSS_NEWTON!r}: single shooting on positions (Eq. 16) only; use an NLP solver "
                             "(e.g. ipopt) for multiple shooting or residue 'full'")
        return estimate(model, experiments, run=run, solver=dataclasses.replace(solver, name=None), start=start,
                        uncertainty=uncertainty, check_data=check_data)
    return _nlp_then_estimate(model, experiments, shooting, dataclasses.replace(solver, name=name), run, uncertainty,
                              start, check_data)


def _nlp_then_estimate(model: Model, experiments: list[Experiment], shooting: Shooting, solver: Solver, run: ModelRun,
                       uncertainty: Uncertainty, start: float | dict[str, float] | np.ndarray | None,
                       check_data: bool) -> IdentificationResult:
    """The NLP transcription (:func:`.shooting_nlp.identify_nlp`) of one recording; for Eq. 16 its answer
    polished and reported by the default procedure (:func:`.estimate.estimate`)."""
    transcription, residue = shooting.transcription, shooting.residue
    if len(experiments) > 1 or experiments[0].initial_state == "velocities" or (
            experiments[0].initial_state == "estimate" and residue != "positions"):
        raise ValueError(f"solver {solver.name!r} ({transcription}): one recording, from the scene's initial state or "
                         f"an estimated one (residue 'positions'); use solver {GAUSS_NEWTON!r} (single shooting) for "
                         "several recordings or estimated velocities")
    if residue == "full":
        require_no_uncertain(model, "the full residue (Eq. 17)", uncertainty.uncertain)
    exp = experiments[0]
    nlp_solver = solver
    if solver.name == "ipopt":  # the budget's time holds for IPOPT too: no one waits unboundedly for a failure
        nlp_solver = dataclasses.replace(solver, options=merge_options(
            {"ipopt": {"max_wall_time": solver.limits.max_time}}, solver.options or {}))
    r = identify_nlp(model, exp, float(exp.data.t[-1] - exp.data.t[0]), shooting=shooting, run=run,
                     solver=nlp_solver, start=start)
    if residue == "full":
        return r
    # Eq. 16: the default procedure polishes the NLP's answer and reports it as every result is
    final = estimate(model, experiments, run=run, start=r.extra["solver_parameters"], uncertainty=uncertainty,
                     solver=dataclasses.replace(solver, name=None, options=None, hessian=None, compiled=True),
                     check_data=check_data)
    # the NLP's own answer is the start of the reported one: its solver's convergence and bounds count; its fit
    # to the recording is judged again on the reported answer
    nlp_why = r.extra["refusal"]["other"]
    reasons = [m for m in (f"the NLP solver did not succeed ({r.status}: {'; '.join(nlp_why)})" if nlp_why else "",
                           final.message) if m]
    extra = {**final.extra, "transcription": transcription, "intervals": r.extra["intervals"],
             "hessian": r.extra["hessian"], "nlp": {k: r.extra[k] for k in ("solver_s", "solver_parameters",
                                                                           "constraint_violation", "refusal")},
             "nlp_status": r.status, "nlp_iterations": r.iterations}
    return dataclasses.replace(final, solver=solver.name, status=r.status, iterations=r.iterations,
                               success=not nlp_why and final.success, message="; ".join(reasons),
                               wall_build_s=r.wall_build_s + final.wall_build_s,
                               wall_solve_s=r.wall_solve_s + final.wall_solve_s, extra=extra)
