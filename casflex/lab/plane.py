"""The plane that takes the lab's 3-D axes to a scene's x and y, and a scene's markers from a trial.

- :class:`Plane` (``"X,Y"``, ``"-Z,Y"``): which lab axes become the model's x and y, with their
  signs; the model's plane is seen from the lab axis x cross y (``view``), which it reports, so that
  a mirrored plane (a left side seen from the right) is said, not silently taken.
- :func:`markers_in_plane`: a :class:`~casflex.data.MeasurementSet` of the scene's markers
  (``x<marker>``, ``y<marker>``) from the lab labels they stand for (``label`` of ``[[markers]]``).
- :func:`trial_markers`: the same from a TRC or C3D file, checked (:mod:`casflex.lab.checks`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from casflex.data import MeasurementSet
from casflex.lab.c3d import read_c3d
from casflex.lab.tables import LabMarkers, read_trc

__all__ = ["Plane", "markers_in_plane", "trial_markers"]

_AXES = {"X": 0, "Y": 1, "Z": 2}


@dataclass(frozen=True)
class Plane:
    """Which lab axes become the model's x and y, e.g. ``Plane.parse("X,Y")`` (OpenSim's lab: X forward,
    Y up, the sagittal plane seen from +Z, the subject's right) or ``"-Z,Y"``. ``view``: the lab axis the
    plane is seen from, x cross y (e.g. "+Z")."""

    x: str
    y: str

    @classmethod
    def parse(cls, text: str, *, option: str = "plane") -> Plane:
        parts = [p.strip().upper() for p in str(text).split(",")]
        ok = len(parts) == 2 and all(p.lstrip("+-") in _AXES for p in parts)
        if not ok or parts[0].lstrip("+-") == parts[1].lstrip("+-"):
            raise ValueError(f"{option}: expected two different lab axes for the model's x and y, e.g. 'X,Y' or "
                             f"'-Z,Y', got {text!r}")
        return cls(*parts)

    def _vector(self, axis: str) -> np.ndarray:
        v = np.zeros(3)
        v[_AXES[axis.lstrip("+-")]] = -1.0 if axis.startswith("-") else 1.0
        return v

    @property
    def matrix(self) -> np.ndarray:
        """(2, 3): model (x, y) = matrix @ lab (X, Y, Z)."""
        return np.vstack([self._vector(self.x), self._vector(self.y)])

    @property
    def view(self) -> str:
        n = np.cross(*self.matrix)
        k = int(np.argmax(np.abs(n)))
        return ("+" if n[k] > 0 else "-") + "XYZ"[k]


def markers_in_plane(lab: LabMarkers, labels: dict[str, str], plane: Plane) -> MeasurementSet:
    """A MeasurementSet of channels x<marker>, y<marker> (m) for the scene markers ``labels`` maps to
    their lab labels, projected on ``plane``; NaN where the lab marker is missing."""
    P = plane.matrix
    channels, cols = [], []
    for name, label in labels.items():
        xy = lab.marker(label) @ P.T
        channels += [f"x{name}", f"y{name}"]
        cols += [xy[:, 0], xy[:, 1]]
    return MeasurementSet(lab.t.copy(), tuple(channels), np.column_stack(cols), None, None, source=lab.source,
                          meta={"plane": f"{plane.x},{plane.y}", "view": plane.view, "labels": dict(labels)})


def trial_markers(model, path: str | os.PathLike[str], plane: Plane | str = "X,Y") -> MeasurementSet:
    """The scene's markers (each by its ``label``, or its name) in the TRC or C3D file ``path``, projected on
    ``plane``: a MeasurementSet for identification (module docstring). ValueError naming a label the
    trial lacks, a scene without markers, or a marker no body moves so (:func:`casflex.lab.checks.check_markers`)."""
    markers = model.scene.markers
    if not markers:
        raise ValueError(f"{path}: the scene has no [[markers]] to take from the trial")
    from casflex.lab.checks import check_markers

    plane = Plane.parse(plane) if isinstance(plane, str) else plane
    lab = read_c3d(path, plates=False)[0] if os.fspath(path).lower().endswith(".c3d") else read_trc(path)
    labels = {m.name: m.lab_label for m in markers}
    check_markers(lab, tuple(labels.values()))
    return markers_in_plane(lab, labels, plane)
