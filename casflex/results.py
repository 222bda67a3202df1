"""Result records and atomic file output; the memory a result or an input may take.

Every file casflex writes goes through :func:`atomic_write_bytes`: the data is written to a
temporary file in the target directory, flushed, and renamed over the target, so a reader
never sees a half-written file, even if the writer is interrupted.
"""

from __future__ import annotations

import io
import json
import math
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["Trajectory", "atomic_write_bytes", "atomic_write_text", "atomic_write_json", "jsonable", "NPZ_KEYS",
           "memory_available", "format_bytes"]


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes, durable: bool = True) -> Path:
    """Write ``data`` to ``path`` atomically (temporary file + rename); returns the path. ``durable``: the data
    flushed to the disk (fsync) before the rename, so that a power cut leaves the old file or the new one; False
    for a file whose reader refuses a partial one (a sweep's record: run again), where the fsync is the write's
    largest cost (3 of 7 ms CPU for a study's trial record, and up to a second of wall under load)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600; give the file ordinary permissions
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            if durable:
                os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def atomic_write_text(path: str | os.PathLike[str], text: str, durable: bool = True) -> Path:
    return atomic_write_bytes(path, text.encode("utf-8"), durable)


def jsonable(x: Any) -> Any:
    """``x`` with numpy arrays and scalars as lists and numbers, and non-finite floats as the
    strings 'nan', 'inf', '-inf' (strict JSON has no NaN)."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(x) else str(float(x))
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def _native(x: Any) -> Any:
    raise TypeError(type(x).__name__)


def json_text(obj: Any, indent: int | None = 2) -> str:
    """``jsonable(obj)`` as JSON text (``indent`` None: on one line). ``obj`` is encoded as it is where JSON's
    encoder takes it without a change (no numpy value, no non-finite float: a sweep's record, 38 kB, 1.3 ms of CPU
    less than its walk by :func:`jsonable`), else walked first. The same text but for a dict key True, False or
    None (no casflex output has one), which JSON's encoder writes true, false, null and :func:`jsonable` "True"."""
    try:
        return json.dumps(obj, indent=indent, allow_nan=False, default=_native)
    except (TypeError, ValueError):
        return json.dumps(jsonable(obj), indent=indent)


def atomic_write_json(path: str | os.PathLike[str], obj: Any, durable: bool = True, indent: int | None = 2) -> Path:
    """Write ``jsonable(obj)`` as JSON (``indent`` None: on one line; :func:`json_text`), atomically (``durable``:
    :func:`atomic_write_bytes`)."""
    return atomic_write_text(path, json_text(obj, indent) + "\n", durable)


#: Keys of a trajectory .npz file and what they hold (n = number of time points).
NPZ_KEYS = {
    "t": "(n,) time, s, from 0 to t_end in steps of dt, both ends included",
    "q": "(n, n_dof) nodal dofs: x, y (m) and theta (rad) per node",
    "qd": "(n, n_dof) velocities",
    "qdd": "(n, n_dof) accelerations",
    "lam": "(n, n_con) Lagrange multipliers (Eq. 1 sign: the support exerts -lam)",
    "dof_names": "(n_dof,) 'x1', 'y1', 'theta1', ...",
    "constraint_names": "(n_con,) '<support>.<x|y|theta>'",
    "outputs": "(n, n_out) joint outputs: spring force/length/fx/fy, torsion moment, damper forces and "
    "moments, support reactions, beam end forces; the markers' positions (<marker>.x, .y, m)",
    "output_names": "(n_out,) names of the columns of outputs",
    "energy_kinetic": "(n,) J", "energy_elastic": "(n,) J", "energy_gravity": "(n,) J",
    "energy_total": "(n,) J, kinetic + elastic + gravity",
    "work_external": "(n,) J, work of the nodal loads since t = 0 (trapezoidal)",
    "work_dampers": "(n,) J, energy the dampers dissipated since t = 0 (trapezoidal, >= 0)",
    "energy_balance_error": "(n,) J, E(t) - E(0) - W_ext(t) + W_dampers(t): at alpha = 0 the integration error "
    "(either sign, O(dt^2)); at alpha < 0 mostly the energy HHT's numerical damping removed (negative)",
    "p": "(n_p,) parameter values used", "parameter_names": "(n_p,)",
    "newton_iterations": "(n-1,) Newton iterations per step (-1 where not recorded: compiled runs)",
    "meta": "JSON string: scene, alpha, dt, inertia, compiled, success, status, message, stats",
}


@dataclass(frozen=True, eq=False)
class Trajectory:
    """A simulated motion (see :data:`NPZ_KEYS` for shapes and units).

    ``success`` is False when the run stopped early; then the arrays hold the steps that
    converged and ``message`` says where and why it stopped.
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    lam: np.ndarray
    dof_names: tuple[str, ...]
    constraint_names: tuple[str, ...]
    outputs: np.ndarray
    output_names: tuple[str, ...]
    energies: dict[str, np.ndarray]
    p: np.ndarray
    parameter_names: tuple[str, ...]
    newton_iterations: np.ndarray
    success: bool = True
    status: str = "success"
    message: str = ""
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def stats(self) -> dict[str, Any]:
        return self.meta.get("stats", {})

    def dof(self, name: str) -> np.ndarray:
        """Time series (n,) of the dof called ``name`` (e.g. ``"y5"``)."""
        try:
            return self.q[:, self.dof_names.index(name)]
        except ValueError:
            raise KeyError(f"unknown dof {name!r}; dofs are {list(self.dof_names)}") from None

    def channel(self, name: str) -> np.ndarray:
        """Time series (n,) of a recording's channel: a dof (``"y5"``) or a marker's coordinate
        (``"xTOE"``, the output ``"TOE.x"``)."""
        if name in self.dof_names or not name.startswith(("x", "y")):
            return self.dof(name)
        return self.output(f"{name[1:]}.{name[0]}")

    def output(self, name: str) -> np.ndarray:
        """Time series (n,) of the joint output called ``name`` (e.g. ``"spring1.force"``)."""
        try:
            return self.outputs[:, self.output_names.index(name)]
        except ValueError:
            raise KeyError(f"unknown output {name!r}; outputs are {list(self.output_names)}") from None

    def at(self, t: float) -> int:
        """Index of the time point nearest to ``t`` (s)."""
        return int(np.argmin(np.abs(self.t - t)))

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write an .npz file atomically (keys: :data:`NPZ_KEYS`)."""
        arrays = {
            "t": self.t, "q": self.q, "qd": self.qd, "qdd": self.qdd, "lam": self.lam,
            "dof_names": np.array(self.dof_names), "constraint_names": np.array(self.constraint_names),
            "outputs": self.outputs, "output_names": np.array(self.output_names),
            "p": self.p, "parameter_names": np.array(self.parameter_names),
            "newton_iterations": self.newton_iterations,
            "meta": np.array(json.dumps({**self.meta, "success": self.success, "status": self.status,
                                         "message": self.message})),
        }
        for k, v in self.energies.items():
            arrays[k if k.startswith("work") else f"energy_{k}"] = v
        buf = io.BytesIO()
        np.savez_compressed(buf, **arrays)
        return atomic_write_bytes(path, buf.getvalue())

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Trajectory:
        """Read a trajectory written by :meth:`save`."""
        try:
            with np.load(path, allow_pickle=False) as z:
                data = {k: z[k] for k in z.files}
        except (OSError, ValueError) as exc:
            raise ValueError(f"{path}: not a casflex trajectory file ({exc})") from None
        meta = json.loads(str(data["meta"]))
        if "energy_balance_error" not in data and "energy_dissipated" in data:  # written before 0.2
            data["energy_balance_error"] = -data.pop("energy_dissipated")
        if "work_dampers" not in data and "t" in data:  # written before dampers: none
            data["work_dampers"] = np.zeros_like(data["t"])
        missing = [k for k in NPZ_KEYS if k not in data]
        if missing:
            raise ValueError(f"{path}: not a casflex trajectory file, missing keys {missing}")
        energies = {k[len("energy_"):] if k.startswith("energy_") else k: data[k]
                    for k in NPZ_KEYS if k.startswith(("energy_", "work_"))}
        return cls(
            t=data["t"], q=data["q"], qd=data["qd"], qdd=data["qdd"], lam=data["lam"],
            dof_names=tuple(str(s) for s in data["dof_names"]),
            constraint_names=tuple(str(s) for s in data["constraint_names"]),
            outputs=data["outputs"], output_names=tuple(str(s) for s in data["output_names"]),
            energies=energies, p=data["p"], parameter_names=tuple(str(s) for s in data["parameter_names"]),
            newton_iterations=data["newton_iterations"],
            success=bool(meta.pop("success")), status=str(meta.pop("status")), message=str(meta.pop("message")),
            meta=meta,
        )


def memory_available() -> int | None:
    """Bytes of memory available to a new allocation (MemAvailable of /proc/meminfo, else the
    free physical pages), or None where neither can be read."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (OSError, ValueError, AttributeError):
        return None


def format_bytes(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if n < 1024 or unit == "PiB":
            return f"{n:.3g} {unit}"
        n /= 1024
    raise AssertionError("unreachable")
