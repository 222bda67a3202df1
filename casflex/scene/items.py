"""The items a scene lists: nodes, beams, springs, torsion springs, rigid bodies, supports, loads,
parameters and run settings. Each validates its own fields on construction and raises
:class:`SceneError` naming the offending one. Numbers only (no CasADi); units SI (m, rad, s, kg,
N, N m, Pa). :mod:`casflex.scene` holds the whole :class:`~casflex.scene.Scene` and re-exports these.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any


class SceneError(ValueError):
    """A scene is malformed; the message names the offending field.

    Errors raised by an element's own validation also carry ``field`` (the field path inside
    the element, e.g. ``"k"`` or ``"table[1][0]"``, or None) and ``reason`` (the message
    without the location), so that a reader can relocate them, e.g. from
    ``spring 'spring1'.k: must be > 0, got -5`` to ``springs[0] (spring1).k: must be > 0, got -5``.
    """

    def __init__(self, message: str, *, field: str | None = None, reason: str | None = None) -> None:
        super().__init__(message)
        self.field = field
        self.reason = message if reason is None else reason

    @classmethod
    def at(cls, owner: str, field: str | None, reason: str) -> SceneError:
        """The error ``"<owner>.<field>: <reason>"`` (``"<owner>: <reason>"`` without a field)."""
        where = owner if field is None else (f"{owner}.{field}" if owner else field)
        return cls(f"{where}: {reason}", field=field, reason=reason)


#: Which nodal dofs ("x", "y", "theta") each support kind fixes.
SUPPORT_DOFS: dict[str, tuple[str, ...]] = {
    "clamp": ("x", "y", "theta"),
    "pin": ("x", "y"),
    "x": ("x",),
    "y": ("y",),
    "theta": ("theta",),
}

#: Forms of the velocity-dependent inertia term (see casflex.model).
INERTIA_FORMS = ("lagrange", "seed")
_NON_NUMERIC = ("name", "nodes", "node", "elements", "table", "kind", "rotary_inertia", "follower", "motion",
                "point_a", "point_b", "point", "axis", "shift_x", "shift_y")


def _number(owner: str, field: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError.at(owner, field, f"expected a number, got {value!r} ({type(value).__name__})")
    value = float(value)
    if not math.isfinite(value):
        raise SceneError.at(owner, field, f"must be finite, got {value}")
    return value


def _positive(owner: str, field: str, value: Any) -> float:
    value = _number(owner, field, value)
    if value <= 0.0:
        raise SceneError.at(owner, field, f"must be > 0, got {value:g}")
    return value


def _non_negative(owner: str, field: str, value: Any) -> float:
    value = _number(owner, field, value)
    if value < 0.0:
        raise SceneError.at(owner, field, f"must be >= 0, got {value:g}")
    return value


def _name(owner: str, field: str, value: Any) -> str:
    if not isinstance(value, str) or not value.strip():
        raise SceneError.at(owner, field, f"expected a non-empty name (a string), got {value!r}")
    if any(c in value for c in ".:[] \t\n"):
        raise SceneError.at(owner, field, f"name {value!r} may not contain '.', ':', '[', ']' or spaces")
    return value


def node_name(s: str) -> str:
    """The scene name of an OpenSim body, joint or marker: its name with '.', ':', '[', ']' and spaces made '_'
    (casflex's names may not hold them, :func:`_name`); a body's node is so named."""
    return re.sub(r"[.:\[\]\s]", "_", s) or "_"


def _node_pair(owner: str, value: Any) -> tuple[str, str]:
    if isinstance(value, str) or not isinstance(value, (list, tuple)) or len(value) != 2:
        raise SceneError.at(owner, "nodes", f"expected a list of two node names, got {value!r}")
    a, b = (_name(owner, f"nodes[{i}]", v) for i, v in enumerate(value))
    if a == b:
        raise SceneError.at(owner, "nodes", f"the two nodes must differ, got {a!r} twice")
    return a, b


def _owner(kind: str, name: Any) -> str:
    return f"{kind} {name!r}"


@dataclass(frozen=True)
class Node:
    """A node: initial position (m), initial rotation (rad) and initial velocity.

    The rotation dof ``theta`` is absolute; its initial value is ``theta`` and elements
    attached to the node are stress-free in the initial configuration.
    """

    name: str
    x: float
    y: float
    theta: float = 0.0
    vx: float = 0.0
    vy: float = 0.0
    omega: float = 0.0

    def __post_init__(self) -> None:
        where = _owner("node", self.name)
        object.__setattr__(self, "name", _name(where, "name", self.name))
        for f in ("x", "y", "theta", "vx", "vy", "omega"):
            object.__setattr__(self, f, _number(where, f, getattr(self, f)))


@dataclass(frozen=True)
class Beam:
    """A straight co-rotational Euler-Bernoulli beam between two nodes.

    E (Pa), A (m^2), I (m^4), rho (kg/m^3); meshed into ``elements`` equal elements.
    ``rotary_inertia`` adds the cross-section rotary inertia rho*I to the consistent mass.
    ``beta`` (s): stiffness-proportional (Rayleigh) damping of the element's deformation rates,
    modal damping ratio beta omega / 2; 0 (the default) adds nothing to the model.
    """

    name: str
    nodes: tuple[str, str]
    E: float
    A: float
    I: float  # noqa: E741 - the paper's symbol
    rho: float
    elements: int = 1
    rotary_inertia: bool = False
    beta: float = 0.0

    def __post_init__(self) -> None:
        where = _owner("beam", self.name)
        object.__setattr__(self, "name", _name(where, "name", self.name))
        object.__setattr__(self, "nodes", _node_pair(where, self.nodes))
        for f in ("E", "A", "I"):
            object.__setattr__(self, f, _positive(where, f, getattr(self, f)))
        object.__setattr__(self, "rho", _non_negative(where, "rho", self.rho))
        object.__setattr__(self, "beta", _non_negative(where, "beta", self.beta))
        n = self.elements
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise SceneError.at(where, "elements", f"expected an integer >= 1, got {n!r}")
        if not isinstance(self.rotary_inertia, bool):
            raise SceneError.at(where, "rotary_inertia", f"expected true or false, got {self.rotary_inertia!r}")


@dataclass(frozen=True)
class Spring:
    """A massless co-rotational linear (axial, pin-to-pin) spring, stiffness k (N/m), with an
    optional viscous damper c (N s/m) in parallel.

    ``rest_length`` (m) defaults to the initial distance between its two ends. The damper acts
    along the spring on the rate of its length (force c dL/dt); a spring of rest length 0 (a
    bushing) is damped on the relative velocity of its ends instead (force c (v_b - v_a)).
    ``c = 0`` (the default) adds nothing to the model.

    Its ends are the nodes, or ``point_a`` / ``point_b`` (x, y in m, in the scene's initial
    configuration): points fixed in the frame of node a / b, which keep their offset from the
    node as it turns (a point on the rigid body at that node, e.g. the knee end of a rigid thigh
    whose node is at the hip).
    """

    name: str
    nodes: tuple[str, str]
    k: float
    rest_length: float | None = None
    c: float = 0.0
    point_a: tuple[float, float] | None = None
    point_b: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        where = _owner("spring", self.name)
        object.__setattr__(self, "name", _name(where, "name", self.name))
        object.__setattr__(self, "nodes", _node_pair(where, self.nodes))
        object.__setattr__(self, "k", _positive(where, "k", self.k))
        if self.rest_length is not None:
            object.__setattr__(self, "rest_length", _non_negative(where, "rest_length", self.rest_length))
        object.__setattr__(self, "c", _non_negative(where, "c", self.c))
        for f in ("point_a", "point_b"):
            v = getattr(self, f)
            if v is None:
                continue
            if isinstance(v, str) or not isinstance(v, (list, tuple)) or len(v) != 2:
                raise SceneError.at(where, f, f"expected [x, y] in m (two numbers), got {v!r}")
            object.__setattr__(self, f, tuple(_number(where, f"{f}[{i}]", x) for i, x in enumerate(v)))


@dataclass(frozen=True)
class TorsionSpring:
    """A massless torsional spring kt (N m/rad) on the relative rotation theta_b - theta_a, with an
    optional viscous damper ct (N m s/rad) in parallel on the relative angular velocity.

    ``rest_angle`` (rad) defaults to the initial relative rotation; ``ct = 0`` (the default) adds
    nothing to the model.
    """

    name: str
    nodes: tuple[str, str]
    kt: float
    rest_angle: float | None = None
    ct: float = 0.0

    def __post_init__(self) -> None:
        where = _owner("torsion spring", self.name)
        object.__setattr__(self, "name", _name(where, "name", self.name))
        object.__setattr__(self, "nodes", _node_pair(where, self.nodes))
        object.__setattr__(self, "kt", _positive(where, "kt", self.kt))
        if self.rest_angle is not None:
            object.__setattr__(self, "rest_angle", _number(where, "rest_angle", self.rest_angle))
        object.__setattr__(self, "ct", _non_negative(where, "ct", self.ct))


@dataclass(frozen=True)
class RigidBody:
    """A planar rigid body fixed to a node: mass (kg), moment of inertia about its centre of mass
    (kg m^2), centre of mass initially at (com_x, com_y) (m; default: the node).

    The body turns with the node's rotation dof: its centre of mass stays at the initial offset
    from the node in the node's frame. A body of zero inertia at the node is a point mass.
    """

    name: str
    node: str
    mass: float
    inertia: float = 0.0
    com_x: float | None = None
    com_y: float | None = None

    def __post_init__(self) -> None:
        where = _owner("rigid body", self.name)
        object.__setattr__(self, "name", _name(where, "name", self.name))
        object.__setattr__(self, "node", _name(where, "node", self.node))
        object.__setattr__(self, "mass", _positive(where, "mass", self.mass))
        object.__setattr__(self, "inertia", _non_negative(where, "inertia", self.inertia))
        for f in ("com_x", "com_y"):
            if getattr(self, f) is not None:
                object.__setattr__(self, f, _number(where, f, getattr(self, f)))


#: Ideal joint kinds and the constraint rows each adds (casflex.elements.joints).
JOINT_KINDS = {"hinge": 2, "slider": 2, "weld": 3, "drive": 1}


def _point(owner: str, field: str, value: Any) -> tuple[float, float]:
    if isinstance(value, str) or not isinstance(value, (list, tuple)) or len(value) != 2:
        raise SceneError.at(owner, field, f"expected [x, y] in m (two numbers), got {value!r}")
    return tuple(_number(owner, f"{field}[{i}]", x) for i, x in enumerate(value))  # type: ignore[return-value]


def _knots(owner: str, field: str, rows: Any) -> tuple[tuple[float, float], ...]:
    """Rows [psi (rad), s (m)], two or more, psi strictly increasing, as tuples."""
    if isinstance(rows, str) or not isinstance(rows, (list, tuple)) or len(rows) < 2:
        raise SceneError.at(owner, field, f"expected two or more rows [angle, shift], got {rows!r}")
    out = []
    for i, r in enumerate(rows):
        if isinstance(r, str) or not isinstance(r, (list, tuple)) or len(r) != 2:
            raise SceneError.at(owner, f"{field}[{i}]", f"expected [angle (rad), shift (m)], got {r!r}")
        out.append((_number(owner, f"{field}[{i}][0]", r[0]), _number(owner, f"{field}[{i}][1]", r[1])))
        if i and out[-1][0] <= out[-2][0]:
            raise SceneError.at(owner, f"{field}[{i}][0]", f"the angles must increase, got {out[-1][0]:g} after "
                                f"{out[-2][0]:g}")
    return tuple(out)


@dataclass(frozen=True)
class Joint:
    """An ideal joint: constraints Phi(q) = 0 between the frames of node a and node b, held by
    Lagrange multipliers (no stiffness to choose, no fast mode). ``nodes = [a, b]``, or ``[b]``
    for a joint to the ground (a is then the ground, fixed where the scene starts).

    ``point`` (x, y in m, in the initial configuration; default: node b's position) is fixed in
    both frames (and the ground's):

    - ``hinge`` (revolute, 2 rows): the point of a and the point of b coincide; the relative
      rotation is free (a torsion spring between the nodes makes it compliant). Outputs ``fx``,
      ``fy`` (N, global) and ``f_along``, ``f_across`` (N, along and across ``axis`` turned with
      node b): the force that a exerts on b at the point; ``angle`` (rad): the relative rotation
      theta_b - theta_a from the initial configuration.
    - ``slider`` (prismatic, 2 rows): b's point moves along the line through a's point in the
      direction ``axis`` (fixed in a's frame), the relative rotation locked. Outputs ``travel``
      (m, along the axis from the start), ``force`` (N, on b, across the axis, to its left) and
      ``moment`` (N m, on b: the couple that locks the rotation).
    - ``weld`` (3 rows): the two frames locked together at the point. Outputs ``fx``, ``fy``
      (N, global, on b) and ``moment`` (N m, on b).
    - ``drive`` (1 row; ``nodes = [a, b, c]``): the relative rotation theta_b - theta_a (from the
      initial configuration) follows node c's rotation (from its initial one), c a driver node that
      a support moves along a path: an actuated joint driven at a measured angle (inverse dynamics
      adds one across each hinge). Outputs ``moment`` (N m, on b; a gets its opposite: the actuator's
      moment) and ``angle`` (rad). ``point`` and ``axis`` do not apply.

    ``axis`` (a direction, normalised; initial configuration) defaults to the x axis for a slider;
    for a hinge to the direction from the point to node b, or from node a to the point where b
    sits at it, or the x axis.

    ``shift_x``, ``shift_y`` (a hinge between two nodes; tables of [psi, s] rows, psi in rad increasing,
    s in m): a coupled hinge, whose point on a moves as it turns (OpenSim's custom joints: a knee's
    centre rolling with its angle). The point of a is then the point + (s(psi) - s(0)) in a's frame (its
    axes as in the initial configuration), s a cubic spline of the knots (SIMM's, as OpenSim's
    SimmSpline: :mod:`casflex.scene.functions`), psi the hinge's angle.
    """

    name: str
    kind: str
    nodes: tuple[str, ...]
    point: tuple[float, float] | None = None
    axis: tuple[float, float] | None = None
    shift_x: tuple[tuple[float, float], ...] | None = None
    shift_y: tuple[tuple[float, float], ...] | None = None

    @property
    def coupled(self) -> bool:
        """Whether the hinge's point moves with its angle (``shift_x`` or ``shift_y``)."""
        return self.shift_x is not None or self.shift_y is not None

    def shift_splines(self) -> tuple:
        """(s_x, s_y): the SIMM splines (:class:`casflex.scene.functions.SimmSpline`) through the knots of
        ``shift_x`` and ``shift_y``, each None where the table is."""
        from casflex.scene.functions import SimmSpline

        return tuple(None if t is None else SimmSpline(tuple(r[0] for r in t), tuple(r[1] for r in t))
                     for t in (self.shift_x, self.shift_y))

    def __post_init__(self) -> None:
        where = _owner("joint", self.name)
        object.__setattr__(self, "name", _name(where, "name", self.name))
        if self.kind not in JOINT_KINDS:
            raise SceneError.at(where, "kind", f"expected one of {list(JOINT_KINDS)}, got {self.kind!r}")
        nodes = self.nodes
        sizes, form = ((3,), "[a, b, driver]") if self.kind == "drive" else ((1, 2), "[a, b] or [b] (to the ground)")
        if isinstance(nodes, str) or not isinstance(nodes, (list, tuple)) or len(nodes) not in sizes:
            raise SceneError.at(where, "nodes", f"expected {form}: node names, got {nodes!r}")
        nodes = tuple(_name(where, f"nodes[{i}]", v) for i, v in enumerate(nodes))
        if len(set(nodes)) < len(nodes):
            raise SceneError.at(where, "nodes", f"the nodes must differ, got {list(nodes)}")
        object.__setattr__(self, "nodes", nodes)
        for f in ("point", "axis"):
            if self.kind == "drive" and getattr(self, f) is not None:
                raise SceneError.at(where, f, "does not apply to a drive (it holds a relative rotation only)")
        if self.point is not None:
            object.__setattr__(self, "point", _point(where, "point", self.point))
        if self.axis is not None:
            ax = _point(where, "axis", self.axis)
            norm = math.hypot(*ax)
            if norm == 0.0:
                raise SceneError.at(where, "axis", "must be a direction, got [0, 0]")
            object.__setattr__(self, "axis", (ax[0] / norm, ax[1] / norm))
        for f in ("shift_x", "shift_y"):
            if getattr(self, f) is not None:
                if self.kind != "hinge" or len(self.nodes) != 2:
                    raise SceneError.at(where, f, "applies to a hinge between two nodes only")
                object.__setattr__(self, f, _knots(where, f, getattr(self, f)))

    @property
    def rows(self) -> int:
        """How many constraint equations (and multipliers) the joint adds."""
        return JOINT_KINDS[self.kind]


def _time_rows(where: str, field: str, rows: Any, header: str) -> tuple[tuple[float, ...], ...]:
    """Rows of 4 finite numbers whose first (a time, s) increases strictly, as tuples."""
    out = []
    for i, row in enumerate(rows):
        if isinstance(row, str) or not isinstance(row, (list, tuple)) or len(row) != 4:
            raise SceneError.at(where, f"{field}[{i}]", f"expected a row {header}, got {row!r}")
        out.append(tuple(_number(where, f"{field}[{i}][{j}]", v) for j, v in enumerate(row)))
    for i in range(1, len(out)):
        if out[i][0] <= out[i - 1][0]:
            raise SceneError.at(where, f"{field}[{i}][0]",
                                f"times must increase strictly, got {out[i][0]:g} after {out[i - 1][0]:g}")
    return tuple(out)


@dataclass(frozen=True)
class Support:
    """A support fixing some dofs of a node at their initial values, or moving them along a path.

    kind: ``clamp`` (x, y, theta), ``pin`` (x, y), or a single dof ``x``, ``y``, ``theta``.

    ``motion``: rows (t, dx, dy, dtheta) (s, m, m, rad), at least 4, t strictly increasing: the
    displacement of the fixed dofs from the node's initial position (the components of dofs the
    support does not fix are ignored), interpolated by a quintic spline (a cubic one under 6 rows:
    continuous velocity, acceleration, jerk and snap; a rheonomic constraint) and held at the end values
    outside the table. The
    multipliers are then the forces and moments that drive the node along the path.
    """

    name: str
    node: str
    kind: str = "clamp"
    motion: tuple[tuple[float, float, float, float], ...] | None = None

    def __post_init__(self) -> None:
        where = _owner("support", self.name)
        object.__setattr__(self, "name", _name(where, "name", self.name))
        object.__setattr__(self, "node", _name(where, "node", self.node))
        if not isinstance(self.kind, str) or self.kind not in SUPPORT_DOFS:
            raise SceneError.at(where, "kind",
                                f"unknown support kind {self.kind!r}; expected one of {list(SUPPORT_DOFS)}")
        if self.motion is None:
            return
        if not isinstance(self.motion, (list, tuple)) or len(self.motion) < 4:
            raise SceneError.at(where, "motion", f"expected at least 4 rows [t, dx, dy, dtheta] (a cubic spline "
                                f"runs through them), got {self.motion!r}")
        object.__setattr__(self, "motion", _time_rows(where, "motion", self.motion, "[t, dx, dy, dtheta]"))

    @property
    def dofs(self) -> tuple[str, ...]:
        return SUPPORT_DOFS[self.kind]


@dataclass(frozen=True)
class Load:
    """A nodal load: force fx, fy (N) and moment mz (N m) in the global frame.

    Constant, or a time table: rows (t, fx, fy, mz) with strictly increasing t (s), interpolated
    linearly and held constant outside the table. A constant load is a table with one row.

    ``follower = true``: the force turns with its node, R(theta) (fx, fy) with theta the node's
    rotation (fx, fy are its components while theta = 0), as a muscle or a thruster acts; not
    conservative, so statics solves it by Newton (``seek = "nearest"``) and modes may flutter.
    Constant components only; mz is the same moment in any frame.

    ``against``: another node that takes the opposite load, an actuator between two nodes: a joint
    torque across a hinge is ``mz`` on the hinge's node b with ``against`` its node a (the moment a's
    segment exerts on b's, as inverse dynamics reports ``<hinge>.moment``).
    """

    name: str
    node: str
    fx: float = 0.0
    fy: float = 0.0
    mz: float = 0.0
    table: tuple[tuple[float, float, float, float], ...] | None = None
    follower: bool = False
    against: str | None = None

    def __post_init__(self) -> None:
        where = _owner("load", self.name)
        object.__setattr__(self, "name", _name(where, "name", self.name))
        object.__setattr__(self, "node", _name(where, "node", self.node))
        if self.against is not None:
            object.__setattr__(self, "against", _name(where, "against", self.against))
            if self.against == self.node:
                raise SceneError.at(where, "against", f"must be another node than 'node' ({self.node!r})")
            if self.follower:
                raise SceneError.at(where, "against", "a follower load has no opposite on another node")
        for f in ("fx", "fy", "mz"):
            object.__setattr__(self, f, _number(where, f, getattr(self, f)))
        if not isinstance(self.follower, bool):
            raise SceneError.at(where, "follower", f"expected true or false, got {self.follower!r}")
        if self.follower and self.table is not None:
            raise SceneError.at(where, "table", "a follower load takes constant fx, fy (and mz), not a table")
        if self.table is None:
            return
        if not isinstance(self.table, (list, tuple)) or len(self.table) == 0:
            raise SceneError.at(where, "table",
                                f"expected a non-empty list of rows [t, fx, fy, mz], got {self.table!r}")
        if self.fx or self.fy or self.mz:
            given = [f for f in ("fx", "fy", "mz") if getattr(self, f)]
            raise SceneError.at(where, "table",
                                f"give either constant fx/fy/mz or a table, not both (also given: {given})")
        object.__setattr__(self, "table", _time_rows(where, "table", self.table, "[t, fx, fy, mz]"))

    def rows(self) -> tuple[tuple[float, float, float, float], ...]:
        """The load as table rows (t, fx, fy, mz)."""
        return self.table if self.table is not None else ((0.0, self.fx, self.fy, self.mz),)


#: Fields whose parameters get a lower bound of 0 by default: no physical value is negative.
NONNEGATIVE_FIELDS = frozenset({"k", "kt", "c", "ct", "E", "A", "I", "rho", "rest_length", "mass", "inertia",
                                "beta"})


@dataclass(frozen=True)
class Parameter:
    """A scene property declared as an identification parameter.

    ``target`` names the property as ``"<element>.<field>"`` (e.g. ``"spring1.k"``), or
    ``"gravity.<x|y>"`` or ``"<load>.<fx|fy|mz>"``. Its nominal value is the property's value in
    the scene. ``lower``/``upper`` bound it; the nominal value must lie within them. The default
    lower bound is 0 for properties that are non-negative by nature (``NONNEGATIVE_FIELDS``:
    stiffnesses, damping coefficients, section, density, rest length, masses), else -inf; the default
    upper bound is +inf. ``scale`` is the typical magnitude used to scale the NLP (default: the nominal).
    ``prior`` (mean, standard deviation), in the property's unit: what is known of it before the data
    (a Gaussian prior); the fit then estimates it by maximum a posteriori (:mod:`casflex.identification.priors`).
    The scene's ``[[uncertain]]`` properties become such parameters (:class:`casflex.scene.uncertain.Uncertain`).
    """

    name: str
    target: str
    unit: str = ""
    lower: float | None = None
    upper: float = math.inf
    scale: float | None = None
    prior: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        where = _owner("parameter", self.name)
        object.__setattr__(self, "name", _name(where, "name", self.name))
        target = self.target
        if not isinstance(target, str) or target.count(".") != 1 or not all(target.partition(".")[::2]):
            raise SceneError.at(where, "target", f"expected '<element>.<field>', e.g. 'spring1.k', got {target!r}")
        if not isinstance(self.unit, str):
            raise SceneError.at(where, "unit", f"expected a string, got {self.unit!r}")
        if self.lower is None:
            field_ = target.partition(".")[2]
            object.__setattr__(self, "lower", 0.0 if field_ in NONNEGATIVE_FIELDS else -math.inf)
        for f in ("lower", "upper"):
            v = getattr(self, f)
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise SceneError.at(where, f, f"expected a number (inf allowed), got {v!r} ({type(v).__name__})")
            if math.isnan(v):
                raise SceneError.at(where, f, "must not be nan")
            object.__setattr__(self, f, float(v))
        if self.lower >= self.upper:
            raise SceneError.at(where, "lower", f"must be below upper = {self.upper:g}, got {self.lower:g}")
        if self.scale is not None:
            object.__setattr__(self, "scale", _positive(where, "scale", self.scale))
        if self.prior is not None:
            if isinstance(self.prior, str) or not isinstance(self.prior, (list, tuple)) or len(self.prior) != 2:
                raise SceneError.at(where, "prior", f"expected [mean, standard deviation], got {self.prior!r}")
            object.__setattr__(self, "prior", (_number(where, "prior[0]", self.prior[0]),
                                               _positive(where, "prior[1]", self.prior[1])))


@dataclass(frozen=True)
class RunSettings:
    """Default simulation settings: horizon t_end (s), step dt (s), HHT alpha, inertia form."""

    t_end: float = 3.0
    dt: float = 1e-3
    alpha: float = -0.05
    inertia: str = "lagrange"

    def __post_init__(self) -> None:
        object.__setattr__(self, "t_end", _positive("run", "t_end", self.t_end))
        object.__setattr__(self, "dt", _positive("run", "dt", self.dt))
        alpha = _number("run", "alpha", self.alpha)
        if not -1.0 / 3.0 - 1e-12 <= alpha <= 0.0:
            raise SceneError.at("run", "alpha", f"must lie in [-1/3, 0], got {alpha:g}")
        object.__setattr__(self, "alpha", alpha)
        if not isinstance(self.inertia, str) or self.inertia not in INERTIA_FORMS:
            raise SceneError.at("run", "inertia", f"expected one of {list(INERTIA_FORMS)}, got {self.inertia!r}")
        if self.dt > self.t_end:
            raise SceneError.at("run", "dt", f"the step {self.dt:g} s is longer than t_end = {self.t_end:g} s")


