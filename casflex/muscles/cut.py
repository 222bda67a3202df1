"""The load each joint of a rigid scene applies to the part of the body beyond it, by cutting the body there.

Cut the scene at a hinge: the distal part D (the nodes the hinge separates from the root, with their rigid
bodies) moves as the trial's coordinates say, under gravity, the plates under its nodes and what the joint
applies to it. Newton and Euler for D give that last load, frame by frame, about the hinge's point P:

    F = sum_i m_i (a_i - g) - sum_plates F_p,
    M_P = sum_i [ (r_i - P) x m_i (a_i - g) + I_i alpha_i ] - sum_plates (M_p - P x F_p)

(r_i, a_i: body i's centre of mass and its acceleration; alpha_i its angular acceleration; a plate's moment
M_p is about the lab's origin: :class:`casflex.inverse.plates.Plate`). Without muscles this is the net
intersegmental load of inverse dynamics: F equals the hinge's ``fx``, ``fy`` (a check,
tests/test_muscles_cut.py), and M_P its net moment where the hinge's centre is fixed in both segments (for a
coupled hinge, whose centre slides with the angle, M_P is the physical moment about the moving centre, not
the generalised force ``.moment``). With muscles, the joint's reaction is this load less what the muscles and
actuators crossing the cut apply to D (:mod:`casflex.muscles.reaction`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["distal_nodes", "joint_loads"]


def distal_nodes(scene, root: str) -> dict[str, frozenset[str]]:
    """Each two-node hinge's distal part: the nodes it separates from ``root`` (its node b's side, or a's where the
    root is on b's side)."""
    links: dict[str, set[str]] = {n.name: set() for n in scene.nodes}
    for j in scene.joints:
        if len(j.nodes) == 2 and j.kind in ("hinge", "weld"):
            a, b = j.nodes
            links[a].add(b)
            links[b].add(a)
    for beam in getattr(scene, "beams", ()):
        a, b = beam.nodes
        links[a].add(b)
        links[b].add(a)
    out = {}
    for j in scene.joints:
        if j.kind != "hinge" or len(j.nodes) != 2:
            continue
        a, b = j.nodes
        side, todo = {b}, [b]
        while todo:
            n = todo.pop()
            for m in links[n]:
                if m not in side and {n, m} != {a, b}:
                    side.add(m)
                    todo.append(m)
        out[j.name] = frozenset(side if root not in side else {n.name for n in scene.nodes} - side)
    return out


def _rot(d: np.ndarray, v: np.ndarray) -> np.ndarray:
    """v (2,) turned by the angles d (k,): (k, 2)."""
    c, s = np.cos(d), np.sin(d)
    return np.column_stack([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def _cross(r: np.ndarray, f: np.ndarray) -> np.ndarray:
    return r[:, 0] * f[:, 1] - r[:, 1] * f[:, 0]


def joint_loads(scene, dof_names, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, t: np.ndarray, plates=(),
                root: str | None = None) -> dict[str, np.ndarray]:
    """hinge -> (k, 3): the load the hinge applies to its distal part (:func:`distal_nodes`): fx, fy (N, the
    ground's axes) and the moment about the hinge's point (N m, counter-clockwise), at the k frames of the
    scene's motion q, qd, qdd (k, n_dof; dofs ``x<node>``, ``y<node>``, ``theta<node>``) with the ``plates``
    (:class:`casflex.inverse.plates.Plate`) applied. Rigid bodies on nodes only (the rigid inverse's scenes)."""
    g = np.asarray(scene.gravity, dtype=float)
    idx = {n: i for i, n in enumerate(dof_names)}
    nodes = {n.name: n for n in scene.nodes}

    def pose(node: str):
        i = idx[f"x{node}"]
        return q[:, i:i + 3], qd[:, i:i + 3], qdd[:, i:i + 3]

    # each body's share: force (k, 2) and moment about the lab's origin (k,) that D needs for it
    need_f: dict[str, np.ndarray] = {}
    need_m: dict[str, np.ndarray] = {}
    for b in scene.bodies:
        n = nodes[b.node]
        (p, v, a) = pose(b.node)
        com0 = np.array([b.com_x if b.com_x is not None else n.x, b.com_y if b.com_y is not None else n.y])
        r = _rot(p[:, 2] - n.theta, com0 - np.array([n.x, n.y]))  # node -> centre of mass, (k, 2)
        w, al = v[:, 2], a[:, 2]
        acc = a[:, :2] + np.column_stack([-al * r[:, 1], al * r[:, 0]]) - (w**2)[:, None] * r
        f = b.mass * (acc - g)
        need_f[b.node] = need_f.get(b.node, 0.0) + f
        need_m[b.node] = need_m.get(b.node, 0.0) + _cross(p[:, :2] + r, f) + b.inertia * al
    for pl in plates:
        F, Mo = pl.at(t)
        need_f[pl.node] = need_f.get(pl.node, 0.0) - F
        need_m[pl.node] = need_m.get(pl.node, 0.0) - Mo
    out = {}
    hinges = {j.name: j for j in scene.joints}
    for name, part in distal_nodes(scene, root or scene.nodes[0].name).items():
        j = hinges[name]
        b = nodes[j.nodes[1]]
        point0 = np.asarray(j.point if j.point is not None else (b.x, b.y), dtype=float)
        pb = pose(b.name)[0]
        P = pb[:, :2] + _rot(pb[:, 2] - b.theta, point0 - np.array([b.x, b.y]))
        F = sum((need_f[n] for n in part if n in need_f), np.zeros((t.size, 2)))
        M = sum((need_m[n] for n in part if n in need_m), np.zeros(t.size))
        out[name] = np.column_stack([F, M - _cross(P, F)])
    return out
