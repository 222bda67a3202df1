"""What each reserve and residual actuator does along the scene's lab coordinates: its generalised force per
unit control, frame by frame (the columns static optimization weighs against the muscles' moment arms).

An actuator's generalised force on lab coordinate c is the virtual work of its output over a change of c:

- a CoordinateActuator on c: ``optimal_force`` on c, nothing on the others;
- a PointActuator: the force F (``optimal_force`` along its unit direction, turning with its body unless
  ``force_is_global``) at the point P of its body, Q_c = (dr/dc + dtheta/dc e_z x (P - r)) . F, with r, theta
  the pose of the body's node (:mod:`casflex.inverse.tree`) and P the body's station at the point (which,
  ``point_is_global``, is the station under that ground point, as OpenSim applies it);
- a TorqueActuator: the torque's component along the plane's normal on body A, its opposite on body B,
  Q_c = tau_z (dtheta_A/dc - dtheta_B/dc).

The derivatives are exact (CasADi AD of the tree's forward kinematics); ``value = value0 + sign (own -
own0)`` (:mod:`casflex.scene.coordinates`) gives dc = sign d(own). A force's out-of-plane part does no work
in the planar scene and is dropped (said in the report).
"""

from __future__ import annotations

from collections.abc import Mapping

import casadi as ca
import numpy as np

from casflex.inverse.tree import KinematicTree
from casflex.scene.from_osim import node_name
from casflex.scene.osim_actuators import Actuator

__all__ = ["actuator_columns", "check_actuators"]


def _own(tree: KinematicTree, coordinate) -> int:
    """The tree's coordinate index a lab coordinate moves."""
    return tree.names.index(coordinate.of if "." in coordinate.of else f"{coordinate.of}.angle")


def check_actuators(actuators: tuple[Actuator, ...], scene, source: str, *, model_coordinates=(),
                    bodies=(), muscles=()) -> list[str]:
    """ValueError in one line for an actuator naming a coordinate or body the model lacks, or taking the name of a
    muscle (``muscles``: their names) or of another actuator (the model's and the file's together: OpenSim refuses
    two forces of one name, and the results' columns, one per name, would take one for the other); the report's
    lines for those the planar scene leaves without effect (a coordinate of the model it does not move: locked or
    out of the plane; a force or torque with no part in the plane)."""
    lab = {c.name for c in scene.coordinates}
    nodes = {n.name for n in scene.nodes}
    report = []
    muscles, seen = set(muscles), set()
    for a in actuators:
        if a.name in muscles:
            raise ValueError(f"{source}: {a.kind} {a.name!r}: a muscle of the model has that name; give the actuator "
                             "its own (the results' columns, one per name, would take one for the other)")
        if a.name in seen:
            raise ValueError(f"{source}: two actuators named {a.name!r} (the model's and the file's together); give "
                             "each its own name (the results' columns would take one for the other)")
        seen.add(a.name)
        if a.kind == "CoordinateActuator" and a.coordinate not in lab:
            if a.coordinate not in model_coordinates:
                raise ValueError(f"{source}: CoordinateActuator {a.name!r}: coordinate: no coordinate "
                                 f"{a.coordinate!r} in the model; its coordinates are {sorted(lab)}")
            report.append(f"actuator {a.name!r}: on {a.coordinate!r}, which the planar scene holds still; no effect")
        for body in (a.body, a.other):
            if body is not None and body != "ground" and node_name(body) not in nodes:
                if body not in bodies:
                    raise ValueError(f"{source}: {a.kind} {a.name!r}: body: no body {body!r} in the model")
        if a.kind == "PointActuator" and not any(a.direction[:2]) and a.force_is_global:
            report.append(f"actuator {a.name!r}: its force is normal to the plane; no effect")
        if a.kind == "TorqueActuator" and a.torque_is_global and not a.axis[2]:
            report.append(f"actuator {a.name!r}: its torque lies in the plane; no effect")
    return report


def _node_pose(tree: KinematicTree, q, body: str):
    """(x, y, theta) of the node whose motion ``body`` follows, as expressions of the configuration q (the
    ground: zeros)."""
    if body == "ground":
        return ca.MX.zeros(3)
    dofs = tree.model.dof_names
    node = node_name(body)
    return ca.vertcat(*(q[dofs.index(f"{k}{node}")] for k in ("x", "y", "theta")))


def _rot(th, v):
    c, s = ca.cos(th), ca.sin(th)
    return ca.vertcat(c * v[0] - s * v[1], s * v[0] + c * v[1])


def actuator_columns(tree: KinematicTree, scene, actuators: tuple[Actuator, ...],
                     frames: Mapping[str, tuple[np.ndarray, np.ndarray]], z: np.ndarray) -> np.ndarray:
    """(k, n_c, n_a): each actuator's generalised force per unit control (its ``optimal_force`` included) on each
    lab coordinate (``scene.coordinates`` order; N m for rotations, N for translations) at the k frames of the
    tree's coordinates z (k, n_z). ``frames``: each OpenSim body's frame in the ground at the default pose, R
    (3, 3) and origin p (3,) m (a PointActuator's point is in it)."""
    zs = ca.MX.sym("z", tree.n)
    q = tree.forward(zs)
    coords = list(scene.coordinates)
    own = [_own(tree, c) for c in coords]
    sign = np.array([c.sign for c in coords])
    cols = []
    for a in actuators:
        if a.kind == "CoordinateActuator":
            col = ca.DM([a.optimal_force if c.name == a.coordinate else 0.0 for c in coords])
            cols.append(ca.MX(col))
            continue
        pose = _node_pose(tree, q, a.body)
        dpose = ca.mtimes(ca.jacobian(pose, zs)[:, own], ca.diag(sign))  # (3, n_c): d(x, y, theta)/d(value_c)
        if a.kind == "TorqueActuator":
            R = frames[a.body][0] if a.body in frames else np.eye(3)
            tau = a.optimal_force * (np.asarray(a.axis) / np.linalg.norm(a.axis))
            tz = tau[2] if a.torque_is_global else float((R @ tau)[2])
            other = _node_pose(tree, q, a.other or "ground")
            dother = ca.mtimes(ca.jacobian(other, zs)[:, own], ca.diag(sign))
            cols.append((tz * (dpose[2, :] - dother[2, :])).T)
            continue
        R, p = frames[a.body]
        x0 = _initial_pose(tree, a.body)
        if a.point_is_global:
            P = ca.DM(np.asarray(a.point, dtype=float)[:2])
        else:
            P0 = (p + R @ np.asarray(a.point, dtype=float))[:2]
            P = pose[:2] + _rot(pose[2] - x0[2], ca.DM(P0 - x0[:2]))
        d = np.asarray(a.direction, dtype=float) / np.linalg.norm(a.direction)
        F = a.optimal_force * (ca.DM(d[:2]) if a.force_is_global else _rot(pose[2] - x0[2], ca.DM((R @ d)[:2])))
        arm = P - pose[:2]
        moment = arm[0] * F[1] - arm[1] * F[0]
        cols.append((F[0] * dpose[0, :] + F[1] * dpose[1, :] + moment * dpose[2, :]).T)
    G = ca.Function("actuator_columns", [zs], [ca.horzcat(*cols) if cols else ca.MX.zeros(len(coords), 0)])
    z = np.atleast_2d(np.asarray(z, dtype=float))
    out = np.array(G.map(z.shape[0])(z.T)).reshape(len(coords), z.shape[0], len(actuators))
    return np.transpose(out, (1, 0, 2))


def _initial_pose(tree: KinematicTree, body: str) -> np.ndarray:
    """(x, y, theta) of the body's node in the scene's initial configuration (the model's default pose)."""
    node = next(n for n in tree.model.scene.nodes if n.name == node_name(body))
    return np.array([node.x, node.y, node.theta])
