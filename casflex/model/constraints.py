"""Constraint equations Phi(q) = 0 of supports and ideal joints (Eq. 1, second line).

A support fixes some dofs of a node at their initial values: Phi_j = q_i - q0_i. Its
multiplier lambda_j enters the equations of motion as B^T lambda (Eq. 1), so the force (or
moment) the support exerts on the node is -lambda_j. An ideal joint (hinge, slider, weld)
constrains the frames of two nodes, or of a node and the ground: its rows come from the joint
kernels (:mod:`casflex.elements.joints`), grouped by kind like the elements (:func:`joint_groups`).
The multipliers are ordered supports first, then joints.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from casflex.elements.joints import ROWS, base_kind, coupled_kind, joint_kernel, joint_kind, joint_spec
from casflex.model.assembly import ElementGroup
from casflex.scene.scene import Joint, Scene


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
    """The interpolating spline through ``path`` rows (t_k, d_k) at t, held at the ends outside them: quintic
    (not-a-knot: jerk and snap continuous) where the path has 6 rows or more, cubic (not-a-knot) where it has
    4 or 5. The jerk a cubic spline breaks at every row made the joint forces of a driven scene converge at
    first order in the time step; with the quintic, at second order (tests/test_moving_supports.py). scipy's
    coefficients; the interval chosen by comparisons, so it stays SX and expandable."""
    from scipy.interpolate import PPoly, make_interp_spline

    times = np.array([r[0] for r in path])
    pp = PPoly.from_spline(make_interp_spline(times, [r[1] for r in path], k=5 if len(path) >= 6 else 3))
    piece = np.flatnonzero(np.diff(pp.x) > 0)  # the B-spline's repeated end knots make empty pieces
    starts, c = pp.x[piece], pp.c[:, piece]  # (degree + 1, pieces), highest power first
    # (if_else, not fmin/fmax: at the table's ends the rates are the spline's, not halved by a tie)
    tc = ca.if_else(t < times[0], times[0], ca.if_else(t > times[-1], times[-1], t))
    k = ca.fmin(sum(tc >= tk for tk in starts[1:]), len(starts) - 1)  # the piece of tc
    u = tc - ca.conditional(k, [ca.SX(tk) for tk in starts], 0)
    value = ca.SX(0)
    for row in c:  # Horner
        value = value * u + ca.conditional(k, [ca.SX(x) for x in row], 0)
    return value


def prescribed(constraints: list[FixedDof]) -> ca.Function:
    """``prescribed(t) -> (v, vd, vdd)``, each (m,): the fixed dofs' values at time t (s) and their
    rates. A path is a quintic spline through its rows (a cubic one under 6 rows: :func:`_spline`), held at
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


def _offset(node: tuple[float, ...], point: tuple[float, float]) -> list[float]:
    """A point's offset from a node in the node's frame, R(theta0)^T (point - node) (m)."""
    x0, y0, th0 = node[:3]
    c, s = math.cos(th0), math.sin(th0)
    dx, dy = point[0] - x0, point[1] - y0
    return [c * dx + s * dy, -s * dx + c * dy]


def _axis(scene: Scene, joint: Joint, point: tuple[float, float]) -> tuple[float, float]:
    """The joint's axis (initial configuration): given, or the default of :class:`~casflex.scene.Joint`."""
    if joint.axis is not None or joint.kind != "hinge":
        return joint.axis or (1.0, 0.0)
    for frm, to in ((point, scene.node(joint.nodes[-1])), (scene.node(joint.nodes[0]), point)):
        fx, fy = frm if isinstance(frm, tuple) else (frm.x, frm.y)
        tx, ty = to if isinstance(to, tuple) else (to.x, to.y)
        d = math.hypot(tx - fx, ty - fy)
        if d > 1e-12 * scene.length_scale:
            return (tx - fx) / d, (ty - fy) / d
    return 1.0, 0.0


def joint_groups(scene: Scene, nodes: dict[str, tuple[float, ...]], idx: dict[str, int],
                 n: int) -> tuple[tuple[ElementGroup, ...], tuple[str, ...]]:
    """The scene's joints grouped by kernel kind, and the names of their constraint rows.

    A group's ``dofs`` are indices into the vector (q, mu) of n + (joint rows) entries: each joint's
    nodes' dofs, then its multipliers (n + its first row, ...), so that the HHT Newton assembles a
    joint's residual and tangent in q and mu like an element's."""
    kinds: dict[str, list] = {}
    names, row = [], 0
    for jt in scene.joints:
        kind = joint_kind(jt.kind, len(jt.nodes) == 1)
        if jt.coupled:
            kind = coupled_kind(jt.shift_splines())
        if kind == "drive":  # theta_c0 in ax's slot (casflex.elements.joints)
            a, b, c = (nodes[nd] for nd in jt.nodes)
            props = [c[2], 0.0, 0.0, 0.0, a[2], b[2], 1.0, 0.0]
        else:
            P = scene.joint_point(jt)
            b = nodes[jt.nodes[-1]]
            a = None if len(jt.nodes) == 1 else nodes[jt.nodes[0]]
            props = [*(P if a is None else _offset(a, P)), *_offset(b, P), 0.0 if a is None else a[2], b[2],
                     *_axis(scene, jt, P)]
        k = len(ROWS[jt.kind])
        dofs = [idx[nd] + j for nd in jt.nodes for j in range(3)] + [n + row + i for i in range(k)]
        kinds.setdefault(kind, []).append((jt.name, dofs, props))
        names += [f"{jt.name}.{r}" for r in ROWS[jt.kind]]
        row += k
    groups = tuple(ElementGroup(kind, tuple(it[0] for it in items), np.array([it[1] for it in items], dtype=int),
                                np.array([it[2] for it in items], dtype=float).T) for kind, items in kinds.items())
    return groups, tuple(names)


def split(group: ElementGroup) -> tuple[np.ndarray, np.ndarray]:
    """A joint group's (node dofs, multiplier positions in (q, mu)), shapes (n_joints, 6 or 3) and (n_joints, rows)."""
    nq = joint_spec(group.kind).n_dof - len(ROWS[base_kind(group.kind)])
    return group.dofs[:, :nq], group.dofs[:, nq:]


def gather_at(v: ca.SX | ca.MX, at: np.ndarray) -> ca.SX | ca.MX:
    """v's entries at the indices ``at`` (n_joints, k), one joint per column: shape (k, n_joints)."""
    return ca.reshape(v[at.ravel().tolist()], at.shape[1], at.shape[0])


def mapped_joint(group: ElementGroup, what: str, *args, alpha: float = 0.0):
    """The joint kernel ``what`` over every joint of ``group`` (arguments gathered by the caller)."""
    f = joint_kernel(group.kind, what, alpha)
    return f.map(f"{f.name()}_{group.n}", "serial", group.n, [], [])(*args)


def joint_phi(groups: tuple[ElementGroup, ...], q: ca.SX | ca.MX) -> ca.SX | ca.MX:
    """Phi of every joint row, in row order, at q (n,)."""
    if not groups:
        return type(q)(0, 1)
    parts, rows = [], []
    for grp in groups:
        at, mu_at = split(grp)
        parts.append(ca.vec(mapped_joint(grp, "phi", gather_at(q, at), ca.DM(grp.base))))
        rows += mu_at.ravel().tolist()
    order = np.argsort(rows)
    return ca.vertcat(*parts)[order.tolist()]
