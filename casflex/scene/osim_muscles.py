"""An OpenSim model's muscles read into plain data (:mod:`casflex.scene.osim` reads the rest of the model).

The ForceSet's ``Millard2012EquilibriumMuscle``, ``Thelen2003Muscle`` and ``DeGrooteFregly2016Muscle``
(:data:`casflex.scene.muscles.MUSCLE_KINDS`): the five properties every muscle has, the model's other numbers
for it (a Millard muscle's curve objects' as ``<Curve>.<tag>``), and its GeometryPath: the points of its
PathPointSet (``PathPoint``, ``ConditionalPathPoint``, ``MovingPathPoint``) and its PathWrapSet's wraps with
the wrap objects of the bodies' WrapObjectSets. A path point's body is its socket ``socket_parent_frame``
(OpenSim 4: ``/bodyset/femur_r``) or OpenSim 3's ``<body>``; a coordinate the socket's last name
(``/jointset/knee_r/knee_angle_r``). Refused, one line naming the file, the muscle and the element: a number
that is NaN, infinite or out of its range, a point on no body of the model, a path of fewer than two points, a
condition or moving point naming no coordinate of the model, a wrap naming no wrap object.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from casflex.scene.functions import Constant, Function
from casflex.scene.muscles import MUSCLE_KINDS, QUADRANTS

__all__ = ["OsimPathPoint", "OsimMuscle", "OsimWrapObject", "read_muscles", "read_wrap_objects"]

#: The five properties of every muscle: (tag, OpenSim's default, must be > 0). Lengths m, force N, angle rad,
#: velocity optimal fibre lengths per second.
COMMON = (("max_isometric_force", 1000.0, True), ("optimal_fiber_length", 0.1, True),
          ("tendon_slack_length", 0.2, True), ("pennation_angle_at_optimal", 0.0, False),
          ("max_contraction_velocity", 10.0, True))
#: A muscle's child elements that hold no numbers of the muscle (its path, its display).
_NOT_NUMBERS = {"GeometryPath", "Appearance", "appliesForce", "isDisabled"}


@dataclass(frozen=True)
class OsimPathPoint:
    """A path point: its OpenSim class ``kind``, its body (``ground`` for the ground), ``location`` (3,) m in the
    body's frame (a MovingPathPoint's: zeros), a ConditionalPathPoint's ``condition`` (coordinate, lower, upper)
    and a MovingPathPoint's ``moving`` ((axis 0-2, coordinate or None, function), ...) for x, y, z."""

    name: str
    kind: str
    body: str
    location: np.ndarray
    condition: tuple[str, float, float] | None = None
    moving: tuple[tuple[int, str | None, Function], ...] = ()


@dataclass(frozen=True)
class OsimWrapObject:
    """A wrap object of a body's (or the ground's) WrapObjectSet: its class ``kind`` (``WrapCylinder``,
    ``WrapSphere``, ...), body, orientation (3, 3) and origin (3,) in the body's frame, ``quadrant``, ``active``,
    and a cylinder's ``radius`` and ``length`` (m; NaN for other kinds; OpenSim's default 1 m where a cylinder's
    file gives none)."""

    name: str
    kind: str
    body: str
    rotation: np.ndarray
    translation: np.ndarray
    quadrant: str
    active: bool
    radius: float = math.nan
    length: float = math.nan


@dataclass(frozen=True)
class OsimMuscle:
    """A muscle of the model's ForceSet (module docstring): ``numbers`` the five common properties by tag,
    ``properties`` the other numbers as (tag, value), ``path`` its points, ``wraps`` (wrap object, (first,
    last) point range) of its PathWrapSet."""

    name: str
    kind: str
    numbers: dict[str, float]
    properties: tuple[tuple[str, float], ...]
    path: tuple[OsimPathPoint, ...]
    wraps: tuple[tuple[str, tuple[int, int]], ...] = ()


def _leaf(text: str | None) -> str:
    return (text or "").strip().rsplit("/", 1)[-1]


def _numbers(r, m, owner: str) -> tuple[dict[str, float], tuple[tuple[str, float], ...]]:
    """The five common properties (checked) and the muscle's other numeric children, curves' as ``Curve.tag``."""
    numbers = {}
    for tag, default, positive in COMMON:
        v = r.number(m, tag, owner, default)
        bad = v <= 0 if positive else not 0 <= v < math.pi / 2
        if bad:
            want = "> 0" if positive else "in [0, pi/2) rad"
            raise ValueError(f"{r.source}: {owner}.{tag}: must be {want}, got {v:g}")
        numbers[tag] = v
    props: list[tuple[str, float]] = []
    for el in m:
        if el.tag in _NOT_NUMBERS or el.tag in numbers or not isinstance(el.tag, str):
            continue
        r.single(m, el.tag, owner)  # a property given twice (two max_control): refused, not read first-wins
        if len(el):  # an object (a Millard curve): its numbers, each given once
            for c in el:
                if isinstance(c.tag, str):
                    r.single(el, c.tag, f"{owner}.{el.tag}")
            props += [(f"{el.tag}.{k}", v) for k, v in _scalars(r, el, f"{owner}.{el.tag}")]
        else:
            props += _scalars(r, [el], owner)
    return numbers, tuple(props)


def _scalars(r, elements, owner: str) -> list[tuple[str, float]]:
    """(tag, value) of each element holding one number; NaN or infinity refused (a muscle's curve or force made
    of it would be NaN), an element of text or several numbers skipped."""
    out = []
    for el in elements:
        if len(el) or not isinstance(el.tag, str):
            continue
        text = (el.text or "").strip()
        try:
            v = float(text)
        except ValueError:
            continue
        if not math.isfinite(v) or abs(v) > 1e9:
            raise ValueError(f"{r.source}: {owner}.{el.tag}: {text!r} is no number of a muscle (finite, up to 1e9)")
        out.append((el.tag, v))
    return out


def _point(r, p, owner: str, bodies, coordinates) -> OsimPathPoint:
    name = p.get("name", "")
    where = f"{owner} path point {name!r}"
    body = _leaf(p.findtext("socket_parent_frame") or p.findtext("body"))
    if body not in bodies and body != "ground":
        raise ValueError(f"{r.source}: {where}: on {body or '(none)'!r}, no body of the model (socket_parent_frame "
                         "names a body: /bodyset/<body>)")
    if p.tag == "MovingPathPoint":
        moving = []
        for k, axis in enumerate("xyz"):
            fn = p.find(f"{axis}_location")
            coord = _leaf(p.findtext(f"socket_{axis}_coordinate") or p.findtext(f"{axis}_coordinate")) or None
            if coord is not None and coord not in coordinates:
                raise ValueError(f"{r.source}: {where}.socket_{axis}_coordinate: {coord!r} is no coordinate of the "
                                 "model")
            moving.append((k, coord, Constant(0.0) if fn is None else r.function(fn, f"{where}.{axis}_location")))
        return OsimPathPoint(name, p.tag, body, np.zeros(3), moving=tuple(moving))
    loc = r.vector(p, "location", 3, where)
    if p.tag != "ConditionalPathPoint":
        return OsimPathPoint(name, p.tag, body, loc)
    coord = _leaf(p.findtext("socket_coordinate") or p.findtext("coordinate"))
    if coord not in coordinates:
        raise ValueError(f"{r.source}: {where}.socket_coordinate: {coord or '(none)'!r} is no coordinate of the model")
    lo, hi = (float(v) for v in r.vector(p, "range", 2, where))
    if hi < lo:
        raise ValueError(f"{r.source}: {where}.range: its upper end {hi:g} is below its lower end {lo:g}; write it "
                         "lower then upper")
    return OsimPathPoint(name, p.tag, body, loc, condition=(coord, lo, hi))


def _muscle(r, m, bodies, coordinates) -> OsimMuscle:
    name = m.get("name", "")
    owner = f"ForceSet: {m.tag} {name!r}"
    numbers, props = _numbers(r, m, owner)
    gp = m.find("GeometryPath")
    pts = [] if gp is None else [p for p in gp.findall("PathPointSet/objects/*")]
    path = tuple(_point(r, p, owner, bodies, coordinates) for p in pts)
    r.unique(f"{owner}.GeometryPath", "path point", (p.name for p in path))
    if len(path) < 2:
        raise ValueError(f"{r.source}: {owner}.GeometryPath: {len(path)} path point(s); a muscle's path needs two "
                         "or more (origin and insertion)")
    wraps = []
    for w in [] if gp is None else gp.findall("PathWrapSet/objects/PathWrap"):
        obj = (w.findtext("wrap_object") or "").strip()
        rng = r.vector(w, "range", 2, f"{owner} wrap {w.get('name', '')!r}", np.array([-1.0, -1.0]))
        wraps.append((obj, (int(rng[0]), int(rng[1]))))
    return OsimMuscle(name, m.tag, numbers, props, path, tuple(wraps))


def read_muscles(r, bodies, coordinates) -> tuple[OsimMuscle, ...]:
    """The muscles of :data:`MUSCLE_KINDS` in the ForceSet of the model that ``r`` (:class:`casflex.scene.osim.
    _Reader`) reads; ``bodies`` and ``coordinates`` the model's names (module docstring's refusals)."""
    objs = r.model.find("ForceSet/objects")
    return tuple(_muscle(r, m, bodies, coordinates) for m in (objs if objs is not None else ()) if m.tag in
                 MUSCLE_KINDS)


def read_wrap_objects(r, rotation) -> dict[str, OsimWrapObject]:
    """The wrap objects of the bodies' and the ground's WrapObjectSets, by name; ``rotation`` the X-Y-Z
    body-fixed rotation of :mod:`casflex.scene.osim`."""
    out: dict[str, OsimWrapObject] = {}
    holders = [(b.get("name", ""), b) for b in r.model.findall("BodySet/objects/Body")]
    holders += [("ground", g) for g in r.model.findall("Ground")]
    for body, b in holders:
        for w in b.findall("WrapObjectSet/objects/*"):
            name = w.get("name", "")
            owner = f"body {body!r} wrap object {name!r}"
            zero = np.zeros(3)
            cylinder = w.tag == "WrapCylinder"
            radius = r.number(w, "radius", owner, 1.0 if cylinder else math.nan)
            length = r.number(w, "length", owner, 1.0) if cylinder else math.nan
            quadrant = (w.findtext("quadrant") or "all").strip()
            if quadrant not in QUADRANTS:
                raise ValueError(f"{r.source}: {owner}.quadrant: {quadrant!r} is none of OpenSim's (all, +x, -x, +y, "
                                 "-y, +z, -z)")
            if cylinder and not (radius > 0 and length > 0):
                raise ValueError(f"{r.source}: {owner}: radius {radius:g} m, length {length:g} m: both must be > 0")
            out[name] = OsimWrapObject(name, w.tag, body, rotation(r.vector(w, "xyz_body_rotation", 3, owner, zero)),
                                       r.vector(w, "translation", 3, owner, zero), quadrant,
                                       (w.findtext("active") or "true").strip().lower() != "false", radius, length)
    return out
