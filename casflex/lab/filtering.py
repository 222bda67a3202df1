"""Lab data filtered the way motion labs filter it, and force plates' loads in a form that may be filtered.

:func:`filtered`: the lab's zero-lag low-pass Butterworth (:mod:`casflex.lab.lowpass`: a 2nd-order Butterworth
run forward and backward, scipy's ``filtfilt`` algorithm: 4th order, no phase lag), per marker coordinate of a
:class:`~casflex.lab.LabMarkers` or per column of a :class:`~casflex.lab.LabTable`, at ``cutoff_hz``.

- The cut-off is each pass's -3 dB frequency, as everywhere in casflex, *not* corrected for the
  double pass as Winter (2009, sec. 3.4.4.3) corrects it: the zero-lag filter is at -6 dB there and at
  -3 dB at about 0.802 x the cut-off (:func:`zero_lag_minus_3db` gives the exact digital value). For
  Winter's convention pass ``cutoff_hz / 0.802``.
- Even sampling is needed: times within a tenth of a step of an even grid (lab files print 1/60 s as
  0.017, 0.033: that rounding passes), else one ValueError line.
- Missing samples (NaN): a gap inside a channel of at most ``max_gap`` samples (default
  :data:`MAX_GAP`, 10) is filled by a cubic spline (``scipy.interpolate.CubicSpline``, not-a-knot,
  through the channel's samples) and stays filled in the result; the report names it. A longer gap is
  refused in one line naming the marker or column and the gap's times. Samples missing at the start or
  the end (a marker not yet, or no longer, seen) stay NaN and the stretch between them is filtered
  alone; a channel with no samples stays NaN. A marker is missing as a whole (its three coordinates).

A force plate's centre of pressure p is a moment divided by the vertical force: where that force is
small, p is noise, and where it vanishes p is undefined, so p is not to be filtered. The force F and the
moment about the lab's origin M = p x F + T (T the free moment) are linear in the plate's signals:
:func:`plate_moment_about_origin` gives them, they are filtered, and :func:`centre_of_pressure` goes back
to p and T.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from casflex.lab.c3d import MIN_PLATE_FORCE

if TYPE_CHECKING:
    from casflex.lab.tables import LabMarkers, LabTable

__all__ = ["filtered", "plate_moment_about_origin", "plate_wrench", "centre_of_pressure", "zero_lag_minus_3db",
           "MAX_GAP"]

#: samples: the longest gap inside a channel that :func:`filtered` fills by a cubic spline.
MAX_GAP = 10
_MIN_SAMPLES = 10  # scipy's filtfilt pads 9 samples at each end of a 2nd-order filter: needs more


def zero_lag_minus_3db(cutoff_hz: float, rate_hz: float) -> float:
    """Hz: where the zero-lag filter of :func:`filtered` at ``cutoff_hz`` (sampling ``rate_hz``) is at
    -3 dB: |H|^2 = 1 / (1 + (tan(pi f / fs) / tan(pi fc / fs))^4) = 1 / sqrt(2)."""
    return rate_hz / math.pi * math.atan((math.sqrt(2.0) - 1.0) ** 0.25 * math.tan(math.pi * cutoff_hz / rate_hz))


def _rate(t: np.ndarray, where: str) -> tuple[float, np.ndarray]:
    """(rate Hz, the even grid of t: :func:`casflex.lab.lowpass.even_times`); ValueError unless every time lies
    within a tenth of a step of it."""
    from casflex.lab.lowpass import even_times

    if t.size < _MIN_SAMPLES:
        raise ValueError(f"{where}: filtering needs at least {_MIN_SAMPLES} samples, got {t.size}")
    h = (t[-1] - t[0]) / (t.size - 1)
    grid = even_times(t)
    off = np.abs(t - (t[0] + h * np.arange(t.size)))
    if not h > 0 or np.ptp(np.diff(grid)) > 1e-9 * h:
        k = int(np.argmax(off))
        raise ValueError(f"{where}: filtering needs evenly spaced samples: t = {t[k]:g} s is {off[k]:g} s off the "
                         f"grid of {h:g} s steps")
    return 1.0 / (grid[1] - grid[0]), grid


def _filter_channel(t: np.ndarray, grid: np.ndarray, y: np.ndarray, cutoff: float, name: str, where: str,
                    max_gap: int) -> tuple[np.ndarray, list[str]]:
    """y (n, c) of one marker or column at times t (their even grid: grid) filtered: gaps filled (at most
    max_gap samples), the ends missing kept missing; (result, notes for the report)."""
    from scipy.interpolate import CubicSpline

    from casflex.lab.lowpass import butterworth2, filtfilt2, runs

    ok = np.isfinite(y).all(axis=1)
    out = np.full_like(y, np.nan, dtype=float)
    if not ok.any():
        return out, [f"{name}: no samples, left missing"]
    a, b = int(np.argmax(ok)), int(ok.size - np.argmax(ok[::-1]))
    notes = []
    if a or b < ok.size:
        notes.append(f"{name}: missing at the ends ({a} + {ok.size - b} samples), left missing; filtered "
                     f"from t = {t[a]:g} to {t[b - 1]:g} s")
    if b - a < _MIN_SAMPLES:
        raise ValueError(f"{where}: {name}: only {b - a} samples in a row (t = {t[a]:g} to {t[b - 1]:g} s); "
                         f"filtering needs {_MIN_SAMPLES}")
    seg = y[a:b].astype(float)
    for s, e in runs(~ok[a:b]):
        if e - s > max_gap:
            raise ValueError(f"{where}: {name}: a gap of {e - s} samples (t = {t[a + s]:g} to "
                             f"{t[a + e - 1]:g} s) is longer than max_gap = {max_gap} samples, the longest a "
                             "cubic spline fills")
        seg[s:e] = CubicSpline(grid[a:b][ok[a:b]], seg[ok[a:b]])(grid[a + s:a + e])
        notes.append(f"{name}: {e - s} samples filled by a cubic spline (t = {t[a + s]:g} to "
                     f"{t[a + e - 1]:g} s)")
    out[a:b] = filtfilt2(*butterworth2(cutoff, 1.0 / (grid[1] - grid[0])), seg)
    return out, notes


def filtered(data: LabMarkers | LabTable, cutoff_hz: float, order: int = 4, *, max_gap: int = MAX_GAP,
             names: Sequence[str] | None = None) -> tuple[LabMarkers | LabTable, str]:
    """(a copy of ``data`` low-pass filtered, a short report): markers (n, k, 3) m per coordinate, a table's
    columns (n, m) per column, at ``cutoff_hz`` (Hz, below half the rate), by the zero-lag Butterworth of
    ``order`` 4 (the only order: casflex.lab.lowpass'); ``names``: the markers or columns to filter
    (default all; the others are copied as they are). Gaps as the module docstring says."""
    from casflex.lab.tables import LabMarkers

    where = data.source or type(data).__name__
    if order != 4:
        raise ValueError(f"order: only 4, a 2nd-order Butterworth run forward and backward, got {order}")
    is_markers = isinstance(data, LabMarkers)
    have = data.labels if is_markers else data.names
    chosen = list(have) if names is None else list(names)
    unknown = [n for n in chosen if n not in have]
    if unknown:
        raise ValueError(f"{where}: no {'marker' if is_markers else 'column'} {unknown[0]!r}; there are {list(have)}")
    t = np.asarray(data.t, dtype=float)
    fs, grid = _rate(t, where)
    if not 0 < cutoff_hz < fs / 2:
        raise ValueError(f"cutoff: must lie between 0 and the Nyquist frequency {fs / 2:g} Hz, got {cutoff_hz:g}")
    values = np.array(data.xyz if is_markers else data.values, dtype=float)
    notes: list[str] = []
    for name in chosen:
        i = have.index(name)
        block = values[:, i] if is_markers else values[:, i:i + 1]
        block[:], more = _filter_channel(t, grid, block, cutoff_hz, name, where, max_gap)
        notes += more
    cop = [n for n in chosen if not is_markers and "force_p" in n]
    if cop:
        notes.append(f"{', '.join(cop)}: centres of pressure, filtered as asked; filtering a plate's force and "
                     "moment about the origin is sounder (plate_moment_about_origin, centre_of_pressure)")
    new = replace(data, xyz=values) if is_markers else replace(data, values=values, header=dict(data.header))
    head = (f"zero-lag Butterworth low-pass, order 4 (2nd order forward and backward), cut-off {cutoff_hz:g} Hz "
            f"per pass, not corrected for the double pass (-3 dB at {zero_lag_minus_3db(cutoff_hz, fs):.3g} Hz), "
            f"{fs:g} Hz sampling; {len(chosen)} of {len(have)} {'markers' if is_markers else 'columns'} filtered")
    return new, "\n".join([head] + notes)


def _plate_columns(table: LabTable, prefix: str) -> str:
    """The column prefix of plate ``prefix`` ("ground_", "1_ground_"; "" and "1_" stand for them)."""
    for p in (prefix, prefix + "ground_"):
        if f"{p}force_vx" in table.names:
            return p
    have = sorted({n[:-len("force_vx")] for n in table.names if n.endswith("force_vx")})
    raise ValueError(f"{table.source}: no plate {prefix!r} (columns {prefix}force_vx ...); the plates there are "
                     f"{have or 'none'}")


def plate_wrench(table: LabTable, prefix: str, *, min_force: float = MIN_PLATE_FORCE
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(force F (n, 3) N, moment about the lab's origin M (n, 3) N m, unloaded (n,) bool) of the plate ``prefix``
    of an OpenSim-style ground-reaction table ("ground_" the first plate, "1_ground_" the second), with the
    samples the table does not give as NaN rows (to be filled or refused by the caller).

    M is the table's ``<prefix>moment_{x,y,z}`` where :func:`casflex.lab.c3d.read_c3d` gave them, else p x F + T
    from the centre of pressure p and the free moment T. A sample is missing where a force component or the
    moment is not a number. A force below ``min_force`` (N, in magnitude) whose point of application the
    table leaves undefined (NaN centre of pressure: the convention of exports that write none where the plate
    is unloaded) is taken as no load, F = M = 0, and flagged in ``unloaded``; a larger force without a centre
    of pressure is missing. Forces, centres of pressure and moments no lab records
    (:func:`casflex.lab.checks.check_plate_values`) are refused in one line naming the plate and the time."""
    from casflex.lab.checks import check_plate_values

    p = _plate_columns(table, prefix)

    def cols(kind: str) -> np.ndarray:
        return np.column_stack([table.column(f"{p}{kind}{a}") for a in "xyz"]).astype(float)

    F = cols("force_v")
    with np.errstate(invalid="ignore", over="ignore"):
        size = np.linalg.norm(F, axis=1)
    if f"{p}moment_x" in table.names:
        M, P = cols("moment_"), None
        check_plate_values(table, p, F, None, M)
    else:
        P, T = cols("force_p"), cols("torque_")
        T[~np.isfinite(T).all(axis=1) & np.isfinite(P).all(axis=1) & (size == 0)] = 0.0
        check_plate_values(table, p, F, P, T)
        with np.errstate(invalid="ignore", over="ignore"):
            M = np.cross(P, F) + T
    unloaded = np.isfinite(F).all(axis=1) & ~np.isfinite(M).all(axis=1) & (size < min_force)
    F[unloaded], M[unloaded] = 0.0, 0.0
    missing = ~(np.isfinite(F).all(axis=1) & np.isfinite(M).all(axis=1))
    F[missing], M[missing] = np.nan, np.nan
    return F, M, unloaded


def plate_moment_about_origin(table: LabTable, prefix: str) -> tuple[np.ndarray, np.ndarray]:
    """(force (n, 3) N, moment about the lab's origin (n, 3) N m) of the plate ``prefix`` of an OpenSim-style
    ground-reaction table (:func:`plate_wrench`), every sample defined: a sample the table does not give (a
    force that is not a number, a force of ``MIN_PLATE_FORCE`` or more without a centre of pressure) is
    refused in one line naming its time. Where the force is zero, so is the moment."""
    F, M, _ = plate_wrench(table, prefix)
    missing = ~np.isfinite(F).all(axis=1)
    if missing.any():
        i, p = int(np.argmax(missing)), _plate_columns(table, prefix)
        forced = np.isfinite(np.column_stack([table.column(f"{p}force_v{a}") for a in "xyz"])[i]).all()
        what = "a force but no centre of pressure" if forced else "a force that is not a number"
        raise ValueError(f"{table.source}: plate {p!r} has {what} at t = {table.t[i]:g} s: its moment about the "
                         "origin is unknown")
    return F, M


def _axis(up: str) -> np.ndarray:
    m = re.fullmatch(r"([+-]?)([XYZ])", str(up).strip().upper())
    if not m:
        raise ValueError(f"up: expected a lab axis such as 'Y', '+Z' or '-Z', got {up!r}")
    u = np.zeros(3)
    u["XYZ".index(m[2])] = -1.0 if m[1] == "-" else 1.0
    return u


def centre_of_pressure(force: np.ndarray, moment: np.ndarray, plate_height: float = 0.0, *, up: str = "Y",
                       min_force: float = MIN_PLATE_FORCE) -> tuple[np.ndarray, np.ndarray]:
    """(centre of pressure p (n, 3) m, free moment T (n, 3) N m, along ``up``) of a plate's force (n, 3) N
    and moment about the lab's origin (n, 3) N m, with the plate's surface at the lab coordinate
    ``plate_height`` (m) along the axis ``up`` ("Y" in OpenSim's files, usually "Z" in C3D files:
    ``LabTable.header["up"]``): p = (u x M + h F) / (u . F) with h = u . p, T = M - p x F. NaN where the
    force along ``up`` is below ``min_force`` (N)."""
    F, M = np.asarray(force, dtype=float), np.asarray(moment, dtype=float)
    if F.shape != M.shape or F.ndim != 2 or F.shape[1] != 3:
        raise ValueError(f"force and moment: expected two (n, 3) arrays, got {F.shape} and {M.shape}")
    u = _axis(up)
    h = plate_height * u.sum()  # u . p for p on the surface
    Fu = F @ u
    on = Fu >= min_force
    P = np.full_like(F, np.nan)
    P[on] = (np.cross(u, M[on]) + h * F[on]) / Fu[on, None]
    return P, M - np.cross(P, F)
