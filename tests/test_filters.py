"""casflex.lab.lowpass: the lab's zero-lag Butterworth against scipy's, its response against theory, and
rounded lab times."""

from __future__ import annotations

import numpy as np
import pytest

from casflex.inverse.fit import coordinate_rates
from casflex.lab.lowpass import butterworth2, even_times, filtfilt2, lowpass


@pytest.mark.parametrize(("cutoff", "fs"), [(6.0, 60.0), (10.0, 100.0), (15.0, 1000.0)])
def test_lab_filter_is_scipys(cutoff, fs):
    from scipy.signal import butter, filtfilt

    b, a = butter(2, cutoff / (fs / 2))
    b2, a2 = butterworth2(cutoff, fs)
    assert np.allclose(b, b2, rtol=1e-14, atol=0) and np.allclose(a, a2, rtol=1e-14, atol=1e-16)
    x = np.random.default_rng(1).standard_normal((200, 3)).cumsum(0)
    # the same recursion in another order of operations: round-off, amplified by the filter's gain (~1e2)
    assert np.abs(filtfilt(b, a, x, axis=0) - filtfilt2(b2, a2, x)).max() < 1e-12 * np.abs(x).max()


def test_filter_keeps_slow_motion_and_removes_fast():
    t = np.arange(0, 2, 0.01)
    slow, fast = np.sin(2 * np.pi * 1.0 * t), np.sin(2 * np.pi * 30.0 * t)
    out = lowpass(t, np.column_stack([slow, fast]), 6.0)
    mid = slice(50, 150)
    # |H|^2 of the 2nd-order Butterworth run twice: 1 / (1 + (f/fc)^4); at 1 Hz 0.9992, at 30 Hz 1.6e-3 (prewarped)
    assert np.abs(out[mid, 0] - slow[mid]).max() < 2e-3
    assert np.abs(out[mid, 1]).max() < 5e-3


def test_even_times_snap_rounded_frames_only():
    t = np.round(np.arange(20) / 60, 3)  # a lab file's 0.017, 0.033, ...
    assert np.allclose(np.diff(even_times(t, 60.0)), 1 / 60, rtol=1e-12)  # the header's rate
    assert np.allclose(np.diff(even_times(t)), 1 / 60, rtol=1e-3)  # the slope: rounding's 0.5 ms over 20 frames
    uneven = np.cumsum(np.r_[0, np.full(9, 0.01), np.full(10, 0.02)])
    assert even_times(uneven) is not None and np.array_equal(even_times(uneven), uneven)
    with pytest.raises(ValueError, match="evenly spaced"):
        lowpass(uneven, uneven[:, None], 6.0)
    zd, zdd = coordinate_rates(np.arange(10) * 0.1, (np.arange(10) * 0.1)[:, None] ** 2)
    assert np.allclose(zd[:, 0], 2 * np.arange(10) * 0.1) and np.allclose(zdd, 2.0)  # exact on quadratics


def test_seven_point_rates_are_exact_on_quintics_and_keep_a_10_hz_acceleration():
    t = np.arange(40) / 60.0
    c = np.array([0.3, -1.2, 2.0, 0.7, -3.1, 1.5])  # a quintic: the 7-, 5- and 3-point stencils' orders cover it
    p = np.polynomial.Polynomial(c)
    zd, zdd = coordinate_rates(t, p(t)[:, None])
    inner = slice(3, -3)
    assert np.allclose(zd[inner, 0], p.deriv(1)(t[inner]), rtol=0, atol=1e-9)
    assert np.allclose(zdd[inner, 0], p.deriv(2)(t[inner]), rtol=0, atol=1e-7)
    # a 10 Hz motion sampled at 60 Hz: the 7-point stencils' transfer at omega h = pi / 3 is 0.992 (velocity)
    # and 0.998 (acceleration); the textbook's 3-point ones keep 0.827 and 0.912 of it
    w = 2 * np.pi * 10.0
    zd, zdd = coordinate_rates(t, np.sin(w * t)[:, None])
    assert np.abs(zd[inner, 0] / w - np.cos(w * t[inner])).max() < 0.009
    assert np.abs(zdd[inner, 0] / w**2 + np.sin(w * t[inner])).max() < 0.003


def test_opensims_filter_halves_its_cut_off_and_keeps_slow_motion():
    from casflex.lab.lowpass import opensim_lowpass

    t = np.arange(600) / 60.0
    fc = 6.0
    x = np.column_stack([np.sin(2 * np.pi * fc * t), np.sin(2 * np.pi * 0.2 * fc * t), 0.5 + 0.3 * t])
    tp, y, keep = opensim_lowpass(t, x, fc)
    assert tp.size == y.shape[0] == 600 + 2 * 300 and np.allclose(tp[keep], t) and keep.stop - keep.start == 600
    mid = slice(keep.start + 100, keep.stop - 100)
    # the prewarped 3rd-order Butterworth: |H(fc)|^2 = 1/2 for both passes; at fc / 5, 1 / (1 + 5^-6) = 0.99994
    assert abs(np.sqrt(2 * np.mean(y[mid, 0] ** 2)) - 0.5) < 0.005  # 40 whole periods: RMS = amplitude / sqrt 2
    assert np.abs(y[mid, 1] - x[100:500, 1]).max() < 2e-4
    # a line passes: the padding keeps value and slope, the filter's gain at 0 is 1 (its start-up transient
    # stays in the padding)
    assert np.abs(y[keep, 2] - x[:, 2]).max() < 1e-6
