"""A planar casflex scene made of an OpenSim model (:mod:`casflex.scene.osim`), with a report of what was
kept, projected and dropped.

The plane is the model's x-y plane (OpenSim's sagittal plane: x forward, y up, z to the right); the
scene's initial configuration is the model's default pose. Each body becomes a node at the origin of its
joint's child frame (the joint centre) and a rigid body (mass, centre of mass in the plane, moment of
inertia about the plane's normal through the centre of mass); each joint a hinge, a weld or the free root:

- a rotation about the plane's normal with a coordinate (a PinJoint's, a CustomJoint's) is a hinge, its
  coordinate a ``[[coordinates]]`` entry (``knee_angle_r`` of ``knee_r``, its default value and sign);
- a coordinate the file clamps keeps its range as its ``limits``: the marker fit keeps it there, as
  OpenSim's IK does (a knee that the markers would hyperextend held at full extension);
- the joint to the ground gives the scene's root: its rotation about the normal and its translations
  along x and y are the root's coordinates (``pelvis_tilt``, ``pelvis_tx``, ``pelvis_ty``);
- a joint with no such rotation is a weld; so is one whose coordinate the model file locks (OpenSim holds a
  locked coordinate at its default value in its tools); a UniversalJoint, GimbalJoint or BallJoint is read
  as its body-fixed rotations about F's x, y (and z), as a CustomJoint's (a wrist's, a shoulder's): a weld at
  the pose of its coordinates' default values, each held coordinate reported with its value, unless one of
  its rotations turns about the normal there (a hinge; the others held);
- what cannot move in the plane is projected and reported: a coordinate that turns about another axis
  or translates out of the plane is locked at its default value, a rotation or translation that follows
  the hinge's coordinate about or along something else is held at its default value (its reach over the
  coordinate's range said);
- a translation along x or y of the plane that follows the hinge's coordinate (a knee's rolling, a SIMM
  spline or linear function of the knee angle) makes the hinge a coupled one (``shift_x``, ``shift_y``:
  :class:`casflex.scene.Joint`), the spline's knots carried over exactly;
- markers are projected on the plane; forces (muscles, actuators), contact geometry, controllers and probes
  are listed as ignored; a constraint is refused where the scene would break it (a coupler whose dependent
  coordinate the scene moves, a loop closed between bodies it moves relative to each other), else ignored with
  a warning (``warnings``: OpenSim's tools keep it).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from casflex.scene.coordinates import Coordinate
from casflex.scene.functions import Clamped, Linear, Multiplier, SimmSpline
from casflex.scene.items import node_name
from casflex.scene.markers import Marker
from casflex.scene.muscles import Muscle, PathPoint, Wrap
from casflex.scene.osim import OsimJoint, OsimModel, axis_rotation, read_osim
from casflex.scene.scene import Joint, Node, RigidBody, Scene

__all__ = ["OsimScene", "node_name", "scene_from_osim"]

#: |cos| of the angle between an axis and the plane's normal above which the axis is the normal (a
#: thousandth of a degree: OpenSim's files print axes to 1e-16, a hand-written one may round them).
NORMAL = math.cos(math.radians(1e-3))
#: The largest angle (deg) between a joint's rotation axis and the plane's normal that still makes a hinge,
#: the axis projected on the normal and the angle reported: 3D models tilt the ankle's axis 12 degrees
#: (Inman's talocrural axis, Delp 1990) and the lab's sagittal analysis takes it as the flexion axis; an axis
#: farther off turns the segment mostly out of the plane.
PROJECTED = 30.0
#: OpenSim's range of a coordinate whose file gives none (Coordinate's default ``range``): a MovingPathPoint's
#: location is its function of the coordinate's value clamped to the range.
OPENSIM_RANGE = (-10.0, 10.0)


@dataclass(frozen=True)
class OsimScene:
    """The scene of an OpenSim model and the report of what was made of each part (lines)."""

    scene: Scene
    report: tuple[str, ...]
    dropped: tuple[str, ...]
    #: what of the model the scene leaves out that OpenSim's tools would apply (its constraints): a command says
    #: them on stderr (also in ``report``)
    warnings: tuple[str, ...] = ()
    #: the model's muscles (:mod:`casflex.scene.muscles`), their paths on the scene's nodes
    muscles: tuple[Muscle, ...] = ()
    #: each body's frame in the ground at the default pose (the scene's initial configuration): body -> (R (3, 3),
    #: origin p (3,) m); a point at ``location`` in the body's frame is at ``p + R @ location``
    frames: Mapping[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    #: each scene joint's OpenSim bodies and its parent frame's origin: joint -> (parent body, child body, the
    #: origin (3,) m in the ground at the default pose; it moves with the parent; where OpenSim reports a reaction
    #: on the parent)
    joint_frames: Mapping[str, tuple[str, str, np.ndarray]] = field(default_factory=dict)
    #: the model file read ("" where the scene was made otherwise): what a refusal of one of its muscles names
    source: str = ""


class _Builder:
    def __init__(self, model: OsimModel):
        self.m = model
        self.default = {c.name: c.default for j in model.joints for c in j.coordinates}
        self.range = {c.name: c.range for j in model.joints for c in j.coordinates}
        self.locked = {c.name for j in model.joints for c in j.coordinates if c.locked}  # OpenSim holds them
        self.limits = {c.name: c.range for j in model.joints for c in j.coordinates if c.clamped}
        self.pose: dict[str, tuple[np.ndarray, np.ndarray]] = {"ground": (np.eye(3), np.zeros(3))}
        self.nodes: list[Node] = []
        self.joints: list[Joint] = []
        self.coords: list[Coordinate] = []
        self.report: list[str] = []
        self.dropped: list[str] = []
        self.warnings: list[str] = []
        self.moving: set[str] = set()  # the joints the scene moves (hinges, the root's coordinates)
        self.joint_frames: dict[str, tuple[str, str, np.ndarray]] = {}  # OsimScene.joint_frames

    # -- geometry -------------------------------------------------------------------------
    def transform(self, j: OsimJoint, values: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
        """X_FM (rotation, translation) of the joint at the coordinates' ``values``."""
        R, t = np.eye(3), np.zeros(3)
        for ax in j.axes:
            v = float(ax.function(values[ax.coordinate] if ax.coordinate else 0.0))
            if ax.rotation:
                R = R @ axis_rotation(ax.axis, v)
            else:
                t = t + v * np.asarray(ax.axis, dtype=float) / np.linalg.norm(ax.axis)
        return R, t

    def rotation_axes_in_ground(self, j: OsimJoint, RF: np.ndarray) -> list[np.ndarray]:
        """Each rotation axis of the joint, in the ground at the default pose (body-fixed sequence)."""
        out, R = [], RF
        for ax in j.axes:
            a = np.asarray(ax.axis, dtype=float) / np.linalg.norm(ax.axis)
            out.append(R @ a if ax.rotation else RF @ a)
            if ax.rotation:
                R = R @ axis_rotation(a, float(ax.function(self.default[ax.coordinate] if ax.coordinate else 0.0)))
        return out

    def reach(self, ax, coordinate: str) -> float:
        """How far the axis's function moves over the coordinate's range (m or rad)."""
        lo, hi = self.range.get(coordinate, (-math.pi, math.pi))
        lo, hi = max(lo, -2 * math.pi), min(hi, 2 * math.pi)
        v = np.asarray(ax.function(np.linspace(lo, hi, 201)), dtype=float)
        return float(np.ptp(v))

    # -- joints ---------------------------------------------------------------------------
    def joint(self, j: OsimJoint) -> None:
        RP, pP = self.pose[j.parent]
        RF, pF = RP @ j.parent_offset[0], pP + RP @ j.parent_offset[1]
        R, t = self.transform(j, self.default)
        RM, pM = RF @ R, pF + RF @ t
        RB = RM @ j.child_offset[0].T
        self.pose[j.child] = (RB, pM - RB @ j.child_offset[1])
        theta = math.atan2(RM[1, 0], RM[0, 0])
        child = node_name(j.child)
        self.nodes.append(Node(child, float(pM[0]), float(pM[1]), theta))
        axes_g = self.rotation_axes_in_ground(j, RF)
        hinge = self.hinge(j, axes_g)
        shifts = self.shifts(j, axes_g, hinge) if hinge and j.parent != "ground" else {}
        n_coords = len(self.coords)
        self.classify(j, axes_g, hinge, shifts, root=j.parent == "ground")
        if hinge is not None or len(self.coords) > n_coords:
            self.moving.add(j.name)
        if j.parent == "ground":
            return
        name = node_name(j.name)
        self.joint_frames[name] = (j.parent, j.child, pF)
        if hinge is None:
            self.joints.append(Joint(name, "weld", (node_name(j.parent), child)))
            self.report.append(f"joint {j.name!r} ({j.kind}): a weld")
        else:
            coord, sign = hinge
            sx, sy = shifts.get("x"), shifts.get("y")
            self.joints.append(Joint(name, "hinge", (node_name(j.parent), child), shift_x=sx and sx[1],
                                     shift_y=sy and sy[1]))
            self.coords.append(Coordinate(coord, name, self.default[coord], sign, self.limits.get(coord)))
            kind = "a coupled hinge (its centre moves along " + " and ".join(sorted(shifts)) + ")" if shifts \
                else "a hinge"
            self.report.append(f"joint {j.name!r} ({j.kind}): {kind}, coordinate {coord!r}")

    def hinge(self, j: OsimJoint, axes_g):
        """The joint's rotation about the plane's normal: (coordinate, sign), or None."""
        hinge, used = None, set()
        for ax, a in zip(j.axes, axes_g, strict=True):
            if not ax.rotation or ax.coordinate is None or abs(a[2]) < math.cos(math.radians(PROJECTED)) or \
                    ax.function.is_constant() or ax.coordinate in self.locked:
                continue
            slope = getattr(ax.function, "slope", None)
            if ax.coordinate in used or hinge is not None or slope is None or abs(abs(slope) - 1.0) > 1e-12:
                raise ValueError(f"{self.m.source}: joint {j.name!r}: turns about the plane's normal as "
                                 f"{type(ax.function).__name__} of {ax.coordinate!r}; casflex takes one rotation "
                                 "about the normal equal to +-1 times a coordinate")
            hinge = (ax.coordinate, float(np.sign(slope) * np.sign(a[2])))
            used.add(ax.coordinate)
            if abs(a[2]) < NORMAL:
                tilt = math.degrees(math.acos(min(1.0, abs(a[2]))))
                self.dropped.append(f"joint {j.name!r}: its axis {np.round(a, 3).tolist()} is {tilt:.1f} deg from the "
                                    "plane's normal; projected on it (a hinge about the normal)")
        return hinge

    def shifts(self, j: OsimJoint, axes_g, hinge) -> dict[str, tuple[int, tuple]]:
        """The hinge's coupled translations: 'x' or 'y' -> (the axis's index, knots [psi, s])."""
        coord, sign = hinge
        q0 = self.default[coord]
        out: dict[str, tuple[int, tuple]] = {}
        for i, (ax, a) in enumerate(zip(j.axes, axes_g, strict=True)):
            if ax.rotation or ax.coordinate != coord or ax.function.is_constant():
                continue
            k = int(np.argmax(np.abs(a[:2])))
            f, scale = ax.function, 1.0
            while isinstance(f, Multiplier):  # a scaled model's function: exact on the knots (linear in y)
                f, scale = f.inner, scale * f.scale
            if abs(a[k]) < NORMAL or "xy"[k] in out or not isinstance(f, (SimmSpline, Linear)):
                continue  # reported by classify as held at its default
            if isinstance(f, Linear):
                lo, hi = self.range.get(coord, (-math.pi, math.pi))
                xs = np.array([max(lo, -2 * math.pi), min(hi, 2 * math.pi)])
                ys = f(xs)
            else:
                xs, ys = np.asarray(f.x, dtype=float), np.asarray(f.y, dtype=float)
            psi, s = sign * (xs - q0), np.sign(a[k]) * scale * ys
            order = np.argsort(psi)
            out["xy"[k]] = (i, tuple((float(p), float(v)) for p, v in zip(psi[order], s[order], strict=True)))
        return out

    def classify(self, j: OsimJoint, axes_g, hinge, shifts, root: bool) -> None:
        """The root's coordinates; what is locked, held or dropped (reported)."""
        free = [c for c in j.coordinates if not c.locked]
        used = {hinge[0]} if hinge else set()
        coupled = {i for i, _ in shifts.values()}
        if root:
            self.root(j, axes_g, hinge)
            used |= {c.name for c in self.coords}
        for i, (ax, a) in enumerate(zip(j.axes, axes_g, strict=True)):
            own = ax.rotation and abs(a[2]) >= math.cos(math.radians(PROJECTED)) and getattr(ax.function, "slope", 0)
            if ax.coordinate is None or ax.function.is_constant() or i in coupled or ax.coordinate in used and not (
                    hinge and ax.coordinate == hinge[0] and not own):
                continue
            what = "rotation about" if ax.rotation else "translation along"
            direction = np.round(a, 3).tolist()
            if hinge and ax.coordinate == hinge[0]:
                unit = "deg" if ax.rotation else "mm"
                size = self.reach(ax, ax.coordinate) * (180 / math.pi if ax.rotation else 1e3)
                self.dropped.append(f"joint {j.name!r}: its {what} {direction} follows {ax.coordinate!r} "
                                    f"(reach {size:.1f} {unit} over its range); held at its default value")
            elif ax.coordinate in self.locked:
                self.report.append(f"joint {j.name!r}: coordinate {ax.coordinate!r} ({what} {direction}) locked in "
                                   f"the model file, at {self.default[ax.coordinate]:g}")
            else:
                self.dropped.append(f"joint {j.name!r}: coordinate {ax.coordinate!r} ({what} {direction}) locked "
                                    f"at its default value {self.default[ax.coordinate]:g}")
        for c in free:
            if c.name not in used and not any(ax.coordinate == c.name for ax in j.axes):
                self.dropped.append(f"joint {j.name!r}: coordinate {c.name!r} moves nothing; ignored")

    def root(self, j: OsimJoint, axes_g, hinge) -> None:
        """The root's coordinates: the rotation about the normal and translations along the ground's x and y."""
        child = node_name(j.child)
        if hinge is not None:
            self.coords.append(Coordinate(hinge[0], f"{child}.theta", self.default[hinge[0]], hinge[1],
                                          self.limits.get(hinge[0])))
        for ax, a in zip(j.axes, axes_g, strict=True):
            if ax.rotation or ax.coordinate is None or ax.function.is_constant() or ax.coordinate in self.locked:
                continue
            slope = getattr(ax.function, "slope", 0.0)
            for k, dof in ((0, "x"), (1, "y")):
                if abs(a[k]) >= NORMAL and abs(abs(slope) - 1.0) < 1e-12:
                    self.coords.append(Coordinate(ax.coordinate, f"{child}.{dof}", self.default[ax.coordinate],
                                                  float(np.sign(a[k]) * np.sign(slope)),
                                                  self.limits.get(ax.coordinate)))
        self.report.append(f"joint {j.name!r} ({j.kind}): the root {child!r}, driven by the data; coordinates "
                           f"{[c.name for c in self.coords]}")

    # -- bodies and markers ---------------------------------------------------------------
    def bodies(self) -> list[RigidBody]:
        out, joints = [], {j.name for j in self.joints}
        for b in self.m.bodies.values():
            if b.name not in self.pose:
                continue
            if b.mass <= 0:
                self.report.append(f"body {b.name!r}: massless, a node only")
                continue
            R, p = self.pose[b.name]
            com = p + R @ b.com
            Ig = R @ b.inertia @ R.T
            name = node_name(b.name) + ("_body" if node_name(b.name) in joints else "")
            out.append(RigidBody(name, node_name(b.name), b.mass, float(Ig[2, 2]), float(com[0]), float(com[1])))
        return out

    def welded_body(self, node: str, on: dict[str, str]) -> str | None:
        """The body (its name) of the nearest node welded to the massless ``node`` (the same rigid segment: a marker
        on a massless calcaneus welded to the talus moves with the talus), None where no weld reaches one."""
        welds = [j.nodes for j in self.joints if j.kind == "weld" and len(j.nodes) == 2]
        seen, todo = {node}, [node]
        while todo:
            n = todo.pop(0)
            if n in on:
                return on[n]
            nxt = [b if a == n else a for a, b in welds if n in (a, b) and (b if a == n else a) not in seen]
            seen.update(nxt)
            todo += nxt
        return None

    def markers(self, bodies: list[RigidBody]) -> list[Marker]:
        on = {b.node: b.name for b in bodies}
        out = []
        for mk in self.m.markers:
            node = node_name(mk.body)
            carrier = self.welded_body(node, on) if mk.body in self.pose and node not in on else None
            if carrier is not None:  # OpenSim keeps it: left out, the segment could lose its only markers
                self.report.append(f"marker {mk.name!r}: on {mk.body!r}, massless, welded to {carrier!r}: carried "
                                   "by it")
                R, p = self.pose[mk.body]
                x = p + R @ mk.location
                out.append(Marker(node_name(mk.name), carrier, float(x[0]), float(x[1]), label=mk.name, fixed=mk.fixed))
                continue
            if mk.body not in self.pose or node not in on:
                why = ("the ground: it moves with no coordinate" if mk.body == "ground" else "massless"
                       if mk.body in self.pose else "no body of the tree")
                self.dropped.append(f"marker {mk.name!r}: on {mk.body!r}, {why}; left out")
                continue
            R, p = self.pose[mk.body]
            x = p + R @ mk.location
            out.append(Marker(node_name(mk.name), on[node], float(x[0]), float(x[1]), label=mk.name, fixed=mk.fixed))
        return out


def _muscles(b: _Builder) -> tuple[Muscle, ...]:
    """The model's muscles on the scene's nodes; a condition or moving point of a coordinate the scene does not
    move evaluated at its default value (reported); its wraps (:func:`_wraps`)."""
    lab = {c.name for c in b.coords}
    out = []
    for m in b.m.muscles:
        owner = f"{b.m.source}: ForceSet: {m.kind} {m.name!r}"
        points = [(k, _path_point(b, m, p, lab, owner)) for k, p in enumerate(m.path)]
        path = tuple(p for _, p in points if p is not None)
        wraps = _wraps(b, m, owner, [k for k, p in points if p is not None])
        if len(path) < 2:
            raise ValueError(f"{owner}: {len(path)} path point(s) on its path at the scene's held coordinates; a "
                             "muscle's path needs two or more")
        out.append(Muscle(m.name, m.kind, *(m.numbers[k] for k in ("max_isometric_force", "optimal_fiber_length",
                          "tendon_slack_length", "pennation_angle_at_optimal", "max_contraction_velocity")),
                          path=path, properties=m.properties, wraps=wraps))
    if out:
        kinds = sorted({m.kind for m in out})
        b.report.append(f"muscles: {len(out)} ({', '.join(f'{sum(m.kind == k for m in out)} {k}' for k in kinds)})")
    return tuple(out)


def _path_point(b: _Builder, m, p, lab: set[str], owner: str) -> PathPoint | None:
    """The scene's path point of the OpenSim point p; None for a conditional point never on the path."""
    where = f"muscle {m.name!r} path point {p.name!r}"
    if p.body not in b.pose or p.body == "ground":
        raise ValueError(f"{owner}: path point {p.name!r}: on {p.body!r}, "
                         + ("the ground (casflex's scene has no node for it)" if p.body == "ground" else
                            "a body no joint of the tree places"))
    R, pos = b.pose[p.body]
    condition, location, moving = None, np.array(p.location, dtype=float), []
    if p.condition is not None:
        c, lo, hi = p.condition
        if c in lab:
            condition = (c, lo, hi)
        else:  # OpenSim's test, with its tolerance (ConditionalPathPoint::isActive)
            on = lo - 1e-5 <= b.default[c] <= hi + 1e-5
            b.dropped.append(f"{where}: its coordinate {c!r} is held at {b.default[c]:g} by the scene: "
                             + ("always on the path" if on else "never on the path; left out"))
            if not on:
                return None
    for axis, c, f in p.moving:
        lo, hi = b.range.get(c, (-math.inf, math.inf)) if c else (-math.inf, math.inf)
        if math.isinf(lo) and math.isinf(hi):  # no <range> in the file: OpenSim's default range clamps it
            lo, hi = OPENSIM_RANGE
        clamped = Clamped(f, lo, hi)
        location[axis] = float(clamped(b.default[c] if c else 0.0))
        if c in lab and not f.is_constant():
            moving.append((axis, c, clamped))
        elif c and not f.is_constant():
            b.dropped.append(f"{where}: its {'xyz'[axis]} follows {c!r}, held at {b.default[c]:g} by the scene: "
                             f"fixed at {location[axis]:g} m")
    return PathPoint(p.name, node_name(p.body), tuple(float(v) for v in location),
                     tuple(float(v) for v in (*R.ravel(), *pos)), condition, tuple(moving))


def _wraps(b: _Builder, m, owner: str, kept: list[int]) -> tuple[Wrap, ...]:
    """The muscle's wraps that stay in the plane (a WrapCylinder whose axis is the plane's normal: a circle), their
    ranges counted in the scene's path (``kept``: the model's index of each point the scene keeps); any other wrap
    refused in one line naming the wrap object and why; an inactive wrap object reported."""
    out = []
    for obj, (first, last) in m.wraps:
        w = b.m.wrap_objects.get(obj)
        if w is None:
            raise ValueError(f"{owner}: PathWrap: wrap object {obj!r} is on no body of the model (WrapObjectSet)")
        if not w.active:
            b.report.append(f"muscle {m.name!r}: wrap object {obj!r} is not active in the model; ignored")
            continue
        if w.body not in b.pose or w.body == "ground":
            raise ValueError(f"{owner}: wrap object {obj!r}: on {w.body!r}, "
                             + ("the ground (casflex's scene has no node for it)" if w.body == "ground" else
                                "a body no joint of the tree places"))
        Rb, pb = b.pose[w.body]
        R = Rb @ w.rotation
        if not (w.kind == "WrapCylinder" and abs(R[2, 2]) >= NORMAL):
            why = (f"a {w.kind}" + (f" whose axis {np.round(R[:, 2], 3).tolist()} is not the plane's normal"
                                    if w.kind == "WrapCylinder" else "") + ": its wrapping leaves the plane")
            raise ValueError(f"{owner}: wrap object {obj!r}: {why}; remove it from the muscle's PathWrapSet to compute "
                             "the path without it")
        centre = pb + Rb @ w.translation
        lo = next((k + 1 for k, i in enumerate(kept) if i >= first - 1), 0) if first >= 1 else -1
        hi = next((k + 1 for k, i in reversed(list(enumerate(kept))) if i <= last - 1), 0) if last >= 1 else -1
        out.append(Wrap(obj, node_name(w.body), float(w.radius), tuple(float(v) for v in centre),
                        tuple(float(v) for v in (*R.ravel(), *centre)), w.quadrant, (lo, hi), float(w.length)))
    if len(out) > 1:
        raise ValueError(f"{owner}: wrap objects {[w.name for w in out]}: {len(out)} wraps on one path; OpenSim "
                         "iterates between several until the path's length settles, casflex computes one: keep one "
                         "in the muscle's PathWrapSet")
    if out:
        b.report.append(f"muscle {m.name!r}: wraps over {out[0].name!r} (a circle in the plane, radius "
                        f"{out[0].radius:g} m)")
    return tuple(out)


def _constraints(b: _Builder, by_child: dict[str, OsimJoint]) -> None:
    """Each constraint of the model: one the scene would break refused (a coupler whose dependent coordinate the
    scene moves freely, a loop closed between bodies the scene moves relative to each other), the others
    ignored with a warning (OpenSim's IK and ID keep them; casflex's planar scene does not), an unenforced one
    reported."""
    kept = {c.name for c in b.coords}
    for c in b.m.constraints:
        what = f"{c.kind} {c.name!r}"
        if not c.enforced:
            b.report.append(f"constraint {what}: not enforced in the model; ignored")
            continue
        if c.dependent is not None or c.independent:
            unknown = [n for n in (c.dependent or "", *c.independent) if n not in b.default]
            if unknown:
                raise ValueError(f"{b.m.source}: ConstraintSet: {what}: {unknown[0]!r} is no coordinate of the model "
                                 "(dependent_coordinate_name, independent_coordinate_names)")
            if c.dependent in kept:
                raise ValueError(f"{b.m.source}: ConstraintSet: {what} makes {c.dependent!r} follow "
                                 f"{list(c.independent)}, and the planar scene moves {c.dependent!r} on its own "
                                 "(casflex takes no constraints): lock it in the model (<locked>true</locked>) or "
                                 "remove the constraint")
            follows = [i for i in c.independent if i in kept]
            held = "locked in the model" if c.dependent in b.locked else "held at its default value"
            b.warnings.append(f"{b.m.source}: constraint {what} ignored: {c.dependent!r} is {held}"
                              + (f", where OpenSim's tools move it with {follows}" if follows else ""))
            continue
        if len(c.bodies) < 2 or None in c.bodies:
            raise ValueError(f"{b.m.source}: ConstraintSet: {what}: its sockets name no two bodies of the model "
                             f"(found {list(c.bodies)}); casflex cannot tell what it joins: remove it or name the "
                             "bodies")
        path = _path(c.bodies[0], by_child) ^ _path(c.bodies[1], by_child)
        moving = sorted(path & b.moving)
        if moving:
            raise ValueError(f"{b.m.source}: ConstraintSet: {what} closes a loop between {c.bodies[0]!r} and "
                             f"{c.bodies[1]!r}, which the planar scene moves relative to each other (joints "
                             f"{moving}); casflex reads trees: remove the constraint, or lock those joints' "
                             "coordinates in the model")
        b.warnings.append(f"{b.m.source}: constraint {what} ignored: the planar scene holds {c.bodies[0]!r} and "
                          f"{c.bodies[1]!r} fixed relative to each other already")


def _path(body: str, by_child: dict[str, OsimJoint]) -> set[str]:
    """The joints from ``body`` to the ground."""
    out: set[str] = set()
    while body in by_child and by_child[body].name not in out:
        out.add(by_child[body].name)
        body = by_child[body].parent
    return out


def _tree_order(model: OsimModel) -> list[OsimJoint]:
    """The joints from the ground outwards; ValueError for a body with two joints, or none from the ground."""
    by_child: dict[str, OsimJoint] = {}
    for j in model.joints:
        if j.child == "ground":
            raise ValueError(f"{model.source}: joint {j.name!r}: its child frame is on the ground, which is no joint's "
                             f"child (it closes a loop from {j.parent!r} to the ground); casflex reads trees")
        if j.child in by_child:
            raise ValueError(f"{model.source}: body {j.child!r} is the child of joints {by_child[j.child].name!r} and "
                             f"{j.name!r}: a closed loop; casflex reads trees")
        by_child[j.child] = j
    roots = [j for j in model.joints if j.parent == "ground"]
    if len(roots) != 1:
        raise ValueError(f"{model.source}: {len(roots)} joints to the ground ({[j.name for j in roots]}); casflex "
                         "reads a model with one (its root)")
    order, placed = [], {"ground"}
    todo = list(model.joints)
    while todo:
        nxt = [j for j in todo if j.parent in placed]
        if not nxt:
            raise ValueError(f"{model.source}: joints {[j.name for j in todo][:4]} do not reach the ground")
        for j in nxt:
            order.append(j)
            placed.add(j.child)
            todo.remove(j)
    return order


def scene_from_osim(source: str | os.PathLike[str] | OsimModel, name: str | None = None, *,
                    muscles: bool = False) -> OsimScene:
    """The planar scene of an OpenSim model file (or its parts) and the report (module docstring). ``muscles``:
    the model's muscles read and carried (``OsimScene.muscles``; a muscle casflex cannot compute, a wrap the plane
    cannot hold, refused in one line); else they are listed as ignored, as inverse dynamics needs none of them
    (a model whose muscles wrap in 3D is still read for its bones)."""
    model = source if isinstance(source, OsimModel) else read_osim(source, muscles=muscles)
    b = _Builder(model)
    for j in _tree_order(model):
        b.joint(j)
    bodies = b.bodies()
    if not bodies:
        raise ValueError(f"{model.source}: BodySet: no body of the tree has a mass > 0 ({len(model.bodies)} bodies); "
                         "a scene of massless nodes has no dynamics: give the bodies their masses")
    _constraints(b, {j.child: j for j in model.joints})
    markers = b.markers(bodies)
    muscles = _muscles(b) if muscles else ()
    kept = {("ForceSet", m.kind, m.name) for m in muscles}
    others: dict[str, int] = {}
    for s, kind, n in model.others:
        if (s, kind, n) in kept:
            continue
        others[f"{s} {kind}"] = others.get(f"{s} {kind}", 0) + 1
    if others:
        b.report.append("ignored: " + ", ".join(f"{n} {k}" for k, n in sorted(others.items())))
    g = model.gravity
    title = node_name(name or os.path.splitext(os.path.basename(model.name))[0])
    try:
        scene = Scene(title, tuple(b.nodes), bodies=tuple(bodies), joints=tuple(b.joints), markers=tuple(markers),
                      coordinates=tuple(b.coords), gravity=(float(g[0]), float(g[1])))
    except ValueError as exc:  # the scene's own checks (a default outside a clamped range, ...): name the file
        raise ValueError(f"{model.source}: {exc}") from None
    report = [f"{model.source}: {len(bodies)} bodies, {len(b.joints)} joints, {len(markers)} markers, "
              f"{len(b.coords)} coordinates in the x-y plane", *b.report, *b.dropped, *b.warnings]
    return OsimScene(scene, tuple(report), tuple(b.dropped), tuple(b.warnings), muscles, dict(b.pose),
                     dict(b.joint_frames), source=str(model.source))
