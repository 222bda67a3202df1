"""assemble(scene) -> Model: the symbolic equations of motion of a scene (Eq. 1).

    M(q) q'' + h(q, q') + f_int(q, p) + B(q)^T lambda - f_ext(t) - g(q) = 0,    Phi(q) = 0

Every term comes from energies by CasADi's automatic differentiation: M = d2T/dqd2,
f_int = dV_el/dq, g = -dV_g/dq, B = dPhi/dq. The velocity-dependent inertia term h has two
forms (``inertia``):

- ``"lagrange"`` (default): h = Mdot q' - dT/dq, from d/dt(dT/dq') - dT/dq; energy consistent.
- ``"seed"``: h = Mbar q' = Mdot q', the paper's Eq. 2 (Mbar_i = Rdot^T M R + R^T M Rdot).

Viscous dampers (a spring's ``c``, a torsion spring's ``ct``) add their forces dD/dq' (D the
Rayleigh dissipation function) to h: they are the other velocity-dependent term.

Only the scene's elements and supports are modelled; properties declared as parameters are
entries of the symbol p (in the scene's parameter order), all others are constants.

Structure is kept: the elements of each kind form a group (:mod:`casflex.model.assembly`) whose kernel
(:mod:`casflex.elements.kernels`, one element's energies, forces, mass and outputs) is mapped
over the group and summed into the global vectors and sparse matrices through constant index
maps. The Functions are MX; evaluated on SX symbols they give the flat expressions.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from casflex.elements import BeamElement
from casflex.elements.joints import OUTPUTS as JOINT_OUTPUTS
from casflex.elements.joints import base_kind
from casflex.elements.kernels import AT_POINTS, DAMPERS, KINDS, NONCONSERVATIVE, kernel
from casflex.model.assembly import ElementGroup, MatrixAssembly, gather, scatter
from casflex.model.constraints import (
    FixedDof,
    constraint_vector,
    gather_at,
    joint_groups,
    joint_phi,
    mapped_joint,
    prescribed,
    split,
    support_constraints,
)
from casflex.scene.items import INERTIA_FORMS
from casflex.scene.scene import Parameter, Scene, SceneError

__all__ = ["Model", "assemble", "INERTIA_FORMS"]


@dataclass(frozen=True, eq=False)
class Model:
    """The assembled symbolic model of a scene.

    Attributes
    ----------
    dof_names : tuple of str, length n_dof
        ``x<node>``, ``y<node>``, ``theta<node>`` per node; user nodes first, in scene order,
        then nodes added by meshing (named ``<beam>.<k>``).
    constraint_names : tuple of str, length n_con
        ``<support>.<x|y|theta>`` (the supports' rows, ``n_fixed``), then the joints' rows
        ``<joint>.<x|y|across|theta>`` (``joint_row_names``).
    output_names : tuple of str
        Joint outputs: ``<spring>.force|length|fx|fy``, ``<torsion>.moment``,
        ``<support>.<dof>`` (reaction exerted by the support), ``<beam>.<element>.N|V|Ma|Mb``,
        ``<joint>.<output>`` (:class:`casflex.scene.Joint`).
    q0, qd0 : ndarray, shape (n_dof,)
        Initial configuration and velocity from the scene.
    p_nominal : ndarray, shape (n_p,)
        Nominal values of the declared parameters.

    segments : tuple of (kind, name, node_a, node_b)
        Beam elements and linear springs with node indices, for drawing.

    Functions (all named, inputs and outputs named): ``energy(q, qd, p) -> (kinetic, elastic,
    gravity)``, ``mass(q, p) -> M``, ``forces(q, qd, p) -> (h, f_int, g)``,
    ``dissipation(q, qd, p) -> P`` (W, the power of the dampers, 0 without them),
    ``follower_power(q, qd, p) -> P`` (W, the power the follower loads supply, 0 without them),
    ``load(t, p) -> f_ext``, ``constraint(q) -> (phi, B)``,
    ``equilibrium(q, qd, qdd, lam, t, p) -> (r, phi)`` (Eq. 11), ``outputs(q, qd, lam, p) -> y``,
    ``local_rotations(q) -> theta_l`` (rad, in (-pi, pi]: the co-rotational end rotations of the
    beam elements, named ``<beam>.<element>.a|b`` in ``local_rotation_names``).
    """

    scene: Scene
    inertia: str
    node_names: tuple[str, ...]
    dof_names: tuple[str, ...]
    is_rotation: np.ndarray
    constraints: tuple[FixedDof, ...]
    parameters: tuple[Parameter, ...]
    p_nominal: np.ndarray
    q0: np.ndarray
    qd0: np.ndarray
    output_names: tuple[str, ...]
    groups: tuple[ElementGroup, ...]
    gravity: ca.Function
    energy: ca.Function
    mass: ca.Function
    forces: ca.Function
    dissipation: ca.Function
    follower_power: ca.Function
    load: ca.Function
    constraint: ca.Function
    equilibrium: ca.Function
    outputs: ca.Function
    local_rotations: ca.Function
    local_rotation_names: tuple[str, ...]
    segments: tuple[tuple[str, str, int, int], ...] = field(default=())
    joint_groups: tuple[ElementGroup, ...] = ()
    joint_row_names: tuple[str, ...] = ()

    @property
    def moving(self) -> bool:
        """Whether a support follows a path (``motion``): the constraints then depend on t."""
        return any(c.path is not None for c in self.constraints)

    @functools.cached_property
    def prescribed(self) -> ca.Function:
        """``prescribed(t) -> (v, vd, vdd)`` (n_con,): the supports' values at t and their rates
        (:func:`casflex.model.constraints.prescribed`); constants and zeros for fixed supports."""
        return prescribed(list(self.constraints))

    def supports_at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(values, rates) of the supports' dofs at t (s), shape (n_con,) each, in constraint order:
        constants and zeros, or where a moving support's path has them."""
        v, vd, _ = (np.array(a, dtype=float).ravel() for a in self.prescribed(t))
        return v, vd

    @property
    def n_dof(self) -> int:
        return len(self.dof_names)

    @functools.cached_property
    def joint_scales(self) -> np.ndarray:
        """(n_mu,): the scale of each joint row, the length scale (m) for a row in metres (hinge x, y,
        a slider's across) and 1 for a row in radians."""
        return np.array([1.0 if r.endswith(".theta") else self.length_scale for r in self.joint_row_names])

    @functools.cached_property
    def joint_rows(self) -> ca.Function:
        """``joint_rows(q, mu) -> (phi, B, H)``: the joints' Phi (n_mu,), B = dPhi/dq (n_mu, n) and
        H = d2(mu^T Phi)/dq2 (n, n), the joints' part of a Lagrangian's tangent; built once per model."""
        q, mu = ca.SX.sym("q", self.n_dof), ca.SX.sym("mu", len(self.joint_row_names))
        phi = self.constraint(q)[0][self.n_fixed:]
        return ca.Function("joint_rows", [q, mu], [phi, ca.jacobian(phi, q), ca.hessian(ca.dot(mu, phi), q)[0]],
                           ["q", "mu"], ["phi", "B", "H"])

    @property
    def n_con(self) -> int:
        """Multipliers: the supports' rows (``n_fixed``), then the joints'."""
        return len(self.constraints) + len(self.joint_row_names)

    @property
    def n_fixed(self) -> int:
        """The supports' rows: dofs held at values (the first multipliers)."""
        return len(self.constraints)

    @property
    def n_p(self) -> int:
        return len(self.parameters)

    @property
    def constraint_names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.constraints) + self.joint_row_names

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    @property
    def length_scale(self) -> float:
        return self.scene.length_scale

    @property
    def tip_node(self) -> str:
        """The scene node farthest from the supports: most elements away (beams, springs, torsion
        springs), ties broken by distance in space; the node summaries and standard figures show
        (node 5 of twobar)."""
        sc = self.scene
        links: dict[str, set[str]] = {n.name: set() for n in sc.nodes}
        for el in (*sc.beams, *sc.springs, *sc.torsion_springs):
            a, b = el.nodes
            links[a].add(b)
            links[b].add(a)
        roots = [s.node for s in sc.supports] or [sc.nodes[0].name]
        hops = dict.fromkeys(roots, 0)
        queue = list(roots)
        for n in queue:  # breadth first: the queue grows while it is read
            for m in sorted(links[n]):
                if m not in hops:
                    hops[m] = hops[n] + 1
                    queue.append(m)
        origin = np.array([[sc.node(r).x, sc.node(r).y] for r in roots])

        def reach(name: str) -> tuple[int, float]:
            xy = np.array([sc.node(name).x, sc.node(name).y])
            return hops.get(name, -1), float(np.min(np.linalg.norm(origin - xy, axis=1)))

        return max((n.name for n in sc.nodes), key=reach)

    def dof(self, name: str) -> int:
        """Index of the dof called ``name`` (e.g. ``"y5"``)."""
        try:
            return self.dof_names.index(name)
        except ValueError:
            raise KeyError(f"unknown dof {name!r}; dofs are {list(self.dof_names)}") from None

    def data_columns(self, channels: tuple[str, ...]) -> np.ndarray:
        """Column of each dof in a recording's ``channels`` (-1 where the dof is not measured). Channels of the
        scene's markers (``x<marker>``, ``y<marker>``) are known channels, but no dof's; ValueError for others."""
        from casflex.model.markers import marker_channels

        markers = marker_channels(self)
        unknown = [c for c in channels if c not in self.dof_names and c not in markers]
        if unknown:
            raise ValueError(f"data: unknown channels {unknown}; the model's dofs are {list(self.dof_names)}"
                             + (f", its markers' channels {list(markers)}" if markers else ""))
        return np.array([channels.index(d) if d in channels else -1 for d in self.dof_names])

    def params(self, values: dict[str, float] | np.ndarray | None = None) -> np.ndarray:
        """Parameter vector p from a {name: value} dict (others nominal), an array, or None."""
        if values is None:
            return self.p_nominal.copy()
        if isinstance(values, dict):
            p = self.p_nominal.copy()
            for k, v in values.items():
                if k not in self.parameter_names:
                    raise KeyError(f"unknown parameter {k!r}; declared: {list(self.parameter_names)}")
                p[self.parameter_names.index(k)] = float(v)
            return p
        p = np.asarray(values, dtype=float).reshape(-1)
        if p.shape != (self.n_p,):
            raise ValueError(f"p: expected {self.n_p} values {list(self.parameter_names)}, got shape {p.shape}")
        return p


def _mesh(scene: Scene):
    """Nodes (user nodes, then mesh nodes) with initial state, and beam elements per beam."""
    nodes = {n.name: (n.x, n.y, n.theta, n.vx, n.vy, n.omega) for n in scene.nodes}
    order = [n.name for n in scene.nodes]
    beam_elems = []  # (beam, k, node_a, node_b)
    for b in scene.beams:
        a, z = b.nodes
        chain = [a]
        for k in range(1, b.elements):
            s = k / b.elements
            name = f"{b.name}.{k}"
            nodes[name] = tuple((1 - s) * va + s * vz for va, vz in zip(nodes[a], nodes[z], strict=True))
            order.append(name)
            chain.append(name)
        chain.append(z)
        beam_elems += [(b, k + 1, chain[k], chain[k + 1]) for k in range(b.elements)]
    return order, nodes, beam_elems


def _groups(scene: Scene, order, nodes, beam_elems, idx, params: tuple[Parameter, ...]) -> tuple[ElementGroup, ...]:
    """The scene's elements by kind, with their dofs and property tables (``params``, the parameters and run-time
    inputs, in slots)."""
    slot_of = {par.target: i for i, par in enumerate(params)}
    out = []

    def group(kind: str, items: list[tuple[str, str, list[int], list[float], tuple]]):
        # items: (element name, scene owner of the properties, dofs, values, per property: the scene field it is
        # ("" for none), or ((field, coefficient), ...) where it is a combination of fields plus a constant)
        if not items:
            return
        base = np.array([it[3] for it in items], dtype=float).T
        slots = []
        for e, it in enumerate(items):
            for r, spec in enumerate(it[4]):
                for fld, coef in (((spec, 1.0),) if isinstance(spec, str) else spec):
                    if f"{it[1]}.{fld}" not in slot_of:
                        continue
                    slots.append((r, e, slot_of[f"{it[1]}.{fld}"], coef))
                    # the row is then its constant part plus coef p (a property that is a field itself: 0 + p)
                    base[r, e] = 0.0 if isinstance(spec, str) else base[r, e] - coef * scene.property_value(
                        f"{it[1]}.{fld}")
        out.append(ElementGroup(kind, tuple(it[0] for it in items), np.array([it[2] for it in items], dtype=int),
                                base, tuple(slots)))

    beams = []
    for b, k, na, nb in beam_elems:
        el = BeamElement.between(f"{b.name}.{k}", (nodes[na][0], nodes[na][1], nodes[nb][0], nodes[nb][1]),
                                 (nodes[na][2], nodes[nb][2]), E=b.E, A=b.A, I=b.I, rho=b.rho)
        beams.append((el.name, b.name, [idx[na] + j for j in range(3)] + [idx[nb] + j for j in range(3)],
                      [el.L0, *el.offsets, b.E, b.A, b.I, b.rho, float(b.rotary_inertia)],
                      ("", "", "", "E", "A", "I", "rho", "rotary_inertia")))
    group("beam", beams)

    def ends(s) -> tuple[list[int], list[float]]:
        """A spring's dofs and, for ends at points off its nodes, the points' offsets in the nodes'
        frames, R(theta0)^T (point - node) (m); only such springs carry their nodes' rotations."""
        if s.point_a is None and s.point_b is None:
            return [idx[s.nodes[0]], idx[s.nodes[0]] + 1, idx[s.nodes[1]], idx[s.nodes[1]] + 1], []
        offsets = []
        for nd, (px, py) in zip(s.nodes, scene.spring_ends(s), strict=True):
            x0, y0, th0 = nodes[nd][:3]
            c, s_ = math.cos(th0), math.sin(th0)
            offsets += [c * (px - x0) + s_ * (py - y0), -s_ * (px - x0) + c * (py - y0)]
        return [idx[nd] + j for nd in s.nodes for j in range(3)], offsets

    springs: dict[str, list] = {"spring": [], "spring0": [], "ospring": [], "ospring0": []}
    zero_names = set()
    for s in scene.springs:
        dofs, offsets = ends(s)
        rest = scene.spring_length(s) if s.rest_length is None else s.rest_length
        if rest == 0.0 and f"{s.name}.rest_length" not in slot_of:  # smooth where the ends meet
            zero_names.add(s.name)
            springs[AT_POINTS["spring0"] if offsets else "spring0"].append(
                (s.name, s.name, dofs, [s.k, *offsets], ("k", "", "", "", "")))
        else:
            springs[AT_POINTS["spring"] if offsets else "spring"].append(
                (s.name, s.name, dofs, [s.k, rest, *offsets], ("k", "rest_length", "", "", "", "")))
    for kind, items in springs.items():
        group(kind, items)
    group("torsion", [(s.name, s.name, [idx[s.nodes[0]] + 2, idx[s.nodes[1]] + 2],
                       [s.kt, nodes[s.nodes[1]][2] - nodes[s.nodes[0]][2] if s.rest_angle is None else s.rest_angle],
                       ("kt", "rest_angle")) for s in scene.torsion_springs])

    # dampers: only those with a coefficient or a parameter on it, so a scene without them is unchanged
    def damped(s, fld: str) -> bool:
        return getattr(s, fld) > 0.0 or f"{s.name}.{fld}" in slot_of

    for kind, bushing in (("damper", False), ("damper0", True)):
        for at_points in (False, True):
            group(AT_POINTS[kind] if at_points else kind,
                  [(s.name, s.name, dofs, [s.c, *offsets], ("c", "", "", "", "")) for s in scene.springs
                   for dofs, offsets in [ends(s)]
                   if damped(s, "c") and (s.name in zero_names) == bushing and bool(offsets) == at_points])
    group("tdamper", [(s.name, s.name, [idx[s.nodes[0]] + 2, idx[s.nodes[1]] + 2], [s.ct], ("ct",))
                      for s in scene.torsion_springs if damped(s, "ct")])
    group("bdamper", [(f"{nm}.damping", owner, dofs, [vals[0], *vals[3:6], b.beta], ("", "E", "A", "I", "beta"))
                      for (nm, owner, dofs, vals, _), (b, *_) in zip(beams, beam_elems, strict=True)
                      if damped(b, "beta")])
    bodies = []
    for bd in scene.bodies:
        x0, y0, th0 = nodes[bd.node][:3]
        dx = (x0 if bd.com_x is None else bd.com_x) - x0
        dy = (y0 if bd.com_y is None else bd.com_y) - y0
        c, s_ = math.cos(th0), math.sin(th0)  # the offset in the node's frame: R(theta0)^T (com - node)
        bodies.append((bd.name, bd.name, [idx[bd.node] + j for j in range(3)],
                       [bd.mass, bd.inertia, c * dx + s_ * dy, -s_ * dx + c * dy],
                       ("mass", "inertia", (("com_x", c), ("com_y", s_)), (("com_x", -s_), ("com_y", c)))))
    group("body", bodies)
    group("follower", [(ld.name, ld.name, [idx[ld.node] + j for j in range(3)], [ld.fx, ld.fy], ("fx", "fy"))
                       for ld in scene.loads if ld.follower])
    return tuple(out)


def _joint_outputs(groups: tuple[ElementGroup, ...], q: ca.MX, mu: ca.MX, n: int) -> tuple[ca.MX, tuple[str, ...]]:
    """The joints' outputs (``casflex.elements.joints.OUTPUTS``) at (q, mu), by kind, and their names."""
    y, names = ca.MX(0, 1), ()
    for grp in groups:
        at, mu_at = split(grp)
        y = ca.vertcat(y, ca.vec(mapped_joint(grp, "outputs", gather_at(q, at), gather_at(mu, mu_at - n),
                                              ca.DM(grp.base))))
        names += tuple(f"{nm}.{o}" for nm in grp.names for o in JOINT_OUTPUTS[base_kind(grp.kind)])
    return y, names


def _input(scene: Scene, target: str) -> Parameter:
    """A run-time input of :func:`assemble` as a parameter (its slot in the property tables, appended to p): a
    beam's ``rotary_inertia`` (its weight, 0 or 1) or a property that could be a parameter (not one already)."""
    owner, _, fld = target.partition(".")
    if fld == "rotary_inertia":
        if owner not in {b.name for b in scene.beams}:
            raise ValueError(f"inputs: {target!r}: no beam {owner!r}")
    else:
        scene.property_value(target, where="inputs")  # an unknown target: SceneError naming it
        if target in {p.target for p in scene.parameters}:
            raise ValueError(f"inputs: {target!r} is a parameter already")
    return Parameter(f"input_{owner}_{fld}", target, lower=-math.inf)


def _value(scene: Scene, target: str) -> float:
    """A parameter's or run-time input's value in ``scene`` (a beam's rotary_inertia: its weight, 0 or 1)."""
    owner, _, fld = target.partition(".")
    if fld == "rotary_inertia":
        return float(scene.item(owner).rotary_inertia)
    return scene.property_value(target)


def assembled(scene: Scene, *, inertia: str | None = None) -> Model:
    """:func:`assemble`'s Model of ``scene``, shared in this process by every call with an equal scene,
    and with it its integrators and compiled code: an identification's refined and alternative models
    are otherwise rebuilt by every fit (twobar: 0.1 s each, as long as 20 simulations of 3 s)."""
    inertia = scene.run.inertia if inertia is None else inertia
    try:
        hash(scene)
    except TypeError:  # a scene holding an unhashable value: its own model
        return assemble(scene, inertia=inertia)
    return _assembled(scene, inertia)


@functools.lru_cache(maxsize=16)
def _assembled(scene: Scene, inertia: str, inputs: tuple[str, ...] = ()) -> Model:
    return assemble(scene, inertia=inertia, inputs=inputs)


def assemble(scene: Scene, *, inertia: str | None = None, inputs: tuple[str, ...] = ()) -> Model:
    """Build the symbolic model of ``scene`` (see the module docstring).

    Parameters
    ----------
    scene : Scene
    inertia : {"lagrange", "seed"}, optional
        Form of the velocity-dependent inertia term; default ``scene.run.inertia``.
    inputs : targets ``"<beam>.rotary_inertia"`` made run-time inputs: parameters of the model appended to
        the scene's (:func:`form_inputs`).
    """
    inertia = scene.run.inertia if inertia is None else inertia
    if inertia not in INERTIA_FORMS:
        raise ValueError(f"inertia: expected one of {INERTIA_FORMS}, got {inertia!r}")
    order, nodes, beam_elems = _mesh(scene)
    idx = {name: 3 * i for i, name in enumerate(order)}
    dof_names = tuple(f"{d}{n}" for n in order for d in ("x", "y", "theta"))
    n = len(dof_names)
    q0 = np.array([v for name in order for v in nodes[name][:3]], dtype=float)
    qd0 = np.array([v for name in order for v in nodes[name][3:]], dtype=float)
    is_rot = np.array([i % 3 == 2 for i in range(n)])
    params = scene.parameters + tuple(_input(scene, t) for t in inputs)
    groups = _groups(scene, order, nodes, beam_elems, idx, params)
    slotted = {k for grp in groups for *_, k, _ in grp.slots}
    loads = {ld.name for ld in scene.loads}
    for k, par in enumerate(params[len(scene.parameters):], start=len(scene.parameters)):
        if k not in slotted and par.target.partition(".")[0] not in loads | {"gravity"}:
            raise ValueError(f"inputs: {par.target!r} is not a number in the model's equations")

    cons = support_constraints(scene, {d: i for i, d in enumerate(dof_names)}, q0)
    jgroups, jrows = joint_groups(scene, nodes, idx, n)
    used = np.zeros(n, dtype=bool)
    for grp in groups:
        used[grp.dofs.ravel()] = True
    for grp in jgroups:
        used[split(grp)[0].ravel()] = True
    for c in cons:
        used[c.dof] = True
    if not used.all():
        free = [dof_names[i] for i in np.flatnonzero(~used)]
        raise SceneError(f"dofs {free} are acted on by nothing (no beam, spring, joint or support): "
                         "the equations of motion would be singular; add a support for them")

    # -- small SX pieces: gravity, loads, constraints ------------------------------------------
    ps = ca.SX.sym("p", len(params))
    symbol = {par.target: ps[i] for i, par in enumerate(params)}
    gravity = ca.Function("gravity", [ps], [ca.vertcat(*(symbol.get(f"gravity.{c}", scene.gravity[i])
                                                         for i, c in enumerate("xy")))], ["p"], ["g"])
    ts = ca.SX.sym("t")
    f_ext = ca.SX.zeros(n)
    for ld in scene.loads:
        rows = ld.rows()
        for comp, key in enumerate(("fx", "fy", "mz")):
            if ld.follower and key != "mz":  # an element of kind follower (_groups)
                continue
            if len(rows) == 1:
                value = symbol.get(f"{ld.name}.{key}", rows[0][comp + 1])
            else:
                tt = ca.DM([r[0] for r in rows])
                vv = ca.DM([r[comp + 1] for r in rows])
                tc = ca.fmin(ca.fmax(ts, tt[0]), tt[-1])  # hold the end values outside the table
                value = ca.pw_lin(tc, tt, vv)
            f_ext[idx[ld.node] + comp] += value
            if ld.against is not None:  # an actuator between two nodes: the opposite load on the other
                f_ext[idx[ld.against] + comp] -= value
    load = ca.Function("load", [ts, ps], [f_ext], ["t", "p"], ["f_ext"])
    qs = ca.SX.sym("q", n)
    phi = ca.vertcat(constraint_vector(cons, qs), joint_phi(jgroups, qs))
    constraint = ca.Function("constraint", [qs], [phi, ca.jacobian(phi, qs)], ["q"], ["phi", "B"])

    # -- structured Functions: element kernels mapped over the groups ---------------------------
    q, qd, qdd = ca.MX.sym("q", n), ca.MX.sym("qd", n), ca.MX.sym("qdd", n)
    lam, t, p = ca.MX.sym("lam", len(cons) + len(jrows)), ca.MX.sym("t"), ca.MX.sym("p", len(params))
    g = gravity(p)
    props = [grp.props(p) for grp in groups]

    def mapped(grp: ElementGroup, what: str, *args):
        f = kernel(grp.kind, what, inertia)
        return f.map(f"{f.name()}_{grp.n}", "serial", grp.n, [f.n_in() - 1] if f.name_in()[-1] == "g" else [], [])(
            *args)

    T = V_el = V_g = P_d = P_f = ca.MX(0)
    h = f_int = gf = ca.MX.zeros(n)
    for grp, pr in zip(groups, props, strict=True):
        if grp.kind == "follower":  # its kernel's "dissipation" is minus the power it supplies
            P_f -= ca.sum2(mapped(grp, "dissipation", gather(q, grp), gather(qd, grp), pr))
        elif grp.kind in NONCONSERVATIVE:
            P_d += ca.sum2(mapped(grp, "dissipation", gather(q, grp), gather(qd, grp), pr))
        else:
            e = mapped(grp, "energy", gather(q, grp), gather(qd, grp), pr, g)
            T, V_el, V_g = T + ca.sum2(e[0]), V_el + ca.sum2(e[1]), V_g + ca.sum2(e[2])
        hh, fi, gg = mapped(grp, "forces", gather(q, grp), gather(qd, grp), pr, g)
        h, f_int, gf = h + scatter(hh, grp, n), f_int + scatter(fi, grp, n), gf + scatter(gg, grp, n)
    whole = np.arange(n)
    mass_asm = MatrixAssembly(groups, whole, whole)
    M = mass_asm([mapped(grp, "mass", gather(q, grp), pr) if grp.spec.massive else None
                  for grp, pr in zip(groups, props, strict=True)])
    _, B = constraint(q)
    r = ca.mtimes(M, qdd) + h + f_int + ca.mtimes(B.T, lam) - load(t, p) - gf

    # joint outputs in the scene's order: beams, springs, torsion springs, their dampers, the supports
    out_vals, out_names = [], []
    for grp, pr in zip(groups, props, strict=True):
        if not grp.spec.outputs:  # bodies, follower loads
            continue
        out_vals.append(ca.vec(mapped(grp, "outputs", gather(q, grp), gather(qd, grp), pr)))
        out_names += [f"{nm}.{o}" for nm in grp.names for o in grp.spec.outputs]
    damper_outputs = list(dict.fromkeys(o for kind in DAMPERS for o in KINDS[kind].outputs))
    want = ([f"{b.name}.{k}.{o}" for b, k, _, _ in beam_elems for o in KINDS["beam"].outputs]
            + [f"{s.name}.{o}" for s in scene.springs for o in KINDS["spring"].outputs]
            + [f"{s.name}.{o}" for s in scene.torsion_springs for o in KINDS["torsion"].outputs]
            + [f"{s.name}.{o}" for s in (*scene.springs, *scene.torsion_springs) for o in damper_outputs
               if f"{s.name}.{o}" in out_names])
    y = ca.vertcat(*out_vals)[[out_names.index(w) for w in want]] if want else ca.MX(0, 1)
    y = ca.vertcat(y, -lam[:len(cons)])
    names = tuple(want) + tuple(c.name for c in cons)
    y_j, names_j = _joint_outputs(jgroups, q, lam[len(cons):], n)
    y, names = ca.vertcat(y, y_j), names + names_j
    beams = [grp for grp in groups if grp.kind == "beam"]  # local rotations: geometry only, never parameters
    th_l = ca.vec(mapped(beams[0], "rotations", gather(q, beams[0]), ca.DM(beams[0].base))) if beams else ca.MX(0, 1)
    return Model(
        scene=scene,
        inertia=inertia,
        node_names=tuple(order),
        dof_names=dof_names,
        is_rotation=is_rot,
        constraints=tuple(cons),
        parameters=params,
        p_nominal=np.array([_value(scene, par.target) for par in params], dtype=float),
        q0=q0,
        qd0=qd0,
        output_names=names,
        groups=groups,
        gravity=gravity,
        energy=ca.Function("energy", [q, qd, p], [T, V_el, V_g], ["q", "qd", "p"], ["kinetic", "elastic", "gravity"]),
        mass=ca.Function("mass", [q, p], [M], ["q", "p"], ["M"]),
        forces=ca.Function("forces", [q, qd, p], [h, f_int, gf], ["q", "qd", "p"], ["h", "f_int", "g"]),
        dissipation=ca.Function("dissipation", [q, qd, p], [P_d], ["q", "qd", "p"], ["P"]),
        follower_power=ca.Function("follower_power", [q, qd, p], [P_f], ["q", "qd", "p"], ["P"]),
        load=load,
        constraint=constraint,
        equilibrium=ca.Function("equilibrium", [q, qd, qdd, lam, t, p], [r, constraint(q)[0]],
                                ["q", "qd", "qdd", "lam", "t", "p"], ["r", "phi"]),
        outputs=ca.Function("joint_outputs", [q, qd, lam, p], [y], ["q", "qd", "lam", "p"], ["y"]),
        local_rotations=ca.Function("local_rotations", [q], [th_l], ["q"], ["theta_l"]),
        local_rotation_names=tuple(f"{b.name}.{k}.{e}" for b, k, _, _ in beam_elems for e in "ab"),
        segments=tuple(("beam", f"{b.name}.{k}", idx[na] // 3, idx[nb] // 3) for b, k, na, nb in beam_elems)
        + tuple(("spring", s.name, idx[s.nodes[0]] // 3, idx[s.nodes[1]] // 3) for s in scene.springs),
        joint_groups=jgroups,
        joint_row_names=jrows,
    )
