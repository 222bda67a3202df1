"""Scene inputs read from data files: a support's ``motion`` and a load's ``table`` given as
``{file = ..., <column>: <name>, ...}`` instead of inline rows (docs/scene-format.md, "Inputs from files").

Read when the scene is loaded, relative to the scene file's folder (to the working folder for a scene
given as text): OpenSim .mot/.sto files (:func:`casflex.lab.read_sto`) or CSV files with a header line
of column names. Each named column may be negated (``"-pelvis_tz"``); omitted columns are zero. Times
are the file's plus ``offset`` (s). ``cutoff`` (Hz) filters the columns by the lab's zero-lag
Butterworth first (:mod:`casflex.lab.lowpass`). A support's motion is the columns' change from the file's
first row (the node starts where the scene has it); a file flagged ``inDegrees=yes`` has its angle
column converted to radians. The scene keeps the rows (a saved scene holds them inline).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

import numpy as np

from casflex.scene.items import SceneError

__all__ = ["resolve_file_inputs"]

_MOTION = ("dx", "dy", "dtheta")
_LOAD = ("fx", "fy", "mz")
_OPTIONS = ("file", "offset", "cutoff")


def _read(path: Path, where: str):
    """(t (n,), names, values (n, k), in_degrees) of a .mot/.sto or .csv file."""
    from casflex.lab.tables import read_sto

    if not path.is_file():
        raise SceneError(f"{where}.file: no such file {str(path)!r}")
    if path.suffix.lower() in (".mot", ".sto"):
        try:
            tab = read_sto(path)
        except ValueError as exc:
            raise SceneError(f"{where}.file: {exc}") from None
        return tab.t, tab.names, tab.values, bool(tab.in_degrees)
    if path.suffix.lower() != ".csv":
        raise SceneError(f"{where}.file: {str(path)!r} must be a .mot, .sto or .csv file")
    return _read_csv(path, where)


def _read_csv(path: Path, where: str):
    """(t, names, values, False) of a CSV file: a header line of names, then rows of numbers (blank lines
    skipped), times increasing, every cell a finite number; SceneError naming the file and the row."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise SceneError(f"{where}.file: {str(path)!r} is not a UTF-8 text file (byte {exc.start})") from None
    except OSError as exc:
        raise SceneError(f"{where}.file: {str(path)!r} cannot be read ({exc.strerror})") from None
    rows = [(i, r) for i, r in enumerate(csv.reader(text.splitlines()), start=1) if any(c.strip() for c in r)]
    if len(rows) < 2:
        raise SceneError(f"{where}.file: {str(path)!r} has no data rows under its header")
    names = [c.strip() for c in rows[0][1]]
    data = np.empty((len(rows) - 1, len(names)))
    for k, (line, r) in enumerate(rows[1:]):
        if len(r) != len(names):
            raise SceneError(f"{where}.file: {str(path)!r}: line {line} has {len(r)} cells under {len(names)} names")
        try:
            data[k] = [float(c) for c in r]
        except ValueError:
            raise SceneError(f"{where}.file: {str(path)!r}: line {line}: a cell is not a number") from None
    from casflex.lab.tables import increasing_times

    try:
        increasing_times(data[:, 0], str(path))
    except ValueError as exc:
        raise SceneError(f"{where}.file: {exc}") from None
    return data[:, 0], tuple(names[1:]), data[:, 1:], False


def _columns(spec: dict, keys: tuple[str, ...], names: tuple[str, ...], values: np.ndarray,
             where: str) -> np.ndarray:
    out = np.zeros((values.shape[0], len(keys)))
    for k, key in enumerate(keys):
        name = spec.get(key)
        if name is None:
            continue
        if not isinstance(name, str):
            raise SceneError(f"{where}.{key}: expected a column name (a string), got {name!r}")
        sign, col = (-1.0, name[1:]) if name.startswith("-") else (1.0, name)
        if col not in names:
            raise SceneError(f"{where}.{key}: no column {col!r} in the file; its columns are {list(names)}")
        out[:, k] = sign * values[:, names.index(col)]
    return out


def _rows(spec: Any, keys: tuple[str, ...], base: Path, where: str, motion: bool) -> list[list[float]]:
    from casflex.lab.lowpass import even_times, lowpass

    unknown = [k for k in spec if k not in (*_OPTIONS, *keys)]
    if unknown or "file" not in spec:
        what = f"unknown field {unknown[0]!r}" if unknown else "missing field 'file'"
        raise SceneError(f"{where}: {what}; a table from a file takes {list(_OPTIONS + keys)}")
    t, names, values, degrees = _read(base / str(spec["file"]), where)
    cols = _columns(spec, keys, names, values, where)
    bad = ~np.isfinite(cols)
    if bad.any():
        i, k = (int(v) for v in np.argwhere(bad)[0])
        raise SceneError(f"{where}.{keys[k]}: column {spec[keys[k]]!r} is not a number at t = {t[i]:g} s (row {i + 1} "
                         "of the data): a support's motion and a load are needed at every time")
    offset, cutoff = spec.get("offset", 0.0), spec.get("cutoff")
    for key, v in (("offset", offset), ("cutoff", cutoff)):
        if v is not None and (not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v)):
            raise SceneError(f"{where}.{key}: expected a number, got {v!r}")
    if cutoff is not None:
        try:
            cols = lowpass(even_times(t), cols, float(cutoff), what=f"{where}.file")
        except ValueError as exc:
            raise SceneError(f"{where}.cutoff: {exc}") from None
    if motion:
        if degrees:
            cols[:, 2] = np.radians(cols[:, 2])
        cols = cols - cols[0]
    return [[float(ti + offset), *map(float, row)] for ti, row in zip(t, cols, strict=True)]


def resolve_file_inputs(data: dict, base: Path) -> dict:
    """``data`` (a parsed scene) with its supports' motions and loads' tables from files as rows."""
    if not isinstance(data, dict):
        return data
    for key, field, cols, motion in (("supports", "motion", _MOTION, True), ("loads", "table", _LOAD, False)):
        for i, item in enumerate(data.get(key) or []):
            if isinstance(item, dict) and isinstance(item.get(field), dict):
                item[field] = _rows(item[field], cols, base, f"{key}[{i}].{field}", motion)
    return data
