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

__all__ = [
    "SceneError",
    "Node",
    "Beam",
    "Spring",
    "TorsionSpring",
    "RigidBody",
    "Support",
    "Load",
    "Parameter",
    "RunSettings",
    "Scene",
    "SUPPORT_DOFS",
]


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
_NON_NUMERIC = ("name", "nodes", "node", "elements", "table", "kind", "rotary_inertia", "follower", "motion")


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

    ``rest_length`` (m) defaults to the initial distance between the two nodes. The damper acts
    along the spring on the rate of its length (force c dL/dt); a spring of rest length 0 (a
    bushing) is damped on the relative velocity of its nodes instead (force c (v_b - v_a)).
    ``c = 0`` (the default) adds nothing to the model.
    """

    name: str
    nodes: tuple[str, str]
    k: float
    rest_length: float | None = None
    c: float = 0.0

    def __post_init__(self) -> None:
        where = _owner("spring", self.name)
        object.__setattr__(self, "name", _name(where, "name", self.name))
        object.__setattr__(self, "nodes", _node_pair(where, self.nodes))
        object.__setattr__(self, "k", _positive(where, "k", self.k))
        if self.rest_length is not None:
            object.__setattr__(self, "rest_length", _non_negative(where, "rest_length", self.rest_length))
        object.__setattr__(self, "c", _non_negative(where, "c", self.c))


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
    support does not fix are ignored), interpolated by a cubic spline (continuous velocity and
    acceleration: a rheonomic constraint) and held at the end values outside the table. The
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
    """

    name: str
    node: str
    fx: float = 0.0
    fy: float = 0.0
    mz: float = 0.0
    table: tuple[tuple[float, float, float, float], ...] | None = None
    follower: bool = False

    def __post_init__(self) -> None:
        where = _owner("load", self.name)
        object.__setattr__(self, "name", _name(where, "name", self.name))
        object.__setattr__(self, "node", _name(where, "node", self.node))
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
    """

    name: str
    target: str
    unit: str = ""
    lower: float | None = None
    upper: float = math.inf
    scale: float | None = None

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
    loads: tuple[Load, ...] = ()
    parameters: tuple[Parameter, ...] = ()
    gravity: tuple[float, float] = (0.0, -9.81)
    run: RunSettings = field(default_factory=RunSettings)
    markers: tuple[Any, ...] = ()  # casflex.markers.Marker

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise SceneError(f"name: expected a non-empty string (the scene's name), got {self.name!r}")
        for f in ("nodes", "beams", "springs", "torsion_springs", "bodies", "supports", "loads", "parameters",
                  "markers"):
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
        from casflex.markers import check_markers

        check_markers(self)

    # -- validation -------------------------------------------------------------------------
    def _check_types(self) -> None:
        from casflex.markers import Marker

        kinds = {"nodes": Node, "beams": Beam, "springs": Spring, "torsion_springs": TorsionSpring,
                 "bodies": RigidBody, "supports": Support, "loads": Load, "parameters": Parameter, "markers": Marker}
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
        for f in ("beams", "springs", "torsion_springs", "bodies", "supports", "loads"):
            for i, item in enumerate(getattr(self, f)):
                if item.name == "gravity":
                    raise SceneError(f"{f}[{i}].name: 'gravity' is reserved "
                                     "(parameter targets 'gravity.x', 'gravity.y')")
                if item.name in names:
                    raise SceneError(f"{f}[{i}].name: duplicate name {item.name!r}, already used in {names[item.name]} "
                                     "(names are unique across beams, springs, torsion springs, bodies, supports "
                                     "and loads)")
                names[item.name] = f
                refs = ([(f"nodes[{j}]", r) for j, r in enumerate(item.nodes)] if hasattr(item, "nodes")
                        else [("node", item.node)])
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
            if self.distance(*s.nodes) <= 0.0 and (s.rest_length is None or s.rest_length > 0.0):
                raise SceneError(f"springs[{i}] ({s.name}).nodes: nodes {s.nodes[0]!r} and {s.nodes[1]!r} coincide; "
                                 "a spring needs a direction "
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

    def item(self, name: str) -> Any:
        """The element, support or load called ``name``."""
        for f in ("beams", "springs", "torsion_springs", "bodies", "supports", "loads"):
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
        if isinstance(it, Support):
            raise SceneError(f"{where}: {owner!r} is a support; supports have no numeric properties to identify")
        numeric = [f.name for f in fields(it) if f.name not in _NON_NUMERIC]
        if isinstance(it, RigidBody):
            numeric = ["mass", "inertia"]  # where the centre of mass sits is geometry, not a parameter
        if prop not in numeric:
            raise SceneError(f"{where}: {owner!r} has no numeric property {prop!r}; expected one of {numeric}")
        if isinstance(it, Load) and it.table is not None:
            raise SceneError(f"{where}: load {owner!r} is given as a table; tabulated loads cannot be parameters")
        value = getattr(it, prop)
        if value is None:
            if isinstance(it, Spring):
                value = self.distance(*it.nodes)
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
            target = self.parameter(name).target
            owner, _, prop = target.partition(".")
            if owner == "gravity":
                g = list(scene.gravity)
                g[0 if prop == "x" else 1] = v
                scene = replace(scene, gravity=tuple(g))
                continue
            for f in ("beams", "springs", "torsion_springs", "bodies", "loads"):
                items = list(getattr(scene, f))
                for i, it in enumerate(items):
                    if it.name == owner:
                        try:
                            items[i] = replace(it, **{prop: v})
                        except SceneError as exc:
                            raise SceneError(f"with_values({name}={v!r}): {exc}") from None
                        scene = replace(scene, **{f: tuple(items)})
        return scene

    @property
    def length_scale(self) -> float:
        """Characteristic length (m): the largest distance between two nodes (>= 1e-3)."""
        xs = [n.x for n in self.nodes]
        ys = [n.y for n in self.nodes]
        return max(math.hypot(max(xs) - min(xs), max(ys) - min(ys)), 1e-3)
