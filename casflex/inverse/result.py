"""The result of an inverse dynamics run: loads over the trial, the motion they belong to, a report."""

from __future__ import annotations

import io
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from casflex.results import atomic_write_bytes, atomic_write_text

__all__ = ["InverseResult"]


@dataclass
class InverseResult:
    """Inverse dynamics over a trial.

    t (k,) s; ``coordinate_names`` (n_z,) with z, zd, zdd (k, n_z) the filtered coordinates (m, rad)
    and their rates; q, qd, qdd (k, n_dof) the scene's motion (``dof_names``); ``loads``: name -> (k,)
    (N, N m; :mod:`casflex.inverse.rigid` names them: ``<hinge>.moment``, ``<hinge>.fx`` ...,
    ``root.fx|fy|mz``, and every element output of simulate); ``marker_rms`` (n_frames,) m at the
    trial's frames ``frame_t``; ``report``: what was done to the data (fit, gaps, filters), one line
    each; ``settings``: the options; ``warnings``: the report's lines that say what changed the data
    (samples filled, taken as no load); ``marker_misfit`` (n_frames, m) m: each marker's (``marker_labels``,
    the trial's names) distance from the fitted pose, NaN where it is missing; ``plates``: the
    :class:`~casflex.inverse.plates.Plate` s applied, as filtered (``plate.at(t)``: force and moment).
    """

    t: np.ndarray
    coordinate_names: tuple[str, ...]
    z: np.ndarray
    zd: np.ndarray
    zdd: np.ndarray
    dof_names: tuple[str, ...]
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    loads: dict[str, np.ndarray]
    frame_t: np.ndarray
    marker_rms: np.ndarray
    report: list[str] = field(default_factory=list)
    settings: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    marker_labels: tuple[str, ...] = ()
    marker_misfit: np.ndarray | None = None
    plates: tuple = ()

    def load(self, name: str) -> np.ndarray:
        """(k,) the load called ``name``; KeyError naming the known ones."""
        if name not in self.loads:
            raise KeyError(f"unknown load {name!r}; loads are {sorted(self.loads)}")
        return self.loads[name]

    def summary(self) -> str:
        lines = [*self.report, f"{self.t.size} instants, t = {self.t[0]:g}..{self.t[-1]:g} s"]
        for name in (*self.settings.get("moments", ()), "root.fx", "root.fy", "root.mz"):
            v = self.loads[name]
            unit = "N" if name.endswith(("fx", "fy")) else "N m"
            lines.append(f"  {name:24s} {v.min():10.2f} .. {v.max():10.2f} {unit}  (RMS {np.sqrt(np.mean(v**2)):.2f})")
        return "\n".join(lines)

    def save(self, path: str | os.PathLike[str], fmt: str | None = None) -> Path:
        """Write ``npz`` (every array, names and the report), ``csv`` (t, the coordinates and the
        loads, one column each, a header line of names with units in brackets) or ``sto`` (OpenSim's
        table: time and the loads, in the lab's names where the scene has ``[[coordinates]]``, every
        column's unit listed once in the header), atomically; ``fmt`` defaults to the path's suffix."""
        path = Path(path)
        names = sorted(self.loads)
        if (fmt or path.suffix.lstrip(".").lower()) == "sto":
            trial = self.settings.get("source") or "a trial"
            return atomic_write_text(path, self._sto(f"casflex inverse dynamics of {trial}"))
        if (fmt or path.suffix.lstrip(".").lower()) == "csv":
            cols = ["t [s]"] + [f"{c} [{'rad' if c.endswith(('.theta', '.angle')) else 'm'}]"
                                for c in self.coordinate_names] + names
            data = np.column_stack([self.t, self.z, *(self.loads[n] for n in names)])
            buf = io.StringIO()
            np.savetxt(buf, data, delimiter=",", header=",".join(cols), comments="", fmt="%.10g")
            return atomic_write_text(path, buf.getvalue())
        arrays = {"t": self.t, "z": self.z, "zd": self.zd, "zdd": self.zdd, "q": self.q, "qd": self.qd,
                  "qdd": self.qdd, "coordinate_names": np.array(self.coordinate_names),
                  "dof_names": np.array(self.dof_names), "load_names": np.array(names),
                  "loads": np.column_stack([self.loads[n] for n in names]), "frame_t": self.frame_t,
                  "marker_rms": self.marker_rms,
                  "meta": np.array(json.dumps({"report": self.report, "settings": self.settings}))}
        buf = io.BytesIO()
        np.savez_compressed(buf, **arrays)
        return atomic_write_bytes(path, buf.getvalue())

    def _sto(self, title: str) -> str:
        """The loads as an OpenSim .sto table (:meth:`save`)."""
        lab = [n for n in self.loads if n.endswith(("_moment", "_force"))]
        names = lab or sorted(self.loads)
        unit = {n: _unit(n) for n in names}
        header = [title, "version=1", f"nRows={self.t.size}", f"nColumns={len(names) + 1}", "inDegrees=no",
                  "Units are S.I. units (second, meters, Newtons, ...)",
                  "units: time s; " + "; ".join(f"{n} {unit[n]}" for n in names),
                  "endheader", "\t".join(["time", *names])]
        buf = io.StringIO()
        np.savetxt(buf, np.column_stack([self.t, *(self.loads[n] for n in names)]), delimiter="\t", fmt="%.10g")
        return "\n".join(header) + "\n" + buf.getvalue()


def _unit(name: str) -> str:
    """The unit of a load called ``name`` (N or N m)."""
    if name.endswith("_force") or name.endswith((".fx", ".fy", ".f_along", ".f_across", ".force")):
        return "N"
    return "N m"
