"""OpenSim's setup files, as a lab has them: the marker weights of an inverse kinematics task set
(``<IKTaskSet>``, in its own file or inside an ``<InverseKinematicsTool>`` setup, or in a file that
setup names), and which plate acts on which body (an ``<ExternalLoads>`` file, or an inverse dynamics
setup naming one). Read directly from the XML (no ``opensim`` needed)."""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass

__all__ = ["ExternalLoads", "MarkerTasks", "read_external_loads", "read_tasks", "tool_settings"]


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


def _text(path: str, el: ET.Element, tag: str, owner: str, default: str = "") -> str:
    """``el``'s element ``tag``'s text, stripped (``default`` where left out or empty); ValueError in one line
    naming it where ``el`` holds it twice (OpenSim reads the first without a word: which one was meant is a guess)."""
    found = el.findall(tag)
    if len(found) > 1:
        raise ValueError(f"{path}: {owner}: {tag} given {len(found)} times; give it once")
    return ((found[0].text or "").strip() if found else "") or default


def _named(path: str, name: str, element: str, seen: tuple[str, ...]) -> str:
    """The file ``name`` that ``path``'s ``element`` names (relative to ``path``'s directory); ValueError in one
    line when it is one of the files ``seen`` on the way here (a setup naming itself, two naming each other)."""
    inner = os.path.join(os.path.dirname(path), name)
    if any(_same(inner, s) for s in (*seen, path)):
        loop = " -> ".join([*seen, path, inner])
        raise ValueError(f"{path}: {element} names {name!r}, a file already on the way here ({loop}): a loop of "
                         "setup files; name the file that holds the data")
    return inner


def _same(a: str, b: str) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.normpath(a) == os.path.normpath(b)


def read_tasks(path: str | os.PathLike[str], _seen: tuple[str, ...] = ()) -> MarkerTasks:
    """The marker tasks of an IK task set file or an IK setup file (module docstring). ValueError in one
    line for a file with no task set, a weight that is not a number >= 0, or a setup that names itself."""
    path = os.fspath(path)
    root = _parse(path)
    sets = root.findall(".//IKTaskSet") if root.tag != "IKTaskSet" else [root]
    for s in sets:
        if s.get("file") and s.find("objects") is None:  # the setup names a task file
            return read_tasks(_named(path, s.get("file"), "IKTaskSet file", _seen), (*_seen, path))
    weights: dict[str, float] = {}
    coords = []
    for s in sets:
        for task in s.iter():
            if task.tag not in ("IKMarkerTask", "IKCoordinateTask"):
                continue
            name = task.get("name", "")
            owner = f"{task.tag} {name!r}"
            if name in weights or name in coords:
                raise ValueError(f"{path}: two tasks named {name!r}; give each marker or coordinate one task")
            apply = _text(path, task, "apply", owner, "true").lower() == "true"
            text = _text(path, task, "weight", owner, "1")
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


@dataclass(frozen=True)
class ExternalLoads:
    """An ``ExternalLoads`` file's plates: ``datafile`` (the ground reactions' .mot, its path resolved from
    the file's directory), ``plates`` body -> its plates' (force, point, torque) identifiers, in the file's order
    (a foot on plate 1, a stride later on plate 3: two ExternalForces on one body, OpenSim sums them), the
    columns' stems (``("ground_force_v", "ground_force_p", "ground_torque_")``: columns ``ground_force_vx`` ...)."""

    source: str
    datafile: str
    plates: dict[str, tuple[tuple[str, str, str], ...]]

    @staticmethod
    def prefix(identifiers: tuple[str, str, str]) -> str | None:
        """The column prefix of a plate whose identifiers are ``<prefix>force_v``, ``<prefix>force_p``,
        ``<prefix>torque_`` (OpenSim's examples; casflex's plates), else None."""
        force, point, torque = identifiers
        p = force[:-len("force_v")] if force.endswith("force_v") else None
        return p if p is not None and point == f"{p}force_p" and torque == f"{p}torque_" else None


def _identifiers(path: str, force: ET.Element) -> tuple[str, tuple[str, str, str]]:
    """(body, (force, point, torque) identifiers) of an ``ExternalForce`` expressed in the ground."""
    name = force.get("name", "")
    owner = f"ExternalForce {name!r}"
    body = _text(path, force, "applied_to_body", owner)
    for tag in ("force_expressed_in_body", "point_expressed_in_body"):
        frame = _text(path, force, tag, owner, "ground")
        if frame != "ground":
            raise ValueError(f"{path}: ExternalForce {name!r}: {tag} is {frame!r}; casflex takes plates in the ground")
    ident = tuple(_text(path, force, f"{tag}_identifier", owner) for tag in ("force", "point", "torque"))
    if not body or not ident[0] or not ident[1]:
        raise ValueError(f"{path}: ExternalForce {name!r}: needs applied_to_body, force_identifier and "
                         f"point_identifier, got {body!r}, {ident[0]!r} and {ident[1]!r}")
    return body, ident


def read_external_loads(path: str | os.PathLike[str], _seen: tuple[str, ...] = ()) -> ExternalLoads:
    """The plates of an ``ExternalLoads`` file, or of the one an inverse dynamics setup names in
    ``external_loads_file`` (module docstring). ValueError in one line for a file with no external force,
    one that is not in the ground, no data file, or a setup that names itself."""
    path = os.fspath(path)
    root = _parse(path)
    loads = root if root.tag == "ExternalLoads" else root.find(".//ExternalLoads")
    if loads is None:
        inner = (root.findtext(".//external_loads_file") or "").strip()
        if inner:
            return read_external_loads(_named(path, inner, "external_loads_file", _seen), (*_seen, path))
        raise ValueError(f"{path}: no ExternalLoads: not an OpenSim external loads or inverse dynamics setup file")
    plates: dict[str, tuple[tuple[str, str, str], ...]] = {}
    for force in loads.iter("ExternalForce"):
        body, ident = _identifiers(path, force)
        twin = next((b for b, others in plates.items() if any(o[0] == ident[0] for o in others)), None)
        if twin is not None:
            raise ValueError(f"{path}: the external forces on {twin!r} and {body!r} both take the columns "
                             f"{ident[0]!r}: one plate's load would be counted twice; give each plate once")
        plates[body] = (*plates.get(body, ()), ident)
    if not plates:
        raise ValueError(f"{path}: no ExternalForce")
    data = _text(path, loads, "datafile", "ExternalLoads")
    if not data:
        raise ValueError(f"{path}: no datafile: the ground reactions' file is not named")
    return ExternalLoads(path, os.path.join(os.path.dirname(path), data), plates)


def tool_settings(path: str | os.PathLike[str]) -> dict[str, object]:
    """What an inverse dynamics or kinematics setup file (``<InverseDynamicsTool>``, ``<InverseKinematicsTool>``)
    asks of the trial beyond its plates or tasks: ``cutoff`` (an ID setup's
    ``lowpass_cutoff_frequency_for_coordinates``, Hz; None where it is -1: unfiltered) and ``time_range`` ((start,
    end) s), each where the file gives it; {} for a file that is no such setup (an ExternalLoads or task file)."""
    path = os.fspath(path)
    root = _parse(path)
    tool = next((el for tag in ("InverseDynamicsTool", "InverseKinematicsTool")
                 for el in ([root] if root.tag == tag else root.findall(f".//{tag}"))), None)
    if tool is None:
        return {}
    owner = f"InverseDynamicsTool {tool.get('name', '')!r}"
    out: dict[str, object] = {}
    try:
        cutoff = _text(path, tool, "lowpass_cutoff_frequency_for_coordinates", owner)
        cutoff = float(cutoff) if cutoff else None
        span = [float(v) for v in _text(path, tool, "time_range", owner).split()]
    except ValueError as exc:
        if "given" in str(exc):
            raise
        raise ValueError(f"{path}: {owner}: lowpass_cutoff_frequency_for_coordinates and time_range must be "
                         "numbers") from None
    if cutoff is not None:
        out["cutoff"] = cutoff if cutoff > 0 else None
    if len(span) == 2:
        out["time_range"] = (span[0], span[1])
    return out
