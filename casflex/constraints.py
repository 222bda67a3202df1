"""Constraint equations Phi(q) = 0 of supports (Eq. 1, second line).

A support fixes some dofs of a node at their initial values: Phi_j = q_i - q0_i. Its
multiplier lambda_j enters the equations of motion as B^T lambda (Eq. 1), so the force (or
moment) the support exerts on the node is -lambda_j.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from casflex.scene import Scene


@dataclass(frozen=True)
class FixedDof:
    """Phi = q[dof] - value; ``name`` is ``"<support>.<x|y|theta>"``."""

    name: str
    dof: int
    value: float


def support_constraints(scene: Scene, dof_index: dict[str, int], q0: np.ndarray) -> list[FixedDof]:
    """One FixedDof per dof fixed by the scene's supports, in the scene's order."""
    out = []
    for s in scene.supports:
        for d in s.dofs:
            i = dof_index[f"{d}{s.node}"]
            out.append(FixedDof(f"{s.name}.{d}", i, float(q0[i])))
    return out


def constraint_vector(constraints: list[FixedDof], q: ca.SX) -> ca.SX:
    """Phi(q), shape (m,)."""
    if not constraints:
        return ca.SX(0, 1)
    return ca.vertcat(*[q[c.dof] - c.value for c in constraints])
