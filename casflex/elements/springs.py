"""Massless co-rotational springs: the paper's flexible joints.

A linear (axial, pin-to-pin) spring acts along the current line of its two nodes; a
torsional spring acts on the relative rotation of its two nodes. Neither has mass or
gravity energy.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca

Scalar = float | ca.SX


@dataclass(frozen=True)
class LinearSpring:
    """U = k/2 (L - L_r)^2, L the current distance of the nodes (m), k (N/m)."""

    name: str
    k: Scalar
    rest_length: Scalar

    def _length(self, qa: ca.SX, qb: ca.SX) -> ca.SX:
        return ca.sqrt((qb[0] - qa[0]) ** 2 + (qb[1] - qa[1]) ** 2)

    @property
    def _zero_length(self) -> bool:
        return isinstance(self.rest_length, float) and self.rest_length == 0.0

    def strain_energy(self, qa: ca.SX, qb: ca.SX) -> ca.SX:
        if self._zero_length:
            # smooth at L = 0, where sqrt is not
            return 0.5 * self.k * ((qb[0] - qa[0]) ** 2 + (qb[1] - qa[1]) ** 2)
        return 0.5 * self.k * (self._length(qa, qb) - self.rest_length) ** 2

    def outputs(self, qa: ca.SX, qb: ca.SX) -> dict[str, ca.SX]:
        """force N (tension positive, N), length L (m), fx, fy: force on node b (N)."""
        L = self._length(qa, qb)
        N = self.k * (L - self.rest_length)
        if self._zero_length:  # N / L = k: no division, so no NaN when the nodes coincide
            return {"force": N, "length": L, "fx": -self.k * (qb[0] - qa[0]), "fy": -self.k * (qb[1] - qa[1])}
        return {"force": N, "length": L, "fx": -N * (qb[0] - qa[0]) / L, "fy": -N * (qb[1] - qa[1]) / L}


@dataclass(frozen=True)
class TorsionalSpring:
    """U = kt/2 (theta_b - theta_a - rest)^2, kt (N m/rad)."""

    name: str
    kt: Scalar
    rest_angle: Scalar

    def strain_energy(self, tha: ca.SX, thb: ca.SX) -> ca.SX:
        return 0.5 * self.kt * (thb - tha - self.rest_angle) ** 2

    def outputs(self, tha: ca.SX, thb: ca.SX) -> dict[str, ca.SX]:
        """moment: kt (theta_b - theta_a - rest) (N m), the torque the spring carries
        (it acts as -moment on node b and +moment on node a)."""
        return {"moment": self.kt * (thb - tha - self.rest_angle)}
