"""Element kernels: the named CasADi Functions of ONE element of each kind, in its own dofs and
properties, that :mod:`casflex.model.assembly` maps over every element of that kind.

Kinds and their element dofs and properties (a property may be a parameter of the scene):

- ``beam``: (x_a, y_a, theta_a, x_b, y_b, theta_b); L0 (m), off_a, off_b (rad: beta0 - theta0 at
  each end), E (Pa), A (m^2), I (m^4), rho (kg/m^3), rotary (1 adds the section's rotary inertia);
- ``spring``: (x_a, y_a, x_b, y_b); k (N/m), rest (m);
- ``spring0``: a spring of rest length zero (smooth where the nodes meet); k (N/m);
- ``torsion``: (theta_a, theta_b); kt (N m/rad), rest (rad);
- ``damper``: (x_a, y_a, x_b, y_b); c (N s/m): a viscous damper along the line of its nodes,
  Rayleigh function D = c/2 (dL/dt)^2 (its nodes must stay apart, as a spring's of rest length > 0);
- ``damper0``: the damper of a zero-length spring (a bushing), D = c/2 |v_b - v_a|^2;
- ``tdamper``: (theta_a, theta_b); ct (N m s/rad), D = ct/2 (theta_b' - theta_a')^2;
- ``bdamper``: a beam element's dofs; L0, E, A, I, beta (s): stiffness-proportional damping of its
  co-rotational deformation rates e' = (L', tha', thb'), D = beta U(e') with U the element's strain
  energy as a quadratic form, beta/2 e'^T K_l e' (a rigid motion has e' = 0 and is not damped);
- ``body``: (x, y, theta) of its node; m (kg), J (kg m^2, about the centre of mass), rx, ry (m: the
  centre of mass from the node in the node's frame, c = (x, y) + R(theta) r). T = m/2 |c'|^2 +
  J/2 theta'^2, V_g = -m g . c; its inertia term is Lagrange's in either form (the paper's
  form concerns beams): h = -m R(theta) r theta'^2 on x, y;
- ``follower``: (x, y, theta) of its node; fx, fy (N): a force R(theta) (fx, fy) that turns with the
  node. Not conservative: it joins h (as -R(theta) f, a force on the left-hand side that depends on
  q only) with its load stiffness dh/dq, non-symmetric in general; ``dissipation`` gives minus the
  power it supplies, -R(theta) f . (x', y') (W), so the energy balance holds as for dampers.

A damper's force dD/dqd is velocity dependent: it joins the inertia term h (in ``forces``,
``scale`` and the HHT kernels, with its exact tangents in q and qd); ``dissipation`` gives its
power qd . dD/dqd = 2 D (W).

Kernels (all SX, common subexpressions eliminated), with ``g`` the gravity vector (m/s^2):

- ``<kind>_energy(q, qd, props, g) -> (kinetic, elastic, gravity)`` (J);
- ``<kind>_forces(q, qd, props, g) -> (h, f_int, g)``: inertia, elastic and gravity forces;
- ``<kind>_mass(q, props) -> M`` (dense, n_dof x n_dof);
- ``<kind>_outputs(q, qd, props) -> y``: the joint outputs of the element (``Kind.outputs``; a
  damper's force, N or N m, as its spring reports its own: along the line of the nodes, tension
  positive; a bushing's on node b; a torsion damper's moment);
- ``<kind>_rotations(q, props) -> theta_l``: local end rotations (beams);
- ``<kind>_dissipation(q, qd, props) -> P``: power taken out by a damper or follower load (W);
- ``<kind>_scale(q, qd, props, g) -> (m, c, k)``: diagonals of M, dh/dqd and d(f_int - g)/dq;
- ``<kind>_hht<tag>(q, qd, qdd, [qa,] props, g, c) -> (r, K)`` and ``..._r`` (r only): the
  element's part of the HHT residual r = M(qa) qdd + (1 + alpha) (h + f_int - g) and its exact
  tangent K = dr/dq along the Newmark relations, c = (gamma / (beta h), 1 / (beta h^2)).

Kernels are cached per process: they depend on the kind (and the HHT settings) only.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import casadi as ca

from casflex.elements.beam import BeamElement
from casflex.elements.springs import LinearSpring, TorsionalSpring

__all__ = ["DAMPERS", "NONCONSERVATIVE", "KINDS", "Kind", "kernel", "hht_kernel"]


@dataclass(frozen=True)
class Kind:
    """An element kind: its dof count, property names and joint outputs."""

    name: str
    n_dof: int
    props: tuple[str, ...]
    outputs: tuple[str, ...]
    massive: bool


KINDS = {
    "beam": Kind("beam", 6, ("L0", "off_a", "off_b", "E", "A", "I", "rho", "rotary"), ("N", "V", "Ma", "Mb"), True),
    "spring": Kind("spring", 4, ("k", "rest"), ("force", "length", "fx", "fy"), False),
    "spring0": Kind("spring0", 4, ("k",), ("force", "length", "fx", "fy"), False),
    "torsion": Kind("torsion", 2, ("kt", "rest"), ("moment",), False),
    "damper": Kind("damper", 4, ("c",), ("damper_force",), False),
    "damper0": Kind("damper0", 4, ("c",), ("damper_fx", "damper_fy"), False),
    "tdamper": Kind("tdamper", 2, ("ct",), ("damper_moment",), False),
    "bdamper": Kind("bdamper", 6, ("L0", "E", "A", "I", "beta"), (), False),
    "body": Kind("body", 3, ("m", "J", "rx", "ry"), (), True),
    "follower": Kind("follower", 3, ("fx", "fy"), (), False),
}
#: Springs and dampers whose ends are points off their nodes: the plain kind's law on the points
#: x + R(theta) r, with the points' offsets r in their nodes' frames as four more properties.
AT_POINTS = {"spring": "ospring", "spring0": "ospring0", "damper": "odamper", "damper0": "odamper0"}
KINDS.update({o: Kind(o, 6, (*KINDS[k].props, "rax", "ray", "rbx", "rby"), KINDS[k].outputs, False)
              for k, o in AT_POINTS.items()})
_PLAIN = {o: k for k, o in AT_POINTS.items()}

#: Kinds whose force depends on the velocities only (no energy, mass or outputs).
DAMPERS = ("damper", "damper0", "tdamper", "bdamper", "odamper", "odamper0")
#: Kinds with no potential: their power is reported by ``dissipation`` instead of an energy.
NONCONSERVATIVE = (*DAMPERS, "follower")


class _Element:
    """Uniform view of one symbolic element: energies, forces and their tangents, outputs."""

    def __init__(self, kind: str, pr: ca.SX):
        self.kind = kind
        if kind in _PLAIN:  # the plain element on the end points (x_a, y_a, x_b, y_b)
            self.plain, self.r = _Element(_PLAIN[kind], pr[:-4]), pr[-4:]
        elif kind == "beam":
            self.beam = BeamElement("e", pr[0], (pr[1], pr[2]), pr[3], pr[4], pr[5], pr[6], rotary_inertia=pr[7])
        elif kind == "spring":
            self.spring = LinearSpring("e", pr[0], pr[1])
        elif kind == "spring0":
            self.spring = LinearSpring("e", pr[0], 0.0)
        elif kind == "torsion":
            self.spring = TorsionalSpring("e", pr[0], pr[1])
        elif kind == "body":
            self.m, self.J, self.r = pr[0], pr[1], pr[2:4]
        elif kind == "follower":
            self.f = pr[0:2]
        elif kind == "bdamper":
            self.props = pr
        else:
            self.c = pr[0]

    def _body_offset(self, q: ca.SX) -> tuple[ca.SX, ca.SX]:
        """u = R(theta) r, the centre of mass from the node (m), and du/dtheta."""
        c, s = ca.cos(q[2]), ca.sin(q[2])
        u = ca.vertcat(c * self.r[0] - s * self.r[1], s * self.r[0] + c * self.r[1])
        return u, ca.vertcat(-u[1], u[0])

    def _ends(self, q: ca.SX) -> ca.SX:
        """The end points (x_a, y_a, x_b, y_b) = (x + R(theta) r)_a,b (m)."""
        ends = []
        for j, r in ((0, self.r[0:2]), (3, self.r[2:4])):
            c, s = ca.cos(q[j + 2]), ca.sin(q[j + 2])
            ends.append(q[j:j + 2] + ca.vertcat(c * r[0] - s * r[1], s * r[0] + c * r[1]))
        return ca.vertcat(*ends)

    def _points(self, q: ca.SX, qd: ca.SX) -> tuple[ca.SX, ca.SX]:
        """The end points (m) and their velocities (m/s)."""
        P = self._ends(q)
        return P, ca.jtimes(P, q, qd)

    def rayleigh(self, q: ca.SX, qd: ca.SX) -> ca.SX:
        """The damper's Rayleigh dissipation function D(q, qd) (W / 2); 0 for other kinds."""
        if self.kind in _PLAIN:
            return self.plain.rayleigh(*self._points(q, qd))
        if self.kind == "damper":
            d = q[2:] - q[:2]
            rate = ca.dot(d, qd[2:] - qd[:2]) / ca.norm_2(d)  # dL/dt
            return 0.5 * self.c * rate**2
        if self.kind == "damper0":
            return 0.5 * self.c * ca.sumsqr(qd[2:] - qd[:2])
        if self.kind == "tdamper":
            return 0.5 * self.c * (qd[1] - qd[0]) ** 2
        if self.kind == "bdamper":
            L0, E, A, I, beta = (self.props[i] for i in range(5))
            d, v = q[3:5] - q[0:2], qd[3:5] - qd[0:2]
            L2 = ca.sumsqr(d)
            rate_L = ca.dot(d, v) / ca.sqrt(L2)
            rate_chord = (d[0] * v[1] - d[1] * v[0]) / L2
            ra, rb = qd[2] - rate_chord, qd[5] - rate_chord
            return beta * (E * A / (2 * L0) * rate_L**2 + E * I / L0 * (2 * ra**2 + 2 * ra * rb + 2 * rb**2))
        return ca.SX(0)

    def follower_force(self, q: ca.SX) -> ca.SX:
        """R(theta) f: the follower load on the node's x, y (N)."""
        c, s = ca.cos(q[2]), ca.sin(q[2])
        return ca.vertcat(c * self.f[0] - s * self.f[1], s * self.f[0] + c * self.f[1])

    def power(self, q: ca.SX, qd: ca.SX) -> ca.SX:
        """Power taken out of the system (W): 2 D for a damper, minus the follower load's power."""
        if self.kind == "follower":
            return -ca.dot(self.follower_force(q), qd[:2])
        return 2 * self.rayleigh(q, qd)

    def strain(self, q: ca.SX) -> ca.SX:
        if self.kind == "ospring" or self.kind == "ospring0":
            return self.plain.strain(self._ends(q))
        if self.kind in NONCONSERVATIVE or self.kind == "body":
            return ca.SX(0)
        if self.kind == "beam":
            return self.beam.strain_energy(q)
        if self.kind == "torsion":
            return self.spring.strain_energy(q[0], q[1])
        return self.spring.strain_energy(q[:2], q[2:])

    def gravity(self, q: ca.SX, g: ca.SX) -> ca.SX:
        if self.kind == "body":
            return -self.m * ca.dot(g, q[:2] + self._body_offset(q)[0])
        return self.beam.gravity_energy(q, g) if self.kind == "beam" else ca.SX(0)

    def mass_terms(self, q: ca.SX, a: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX]:
        n = q.numel()
        if self.kind == "body":
            u, du = self._body_offset(q)
            m = self.m
            M = ca.SX.zeros(3, 3)
            M[0, 0] = M[1, 1] = m
            M[0, 2] = M[2, 0] = m * du[0]
            M[1, 2] = M[2, 1] = m * du[1]
            M[2, 2] = self.J + m * ca.sumsqr(u)
            Ma = ca.mtimes(M, a)
            return Ma, M, ca.jacobian(Ma, q)
        if self.kind != "beam":
            return ca.SX.zeros(n), ca.SX.zeros(n, n), ca.SX.zeros(n, n)
        return self.beam.mass_terms(q, a)

    def inertia_terms(self, q: ca.SX, qd: ca.SX, form: str) -> tuple[ca.SX, ca.SX, ca.SX]:
        """(h, dh/dq, dh/dqd): the velocity-dependent forces, a damper's included."""
        n = q.numel()
        if self.kind in DAMPERS:
            f = ca.gradient(self.rayleigh(q, qd), qd)
            return f, ca.jacobian(f, q), ca.jacobian(f, qd)
        if self.kind == "follower":
            f = ca.vertcat(-self.follower_force(q), 0)
            return f, ca.jacobian(f, q), ca.SX.zeros(n, n)
        if self.kind == "body":
            f = ca.vertcat(-self.m * self._body_offset(q)[0] * qd[2] ** 2, 0)
            return f, ca.jacobian(f, q), ca.jacobian(f, qd)
        if self.kind != "beam":
            return ca.SX.zeros(n), ca.SX.zeros(n, n), ca.SX.zeros(n, n)
        return self.beam.inertia_terms(q, qd, form)

    def kinetic(self, q: ca.SX, qd: ca.SX) -> ca.SX:
        if self.kind == "body":
            vc = qd[:2] + self._body_offset(q)[1] * qd[2]
            return 0.5 * self.m * ca.sumsqr(vc) + 0.5 * self.J * qd[2] ** 2
        return self.beam.kinetic_energy(q, qd) if self.kind == "beam" else ca.SX(0)

    def outputs(self, q: ca.SX, qd: ca.SX) -> ca.SX:
        if self.kind in _PLAIN:  # the plain element's, at the end points: forces on point b
            Ps, Pds = ca.SX.sym("P", 4), ca.SX.sym("Pd", 4)  # symbols: a damper's output differentiates in Pd
            return ca.substitute([self.plain.outputs(Ps, Pds)], [Ps, Pds], list(self._points(q, qd)))[0]
        if self.kind in DAMPERS:  # the damper's force dD/dqd as the spring's outputs give it
            f = ca.gradient(self.rayleigh(q, qd), qd)
            if self.kind == "damper":  # along the line of the nodes, tension positive: c dL/dt
                d = q[2:] - q[:2]
                return ca.dot(f[2:], d) / ca.norm_2(d)
            if self.kind == "bdamper":
                return ca.SX(0, 1)
            return -f[2:] if self.kind == "damper0" else f[1]  # on node b; the moment, as a torsion spring's
        if self.kind in NONCONSERVATIVE or self.kind == "body":
            return ca.SX(0, 1)
        if self.kind == "beam":
            return self.beam.end_forces(q)
        if self.kind == "torsion":
            return ca.vertcat(*self.spring.outputs(q[0], q[1]).values())
        return ca.vertcat(*self.spring.outputs(q[:2], q[2:]).values())


def _symbols(kind: str) -> tuple[Kind, ca.SX, ca.SX, ca.SX, ca.SX, _Element]:
    k = KINDS[kind]
    q, qd = ca.SX.sym("q", k.n_dof), ca.SX.sym("qd", k.n_dof)
    pr, g = ca.SX.sym("props", len(k.props)), ca.SX.sym("g", 2)
    return k, q, qd, pr, g, _Element(kind, pr)


CSE = {"cse": True}  # common subexpression elimination


@functools.cache
def kernel(kind: str, what: str, form: str = "lagrange") -> ca.Function:
    """The kernel ``what`` (energy, forces, mass, outputs, rotations, dissipation, scale) of element ``kind``;
    ``form``: the inertia form of ``forces`` and ``scale`` (``"lagrange"`` or ``"seed"``)."""
    k, q, qd, pr, g, el = _symbols(kind)
    name = f"{kind}_{what}"
    if what == "energy":
        return ca.Function(name, [q, qd, pr, g], [el.kinetic(q, qd), el.strain(q), el.gravity(q, g)],
                           ["q", "qd", "props", "g"], ["kinetic", "elastic", "gravity"], CSE)
    if what == "forces":
        h = el.inertia_terms(q, qd, form)[0]
        return ca.Function(name, [q, qd, pr, g], [h, ca.gradient(el.strain(q), q), -ca.gradient(el.gravity(q, g), q)],
                           ["q", "qd", "props", "g"], ["h", "f_int", "f_g"], CSE)
    if what == "mass":
        return ca.Function(name, [q, pr], [ca.densify(el.mass_terms(q, qd)[1])], ["q", "props"], ["M"], CSE)
    if what == "outputs":
        return ca.Function(name, [q, qd, pr], [el.outputs(q, qd)], ["q", "qd", "props"], ["y"], CSE)
    if what == "rotations":
        kin = el.beam.kinematics(q)
        return ca.Function(name, [q, pr], [ca.vertcat(kin["tha"], kin["thb"])], ["q", "props"], ["theta_l"], CSE)
    if what == "dissipation":
        return ca.Function(name, [q, qd, pr], [el.power(q, qd)], ["q", "qd", "props"], ["P"], CSE)
    if what == "scale":
        _, M, _ = el.mass_terms(q, qd)
        _, _, C = el.inertia_terms(q, qd, form)
        K = ca.hessian(el.strain(q) + el.gravity(q, g), q)[0]
        return ca.Function(name, [q, qd, pr, g], [ca.diag(M), ca.diag(C), ca.diag(K)],
                           ["q", "qd", "props", "g"], ["m", "c", "k"], CSE)
    raise ValueError(f"what: unknown kernel {what!r}")


@functools.cache
def hht_kernel(kind: str, alpha: float, form: str, with_tangent: bool, padded: bool = False) -> ca.Function:
    """The element's part of the HHT residual (Eq. 4) and, ``with_tangent``, its exact tangent.

    Inputs q, qd, qdd: the element's dofs at t_{n+1}; qa: its dofs at q_alpha = (1 + alpha) q_{n+1}
    - alpha q_n, where the mass is taken (absent at alpha = 0, where qa = q); c = (gamma / (beta h),
    1 / (beta h^2)). Outputs r = M(qa) qdd + (1 + alpha) (h + f_int - g) and K = dr/dq_{n+1} with
    qd, qdd and qa following q_{n+1} through the Newmark relations (dqd/dq = c[0], dqdd/dq = c[1],
    dqa/dq = 1 + alpha). ``padded``: K as the column vec(K) followed by 0 and 1, so that a map's output holds
    the constants that an assembly gathers beside the entries (:mod:`casflex.integrators.newton_band`).
    """
    k, q, qd, pr, g, el = _symbols(kind)
    qdd = ca.SX.sym("qdd", k.n_dof)
    qa = q if alpha == 0.0 else ca.SX.sym("qa", k.n_dof)
    c = ca.SX.sym("c", 2)
    Ma, M, dMa = el.mass_terms(qa, qdd)
    h, dh_dq, dh_dqd = el.inertia_terms(q, qd, form)
    V = el.strain(q) + el.gravity(q, g)
    f = ca.gradient(V, q)
    w = 1.0 + alpha
    r = Ma + w * (h + f)
    ins = [q, qd, qdd] + ([] if alpha == 0.0 else [qa]) + [pr, g, c]
    names = ["q", "qd", "qdd"] + ([] if alpha == 0.0 else ["qa"]) + ["props", "g", "c"]
    tag = f"{kind}_hht_a{round(-alpha * 1e6)}_{form}"  # alpha in the name: one C symbol per variant
    if not with_tangent:
        return ca.Function(f"{tag}_r", ins, [r], names, ["r"], CSE)
    K = ca.densify(c[1] * M + w * dMa + w * (dh_dq + ca.jacobian(f, q) + c[0] * dh_dqd))
    if padded:
        return ca.Function(f"{tag}_padded", ins, [r, ca.densify(ca.vertcat(ca.vec(K), 0, 1))], names, ["r", "K"], CSE)
    return ca.Function(tag, ins, [r, K], names, ["r", "K"], CSE)
