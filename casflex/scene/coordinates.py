"""The lab's coordinates of a scene (``[[coordinates]]``): the names and values a lab's model gives its
degrees of freedom (an OpenSim model's ``hip_flexion_r``, ``pelvis_tx``), tied to the scene's own.

Inverse dynamics moves a scene by its root's pose (x, y in m, theta in rad) and its hinges' angles (rad,
from the initial configuration: :mod:`casflex.inverse.tree`). A lab coordinate is one of them, shifted
and perhaps reversed: ``value = value0 + sign * (own - own0)``, with ``own0`` the scene coordinate's value
in the initial configuration (0 for a hinge's angle, the root node's x, y or theta for the root) and
``value0`` the lab coordinate's value there (an OpenSim model's default pose). Loads along a coordinate
are named after it (``hip_flexion_r_moment``, ``pelvis_tx_force``) and a table of coordinates
(an OpenSim IK ``.mot``) can drive the scene instead of markers.
"""

from __future__ import annotations

from dataclasses import dataclass

from casflex.scene.items import SceneError, _number, _owner

__all__ = ["Coordinate", "check_coordinates"]

_ROOT_DOFS = ("x", "y", "theta")


@dataclass(frozen=True)
class Coordinate:
    """A lab coordinate ``name``: the angle of the hinge ``of`` (rad), or the root's pose ``of =
    "<node>.x"``, ``"<node>.y"`` (m), ``"<node>.theta"`` (rad); ``value0`` its value in the scene's
    initial configuration (m or rad), ``sign`` +1 or -1 (module docstring); ``limits`` (lower, upper) in
    the coordinate's own units: the range a marker fit keeps it in (an OpenSim model's clamped coordinate,
    which OpenSim's IK keeps in its range), None: any value."""

    name: str
    of: str
    value0: float = 0.0
    sign: float = 1.0
    limits: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        where = _owner("coordinate", self.name)
        if not isinstance(self.name, str) or not self.name.strip() or any(c in self.name for c in " \t\n"):
            raise SceneError.at(where, "name", f"expected the lab's name of the coordinate, got {self.name!r}")
        if not isinstance(self.of, str) or not self.of.strip():
            raise SceneError.at(where, "of", f"expected a hinge's name or '<node>.x|y|theta', got {self.of!r}")
        object.__setattr__(self, "value0", _number(where, "value0", self.value0))
        sign = _number(where, "sign", self.sign)
        if sign not in (1.0, -1.0):
            raise SceneError.at(where, "sign", f"must be 1 or -1, got {sign:g}")
        object.__setattr__(self, "sign", sign)
        if self.limits is not None:
            if not isinstance(self.limits, (list, tuple)) or len(self.limits) != 2:
                raise SceneError.at(where, "limits", f"expected [lower, upper], got {self.limits!r}")
            lo, hi = (_number(where, "limits", v) for v in self.limits)
            if not lo < hi:
                raise SceneError.at(where, "limits", f"the lower limit must be below the upper, got [{lo:g}, {hi:g}]")
            object.__setattr__(self, "limits", (lo, hi))

    @property
    def translational(self) -> bool:
        """Whether the coordinate is a length (m): the root's x or y."""
        return self.of.endswith((".x", ".y"))

    @property
    def unit(self) -> str:
        return "m" if self.translational else "rad"

    def scene_coordinate(self) -> str:
        """The scene's own coordinate (:class:`casflex.inverse.tree.KinematicTree` names it so)."""
        return self.of if "." in self.of else f"{self.of}.angle"


def check_coordinates(scene) -> None:
    """SceneError for a coordinate of nothing the scene has (a hinge, or a node's x, y, theta), or two
    coordinates with one name or one scene coordinate."""
    hinges = {j.name for j in scene.joints if j.kind == "hinge"}
    nodes = {n.name for n in scene.nodes}
    names: set[str] = set()
    ofs: set[str] = set()
    for i, c in enumerate(scene.coordinates):
        where = f"coordinates[{i}] ({c.name})"
        if c.name in names:
            raise SceneError(f"{where}.name: duplicate coordinate {c.name!r}")
        if c.of in ofs:
            raise SceneError(f"{where}.of: {c.of!r} already has a coordinate")
        names.add(c.name)
        ofs.add(c.of)
        node, _, dof = c.of.rpartition(".")
        if not (c.of in hinges or (node in nodes and dof in _ROOT_DOFS)):
            raise SceneError(f"{where}.of: {c.of!r} is no hinge nor '<node>.x|y|theta'; hinges {sorted(hinges)}")


def own_value0(scene, coordinate: Coordinate) -> float:
    """The scene coordinate's value in the initial configuration (module docstring)."""
    node, _, dof = coordinate.of.rpartition(".")
    if not node or dof not in _ROOT_DOFS:
        return 0.0
    n = scene.node(node)
    return {"x": n.x, "y": n.y, "theta": n.theta}[dof]


def to_lab(scene, coordinate: Coordinate, own):
    """The lab coordinate's values from the scene coordinate's (arrays or floats)."""
    return coordinate.value0 + coordinate.sign * (own - own_value0(scene, coordinate))


def from_lab(scene, coordinate: Coordinate, value):
    """The scene coordinate's values from the lab coordinate's."""
    return own_value0(scene, coordinate) + coordinate.sign * (value - coordinate.value0)


def scene_limits(scene, coordinate: Coordinate) -> tuple[float, float]:
    """(lower, upper) of the scene coordinate's values that the lab coordinate's ``limits`` allow
    (-inf, inf without limits)."""
    if coordinate.limits is None:
        return -float("inf"), float("inf")
    a, b = (from_lab(scene, coordinate, v) for v in coordinate.limits)
    return min(a, b), max(a, b)
