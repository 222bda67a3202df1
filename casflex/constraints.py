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
    """Phi = q[dof] - value; ``name`` is ``"<support>.<x|y|theta>"``. A moving support's dof has
    ``path``: the rows (t, displacement) its value follows (value at the table's start included),
    and Phi = q[dof] - value - d(t) (:func:`prescribed`)."""

    name: str
    dof: int
    value: float
    path: tuple[tuple[float, float], ...] | None = None


def support_constraints(scene: Scene, dof_index: dict[str, int], q0: np.ndarray) -> list[FixedDof]:
    """One FixedDof per dof fixed by the scene's supports, in the scene's order."""
    out = []
    for s in scene.supports:
        for d in s.dofs:
            i = dof_index[f"{d}{s.node}"]
            col = {"x": 1, "y": 2, "theta": 3}[d]
            # a dof the motion leaves still (all its rows 0) stays a constant: no spline to evaluate
            moves = s.motion is not None and any(r[col] != 0 for r in s.motion)
            path = tuple((r[0], r[col]) for r in s.motion) if moves else None
            out.append(FixedDof(f"{s.name}.{d}", i, float(q0[i]), path))
    return out


def _spline(path: tuple[tuple[float, float], ...], t: ca.SX) -> ca.SX:
    """The not-a-knot cubic spline through ``path`` rows (t_k, d_k) at t, held at the ends outside
    them (scipy's coefficients; the interval chosen by comparisons, so it stays SX and expandable)."""
    from scipy.interpolate import CubicSpline

    times = np.array([r[0] for r in path])
    c = CubicSpline(times, [r[1] for r in path], bc_type="not-a-knot").c  # (4, intervals)
    # (if_else, not fmin/fmax: at the table's ends the rates are the spline's, not halved by a tie)
    tc = ca.if_else(t < times[0], times[0], ca.if_else(t > times[-1], times[-1], t))
    k = ca.fmin(sum(tc >= tk for tk in times[1:-1]), len(times) - 2)  # the interval of tc
    u = tc - ca.conditional(k, [ca.SX(tk) for tk in times[:-1]], 0)
    coef = [ca.conditional(k, [ca.SX(x) for x in c[m]], 0) for m in range(4)]
    return ((coef[0] * u + coef[1]) * u + coef[2]) * u + coef[3]


def prescribed(constraints: list[FixedDof]) -> ca.Function:
    """``prescribed(t) -> (v, vd, vdd)``, each (m,): the fixed dofs' values at time t (s) and their
    rates. A path is a not-a-knot cubic spline through its rows (continuous acceleration), held at
    its end values outside them (zero rates there)."""
    t = ca.SX.sym("t")
    vals = [ca.SX(c.value) if c.path is None else c.value + _spline(c.path, t) for c in constraints]
    v = ca.vertcat(*vals) if vals else ca.SX(0, 1)
    vd = ca.jacobian(v, t)
    return ca.Function("prescribed", [t], [v, vd, ca.jacobian(vd, t)], ["t"], ["v", "vd", "vdd"])


def constraint_vector(constraints: list[FixedDof], q: ca.SX) -> ca.SX:
    """Phi(q), shape (m,), with the supports at their initial values."""
    if not constraints:
        return ca.SX(0, 1)
    return ca.vertcat(*[q[c.dof] - c.value for c in constraints])
