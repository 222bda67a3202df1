"""The lab's low-pass filter, one implementation for every caller: a 2nd-order Butterworth run forward
and backward (4th order, no phase lag; Winter 2009, ch. 3), with scipy's ``filtfilt`` algorithm and
defaults, in numpy: importing scipy.signal costs 0.8 s, more than a whole ``casflex inverse`` run
(tests/test_filters.py checks it against scipy's to round-off). Used by the inverse dynamics
(:mod:`casflex.inverse`), the lab tables (:mod:`casflex.lab.filtering`) and the measured sets'
smoothing (:mod:`casflex.identification.smoothing`). Beside it, :func:`opensim_lowpass`: the filter OpenSim's
inverse dynamics tool applies to the coordinates, for a lab that wants that tool's answer.
"""

from __future__ import annotations

import numpy as np

__all__ = ["butterworth2", "check_cutoff", "even_times", "filtfilt2", "lowpass", "opensim_lowpass", "runs"]


def even_times(t: np.ndarray, rate: float | None = None) -> np.ndarray:
    """The evenly spaced times t_0 + k h that ``t`` (n,) s writes rounded (lab files print 1/60 s as
    0.017, 0.033: steps 6 % uneven, which would add as much jitter to the rates), if every time lies
    within a tenth of a step of them; otherwise ``t`` unchanged. h is 1 / ``rate`` (Hz, a file's
    header) when given and consistent, else the least-squares slope of t against k."""
    t = np.asarray(t, dtype=float)
    if t.size < 3:
        return t
    k = np.arange(t.size)
    h = np.polyfit(k, t, 1)[0]
    if rate is not None and rate > 0 and abs(1.0 / rate - h) < 0.01 * h:  # rate 0: a header's, or times in ms
        h = 1.0 / rate
    for grid in (t[0] + h * k, np.mean(t - h * k) + h * k):  # from the first time as written, else centred
        if np.max(np.abs(t - grid)) <= 0.1 * h:
            return grid
    return t


def check_cutoff(cutoff: float | None, t: np.ndarray, what: str, option: str = "cutoff") -> None:
    """ValueError naming ``option`` unless the cut-off (Hz) lies below the Nyquist frequency of samples at times
    t (s; ``what`` names them) and above half the inverse of the record's length: a period of more than twice
    the record keeps nothing of its motion but the trend (and at 1e-9 Hz the filter's recursion is singular)."""
    if cutoff is None:
        return
    t = np.asarray(t, dtype=float)
    fs = (t.size - 1) / (t[-1] - t[0])
    span = float(t[-1] - t[0])
    if not cutoff < fs / 2:
        raise ValueError(f"{option}: must lie between 0 and the Nyquist frequency {fs / 2:g} Hz of the {what}, got "
                         f"{cutoff:g}")
    if not cutoff > 0.5 / span:
        raise ValueError(f"{option}: {cutoff:g} Hz is a period over twice the {what}' span of {span:g} s (the lowest "
                         f"cut-off is {0.5 / span:.3g} Hz): it would keep nothing of the motion but its trend")


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[(start, stop)) of the runs of True in ``mask`` (n,): the gaps of a channel, where mask is "missing"."""
    d = np.diff(np.r_[0, np.asarray(mask).astype(np.int8), 0])
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(), strict=True))


def butterworth2(cutoff: float, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """(b, a): the 2nd-order digital Butterworth low-pass at ``cutoff`` Hz for ``fs`` Hz by the bilinear
    transform with prewarping, as ``scipy.signal.butter(2, cutoff / (fs / 2))`` designs it (tested equal)."""
    k = np.tan(np.pi * cutoff / fs)
    norm = 1.0 / (1.0 + np.sqrt(2.0) * k + k * k)
    b0 = k * k * norm
    a2 = (1.0 - np.sqrt(2.0) * k + k * k) * norm
    return np.array([b0, 2.0 * b0, b0]), np.array([1.0, 2.0 * (k * k - 1.0) * norm, a2])


def _lfilter(b: np.ndarray, a: np.ndarray, x: np.ndarray, zi: np.ndarray) -> np.ndarray:
    """Direct form II transposed, 2nd order, along axis 0 of x (n, k), from the state zi (2, k)."""
    y = np.empty_like(x)
    z0, z1 = zi[0].copy(), zi[1].copy()
    for i in range(x.shape[0]):
        y[i] = b[0] * x[i] + z0
        z0 = b[1] * x[i] - a[1] * y[i] + z1
        z1 = b[2] * x[i] - a[2] * y[i]
    return y


def filtfilt2(b: np.ndarray, a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``scipy.signal.filtfilt(b, a, x, axis=0)`` for a 2nd-order filter, its defaults kept (odd
    extension by 3 max(len(a), len(b)) = 9 samples, the steady-state initial conditions of
    ``lfilter_zi``); numpy only, because importing scipy.signal costs 0.8 s, more than a whole
    inverse dynamics run (tested equal to scipy's to round-off)."""
    n_pad = 9
    x = np.asarray(x, dtype=float)
    ext = np.concatenate([2 * x[:1] - x[n_pad:0:-1], x, 2 * x[-1:] - x[-2:-n_pad - 2:-1]], axis=0)
    # lfilter_zi: the state of a unit step's steady response, solved from the 2x2 companion system
    A = np.array([[1.0 + a[1], -1.0], [a[2], 1.0]])
    zi = np.linalg.solve(A, np.array([b[1] - a[1] * b[0], b[2] - a[2] * b[0]]))
    y = _lfilter(b, a, ext, zi[:, None] * ext[:1])
    y = _lfilter(b, a, y[::-1], zi[:, None] * y[-1:])[::-1]
    return y[n_pad:-n_pad]


def lowpass(t: np.ndarray, x: np.ndarray, cutoff: float | None, what: str = "data") -> np.ndarray:
    """x (n, k) filtered along its rows by the zero-lag 4th-order Butterworth at ``cutoff`` Hz (None:
    unfiltered; a 2nd-order filter run forward and backward); evenly spaced t (s) needed (to the
    rounding :func:`even_times` allows)."""
    if cutoff is None:
        return np.array(x, dtype=float)
    t = even_times(t)
    h = np.diff(t)
    if np.ptp(h) > 1e-6 * h.mean():
        raise ValueError(f"{what}: filtering needs evenly spaced samples (times {h.min():g} to {h.max():g} s apart)")
    fs = 1.0 / h.mean()
    if not 0 < cutoff < fs / 2:
        raise ValueError(f"cutoff: must lie between 0 and the Nyquist frequency {fs / 2:g} Hz of the {what}, "
                         f"got {cutoff:g}")
    if t.size <= 10:
        raise ValueError(f"{what}: filtering needs more than 10 samples, got {t.size}")
    x = np.asarray(x, dtype=float)
    return filtfilt2(*butterworth2(cutoff, fs), x.reshape(t.size, -1)).reshape(x.shape)


def _butterworth3(cutoff: float, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """(b, a) of the 3rd-order Butterworth low-pass that OpenSim's ``Signal::LowpassIIR`` builds (bilinear
    transform with prewarping): numerator b (4,), denominator a (4,) with a[0] = 1."""
    w = np.tan(np.pi * cutoff / fs)
    den = (w + 1.0) * (w * w + w + 1.0)
    b = np.array([1.0, 3.0, 3.0, 1.0]) * w**3 / den
    a = np.array([1.0, (3 * w**3 + 2 * w * w - 2 * w - 3) / den, (3 * w**3 - 2 * w * w - 2 * w + 3) / den,
                  (w - 1.0) * (w * w - w + 1.0) / den])
    return b, a


def _iir3(b: np.ndarray, a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """OpenSim's recursion along axis 0 of x (n, k): its first three samples copied, then the 3rd-order filter."""
    y = x.copy()
    for i in range(3, x.shape[0]):
        y[i] = b[0] * x[i] + b[1] * x[i - 1] + b[2] * x[i - 2] + b[3] * x[i - 3] \
            - a[1] * y[i - 1] - a[2] * y[i - 2] - a[3] * y[i - 3]
    return y


def opensim_lowpass(t: np.ndarray, x: np.ndarray, cutoff: float) -> tuple[np.ndarray, np.ndarray, slice]:
    """The coordinates' filter of OpenSim's inverse dynamics tool (``lowpass_cutoff_frequency_for_coordinates``):
    the record x (n, k) at evenly spaced t (n,) s padded at both ends by n // 2 samples reflected about its end
    points (value and slope kept: ``Storage::pad``), then ``Signal::LowpassIIR``: a 3rd-order Butterworth at
    ``cutoff`` Hz run forward and backward (6th order, no lag, -6 dB at the cut-off), each pass starting with
    its first three samples copied. Returns the padded times, the filtered padded record and the slice of the original
    samples in it: the rates are taken on the padded record (OpenSim fits its splines to it), away from its
    ends."""
    t = even_times(np.asarray(t, dtype=float))
    x = np.asarray(x, dtype=float).reshape(t.size, -1)
    n, p = t.size, t.size // 2
    if n < 8:
        raise ValueError(f"filtering needs at least 8 samples, got {n}")
    h = (t[-1] - t[0]) / (n - 1)
    padded = np.concatenate([2 * x[:1] - x[p:0:-1], x, 2 * x[-1:] - x[-2:-p - 2:-1]], axis=0)
    b, a = _butterworth3(cutoff, 1.0 / h)
    y = _iir3(b, a, _iir3(b, a, padded)[::-1])[::-1]
    tp = t[0] + h * np.arange(-p, n + p)
    return tp, y, slice(p, p + n)
