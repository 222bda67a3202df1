"""Statics: static equilibrium (adaptive load stepping, stable by default), its stability,
equilibrium paths through limit points, and linearised vibration modes.

Every static solve treats the equilibrium equations

    f_int(q, p) + B^T lambda - s (f_ext(t, p) + g(q, p)) = 0,    Phi(q) = 0,

at load factor s as the stationarity of the total potential Pi(q) = V_el + s (V_g - f_ext . q)
on the supports' constraint set (the loads are conservative and the supports fix dofs, see
:mod:`casflex.statics.problem`). The reaction a support exerts on a constrained dof is
``-lambda`` (see :mod:`casflex.model.constraints`).

- :func:`equilibrium` (:mod:`~casflex.statics.equilibrium`): adaptive load stepping over a
  trust-region minimisation of Pi (:mod:`~casflex.statics.solve`); the result reports its
  stability from the smallest eigenvalue of the reduced tangent.
- :func:`equilibrium_path` (:mod:`~casflex.statics.path`): arc-length continuation through limit
  points, with the stability along the path and its critical points.
- :func:`modes` (:mod:`~casflex.statics.modes`): K v = omega^2 M v about a configuration, with
  a warning when that configuration is not an equilibrium.

The CasADi Functions of a model (:class:`StaticProblem`) are built once and reused.
"""

from casflex.statics.equilibrium import StaticResult, UnstableEquilibrium, equilibrium
from casflex.statics.flutter import CriticalLoad, critical_load
from casflex.statics.modes import ModesResult, modes
from casflex.statics.path import CriticalPoint, PathResult, equilibrium_path
from casflex.statics.problem import (
    ModesError,
    Stability,
    StabilityWarning,
    StaticOptions,
    StaticProblem,
    StaticsError,
    problem_for,
)

__all__ = [
    "CriticalLoad", "CriticalPoint", "ModesError", "ModesResult", "PathResult", "Stability", "StabilityWarning",
    "StaticOptions", "StaticProblem", "StaticResult", "StaticsError", "UnstableEquilibrium", "equilibrium",
    "equilibrium_path", "critical_load", "modes", "problem_for",
]
