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
