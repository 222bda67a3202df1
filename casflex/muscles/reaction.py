"""Joint reactions as OpenSim 4.6's ``JointReaction`` reports them, on arrays: the force and moment each joint
bears once the muscles carry their share of the net load across it (docs/muscles.md).

Cut a hinge: everything the proximal part exerts on the distal part (the hinge's child and every body below it)
is the net intersegmental load N (casflex's rigid inverse dynamics: ``<hinge>.fx``, ``.fy`` N in the ground and
``<hinge>.moment`` N m about the hinge centre, on the distal part; :mod:`casflex.inverse.rigid`; a coupled
hinge's ``.moment`` is its generalized force: ``lever`` converts it). The muscles crossing the hinge are part of
it: muscle m, at tension F_m, loads the distal part with F_m U_m (U_m: its load per N of tension on the distal
bodies, fx, fy, mz about the hinge centre; zero when it does not cross the hinge). What is left is the joint's
own reaction on the child,

    J_child = N - sum_m F_m U_m,

OpenSim's convention: ``calcReactionOnChildExpressedInGround``, Simbody's mobilizer reaction, the load the joint
applies to the child at the child joint frame's origin (the hinge centre), mobility forces included: a reserve
(``CoordinateActuator``) on the hinge's coordinate is in its moment (at a pin, with SO's forces, J's moment is
the reserve's), its force the bone-on-bone force plus what holds the segments together. On the parent,
-J_child, its moment about the parent joint frame's origin as OpenSim reports it: the hinge centre for a pin,
elsewhere for a coupled knee whose parent frame is the femur's origin (``offset``). Gravity, inertia and the
ground reactions of the distal bodies are in N already; so are the reserves, so nothing of OpenSim's forces is
missing: JointReaction with SO's force file applies every actuator's force from that file (muscles, reserves and
residuals) and realizes the model's accelerations from them, the kinematics' when SO balanced them. Muscles'
passive forces are not applied there (the file's value overrides each muscle's whole tension), as SO leaves
them out.

Expressed in the ground, the child's or the parent's body frame (a rotation of the force by the body's angle;
the moment about the plane's normal is the same in all three), in N and N m, or in body weights (N / W and
N m / W, W the body weight in N).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from casflex.muscles.static_optimization import finite_array

__all__ = ["JointReaction", "JointReactions", "joint_reactions"]


@dataclass(frozen=True)
class JointReaction:
    """Which reaction and how it is expressed (OpenSim's JointReaction properties in brackets).

    on : "child" or "parent" [apply_on_bodies]
    frame : "child", "parent" or "ground": the body frame whose axes the force is expressed in [express_in_frame]
    body_weight : N; None: loads in N and N m, else in body weights (N / body_weight, N m / body_weight)
    """

    on: str = "child"
    frame: str = "child"
    body_weight: float | None = None

    def __post_init__(self) -> None:
        if self.on not in ("child", "parent"):
            raise ValueError(f"on: expected 'child' or 'parent', got {self.on!r}")
        if self.frame not in ("child", "parent", "ground"):
            raise ValueError(f"frame: expected 'child', 'parent' or 'ground', got {self.frame!r}")
        w = self.body_weight
        if w is not None and (isinstance(w, bool) or not isinstance(w, (int, float)) or not math.isfinite(w)
                              or w <= 0.0):
            raise ValueError(f"body_weight: expected a positive number of N (mass times g), got {w!r}")


@dataclass(frozen=True, eq=False)
class JointReactions:
    """Joint reactions of k frames at n_h hinges: ``loads`` (k, n_h, 3) fx, fy (N or body weights), mz (N m or
    body weights m) on ``on``, the force in ``frame``'s axes; ``muscles`` (k, n_h, 3): the muscles' share
    sum_m F_m U_m of the net load, on the child, in the same axes and units; ``unit``: "N" or "BW"."""

    loads: np.ndarray
    muscles: np.ndarray
    on: str
    frame: str
    unit: str


def _rotate(f: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """The (k, n_h, 2) ground vectors f in the axes of frames at ``angle`` (k, n_h) rad: R(angle)^T f."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * f[..., 0] + s * f[..., 1], -s * f[..., 0] + c * f[..., 1]], axis=-1)


def joint_reactions(net, unit, forces, child=None, parent=None, options: JointReaction | None = None, *,
                    lever=None, offset=None) -> JointReactions:
    """The reactions of n_h hinges over k frames (module docstring).

    net (k, n_h, 3): each hinge's net load on its distal part, fx, fy N in the ground and mz N m about the hinge
    centre; unit (k, n_h * 3, n_m): each muscle's load per N of tension on each hinge's distal part (rows fx, fy,
    mz of hinge 0, then hinge 1, ...; N/N and m); forces (k, n_m) N: the muscles' tensions (e.g. SO's forces);
    child, parent (k, n_h) rad: the angles of each hinge's child and parent body frames in the ground, needed
    only to express in that frame; lever (k, n_h, 2) m/rad: for a hinge whose centre moves with its angle (a
    coupled knee's translation), d(centre in the ground)/d(angle) with the parent held: ``net``'s moment is then
    casflex's ``<hinge>.moment``, the generalized force, and the moment about the centre is that minus the force
    along the lever (virtual work: tau = m + f . lever); None: every centre fixed on the parent; offset (k, n_h, 2)
    m: where the reaction on the parent is reported (OpenSim: the parent joint frame's origin) minus the hinge
    centre, in the ground, for a hinge whose two joint frames part (the coupled knee's translation); None: 0.
    """
    options = options or JointReaction()
    net = np.asarray(net, dtype=float)
    if net.ndim != 3 or net.shape[2] != 3:
        raise ValueError(f"net: expected (frames, hinges, 3) (fx, fy, mz), got shape {net.shape}")
    k, n_h, _ = net.shape
    net = finite_array("net", net, (k, n_h, 3))
    unit = np.asarray(unit, dtype=float)
    if unit.ndim != 3 or unit.shape[:2] != (k, 3 * n_h):
        raise ValueError(f"unit: expected ({k}, {3 * n_h}, muscles) (frames, hinges x (fx, fy, mz), muscles), "
                         f"got shape {unit.shape}")
    n_m = unit.shape[2]
    unit = finite_array("unit", unit, (k, 3 * n_h, n_m))
    forces = finite_array("forces", forces, (k, n_m))
    if lever is not None:
        lever = finite_array("lever", lever, (k, n_h, 2))
        net = np.concatenate([net[..., :2], net[..., 2:] - np.sum(net[..., :2] * lever, axis=-1, keepdims=True)],
                             axis=-1)
    muscles = np.einsum("krm,km->kr", unit, forces).reshape(k, n_h, 3)
    loads = net - muscles
    if options.on == "parent":
        loads = -loads
        if offset is not None:  # the parent's load (-f at the centre) about the point offset from it
            d = finite_array("offset", offset, (k, n_h, 2))
            moment = loads[..., 2] - (d[..., 0] * loads[..., 1] - d[..., 1] * loads[..., 0])
            loads = np.concatenate([loads[..., :2], moment[..., None]], axis=-1)
    if options.frame != "ground":
        angle = child if options.frame == "child" else parent
        if angle is None:
            raise ValueError(f"{options.frame}: the {options.frame} bodies' angles are needed to express the loads "
                             "in their frames")
        angle = finite_array(options.frame, angle, (k, n_h))
        loads = np.concatenate([_rotate(loads[..., :2], angle), loads[..., 2:]], axis=-1)
        muscles = np.concatenate([_rotate(muscles[..., :2], angle), muscles[..., 2:]], axis=-1)
    if options.body_weight is not None:
        loads, muscles = loads / options.body_weight, muscles / options.body_weight
    return JointReactions(loads, muscles, options.on, options.frame, "N" if options.body_weight is None else "BW")
