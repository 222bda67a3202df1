"""EMG envelopes beside static optimization's activations (drawn on or off only: an envelope's height is not an
activation, its timing is what compares).

A trial's raw EMG from a C3D file's analog channels (by their ANALOG:LABELS) or an OpenSim .mot / .sto table with
EMG columns, the channels named per muscle. Each column's
envelope: band-pass 20-400 Hz (the upper edge at most 0.45 of the sampling rate; 4th order, Butterworth, forward and
backward: no lag), rectified, low-pass 6 Hz (4th order, no lag), normalised to its peak over the trial's window, then
sampled at the trial's frames. Refused in one line naming the file and the column: a column the file does not
have, a muscle the model does not have, a file that does not span the trial's window, a rate below 100 Hz (a
table already smoothed: the band-pass would empty it).
"""

from __future__ import annotations

import os
from collections.abc import Mapping

import numpy as np

__all__ = ["BAND", "LOW_PASS", "emg_envelopes", "envelope"]

#: The band-pass (Hz) and the envelope's low-pass (Hz).
BAND, LOW_PASS = (20.0, 400.0), 6.0
#: The lowest sampling rate (Hz) of a raw EMG.
MIN_RATE = 100.0


def envelope(t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The envelope (module docstring, not normalised) of the raw signal x at the evenly spaced times t (s)."""
    from scipy.signal import butter, sosfiltfilt

    fs = (t.size - 1) / (t[-1] - t[0])
    band = butter(2, [BAND[0], min(BAND[1], 0.45 * fs)], btype="bandpass", fs=fs, output="sos")
    low = butter(4, LOW_PASS, btype="lowpass", fs=fs, output="sos")
    return sosfiltfilt(low, np.abs(sosfiltfilt(band, x - np.mean(x))))


def emg_envelopes(path: str | os.PathLike[str], columns: Mapping[str, str], t: np.ndarray,
                  muscles: tuple[str, ...] = ()) -> dict[str, np.ndarray]:
    """muscle -> its EMG envelope (k,) at the trial's times t (s), normalised to 1 at its peak over [t[0], t[-1]]:
    ``columns`` muscle -> the file's column; ``muscles`` the model's (a muscle not among them refused)."""
    from casflex.lab.c3d import read_c3d_analogs
    from casflex.lab.tables import read_sto

    where = f"emg: {os.fspath(path)}"
    for m in columns:
        if muscles and m not in muscles:
            raise ValueError(f"{where}: muscle {m!r} is no muscle of the model")
    table = read_c3d_analogs(path) if os.fspath(path).lower().endswith(".c3d") else read_sto(path)
    for m, c in columns.items():
        if c not in table.names:
            raise ValueError(f"{where}: column {c!r} (for {m!r}) is not in the file; its columns are "
                             f"{list(table.names[:12])}")
    te = np.asarray(table.t, dtype=float)
    t = np.asarray(t, dtype=float)
    if te.size < 3 or te[0] > t[0] + 1e-9 or te[-1] < t[-1] - 1e-9:
        raise ValueError(f"{where}: spans {te[0]:g}..{te[-1]:g} s; the trial's window is {t[0]:g}..{t[-1]:g} s")
    steps = np.diff(te)
    fs = 1.0 / np.median(steps)
    if fs < MIN_RATE or np.abs(steps - 1.0 / fs).max() > 1e-3 / fs:
        raise ValueError(f"{where}: sampled at {fs:g} Hz" + (", unevenly" if fs >= MIN_RATE else "")
                         + f": an envelope needs the raw EMG, evenly sampled at {MIN_RATE:g} Hz or more")
    inside = (te >= t[0] - 1e-9) & (te <= t[-1] + 1e-9)
    out = {}
    for m, c in columns.items():
        x = np.asarray(table.column(c), dtype=float)
        bad = ~np.isfinite(x)
        if bad.any():  # the filters run over the whole record: one NaN would make the whole envelope NaN
            raise ValueError(f"{where}: column {c!r} (for {m!r}) has no number at {int(bad.sum())} samples (t = "
                             f"{te[bad][0]:g}..{te[bad][-1]:g} s; NaN or infinite); fill the gap or cut the file")
        env = envelope(te, x)
        peak = env[inside].max()
        if not peak > 0:
            raise ValueError(f"{where}: column {c!r} (for {m!r}) is flat over the trial's window")
        out[m] = np.interp(t, te, env) / peak
    return out
