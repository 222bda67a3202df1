"""Measurement sets: channels sampled at their times, pure data (no model, no CasADi), with optional noise.

- simulated set: every nodal dof with velocities and accelerations, from an HHT simulation
  (:func:`casflex.simulate.simulated_set`, which builds a :class:`MeasurementSet` of a run);
- measured set: positions only (optionally with Gaussian noise, sigma in m for x, y and rad
  for theta); velocities and accelerations by central differences (2nd order), so the first
  and last samples are dropped;
- user files: :func:`load_measurements` and :func:`save_measurements` read and write ``.npz``
  and ``.csv`` files (format and error messages in ``docs/data-format.md``).
"""

from __future__ import annotations

import csv
import io
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["MeasurementSet", "measured_set", "load_measurements", "save_measurements",
           "add_position_noise", "FILE_FORMATS", "builtin_recordings"]

#: Example recordings shipped with casflex, beside the built-in scenes they belong to
_BUILTIN_DIR = Path(__file__).parent / "scene" / "builtin"


def builtin_recordings() -> list[str]:
    """Names of the example recordings shipped with casflex (``casflex/scene/builtin/*.csv``), which
    :func:`load_measurements` (and ``casflex identify --data NAME``) read by name."""
    return sorted(p.stem for p in _BUILTIN_DIR.glob("*.csv"))


@dataclass(frozen=True, eq=False)
class MeasurementSet:
    """Kinematic data: t (n,) s; q, qd, qdd (n, k) for the dofs named in ``channels``.

    ``qd`` and ``qdd`` may be None when only positions are known. NaN marks a missing sample
    (a marker hidden for a while); times must be finite and increasing, no value infinite.
    """

    t: np.ndarray
    channels: tuple[str, ...]
    q: np.ndarray
    qd: np.ndarray | None
    qdd: np.ndarray | None
    source: str = "user"
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        seen: set[str] = set()
        for c in self.channels:
            if c in seen:
                raise ValueError(f"data.channels: duplicate channel name {c!r}")
            seen.add(c)
        t = np.asarray(self.t, dtype=float)
        if t.ndim != 1 or t.size < 1 or not np.isfinite(t).all():
            raise ValueError("data.t: expected a 1-d array of finite times (s)")
        if t.size > 1 and np.any(np.diff(t) <= 0):
            i = int(np.argmax(np.diff(t) <= 0)) + 1
            raise ValueError(f"data.t: times must increase strictly; t[{i}] = {t[i]:g} follows {t[i - 1]:g}")
        for name in ("q", "qd", "qdd"):
            a = getattr(self, name)
            if a is None:
                continue
            a = np.asarray(a, dtype=float)
            if a.shape != (t.size, len(self.channels)):
                raise ValueError(f"data.{name}: expected shape ({t.size}, {len(self.channels)}), got {a.shape}")
            if np.isinf(a).any():  # NaN marks a missing sample; an infinity is an error
                r, c = np.argwhere(np.isinf(a))[0]
                raise ValueError(f"data.{name}: infinite value for channel {self.channels[c]} at t = {t[r]:g} s")
        if self.q is None:
            raise ValueError("data.q: positions are required")

    def index(self, t: float) -> int:
        """Index of the sample at time ``t`` (s); error if none lies within half a sample."""
        i = int(np.argmin(np.abs(self.t - t)))
        tol = 0.5 * (np.min(np.diff(self.t)) if self.t.size > 1 else 1e-9)
        if abs(self.t[i] - t) > tol:
            raise ValueError(f"instant t = {t:g} s: no sample there (data cover {self.t[0]:g} .. {self.t[-1]:g} s)")
        return i

    def window(self, t_from: float, t_to: float) -> MeasurementSet:
        """The samples with t_from <= t <= t_to (s)."""
        keep = (self.t >= t_from - 1e-12) & (self.t <= t_to + 1e-12)
        if not keep.any():
            raise ValueError(f"data: no sample between {t_from:g} and {t_to:g} s (data cover {self.t[0]:g} .. "
                             f"{self.t[-1]:g} s)")
        cut = [None if a is None else np.asarray(a)[keep] for a in (self.q, self.qd, self.qdd)]
        return MeasurementSet(self.t[keep], self.channels, *cut, source=self.source, meta=self.meta)

    def select(self, model) -> np.ndarray:
        """Column of each dof of ``model`` (a :class:`casflex.model.Model`) in the data (-1 where the dof is not
        measured); ValueError for a channel that is neither a dof's nor a marker's
        (:meth:`casflex.model.Model.data_columns`, where the rule lives: the data know no model)."""
        return model.data_columns(self.channels)


def measured_set(data: MeasurementSet, *, noise: float = 0.0, seed: int | None = None) -> MeasurementSet:
    """Positions of ``data`` (plus Gaussian noise of std ``noise``), derivatives by central
    differences: qd_i = (q_{i+1} - q_{i-1}) / 2h, qdd_i = (q_{i+1} - 2 q_i + q_{i-1}) / h^2."""
    if noise < 0 or not np.isfinite(noise):
        raise ValueError(f"noise: expected a standard deviation >= 0 (m, rad), got {noise!r}")
    h = np.diff(data.t)
    if data.t.size < 3 or np.ptp(h) > 1e-9 * h.mean():
        raise ValueError("measured set: central differences need at least 3 equally spaced samples")
    h = float(h.mean())
    q = data.q + (np.random.default_rng(seed).normal(0.0, noise, data.q.shape) if noise > 0 else 0.0)
    qd = (q[2:] - q[:-2]) / (2 * h)
    qdd = (q[2:] - 2 * q[1:-1] + q[:-2]) / h**2
    return MeasurementSet(data.t[1:-1], data.channels, q[1:-1], qd, qdd, source="measured",
                          meta={"noise": noise, "seed": seed, "from": data.source})


# --------------------------------------------------------------------------------------------
# user measurement files (docs/data-format.md)

#: File extensions :func:`load_measurements` and :func:`save_measurements` understand.
FILE_FORMATS = (".npz", ".csv")

#: CSV column prefixes of velocities and accelerations: ``d:x5`` is dx5/dt (m/s), ``dd:x5`` d2x5/dt2 (m/s^2).
CSV_PREFIXES = {1: "d:", 2: "dd:"}

_NPZ_ARRAYS = ("t", "q", "qd", "qdd")

# q, qd, qdd of a file: (t (n,) s, channels, q (n, k), qd (n, k) or None, qdd (n, k) or None)
_Arrays = tuple[np.ndarray, tuple[str, ...], np.ndarray, np.ndarray | None, np.ndarray | None]


def _format_of(path: Path) -> str:
    """The file format (``.npz`` or ``.csv``) from the extension; ValueError otherwise."""
    ext = path.suffix.lower()
    if ext not in FILE_FORMATS:
        raise ValueError(f"{path}: unknown extension {path.suffix or '(none)'!r}; measurement files are "
                         f"{' or '.join(FILE_FORMATS)} (docs/data-format.md)")
    return ext


def load_measurements(path: str | os.PathLike[str]) -> MeasurementSet:
    """Read a measurement file (``.npz`` or ``.csv``, see ``docs/data-format.md``), or an example recording
    shipped with casflex by its name (:func:`builtin_recordings`, e.g. ``"knee_pendulum_trial"``).

    Returns a :class:`MeasurementSet` with t in s, positions q (m, rad) and, when the file has
    them, velocities qd (m/s, rad/s) and accelerations qdd (m/s^2, rad/s^2). Every problem
    raises a one-line ValueError that names the file and the offending key, line or column.
    Channel names are not checked against a model here: :meth:`MeasurementSet.select` does.
    """
    path = Path(path)
    if not path.exists() and not path.suffix and str(path) in builtin_recordings():  # an example shipped with casflex
        path = _BUILTIN_DIR / f"{path}.csv"
    fmt = _format_of(path)
    if not path.exists():
        raise ValueError(f"{path}: no such file")
    if not path.is_file():
        raise ValueError(f"{path}: not a regular file")
    t, channels, q, qd, qdd = _read_npz(path) if fmt == ".npz" else _read_csv(path)
    if t.size == 0:
        raise ValueError(f"{path}: no samples (t is empty)")
    if not channels:
        raise ValueError(f"{path}: no channels (expected at least one dof such as x5)")
    bad_t = np.flatnonzero(~np.isfinite(t))
    if bad_t.size:
        raise ValueError(f"{path}: t: non-finite time {t[bad_t[0]]} at sample {bad_t[0]}")
    try:
        return MeasurementSet(t, channels, q, qd, qdd, source="file", meta={"path": str(path)})
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None


def _npz_array(path: Path, z, key: str) -> np.ndarray:
    """Array ``key`` of an open .npz file, numeric (float) unless it is ``channels``."""
    try:
        a = z[key]
    except ValueError:  # object arrays need pickle, which is never enabled for data files
        raise ValueError(f"{path}: key {key!r}: holds Python objects; store plain numbers and strings") from None
    if key in ("channels", "dof_names"):
        if a.dtype.kind not in "US" or a.ndim != 1:
            raise ValueError(f"{path}: key {key!r}: expected a 1-d array of strings (dof names such as x5), "
                             f"got dtype {a.dtype} and shape {a.shape}")
        return a
    if a.dtype.kind not in "iuf":
        raise ValueError(f"{path}: key {key!r}: expected numbers, got dtype {a.dtype}")
    return a.astype(float)


def _read_npz(path: Path) -> _Arrays:
    """t, channels, q, qd, qdd of a .npz file (keys t, channels or dof_names, q, qd, qdd)."""
    import zipfile

    try:
        z = np.load(path, allow_pickle=False)
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise ValueError(f"{path}: not a readable .npz file ({str(exc).splitlines()[0] if str(exc) else exc!r})") \
            from None
    if not isinstance(z, np.lib.npyio.NpzFile):
        raise ValueError(f"{path}: not a .npz archive (a single .npy array?); expected keys t, channels, q")
    with z:
        ch_key = "channels" if "channels" in z.files else "dof_names" if "dof_names" in z.files else None
        for key in ("t", "q"):
            if key not in z.files:
                raise ValueError(f"{path}: missing key {key!r} (keys present: {sorted(z.files)})")
        if ch_key is None:
            raise ValueError(f"{path}: missing key 'channels' (keys present: {sorted(z.files)})")
        arrays = {key: _npz_array(path, z, key) for key in _NPZ_ARRAYS if key in z.files}
        names = tuple(str(c).strip() for c in _npz_array(path, z, ch_key))
    for i, c in enumerate(names):
        if not c:
            raise ValueError(f"{path}: key {ch_key!r}: channel {i} has an empty name")
    t = arrays["t"]
    if t.ndim != 1:
        raise ValueError(f"{path}: key 't': expected a 1-d array of times (s), got shape {t.shape}")
    for key in ("q", "qd", "qdd"):
        a = arrays.get(key)
        if a is not None and a.shape != (t.size, len(names)):
            raise ValueError(f"{path}: key {key!r}: expected shape (len(t), len({ch_key})) = ({t.size}, {len(names)}), "
                             f"got {a.shape}")
    return t, names, arrays["q"], arrays.get("qd"), arrays.get("qdd")


def _csv_rows(path: Path) -> list[tuple[int, list[str]]]:
    """(line number, stripped cells) of every line that is not blank or a '#' comment."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: not a UTF-8 text file (byte {exc.start})") from None
    rows = []
    for ln, line in enumerate(text.splitlines(), 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        rows.append((ln, [c.strip() for c in next(csv.reader([line]))]))
    return rows


def _csv_header(path: Path, ln: int, header: list[str]) -> tuple[list[str], dict[int, list[int]]]:
    """Position channel names and, per derivative order 0/1/2, the column of each channel."""
    if header[0] != "t":
        raise ValueError(f"{path}: line {ln}: the header's first column must be 't' (time, s), got {header[0]!r}")
    if len(header) < 2:
        raise ValueError(f"{path}: line {ln}: no channel columns after 't' (expected e.g. t,x5,y5)")
    seen: dict[str, int] = {"t": 0}
    kinds: dict[int, dict[str, int]] = {0: {}, 1: {}, 2: {}}
    for j, name in enumerate(header[1:], 1):
        if not name:
            raise ValueError(f"{path}: line {ln}: header column {j + 1} has an empty name")
        if name in seen:
            raise ValueError(f"{path}: line {ln}: duplicate column {name!r} (columns {seen[name] + 1} and {j + 1})")
        seen[name] = j
        order = 2 if name.startswith(CSV_PREFIXES[2]) else 1 if name.startswith(CSV_PREFIXES[1]) else 0
        base = name[len(CSV_PREFIXES[order]):] if order else name
        if not base:
            raise ValueError(f"{path}: line {ln}: header column {j + 1} {name!r} names no channel")
        kinds[order][base] = j
    channels = list(kinds[0])
    for order, what in ((1, "velocity"), (2, "acceleration")):
        prefix = CSV_PREFIXES[order]
        for base in kinds[order]:
            if base not in kinds[0]:
                raise ValueError(f"{path}: line {ln}: {what} column {prefix + base!r} has no position column {base!r}")
        missing = [prefix + c for c in channels if c not in kinds[order]]
        if kinds[order] and missing:
            raise ValueError(f"{path}: line {ln}: {what} columns must cover every channel or none; missing {missing}")
    cols = {order: [kinds[order][c] for c in channels] for order in (0, 1, 2) if kinds[order] or order == 0}
    return channels, cols


def _csv_float(path: Path, ln: int, row: int, column: str, cell: str) -> float:
    """One cell as a float (an empty cell outside the time column: NaN, a missing sample);
    ValueError naming line, data row and column otherwise."""
    if not cell and column != "t":
        return math.nan
    try:
        return float(cell)
    except ValueError:
        what = "empty cell" if not cell else f"{cell!r} is not a number"
        raise ValueError(f"{path}: line {ln} (data row {row}), column {column!r}: {what}") from None


def _read_csv(path: Path) -> _Arrays:
    """t, channels, q, qd, qdd of a .csv file (header ``t,<ch>...,d:<ch>...,dd:<ch>...``)."""
    rows = _csv_rows(path)
    if not rows:
        raise ValueError(f"{path}: empty file (expected a header row 't,<channel>,...')")
    (ln0, header), body = rows[0], rows[1:]
    channels, cols = _csv_header(path, ln0, header)
    if not body:
        raise ValueError(f"{path}: no data rows after the header (line {ln0})")
    values = np.empty((len(body), len(header)))
    for r, (ln, cells) in enumerate(body, 1):
        if len(cells) != len(header):
            raise ValueError(f"{path}: line {ln} (data row {r}): expected {len(header)} cells as in the header, "
                             f"got {len(cells)}")
        values[r - 1] = [_csv_float(path, ln, r, name, cell) for name, cell in zip(header, cells, strict=True)]
    parts = [values[:, cols[o]] if o in cols else None for o in (0, 1, 2)]
    return values[:, 0], tuple(channels), parts[0], parts[1], parts[2]


def save_measurements(data: MeasurementSet, path: str | os.PathLike[str]) -> Path:
    """Write ``data`` to a ``.npz`` or ``.csv`` file atomically (see ``docs/data-format.md``).

    Values are written at full precision (CSV: shortest round-trip decimal), so
    ``load_measurements(save_measurements(d, p))`` reproduces t, q, qd, qdd exactly. Returns the path.
    """
    from casflex.results import atomic_write_bytes, atomic_write_text

    path = Path(path)
    if _format_of(path) == ".npz":
        buf = io.BytesIO()
        extra = {k: np.asarray(v, dtype=float) for k, v in (("qd", data.qd), ("qdd", data.qdd)) if v is not None}
        np.savez(buf, t=np.asarray(data.t, dtype=float), channels=np.array(data.channels, dtype=str),
                 q=np.asarray(data.q, dtype=float), **extra)
        return atomic_write_bytes(path, buf.getvalue())
    return atomic_write_text(path, _csv_text(data))


def _csv_text(data: MeasurementSet) -> str:
    """The CSV form of ``data``: comment lines, header, one row per sample."""
    blocks = [(np.asarray(data.q, dtype=float), "")]
    for order, arr in ((1, data.qd), (2, data.qdd)):
        if arr is not None:
            blocks.append((np.asarray(arr, dtype=float), CSV_PREFIXES[order]))
    buf = io.StringIO()
    buf.write(f"# casflex measurements ({data.source}): t in s; x, y in m; theta in rad; "
              "d:<channel> velocity, dd:<channel> acceleration (docs/data-format.md)\n")
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["t"] + [prefix + c for _, prefix in blocks for c in data.channels])
    table = np.column_stack([np.asarray(data.t, dtype=float)] + [a for a, _ in blocks])
    for row in table:
        w.writerow([repr(float(v)) for v in row])
    return buf.getvalue()


def add_position_noise(data: MeasurementSet, noise: float, seed: int | None = None) -> MeasurementSet:
    """``data`` with seeded Gaussian noise of std ``noise`` (m for x, y; rad for theta) added to q.

    Velocities and accelerations, if any, are left as they are."""
    if not (math.isfinite(noise) and noise >= 0):
        raise ValueError(f"noise: expected a standard deviation >= 0 (m, rad), got {noise!r}")
    q = np.asarray(data.q, dtype=float)
    q = q + np.random.default_rng(seed).normal(0.0, noise, q.shape) if noise > 0 else q
    return MeasurementSet(data.t, data.channels, q, data.qd, data.qdd, source=data.source,
                          meta={**data.meta, "noise": noise, "seed": seed})
