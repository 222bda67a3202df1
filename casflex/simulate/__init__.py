"""The forward simulation: ``simulate(model, t_end, ...) -> Trajectory`` by HHT-alpha (:mod:`casflex.simulate.run`;
``simulated_set``: a run as a :class:`~casflex.data.MeasurementSet`),
run here (interpreted or compiled) or exported as standalone C with an example program
(:mod:`casflex.simulate.export`, ``casflex export``). Its choices are values (:mod:`casflex.simulate.options`):
``simulate(model, t_end, stepping=Stepping(dt=1e-3, alpha=-0.05), start=Start(q0=q))``.

The package is also the verb: ``casflex.simulate(model, t_end, ...)`` calls :func:`simulate`.
"""

import sys
import types

from casflex.simulate.options import Start, Stepping
from casflex.simulate.run import (
    CHUNK,
    ENERGY_GROWTH,
    SimulationError,
    check_memory,
    compile_pays,
    compiled_library,
    format_bytes,
    initial_state,
    integrator_for,
    memory_available,
    simulate,
    simulated_set,
    step_count,
)

__all__ = ["simulate", "simulated_set", "Stepping", "Start", "SimulationError", "integrator_for", "step_count",
           "check_memory", "CHUNK", "ENERGY_GROWTH", "compiled_library", "compile_pays", "initial_state",
           "memory_available", "format_bytes"]


class _Verb(types.ModuleType):
    """This package, callable as :func:`simulate` (``casflex.simulate(model, t_end)``): the name ``casflex.simulate``
    is bound to the package as soon as anything imports it, so the verb is the package."""

    def __call__(self, *args, **kwargs):
        return simulate(*args, **kwargs)


sys.modules[__name__].__class__ = _Verb
