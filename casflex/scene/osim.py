"""OpenSim model files (``.osim``, format 4.x) read into plain data: bodies, joints with their
coordinates and transforms, markers, and what else the model holds (forces, constraints), for
:mod:`casflex.scene.from_osim` to make a planar scene of. The XML is read directly: the lab path
does not need the ``opensim`` package.

Conventions (OpenSim's): lengths in m, angles in rad, a frame's ``orientation`` an X-Y-Z body-fixed
rotation sequence; a joint places its child frame M in its parent frame F by the SpatialTransform
X_FM(q): the rotations (body-fixed, in order) then the translations along their axes in F. A PinJoint
turns about F's z axis; a WeldJoint locks M to F; a UniversalJoint turns about F's x then the new y, a
GimbalJoint and a BallJoint about x, y, z (body-fixed: R_FM = Rx(q1) Ry(q2) Rz(q3), OpenSim's coordinates of a
BallJoint too; checked against OpenSim 4.6, the other orders centimetres off it: tests/test_osim_3d_joints.py).
An EllipsoidJoint is refused: its M's origin moves on an ellipsoid in F as it turns (Seth et al. 2010), a
translation that follows several coordinates at once, which a transform axis (one coordinate's function) does not.
"""

from __future__ import annotations

import math
import os
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import numpy as np

from casflex.scene.functions import Constant, Function, Linear, Multiplier, Polynomial, SimmSpline
from casflex.scene.osim_muscles import OsimMuscle, OsimWrapObject, read_muscles, read_wrap_objects

__all__ = ["OsimBody", "OsimConstraint", "OsimCoordinate", "OsimJoint", "OsimMarker", "OsimModel", "read_osim",
           "rotation"]


@dataclass(frozen=True)
class OsimCoordinate:
    name: str
    default: float
    range: tuple[float, float]
    locked: bool
    clamped: bool = False  # kept in its range (OpenSim's IK bounds it there)


@dataclass(frozen=True)
class Axis:
    """One TransformAxis of a SpatialTransform: ``rotation`` or not, its axis (3,) in F (rotations: in the
    frame the earlier rotations left), the coordinate it follows (None: constant) and its function."""

    rotation: bool
    axis: np.ndarray
    coordinate: str | None
    function: Function


@dataclass(frozen=True)
class OsimJoint:
    """A joint: its kind (``PinJoint``, ``WeldJoint``, ``CustomJoint``, ...), parent and child bodies
    (``ground`` for the ground), the offset frames (rotation (3, 3), translation (3,)) of F in the parent
    and M in the child, its coordinates and (CustomJoint, PinJoint) its transform axes."""

    name: str
    kind: str
    parent: str
    child: str
    parent_offset: tuple[np.ndarray, np.ndarray]
    child_offset: tuple[np.ndarray, np.ndarray]
    coordinates: tuple[OsimCoordinate, ...]
    axes: tuple[Axis, ...]


@dataclass(frozen=True)
class OsimBody:
    name: str
    mass: float
    com: np.ndarray
    inertia: np.ndarray  # (3, 3) about the centre of mass, in the body's frame


@dataclass(frozen=True)
class OsimMarker:
    name: str
    body: str
    location: np.ndarray
    fixed: bool = False  # <fixed>true</fixed>: OpenSim's marker placer leaves it where it is


@dataclass(frozen=True)
class OsimConstraint:
    """A constraint of the model's ConstraintSet: its ``kind`` (``CoordinateCouplerConstraint``, ``WeldConstraint``,
    ``PointConstraint``, ...), ``name``, whether the model ``enforced`` it, a coupler's ``dependent`` coordinate
    and its ``independent`` ones, and the ``bodies`` a loop-closing constraint joins (its sockets' bodies,
    ``ground`` for the ground; None where a socket names no body of the model)."""

    kind: str
    name: str
    enforced: bool
    dependent: str | None = None
    independent: tuple[str, ...] = ()
    bodies: tuple[str | None, ...] = ()


@dataclass(frozen=True)
class OsimModel:
    """An OpenSim model's parts (module docstring); ``others``: what casflex does not take (forces,
    constraints, contact geometry, probes, controllers), as ``(set, type, name)``."""

    name: str
    source: str
    gravity: np.ndarray
    bodies: dict[str, OsimBody]
    joints: tuple[OsimJoint, ...]
    markers: tuple[OsimMarker, ...]
    others: tuple[tuple[str, str, str], ...] = field(default=())
    constraints: tuple[OsimConstraint, ...] = field(default=())
    #: the ForceSet's muscles casflex computes and the wrap objects (:mod:`casflex.scene.osim_muscles`)
    muscles: tuple[OsimMuscle, ...] = field(default=())
    wrap_objects: dict[str, OsimWrapObject] = field(default_factory=dict)


#: The joints that turn F by body-fixed rotations about its x, y (and z) axes, one coordinate each, and how many.
#: Read as a CustomJoint of those rotations: a rotation about the plane's normal is a hinge, the others are
#: held at their default values (:mod:`casflex.scene.from_osim`).
_EULER = {"UniversalJoint": 2, "GimbalJoint": 3, "BallJoint": 3}
#: A SpatialTransform's axes: three rotations (body-fixed, in this order), then three translations.
_AXES = ("rotation1", "rotation2", "rotation3", "translation1", "translation2", "translation3")
#: A 3.x-style constraint's elements that name its bodies (4.x names them in ``socket_*`` elements).
_BODY_TAGS = ("body_1", "body_2")


#: The most bodies a model may have: a whole-body OpenSim model has 20-100 (Rajagopal's 22, a thoracolumbar
#: spine's some 100); the kinematic tree and the marker fit's Jacobian grow with the square of the chain
#: (a 200-body chain: 2 s and 80 MB to build, a 1000-body one ran a 4 GB process out of memory).
MAX_BODIES = 300
#: The largest model file read (bytes): the XML tree takes some ten times the file in memory.
MAX_FILE_BYTES = 256 * 2**20
#: The largest magnitude a number of a model file may have (m, kg, kg m^2, rad): a body 1e9 m long or heavy is a
#: corrupted file (a coordinate's range that means "unbounded" is written 1e5 or less by OpenSim's models), and
#: the products of such numbers (an inertia moved by the parallel-axis theorem) stay finite.
LARGEST = 1e9


def _short(text: str | None) -> str:
    """``text`` quoted for an error line, cut to 60 characters."""
    t = " ".join((text or "").split())
    return repr(t if len(t) <= 60 else t[:57] + "...")


def rotation(angles) -> np.ndarray:
    """The rotation matrix (3, 3) of X-Y-Z body-fixed angles (rad): Rx Ry Rz."""
    R = np.eye(3)
    for k, a in enumerate(angles):
        R = R @ axis_rotation(np.eye(3)[k], a)
    return R


def axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """The rotation (3, 3) by ``angle`` (rad) about the unit vector ``axis`` (Rodrigues)."""
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


#: an element named as OpenSim names a property of a base class (``<HuntCrossleyForce::ContactParametersSet>``): no
#: XML name, which OpenSim reads and writes (its ToyLanding, WalkerModel, SoccerKick and Jumper models)
_QUALIFIED_TAG = re.compile(r"<(/?)([A-Za-z_][\w.-]*)::([A-Za-z_][\w.-]*)")


def _with_qualified_tags(source: str, exc: ET.ParseError):
    """The root of the model file ``source`` that ET could not parse (``exc``), its elements named ``A::B`` read as
    ``A__B`` (OpenSim's own names: nothing casflex takes); ValueError naming the XML's fault where that is not it."""
    try:
        with open(source, encoding="utf-8") as fh:
            text = fh.read()
        if _QUALIFIED_TAG.search(text):
            return ET.fromstring(_QUALIFIED_TAG.sub(r"<\1\2__\3", text))
    except ET.ParseError as other:  # the file's own fault beside those names (its line and column unchanged)
        exc = other
    except (UnicodeDecodeError, OSError):
        pass
    raise ValueError(f"{source}: not an OpenSim model (XML: {exc})") from None


class _Reader:
    def __init__(self, path: str):
        self.source = os.fspath(path)
        try:
            size = os.path.getsize(self.source)
        except OSError:
            size = 0  # ET.parse names the reason below
        if size > MAX_FILE_BYTES:
            raise ValueError(f"{self.source}: {size / 2**20:.0f} MiB; casflex reads model files of up to "
                             f"{MAX_FILE_BYTES / 2**20:.0f} MiB (a whole-body model with its muscles is a few MiB)")
        try:
            root = ET.parse(self.source).getroot()
        except ET.ParseError as exc:
            root = _with_qualified_tags(self.source, exc)
        except OSError as exc:
            raise ValueError(f"{self.source}: cannot read it ({exc.strerror or exc})") from None
        self.joint_frames: dict[str, dict] = {}  # joint name -> its offset frames (:meth:`frames`)
        version = root.get("Version", "")
        self.model = root.find("Model")
        if root.tag != "OpenSimDocument" or self.model is None:
            raise ValueError(f"{self.source}: not an OpenSim model (no <OpenSimDocument><Model>)")
        if not version.isdigit() or int(version) < 40000:
            raise ValueError(f"{self.source}: an OpenSim model of format {version or '?'}; casflex reads format 4.x "
                             "(40000 and later): open and save it once in OpenSim 4 to update it")

    def unique(self, where: str, kind: str, names) -> None:
        """ValueError naming the first name that two of ``names`` share: the second part would replace the first
        (casflex keys the parts by name) or be taken for it, as OpenSim refuses such a model."""
        seen: set[str] = set()
        for n in names:
            if not n.strip():
                raise ValueError(f"{self.source}: {where}: a {kind} without a name; give it one")
            if n in seen:
                raise ValueError(f"{self.source}: {where}: two {kind}s named {n!r}; give each its own name (one would "
                                 "be taken for the other)")
            seen.add(n)

    def vector(self, el, tag: str, n: int | None, owner: str, default: np.ndarray | None = None) -> np.ndarray:
        """The numbers of ``el``'s element ``tag``: ``n`` of them (None: any number, at least one), each finite
        and of a magnitude up to :data:`LARGEST`; ValueError naming the file, ``owner`` and the tag otherwise.
        ``default``: the value of an element left out (OpenSim's property default); the element given twice
        refused (which one counts would be a guess: OpenSim reads the first)."""
        node = self.single(el, tag, owner)
        if node is None and default is not None:
            return default
        text = "" if node is None or node.text is None else node.text
        try:
            v = np.array([float(s) for s in text.split()], dtype=float)
        except ValueError:
            v = np.zeros(0)
        if v.size != (n or max(v.size, 1)) or not np.isfinite(v).all():
            count = "one or more" if n is None else n
            raise ValueError(f"{self.source}: {owner}.{tag}: expected {count} numbers, got {_short(text)}")
        if np.abs(v).max() > LARGEST:
            raise ValueError(f"{self.source}: {owner}.{tag}: {_short(text)} holds a number beyond {LARGEST:g}: no "
                             "length (m), mass (kg), inertia or angle of a model is that large")
        return v

    def single(self, el, tag: str, owner: str):
        """``el``'s element ``tag`` (None where left out); ValueError naming it where ``el`` holds two."""
        found = el.findall(tag)
        if len(found) > 1:
            raise ValueError(f"{self.source}: {owner}.{tag}: given {len(found)} times; give it once (which one counts "
                             "would be a guess: OpenSim reads the first without a word)")
        return found[0] if found else None

    def number(self, el, tag: str, owner: str, default: float | None = None) -> float:
        if self.single(el, tag, owner) is None and default is not None:
            return default
        return float(self.vector(el, tag, 1, owner)[0])

    def function(self, el, owner: str) -> Function:
        """The Function element that ``el`` holds (a TransformAxis's, a MultiplierFunction's)."""
        for f in el:
            tag = f.tag
            if tag == "Constant":
                return Constant(self.number(f, "value", owner))
            if tag == "LinearFunction":
                a, b = self.vector(f, "coefficients", 2, owner)
                return Linear(float(a), float(b))
            if tag == "PolynomialFunction":
                return Polynomial(tuple(self.vector(f, "coefficients", None, f"{owner} {tag}").tolist()))
            if tag == "SimmSpline":
                x, y = (self.vector(f, k, None, f"{owner} {tag}").tolist() for k in "xy")
                try:
                    return SimmSpline(tuple(x), tuple(y))
                except ValueError as exc:
                    raise ValueError(f"{self.source}: {owner}: {exc}") from None
            if tag == "MultiplierFunction":
                inner = f.find("function")
                return Multiplier(self.function(f if inner is None else inner, owner),
                                  self.number(f, "scale", owner, 1.0))
            if tag in ("NaturalCubicSpline", "GCVSpline", "PiecewiseLinearFunction", "PiecewiseConstantFunction",
                       "StepFunction", "Sine", "FunctionAdapter"):
                raise ValueError(f"{self.source}: {owner}: a {tag} is not read by casflex yet (Constant, "
                                 "LinearFunction, PolynomialFunction, SimmSpline and MultiplierFunction are)")
        return Constant(0.0)

    def bodies(self) -> dict[str, OsimBody]:
        out = {}
        found = self.model.findall("BodySet/objects/Body")
        if len(found) > MAX_BODIES:
            raise ValueError(f"{self.source}: BodySet: {len(found):,} bodies; casflex reads models of up to "
                             f"{MAX_BODIES} (its inverse's cost grows with their square; a whole-body OpenSim model "
                             "has some 20-100)")
        for b in found:
            name = b.get("name", "")
            owner = f"body {name!r}"
            mass = self.number(b, "mass", owner, 0.0)
            com = self.vector(b, "mass_center", 3, owner) if b.find("mass_center") is not None else np.zeros(3)
            i6 = self.vector(b, "inertia", 6, owner) if b.find("inertia") is not None else np.zeros(6)
            xx, yy, zz, xy, xz, yz = i6
            inertia = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
            if mass < 0:
                raise ValueError(f"{self.source}: {owner}.mass: must be >= 0, got {mass:g}")
            eig = np.linalg.eigvalsh(inertia)
            if eig[0] < -1e-9 * max(eig[-1], 0.0):  # a moment about some axis < 0: the plane's could be too
                raise ValueError(f"{self.source}: {owner}.inertia: {' '.join(f'{v:g}' for v in i6)} is no body's "
                                 f"inertia (principal moments {' '.join(f'{v:.4g}' for v in eig)} kg m^2: each must "
                                 "be >= 0)")
            if not name.strip():
                raise ValueError(f"{self.source}: BodySet: a body without a name; give it one")
            if name in out or name == "ground":
                what = "a body named 'ground', the ground's name" if name == "ground" else f"two bodies named {name!r}"
                raise ValueError(f"{self.source}: BodySet: {what}; give each its own name (the second would replace "
                                 "the first)")
            out[name] = OsimBody(name, mass, com, inertia)
        return out

    def frames(self, j, jname: str) -> dict[str, tuple[str, np.ndarray, np.ndarray]]:
        """The joint's offset frames: name -> (body, rotation, translation)."""
        out: dict[str, tuple[str, np.ndarray, np.ndarray]] = {}
        self.joint_frames[jname] = out
        for f in j.findall("frames/PhysicalOffsetFrame"):
            owner = f"joint {jname!r} frame {f.get('name')!r}"
            body = (f.findtext("socket_parent") or "").strip().rsplit("/", 1)[-1]
            zero = np.zeros(3)  # OpenSim's default of a frame's orientation and translation left out
            out[f.get("name", "")] = (body, rotation(self.vector(f, "orientation", 3, owner, zero)),
                                      self.vector(f, "translation", 3, owner, zero))
        return out

    def frame(self, frames, socket: str, jname: str) -> tuple[str, tuple[np.ndarray, np.ndarray]]:
        """(body, (rotation, translation)) of a joint's socket: an offset frame, a body or the ground."""
        path = socket.strip()
        leaf = path.rsplit("/", 1)[-1]
        if leaf in frames:
            body, R, p = frames[leaf]
            return body, (R, p)
        return leaf, (np.eye(3), np.zeros(3))

    def coordinates(self, j, owner: str) -> tuple[OsimCoordinate, ...]:
        out = []
        for c in j.findall("coordinates/Coordinate"):
            cname = c.get("name", "")
            where = f"{owner} coordinate {cname!r}"
            locked, clamped = ((c.findtext(tag) or "false").strip().lower() == "true" for tag in ("locked", "clamped"))
            rng = self.range(c, where, clamped)
            out.append(OsimCoordinate(cname, self.number(c, "default_value", where, 0.0), rng, locked, clamped))
        return tuple(out)

    def range(self, c, where: str, clamped: bool) -> tuple[float, float]:
        """A coordinate's range (lower, upper): refused reversed (its clamp, or OpenSim's IK bounds, would be lost
        without a word) or missing on a clamped coordinate (kept in no range); (-inf, inf) when an unclamped
        coordinate has none."""
        if c.find("range") is None:
            if clamped:
                raise ValueError(f"{self.source}: {where}: clamped, but it has no <range>: give its range (lower "
                                 "upper, rad or m) or set <clamped>false</clamped>")
            return -math.inf, math.inf
        lo, hi = (float(v) for v in self.vector(c, "range", 2, where))
        if hi < lo or (clamped and hi == lo):
            raise ValueError(f"{self.source}: {where}.range: its upper end {hi:g} is "
                             f"{'below' if hi < lo else 'at'} its lower end {lo:g}; write it lower then upper"
                             + (" (a coordinate held at one value: <locked>true</locked>)" if hi == lo else ""))
        return lo, hi

    def axes(self, j, kind: str, coords: tuple[OsimCoordinate, ...], owner: str) -> tuple[Axis, ...]:
        if kind == "PinJoint":
            return (Axis(True, np.array([0.0, 0.0, 1.0]), coords[0].name if coords else None, Linear(1.0)),)
        if kind == "SliderJoint":
            return (Axis(False, np.array([1.0, 0.0, 0.0]), coords[0].name if coords else None, Linear(1.0)),)
        if kind in _EULER:  # body-fixed X-Y(-Z) rotations of F (OpenSim 4.6's: tests/test_osim_3d_joints.py)
            names = [c.name for c in coords]
            return tuple(Axis(True, np.eye(3)[k], names[k] if k < len(names) else None, Linear(1.0))
                         for k in range(_EULER[kind]))
        if kind == "PlanarJoint":
            names = [c.name for c in coords]
            e = np.eye(3)
            return (Axis(True, e[2], names[0], Linear(1.0)), Axis(False, e[0], names[1], Linear(1.0)),
                    Axis(False, e[1], names[2], Linear(1.0)))
        out = []
        tas = j.findall("SpatialTransform/TransformAxis")
        names = [ta.get("name", "") for ta in tas]
        odd = [n for n in names if n not in _AXES]
        if odd:
            raise ValueError(f"{self.source}: {owner} SpatialTransform: a TransformAxis named {odd[0]!r}; OpenSim's "
                             f"are {', '.join(_AXES)}")
        self.unique(f"{owner} SpatialTransform", "TransformAxis element", names)
        for ta in sorted(tas, key=lambda ta: _AXES.index(ta.get("name"))):  # OpenSim's order, whatever the file's
            name = ta.get("name", "")
            c = (ta.findtext("coordinates") or "").split()
            if len(c) > 1:
                raise ValueError(f"{self.source}: {owner} {name}: a function of {len(c)} coordinates; casflex takes "
                                 "functions of one")
            if c and c[0] not in {k.name for k in coords}:
                raise ValueError(f"{self.source}: {owner} {name}.coordinates: {c[0]!r} is no coordinate of the joint "
                                 f"(its coordinates: {[k.name for k in coords]})")
            axis = self.vector(ta, "axis", 3, f"{owner} {name}")
            if np.linalg.norm(axis) < 1e-9:  # OpenSim normalises the axis: one of length 0 has no direction
                raise ValueError(f"{self.source}: {owner} {name}.axis: {' '.join(f'{v:g}' for v in axis)} has no "
                                 "direction (length 0); give the axis's direction")
            out.append(Axis(name.startswith("rotation"), axis, c[0] if c else None,
                            self.function(ta, f"{owner} {name}")))
        return tuple(out)

    def joints(self) -> tuple[OsimJoint, ...]:
        out = []
        for j in self.model.find("JointSet/objects") if self.model.find("JointSet/objects") is not None else ():
            kind, name = j.tag, j.get("name", "")
            owner = f"joint {name!r}"
            if kind not in ("PinJoint", "WeldJoint", "CustomJoint", "PlanarJoint", "SliderJoint", *_EULER):
                raise ValueError(f"{self.source}: {owner}: a {kind} is not read by casflex (PinJoint, WeldJoint, "
                                 "CustomJoint, PlanarJoint, SliderJoint, UniversalJoint, GimbalJoint and BallJoint "
                                 "are)")
            frames = self.frames(j, name)
            parent, po = self.frame(frames, j.findtext("socket_parent_frame") or "", name)
            child, co = self.frame(frames, j.findtext("socket_child_frame") or "", name)
            coords = self.coordinates(j, owner)
            out.append(OsimJoint(name, kind, parent, child, po, co, coords, self.axes(j, kind, coords, owner)))
        self.unique("JointSet", "joint", (j.name for j in out))
        self.unique("coordinates", "coordinate", (c.name for j in out for c in j.coordinates))
        return tuple(out)

    def markers(self) -> tuple[OsimMarker, ...]:
        out = []
        bodies = {b.get("name", "") for b in self.model.findall("BodySet/objects/Body")}
        for m in self.model.findall("MarkerSet/objects/Marker"):
            name = m.get("name", "")
            frame = (m.findtext("socket_parent_frame") or "").strip()
            body = frame.rsplit("/", 1)[-1]
            if frame.rpartition("/")[0].endswith("bodyset") and body not in bodies:  # was left out of the fit, unsaid
                raise ValueError(f"{self.source}: MarkerSet: marker {name!r} is on {frame!r}, a body the model does "
                                 "not have: fix its socket_parent_frame (OpenSim refuses such a model)")
            out.append(OsimMarker(name, body, self.vector(m, "location", 3, f"marker {name!r}"),
                                  (m.findtext("fixed") or "").strip().lower() == "true"))
        self.unique("MarkerSet", "marker", (m.name for m in out))
        return tuple(out)

    def others(self) -> tuple[tuple[str, str, str], ...]:
        out = []
        for s in ("ForceSet", "ConstraintSet", "ControllerSet", "ContactGeometrySet", "ProbeSet", "ComponentSet"):
            objs = self.model.find(f"{s}/objects")
            mine = [(s, o.tag, o.get("name", "")) for o in (objs if objs is not None else ())]
            self.unique(s, f"{s[:-3].lower()} element", (n for _, _, n in mine if n))
            out += mine
        return tuple(out)


    def constraints(self, bodies) -> tuple[OsimConstraint, ...]:
        """The ConstraintSet's constraints (:class:`OsimConstraint`), after :meth:`joints` (their frames)."""
        objs = self.model.find("ConstraintSet/objects")
        out = []
        for c in objs if objs is not None else ():
            enforced = (c.findtext("isEnforced") or "true").strip().lower() != "false" and (
                c.findtext("isDisabled") or "false").strip().lower() != "true"
            own = {f.get("name", ""): (f.findtext("socket_parent") or "").strip() for f in c.findall(
                "frames/PhysicalOffsetFrame")}
            sockets = [(e.text or "").strip() for e in c if e.tag.startswith("socket_") or e.tag in _BODY_TAGS]
            out.append(OsimConstraint(c.tag, c.get("name", ""), enforced,
                                      (c.findtext("dependent_coordinate_name") or "").strip() or None,
                                      tuple((c.findtext("independent_coordinate_names") or "").split()),
                                      tuple(self.socket_body(own.get(s.rsplit("/", 1)[-1], s), bodies)
                                            for s in sockets if s)))
        return tuple(out)

    def socket_body(self, path: str, bodies) -> str | None:
        """The body (or ``ground``) a socket's path names: a body, the ground, a joint's offset frame; else None."""
        parts = [p for p in path.split("/") if p]
        if len(parts) >= 2 and parts[-2] in self.joint_frames and parts[-1] in self.joint_frames[parts[-2]]:
            return self.joint_frames[parts[-2]][parts[-1]][0]
        leaf = parts[-1] if parts else ""
        return leaf if leaf in bodies or leaf == "ground" else None


def read_osim(path: str | os.PathLike[str], *, muscles: bool = False) -> OsimModel:
    """The parts of the OpenSim model file ``path`` (module docstring). ValueError in one line naming the
    file and the element for a file that is no OpenSim 4 model, or a part casflex cannot read. ``muscles``: its
    muscles and wrap objects read too (:mod:`casflex.scene.osim_muscles`; a bad muscle refused); else they are
    listed with the other forces as not taken (inverse dynamics does not use them)."""
    r = _Reader(path)
    g = r.vector(r.model, "gravity", 3, "model") if r.model.find("gravity") is not None else np.array([0, -9.80665, 0])
    bodies, joints = r.bodies(), r.joints()
    coordinates = {c.name for j in joints for c in j.coordinates}
    return OsimModel(r.model.get("name", os.path.basename(r.source)), r.source, g, bodies, joints, r.markers(),
                     r.others(), r.constraints(bodies), read_muscles(r, bodies, coordinates) if muscles else (),
                     read_wrap_objects(r, rotation) if muscles else {})
