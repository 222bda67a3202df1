"""A casflex scene of rigid bodies on hinges in OpenSim: an independent inverse dynamics.

``pip install opensim`` (4.6; the ``peers`` extra). The translation of a scene whose every node
carries zero or more ``[[bodies]]`` and whose nodes are joined by ``hinge`` joints forming a tree
rooted at node ``root``:

- node k -> one OpenSim ``Body`` named k whose frame is casflex's node frame: origin at the node,
  orientation theta_k in ground (so the body's angle is casflex's theta). Its bodies are summed:
  mass, centre of mass at R(theta0)^T (c - x0) in the node's frame (c the scene's centre of mass,
  x0, theta0 the node's initial pose), Izz about the combined centre of mass (parallel axes);
  Ixx = Iyy = Izz (out of the plane they do not matter; equal values keep the inertia valid);
- root -> ``PlanarJoint`` to the ground, coordinates ``<root>_rz`` (rad), ``<root>_tx``,
  ``<root>_ty`` (m): rz = theta_root and (tx, ty) = the root's origin (x_root, y_root), the
  translation being expressed in the ground (Simbody's Planar mobilizer, checked in
  tests/test_peers_opensim.py at rz != 0);
- hinge [a, b] at ``scene.joint_point`` P -> ``PinJoint`` named as the hinge, the parent (a, or b
  where b is nearer the root) offset at P in its frame, R(theta_p0)^T (P - x_p0), the child's at P
  in its own frame, both offsets unrotated: coordinate ``<hinge>_angle`` = theta_child - theta_parent;
- gravity -> the model's gravity (gx, gy, 0).

What is refused (one ``ValueError`` line naming the item): beams, springs, torsion springs, supports,
loads, sliders, welds, hinges to the ground, hinges that close a loop or leave a node unconnected,
a node without bodies at the end of a chain (OpenSim refuses a massless terminal body). Markers,
parameters and run settings do not enter the dynamics and are ignored. A scene with supports or
torsion springs (e.g. leg_hinged) is used by copying it without them (``dataclasses.replace(scene,
supports=(), torsion_springs=(), parameters=())``): the root's drive is what the supports were, and
torsion springs are passive moments that the hinge moments here include.

CasADi and OpenSim do not share a process: OpenSim 4.6's wheel bundles its own libcasadi.so.3.7,
whose soname CasADi 3.8's Python package also loads, so whichever comes second fails to import (and
constructing a :class:`~casflex.scene.Scene` imports CasADi, through its markers). :func:`inverse_dynamics`,
:func:`kinematics` and :func:`write_osim` therefore run OpenSim in a worker process (``worker=None``:
unless ``opensim`` is already imported here); they send it :class:`Mechanism`, the scene's plain
numbers. :func:`opensim_model` builds the ``opensim.Model`` itself, in a process without CasADi.
"""

from __future__ import annotations

import math
import os
import pickle
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from casflex.scene import Scene

__all__ = ["Mechanism", "mechanism", "opensim_model", "inverse_dynamics", "kinematics", "file_kinematics", "write_osim"]

_REFUSED = (("beams", "beam"), ("springs", "spring"), ("torsion_springs", "torsion spring"),
            ("supports", "support"), ("loads", "load"))


@dataclass(frozen=True, eq=False)
class Mechanism:
    """The numbers OpenSim needs of a scene (picklable; no CasADi, no OpenSim).

    ``nodes``: the scene's node names in its order; ``pose0`` (n_nodes, 3): their initial (x, y,
    theta) (m, m, rad); ``mass`` (kg), ``com`` (m, in the node's frame) and ``izz`` (kg m^2, about the
    node's combined centre of mass) per node, in node order; ``hinges``: (name, parent, child, point in
    the parent's frame, point in the child's frame, sign) with parents before children, sign = +1 where
    the scene's hinge is [parent, child], -1 where it is [child, parent]; ``gravity`` (m/s^2).
    """

    nodes: tuple[str, ...]
    root: str
    pose0: np.ndarray
    mass: np.ndarray
    com: np.ndarray
    izz: np.ndarray
    hinges: tuple[tuple[str, str, str, tuple[float, float], tuple[float, float], int], ...]
    gravity: tuple[float, float]

    def index(self, node: str) -> int:
        return self.nodes.index(node)


def _local(pose: np.ndarray, point: Sequence[float]) -> tuple[float, float]:
    """``point`` (ground, m) in the frame of a node at ``pose`` (x, y, theta): R(theta)^T (point - x)."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    dx, dy = point[0] - pose[0], point[1] - pose[1]
    return (float(c * dx + s * dy), float(-s * dx + c * dy))


def _refuse(scene: Scene) -> None:
    for field, what in _REFUSED:
        items = getattr(scene, field)
        if items:
            raise ValueError(f"{what} {items[0].name!r}: the OpenSim peer translates rigid bodies on hinges only "
                             f"(remove the scene's {field} with dataclasses.replace)")
    for j in scene.joints:
        if j.kind != "hinge":
            raise ValueError(f"joint {j.name!r}: a {j.kind} is not translated to OpenSim (hinges only)")
        if len(j.nodes) != 2:
            raise ValueError(f"joint {j.name!r}: a hinge to the ground is not translated (the root's PlanarJoint "
                             "is its only tie to the ground)")
    for n in scene.nodes:
        if any(c in n.name for c in "/\\*+") or n.name == "ground":
            raise ValueError(f"node {n.name!r}: not a valid OpenSim body name (no '/', '\\', '*', '+', nor 'ground')")


def _tree(scene: Scene, root: str) -> list[tuple[Any, str, str]]:
    """The hinges as (joint, parent, child), parents before children (breadth first from ``root``)."""
    names = [n.name for n in scene.nodes]
    if root not in names:
        raise ValueError(f"root: unknown node {root!r}; known nodes: {names}")
    reached, order, frontier = {root}, [], [root]
    pending = list(scene.joints)
    while frontier:
        node, nxt = frontier.pop(0), []
        for j in pending:
            if node not in j.nodes:
                nxt.append(j)
                continue
            other = j.nodes[1] if j.nodes[0] == node else j.nodes[0]
            if other in reached:
                raise ValueError(f"joint {j.name!r}: closes a loop (the hinges must form a tree rooted at {root!r})")
            reached.add(other)
            order.append((j, node, other))
            frontier.append(other)
        pending = nxt
    for n in names:
        if n not in reached:
            raise ValueError(f"node {n!r}: not connected to the root {root!r} by hinges")
    return order


def mechanism(scene: Scene, root: str) -> Mechanism:
    """The :class:`Mechanism` of ``scene`` rooted at node ``root``, or a one-line ``ValueError``
    naming what is not translated (see the module's docstring)."""
    _refuse(scene)
    order = _tree(scene, root)
    if any(j.name == f"{root}_ground" for j in scene.joints):
        raise ValueError(f"joint {root}_ground: the name of the root's PlanarJoint; rename the hinge")
    nodes = tuple(n.name for n in scene.nodes)
    pose0 = np.array([[n.x, n.y, n.theta] for n in scene.nodes], dtype=float)
    mass, com, izz = np.zeros(len(nodes)), np.zeros((len(nodes), 2)), np.zeros(len(nodes))
    for k, name in enumerate(nodes):
        bodies = [b for b in scene.bodies if b.node == name]
        if not bodies:
            continue
        cs = np.array([[pose0[k, 0] if b.com_x is None else b.com_x, pose0[k, 1] if b.com_y is None else b.com_y]
                       for b in bodies])
        ms = np.array([b.mass for b in bodies])
        mass[k] = ms.sum()
        c = ms @ cs / mass[k]
        izz[k] = sum(b.inertia for b in bodies) + float(ms @ ((cs - c) ** 2).sum(axis=1))
        com[k] = _local(pose0[k], c)
    parents = {parent for _, parent, _ in order}
    for k, name in enumerate(nodes):
        if mass[k] == 0.0 and name not in parents:
            raise ValueError(f"node {name!r}: carries no body and ends a chain (OpenSim refuses a massless terminal "
                             "body; its rotation would be undetermined)")
    hinges = tuple((j.name, p, c, _local(pose0[nodes.index(p)], scene.joint_point(j)),
                    _local(pose0[nodes.index(c)], scene.joint_point(j)), 1 if j.nodes[0] == p else -1)
                   for j, p, c in order)
    return Mechanism(nodes, root, pose0, mass, com, izz, hinges, tuple(scene.gravity))


def _as_mechanism(scene: Scene | Mechanism, root: str | None) -> Mechanism:
    if isinstance(scene, Mechanism):
        if root is not None and root != scene.root:
            raise ValueError(f"root: {root!r} differs from the mechanism's root {scene.root!r}")
        return scene
    if root is None:
        raise ValueError("root: name the node that the PlanarJoint ties to the ground")
    return mechanism(scene, root)


def _opensim():
    if "casadi" in sys.modules and "opensim" not in sys.modules:
        raise ImportError("OpenSim cannot be imported in a process that has loaded CasADi (OpenSim 4.6 bundles "
                          "its own libcasadi.so.3.7); call with worker=True, or from a process without casadi")
    try:
        import opensim
    except ImportError as exc:
        raise ImportError(f"OpenSim is not importable: pip install opensim (casflex's extra 'peers'): {exc}") from None
    return opensim


def opensim_model(scene: Scene | Mechanism, root: str | None = None) -> Any:
    """The ``opensim.Model`` of ``scene`` (a Scene and its ``root``, or a :class:`Mechanism`): bodies
    named as the nodes, the PlanarJoint ``<root>_ground`` (coordinates ``<root>_rz``, ``<root>_tx``,
    ``<root>_ty``), PinJoints named as the hinges (coordinate ``<hinge>_angle`` = theta_child -
    theta_parent), default coordinate values = the scene's initial configuration. Must run in a
    process without CasADi (see the module's docstring); ``initSystem`` is left to the caller."""
    mech = _as_mechanism(scene, root)
    osim = _opensim()
    model = osim.Model()
    model.setName("casflex")
    model.setGravity(osim.Vec3(mech.gravity[0], mech.gravity[1], 0.0))
    bodies = {}
    for k, name in enumerate(mech.nodes):
        i = float(mech.izz[k])
        bodies[name] = osim.Body(name, float(mech.mass[k]), osim.Vec3(*map(float, mech.com[k]), 0.0),
                                  osim.Inertia(i, i, i))
        model.addBody(bodies[name])
    zero = osim.Vec3(0.0)
    k = mech.index(mech.root)
    planar = osim.PlanarJoint(f"{mech.root}_ground", model.getGround(), zero, zero, bodies[mech.root], zero, zero)
    for i, (suffix, value) in enumerate(zip(("rz", "tx", "ty"), mech.pose0[k][[2, 0, 1]], strict=True)):
        coord = planar.upd_coordinates(i)
        coord.setName(f"{mech.root}_{suffix}")
        coord.setDefaultValue(float(value))
        coord.setRangeMin(-1e6)
        coord.setRangeMax(1e6)
    model.addJoint(planar)
    for name, parent, child, p_parent, p_child, _ in mech.hinges:
        pin = osim.PinJoint(name, bodies[parent], osim.Vec3(*p_parent, 0.0), zero,
                            bodies[child], osim.Vec3(*p_child, 0.0), zero)
        coord = pin.upd_coordinates(0)
        coord.setName(f"{name}_angle")
        coord.setDefaultValue(float(mech.pose0[mech.index(child), 2] - mech.pose0[mech.index(parent), 2]))
        coord.setRangeMin(-1e6)
        coord.setRangeMax(1e6)
        model.addJoint(pin)
    model.finalizeConnections()
    return model


def _coordinates(mech: Mechanism, q: np.ndarray) -> np.ndarray:
    """OpenSim's coordinates (or their rates) of casflex's nodal ones: (n, 3 n_nodes) -> (n, 3 + n_hinges)
    in the order rz, tx, ty of the root, then the hinges' angles theta_child - theta_parent."""
    k = mech.index(mech.root)
    cols = [q[:, 3 * k + 2], q[:, 3 * k], q[:, 3 * k + 1]]
    cols += [q[:, 3 * mech.index(c) + 2] - q[:, 3 * mech.index(p) + 2] for _, p, c, *_ in mech.hinges]
    return np.column_stack(cols)


class _Session:
    """An initialised OpenSim model of a mechanism and the state indices of its coordinates."""

    def __init__(self, mech: Mechanism) -> None:
        self.osim = _opensim()
        self.mech = mech
        self.model = opensim_model(mech)
        self.state = self.model.initSystem()
        coords = [self.model.getCoordinateSet().get(f"{mech.root}_{s}") for s in ("rz", "tx", "ty")]
        coords += [self.model.getCoordinateSet().get(f"{h[0]}_angle") for h in mech.hinges]
        nq, nu = self.state.getNQ(), self.state.getNU()
        self.qi, self.ui = [], []
        for c in coords:  # where each coordinate sits in the state's Q and U (the multibody tree's order)
            self.state.setQ(self.osim.Vector(nq, 0.0))
            c.setValue(self.state, 1.0, False)
            self.qi.append(int(np.argmax(self.state.getQ().to_numpy())))
            self.state.setU(self.osim.Vector(nu, 0.0))
            c.setSpeedValue(self.state, 1.0)
            self.ui.append(int(np.argmax(self.state.getU().to_numpy())))
        self.bodies = [self.model.getBodySet().get(n) for n in mech.nodes]
        self.mbi = [int(b.getMobilizedBodyIndex()) for b in self.bodies]

    def vector(self, values: np.ndarray, index: list[int]) -> Any:
        v = np.zeros(len(index))
        v[index] = values
        return self.osim.Vector.createFromMat(v)

    def set_q(self, t: float, qc: np.ndarray) -> None:
        self.state.setTime(float(t))
        self.state.setQ(self.vector(qc, self.qi))
        self.model.realizePosition(self.state)

    def origins(self) -> np.ndarray:
        """The bodies' origins (m) and angles (rad, in (-pi, pi]) in ground, (n_nodes, 3)."""
        out = np.empty((len(self.bodies), 3))
        for k, b in enumerate(self.bodies):
            p, r = b.getPositionInGround(self.state), b.getRotationInGround(self.state)
            out[k] = p.get(0), p.get(1), math.atan2(r.get(1, 0), r.get(0, 0))
        return out


def _plates(mech: Mechanism, plates: Sequence[tuple], n: int) -> list[tuple[int, np.ndarray, np.ndarray, np.ndarray]]:
    out = []
    for i, plate in enumerate(plates):
        if len(plate) != 4:
            raise ValueError(f"plates[{i}]: expected (node, force (n, 2), point (n, 2), moment (n,)), got {len(plate)} "
                             "items")
        node, force, point, moment = plate
        if node not in mech.nodes:
            raise ValueError(f"plates[{i}]: unknown node {node!r}; known nodes: {list(mech.nodes)}")
        try:
            arrays = tuple(np.broadcast_to(np.asarray(a, dtype=float), shape)
                           for a, shape in ((force, (n, 2)), (point, (n, 2)), (moment, (n,))))
        except ValueError:
            raise ValueError(f"plates[{i}] ({node}): force and point must be (n, 2), moment (n,), n = {n}") from None
        out.append((mech.index(node), *arrays))
    return out


def _body_forces(ses: _Session, plates: list, f: int, origins: np.ndarray) -> Any:
    """The model's applied body forces (gravity) at the Dynamics stage plus the plates of frame ``f``:
    each a spatial force (moment about the body's origin, force), in ground, by mobilized body."""
    osim = ses.osim
    forces = osim.VectorOfSpatialVec(ses.model.getRigidBodyForces(ses.state))  # a copy, not the cache
    for k, force, point, moment in plates:
        fx, fy = force[f]
        mz = (point[f, 0] - origins[k, 0]) * fy - (point[f, 1] - origins[k, 1]) * fx + moment[f]
        old = forces.get(ses.mbi[k])
        m0, f0 = old.get(0), old.get(1)
        forces.set(ses.mbi[k], osim.SpatialVec(osim.Vec3(m0.get(0), m0.get(1), m0.get(2) + mz),
                                               osim.Vec3(f0.get(0) + fx, f0.get(1) + fy, f0.get(2))))
    return forces


def _check_frames(mech: Mechanism, t, q, qd, qdd) -> tuple[np.ndarray, ...]:
    t = np.atleast_1d(np.asarray(t, dtype=float))
    arrays = []
    for what, a in (("q", q), ("qd", qd), ("qdd", qdd)):
        a = np.atleast_2d(np.asarray(a, dtype=float))
        if a.shape != (t.size, 3 * len(mech.nodes)):
            raise ValueError(f"{what}: expected shape ({t.size}, {3 * len(mech.nodes)}) (frames, x y theta per node "
                             f"in the scene's order {list(mech.nodes)}), got {a.shape}")
        arrays.append(a)
    return (t, *arrays)


def _inverse_dynamics_here(mech: Mechanism, t, q, qd, qdd, plates, tol: float) -> dict[str, np.ndarray]:
    t, q, qd, qdd = _check_frames(mech, t, q, qd, qdd)
    plate_data = _plates(mech, plates, t.size)
    ses = _Session(mech)
    solver = ses.osim.InverseDynamicsSolver(ses.model)
    qc, uc, udc = (_coordinates(mech, a) for a in (q, qd, qdd))
    tau = np.empty((t.size, qc.shape[1]))
    xy = q.reshape(t.size, -1, 3)[:, :, :2]
    for f in range(t.size):
        ses.set_q(t[f], qc[f])
        origins = ses.origins()
        gap = np.hypot(*(origins[:, :2] - xy[f]).T)
        if gap.max() > tol:
            k = int(np.argmax(gap))
            raise ValueError(f"frame {f} (t = {t[f]:g} s): node {mech.nodes[k]!r} is {gap[k]:.3g} m from where the "
                             f"hinges put it (tolerance {tol:g} m): q does not satisfy the hinges")
        ses.state.setU(ses.vector(uc[f], ses.ui))
        ses.model.realizeDynamics(ses.state)
        forces = _body_forces(ses, plate_data, f, origins)
        residual = solver.solve(ses.state, ses.vector(udc[f], ses.ui), ses.model.getMobilityForces(ses.state), forces)
        tau[f] = residual.to_numpy()[ses.ui]
    out = {"root.fx": tau[:, 1], "root.fy": tau[:, 2], "root.mz": tau[:, 0]}
    for i, (name, *_, sign) in enumerate(mech.hinges):
        out[f"{name}.moment"] = sign * tau[:, 3 + i]
    return out


def _kinematics_here(mech: Mechanism, q) -> dict[str, np.ndarray]:
    q = np.atleast_2d(np.asarray(q, dtype=float))
    if q.shape[1] != 3 * len(mech.nodes):
        raise ValueError(f"q: expected {3 * len(mech.nodes)} columns (x y theta per node), got {q.shape[1]}")
    ses = _Session(mech)
    qc = _coordinates(mech, q)
    poses, com = np.empty((q.shape[0], len(mech.nodes), 3)), np.empty((q.shape[0], 2))
    for f in range(q.shape[0]):
        ses.set_q(0.0, qc[f])
        poses[f] = ses.origins()
        c = ses.model.calcMassCenterPosition(ses.state)
        com[f] = c.get(0), c.get(1)
    theta = q.reshape(q.shape[0], -1, 3)[:, :, 2]
    poses[:, :, 2] = theta + (poses[:, :, 2] - theta + math.pi) % (2 * math.pi) - math.pi
    out = {f"{d}{n}": poses[:, k, i] for k, n in enumerate(mech.nodes) for i, d in enumerate(("x", "y", "theta"))}
    out.update({"mass": np.asarray(ses.model.getTotalMass(ses.state)), "com_x": com[:, 0], "com_y": com[:, 1]})
    return out


def _write_osim_here(mech: Mechanism, path: str) -> str:
    model = opensim_model(mech)
    model.initSystem()
    model.printToXML(path)
    return path


def _file_kinematics_here(path: str, values: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The markers' and bodies' origins' positions in the ground (n, 3) of the model file ``path`` at the
    coordinates ``values`` (name -> (n,), rad or m; the others at their defaults)."""
    osim = _opensim()
    model = osim.Model(path)
    state = model.initSystem()
    n = len(next(iter(values.values()))) if values else 1
    cs = model.getCoordinateSet()
    out = {f"marker:{model.getMarkerSet().get(i).getName()}": np.zeros((n, 3))
           for i in range(model.getMarkerSet().getSize())}
    bodies = model.getBodySet()
    out |= {f"body:{bodies.get(i).getName()}": np.zeros((n, 3)) for i in range(bodies.getSize())}
    for k in range(n):
        for name, v in values.items():
            cs.get(name).setValue(state, float(v[k]), False)
        model.assemble(state)
        model.realizePosition(state)
        for i in range(model.getMarkerSet().getSize()):
            m = model.getMarkerSet().get(i)
            out[f"marker:{m.getName()}"][k] = m.getLocationInGround(state).to_numpy()
        for i in range(model.getBodySet().getSize()):
            b = model.getBodySet().get(i)
            out[f"body:{b.getName()}"][k] = b.getPositionInGround(state).to_numpy()
    return out


_TASKS = {"inverse_dynamics": _inverse_dynamics_here, "kinematics": _kinematics_here, "write_osim": _write_osim_here,
          "file_kinematics": _file_kinematics_here}


def _task(name: str) -> Any:
    """The function a task names: a key of ``_TASKS``, or ``module:function`` of another module of
    casflex.peers (e.g. :mod:`casflex.peers.opensim_tools`'s)."""
    if ":" not in name:
        return _TASKS[name]
    module, function = name.split(":")
    if not module.startswith("casflex.peers."):
        raise ValueError(f"an OpenSim task must be a function of casflex.peers, got {name!r}")
    import importlib

    return getattr(importlib.import_module(module), function)


def _run(task: str, worker: bool | None, *args: Any) -> Any:
    """:func:`_task` (task)(*args) here (``worker=False``, or None with OpenSim already imported here) or in
    a fresh Python process (``python -c`` calling :func:`_serve`), its exceptions raised here again."""
    if worker is False or (worker is None and "opensim" in sys.modules):
        return _task(task)(*args)
    import casflex

    env = dict(os.environ)
    top = os.path.dirname(os.path.dirname(os.path.abspath(casflex.__file__)))
    env["PYTHONPATH"] = os.pathsep.join([top, *filter(None, [env.get("PYTHONPATH")])])
    with tempfile.TemporaryDirectory(prefix="casflex-opensim-") as tmp:
        inp, outp = os.path.join(tmp, "in.pickle"), os.path.join(tmp, "out.pickle")
        with open(inp, "wb") as fh:
            pickle.dump((task, args), fh)
        proc = subprocess.run([sys.executable, "-c", "from casflex.peers.opensim import _serve; _serve()", inp, outp],
                              env=env, capture_output=True, text=True)
        if not os.path.exists(outp):
            tail = (proc.stderr or proc.stdout).strip().splitlines()[-5:]
            raise RuntimeError(f"the OpenSim worker failed (exit code {proc.returncode}): " + " | ".join(tail))
        with open(outp, "rb") as fh:
            ok, value = pickle.load(fh)
    if ok:
        return value
    kind, message = value
    raise (ValueError if kind == "ValueError" else ImportError if kind == "ImportError" else RuntimeError)(message)


def _serve() -> None:
    """The worker's side of :func:`_run`: ``python -c ... in.pickle out.pickle``."""
    inp, outp = sys.argv[1:3]
    with open(inp, "rb") as fh:
        task, args = pickle.load(fh)
    try:
        osim = _opensim()
        osim.Logger.setLevelString("error")
        osim.Logger.removeFileSink()  # no opensim.log left in the caller's directory
        result = (True, _task(task)(*args))
    except Exception as exc:  # noqa: BLE001 - handed back to the caller's process
        result = (False, (type(exc).__name__, str(exc)))
    with open(outp, "wb") as fh:
        pickle.dump(result, fh)


def inverse_dynamics(scene: Scene | Mechanism, root: str | None, t, q, qd, qdd, plates: Sequence[tuple] = (), *,
                     tol: float = 1e-9, worker: bool | None = None) -> dict[str, np.ndarray]:
    """OpenSim's inverse dynamics (``InverseDynamicsSolver``) of a motion of ``scene``'s nodes.

    Parameters
    ----------
    scene, root : Scene and node name, or a :class:`Mechanism` (root None)
        The mechanism (see the module's docstring); ``root`` is tied to the ground by the PlanarJoint.
    t : (n,) s
    q, qd, qdd : (n, 3 n_nodes)
        The nodes' (x, y, theta) (m, rad) and their first and second time derivatives, in the scene's
        node order (casflex's dofs ``x<node>, y<node>, theta<node>``). They must satisfy the hinges:
        OpenSim is given the root's (theta, x, y) and each hinge's theta_child - theta_parent (and their
        rates); its body origins must then be each node's (x, y) within ``tol`` m, or ValueError. The
        other nodes' x, y rates are not used (the hinges imply them).
    plates : sequence of (node, force (n, 2) N, point (n, 2) m, moment (n,) N m)
        External loads: the force, in ground, applied to the node's body at the ground point, plus the
        free moment about z (counter-clockwise positive). Broadcast to n frames (a constant may be (2,)).
    worker : bool or None
        Run OpenSim in a worker process (True), here (False: needs a process without CasADi), or here only
        if ``opensim`` is imported here already (None).

    Returns
    -------
    dict of (n,) arrays
        ``<hinge>.moment`` (N m): the moment that segment a exerts on segment b (the scene's hinge [a, b])
        about z, counter-clockwise positive, including all that turns b relative to a (e.g. what a torsion
        spring left out of the scene would give). OpenSim's pin generalized force is the moment the parent
        exerts on the child, so this is it where a is the parent, its negative where b is.
        ``root.fx``, ``root.fy`` (N): the force, in ground, that the ground must apply to the root node's
        body (the PlanarJoint's tx, ty generalized forces, tx, ty being the root's origin in ground);
        ``root.mz`` (N m): the moment that the ground must apply to it about the root node's origin (the
        rz generalized force: Planar's angular speed is about the child frame's origin, the node).
        Gravity and the plates included.

    The applied loads reach ``InverseDynamicsSolver.solve(state, udot, mobility forces, body forces)``
    frame by frame: the model's body forces at the Dynamics stage (gravity, as ``solve(state, udot)``
    computes them) plus the plates, each a spatial force at its body's origin (moment (P - o) x F + M,
    force F): exact at every frame, where an ExternalForce / PrescribedForce would interpolate the data.
    """
    mech = _as_mechanism(scene, root)
    return _run("inverse_dynamics", worker, mech, t, q, qd, qdd, list(plates), tol)


def kinematics(scene: Scene | Mechanism, root: str | None, q, *, worker: bool | None = None) -> dict[str, np.ndarray]:
    """OpenSim's forward kinematics of casflex nodal coordinates ``q`` (n, 3 n_nodes), mapped as in
    :func:`inverse_dynamics`: ``x<node>``, ``y<node>`` (m), ``theta<node>`` (rad, OpenSim's body angle
    taken modulo 2 pi nearest the input's theta) of every body origin, (n,) each; ``mass`` (kg, the
    model's total, a scalar array); ``com_x``, ``com_y`` (m, the model's centre of mass, (n,))."""
    return _run("kinematics", worker, _as_mechanism(scene, root), q)


def file_kinematics(path: str | os.PathLike[str], values: dict[str, np.ndarray], *, worker: bool | None = None
                    ) -> dict[str, np.ndarray]:
    """OpenSim's positions in the ground (n, 3) of the markers (``marker:<name>``) and bodies' origins
    (``body:<name>``) of the model file ``path`` at the coordinates ``values`` (name -> (n,) rad or m)."""
    return _run("file_kinematics", worker, os.fspath(path), {k: np.asarray(v, dtype=float) for k, v in values.items()})


def write_osim(scene: Scene | Mechanism, root: str | None, path: str | os.PathLike[str], *,
               worker: bool | None = None) -> str:
    """Write :func:`opensim_model` of ``scene`` to the OpenSim model file ``path`` (.osim XML), e.g. to
    open it in OpenSim's GUI or in a script without CasADi; returns the path."""
    return _run("write_osim", worker, _as_mechanism(scene, root), os.fspath(path))
