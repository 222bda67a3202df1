"""Markers in a scene: named points fixed on a beam or a rigid body (``[[markers]]``), checked against the
scene they sit in. Their kinematics, as the model moves, are :mod:`casflex.model.markers`'s."""

from __future__ import annotations

import math
from dataclasses import dataclass

from casflex.scene.items import SceneError, _name, _number, _owner

__all__ = ["Marker", "check_markers"]


@dataclass(frozen=True)
class Marker:
    """A point fixed on the beam or rigid body ``on``, at (x, y) (m) in the scene's initial
    configuration; ``label``: the lab's label of the marker it stands for in a trial's TRC file
    (default: its name; :mod:`casflex.lab`); ``weight``: its weight in the marker fit (>= 0, as an OpenSim
    IK task's: the fit minimises the sum of weight * squared distance; 0 leaves it out); ``fixed``: where it sits
    on its segment is given, not measured: a static trial's calibration leaves it there (OpenSim's ``<fixed>``,
    which its marker placer keeps)."""

    name: str
    on: str
    x: float
    y: float
    label: str | None = None
    weight: float = 1.0
    fixed: bool = False

    def __post_init__(self) -> None:
        where = _owner("marker", self.name)
        object.__setattr__(self, "name", _name(where, "name", self.name))
        object.__setattr__(self, "on", _name(where, "on", self.on))
        for f in ("x", "y"):
            object.__setattr__(self, f, _number(where, f, getattr(self, f)))
        weight = _number(where, "weight", self.weight)
        if weight < 0:
            raise SceneError.at(where, "weight", f"must be >= 0, got {weight:g}")
        object.__setattr__(self, "weight", weight)
        if not isinstance(self.fixed, bool):
            raise SceneError.at(where, "fixed", f"expected true or false, got {self.fixed!r}")
        if self.label is not None and (not isinstance(self.label, str) or not self.label.strip()):
            raise SceneError.at(where, "label", f"expected the lab's marker label (a string), got {self.label!r}")

    @property
    def lab_label(self) -> str:
        """The lab's label of the marker this one stands for in a trial: ``label``, or else the name."""
        return self.label or self.name


def check_markers(scene) -> None:
    """SceneError for a marker on nothing known, a name clashing with a node's or another
    marker's (their channels would coincide), or a point beyond its beam's ends."""
    nodes = {n.name for n in scene.nodes}
    beams = {b.name: b for b in scene.beams}
    bodies = {b.name for b in scene.bodies}
    seen: set[str] = set()
    for i, m in enumerate(scene.markers):
        where = f"markers[{i}] ({m.name})"
        if m.name in nodes or m.name in seen:
            raise SceneError(f"{where}.name: {m.name!r} is already a {'node' if m.name in nodes else 'marker'}; "
                             "its channels x, y would coincide")
        seen.add(m.name)
        if m.on not in beams and m.on not in bodies:
            raise SceneError(f"{where}.on: {m.on!r} is no beam or rigid body; beams {sorted(beams)}, "
                             f"bodies {sorted(bodies)}")
        if m.on in beams:
            a, b = (scene.node(n) for n in beams[m.on].nodes)
            L = math.hypot(b.x - a.x, b.y - a.y)
            s = ((m.x - a.x) * (b.x - a.x) + (m.y - a.y) * (b.y - a.y)) / L
            if not -1e-9 * L <= s <= L * (1 + 1e-9):
                raise SceneError(f"{where}: the point ({m.x:g}, {m.y:g}) lies {s:g} m along beam {m.on!r}, beyond its "
                                 f"ends (0 to {L:g} m)")
