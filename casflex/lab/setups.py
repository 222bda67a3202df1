"""OpenSim's setup files, as a lab has them: the marker weights of an inverse kinematics task set
(``<IKTaskSet>``, in its own file or inside an ``<InverseKinematicsTool>`` setup, or in a file that
setup names). Read directly from the XML (no ``opensim`` needed)."""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass

__all__ = ["MarkerTasks", "read_tasks"]


@dataclass(frozen=True)
class MarkerTasks:
    """The marker weights of a task set: ``weights`` label -> weight (0 for a task not applied), and the
    coordinate tasks casflex does not take (``coordinate_tasks``: their names)."""

    source: str
    weights: dict[str, float]
    coordinate_tasks: tuple[str, ...] = ()


def _parse(path: str):
    try:
        return ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise ValueError(f"{path}: not an OpenSim setup or task file (XML: {exc})") from None
    except OSError as exc:
        raise ValueError(f"{path}: cannot read it ({exc.strerror or exc})") from None


def read_tasks(path: str | os.PathLike[str]) -> MarkerTasks:
    """The marker tasks of an IK task set file or an IK setup file (module docstring). ValueError in one
    line for a file with no task set, or a weight that is not a number >= 0."""
    path = os.fspath(path)
    root = _parse(path)
    sets = root.findall(".//IKTaskSet") if root.tag != "IKTaskSet" else [root]
    for s in sets:
        if s.get("file") and s.find("objects") is None:  # the setup names a task file
            inner = os.path.join(os.path.dirname(path), s.get("file"))
            return read_tasks(inner)
    weights: dict[str, float] = {}
    coords = []
    for s in sets:
        for task in s.iter():
            if task.tag not in ("IKMarkerTask", "IKCoordinateTask"):
                continue
            name = task.get("name", "")
            apply = (task.findtext("apply") or "true").strip().lower() == "true"
            text = (task.findtext("weight") or "1").strip()
            try:
                w = float(text)
            except ValueError:
                w = -1.0
            if not w >= 0 or w == float("inf"):
                raise ValueError(f"{path}: task {name!r}: weight must be a number >= 0, got {text!r}")
            if task.tag == "IKMarkerTask":
                weights[name] = w if apply else 0.0
            elif apply and w > 0:
                coords.append(name)
    if not weights:
        raise ValueError(f"{path}: no IKMarkerTask: not an OpenSim IK task set or setup file")
    return MarkerTasks(path, weights, tuple(coords))
