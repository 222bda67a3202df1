"""C3D files: markers and force plates, through ezc3d (an optional dependency: ``pip install 'casflex[lab]'``).

:func:`read_c3d` gives the markers as :func:`casflex.lab.read_trc` does (a :class:`~casflex.lab.LabMarkers`,
metres from ``POINT:UNITS``, NaN where a marker is missing: a negative residual, or the exact (0, 0, 0)
that some exports write) and, when the file has force plates, a :class:`~casflex.lab.LabTable` with the
columns of OpenSim's ground-reaction .mot files at the analog rate, in the file's lab axes (its vertical is
usually Z; OpenSim's .mot files have Y up). Per plate, with the prefix ``ground_`` for the first,
``1_ground_`` for the second, ``2_ground_`` ...:

- ``<prefix>force_v{x,y,z}`` (N): the reaction on the subject (upward during stance);
- ``<prefix>force_p{x,y,z}`` (m): the centre of pressure on the plate's surface, NaN where the force
  along the plate's upward normal is below ``min_force`` (default :data:`MIN_PLATE_FORCE`, 20 N);
- ``<prefix>torque_{x,y,z}`` (N m): the free moment about the centre of pressure (along the normal),
  NaN where the centre of pressure is;
- ``<prefix>moment_{x,y,z}`` (N m): the moment of the plate's reaction about the lab's origin, p x F + T,
  defined at every sample (not in OpenSim's files; what :func:`casflex.lab.filtering.filtered` should filter,
  see :func:`casflex.lab.filtering.plate_moment_about_origin`).

Why 20 N: the centre of pressure is a moment divided by the vertical force, so a moment error dM moves
it by dM / F. On the two plates of OpenSim's walking2.c3d (tests/data/lab) the unloaded plates read
0.5 to 1.5 N m of moment (offsets the file does not zero; 0.1 to 0.25 N m of noise) and -14 and -20 N
of force: at 20 N the centre of pressure is good to about 5 cm, at 150 N to 1 cm, and an unloaded plate
(negative here) gives none. Raise ``min_force`` for noisier plates. The force itself is kept as read
(no offset removed, no threshold).

Points that are not markers (model outputs the file lists in ``POINT:ANGLES``, ``FORCES``, ``MOMENTS``,
``POWERS``, ``SCALARS``, ``REACTIONS``) are left out. Times keep the trial's clock: the first frame's
number (1-based in C3D) gives t[0] = (first - 1) / rate, so an excerpt keeps its trial's times.

A file ezc3d cannot read, or that is not whole, gives one ValueError line naming the file and the
problem. The header and the parameter section are walked first, bounds checked, before ezc3d reads the
file: ezc3d 1.7 can crash or hang on a corrupted parameter section, and silently reads fewer frames from
a truncated data section (checked after). Plates of the types ezc3d does not handle (5, 6, 7, 11, 12, 21)
are refused in one line; ``plates=False`` then reads the markers alone.
"""

from __future__ import annotations

import math
import mmap
import os
import pickle
import select
import signal
import struct
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from casflex.lab.tables import FileSpan, LabMarkers, LabTable

__all__ = ["read_c3d", "read_c3d_analogs", "c3d_span", "c3d_body_mass", "MIN_PLATE_FORCE", "NOT_MARKERS", "BODY_MASS"]

#: N: below this force along a plate's upward normal its centre of pressure is NaN (module docstring).
MIN_PLATE_FORCE = 20.0
#: POINT parameters that list model outputs, not markers.
NOT_MARKERS = ("ANGLES", "FORCES", "MOMENTS", "POWERS", "SCALARS", "REACTIONS")
_INSTALL = "read_c3d needs the ezc3d package: pip install 'casflex[lab]'"


def _ezc3d():
    try:
        import ezc3d
    except ImportError:
        raise ModuleNotFoundError(_INSTALL) from None
    return ezc3d


def _int8(b: int) -> int:
    return b - 256 if b > 127 else b


def _check_structure(where: str, raw: bytes | mmap.mmap) -> int:
    """The number of frames the header announces, after its key and its pointer to the parameter section
    are checked and that section's chain of records is walked as ezc3d walks it (each record ending where
    the previous one points), every length inside the file: ezc3d itself may crash or hang on a corrupted
    one."""
    if len(raw) < 512:
        raise ValueError(f"{where}: not a C3D file: {len(raw)} bytes, shorter than a C3D header (512)")
    if raw[1] != 0x50:
        raise ValueError(f"{where}: not a C3D file (its second byte is not the C3D key 0x50)")
    start = 512 * (raw[0] - 1)
    if raw[0] < 2 or start + 4 > len(raw):
        raise ValueError(f"{where}: truncated or corrupted: its header puts the parameters at block {raw[0]}, "
                         f"beyond the file's {len(raw)} bytes")
    proc = raw[start + 3]
    if proc not in (84, 85):  # Intel, DEC
        what = "MIPS (big-endian), which ezc3d does not read" if proc == 86 else f"unknown ({proc})"
        raise ValueError(f"{where}: the parameter section's processor type is {what}")
    _walk_parameters(where, raw, start + 4)
    first, last = (int.from_bytes(raw[i:i + 2], "little") for i in (6, 8))  # Intel and DEC integers
    if last < first:  # ezc3d would read the frames on times from the first one: shifted, not refused
        raise ValueError(f"{where}: corrupted header: its first frame (word 4) is {first} and its last (word 5) "
                         f"{last}: the last cannot precede the first")
    return last - first + 1


def c3d_span(path: str | os.PathLike[str]) -> tuple[FileSpan, float]:
    """(the markers' :class:`~casflex.lab.tables.FileSpan`, the analog rate Hz: the plates', NaN without analog
    channels) from the C3D header and parameter section alone, without ezc3d: t0 = (first - 1) / rate, t1 =
    (last - 1) / rate (:func:`read_c3d`'s times); ``names`` the plates' columns as :func:`read_c3d` names them
    (``FORCE_PLATFORM:USED`` plates; empty where the section cannot tell).
    ValueError in one line where the header is not a C3D's (:func:`read_c3d` says more)."""
    from casflex.lab.tables import FileSpan

    where = str(path)
    head, section = _head_and_parameters(path)
    proc = section[3:4]
    try:  # the plates' count; a section its own header sizes wrongly is read_c3d's to judge (None: not known)
        used = max(_walk_parameters(where, section, 4).get("FORCE_PLATFORM:USED", 0), 0)
    except ValueError:
        used = None
    first, last, per_frame = (int.from_bytes(head[i:i + 2], "little") for i in (6, 8, 18))
    raw = head[20:24] if proc[0] == 84 else head[22:24] + head[20:22]  # DEC: the words swapped, the exponent +2
    rate = struct.unpack("<f", raw)[0] / (1.0 if proc[0] == 84 else 4.0)
    if not (math.isfinite(rate) and rate > 0):
        raise ValueError(f"{where}: its header's frame rate {rate!r} is not a rate > 0")
    analog = rate * per_frame if per_frame else math.nan
    names = () if used is None else plate_names(used)
    return FileSpan((first - 1) / rate, (max(last, first) - 1) / rate, rate, names), analog


def _head_and_parameters(path: str | os.PathLike[str]) -> tuple[bytes, bytes]:
    """(the header's 512 bytes, the parameter section) of a C3D file, read without ezc3d; ValueError in one line
    where the header is not a C3D's."""
    where = str(path)
    try:
        with open(path, "rb") as f:
            head = f.read(512)
            f.seek(max(0, 512 * (head[0] - 1)) if head else 0)
            section = f.read(4)
            section += f.read(max(512 * section[2] - 4, 0)) if len(section) == 4 else b""
    except OSError as exc:
        raise ValueError(f"{where}: cannot read ({exc.strerror})") from None
    proc = section[3:4]
    if len(head) < 512 or head[1] != 0x50 or len(proc) != 1 or proc[0] not in (84, 85):
        raise ValueError(f"{where}: not a C3D file ezc3d reads (its header's key, or its processor type)")
    return head, section


#: the parameters a subject's mass (kg) is read from, in this order: Vicon's (Nexus writes the subject's
#: ``Bodymass`` under PROCESSING, some exports under SUBJECTS), and the names other systems use
BODY_MASS = ("PROCESSING:BODYMASS", "SUBJECTS:BODYMASS", "SUBJECTS:MASS", "SUBJECTS:WEIGHT", "SUBJECT:MASS",
             "SUBJECT:WEIGHT")


def c3d_body_mass(path: str | os.PathLike[str]) -> tuple[float, str] | None:
    """(the subject's mass in kg, the parameter it was read from as ``GROUP:NAME``) from a C3D file's parameter
    section (:data:`BODY_MASS`, the first that holds a number > 0: Vicon writes 0 where none was entered), without
    ezc3d; None where none does. ValueError in one line where the header is not a C3D's."""
    head, section = _head_and_parameters(path)
    try:
        found = _walk_parameters(str(path), section, 4, floats=section[3] == 84)
    except ValueError:  # a section read_c3d refuses: no mass from it
        return None
    for key in BODY_MASS:
        value = found.get(key)
        if value is not None and math.isfinite(value) and value > 0:
            return float(value), key
    return None


def plate_names(count: int) -> tuple[str, ...]:
    """The columns :func:`read_c3d` names for ``count`` plates (the first's prefix ``ground_``, then ``1_ground_``,
    ...)."""
    return tuple(f"{'ground_' if i == 0 else f'{i}_ground_'}{kind}{a}" for i in range(count)
                 for kind in ("force_v", "force_p", "torque_", "moment_") for a in "xyz")


def _walk_parameters(where: str, raw: bytes | mmap.mmap, pos: int, floats: bool = False) -> dict[str, float]:
    """Walk the parameter section from byte ``pos`` as ezc3d does, each record ending where the previous one
    points (ValueError in one line where it does not); returns its integer parameters' first values by
    ``GROUP:NAME`` (``FORCE_PLATFORM:USED``: the plates), and where ``floats`` (an Intel file's: IEEE floats) its
    float parameters' too (``PROCESSING:BODYMASS``)."""
    n = len(raw)
    groups: dict[int, str] = {}
    found: list[tuple[int, str, int]] = []
    while True:
        if pos + 2 > n:
            raise ValueError(f"{where}: truncated in its parameter section (byte {pos} of {n})")
        nchar, gid = _int8(raw[pos]), _int8(raw[pos + 1])
        if nchar == 0:
            break
        name_end = pos + 2 + abs(nchar)
        name = raw[pos + 2:name_end].decode("ascii", errors="replace")
        end = name_end + 2
        if gid < 0:
            groups[-gid] = name.upper()
        if gid > 0:  # a parameter: type (-1 char, 1 byte, 2 int16, 4 float), dimensions, values
            if end + 2 > n:
                raise ValueError(f"{where}: truncated in its parameter section ({name!r} at byte {pos})")
            kind, ndims = _int8(raw[end]), raw[end + 1]
            if kind not in (-1, 1, 2, 4):
                raise ValueError(f"{where}: corrupted parameter section: parameter {name!r} at byte {pos} "
                                 f"has the unknown type {kind}")
            values = end + 2 + ndims
            if kind in (1, 2) and values + kind <= n:
                found.append((gid, name.upper(), int.from_bytes(raw[values:values + kind], "little", signed=True)))
            elif kind == 4 and floats and values + 4 <= n:
                found.append((gid, name.upper(), struct.unpack("<f", raw[values:values + 4])[0]))
            end = values + abs(kind) * math.prod(raw[end + 2:end + 2 + ndims])
        end += 1 + (raw[end] if end < n else 0)  # the description
        if end > n:
            raise ValueError(f"{where}: truncated in its parameter section ({name!r} at byte {pos})")
        offset = int.from_bytes(raw[name_end:name_end + 2], "little")
        if offset == 0:
            break
        if name_end + offset != end:
            raise ValueError(f"{where}: corrupted parameter section: {name!r} at byte {pos} ends at byte "
                             f"{end} but points to byte {name_end + offset}")
        pos = end
    return {f"{groups.get(g, g)}:{name}": v for g, name, v in found}


#: s: the longest a C3D file's read may take before it is taken for a hang (the excerpt reads in 0.05 s).
READ_TIMEOUT = 60.0
_PLATFORM_KEYS = ("force", "moment", "center_of_pressure", "Tz", "corners", "unit_force", "unit_position")


def _plain(c, plates: bool, analogs: bool = False) -> dict:
    """What casflex reads of an ezc3d object, as plain dicts and arrays (picklable); ``analogs``: the analog
    channels and their ANALOG parameters too."""
    data = c["data"]
    return {
        "header": {"points": dict(c["header"]["points"]), "analogs": dict(c["header"]["analogs"])},
        "parameters": {g: {k: {"value": v["value"]} for k, v in c["parameters"][g].items() if k != "__METADATA__"}
                       for g in ("POINT", "EVENT", *(("ANALOG",) if analogs else ())) if g in c["parameters"]},
        "data": {"points": data["points"], "meta_points": {"residuals": data["meta_points"]["residuals"]},
                 "analogs": np.asarray(data["analogs"]) if analogs else
                 np.empty((0, data["analogs"].shape[1] if data["analogs"].ndim > 1 else 0)),
                 "platform": [{k: pf[k] for k in _PLATFORM_KEYS} for pf in data["platform"]]
                 if plates and "platform" in data.keys() else []},
    }


def _read(path: str, plates: bool, analogs: bool = False) -> dict:
    """:func:`_plain` of ezc3d's reading; ValueError naming the problem (ezc3d raises RuntimeError, OSError ...:
    all are the file's)."""
    ezc3d = _ezc3d()
    try:
        return _plain(ezc3d.c3d(path, extract_forceplat_data=plates), plates, analogs)
    except Exception as exc:
        msg = " ".join(str(exc).replace(": iostream error", "").split())
        if plates:
            try:
                ezc3d.c3d(path)
            except Exception:
                pass
            else:
                raise ValueError(f"ezc3d cannot read its force plates: {msg}; read_c3d(..., plates=False) reads the "
                                 "markers alone") from None
        raise ValueError(f"ezc3d cannot read it: {msg}") from None


def _read_apart(path: str, plates: bool, analogs: bool = False) -> dict:
    """:func:`_read` in a forked child process: ezc3d 1.7 crashes (a segmentation fault) or hangs on some
    corrupted files that pass :func:`_check_structure` (a parameter renamed by a flipped byte), and that must
    not take the caller with it. ValueError naming what happened; in the process itself where there is no
    fork (then a crash is ezc3d's to have)."""
    if not hasattr(os, "fork"):
        return _read(path, plates, analogs)
    _ezc3d()  # ModuleNotFoundError here, not in the child
    rd, wr = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: read, send, and leave without running the parent's exit handlers
        os.close(rd)
        try:
            signal.signal(signal.SIGINT, signal.SIG_DFL)
            try:
                out = ("ok", _read(path, plates, analogs))
            except ValueError as exc:
                out = ("error", str(exc))
            with os.fdopen(wr, "wb") as f:
                pickle.dump(out, f, protocol=pickle.HIGHEST_PROTOCOL)
        finally:
            os._exit(0)
    os.close(wr)
    try:
        kind, value = _receive(rd, pid)
    finally:
        os.close(rd)
        _reap(pid)
    if kind == "error":
        raise ValueError(value)
    return value


def _receive(rd: int, pid: int) -> tuple[str, object]:
    """The child's pickled answer from the pipe ``rd``; ValueError when it died or took too long."""
    chunks, deadline = [], time.monotonic() + READ_TIMEOUT
    while True:
        left = deadline - time.monotonic()
        if left <= 0 or not select.select([rd], [], [], left)[0]:
            os.kill(pid, signal.SIGKILL)
            raise ValueError(f"ezc3d did not finish reading it in {READ_TIMEOUT:g} s: the file is corrupted")
        chunk = os.read(rd, 1 << 20)
        if not chunk:
            break
        chunks.append(chunk)
    try:
        return pickle.loads(b"".join(chunks))
    except Exception:  # the child died before it sent its answer: ezc3d crashed
        status = _reap(pid)
        why = f"signal {-status}" if status is not None and status < 0 else f"status {status}"
        raise ValueError(f"ezc3d crashed reading it ({why}): the file is corrupted") from None


def _reap(pid: int) -> int | None:
    """The child's exit status (negative: the signal that ended it), once; None when already reaped."""
    try:
        _, status = os.waitpid(pid, 0)
    except ChildProcessError:
        return None
    return -os.WTERMSIG(status) if os.WIFSIGNALED(status) else os.WEXITSTATUS(status)


def _open(where: str, path: str | os.PathLike[str], plates: bool, analogs: bool = False) -> dict:
    """What casflex reads of the file (:func:`_plain`), checked whole; ValueError in one line otherwise."""
    if not Path(path).is_file():  # ezc3d hangs on a directory
        raise ValueError(f"{where}: " + ("not a file" if Path(path).exists() else "no such file"))
    try:
        with open(path, "rb") as f:
            if os.fstat(f.fileno()).st_size < 512:
                _check_structure(where, f.read())
            with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as raw:
                frames = _check_structure(where, raw)
    except OSError as exc:
        raise ValueError(f"{where}: cannot read ({exc.strerror})") from None
    try:
        c = _read_apart(str(path), plates, analogs)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None
    got = c["data"]["points"].shape[2]  # ezc3d reads what there is and sets its header to it
    if (c["data"]["points"].shape[1] or c["data"]["analogs"].shape[1]) and got < frames:
        raise ValueError(f"{where}: truncated: its header announces {frames} frames, the file holds {got}")
    return c


def _param(c, group: str, name: str, default=None):
    p = c["parameters"]
    if group in p and name in p[group]:
        return p[group][name]["value"]
    return default


def _labels(c, where: str, k: int) -> list[str]:
    labels: list[str] = []
    for key in ["LABELS"] + [f"LABELS{i}" for i in range(2, 100)]:
        more = _param(c, "POINT", key)
        if more is None:
            break
        labels += [str(s).strip() for s in more]
    if len(labels) < k:
        raise ValueError(f"{where}: POINT:LABELS names {len(labels)} of its {k} points")
    return labels[:k]


def _markers(c, where: str) -> LabMarkers:
    from casflex.lab.tables import UNITS, LabMarkers

    pts, res = c["data"]["points"], c["data"]["meta_points"]["residuals"][0]
    labels = _labels(c, where, pts.shape[1])
    units = [str(u).strip() for u in _param(c, "POINT", "UNITS", [])][:1]
    if pts.shape[1] and (not units or units[0] not in UNITS):
        raise ValueError(f"{where}: POINT:UNITS {units[0] if units else ''!r} is " + ("missing" if not units else
                         "not a length unit") + f"; expected one of {list(UNITS)}")
    skip = {str(s).strip() for g in NOT_MARKERS for s in _param(c, "POINT", g, [])}
    keep = [i for i, lb in enumerate(labels) if lb not in skip]
    names = [labels[i] for i in keep]
    dup = sorted({lb for lb in names if names.count(lb) > 1})
    if dup:
        raise ValueError(f"{where}: marker labels {dup} appear more than once")
    xyz = np.transpose(pts[:3, keep, :], (2, 1, 0)) * (UNITS[units[0]] if units else 1.0)
    xyz[(res[keep].T < 0) | np.all(xyz == 0.0, axis=2)] = np.nan
    rate = float(c["header"]["points"]["frame_rate"])
    if not (math.isfinite(rate) and rate > 0):
        raise ValueError(f"{where}: POINT:RATE is {rate:g}: the markers' frame rate must be > 0 Hz")
    t = _t0(c) + np.arange(xyz.shape[0]) / rate
    return LabMarkers(t, tuple(names), xyz, rate, units[0] if units else "", where, _events(c))


def _events(c) -> tuple[tuple[str, str, float], ...]:
    """The EVENT section's (context, label, time s), by time: the C3D standard's TIMES are (minutes, seconds) from
    the recording's start, the first frame's time being (first - 1) / rate, as :func:`_t0`'s (Vicon Nexus writes
    minutes 0; some files, BTKData's Plug-in Gait walks, hold them as one list of (minutes, seconds) pairs, which
    ezc3d reads flat). Empty where the file marks none or its section is inconsistent."""
    labels, contexts = _param(c, "EVENT", "LABELS", []), _param(c, "EVENT", "CONTEXTS", [])
    times = np.asarray(_param(c, "EVENT", "TIMES", np.zeros((2, 0))), dtype=float)
    if times.ndim == 1 and times.size == 2 * len(labels):  # (minutes, seconds) pairs, as some files store them
        times = times.reshape(-1, 2).T
    if times.ndim != 2 or times.shape[0] != 2 or not len(labels) == len(contexts) == times.shape[1]:
        return ()
    secs = 60.0 * times[0] + times[1]
    return tuple(sorted(((str(cx).strip(), str(lb).strip(), float(s)) for cx, lb, s in zip(contexts, labels, secs,
                                                                                             strict=True)),
                        key=lambda e: e[2]))


def _t0(c) -> float:
    """s: the time of the first frame, (first - 1) / rate with C3D's 1-based frame numbers."""
    h = c["header"]["points"]
    return h["first_frame"] / h["frame_rate"] if h["frame_rate"] > 0 else 0.0


def _up(corners: np.ndarray) -> np.ndarray:
    """The unit upward normal of a plate from its corners (3, 4), numbered as C3D numbers them."""
    n = np.cross(corners[:, 3] - corners[:, 0], corners[:, 1] - corners[:, 0])
    return n / np.linalg.norm(n)


def _plate_columns(pf, where: str, i: int, min_force: float) -> tuple[list[str], list[np.ndarray], str]:
    from casflex.lab.tables import UNITS

    if str(pf["unit_force"]).strip().upper() != "N" or pf["unit_position"] not in UNITS:
        raise ValueError(f"{where}: plate {i + 1} gives forces in {pf['unit_force']!r} and positions in "
                         f"{pf['unit_position']!r}; expected N and one of {list(UNITS)}")
    s = UNITS[pf["unit_position"]]
    F = pf["force"].T
    centre = pf["corners"].mean(axis=1) * s
    up = _up(pf["corners"])
    with np.errstate(invalid="ignore", over="ignore"):  # samples that are not numbers: the caller's to refuse
        M = np.cross(centre, F) + pf["moment"].T * s  # ezc3d's moment is about the plate's centre
        off = ~(F @ up >= min_force)
    P, T = pf["center_of_pressure"].T * s, pf["Tz"].T * s
    P[off], T[off] = np.nan, np.nan
    names = list(plate_names(i + 1)[12 * i:])
    axis = int(np.argmax(np.abs(up)))
    return names, [F, P, T, M], ("+" if up[axis] > 0 else "-") + "XYZ"[axis]


def _plates(c, where: str, min_force: float) -> LabTable | None:
    from casflex.lab.tables import LabTable

    platforms = c["data"]["platform"]
    if not platforms:
        return None
    names, blocks, ups = [], [], []
    for i, pf in enumerate(platforms):
        n, b, up = _plate_columns(pf, where, i, min_force)
        names += n
        blocks += b
        ups.append(up)
    values = np.hstack(blocks)
    rate = float(c["header"]["analogs"]["frame_rate"])
    if not (math.isfinite(rate) and rate > 0) or not values.shape[0]:
        raise ValueError(f"{where}: ANALOG:RATE is {rate:g} Hz and the plates have {values.shape[0]} samples: the "
                         "force plates cannot be read (read_c3d(..., plates=False) reads the markers alone)")
    t = _t0(c) + np.arange(values.shape[0]) / rate
    header = {"rate": rate, "plates": len(platforms), "up": ups[0] if len(set(ups)) == 1 else ",".join(ups),
              "min_force": min_force}
    return LabTable(t, tuple(names), values, None, header, where)


def read_c3d(path: str | os.PathLike[str], *, plates: bool = True,
             min_force: float = MIN_PLATE_FORCE) -> tuple[LabMarkers, LabTable | None]:
    """(markers, plates) of the C3D file ``path``: the markers (n frames, k markers, m, NaN where missing)
    and, if the file has force plates and ``plates``, their table at the analog rate (N, m, N m; columns
    in the module docstring; header: ``rate`` Hz, ``plates``, ``up`` (the lab axis of the plates' upward
    normal, e.g. "+Z"), ``min_force`` N), else None. ValueError in one line for a file that cannot be
    read; ModuleNotFoundError naming the install when ezc3d is missing."""
    where = str(path)
    c = _open(where, path, plates)
    markers = _markers(c, where)
    table = _plates(c, where, min_force) if plates else None
    return markers, table


def read_c3d_analogs(path: str | os.PathLike[str]) -> LabTable:
    """The analog channels of the C3D file ``path`` (EMG, plates' raw signals) as a table at the analog rate: the
    columns named by ANALOG:LABELS, the values as ezc3d scales them (ANALOG:SCALE, OFFSET, GEN_SCALE), the times
    from the first frame's. ValueError in one line for a file that cannot be read or has no analog channel."""
    from casflex.lab.tables import LabTable

    where = str(path)
    c = _open(where, path, False, analogs=True)
    values = np.asarray(c["data"]["analogs"], dtype=float)
    values = values.reshape(values.shape[-2], values.shape[-1]).T if values.size else np.zeros((0, 0))
    rate = float(c["header"]["analogs"]["frame_rate"])
    if not values.shape[1] or not (math.isfinite(rate) and rate > 0):
        raise ValueError(f"{where}: no analog channel (ANALOG:USED {values.shape[1]}, ANALOG:RATE {rate:g} Hz)")
    labels = [str(v).strip() for v in (_param(c, "ANALOG", "LABELS") or [])]
    labels += [f"analog{i + 1}" for i in range(len(labels), values.shape[1])]
    t = _t0(c) + np.arange(values.shape[0]) / rate
    return LabTable(t, tuple(labels[:values.shape[1]]), values, None, {"rate": rate}, where)
