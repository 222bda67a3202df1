"""Inverse dynamics with flexible segments: the scene driven along the data by HHT.

Where beams make segments flexible, the coordinates z (root pose, hinge angles) no longer decide
every dof: the bones' deflections follow from the dynamics. The scene is then driven, not solved:

- the root node by a ``clamp`` support moving along z's root pose (``root_drive``);
- every hinge [a, b] by an actuated joint (``<hinge>_drive``, kind ``drive``): its relative
  rotation follows a driver node (``<hinge>_driver``) that a support turns along the hinge's angle;

and integrated by HHT-alpha (:func:`casflex.simulate.simulate`) from the first frame's rigid motion
(the supports' splines' rates), the bones deflected there under its loads (quasi-statically). The
drives' multipliers are the net joint moments, the supports' the root's loads (the same names as the
rigid inverse, :mod:`casflex.inverse.rigid`). The paths are the supports'
quintic splines through the filtered frames; the time step divides the frames' so that
every frame is a step. The plates act on their nodes as load tables (force, and moment about the
node where the rigid fit has it: the bones' deflection at that node, reported, times the force
bounds the error of that moment arm).

The same run on the rigid scene (``flexible=False``) measures what the integrator adds to the
exact rigid inverse; the difference between the flexible and the rigid runs is the flexibility's.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from casflex.inverse.tree import KinematicTree

__all__ = ["driven_scene", "driven_loads"]


def _rows(t: np.ndarray, cols: list[np.ndarray]) -> tuple[tuple[float, ...], ...]:
    return tuple((float(ti), *(float(c[i]) for c in cols)) for i, ti in enumerate(t))


def driven_scene(tree: KinematicTree, t: np.ndarray, z: np.ndarray, plates: list | None = None, q=None):
    """The scene of ``tree.model`` driven along the coordinates z (k, n_z) at the frames t (k,)
    (module docstring), the plates (at configurations q (k, n_dof)) as load tables."""
    from casflex.scene import Joint, Load, Node, Support

    sc = tree.model.scene
    taken = {n.name for n in sc.nodes} | {it.name for f in ("beams", "springs", "torsion_springs", "bodies",
                                                           "supports", "joints", "loads") for it in getattr(sc, f)}
    root = sc.node(tree.root)
    supports = [Support("root_drive", tree.root, "clamp",
                        _rows(t, [z[:, 0] - root.x, z[:, 1] - root.y, z[:, 2] - root.theta]))]
    nodes, joints = list(sc.nodes), list(sc.joints)
    zero = np.zeros_like(t)
    for k, h in enumerate(tree.hinges):
        a, b = sc.item(h).nodes
        drv, jname = f"{h}_driver", f"{h}_drive"
        clash = {drv, jname, "root_drive"} & taken
        if clash:
            raise ValueError(f"scene: the name {sorted(clash)[0]!r} is the flexible inverse's own; rename that item")
        nodes.append(Node(drv, *sc.joint_point(sc.item(h)), 0.0))
        supports.append(Support(drv, drv, "clamp", _rows(t, [zero, zero, z[:, 3 + k]])))
        joints.append(Joint(jname, "drive", (a, b, drv)))
    loads = list(sc.loads)
    for pl in plates or ():
        i = 3 * tree.model.node_names.index(pl.node)
        F, Mo = pl.at(t)
        mz = Mo - (q[:, i] * F[:, 1] - q[:, i + 1] * F[:, 0])
        loads.append(Load(f"plate_{pl.node}", pl.node, table=_rows(t, [F[:, 0], F[:, 1], mz])))
    return dataclasses.replace(sc, nodes=tuple(nodes), supports=tuple(supports), joints=tuple(joints),
                               loads=tuple(loads))


def _start(tree: KinematicTree, model, t0: float, z0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The driven model's (q0, qd0) at t0: the rigid motion that the supports' splines give there
    (positions z0, the splines' rates), the bones deflected quasi-statically (:func:`_deflected`)."""
    names = [model.dof_names[c.dof] for c in model.constraints]
    _, vd, vdd = (np.array(a, dtype=float).ravel() for a in model.prescribed(t0))
    at = [names.index(n) for n in (f"x{tree.root}", f"y{tree.root}", f"theta{tree.root}")]
    at += [names.index(f"theta{h}_driver") for h in tree.hinges]
    q, qd, qdd = (np.array(v).ravel() for v in tree.rates(z0, vd[at], vdd[at]))
    src = {n: i for i, n in enumerate(tree.model.dof_names)}
    state = np.zeros((3, model.n_dof))
    for i, name in enumerate(model.dof_names):
        if name in src:
            state[:, i] = q[src[name]], qd[src[name]], qdd[src[name]]
    for k, h in enumerate(tree.hinges):
        j = model.dof(f"theta{h}_driver")
        state[:, j] = z0[3 + k], vd[at[3 + k]], vdd[at[3 + k]]
        for c in "xy":
            state[0, model.dof(f"{c}{h}_driver")] = model.q0[model.dof(f"{c}{h}_driver")]
    return _deflected(model, t0, *state), state[1]


def _deflected(model, t0: float, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
    """q with the bones deflected under the loads of the rigid motion at t0 (its accelerations qdd,
    velocities qd, gravity, the plates): Eq. 1 and the constraints at t0 solved for (q, lambda) by
    Newton from the rigid pose. An undeformed start would ring at the bones' modes for the first
    tenths of a second (the held leg's lowest: 3.8 Hz, damping ratio 0.3)."""
    import casadi as ca

    n, m = model.n_dof, model.n_con
    w = ca.SX.sym("w", n + m)
    v, _, _ = (np.array(a, dtype=float).ravel() for a in model.prescribed(t0))
    target = np.r_[v - np.array([c.value for c in model.constraints]), np.zeros(m - model.n_fixed)]
    r, phi = model.equilibrium(w[:n], qd, qdd, w[n:], t0, model.p_nominal)
    g = ca.vertcat(r, phi - target)
    f = ca.Function("deflected", [w], [g, ca.jacobian(g, w)])
    x = np.r_[q, np.zeros(m)]
    for _ in range(30):
        res, J = (np.array(a) for a in f(x))
        dx = np.linalg.lstsq(J, -res.ravel(), rcond=None)[0]
        x += dx
        if np.max(np.abs(dx[:n])) < 1e-12 * model.length_scale:
            return x[:n]
    raise ValueError("flexible inverse: the bones' deflection at the first frame did not converge; the "
                     "segments may be too soft for the loads")


def driven_loads(tree: KinematicTree, t: np.ndarray, z: np.ndarray, plates: list, q_fit: np.ndarray,
                 *, dt: float, alpha: float = -0.1, compiled: bool = False) -> dict[str, np.ndarray]:
    """The loads of the driven scene at the frames t (k,) (module docstring): q, qd, qdd (k, n_dof of
    ``tree.model``), the loads by name (k,), and ``deflection`` (k,) m: the largest distance of a node
    from where the rigid pose has it. ``dt`` (s): the largest time step wanted (made to divide the frames')."""
    from casflex.model import assemble
    from casflex.simulate import Start, Stepping, simulate

    h = float(t[1] - t[0])
    sub = max(1, int(np.ceil(h / dt - 1e-9)))
    model = assemble(driven_scene(tree, t, z, plates, q_fit))
    q0, qd0 = _start(tree, model, float(t[0]), z[0])
    traj = simulate(model, (t.size - 1) * h, stepping=Stepping(dt=h / sub, alpha=alpha, compiled=compiled),
                    start=Start(q0=q0, qd0=qd0, t0=float(t[0])))
    keep = np.arange(0, (t.size - 1) * sub + 1, sub)
    cols = [model.dof(n) for n in tree.model.dof_names]
    out = {"q": traj.q[keep][:, cols], "qd": traj.qd[keep][:, cols], "qdd": traj.qdd[keep][:, cols]}
    for name in traj.output_names:
        if not name.startswith(tuple(f"{hh}_driver." for hh in tree.hinges)):
            out[name] = traj.outputs[keep, traj.output_names.index(name)]
    for c, what in enumerate(("x", "y", "theta")):
        out[f"root.{('fx', 'fy', 'mz')[c]}"] = out.pop(f"root_drive.{what}")
    for hh in tree.hinges:
        out[f"{hh}.moment"] = out.pop(f"{hh}_drive.moment")
        out.pop(f"{hh}_drive.angle")
    xy = out["q"].reshape(t.size, -1, 3)[:, :, :2] - q_fit.reshape(t.size, -1, 3)[:, :, :2]
    out["deflection"] = np.linalg.norm(xy, axis=2).max(axis=1)
    return out
