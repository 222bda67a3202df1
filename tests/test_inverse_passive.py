"""casflex.inverse.passive: a torsion spring-damper fitted to a net joint moment, on a pendulum whose
motion an independent integrator (scipy's DOP853) made, from noisy markers."""

from __future__ import annotations

import numpy as np
import pytest
from inverse_scenes import INERTIA, C, M, pendulum
from scipy.integrate import solve_ivp

from casflex.inverse import Filter, Trial, inverse_dynamics, inverse_model, kinematic_tree
from casflex.inverse.passive import fit_passive
from casflex.lab import LabMarkers
from casflex.model.markers import marker_positions
from casflex.scene.io import loads_scene

KT, CT, REST = 4.0, 0.15, 0.2  # N m/rad, N m s/rad, rad


def _trial(muscle: float, seed: int = 3, noise: float = 5e-4):
    """Markers (100 Hz, 2 s, ``noise`` m) of the pendulum swinging on its spring-damper from 0.9 rad, with a
    'muscle' moment muscle * sin(9 t) (N m) on top."""
    def rhs(t, s):
        th, om = s
        tau = -KT * (th - REST) - CT * om + muscle * np.sin(9.0 * t)
        return [om, (tau - M * 9.81 * C * np.sin(th)) / (INERTIA + M * C * C)]

    t = np.arange(0.0, 2.0 + 1e-9, 0.01)
    th = solve_ivp(rhs, (0, 2), [0.9, 0.0], method="DOP853", t_eval=t, rtol=1e-11, atol=1e-12).y[0]
    model = inverse_model(loads_scene(pendulum()))
    tree = kinematic_tree(model)
    z = np.column_stack([np.zeros_like(t), np.ones_like(t), np.zeros_like(t), th])
    y = marker_positions(model, np.array(tree.forward.map(t.size)(z.T)).T).reshape(t.size, -1, 2)
    y = y + np.random.default_rng(seed).normal(0.0, noise, y.shape)
    xyz = np.concatenate([y, np.zeros_like(y[..., :1])], axis=2)
    return LabMarkers(t, ("BASE.1", "BASE.2", "ARM.1", "ARM.2"), xyz, 100.0, "m", "synthetic")


def test_a_passive_swing_gives_back_its_spring_and_damper():
    res = inverse_dynamics(loads_scene(pendulum()), Trial(_trial(0.0)), filter=Filter(cutoff=8.0))
    fit = fit_passive(res, "pivot", 0.1, 1.9)  # the filter's ends left out
    assert fit.passive and fit.r2 > 0.95
    for name, truth in (("kt", KT), ("ct", CT), ("rest_angle", REST)):
        # the truth within 3 standard errors, and the errors not vacuous (under 20 % of the value)
        assert abs(getattr(fit, name) - truth) < 3 * fit.se[name] + 1e-12, (name, getattr(fit, name), fit.se[name])
        assert fit.se[name] < 0.2 * truth, name
    assert "explains" in fit.summary()


def test_a_muscle_at_work_is_not_explained():
    res = inverse_dynamics(loads_scene(pendulum()), Trial(_trial(2.0)), filter=Filter(cutoff=15.0))
    fit = fit_passive(res, "pivot", 0.1, 1.9)
    assert not fit.passive and fit.r2 < 0.8
    assert "not a passive joint: it explains" in fit.summary()


def test_bad_hinge_or_window_is_one_line():
    res = inverse_dynamics(loads_scene(pendulum()), Trial(_trial(0.0)), filter=Filter(cutoff=8.0))
    with pytest.raises(ValueError, match="no hinge 'knee'"):
        fit_passive(res, "knee")
    with pytest.raises(ValueError, match="window 3..4 s holds 0 frames"):
        fit_passive(res, "pivot", 3.0, 4.0)
