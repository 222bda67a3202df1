"""Lab tables: markers from TRC files (:class:`LabMarkers`) and named columns from OpenSim's .mot / .sto
(:class:`LabTable`).

- :func:`read_trc`: marker labels and positions, in metres from the header's ``Units`` (mm, cm, m).
  A marker missing at a frame (empty cells, or the exact (0, 0, 0) that several lab exports write
  for a dropped marker: a real marker at the lab's origin to 1e-6 mm is implausible) is NaN.
- :func:`read_sto`: a .mot / .sto table (header up to ``endheader``, then named columns), with
  the header's ``inDegrees`` kept as it says (nothing is converted: the caller knows which columns
  are angles); :func:`write_sto` writes one that :func:`read_sto` (and OpenSim) reads.

Every malformed file gives one ValueError line naming the file and what is wrong: missing or
unknown units, a DataRate that is no rate, duplicated labels, rows of the wrong length, times that do not
increase, infinite cells.
"""

from __future__ import annotations

import math
import os
import stat
from array import array
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from casflex.results import atomic_write_text

__all__ = ["LabMarkers", "LabTable", "UNITS", "read_trc", "write_trc", "read_sto", "write_sto", "increasing_times",
           "FileSpan", "trc_span", "sto_span"]

#: Length units of TRC headers, in metres.
UNITS = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}


@dataclass(frozen=True)
class LabMarkers:
    """Markers of a lab trial: t (n,) s; labels (k,); xyz (n, k, 3) m in the lab's axes, NaN where a
    marker is missing; ``rate`` (Hz) and ``units`` as the header gives them; ``events``: the gait events the
    lab marked in the file (a C3D's EVENT section), (context, label, time s) such as ("Right", "Foot Strike",
    3.02), on the times ``t`` are on."""

    t: np.ndarray
    labels: tuple[str, ...]
    xyz: np.ndarray
    rate: float
    units: str
    source: str = ""
    events: tuple[tuple[str, str, float], ...] = ()

    def marker(self, label: str) -> np.ndarray:
        """(n, 3) positions (m) of the marker ``label``; ValueError naming the known labels."""
        if label not in self.labels:
            raise ValueError(f"{self.source}: no marker labelled {label!r}; the trial has {list(self.labels)}")
        return self.xyz[:, self.labels.index(label)]


@dataclass(frozen=True)
class LabTable:
    """Named columns: t (n,) s, names (m,) of the other columns, values (n, m) as written (a .mot / .sto
    file), or in N, m, N m (a C3D file's force plates, :func:`read_c3d`)."""

    t: np.ndarray
    names: tuple[str, ...]
    values: np.ndarray
    in_degrees: bool | None = None
    header: dict = field(default_factory=dict)
    source: str = ""

    def column(self, name: str) -> np.ndarray:
        if name not in self.names:
            raise ValueError(f"{self.source}: no column {name!r}; the table has {list(self.names)}")
        return self.values[:, self.names.index(name)]


def increasing_times(t: np.ndarray, where: str) -> np.ndarray:
    """t (n,) s, checked: every time a number, each after the one before; ValueError naming ``where`` and the row."""
    if t.size and not np.isfinite(t).all():
        raise ValueError(f"{where}: a time is not a number (row {int(np.argmax(~np.isfinite(t))) + 1})")
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        kind = "repeats" if t[i] == t[i - 1] else "goes back to"
        raise ValueError(f"{where}: times must increase: row {i + 1} {kind} t = {t[i]:g} s after {t[i - 1]:g} s")
    return t


def _numbers(cells: list[str], where: str, row: int) -> list[float]:
    out = []
    for c in cells:
        c = c.strip()
        try:
            out.append(float(c) if c else math.nan)
        except ValueError:
            raise ValueError(f"{where}: row {row}: {c!r} is not a number") from None
    return out


#: Characters: a line longer than this is no row of a lab table (a TRC row of 1000 markers is 36 kB): a binary
#: file, or one with no line ends (a sparse file of zeros), read no further.
MAX_LINE = 1 << 20
#: Bytes of memory a table's reading takes per byte of its file, at most (its lines, then its numbers: a 60 MB TRC
#: peaked at 2.6 x its size; 4 leaves room for the arrays the reader builds from them)
READ_FACTOR = 4


def _fits_in_memory(where: str, size: int) -> None:
    """ValueError naming the file when reading its ``size`` bytes would take more memory than is available
    (:data:`READ_FACTOR`): refused before it is read, not read until the memory runs out."""
    from casflex.results import format_bytes, memory_available

    avail = memory_available()
    if avail is not None and READ_FACTOR * size > avail:
        raise ValueError(f"{where}: {format_bytes(size)}: reading it needs about {format_bytes(READ_FACTOR * size)} "
                         f"of memory and {format_bytes(avail)} are available; cut the trial to the window you need")


def _lines(path: str | os.PathLike[str]) -> tuple[str, list[str]]:
    """(the path as text, the file's lines, a UTF-8 byte-order mark dropped); ValueError naming the file when it
    cannot be read, is no regular file (a directory, a device such as /dev/zero behind a link, a pipe: read until
    memory runs out), is too large for the memory available, or has a line of more than :data:`MAX_LINE`
    characters."""
    where = str(path)
    try:
        mode = os.stat(path).st_mode
        if not stat.S_ISREG(mode):
            kind = "a directory" if stat.S_ISDIR(mode) else "a device or a pipe"
            raise ValueError(f"{where}: not a regular file ({kind}); give the table's file")
        _fits_in_memory(where, os.stat(path).st_size)
        lines = []
        with open(path, encoding="utf-8-sig", errors="replace", newline=None) as f:
            while line := f.readline(MAX_LINE + 1):
                if len(line) > MAX_LINE:
                    raise ValueError(f"{where}: line {len(lines) + 1} is longer than {MAX_LINE:,} characters: not a "
                                     "text table (a binary file?)")
                lines.append(line.rstrip("\n"))
        return where, lines
    except OSError as exc:
        raise ValueError(f"{where}: cannot read ({exc.strerror})") from None


def read_trc(path: str | os.PathLike[str]) -> LabMarkers:
    """The markers of a TRC file, in metres (module docstring)."""
    where, lines = _lines(path)
    if len(lines) < 5 or not lines[0].startswith("PathFileType"):
        raise ValueError(f"{where}: not a TRC file (its first line should start with 'PathFileType')")
    keys = [k.strip() for k in lines[1].split("\t") if k.strip()]
    vals = [v.strip() for v in lines[2].split("\t")]
    if len(vals) != len(keys):  # values set apart by runs of tabs (some exporters): OpenSim skips the empty ones
        vals = [v for v in vals if v]
    header = dict(zip(keys, vals, strict=False))
    units = header.get("Units", "")
    if units not in UNITS:
        raise ValueError(f"{where}: header Units {units!r} is " + ("missing" if not units else "not a length unit")
                         + f"; expected one of {list(UNITS)}")
    names = lines[3].split("\t")
    if len(names) < 3 or names[0].strip() != "Frame#" or names[1].strip() != "Time":
        raise ValueError(f"{where}: line 4 should start with 'Frame#' and 'Time', then the marker labels")
    labels = [n.strip() for n in names[2:] if n.strip()]
    seen = {lb for lb in labels if labels.count(lb) > 1}
    if seen:
        raise ValueError(f"{where}: marker labels {sorted(seen)} appear more than once")
    rate = _header_rate(header.get("DataRate", ""), where)
    want = 1 + 3 * len(labels)
    flat = array("d")  # 8 bytes a value: a Python list of floats takes four times as much
    for i, line in enumerate(lines[5:], start=6):
        if not line.strip():
            continue
        cells = line.rstrip("\r").split("\t")
        values = _numbers(cells[1:], where, i)
        if len(values) > want and all(math.isnan(v) for v in values[want:]):  # trailing tabs
            values = values[:want]
        if len(values) != want:
            raise ValueError(f"{where}: row {i} has {len(values) - 1} coordinates for {len(labels)} markers "
                             f"({3 * len(labels)} expected)")
        flat.extend(values)
    if not flat:
        raise ValueError(f"{where}: no frames")
    data = np.frombuffer(flat, dtype=float).reshape(-1, want)
    t = increasing_times(data[:, 0].copy(), where)
    xyz = data[:, 1:].reshape(len(t), len(labels), 3) * UNITS[units]
    xyz[np.all(xyz == 0.0, axis=2)] = np.nan  # a dropped marker written as (0, 0, 0)
    return LabMarkers(t, tuple(labels), xyz, rate, units, where)


def _header_rate(text: str, where: str) -> float:
    """Hz: a TRC header's ``DataRate`` (NaN when it is empty: the times then decide)."""
    if not text:
        return math.nan
    try:
        rate = float(text)
    except ValueError:
        raise ValueError(f"{where}: header DataRate {text!r} is not a number (the frames per second)") from None
    if not (math.isfinite(rate) and rate > 0):
        raise ValueError(f"{where}: header DataRate {text!r} must be a rate > 0 (frames per second)")
    return rate


@dataclass(frozen=True)
class FileSpan:
    """What a trial file's header and its first and last rows say, read without its data (a study's checks before
    any work): the first and last times ``t0``, ``t1`` (s), the ``rate`` (Hz: the header's, else from the first two
    rows' times; NaN where neither says) and the columns' ``names`` (a TRC's markers, a .mot's columns)."""

    t0: float
    t1: float
    rate: float
    names: tuple[str, ...]


def _ends(path: str | os.PathLike[str], head: int) -> tuple[str, list[str], str]:
    """(the path as text, the file's first ``head`` lines, its last line that is not blank); ValueError naming the
    file when it cannot be read. Reads the beginning and the last 64 kB, not the whole file."""
    try:
        with open(path, "rb") as f:
            first = [f.readline().decode("utf-8", "replace").rstrip("\r\n") for _ in range(head)]
            f.seek(0, os.SEEK_END)
            f.seek(max(0, f.tell() - 65536))
            tail = f.read().decode("utf-8", "replace").splitlines()
    except OSError as exc:
        raise ValueError(f"{path}: cannot read ({exc.strerror})") from None
    return str(path), first, next((ln for ln in reversed(tail) if ln.strip()), "")


def _first_cell(line: str, where: str, what: str) -> float:
    cells = [c for c in line.replace("\t", " ").split(" ") if c.strip()]
    try:
        return float(cells[0])
    except (IndexError, ValueError):
        raise ValueError(f"{where}: its {what} row has no time: {line[:60]!r}") from None


def trc_span(path: str | os.PathLike[str]) -> FileSpan:
    """A TRC file's :class:`FileSpan` from its header and its first and last frames (ValueError in one line
    where they cannot be read: :func:`read_trc` says more)."""
    where, lines, last = _ends(path, 7)
    if len(lines) < 6 or not lines[0].startswith("PathFileType") or not lines[3].startswith("Frame#"):
        raise ValueError(f"{where}: not a TRC file (its first line should start with 'PathFileType', its fourth "
                         "with 'Frame#')")
    header = dict(zip([k.strip() for k in lines[1].split("\t") if k.strip()],
                      [v.strip() for v in lines[2].split("\t") if v.strip()], strict=False))
    rate = _header_rate(header.get("DataRate", ""), where)
    first = next((ln for ln in lines[5:] if ln.strip()), last)
    t0, t1 = (_first_cell(ln.split("\t", 1)[-1], where, w) for ln, w in ((first, "first"), (last, "last")))
    labels = tuple(n.strip() for n in lines[3].split("\t")[2:] if n.strip())
    return FileSpan(t0, t1, rate, labels)


def sto_span(path: str | os.PathLike[str]) -> FileSpan:
    """A .mot / .sto file's :class:`FileSpan`: its columns (after ``endheader``; time first, left out), its
    first and last times, its rate from the rows among its first 64 lines (ValueError in one line where they
    cannot be read)."""
    where, lines, last = _ends(path, 64)
    end = next((i for i, ln in enumerate(lines) if ln.strip().lower() == "endheader"), None)
    if end is None or end + 2 >= len(lines):
        raise ValueError(f"{where}: no 'endheader' line among its first {len(lines)}: not an OpenSim .mot / .sto file")
    names = [n.strip() for n in lines[end + 1].split("\t") if n.strip()]
    if not names or names[0].lower() != "time":
        raise ValueError(f"{where}: the line after 'endheader' should name the columns, 'time' first")
    rows = [ln for ln in lines[end + 2:] if ln.strip()]
    t = [_first_cell(ln, where, "first") for ln in rows] or [_first_cell(last, where, "first")]
    rate = (len(t) - 1) / (t[-1] - t[0]) if len(t) >= 2 and t[-1] > t[0] else math.nan
    return FileSpan(t[0], _first_cell(last, where, "last"), rate, tuple(names[1:]))


#: How .mot / .sto headers write ``inDegrees`` (OpenSim writes yes/no; other tools true/false).
_DEGREES = {"yes": True, "true": True, "no": False, "false": False}


def read_sto(path: str | os.PathLike[str]) -> LabTable:
    """A .mot / .sto table of named columns (module docstring)."""
    where, lines = _lines(path)
    end = next((i for i, ln in enumerate(lines) if ln.strip().lower() == "endheader"), None)
    if end is None:
        raise ValueError(f"{where}: no 'endheader' line: not an OpenSim .mot / .sto file")
    header = {}
    for ln in lines[:end]:
        key, _, value = ln.strip().partition("=") if "=" in ln else ln.strip().partition(" ")
        if key:
            header[key.strip()] = value.strip()
    names = [n.strip() for n in lines[end + 1].split("\t") if n.strip()] if end + 1 < len(lines) else []
    if not names or names[0].lower() != "time":
        raise ValueError(f"{where}: the line after 'endheader' should name the columns, 'time' first")
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ValueError(f"{where}: columns {dup} appear more than once")
    flat = array("d")
    for i, line in enumerate(lines[end + 2:], start=end + 3):
        if not line.strip():
            continue
        values = _numbers([c for c in line.split("\t") if c.strip() != ""] or line.split(), where, i)
        if len(values) != len(names):
            raise ValueError(f"{where}: row {i} has {len(values)} values for {len(names)} columns")
        flat.extend(values)
    if not flat:
        raise ValueError(f"{where}: no rows")
    data = np.frombuffer(flat, dtype=float).reshape(-1, len(names)).copy()
    deg = header.get("inDegrees")
    if deg is not None and deg.lower() not in _DEGREES:
        raise ValueError(f"{where}: header inDegrees={deg!r}; expected yes or no (true or false)")
    in_degrees = None if deg is None else _DEGREES[deg.lower()]
    return LabTable(increasing_times(data[:, 0], where), tuple(names[1:]), data[:, 1:], in_degrees, header, where)


def write_sto(path: str | os.PathLike[str], t: np.ndarray, columns: dict[str, np.ndarray], *, title: str,
              units: dict[str, str], in_degrees: bool = False) -> Path:
    """Write OpenSim's .sto (or .mot) table atomically: a header (``title``, the size, ``inDegrees=no``, or yes
    where ``in_degrees``: the angles given in degrees, as OpenSim's IK writes its .mot; each column's unit from
    ``units`` listed once), then time (s) and ``columns`` (name -> (k,) values, in SI but for those angles),
    tab-separated, in :func:`read_sto`'s form. Returns the path."""
    import io

    names = list(columns)
    header = [title, "version=1", f"nRows={np.size(t)}", f"nColumns={len(names) + 1}",
              f"inDegrees={'yes' if in_degrees else 'no'}",
              "Units are S.I. units (second, meters, Newtons, ...)",
              "units: time s; " + "; ".join(f"{n} {units[n]}" for n in names), "endheader", "\t".join(["time", *names])]
    buf = io.StringIO()
    np.savetxt(buf, np.column_stack([t, *columns.values()]), delimiter="\t", fmt="%.10g")
    return atomic_write_text(path, "\n".join(header) + "\n" + buf.getvalue())


def write_trc(path: str | os.PathLike[str], markers: LabMarkers, *, units: str | None = None) -> Path:
    """Write ``markers`` as a TRC file atomically, in OpenSim's form (what its IK and scale tools and
    :func:`read_trc` read): the header's DataRate, CameraRate, NumFrames, NumMarkers, Units, OrigDataRate,
    OrigDataStartFrame and OrigNumFrames, the labels each over its X, Y, Z columns, then one row a frame
    (Frame# from 1, Time s), a missing sample as NaN (OpenSim's reader drops a row's trailing empty cells, and
    then refuses the row). ``units`` (mm, cm or m; default the markers'
    own, mm where they say none) are the file's; positions are written to 10 significant digits, so
    ``read_trc(write_trc(p, m))`` gives m back to 1e-9 of its size. Returns the path. A rate the times do not
    give (NaN) is written as the times' mean step's."""
    import io

    units = units or (markers.units if markers.units in UNITS else "mm")
    if units not in UNITS:
        raise ValueError(f"units: {units!r} is not a length unit; expected one of {list(UNITS)}")
    t = np.asarray(markers.t, dtype=float)
    n, k = t.size, len(markers.labels)
    rate = markers.rate if math.isfinite(markers.rate) else (
        (n - 1) / (t[-1] - t[0]) if n > 1 else 1.0)
    name = Path(path).name
    head = [f"PathFileType\t4\t(X/Y/Z)\t{name}",
            "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
            f"{rate:g}\t{rate:g}\t{n}\t{k}\t{units}\t{rate:g}\t1\t{n}",
            "Frame#\tTime\t" + "\t".join(f"{lb}\t\t" for lb in markers.labels),
            "\t\t" + "\t".join(f"X{i + 1}\tY{i + 1}\tZ{i + 1}" for i in range(k)), ""]
    buf = io.StringIO()
    xyz = np.asarray(markers.xyz, dtype=float).reshape(n, 3 * k) / UNITS[units]
    for i in range(n):
        cells = ("NaN" if math.isnan(v) else f"{v:.10g}" for v in xyz[i])
        buf.write(f"{i + 1}\t{t[i]:.10g}\t" + "\t".join(cells) + "\n")
    return atomic_write_text(path, "\n".join(head) + "\n" + buf.getvalue())
