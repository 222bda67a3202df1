"""Markers' kinematics: where the scene's markers (:mod:`casflex.scene.markers`: named points fixed on a
beam or a rigid body) are as the model moves, outputs of a simulation and channels of a recording
(``x<name>``, ``y<name>``, as a node's ``x<node>``).

A marker is declared by its position at the scene's initial configuration (x, y, m) and what it
is fixed on (``on``: a beam or a rigid body), as a motion-capture marker is placed on a subject in
a known pose. On a rigid body it keeps its offset from the body's node in the node's frame. On a
beam it is found on the beam's initial chord: a distance s along it (within the beam) and e
across it (to the left of the first-to-second node direction). As the beam deforms, the marker
follows its element's co-rotational kinematics: the chord point at xi = s_element / L, displaced
across the current chord by the cubic Hermite deflection of the element's local end rotations

    v(xi) = L (xi (1 - xi)^2 th_a - xi^2 (1 - xi) th_b),   psi(xi) = v'(xi),

and the offset e along the cross-section's normal, turned by psi (Euler-Bernoulli: sections stay
normal to the centreline). The same interpolation the element's energy uses (Crisfield 1991).
"""

from __future__ import annotations

import math
import weakref

import casadi as ca
import numpy as np

__all__ = ["marker_kinematics", "marker_states", "marker_positions", "marker_channels", "body_centres",
           "channel_index", "channel_values"]

_KIN: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_CENTRES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def marker_channels(model) -> tuple[str, ...]:
    """The channels of the scene's markers: x<name>, y<name> for each, in the scene's order."""
    return tuple(f"{c}{m.name}" for m in model.scene.markers for c in "xy")


def _element_of(model, beam: str, px: float, py: float) -> tuple[int, int, int, float, float]:
    """(k, node a, node b, xi, e): the element of ``beam`` holding the point's projection on its
    initial chord, the point's fraction along that element and its distance across (m)."""
    q0 = model.q0
    elems = [(int(name.rsplit(".", 1)[1]), a, b) for kind, name, a, b in model.segments
             if kind == "beam" and name.rsplit(".", 1)[0] == beam]
    elems.sort()
    xa, ya = q0[3 * elems[0][1]], q0[3 * elems[0][1] + 1]
    xb, yb = q0[3 * elems[-1][2]], q0[3 * elems[-1][2] + 1]
    L = math.hypot(xb - xa, yb - ya)
    tx, ty = (xb - xa) / L, (yb - ya) / L
    s = (px - xa) * tx + (py - ya) * ty
    e = -(px - xa) * ty + (py - ya) * tx
    j = min(max(int(s / L * len(elems)), 0), len(elems) - 1)
    k, a, b = elems[j]
    la = (q0[3 * a] - xa) * tx + (q0[3 * a + 1] - ya) * ty
    lb = (q0[3 * b] - xa) * tx + (q0[3 * b + 1] - ya) * ty
    return k, a, b, (s - la) / (lb - la), e


def _on_body(model, q: ca.SX, node: str, px: float, py: float) -> list[ca.SX]:
    """[x, y] of the point initially at (px, py) (m) on a rigid body fixed to ``node``: its initial
    offset from the node, turned with the node's rotation since the start."""
    i = model.node_names.index(node)
    rx, ry = px - model.q0[3 * i], py - model.q0[3 * i + 1]
    phi = q[3 * i + 2] - model.q0[3 * i + 2]
    return [q[3 * i] + ca.cos(phi) * rx - ca.sin(phi) * ry, q[3 * i + 1] + ca.sin(phi) * rx + ca.cos(phi) * ry]


def _on_beam(model, q: ca.SX, th_l: ca.SX, beam: str, px: float, py: float) -> list[ca.SX]:
    """[x, y] of the point initially at (px, py) (m) on ``beam`` (module docstring)."""
    k, a, b, xi, e = _element_of(model, beam, px, py)
    j = model.local_rotation_names.index(f"{beam}.{k}.a")
    ta, tb = th_l[j], th_l[j + 1]
    dx, dy = q[3 * b] - q[3 * a], q[3 * b + 1] - q[3 * a + 1]
    L = ca.sqrt(dx * dx + dy * dy)
    tx, ty = dx / L, dy / L
    v = L * (xi * (1 - xi) ** 2 * ta - xi**2 * (1 - xi) * tb)
    psi = (1 - xi) * (1 - 3 * xi) * ta - xi * (2 - 3 * xi) * tb
    nx, ny = -ty * ca.cos(psi) - tx * ca.sin(psi), tx * ca.cos(psi) - ty * ca.sin(psi)
    return [q[3 * a] + xi * dx - v * ty + e * nx, q[3 * a + 1] + xi * dy + v * tx + e * ny]


def marker_kinematics(model) -> ca.Function:
    """``marker_kinematics(q, qd) -> (y, yd, dy_dq, dyd_dq)``: the markers' positions (2 m,) as
    [x1, y1, x2, y2, ...] (m, :func:`marker_channels`), their velocities (m/s), and the Jacobians
    (2 m, n_dof) of both in q (dyd/dqd is dy/dq)."""
    if model in _KIN:
        return _KIN[model]
    q, qd = ca.SX.sym("q", model.n_dof), ca.SX.sym("qd", model.n_dof)
    th_l = model.local_rotations(q)
    bodies = {b.name: b for b in model.scene.bodies}
    ys = []
    for m in model.scene.markers:
        ys += _on_body(model, q, bodies[m.on].node, m.x, m.y) if m.on in bodies else \
            _on_beam(model, q, th_l, m.on, m.x, m.y)
    y = ca.vertcat(*ys) if ys else ca.SX(0, 1)
    J = ca.jacobian(y, q)
    yd = ca.mtimes(J, qd)
    _KIN[model] = ca.Function("marker_kinematics", [q, qd], [y, yd, J, ca.jacobian(yd, q)],
                              ["q", "qd"], ["y", "yd", "dy_dq", "dyd_dq"])
    return _KIN[model]


def marker_states(model, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, ...]:
    """The markers at states q, qd (k, n_dof): positions and velocities (k, 2 m), and their
    Jacobians in q (k, 2 m, n_dof) each (:func:`marker_kinematics`, one evaluation for all)."""
    q, qd = np.atleast_2d(np.asarray(q, dtype=float)), np.atleast_2d(np.asarray(qd, dtype=float))
    k, n = q.shape
    y, yd, J, Jd = (np.array(v) for v in marker_kinematics(model).map(k)(q.T, qd.T))
    m2 = y.shape[0]
    return y.T.reshape(k, m2), yd.T.reshape(k, m2), *(a.reshape(m2, k, n).transpose(1, 0, 2) for a in (J, Jd))


def marker_positions(model, q: np.ndarray) -> np.ndarray:
    """The markers' positions along a motion: q (k, n_dof) -> (k, 2 m), columns as
    :func:`marker_channels`."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    return marker_states(model, q, np.zeros_like(q))[0]


def body_centres(model, q: np.ndarray) -> np.ndarray:
    """(k, 2) centres of mass of the scene's rigid bodies at one state q (n_dof,)."""
    if model not in _CENTRES:
        qs = ca.SX.sym("q", model.n_dof)
        pts = []
        for b in model.scene.bodies:
            node = model.scene.node(b.node)
            pts += _on_body(model, qs, b.node, node.x if b.com_x is None else b.com_x,
                            node.y if b.com_y is None else b.com_y)
        _CENTRES[model] = ca.Function("body_centres", [qs], [ca.vertcat(*pts) if pts else ca.SX(0, 1)])
    return np.array(_CENTRES[model](np.asarray(q, dtype=float).ravel())).reshape(-1, 2)


def channel_index(model, name: str) -> int:
    """Column of channel ``name`` in the model's channels: a dof's index, or n_dof + j for the j-th
    marker coordinate (:func:`marker_channels`). KeyError for neither."""
    if name in model.dof_names:
        return model.dof(name)
    markers = marker_channels(model)
    if name in markers:
        return model.n_dof + markers.index(name)
    raise KeyError(f"unknown channel {name!r}; the model's dofs are {list(model.dof_names)}"
                   + (f" and its markers' channels {list(markers)}" if markers else ""))


def channel_values(model, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every channel's value and rate, (k, n_dof + 2 m) each, from states q, qd (k, n_dof)."""
    q, qd = np.atleast_2d(q), np.atleast_2d(qd)
    y, yd, _, _ = marker_states(model, q, qd)
    return np.hstack([q, y]), np.hstack([qd, yd])

