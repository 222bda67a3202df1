"""Measurement sets: central differences, validation of user data."""

from __future__ import annotations

import numpy as np
import pytest

from casflex.data import MeasurementSet, measured_set


def test_central_differences_are_exact_for_a_quadratic():
    t = np.linspace(0.0, 1.0, 101)
    q = np.column_stack([3 * t**2 - t + 2, -0.5 * t**2])
    data = MeasurementSet(t, ("x2", "y2"), q, None, None)
    m = measured_set(data)
    assert m.t.shape == (99,) and m.t[0] == t[1] and m.t[-1] == t[-2]
    np.testing.assert_allclose(m.qd[:, 0], 6 * m.t - 1, atol=1e-11)  # exact for quadratics
    np.testing.assert_allclose(m.qdd, np.tile([6.0, -1.0], (99, 1)), atol=1e-8)


def test_noise_is_seeded():
    t = np.linspace(0.0, 1.0, 11)
    data = MeasurementSet(t, ("x2",), np.zeros((11, 1)), None, None)
    a, b = measured_set(data, noise=1e-3, seed=7), measured_set(data, noise=1e-3, seed=7)
    np.testing.assert_array_equal(a.q, b.q)
    assert 0 < np.abs(a.q).max() < 5e-3


@pytest.mark.parametrize("t, q, channels, match", [
    (np.array([0.0, 0.2, 0.1]), np.zeros((3, 1)), ("x2",), r"data.t: times must increase strictly; t\[2\]"),
    (np.array([0.0, 0.1]), np.array([[0.0], [np.nan]]), ("x2",), "non-finite value for channel x2 at t = 0.1"),
    (np.array([0.0, 0.1]), np.zeros((2, 2)), ("x2",), r"data.q: expected shape \(2, 1\)"),
])
def test_bad_data_rejected(t, q, channels, match):
    with pytest.raises(ValueError, match=match):
        MeasurementSet(t, channels, q, None, None)


def test_unknown_channel_and_missing_instant():
    import casflex

    m = casflex.assemble(casflex.load_scene("twobar"))
    data = MeasurementSet(np.array([0.0, 0.1]), ("x9",), np.zeros((2, 1)), None, None)
    with pytest.raises(ValueError, match=r"unknown channels \['x9'\]"):
        data.select(m)
    with pytest.raises(ValueError, match="no sample there"):
        data.index(5.0)
    with pytest.raises(ValueError, match="noise"):
        measured_set(MeasurementSet(np.arange(3.0), ("x2",), np.zeros((3, 1)), None, None), noise=-1.0)
