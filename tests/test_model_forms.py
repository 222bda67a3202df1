"""One model for the forms an identification compares (casflex.model.forms): the beams' rotary inertia and the
varied properties as run-time inputs give each form's own numbers."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import casflex
from casflex.model import form_inputs


def _forms():
    scene = casflex.load_scene("twobar")
    rotary = dataclasses.replace(scene, beams=tuple(dataclasses.replace(b, rotary_inertia=True) for b in scene.beams))
    stiffer = scene.with_property("bar2.E", 2.4e11)
    return scene, rotary, stiffer


def test_every_form_is_one_model_with_its_own_numbers():
    vary = {"bar2.E": (1.6e11, 2.4e11)}
    models = [casflex.assemble(s) for s in _forms()]
    found = [form_inputs(m, vary) for m in models]
    shared = found[0][0]
    assert all(f[0] is shared for f in found)  # one model, so one generated C and one compiled library
    assert shared.n_p == models[0].n_p + len(models[0].scene.beams) + 1
    rng = np.random.default_rng(0)
    q = models[0].q0 + 0.05 * rng.normal(size=models[0].n_dof)
    qd = rng.normal(size=models[0].n_dof)
    for m, (_, inputs) in zip(models, found, strict=True):
        p = np.concatenate([m.p_nominal, inputs])
        # the same operations on the same numbers (a weight of 0 adds an exact 0, 1 multiplies by an exact 1)
        np.testing.assert_array_equal(np.array(shared.mass(q, p)), np.array(m.mass(q, m.p_nominal)))
        for a, b in zip(shared.forces(q, qd, p), m.forces(q, qd, m.p_nominal), strict=True):
            np.testing.assert_array_equal(np.array(a), np.array(b))
    # the forms differ: the inputs carry what tells them apart
    assert not np.array_equal(np.array(models[0].mass(q, models[0].p_nominal)),
                              np.array(models[1].mass(q, models[1].p_nominal)))


def test_a_fitted_property_is_no_input():
    model = casflex.assemble(casflex.load_scene("twobar"))
    fitted = model.scene.parameters[0].target
    shared, inputs = form_inputs(model, {fitted: (1.0, 2.0)})
    assert shared.n_p == model.n_p + len(model.scene.beams) and inputs.size == len(model.scene.beams)
    with pytest.raises(ValueError, match="is a parameter already"):
        casflex.assemble(model.scene, inputs=(fitted,))
