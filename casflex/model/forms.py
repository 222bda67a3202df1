"""One model for the forms an identification compares (:mod:`casflex.identification.form`): the properties that
distinguish them as run-time inputs of the equations, appended to p, so that the fit and its refits run one
generated C, compiled once."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np

from casflex.model.model import Model, _assembled, assemble
from casflex.scene import Scene

__all__ = ["form_inputs"]


def form_inputs(model: Model, vary: Mapping[str, tuple[float, float]] | None = None
                ) -> tuple[Model, np.ndarray] | None:
    """The model of ``model``'s scene with every beam's ``rotary_inertia`` (its weight, 0 or 1) and the properties
    in ``vary`` ({target: (lower, upper)}, an identification's declared ranges) run-time inputs appended to p, and
    those inputs' values for ``model``; None for a scene without beams and nothing to vary.

    The model forms that an identification compares (:mod:`casflex.identification.form`: the other beam theory,
    a property at the ends of its range) are then one model, one generated C and one compiled library: twobar's
    sensitivities (387 kB of C, gcc -O1) were compiled for the fit and again for each refit. Evaluated at p = (the
    parameters, the values) its Functions give ``model``'s numbers (a weight of 0 adds an exact 0, 1 multiplies by
    an exact 1; a property is the same number in a slot of the table as in its place). Shared in this process by
    every model whose scene differs from ``model``'s in those properties alone. A property the equations do not
    take as a number (none that can be a parameter, today) stays a constant."""
    scene, vary = model.scene, dict(vary or {})
    fitted = {p.target for p in scene.parameters}
    vary = {t: v for t, v in vary.items() if t not in fitted}
    if not scene.beams and not vary:
        return None
    plain = dataclasses.replace(scene, beams=tuple(dataclasses.replace(b, rotary_inertia=False) for b in scene.beams))
    try:
        for t, (lo, _) in vary.items():  # the scene of every form: each varied property at its lower end
            plain = plain.with_property(t, float(lo))
        found = _assembled_inputs(plain, model.inertia, tuple(f"{b.name}.rotary_inertia" for b in scene.beams),
                                  tuple(vary))
    except (ValueError, TypeError):  # a property the equations do not take as a number: the beams' inputs alone
        if not vary:
            raise
        return form_inputs(model)
    return found, np.array([float(b.rotary_inertia) for b in scene.beams] + [scene.property_value(t) for t in vary])


def _assembled_inputs(scene: Scene, inertia: str, rotary: tuple[str, ...], varied: tuple[str, ...]) -> Model:
    try:
        hash(scene)
    except TypeError:
        return assemble(scene, inertia=inertia, inputs=rotary + varied)
    return _assembled(scene, inertia, rotary + varied)
