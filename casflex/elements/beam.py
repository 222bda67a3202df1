"""Co-rotational Euler-Bernoulli beam element with consistent mass (2D).

Crisfield (1991), Vol. 1, Sec. 7.4: the chord of the element carries its rigid translation and
rotation; what remains is an axial stretch u = L - L0 and two local end rotations
theta_l = phi - beta (phi the nodal triad angle, beta the chord angle). The local rotations are
computed as an atan2 of the triad and chord directions, so they stay continuous when the chord
angle passes +-pi and when nodes turn through full revolutions.

Mass: the consistent mass of a constant-section beam (Dhatt & Batoz 1990), rotated with the
chord, M(q) = R^T M_l R (the paper's Eq. 2 context); kinetic energy T = 1/2 qd^T M(q) qd.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca

Scalar = float | ca.SX


def local_mass(m: Scalar, L: float, rho_I: Scalar | None = None) -> ca.SX:
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


@dataclass(frozen=True)
class BeamElement:
    """One co-rotational element of a beam.

    Reference data: initial end positions (m), initial nodal rotations ``theta0`` (rad) at
    which the element is stress-free and straight. Properties E (Pa), A (m^2), I (m^4),
    rho (kg/m^3) are numbers or CasADi symbols.
    """

    name: str
    X0: tuple[float, float, float, float]  # xa, ya, xb, yb
    theta0: tuple[float, float]
    E: Scalar
    A: Scalar
    I: Scalar  # noqa: E741
    rho: Scalar
    rotary_inertia: bool = False

    @property
    def L0(self) -> float:
        xa, ya, xb, yb = self.X0
        return float(((xb - xa) ** 2 + (yb - ya) ** 2) ** 0.5)

    @property
    def beta0(self) -> float:
        import math

        xa, ya, xb, yb = self.X0
        return math.atan2(yb - ya, xb - xa)

    def kinematics(self, qe: ca.SX) -> dict[str, ca.SX]:
        """Chord length L, chord direction (c, s) and local rotations for dofs qe (6,)."""
        dx = qe[3] - qe[0]
        dy = qe[4] - qe[1]
        L = ca.sqrt(dx**2 + dy**2)
        out = {"L": L, "c": dx / L, "s": dy / L}
        for key, k, th0 in (("tha", 2, self.theta0[0]), ("thb", 5, self.theta0[1])):
            phi = qe[k] - th0 + self.beta0
            # phi - beta wrapped to (-pi, pi]: no branch jump as the chord turns.
            out[key] = ca.atan2(ca.sin(phi) * dx - ca.cos(phi) * dy, ca.cos(phi) * dx + ca.sin(phi) * dy)
        return out

    def strain_energy(self, qe: ca.SX) -> ca.SX:
        """U = EA/(2 L0) (L - L0)^2 + (EI/L0)(2 tha^2 + 2 tha thb + 2 thb^2) (J)."""
        k = self.kinematics(qe)
        L0 = self.L0
        return (self.E * self.A / (2 * L0)) * (k["L"] - L0) ** 2 + (self.E * self.I / L0) * (
            2 * k["tha"] ** 2 + 2 * k["tha"] * k["thb"] + 2 * k["thb"] ** 2
        )

    def kinetic_energy(self, qe: ca.SX, qde: ca.SX) -> ca.SX:
        """T = 1/2 (R qd)^T M_l (R qd), R the chord rotation (J)."""
        k = self.kinematics(qe)
        c, s = k["c"], k["s"]
        w = ca.vertcat(c * qde[0] + s * qde[1], -s * qde[0] + c * qde[1], qde[2],
                       c * qde[3] + s * qde[4], -s * qde[3] + c * qde[4], qde[5])
        rho_I = self.rho * self.I if self.rotary_inertia else None
        Ml = local_mass(self.rho * self.A * self.L0, self.L0, rho_I)
        return 0.5 * ca.dot(w, ca.mtimes(Ml, w))

    def gravity_energy(self, qe: ca.SX, g: tuple[Scalar, Scalar]) -> ca.SX:
        """V = -m g . c, c the centroid of the Hermite-interpolated deformed element (J).

        c = chord midpoint + n L0/12 (tha - thb), n the chord normal (-s, c).
        """
        k = self.kinematics(qe)
        off = self.L0 / 12.0 * (k["tha"] - k["thb"])
        cx = 0.5 * (qe[0] + qe[3]) - k["s"] * off
        cy = 0.5 * (qe[1] + qe[4]) + k["c"] * off
        return -(self.rho * self.A * self.L0) * (g[0] * cx + g[1] * cy)

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
