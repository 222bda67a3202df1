"""Rigid-bar reference for the two-bar scene (docs/scene-format.md, Example 1), independent of casflex.

Model
-----
Two rigid, uniform bars (mass m = rho A L, centroidal inertia J = m L^2 / 12), each described by
the position of its centre of mass (x_c, y_c) and its rotation phi from the initial
configuration: q = [x2, y2, phi2, x4, y4, phi4] (bar 2 = nodes 2-3, bar 4 = nodes 4-5).
With centre-of-mass coordinates the kinetic energy is T = 1/2 m (x'^2 + y'^2) + 1/2 J phi'^2 for
each bar: the mass matrix is constant and diagonal, there is no velocity-dependent term, and
Lagrange's equations reduce to

    m x_c'' = Q_x,   m y_c'' = Q_y,   J phi'' = Q_phi,   Q = -dV/dq.

A point at arc-length s from the centre (s = -L/2 at the first node, +L/2 at the second) is
P = c + s u(phi), u(phi) = R(phi) e with e the initial direction; its Jacobian is
dP/d(x_c, y_c, phi) = [I_2, s u_perp(phi)], u_perp = (-u_y, u_x). A force f applied at P thus
contributes (f_x, f_y, s u_perp . f) to Q (force and moment about the centre).

Potential energy V = m g (y2 + y4) + 1/2 k1 (|P2| - l1)^2 + 1/2 kt1 phi2^2
                     + 1/2 k3 (|P4 - P3| - l3)^2 + 1/2 kt3 (phi4 - phi2)^2,
the axial springs acting along the line between their end points (node 1 fixed at the origin,
theta1 = 0). The springs are massless force elements.

The system is conservative; it is integrated with the classical fourth-order Runge-Kutta method
at a fixed step (pure Python floats: 6 dofs, a numpy call per stage would cost more than the
arithmetic).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

__all__ = ["Params", "RigidTwoBar", "solve", "reference"]

S6, C6 = math.sin(math.pi / 6), math.cos(math.pi / 6)


@dataclass(frozen=True)
class Params:
    """Scene data (SI units), defaults as in docs/scene-format.md, Example 1."""

    k1: float = 700.0
    kt1: float = 0.5
    k3: float = 400.0
    kt3: float = 0.5
    l1: float = 0.1  # rest length of spring 1 (m)
    l3: float = 0.1  # rest length of spring 3 (m)
    L: float = 0.9  # bar length (m)
    rho: float = 7800.0
    A: float = 25e-4
    g: float = 9.81
    e: tuple[float, float] = field(default=(S6, -C6))  # initial chain direction

    @property
    def m(self) -> float:
        return self.rho * self.A * self.L

    @property
    def J(self) -> float:
        return self.m * self.L**2 / 12.0


class RigidTwoBar:
    """Equations of motion of the rigid two-bar chain; state z = [q (6), q' (6)]."""

    def __init__(self, p: Params | None = None):
        self.p = Params() if p is None else p

    # -- kinematics ---------------------------------------------------------------------------
    def initial_state(self) -> np.ndarray:
        p = self.p
        ex, ey = p.e
        s2 = p.l1 + p.L / 2  # arc-length of bar-2 centre from node 1
        s4 = p.l1 + p.L + p.l3 + p.L / 2
        return np.array([s2 * ex, s2 * ey, 0.0, s4 * ex, s4 * ey, 0.0, 0, 0, 0, 0, 0, 0], dtype=float)

    def _dir(self, phi: float) -> tuple[float, float]:
        ex, ey = self.p.e
        c, s = math.cos(phi), math.sin(phi)
        return c * ex - s * ey, s * ex + c * ey

    def nodes(self, q) -> np.ndarray:
        """Node positions [x2, y2, x3, y3, x4, y4, x5, y5] of the configuration q (6,)."""
        h = self.p.L / 2
        out = []
        for xc, yc, phi in ((q[0], q[1], q[2]), (q[3], q[4], q[5])):
            ux, uy = self._dir(phi)
            out += [xc - h * ux, yc - h * uy, xc + h * ux, yc + h * uy]
        return np.array(out)

    # -- dynamics -----------------------------------------------------------------------------
    def rhs(self, z):
        """dz/dt as a tuple of 12 floats (pure Python for speed)."""
        p = self.p
        x2, y2, f2, x4, y4, f4, vx2, vy2, w2, vx4, vy4, w4 = z
        h = p.L / 2
        ex, ey = p.e
        # unit directions of the bars
        c, s = math.cos(f2), math.sin(f2)
        u2x, u2y = c * ex - s * ey, s * ex + c * ey
        c, s = math.cos(f4), math.sin(f4)
        u4x, u4y = c * ex - s * ey, s * ex + c * ey
        # end points: node 2 (s = -h of bar 2), node 3 (+h of bar 2), node 4 (-h of bar 4)
        n2x, n2y = x2 - h * u2x, y2 - h * u2y
        n3x, n3y = x2 + h * u2x, y2 + h * u2y
        n4x, n4y = x4 - h * u4x, y4 - h * u4y
        # spring 1: node 1 (origin) -> node 2; force on node 2 = -k1 (l - l1) d / l
        l1 = math.hypot(n2x, n2y)
        N1 = p.k1 * (l1 - p.l1)
        f2x, f2y = -N1 * n2x / l1, -N1 * n2y / l1
        # spring 3: node 3 -> node 4; force on node 4, the opposite on node 3
        dx, dy = n4x - n3x, n4y - n3y
        l3 = math.hypot(dx, dy)
        N3 = p.k3 * (l3 - p.l3)
        f4x, f4y = -N3 * dx / l3, -N3 * dy / l3
        # torsion springs (generalised moments on phi2, phi4)
        M1 = p.kt1 * f2
        M3 = p.kt3 * (f4 - f2)
        # generalised forces: Q = sum J_P^T f_P; moment of f at s u: s (u_perp . f), u_perp = (-uy, ux)
        Qx2 = f2x - f4x
        Qy2 = f2y - f4y - p.m * p.g
        Qf2 = (-h) * (-u2y * f2x + u2x * f2y) + h * (-u2y * (-f4x) + u2x * (-f4y)) - M1 + M3
        Qx4 = f4x
        Qy4 = f4y - p.m * p.g
        Qf4 = (-h) * (-u4y * f4x + u4x * f4y) - M3
        im, iJ = 1.0 / p.m, 1.0 / p.J
        return (vx2, vy2, w2, vx4, vy4, w4, Qx2 * im, Qy2 * im, Qf2 * iJ, Qx4 * im, Qy4 * im, Qf4 * iJ)

    def potential(self, q) -> float:
        p = self.p
        n = self.nodes(q)
        l1 = math.hypot(n[0], n[1])
        l3 = math.hypot(n[4] - n[2], n[5] - n[3])
        return (p.m * p.g * (q[1] + q[4]) + 0.5 * p.k1 * (l1 - p.l1) ** 2 + 0.5 * p.kt1 * q[2] ** 2
                + 0.5 * p.k3 * (l3 - p.l3) ** 2 + 0.5 * p.kt3 * (q[5] - q[2]) ** 2)

    def kinetic(self, v) -> float:
        p = self.p
        return 0.5 * p.m * (v[0] ** 2 + v[1] ** 2 + v[3] ** 2 + v[4] ** 2) + 0.5 * p.J * (v[2] ** 2 + v[5] ** 2)

    def energy(self, z) -> float:
        return self.potential(z[:6]) + self.kinetic(z[6:])

    def gradient_check(self, q, eps: float = 1e-30) -> float:
        """max |Q + dV/dq| (N or N m) at configuration q: the hand-derived generalised forces of
        :meth:`rhs` against the gradient of the potential by complex-step differentiation."""
        p = self.p
        z = list(q) + [0.0] * 6
        acc = self.rhs(z)[6:]
        mass = (p.m, p.m, p.J, p.m, p.m, p.J)
        Q = np.array([a * mm for a, mm in zip(acc, mass, strict=True)])
        g = np.array([_potential_complex(p, np.array(q, dtype=complex) + 1j * eps * np.eye(6)[i]).imag / eps
                      for i in range(6)])
        return float(np.max(np.abs(Q + g)))

    # -- integration --------------------------------------------------------------------------
    def integrate(self, t_end: float, h: float) -> tuple[np.ndarray, np.ndarray]:
        """Classical RK4 with fixed step h (t_end / h must be whole); returns t (n,), z (n, 12)."""
        n = int(round(t_end / h))
        if abs(n * h - t_end) > 1e-9 * t_end:
            raise ValueError("t_end must be a whole number of steps")
        f = self.rhs
        z = tuple(float(v) for v in self.initial_state())
        out = [z]
        h2, h6 = h / 2, h / 6
        for _ in range(n):
            k1 = f(z)
            k2 = f(tuple(a + h2 * b for a, b in zip(z, k1, strict=True)))
            k3 = f(tuple(a + h2 * b for a, b in zip(z, k2, strict=True)))
            k4 = f(tuple(a + h * b for a, b in zip(z, k3, strict=True)))
            z = tuple(a + h6 * (b1 + 2 * b2 + 2 * b3 + b4) for a, b1, b2, b3, b4 in zip(z, k1, k2, k3, k4, strict=True))
            out.append(z)
        return np.arange(n + 1) * h, np.array(out)

    def outputs(self, z: np.ndarray) -> dict[str, np.ndarray]:
        """Named series from states z (n, 12)."""
        p = self.p
        nodes = np.array([self.nodes(zi[:6]) for zi in z])
        l1 = np.hypot(nodes[:, 0], nodes[:, 1])
        l3 = np.hypot(nodes[:, 4] - nodes[:, 2], nodes[:, 5] - nodes[:, 3])
        N1 = p.k1 * (l1 - p.l1)
        out = {f"{c}{k}": nodes[:, 2 * i + j] for i, k in enumerate((2, 3, 4, 5)) for j, c in enumerate("xy")}
        out.update({
            "phi2": z[:, 2], "phi4": z[:, 5],
            "spring1.force": N1, "spring1.fx": -N1 * nodes[:, 0] / l1, "spring1.fy": -N1 * nodes[:, 1] / l1,
            "spring3.force": p.k3 * (l3 - p.l3),
            "torsion1.moment": p.kt1 * z[:, 2], "torsion3.moment": p.kt3 * (z[:, 5] - z[:, 2]),
            "energy": np.array([self.energy(zi) for zi in z]),
        })
        return out


def _potential_complex(p: Params, q: np.ndarray) -> complex:
    """V(q) in complex arithmetic (for complex-step derivatives of the force check)."""
    h = p.L / 2
    ex, ey = p.e

    def end(xc, yc, phi, s):
        c, sn = np.cos(phi), np.sin(phi)
        return xc + s * (c * ex - sn * ey), yc + s * (sn * ex + c * ey)

    n2 = end(q[0], q[1], q[2], -h)
    n3 = end(q[0], q[1], q[2], h)
    n4 = end(q[3], q[4], q[5], -h)
    l1 = np.sqrt(n2[0] ** 2 + n2[1] ** 2)
    l3 = np.sqrt((n4[0] - n3[0]) ** 2 + (n4[1] - n3[1]) ** 2)
    return (p.m * p.g * (q[1] + q[4]) + 0.5 * p.k1 * (l1 - p.l1) ** 2 + 0.5 * p.kt1 * q[2] ** 2
            + 0.5 * p.k3 * (l3 - p.l3) ** 2 + 0.5 * p.kt3 * (q[5] - q[2]) ** 2)


@lru_cache(maxsize=8)
def solve(t_end: float = 3.0, h: float = 1e-4, p: Params | None = None) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Integrate the rigid reference (cached per process); returns t (n,) and its outputs."""
    model = RigidTwoBar(p)
    t, z = model.integrate(t_end, h)
    out = model.outputs(z)
    out["z"] = z
    return t, out


def reference(times, *, t_end: float = 3.0, h: float = 1e-4, p: Params | None = None) -> dict[str, np.ndarray]:
    """Reference outputs at ``times`` (must lie on the RK4 grid of step h)."""
    t, out = solve(float(t_end), float(h), p)
    times = np.asarray(times, dtype=float)
    idx = np.rint(times / h).astype(int)
    if np.max(np.abs(idx * h - times), initial=0.0) > 1e-9:
        raise ValueError("requested times must be multiples of the reference step h")
    return {k: v[idx] for k, v in out.items()}
