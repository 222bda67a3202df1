"""The forward simulation: ``simulate(model, t_end, ...) -> Trajectory`` by HHT-alpha (:mod:`casflex.simulate.run`;
``simulated_set``: a run as a :class:`~casflex.data.MeasurementSet`),
run here (interpreted or compiled) or exported as standalone C with an example program
(:mod:`casflex.simulate.export`, ``casflex export``)."""

from casflex.simulate.run import (
    CHUNK,
    ENERGY_GROWTH,
    SimulationError,
    check_memory,
    compiled_library,
    format_bytes,
    initial_state,
    integrator_for,
    memory_available,
    simulate,
    simulated_set,
    step_count,
)

__all__ = ["simulate", "simulated_set", "SimulationError", "integrator_for", "step_count", "check_memory", "CHUNK",
           "ENERGY_GROWTH", "compiled_library", "initial_state", "memory_available", "format_bytes"]
