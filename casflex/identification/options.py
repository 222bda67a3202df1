"""The identification's choices as values: one small frozen object per stage, each checking its own
fields when it is made (the one place that says what a bad value is), shared by the Python functions,
the command line (which builds them from its options) and the study files.

- :class:`Shooting`: how the model is compared with a recording (transcription, intervals, residue, weights);
- :class:`ModelRun`: the model's HHT step, alpha and Newton tolerance;
- :class:`Solver`: which solver, with its options, Hessian, transform, compiled code, budget, polish and loss;
- :class:`Uncertainty`: what the standard errors carry besides the noise (model error, forms, priors);
- :class:`Smoothing`: how the direct methods obtain velocities and accelerations from positions;
- :class:`Budget`: the Gauss-Newton iterations and wall time of one solve.

How a recording is measured (its initial state, compared channels and noise) is
:class:`casflex.identification.measurement.Experiment`. The module is light (no CasADi at import): the
command line's parser imports it.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from casflex.identification.choices import (
    FORMS,
    GAUSS_NEWTON,
    HESSIANS,
    LOSSES,
    MODEL_ERRORS,
    RESIDUES,
    SMOOTHERS,
    TRANSCRIPTIONS,
    TRANSFORMS,
)

if TYPE_CHECKING:
    from casflex.identification.problem import NLPOptions
    from casflex.scene import Scene
    from casflex.scene.uncertain import Uncertain

__all__ = ["Budget", "Shooting", "ModelRun", "Solver", "Uncertainty", "Smoothing", "GAUSS_NEWTON"]



def _choice(name: str, value: Any, choices: tuple[str, ...]) -> None:
    if value not in choices:
        raise ValueError(f"{name}: expected one of {choices}, got {value!r}")


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


@dataclass(frozen=True)
class Budget:
    """Limits of one solve: Gauss-Newton iterations (model runs) and wall time (s)."""

    max_iterations: int = 100
    max_time: float = 600.0

    def __post_init__(self) -> None:
        if not (isinstance(self.max_iterations, int) and self.max_iterations >= 1):
            raise ValueError(f"max_iterations: expected an integer >= 1, got {self.max_iterations!r}")
        if not (_number(self.max_time) and self.max_time > 0):
            raise ValueError(f"max_time: expected a positive number of seconds, got {self.max_time!r}")


@dataclass(frozen=True)
class Shooting:
    """How the model is compared with a recording (Eqs. 15-17, :mod:`.shooting_nlp`).

    transcription : {"single-shooting", "multiple-shooting"}
    interval : steps per multiple-shooting interval (default 20); multiple shooting only.
    residue : {"positions", "full"}, Eq. 16 or Eq. 17 (velocities and accelerations too).
    weights : (xi, psi, phi), Eq. 15's weights of the position, velocity and acceleration residues.
    """

    transcription: str = "single-shooting"
    interval: int | None = None
    residue: str = "positions"
    weights: tuple[float, float, float] = (1.0, 1.0, 1.0)

    def __post_init__(self) -> None:
        _choice("transcription", self.transcription, TRANSCRIPTIONS)
        _choice("residue", self.residue, RESIDUES)
        w = tuple(self.weights)
        if len(w) != 3 or not all(_number(v) and v >= 0 for v in w):
            raise ValueError(f"weights: expected three numbers >= 0 (xi, psi, phi), got {self.weights!r}")
        if self.interval is not None:
            if not (isinstance(self.interval, int) and not isinstance(self.interval, bool) and self.interval >= 1):
                raise ValueError(f"interval: expected a whole number of steps >= 1, got {self.interval!r}")
            if self.transcription != "multiple-shooting":
                raise ValueError("interval: applies to transcription 'multiple-shooting' only")

    @property
    def gauss_newton(self) -> bool:
        """Whether casflex's Gauss-Newton applies: single shooting on positions (Eq. 16)."""
        return self.transcription == "single-shooting" and self.residue == "positions"


@dataclass(frozen=True)
class ModelRun:
    """How the model is simulated: HHT step ``dt`` (s) and ``alpha`` (None: the scene's run settings, never
    the samples' spacing) and the tolerance of the HHT Newton iterations (scaled, see HHT)."""

    dt: float | None = None
    alpha: float | None = None
    newton_tol: float = 1e-12

    def __post_init__(self) -> None:
        if self.dt is not None and not (_number(self.dt) and self.dt > 0):
            raise ValueError(f"dt: must be a positive number of seconds, got {self.dt!r}")
        if self.alpha is not None and not _number(self.alpha):
            raise ValueError(f"alpha: expected a number (HHT alpha, -1/3 to 0), got {self.alpha!r}")
        if not (_number(self.newton_tol) and self.newton_tol > 0):
            raise ValueError(f"newton_tol: expected a positive number, got {self.newton_tol!r}")

    def of(self, scene: Any) -> tuple[float, float]:
        """(dt, alpha): these, or the scene's run settings where None."""
        return (float(scene.run.dt if self.dt is None else self.dt),
                float(scene.run.alpha if self.alpha is None else self.alpha))


@dataclass(frozen=True)
class Solver:
    """How the identification problem is solved.

    name : ``"gauss-newton"`` (casflex's own: single shooting on positions) or a CasADi nlpsol plugin
        (``ipopt``, ``sqpmethod``, ...); None: the method's default (gauss-newton where it applies, else ipopt).
    options : nlpsol options merged into casflex's (nested dicts merged, :func:`.problem.merge_options`).
    hessian : {"exact", "gauss-newton"}, an NLP solver's Hessian of the Lagrangian; None: the method's default.
    transform : {"linear", "log"}, the decision variables (:class:`.problem.ParameterMap`).
    compiled : generate and compile C (cached on disk, :mod:`casflex.codegen`); None: the method's default.
    verbose : the solver's iteration log.
    budget : Gauss-Newton iterations and wall time (None: ``Budget()``, 100 per stage, 600 s); for IPOPT
        the wall time is its ``max_wall_time`` too unless ``options`` set it.
    polish : Gauss-Newton steps after an NLP solver (:func:`.shooting_nlp.identify_nlp`).
    loss : {"linear", "huber"}: least squares, or Huber's, robust to marker artefacts (the indirect method).
    """

    name: str | None = None
    options: dict | None = None
    hessian: str | None = None
    transform: str = "linear"
    compiled: bool | None = None
    verbose: bool = False
    budget: Budget | None = None
    polish: int = 3
    loss: str = "linear"

    def __post_init__(self) -> None:
        if self.name is not None:
            import casadi as ca

            if not isinstance(self.name, str) or not (self.name == GAUSS_NEWTON or ca.has_nlpsol(self.name)):
                raise ValueError(f"solver {self.name!r}: not {GAUSS_NEWTON!r} nor a CasADi NLP solver plugin "
                                 "available here (e.g. ipopt, sqpmethod)")
        if self.options is not None and not isinstance(self.options, dict):
            raise ValueError(f"solver_options: expected a dict of nlpsol options, got {self.options!r}")
        _choice("transform", self.transform, TRANSFORMS)
        if self.hessian is not None:
            _choice("hessian", self.hessian, HESSIANS)
        for name in ("compiled", "verbose"):
            value = getattr(self, name)
            if not (isinstance(value, bool) or (name == "compiled" and value is None)):
                raise ValueError(f"{name}: expected True or False, got {value!r}")
        if self.budget is not None and not isinstance(self.budget, Budget):
            raise ValueError(f"budget: expected a Budget(max_iterations, max_time), got {self.budget!r}")
        if not (isinstance(self.polish, int) and not isinstance(self.polish, bool) and self.polish >= 0):
            raise ValueError(f"polish: expected a whole number of steps >= 0, got {self.polish!r}")
        _choice("loss", self.loss, LOSSES)

    @property
    def limits(self) -> Budget:
        """The budget (``Budget()`` when none is given)."""
        return self.budget or Budget()

    def nlp_options(self, method: str, *, name: str = "ipopt", hessian: str = "gauss-newton",
                    compiled: bool | None = None) -> NLPOptions:
        """The resolved options of an NLP front end ``method`` with its defaults; ``"gauss-newton"`` is refused
        (``method`` is an NLP)."""
        from casflex.identification.problem import NLPOptions

        solver = self.name or name
        if solver == GAUSS_NEWTON:
            raise ValueError(f"solver {GAUSS_NEWTON!r}: the indirect method's single shooting; {method} needs a "
                             "CasADi NLP solver (e.g. ipopt)")
        return NLPOptions(solver=solver, solver_options=self.options, transform=self.transform,
                          hessian=self.hessian or hessian,
                          compiled=compiled if self.compiled is None else self.compiled, verbose=self.verbose)


@dataclass(frozen=True)
class Uncertainty:
    """What the indirect method's standard errors carry besides the noise (:mod:`.estimate`, :mod:`.form`,
    :mod:`.priors`).

    model_error : {"refine", "none"}: the discretisation error by a refit on a refined model, or not.
    form : {"auto", "none"}: refit with casflex's own alternative form too (the other beam theory), or not.
    vary : {"<element>.<field>": (lower, upper)}: scene properties known within a range, refitted at each end.
    alternatives : other forms of the model (scenes or their files) declaring the same parameters.
    uncertain : :class:`casflex.scene.Uncertain` properties (besides the scene's ``[[uncertain]]``) estimated
        with their priors beside the parameters.
    """

    model_error: str = "refine"
    form: str = "auto"
    vary: Mapping[str, tuple[float, float]] | None = None
    alternatives: Sequence[Scene | str | os.PathLike[str]] = ()
    uncertain: Sequence[Uncertain] | None = None

    def __post_init__(self) -> None:
        _choice("model_error", self.model_error, MODEL_ERRORS)
        _choice("form", self.form, FORMS)


@dataclass(frozen=True)
class Smoothing:
    """How the direct methods obtain velocities and accelerations from positions-only data
    (:func:`casflex.identification.smoothing.smooth`): a cross-validated smoothing ``"spline"`` or a
    ``"butterworth"`` filter of ``cutoff`` Hz (default chosen from the data)."""

    kind: str = "spline"
    cutoff: float | None = None

    def __post_init__(self) -> None:
        _choice("smoothing", self.kind, SMOOTHERS)
