"""OpenSim's actuators read from a model's ForceSet or an actuator file (a ForceSet document, e.g. a
pipeline's ``*_Reserve_Actuators.xml``): the reserve and residual actuators static optimization adds to the
muscles. Pure data; what each does along the scene's coordinates is :mod:`casflex.muscles.actuators`'s.

Read (:func:`read_actuators`) and written (:func:`write_actuators`, e.g. a study's reserves):
``CoordinateActuator`` (a generalised force on one coordinate), ``PointActuator`` (a force at a point
of a body) and ``TorqueActuator`` (a torque on one body and its opposite on another), each with its
``optimal_force`` and control bounds; one the file disables (``isDisabled`` true, ``appliesForce`` false)
is left out. Any other actuator (a muscle is not one here: :mod:`casflex.scene.osim_muscles` reads those)
is refused by name: static optimization would otherwise solve without a force OpenSim's tool applies.
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass

__all__ = ["ACTUATOR_KINDS", "Actuator", "read_actuators", "write_actuators"]

#: The actuators casflex reads, by their OpenSim class names.
ACTUATOR_KINDS = ("CoordinateActuator", "PointActuator", "TorqueActuator")
#: OpenSim's actuators that casflex does not read (refused by name where a ForceSet holds one).
_OTHER_ACTUATORS = ("ActivationCoordinateActuator", "BodyActuator", "PointToPointActuator", "McKibbenActuator",
                    "ClutchedPathSpring", "PathActuator", "SpringGeneralizedForce")
#: The largest optimal force (N or N m) read: beyond it a number is a typing error, not an actuator.
LARGEST_FORCE = 1e7


@dataclass(frozen=True)
class Actuator:
    """An actuator of an OpenSim ForceSet (module docstring).

    kind : "CoordinateActuator", "PointActuator" or "TorqueActuator"
    optimal_force : N (a force) or N m (a torque, a rotational coordinate's generalised force), > 0: its output
        is control * optimal_force
    min_control, max_control : the control's bounds (may be infinite)
    coordinate : a CoordinateActuator's coordinate (the model's name)
    body : a PointActuator's body, a TorqueActuator's ``bodyA`` (the torque's)
    other : a TorqueActuator's ``bodyB`` (the opposite torque's; "ground" often)
    point : a PointActuator's point (m), in ``body``'s frame or, ``point_is_global``, the ground's
    direction : a PointActuator's force direction, in ``body``'s frame or, ``force_is_global``, the ground's
    axis : a TorqueActuator's axis, in ``body``'s frame or, ``torque_is_global``, the ground's
    """

    name: str
    kind: str
    optimal_force: float
    min_control: float = -math.inf
    max_control: float = math.inf
    coordinate: str | None = None
    body: str | None = None
    other: str | None = None
    point: tuple[float, float, float] = (0.0, 0.0, 0.0)
    point_is_global: bool = False
    direction: tuple[float, float, float] = (1.0, 0.0, 0.0)
    force_is_global: bool = False
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    torque_is_global: bool = True


class _Element:
    """One actuator element of ``source``: its values read with errors that name the file, the actuator and the
    tag."""

    def __init__(self, source: str, el: ET.Element):
        self.source, self.el = source, el
        self.where = f"{el.tag} {el.get('name', '')!r}"

    def fail(self, tag: str, what: str) -> ValueError:
        return ValueError(f"{self.source}: {self.where}: {tag}: {what}")

    def text(self, tag: str) -> str | None:
        found = self.el.findall(tag)
        if len(found) > 1:  # which one counts would be a guess (OpenSim reads the first without a word)
            raise self.fail(tag, f"given {len(found)} times; give it once")
        node = found[0] if found else None
        return None if node is None or node.text is None else node.text.strip()

    def numbers(self, tag: str, n: int, default: tuple[float, ...]) -> tuple[float, ...]:
        text = self.text(tag)
        if text is None:
            return default
        try:
            v = tuple(float(s) for s in text.split())
        except ValueError:
            v = ()
        if len(v) != n or any(math.isnan(x) for x in v) or (n > 1 and not all(math.isfinite(x) for x in v)):
            raise self.fail(tag, f"expected {n} {'finite ' if n > 1 else ''}number{'s' if n > 1 else ''}, got "
                                 f"{text[:60]!r}")
        return v

    def flag(self, tag: str, default: bool) -> bool:
        text = self.text(tag)
        if text is None:
            return default
        if text.lower() not in ("true", "false", "1", "0"):
            raise self.fail(tag, f"expected true or false, got {text[:60]!r}")
        return text.lower() in ("true", "1")

    def name_of(self, *tags: str) -> str | None:
        """The body or coordinate a property (OpenSim 3) or socket (OpenSim 4: a path, its last part) names."""
        for tag in tags:
            text = self.text(tag)
            if text:
                return text.rstrip("/").rsplit("/", 1)[-1]
        return None


def _actuator(source: str, el: ET.Element) -> Actuator | None:
    """The actuator of ``el`` (None where the file disables it)."""
    e = _Element(source, el)
    if e.flag("isDisabled", False) or not e.flag("appliesForce", True):
        return None
    (force,) = e.numbers("optimal_force", 1, (1.0,))
    if not (0.0 < force <= LARGEST_FORCE):
        raise e.fail("optimal_force", f"must be > 0 and at most {LARGEST_FORCE:g} (N or N m), got {force:g}")
    (lo,), (hi,) = e.numbers("min_control", 1, (-math.inf,)), e.numbers("max_control", 1, (math.inf,))
    if not lo <= hi:
        raise e.fail("min_control", f"{lo:g} is above max_control {hi:g}")
    common = dict(name=el.get("name", ""), kind=el.tag, optimal_force=force, min_control=lo, max_control=hi)
    if el.tag == "CoordinateActuator":
        coordinate = e.name_of("coordinate", "socket_coordinate")
        if not coordinate:
            raise e.fail("coordinate", "names no coordinate; give the coordinate the actuator drives")
        return Actuator(coordinate=coordinate, **common)
    if el.tag == "PointActuator":
        body = e.name_of("body", "socket_body")
        if not body:
            raise e.fail("body", "names no body; give the body the force acts on")
        direction = e.numbers("direction", 3, (1.0, 0.0, 0.0))
        if not any(direction):
            raise e.fail("direction", "is zero; give the force's direction")
        return Actuator(body=body, point=e.numbers("point", 3, (0.0, 0.0, 0.0)),
                        point_is_global=e.flag("point_is_global", False), direction=direction,
                        force_is_global=e.flag("force_is_global", False), **common)
    body, other = e.name_of("bodyA", "socket_bodyA"), e.name_of("bodyB", "socket_bodyB")
    if not body:
        raise e.fail("bodyA", "names no body; give the body the torque acts on")
    axis = e.numbers("axis", 3, (0.0, 0.0, 1.0))
    if not any(axis):
        raise e.fail("axis", "is zero; give the torque's axis")
    return Actuator(body=body, other=other or "ground", axis=axis, torque_is_global=e.flag("torque_is_global", True),
                    **common)


def read_actuators(path: str | os.PathLike[str]) -> tuple[Actuator, ...]:
    """The actuators of an OpenSim model (its ForceSet) or actuator file (a ForceSet document), in file order.
    ValueError in one line naming the file, the actuator and the tag for what cannot be read (module
    docstring); muscles and non-actuator forces are skipped (read elsewhere)."""
    source = os.fspath(path)
    try:
        root = ET.parse(source).getroot()
    except ET.ParseError as exc:
        raise ValueError(f"{source}: not an OpenSim actuator file (XML: {exc})") from None
    except OSError as exc:
        raise ValueError(f"{source}: cannot read it ({exc.strerror or exc})") from None
    sets = [root] if root.tag == "ForceSet" else root.findall(".//ForceSet")
    if not sets:
        raise ValueError(f"{source}: no <ForceSet>: not an OpenSim model or actuator file")
    out: list[Actuator] = []
    for forces in sets:
        holder = forces.find("objects")
        for el in (holder if holder is not None else forces):
            if el.tag in _OTHER_ACTUATORS:
                raise ValueError(f"{source}: {el.tag} {el.get('name', '')!r}: not read by casflex (CoordinateActuator, "
                                 "PointActuator and TorqueActuator are); static optimization would solve without "
                                 "it: remove it or replace it by one of those")
            if el.tag in ACTUATOR_KINDS:
                a = _actuator(source, el)
                if a is not None:
                    out.append(a)
    names = [a.name for a in out]
    twice = next((n for n in names if names.count(n) > 1), None)
    if twice is not None:
        raise ValueError(f"{source}: two actuators named {twice!r}; give each its own name")
    return tuple(out)


def _number(v: float) -> str:
    return "Inf" if v == math.inf else "-Inf" if v == -math.inf else f"{v:.17g}"


def write_actuators(path: str | os.PathLike[str], actuators, name: str = "actuators") -> str:
    """Write ``path``: an OpenSim actuator file (a ForceSet document, as OpenSim 4 writes one) holding
    ``actuators`` (:class:`Actuator`), which OpenSim's tools append to a model's forces and :func:`read_actuators`
    reads back as they are. Needs no OpenSim; returns the path."""
    root = ET.Element("OpenSimDocument", Version="40000")
    objects = ET.SubElement(ET.SubElement(root, "ForceSet", name=name), "objects")
    for a in actuators:
        if a.kind not in ACTUATOR_KINDS:
            raise ValueError(f"actuators: {a.name!r}: kind {a.kind!r}; one of {', '.join(ACTUATOR_KINDS)}")
        el = ET.SubElement(objects, a.kind, name=a.name)
        fields = [("min_control", _number(a.min_control)), ("max_control", _number(a.max_control))]
        if a.kind == "CoordinateActuator":
            fields.append(("coordinate", a.coordinate))
        elif a.kind == "PointActuator":
            fields += [("body", a.body), ("point", " ".join(map(_number, a.point))),
                       ("point_is_global", str(a.point_is_global).lower()),
                       ("direction", " ".join(map(_number, a.direction))),
                       ("force_is_global", str(a.force_is_global).lower())]
        else:
            fields += [("bodyA", a.body), ("bodyB", a.other or "ground"),
                       ("torque_is_global", str(a.torque_is_global).lower()), ("axis", " ".join(map(_number, a.axis)))]
        for tag, text in (*fields, ("optimal_force", _number(a.optimal_force))):
            ET.SubElement(el, tag).text = text
    ET.indent(root, space="\t")
    ET.ElementTree(root).write(os.fspath(path), encoding="UTF-8", xml_declaration=True)
    return os.fspath(path)
