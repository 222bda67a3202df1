"""Co-rotational Euler-Bernoulli beam element with consistent mass (2D).

Crisfield (1991), Vol. 1, Sec. 7.4: the chord of the element carries its rigid translation and
rotation; what remains is an axial stretch u = L - L0 and two local end rotations
theta_l = phi - beta (phi the nodal triad angle, beta the chord angle). The chord angle is
beta = atan2(dy, dx) and each local rotation is phi - beta wrapped into [-pi, pi) by a floor
(whose derivative is zero), so the local rotations stay continuous when the chord angle passes
+-pi and when nodes turn through full revolutions, and their derivatives are those of phi - beta.

Mass: the consistent mass of a constant-section beam (Dhatt & Batoz 1990), rotated with the
chord, M(q) = R(beta)^T M_l R(beta) (the paper's Eq. 2 context); kinetic energy
T = 1/2 qd^T M(q) qd.

The reference configuration enters through three numbers per element: the length L0 and the
offsets beta0 - theta0_a, beta0 - theta0_b of the nodal rotations at which the element is
straight and stress-free. They, and E, A, I, rho, may be numbers or CasADi symbols, so one
symbolic element serves every element of a mesh (:mod:`casflex.model.assembly`).

Inertia forces and their exact tangents (:meth:`BeamElement.inertia_terms`) are assembled from
derivatives taken with respect to the chord angle alone: M depends on q only through beta, so
d(M a)/dq = (dM/dbeta a) grad(beta)^T, and likewise for the velocity terms. Each factor is a
CasADi derivative of the element's own expressions; the chain rule is written out because
differentiating the 6-vector M(beta(q)) qdd in six directions at once repeats the work of the
trigonometry in every direction (3x the operations for the same numbers, to round-off).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca

Scalar = float | ca.SX

__all__ = ["BeamElement", "local_mass", "wrap_angle"]


def wrap_angle(x: ca.SX) -> ca.SX:
    """x wrapped into [-pi, pi) (rad); the derivative is 1 (the floor contributes none)."""
    return x - 2 * math.pi * ca.floor((x + math.pi) / (2 * math.pi))


def local_mass(m: Scalar, L: Scalar, rho_I: Scalar | None = None) -> ca.SX:
    """Consistent mass (6x6) in local dofs (u_a, v_a, th_a, u_b, v_b, th_b).

    m = rho A L0 (kg), L = L0 (m). With ``rho_I`` (kg m) the rotary inertia of the cross-section
    is added (Przemieniecki's matrix rho I / (30 L) [...]).
    """
    M = ca.SX.zeros(6, 6)
    ax = m / 6.0
    M[0, 0] = M[3, 3] = 2 * ax
    M[0, 3] = M[3, 0] = ax
    c = m / 420.0
    bend = [[156, 22 * L, 54, -13 * L], [22 * L, 4 * L**2, 13 * L, -3 * L**2],
            [54, 13 * L, 156, -22 * L], [-13 * L, -3 * L**2, -22 * L, 4 * L**2]]
    idx = [1, 2, 4, 5]
    for i in range(4):
        for j in range(4):
            M[idx[i], idx[j]] += c * bend[i][j]
    if rho_I is not None:
        r = rho_I / (30.0 * L)
        rot = [[36, 3 * L, -36, 3 * L], [3 * L, 4 * L**2, -3 * L, -(L**2)],
               [-36, -3 * L, 36, -3 * L], [3 * L, -(L**2), -3 * L, 4 * L**2]]
        for i in range(4):
            for j in range(4):
                M[idx[i], idx[j]] += r * rot[i][j]
    return M


def _rotated(beta: ca.SX, Ml: ca.SX) -> ca.SX:
    """R(beta)^T Ml R(beta), R rotating both nodes' translations into the chord frame."""
    c, s = ca.cos(beta), ca.sin(beta)
    R = ca.SX.zeros(6, 6)
    for o in (0, 3):
        R[o, o] = R[o + 1, o + 1] = c
        R[o, o + 1] = s
        R[o + 1, o] = -s
        R[o + 2, o + 2] = 1
    return ca.mtimes([R.T, Ml, R])


@dataclass(frozen=True)
class BeamElement:
    """One co-rotational element of a beam.

    Reference data: length ``L0`` (m) and ``offsets`` = (beta0 - theta0_a, beta0 - theta0_b)
    (rad), beta0 the initial chord angle and theta0 the initial nodal rotations (build them with
    :meth:`between`). Properties E (Pa), A (m^2), I (m^4), rho (kg/m^3). Any of these may be a
    number or a CasADi symbol.
    """

    name: str
    L0: Scalar
    offsets: tuple[Scalar, Scalar]
    E: Scalar
    A: Scalar
    I: Scalar  # noqa: E741
    rho: Scalar
    rotary_inertia: bool | Scalar = False  # a symbol: a weight (0 or 1) of the section's rotary inertia

    @classmethod
    def between(cls, name: str, X0: tuple[float, float, float, float], theta0: tuple[float, float], *,
                E: Scalar, A: Scalar, I: Scalar, rho: Scalar, rotary_inertia: bool = False) -> BeamElement:  # noqa: E741
        """The element from its initial end positions X0 = (xa, ya, xb, yb) (m) and nodal
        rotations theta0 (rad), at which it is straight and stress-free."""
        xa, ya, xb, yb = X0
        beta0 = math.atan2(yb - ya, xb - xa)
        return cls(name, math.hypot(xb - xa, yb - ya), (beta0 - theta0[0], beta0 - theta0[1]),
                   E, A, I, rho, rotary_inertia)

    @property
    def mass_total(self) -> Scalar:
        return self.rho * self.A * self.L0

    def kinematics(self, qe: ca.SX) -> dict[str, ca.SX]:
        """Chord length L, angle beta, direction (c, s) and local rotations tha, thb for dofs qe (6,)."""
        dx = qe[3] - qe[0]
        dy = qe[4] - qe[1]
        L = ca.sqrt(dx**2 + dy**2)
        beta = ca.atan2(dy, dx)
        return {"L": L, "beta": beta, "c": dx / L, "s": dy / L,
                "tha": wrap_angle(qe[2] + self.offsets[0] - beta), "thb": wrap_angle(qe[5] + self.offsets[1] - beta)}

    def strain_energy(self, qe: ca.SX) -> ca.SX:
        """U = EA/(2 L0) (L - L0)^2 + (EI/L0)(2 tha^2 + 2 tha thb + 2 thb^2) (J)."""
        k = self.kinematics(qe)
        L0 = self.L0
        return (self.E * self.A / (2 * L0)) * (k["L"] - L0) ** 2 + (self.E * self.I / L0) * (
            2 * k["tha"] ** 2 + 2 * k["tha"] * k["thb"] + 2 * k["thb"] ** 2
        )

    def _local_mass(self) -> ca.SX:
        w = self.rotary_inertia
        if isinstance(w, bool):
            return local_mass(self.mass_total, self.L0, self.rho * self.I if w else None)
        return local_mass(self.mass_total, self.L0, w * self.rho * self.I)

    def kinetic_energy(self, qe: ca.SX, qde: ca.SX) -> ca.SX:
        """T = 1/2 w^T M_l w with w = R(beta) qd the local velocities (J): 1/2 qd^T M(q) qd."""
        beta = self.kinematics(qe)["beta"]
        c, s = ca.cos(beta), ca.sin(beta)
        w = ca.vertcat(c * qde[0] + s * qde[1], -s * qde[0] + c * qde[1], qde[2],
                       c * qde[3] + s * qde[4], -s * qde[3] + c * qde[4], qde[5])
        return 0.5 * ca.dot(w, ca.mtimes(self._local_mass(), w))

    def gravity_energy(self, qe: ca.SX, g: tuple[Scalar, Scalar] | ca.SX) -> ca.SX:
        """V = -m g . c, c the centroid of the Hermite-interpolated deformed element (J).

        c = chord midpoint + n L0/12 (tha - thb), n the chord normal (-s, c).
        """
        k = self.kinematics(qe)
        off = self.L0 / 12.0 * (k["tha"] - k["thb"])
        cx = 0.5 * (qe[0] + qe[3]) - k["s"] * off
        cy = 0.5 * (qe[1] + qe[4]) + k["c"] * off
        return -self.mass_total * (g[0] * cx + g[1] * cy)

    def end_forces(self, qe: ca.SX) -> ca.SX:
        """Elastic end forces in the element frame: [N, V, Ma, Mb] (N, N, N m, N m).

        N axial (tension positive), V = (Ma + Mb)/L0 shear, Ma, Mb end moments.
        """
        k = self.kinematics(qe)
        L0 = self.L0
        N = self.E * self.A * (k["L"] - L0) / L0
        Ma = 2 * self.E * self.I / L0 * (2 * k["tha"] + k["thb"])
        Mb = 2 * self.E * self.I / L0 * (k["tha"] + 2 * k["thb"])
        return ca.vertcat(N, (Ma + Mb) / L0, Ma, Mb)

    # -- inertia forces with exact tangents, by the chain rule through the chord angle ----------
    def _mass_in_beta(self) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX]:
        """(b, M(b), dM/db, d2M/db2) with b a free symbol for the chord angle."""
        b = ca.SX.sym("beta")
        M = _rotated(b, self._local_mass())
        Mp = ca.reshape(ca.jacobian(ca.vec(M), b), 6, 6)
        Mpp = ca.reshape(ca.jacobian(ca.vec(Mp), b), 6, 6)
        return b, M, Mp, Mpp

    def mass_terms(self, qe: ca.SX, a: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX]:
        """(M a, M, d(M(q) a)/dq) for an acceleration a (6,): N, kg, N/m."""
        b, M, Mp, _ = self._mass_in_beta()
        beta = self.kinematics(qe)["beta"]
        M1, Mp1 = ca.substitute([M, Mp], [b], [beta])
        Ma = ca.mtimes(M1, a)
        return Ma, M1, ca.mtimes(ca.mtimes(Mp1, a), ca.gradient(beta, qe).T)

    def inertia_terms(self, qe: ca.SX, qde: ca.SX, form: str = "lagrange") -> tuple[ca.SX, ca.SX, ca.SX]:
        """(h, dh/dq, dh/dqd): the velocity-dependent inertia force h (N, N m) and its exact tangents.

        ``form="lagrange"``: h = Mdot qd - dT/dq = bdot M' qd - (1/2 qd^T M' qd) grad(beta);
        ``form="seed"``: h = Mdot qd = bdot M' qd (the paper's Eq. 2); M' = dM/dbeta,
        bdot = grad(beta) . qd.
        """
        b, _, Mp, Mpp = self._mass_in_beta()
        beta = self.kinematics(qe)["beta"]
        Mp1, Mpp1 = ca.substitute([Mp, Mpp], [b], [beta])
        gb = ca.gradient(beta, qe)
        Hb = ca.hessian(beta, qe)[0]
        bdot = ca.dot(gb, qde)
        Mpv = ca.mtimes(Mp1, qde)
        h = bdot * Mpv
        dh_dq = ca.mtimes(bdot * ca.mtimes(Mpp1, qde), gb.T) + ca.mtimes(Mpv, ca.mtimes(Hb, qde).T)
        dh_dqd = ca.mtimes(Mpv, gb.T) + bdot * Mp1
        if form == "lagrange":
            Tb = 0.5 * ca.dot(qde, Mpv)
            Tbb = 0.5 * ca.dot(qde, ca.mtimes(Mpp1, qde))
            h = h - Tb * gb
            dh_dq = dh_dq - Tbb * ca.mtimes(gb, gb.T) - Tb * Hb
            dh_dqd = dh_dqd - ca.mtimes(gb, Mpv.T)
        return h, dh_dq, dh_dqd
