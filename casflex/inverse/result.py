"""The result of an inverse dynamics run: loads over the trial, the motion they belong to, a report."""

from __future__ import annotations

import io
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from casflex.inverse.lab_names import load_unit
from casflex.lab.tables import write_sto
from casflex.results import atomic_write_bytes, atomic_write_text

__all__ = ["InverseResult", "NPZ_KEYS"]

#: Every key of the .npz that :meth:`InverseResult.save` writes, and what it holds (docs/lab.md lists them).
NPZ_KEYS = {
    "t": "(k,) s: the instants",
    "coordinate_names": "(n_z,) the tree's coordinates (pelvis.x, pelvis.y, pelvis.theta, <hinge>.angle)",
    "z": "(k, n_z) the coordinates, filtered (m, rad)",
    "zd": "(k, n_z) their rates (m/s, rad/s)",
    "zdd": "(k, n_z) their accelerations (m/s^2, rad/s^2)",
    "dof_names": "(n_dof,) the scene's degrees of freedom",
    "q": "(k, n_dof) the scene's motion (m, rad)", "qd": "(k, n_dof) its rates", "qdd": "(k, n_dof) its accelerations",
    "load_names": "(n_l,) the loads' names, sorted",
    "loads": "(k, n_l) the loads (N, N m; a hinge's .angle column: rad)",
    "fitted_names": "(n_z,) the IK result's coordinates: the lab's names where the scene has them",
    "fitted_units": "(n_z,) their units (m, rad)",
    "fitted": "(k, n_z) the IK result: the marker fit's coordinates (or those given), unfiltered, in the lab's values",
    "frame_t": "(k,) s: the frames of the fit", "marker_rms": "(k,) m: the markers' RMS misfit per frame",
    "marker_labels": "(m,) the trial's markers", "marker_misfit": "(k, m) m: each marker's misfit (NaN: missing)",
    "meta": "JSON text: report, settings, warnings",
    "sd_total": "(k, n_l) with bands: each load's 1 SD", "sd_anthropometry": "(k, n_l) its part from the properties",
    "sd_markers": "(k, n_l) its part from the markers' noise",
    "band_targets": "(g,) with bands: the uncertain properties",
    "band_parts": "(g, k, n_l) with bands: each load's change when the property moves by its SD",
}


def _unit(name: str, coordinate: bool = False) -> str:
    """A column's unit: rad for an angle (a coordinate's, or a hinge's ``.angle`` among the loads), m for a
    coordinate's position, else the load's (N or N m)."""
    if name.endswith((".theta", ".angle")):
        return "rad"
    return "m" if coordinate else load_unit(name)


@dataclass(frozen=True, kw_only=True)
class InverseResult:
    """Inverse dynamics over a trial (a frozen value, made with named fields).

    t (k,) s; ``coordinate_names`` (n_z,) with z, zd, zdd (k, n_z) the filtered coordinates (m, rad)
    and their rates; q, qd, qdd (k, n_dof) the scene's motion (``dof_names``); ``loads``: name -> (k,)
    (N, N m; :mod:`casflex.inverse.rigid` names them: ``<hinge>.moment``, ``<hinge>.fx`` ...,
    ``root.fx|fy|mz``, and every element output of simulate); ``marker_rms`` (n_frames,) m at the
    trial's frames ``frame_t``; ``report``: what was done to the data (fit, gaps, filters), one line
    each; ``settings``: the options; ``warnings``: the report's lines that say what changed the data
    (samples filled, taken as no load); ``marker_misfit`` (n_frames, m) m: each marker's (``marker_labels``,
    the trial's names) distance from the fitted pose, NaN where it is missing; ``plates``: the
    :class:`~casflex.inverse.plates.Plate` s applied, as filtered (``plate.at(t)``: force and moment);
    ``bands`` (where asked: :mod:`casflex.inverse.bands`): load -> {"anthropometry", "markers", "total"} -> (k,),
    one standard deviation (N, N m) from the uncertain properties, from the markers' noise and both
    (root-sum-square); ``band_parts``: uncertain property (its target) -> load -> (k,), the load's change when
    the property moves by its standard deviation (signed); ``fitted``: the marker fit's coordinates (or those
    given), unfiltered, the IK result (k,) each, named and valued as the lab's coordinates where the scene has
    ``[[coordinates]]`` (``hip_flexion_r``), else as the tree's (``knee.angle``), in ``fitted_units`` (m, rad).
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
    bands: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)
    band_parts: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)
    fitted: dict[str, np.ndarray] = field(default_factory=dict)
    fitted_units: dict[str, str] = field(default_factory=dict)

    def load(self, name: str) -> np.ndarray:
        """(k,) the load called ``name``; KeyError naming the known ones."""
        if name not in self.loads:
            raise KeyError(f"unknown load {name!r}; loads are {sorted(self.loads)}")
        return self.loads[name]

    def summary(self) -> str:
        lines = [*self.report, f"{self.t.size} instants, t = {self.t[0]:g}..{self.t[-1]:g} s"]
        for name in (*self.settings.get("moments", ()), "root.fx", "root.fy", "root.mz"):
            v = self.loads[name]
            lines.append(f"  {name:24s} {v.min():10.2f} .. {v.max():10.2f} {load_unit(name)}  "
                         f"(RMS {np.sqrt(np.mean(v**2)):.2f})")
        return "\n".join(lines + self._band_lines())

    def _band_lines(self) -> list[str]:
        """Per moment: its peak, the band there and the anthropometry's share of its variance."""
        if not self.bands:
            return []
        lines = ["bands at each moment's peak (1 SD: anthropometry, markers; the anthropometry's share of the "
                 "variance):"]
        for name in self.settings.get("moments", ()):
            v, b = self.loads[name], self.bands[name]
            i = int(np.argmax(np.abs(v)))
            a, m, tot = (float(b[k][i]) for k in ("anthropometry", "markers", "total"))
            share = a * a / (tot * tot) if tot > 0 else 0.0
            lines.append(f"  {name:24s} {v[i]:10.2f} N m at t = {self.t[i]:g} s: +-{tot:.2f} ({a:.2f}, {m:.2f}; "
                         f"{100 * share:.0f} %)")
        return lines

    def save(self, path: str | os.PathLike[str], fmt: str | None = None) -> Path:
        """Write the result atomically as ``fmt`` (default the path's suffix): ``npz`` (every array, names and the
        report: :data:`NPZ_KEYS`), ``csv`` (t, the filtered coordinates and the loads, one column each, a header
        line of names with units in brackets, no name twice), ``sto`` (OpenSim's table: time and the loads, in
        the lab's names where the scene has ``[[coordinates]]``, every column's unit listed once in the header) or
        ``mot`` (the IK result as OpenSim's IK writes it: :attr:`fitted`, unfiltered, angles in degrees under
        ``inDegrees=yes``; ``casflex inverse --coordinates`` reads it back)."""
        path = Path(path)
        fmt = fmt or path.suffix.lstrip(".").lower()
        trial = self.settings.get("source") or "a trial"
        if fmt == "sto":
            return self._sto(path, f"casflex inverse dynamics of {trial}")
        if fmt == "mot":
            return self._mot(path, f"Coordinates (casflex marker fit of {trial}, unfiltered)")
        if fmt == "csv":
            return atomic_write_text(path, self._csv())
        buf = io.BytesIO()
        np.savez_compressed(buf, **self._arrays())
        return atomic_write_bytes(path, buf.getvalue())

    def _arrays(self) -> dict[str, np.ndarray]:
        """The .npz's arrays (:data:`NPZ_KEYS`)."""
        names = sorted(self.loads)
        fitted = list(self.fitted)
        arrays = {"t": self.t, "z": self.z, "zd": self.zd, "zdd": self.zdd, "q": self.q, "qd": self.qd,
                  "qdd": self.qdd, "coordinate_names": np.array(self.coordinate_names),
                  "dof_names": np.array(self.dof_names), "load_names": np.array(names),
                  "loads": np.column_stack([self.loads[n] for n in names]), "frame_t": self.frame_t,
                  "marker_rms": self.marker_rms, "fitted_names": np.array(fitted, dtype=str),
                  "fitted_units": np.array([self.fitted_units[n] for n in fitted], dtype=str),
                  "fitted": np.column_stack([self.fitted[n] for n in fitted]) if fitted else np.zeros((self.t.size, 0)),
                  "marker_labels": np.array(self.marker_labels, dtype=str),
                  "marker_misfit": (self.marker_misfit if self.marker_misfit is not None
                                    else np.zeros((self.frame_t.size, 0))),
                  "meta": np.array(json.dumps({"report": self.report, "settings": self.settings,
                                               "warnings": self.warnings}))}
        if self.bands:
            for part in ("total", "anthropometry", "markers"):
                arrays[f"sd_{part}"] = np.column_stack([self.bands[n][part] for n in names])
            targets = sorted(self.band_parts)
            arrays["band_targets"] = np.array(targets)
            arrays["band_parts"] = np.array([np.column_stack([self.band_parts[g][n] for n in names])
                                             for g in targets]).reshape(len(targets), self.t.size, len(names))
        return arrays

    def _csv(self) -> str:
        """The .csv's text: t, the filtered coordinates, the loads (a hinge's angle among the element outputs is
        the coordinate's column already: not again) and the bands, each header cell ``name [unit]``."""
        names = [n for n in sorted(self.loads) if n not in self.coordinate_names]
        bands = self._band_columns(names)
        cols = ["t [s]", *(f"{c} [{_unit(c, True)}]" for c in self.coordinate_names),
                *(f"{n} [{_unit(n)}]" for n in names), *(f"{c} [{_unit(c.partition('_sd')[0])}]" for c in bands)]
        data = np.column_stack([self.t, self.z, *(self.loads[n] for n in names), *bands.values()])
        buf = io.StringIO()
        np.savetxt(buf, data, delimiter=",", header=",".join(cols), comments="", fmt="%.10g")
        return buf.getvalue()

    def _mot(self, path: Path, title: str) -> Path:
        """:attr:`fitted` as OpenSim's IK .mot (:meth:`save`)."""
        if not self.fitted:
            raise ValueError(f"{path}: this result holds no fitted coordinates to write as a .mot")
        deg = {n: self.fitted_units[n] == "rad" for n in self.fitted}
        cols = {n: np.degrees(v) if deg[n] else v for n, v in self.fitted.items()}
        return write_sto(path, self.t, cols, title=title, units={n: "deg" if deg[n] else "m" for n in cols},
                         in_degrees=True)

    def _sto(self, path: Path, title: str) -> Path:
        """The loads as an OpenSim .sto table (:meth:`save`, :func:`casflex.lab.tables.write_sto`)."""
        lab = [n for n in self.loads if n.endswith(("_moment", "_force"))]
        names = lab or sorted(self.loads)
        bands = self._band_columns(names)
        unit = {n: load_unit(n) for n in names} | {c: load_unit(c.rsplit("_sd", 1)[0]) for c in bands}
        return write_sto(path, self.t, {**{n: self.loads[n] for n in names}, **bands}, title=title, units=unit)

    def _band_columns(self, names: list[str]) -> dict[str, np.ndarray]:
        """The bands as columns (none when not asked): ``<load>_sd`` (the total), ``<load>_sd_anthropometry`` and
        ``<load>_sd_markers`` per load of ``names``, in that order."""
        out = {}
        for n in names if self.bands else ():
            for part, suffix in (("total", ""), ("anthropometry", "_anthropometry"), ("markers", "_markers")):
                out[f"{n}_sd{suffix}"] = self.bands[n][part]
        return out
