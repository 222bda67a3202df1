"""Ideal joint kernels: the constraints Phi(q) = 0 of ONE joint of each kind (Eq. 1, second line),
as named CasADi Functions of its nodes' dofs and properties, mapped over the joints of that kind
like the element kernels (:mod:`casflex.elements.kernels`).

Kinds (``<kind>`` between two nodes a and b, dofs (x_a, y_a, theta_a, x_b, y_b, theta_b);
``<kind>_g`` from the ground to node b, dofs (x_b, y_b, theta_b)). Every kind has the same eight
properties: (ax, ay) the offset of the joint's point in a's frame, R(theta_a0)^T (P - x_a0) (m; for
``_g`` the point P itself, fixed in the ground), (rbx, rby) the point's offset in b's frame (m),
theta_a0, theta_b0 (rad, the nodes' initial rotations; theta_a0 = 0 for ``_g``), (ex, ey) the
joint's axis in the initial configuration (unit vector). With p_a = x_a + R(theta_a) r_a (or P),
p_b = x_b + R(theta_b) r_b and psi = (theta_b - theta_b0) - (theta_a - theta_a0):

- ``hinge``: Phi = p_b - p_a (m, 2 rows);
- ``slider``: Phi = (n_a . (p_b - p_a), psi) with e_a = R(theta_a - theta_a0) e, n_a = e_a turned by
  +90 degrees (m, rad);
- ``weld``: Phi = (p_b - p_a, psi) (m, m, rad);
- ``drive`` (three nodes a, b, c; dofs (a, b, c), nine): Phi = psi - (theta_c - theta_c0) (rad): the
  relative rotation of a and b follows the rotation of a driver node c, which a support moves along
  a path (inverse dynamics drives its hinges so). Its properties: theta_a0, theta_b0 as above, and
  theta_c0 in the slot of ax (the others unused).

A coupled hinge (``hinge_c<key>``, two nodes): a hinge whose point moves on a as the hinge turns, as
OpenSim's custom joints move a knee's centre with its angle: Phi = p_b - p_a - R(theta_a - theta_a0)
(s(psi) - s(0)), with s = (s_x, s_y) SIMM splines of psi (their knots and coefficients as the scene's
:class:`casflex.scene.functions.SimmSpline` holds them, m, in a's frame as it is in the initial configuration;
evaluated here as a chain of ``if_else``, :func:`spline_of`), registered by :func:`coupled_kind`.

The multipliers mu enter the equations of motion as B^T mu (B = dPhi/dq), so the joint exerts
-B^T mu: on b's point the force -mu (hinge, weld), -mu_1 n_a across a slider.

Kernels (SX, common subexpressions eliminated):

- ``joint_<kind>_phi(q, props) -> phi``;
- ``joint_<kind>_velocity(q, qd, props) -> (B, gamma)``: B = dPhi/dq and gamma = (dB/dq qd) qd, the
  acceleration-level term (B qdd + gamma = 0);
- ``joint_<kind>_reaction(q, mu, props) -> f``: B^T mu (the generalised force on the joint's dofs);
- ``joint_<kind>_hht_a<alpha>(q, mu, props) -> (r, K)``: the joint's part of the HHT equations in
  its unknowns w = (q, mu): r = ((1 + alpha) B^T mu, (1 + alpha) Phi) and K = dr/dw, symmetric,
  with the zero block of the multipliers;
- ``joint_<kind>_outputs(q, mu, props) -> y``: ``OUTPUTS[kind]``.
"""

from __future__ import annotations

import functools

import casadi as ca
import numpy as np

from casflex.elements.kernels import Kind

__all__ = ["JOINT_KINDS", "OUTPUTS", "PROPS", "ROWS", "base_kind", "coupled_kind", "joint_kernel", "joint_kind",
           "joint_spec"]

#: Constraint rows of each kind, with the suffixes that name them (``<joint>.<suffix>``).
ROWS = {"hinge": ("x", "y"), "slider": ("across", "theta"), "weld": ("x", "y", "theta"), "drive": ("angle",)}
#: Outputs of each kind (``<joint>.<output>``); see :class:`casflex.scene.items.Joint`.
OUTPUTS = {"hinge": ("fx", "fy", "f_along", "f_across", "angle"), "slider": ("travel", "force", "moment"),
           "weld": ("fx", "fy", "moment"), "drive": ("moment", "angle")}
PROPS = ("ax", "ay", "rbx", "rby", "tha0", "thb0", "ex", "ey")
#: The kernel kinds: ``<kind>`` (two nodes) and ``<kind>_g`` (node b to the ground).
JOINT_KINDS = {f"{k}{g}": Kind(f"{k}{g}", n + len(rows), PROPS, OUTPUTS[k], False)
               for k, rows in ROWS.items() if k != "drive" for g, n in (("", 6), ("_g", 3))}
JOINT_KINDS["drive"] = Kind("drive", 9 + 1, PROPS, OUTPUTS["drive"], False)


#: The shifts of the coupled hinges' kernel kinds: kind -> (s_x, s_y), each a function of psi or None.
_COUPLED: dict[str, tuple] = {}


def joint_kind(kind: str, grounded: bool) -> str:
    """The kernel kind of a scene joint of ``kind`` between two nodes, or to the ground."""
    return f"{kind}_g" if grounded else kind


def coupled_kind(splines) -> str:
    """The kernel kind of a coupled hinge whose point moves by (s_x(psi), s_y(psi)) (module docstring):
    ``splines`` (s_x, s_y), each None or a cubic spline of psi (knots ``x`` rad, ``y`` m and ``coefficients()``,
    as :class:`casflex.scene.functions.SimmSpline`): ``hinge_c<digest of the knots>``, a C name."""
    import hashlib

    tables = tuple(None if f is None else tuple(zip(f.x, f.y, strict=True)) for f in splines)
    key = "hinge_c" + hashlib.sha1(repr(tables).encode()).hexdigest()[:12]
    _COUPLED.setdefault(key, tuple(splines))
    return key


def spline_of(f, x: ca.SX) -> ca.SX:
    """The cubic spline ``f`` (knots ``f.x``, ``f.y`` and ``f.coefficients()`` (b, c, d): y_k + b_k s + c_k s^2 +
    d_k s^3 on [x_k, x_k+1], linear beyond the knots) of a CasADi expression x: a chain of if_else over the knots."""
    # Python floats: a numpy scalar meeting an SX goes through numpy's dispatch first, six times as slow (the
    # same expression; the muscles' paths build some 20 of these splines)
    b, c, d = (np.asarray(v, dtype=float).tolist() for v in f.coefficients())
    xk, yk = np.asarray(f.x, dtype=float).tolist(), np.asarray(f.y, dtype=float).tolist()
    out = yk[-1] + (x - xk[-1]) * b[-1]
    for k in range(len(xk) - 2, -1, -1):
        s = x - xk[k]
        out = ca.if_else(x < xk[k + 1], yk[k] + s * (b[k] + s * (c[k] + s * d[k])), out)
    return ca.if_else(x < xk[0], yk[0] + (x - xk[0]) * b[0], out)


def shift(splines, psi):
    """The coupled hinge's point's move s(psi) - s(0) (2,) in a's initial frame; ``splines`` its (s_x, s_y)
    (:func:`coupled_kind`), psi symbolic."""
    return ca.vertcat(*[0.0 * psi if f is None else spline_of(f, psi) - f(0.0) for f in splines])


def coupled_splines(kind: str):
    """(s_x, s_y) of a coupled hinge's kernel kind (:func:`coupled_kind`)."""
    return _COUPLED[kind]


def base_kind(kind: str) -> str:
    """The scene joint kind of a kernel kind (``hinge`` of ``hinge_g`` and ``hinge_c<key>``)."""
    return "hinge" if kind.startswith("hinge_c") else kind.removesuffix("_g")


def joint_spec(kind: str) -> Kind:
    """The kernel :class:`~casflex.elements.kernels.Kind` of a joint kernel kind."""
    return JOINT_KINDS["hinge" if kind.startswith("hinge_c") else kind]


def _rot(th: ca.SX, v: ca.SX) -> ca.SX:
    c, s = ca.cos(th), ca.sin(th)
    return ca.vertcat(c * v[0] - s * v[1], s * v[0] + c * v[1])


def _perp(v: ca.SX) -> ca.SX:
    return ca.vertcat(-v[1], v[0])


class _Joint:
    """One symbolic joint of a kernel kind: its points, relative rotation and constraints."""

    def __init__(self, kind: str, q: ca.SX, pr: ca.SX):
        self.base, grounded = base_kind(kind), kind.endswith("_g")
        if kind == "drive":  # a, b, then the driver c
            self.psi = (q[5] - pr[5]) - (q[2] - pr[4])
            self.drive = self.psi - (q[8] - pr[0])
            return
        b = q[-3:]
        self.p_b = b[:2] + _rot(b[2], pr[2:4])
        self.turn_b = b[2] - pr[5]
        if grounded:
            self.p_a, self.turn_a = pr[0:2], ca.SX(0)
        else:
            self.p_a, self.turn_a = q[:2] + _rot(q[2], pr[0:2]), q[2] - pr[4]
        self.psi = self.turn_b - self.turn_a
        if kind in _COUPLED:  # the point on a moves with psi
            self.p_a = self.p_a + _rot(self.turn_a, shift(_COUPLED[kind], self.psi))
        self.e = pr[6:8]

    def phi(self) -> ca.SX:
        if self.base == "drive":
            return self.drive
        d = self.p_b - self.p_a
        if self.base == "hinge":
            return d
        if self.base == "slider":
            return ca.vertcat(ca.dot(_perp(_rot(self.turn_a, self.e)), d), self.psi)
        return ca.vertcat(d, self.psi)

    def outputs(self, mu: ca.SX) -> ca.SX:
        if self.base == "drive":  # the moment on b (a gets its opposite), the relative rotation
            return ca.vertcat(-mu, self.psi)
        if self.base == "hinge":
            f, e_b = -mu, _rot(self.turn_b, self.e)
            return ca.vertcat(f, ca.dot(f, e_b), ca.dot(f, _perp(e_b)), self.psi)
        if self.base == "slider":
            return ca.vertcat(ca.dot(_rot(self.turn_a, self.e), self.p_b - self.p_a), -mu[0], -mu[1])
        return -mu


@functools.cache
def joint_kernel(kind: str, what: str, alpha: float = 0.0) -> ca.Function:
    """The kernel ``what`` (phi, velocity, reaction, hht, outputs) of joint kernel kind ``kind``;
    ``alpha``: the HHT alpha of ``hht`` (its weight 1 + alpha)."""
    spec = joint_spec(kind)
    nq, k = spec.n_dof - len(ROWS[base_kind(kind)]), len(ROWS[base_kind(kind)])
    q, qd, mu, pr = ca.SX.sym("q", nq), ca.SX.sym("qd", nq), ca.SX.sym("mu", k), ca.SX.sym("props", len(PROPS))
    j = _Joint(kind, q, pr)
    phi = j.phi()
    B = ca.jacobian(phi, q)
    name, cse = f"joint_{kind}_{what}", {"cse": True}
    if what == "phi":
        return ca.Function(name, [q, pr], [phi], ["q", "props"], ["phi"], cse)
    if what == "velocity":
        gamma = ca.jtimes(ca.mtimes(B, qd), q, qd)
        return ca.Function(name, [q, qd, pr], [ca.densify(B), gamma], ["q", "qd", "props"], ["B", "gamma"], cse)
    if what == "reaction":
        return ca.Function(name, [q, mu, pr], [ca.mtimes(B.T, mu)], ["q", "mu", "props"], ["f"], cse)
    if what == "outputs":
        return ca.Function(name, [q, mu, pr], [j.outputs(mu)], ["q", "mu", "props"], ["y"], cse)
    if what == "hht":
        w = ca.vertcat(q, mu)
        r = (1.0 + alpha) * ca.vertcat(ca.mtimes(B.T, mu), phi)
        return ca.Function(f"joint_{kind}_hht_a{round(-alpha * 1e6)}", [q, mu, pr], [r, ca.densify(ca.jacobian(r, w))],
                           ["q", "mu", "props"], ["r", "K"], cse)
    raise ValueError(f"what: unknown joint kernel {what!r}")
