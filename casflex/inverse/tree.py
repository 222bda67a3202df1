"""The kinematic tree of a jointed scene: its motion from a root's pose and its hinges' angles.

Inverse dynamics drives a scene by coordinates z (the lab's "generalised coordinates"): the root
node's pose (x, y in m, theta in rad, absolute) and each hinge's angle (rad, theta_b - theta_a from
the scene's initial configuration, the hinge output ``<hinge>.angle``). Nodes joined by beams or
welds form a cluster that the tree moves as one rigid piece (its initial shape turned and carried
with the node where the tree enters it); the clusters are joined by the hinges. ``forward(z) -> q``
is exact for rigid segments (bodies on nodes) and the rigid part of flexible ones (beams taken
undeformed: the start of a flexible inverse, :mod:`casflex.inverse.flexible`).

Refused, one line each: a spring between clusters (a compliant link the coordinates do not
decide), a slider, a joint to the ground, a support off the root, a cluster the hinges do not reach,
a hinge closing a loop.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

import casadi as ca
import numpy as np

from casflex.elements.joints import coupled_kind, coupled_splines, shift
from casflex.model import Model
from casflex.model.constraints import _offset

__all__ = ["KinematicTree", "kinematic_tree"]

_T = TypeVar("_T")


def _rot(th, v):
    c, s = ca.cos(th), ca.sin(th)
    return ca.vertcat(c * v[0] - s * v[1], s * v[0] + c * v[1])


def _clusters(model: Model) -> list[int]:
    """The cluster (a representative node index) of every model node: nodes joined by beam elements or welds."""
    parent = list(range(len(model.node_names)))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    links = [(a, b) for kind, _, a, b in model.segments if kind == "beam"]
    links += [tuple(model.node_names.index(n) for n in j.nodes) for j in model.scene.joints if j.kind == "weld"]
    for a, b in links:
        parent[find(a)] = find(b)
    return [find(i) for i in range(len(parent))]


def _check(model: Model, root: str) -> None:
    sc = model.scene
    if root not in model.node_names:
        raise ValueError(f"root: no node {root!r}; the scene's nodes are {[n.name for n in sc.nodes]}")
    if sc.supports:
        raise ValueError(f"support {sc.supports[0].name!r}: the kinematic tree's scene has no supports "
                         "(casflex.inverse.inverse_model takes them off the root)")
    for j in sc.joints:
        if len(j.nodes) == 1:
            raise ValueError(f"joint {j.name!r}: a joint to the ground is not taken by inverse dynamics (the root "
                             "moves with the data); join the node to the root's segment instead")
        if j.kind == "slider":
            raise ValueError(f"joint {j.name!r}: sliders are not in inverse dynamics yet (hinges and welds are)")


@dataclass(frozen=True)
class KinematicTree:
    """The tree of ``model`` from node ``root``: coordinate names (``<root>.x``, ``<root>.y``,
    ``<root>.theta``, then ``<hinge>.angle`` in scene order), the hinges in that order, the cluster of
    each node and the node where the tree enters each cluster."""

    model: Model
    root: str
    names: tuple[str, ...]
    hinges: tuple[str, ...]
    cluster: tuple[int, ...]
    entry: dict[int, int]

    @property
    def n(self) -> int:
        return len(self.names)

    @functools.cached_property
    def _built(self) -> dict:
        return {}

    def built(self, key: tuple, build: Callable[[], _T]) -> _T:
        """What ``build()`` makes of this tree alone (another module's CasADi Function of it: the marker fit
        mapped over a block of frames, the rigid inverse's frame), made once per tree under ``key`` (the
        maker's name first, then what else it depends on): a tree shared by the runs of one scene
        (:func:`casflex.inverse.built.inverse_tree`) builds it for the first. Only Functions and other
        immutable values: a Function's buffer (:class:`casflex.codegen.BufferedCall`) is each caller's own."""
        memo = self._built
        if key not in memo:
            memo.setdefault(key, build())  # two threads building at once keep the first one's
        return memo[key]

    @functools.cached_property
    def forward(self) -> ca.Function:
        """``forward(z) -> q``: (n_z,) -> (n_dof,), the configuration of the coordinates z."""
        return _forward(self)

    @functools.cached_property
    def rates(self) -> ca.Function:
        """``rates(z, zd, zdd) -> (q, qd, qdd)``: configuration, velocity J zd and acceleration
        J zdd + (dJ/dz zd) zd of the coordinates' motion (exact, by forward AD)."""
        z, zd, zdd = (ca.SX.sym(s, self.n) for s in ("z", "zd", "zdd"))
        q = self.forward(z)
        qd = ca.jtimes(q, z, zd)
        qdd = ca.jtimes(q, z, zdd) + ca.jtimes(qd, z, zd)
        return ca.Function("tree_rates", [z, zd, zdd], [q, qd, qdd], ["z", "zd", "zdd"], ["q", "qd", "qdd"])

    @functools.cached_property
    def marker_nodes(self) -> tuple[int, ...]:
        """The model node (index) that carries each scene marker: its body's node, or its beam's first node
        (a segment's cluster moves with either)."""
        sc = self.model.scene
        owner = {b.name: b.node for b in sc.bodies} | {b.name: b.nodes[0] for b in sc.beams}
        return tuple(self.model.node_names.index(owner[m.on]) for m in sc.markers)

    @functools.cached_property
    def marker_fit(self) -> ca.Function:
        """``marker_fit(z) -> (y, J)``: the scene's markers (2 m,: x, y each, scene order; m) at the
        coordinates z and their Jacobian dy/dz (2 m, n_z)."""
        from casflex.model.markers import marker_kinematics

        z = ca.SX.sym("z", self.n)
        y = marker_kinematics(self.model)(self.forward(z), ca.DM.zeros(self.model.n_dof))[0]
        return ca.Function("marker_fit", [z], [y, ca.jacobian(y, z)], ["z"], ["y", "J"])

    def coordinates(self, q: np.ndarray) -> np.ndarray:
        """z (n_z,) of a configuration q (n_dof,) the tree can reach (the inverse of ``forward``)."""
        m, idx = self.model, self.model.node_names.index
        r = 3 * idx(self.root)
        z = [q[r], q[r + 1], q[r + 2]]
        for name in self.hinges:
            j = m.scene.item(name)
            a, b = 3 * idx(j.nodes[0]) + 2, 3 * idx(j.nodes[1]) + 2
            z.append(q[b] - q[a] - (m.q0[b] - m.q0[a]))
        return np.array(z, dtype=float)


def kinematic_tree(model: Model, root: str | None = None) -> KinematicTree:
    """The kinematic tree of ``model`` rooted at ``root`` (default: the scene's first node)."""
    sc = model.scene
    root = sc.nodes[0].name if root is None else root
    _check(model, root)
    cl = _clusters(model)
    idx = model.node_names.index
    for s in sc.springs:
        a, b = (cl[idx(n)] for n in s.nodes)
        if a != b:
            raise ValueError(f"spring {s.name!r}: joins two segments with a compliance the coordinates do not decide; "
                             "inverse dynamics takes hinges (with torsion springs) and welds between segments")
    hinges = [j for j in sc.joints if j.kind == "hinge"]
    entry, order, todo = {cl[idx(root)]: idx(root)}, [], list(hinges)
    while todo:  # one hinge at a time: two hinges reaching the same segment at once close a loop too
        closed = [j for j in todo if cl[idx(j.nodes[0])] in entry and cl[idx(j.nodes[1])] in entry]
        if closed:
            raise ValueError(f"joint {closed[0].name!r}: closes a loop; inverse dynamics takes open chains and trees")
        j = next((j for j in todo if (cl[idx(j.nodes[0])] in entry) != (cl[idx(j.nodes[1])] in entry)), None)
        if j is None:
            break
        a, b = j.nodes if cl[idx(j.nodes[0])] in entry else j.nodes[::-1]
        if a != j.nodes[0]:
            raise ValueError(f"joint {j.name!r}: its nodes run away from the root; write them as [parent, child] "
                             f"(nodes = [{j.nodes[1]!r}, {j.nodes[0]!r}])")
        entry[cl[idx(b)]] = idx(b)
        order.append(j)
        todo.remove(j)
    lost = sorted({model.node_names[i] for i, c in enumerate(cl) if c not in entry})
    if lost:
        raise ValueError(f"nodes {lost[:5]}: no hinge or weld joins them to the root {root!r}")
    order.sort(key=lambda j: hinges.index(j))
    names = (f"{root}.x", f"{root}.y", f"{root}.theta") + tuple(f"{j.name}.angle" for j in order)
    return KinematicTree(model, root, names, tuple(j.name for j in order), tuple(cl), entry)


def _forward(tree: KinematicTree) -> ca.Function:
    m, idx = tree.model, tree.model.node_names.index
    q0 = m.q0.reshape(-1, 3)
    z = ca.SX.sym("z", tree.n)
    pose: dict[int, tuple[ca.SX, ca.SX]] = {}  # node -> (position (2,), rotation)
    r = idx(tree.root)
    pose[r] = (z[0:2], z[2])
    hinge_of = {idx(tree.model.scene.item(h).nodes[1]): (tree.model.scene.item(h), 3 + k)
                for k, h in enumerate(tree.hinges)}

    def place(i: int) -> None:  # the entry node i of a cluster, then the cluster's other nodes
        if i not in pose:
            j, k = hinge_of[i]
            a = idx(j.nodes[0])
            if a not in pose:
                place(tree.entry[tree.cluster[a]])
            xa, tha = pose[a]
            P = tree.model.scene.joint_point(j)
            ra, rb = _offset(tuple(q0[a]), P), _offset(tuple(q0[i]), P)
            thb = tha + (q0[i, 2] - q0[a, 2]) + z[k]
            pa = xa + _rot(tha, ra)
            if j.coupled:  # the point on a rolls with the angle (casflex.elements.joints)
                pa = pa + _rot(tha - q0[a, 2], shift(coupled_splines(coupled_kind(j.shift_splines())), z[k]))
            pose[i] = (pa - _rot(thb, rb), thb)
        x_e, th_e = pose[i]
        turn = th_e - q0[i, 2]
        for n in range(len(q0)):
            if tree.cluster[n] == tree.cluster[i] and n not in pose:
                pose[n] = (x_e + _rot(turn, q0[n, :2] - q0[i, :2]), q0[n, 2] + turn)

    for e in tree.entry.values():
        place(e)
    q = ca.vertcat(*[ca.vertcat(pose[n][0], pose[n][1]) for n in range(len(q0))])
    return ca.Function("tree_forward", [z], [q], ["z"], ["q"])
