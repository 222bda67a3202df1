"""Scenes: pure data describing a planar flexible multibody system.

A scene lists nodes, elements (co-rotational beams, linear axial springs, torsional springs),
supports, gravity, nodal loads, the properties declared as identification parameters and the
run settings. It holds numbers only (no CasADi); :func:`casflex.model.assemble` turns it into
a symbolic model. Every constructor validates its fields and raises :class:`SceneError` with
a message that names the offending field, e.g. ``springs[0] (spring1).k: must be > 0, got -5``.

Units are SI throughout: m, rad, s, kg, N, N m, Pa.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import Any

from casflex.scene.items import (
    _NON_NUMERIC,
    SUPPORT_DOFS,
    Beam,
    Joint,
    Load,
    Node,
    Parameter,
    RigidBody,
    RunSettings,
    SceneError,
    Spring,
    Support,
    TorsionSpring,
    _number,
)

__all__ = [
    "SceneError",
    "Node",
    "Beam",
    "Spring",
    "TorsionSpring",
    "RigidBody",
    "Joint",
    "Support",
    "Load",
    "Parameter",
    "RunSettings",
    "Scene",
    "SUPPORT_DOFS",
]


@dataclass(frozen=True)
class Scene:
    """A whole planar flexible multibody system, validated on construction.

    ``gravity`` is the acceleration vector (m/s^2), default (0, -9.81).
    """

    name: str
    nodes: tuple[Node, ...]
    beams: tuple[Beam, ...] = ()
    springs: tuple[Spring, ...] = ()
    torsion_springs: tuple[TorsionSpring, ...] = ()
    bodies: tuple[RigidBody, ...] = ()
    supports: tuple[Support, ...] = ()
    joints: tuple[Joint, ...] = ()
    loads: tuple[Load, ...] = ()
    parameters: tuple[Parameter, ...] = ()
    gravity: tuple[float, float] = (0.0, -9.81)
    run: RunSettings = field(default_factory=RunSettings)
    markers: tuple[Any, ...] = ()  # casflex.scene.markers.Marker
    coordinates: tuple[Any, ...] = ()  # casflex.scene.coordinates.Coordinate
    uncertain: tuple[Any, ...] = ()  # casflex.scene.uncertain.Uncertain

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise SceneError(f"name: expected a non-empty string (the scene's name), got {self.name!r}")
        for f in ("nodes", "beams", "springs", "torsion_springs", "bodies", "supports", "joints", "loads",
                  "parameters", "markers", "coordinates", "uncertain"):
            value = getattr(self, f)
            if isinstance(value, str) or not isinstance(value, (list, tuple)):
                raise SceneError(f"{f}: expected a list, got {type(value).__name__}")
            object.__setattr__(self, f, tuple(value))
        if not self.nodes:
            raise SceneError("nodes: a scene needs at least one node")
        if isinstance(self.gravity, str) or not isinstance(self.gravity, (list, tuple)) or len(self.gravity) != 2:
            raise SceneError(f"gravity: expected [gx, gy] in m/s^2 (two numbers), got {self.gravity!r}")
        object.__setattr__(self, "gravity", tuple(_number("", f"gravity[{i}]", g) for i, g in enumerate(self.gravity)))
        if not isinstance(self.run, RunSettings):
            raise SceneError(f"run: expected RunSettings, got {type(self.run).__name__}")
        self._check_types()
        self._check_references()
        self._check_geometry()
        self._check_parameters()
        from casflex.scene.coordinates import check_coordinates
        from casflex.scene.markers import check_markers
        from casflex.scene.uncertain import check_uncertain

        check_markers(self)
        check_coordinates(self)
        check_uncertain(self)

    # -- validation -------------------------------------------------------------------------
    def _check_types(self) -> None:
        from casflex.scene.coordinates import Coordinate
        from casflex.scene.markers import Marker

        kinds = {"nodes": Node, "beams": Beam, "springs": Spring, "torsion_springs": TorsionSpring,
                 "bodies": RigidBody, "supports": Support, "joints": Joint, "loads": Load, "parameters": Parameter,
                 "markers": Marker, "coordinates": Coordinate}
        for f, cls in kinds.items():
            for i, item in enumerate(getattr(self, f)):
                if not isinstance(item, cls):
                    raise SceneError(f"{f}[{i}]: expected a {cls.__name__}, got {type(item).__name__}")

    def _check_references(self) -> None:
        seen: dict[str, str] = {}
        for i, n in enumerate(self.nodes):
            if n.name in seen:
                raise SceneError(f"nodes[{i}].name: duplicate node {n.name!r}")
            seen[n.name] = "node"
        names: dict[str, str] = {}
        for f in ("beams", "springs", "torsion_springs", "bodies", "supports", "joints", "loads"):
            for i, item in enumerate(getattr(self, f)):
                if item.name == "gravity":
                    raise SceneError(f"{f}[{i}].name: 'gravity' is reserved "
                                     "(parameter targets 'gravity.x', 'gravity.y')")
                if item.name in names:
                    raise SceneError(f"{f}[{i}].name: duplicate name {item.name!r}, already used in {names[item.name]} "
                                     "(names are unique across beams, springs, torsion springs, bodies, supports, "
                                     "joints and loads)")
                names[item.name] = f
                refs = ([(f"nodes[{j}]", r) for j, r in enumerate(item.nodes)] if hasattr(item, "nodes")
                        else [("node", item.node)])
                if getattr(item, "against", None) is not None:
                    refs.append(("against", item.against))
                for key, r in refs:
                    if r not in seen:
                        raise SceneError(f"{f}[{i}] ({item.name}).{key}: unknown node {r!r}; known nodes: {list(seen)}")
        fixed: dict[tuple[str, str], str] = {}
        for i, s in enumerate(self.supports):
            for d in s.dofs:
                if (s.node, d) in fixed:
                    raise SceneError(f"supports[{i}] ({s.name}).kind: dof {d}{s.node} is already fixed by support "
                                     f"{fixed[(s.node, d)]!r}")
                fixed[(s.node, d)] = s.name

    def _check_geometry(self) -> None:
        for i, b in enumerate(self.beams):
            if self.distance(*b.nodes) <= 0.0:
                raise SceneError(f"beams[{i}] ({b.name}).nodes: zero length, "
                                 f"nodes {b.nodes[0]!r} and {b.nodes[1]!r} coincide")
        for i, s in enumerate(self.springs):
            if self.spring_length(s) <= 0.0 and (s.rest_length is None or s.rest_length > 0.0):
                ends = (f"nodes {s.nodes[0]!r} and {s.nodes[1]!r}" if s.point_a is None and s.point_b is None
                        else "its ends")
                raise SceneError(f"springs[{i}] ({s.name}).nodes: {ends} coincide; a spring needs a direction "
                                 "(only a zero-length spring, rest_length = 0, may start there)")

    def _check_parameters(self) -> None:
        seen: set[str] = set()
        targets: dict[str, str] = {}
        for i, p in enumerate(self.parameters):
            if p.name in seen:
                raise SceneError(f"parameters[{i}].name: duplicate parameter {p.name!r}")
            seen.add(p.name)
            where = f"parameters[{i}] ({p.name})"
            if p.target in targets:
                raise SceneError(f"{where}.target: {p.target!r} is already declared by parameter {targets[p.target]!r}")
            targets[p.target] = p.name
            value = self.property_value(p.target, where=f"{where}.target")
            if value < p.lower:
                raise SceneError(f"{where}.lower: the nominal value {value:g} of {p.target} "
                                 f"is below the lower bound {p.lower:g}")
            if value > p.upper:
                raise SceneError(f"{where}.upper: the nominal value {value:g} of {p.target} "
                                 f"is above the upper bound {p.upper:g}")

    # -- queries ----------------------------------------------------------------------------
    def node(self, name: str) -> Node:
        for n in self.nodes:
            if n.name == name:
                return n
        raise SceneError(f"unknown node {name!r}")

    def distance(self, a: str, b: str) -> float:
        na, nb = self.node(a), self.node(b)
        return math.hypot(nb.x - na.x, nb.y - na.y)

    def spring_ends(self, spring: Spring) -> tuple[tuple[float, float], tuple[float, float]]:
        """The spring's two ends in the initial configuration (m): its points, or its nodes."""
        return tuple((n.x, n.y) if pt is None else pt  # type: ignore[return-value]
                     for n, pt in zip((self.node(spring.nodes[0]), self.node(spring.nodes[1])),
                                      (spring.point_a, spring.point_b), strict=True))

    def spring_length(self, spring: Spring) -> float:
        """The initial distance between the spring's ends (m): its default rest length."""
        (xa, ya), (xb, yb) = self.spring_ends(spring)
        return math.hypot(xb - xa, yb - ya)

    def joint_point(self, joint: Joint) -> tuple[float, float]:
        """The joint's point in the initial configuration (m): its ``point``, or node b's position."""
        if joint.point is not None:
            return joint.point
        nb = self.node(joint.nodes[-1])
        return nb.x, nb.y

    def item(self, name: str) -> Any:
        """The element, support, joint or load called ``name``."""
        for f in ("beams", "springs", "torsion_springs", "bodies", "supports", "joints", "loads"):
            for it in getattr(self, f):
                if it.name == name:
                    return it
        raise SceneError(f"unknown element or load {name!r}")

    def property_value(self, target: str, *, where: str = "target") -> float:
        """The numeric value of the property ``"<name>.<field>"`` (defaults resolved)."""
        owner, _, prop = target.partition(".")
        if owner == "gravity":
            if prop not in ("x", "y"):
                raise SceneError(f"{where}: gravity has components 'x' and 'y', got {prop!r}")
            return self.gravity[0 if prop == "x" else 1]
        try:
            it = self.item(owner)
        except SceneError:
            known = [it.name for f in ("beams", "springs", "torsion_springs", "bodies", "loads")
                     for it in getattr(self, f)]
            raise SceneError(f"{where}: unknown element or load {owner!r} in {target!r}; "
                             f"known: {known + ['gravity']}") from None
        if isinstance(it, (Support, Joint)):
            what = "a support; supports" if isinstance(it, Support) else "a joint; joints"
            raise SceneError(f"{where}: {owner!r} is {what} have no numeric properties to identify")
        numeric = [f.name for f in fields(it) if f.name not in _NON_NUMERIC]
        if isinstance(it, RigidBody):
            numeric = ["mass", "inertia", "com_x", "com_y"]
        if prop not in numeric:
            raise SceneError(f"{where}: {owner!r} has no numeric property {prop!r}; expected one of {numeric}")
        if isinstance(it, Load) and it.table is not None:
            raise SceneError(f"{where}: load {owner!r} is given as a table; tabulated loads cannot be parameters")
        value = getattr(it, prop)
        if value is None:
            if isinstance(it, RigidBody):  # the centre of mass defaults to the node
                value = getattr(self.node(it.node), prop[-1])
            elif isinstance(it, Spring):
                value = self.spring_length(it)
            elif isinstance(it, TorsionSpring):
                value = self.node(it.nodes[1]).theta - self.node(it.nodes[0]).theta
        return float(value)

    def parameter(self, name: str) -> Parameter:
        for p in self.parameters:
            if p.name == name:
                return p
        raise SceneError(f"unknown parameter {name!r}; declared: {[p.name for p in self.parameters]}")

    def with_values(self, **values: float) -> Scene:
        """A copy with the named parameters set to new nominal values (bounds still checked)."""
        scene = self
        for name, v in values.items():
            try:
                scene = scene.with_property(self.parameter(name).target, v)
            except SceneError as exc:
                raise SceneError(f"with_values({name}={v!r}): {exc}") from None
        return scene

    def with_property(self, target: str, value: Any) -> Scene:
        """A copy with the property ``"<name>.<field>"`` (or ``"gravity.<x|y>"``) set to ``value``."""
        owner, _, prop = target.partition(".")
        if owner == "gravity":
            g = list(self.gravity)
            g[0 if prop == "x" else 1] = value
            return replace(self, gravity=tuple(g))
        for f in ("beams", "springs", "torsion_springs", "bodies", "loads"):
            items = list(getattr(self, f))
            for i, it in enumerate(items):
                if it.name == owner:
                    items[i] = replace(it, **{prop: value})
                    return replace(self, **{f: tuple(items)})
        raise SceneError(f"unknown element or load {owner!r} in {target!r}")

    @property
    def length_scale(self) -> float:
        """Characteristic length (m): the largest distance between two nodes (>= 1e-3)."""
        xs = [n.x for n in self.nodes]
        ys = [n.y for n in self.nodes]
        return max(math.hypot(max(xs) - min(xs), max(ys) - min(ys)), 1e-3)
