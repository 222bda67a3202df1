"""The muscles of a trial, frame by frame: from the inverse dynamics' coordinates to the muscles' forces (static
optimization) and the loads the joints bear (joint reactions).

Every output at frame k is a function of that frame's coordinates and rates (z, z', z'') and of the model's
properties (:meth:`TrialMuscles.solve`): the inverse's loads (:func:`casflex.inverse.bands.rigid_load_function`),
the paths' lengths, speeds, moment arms and unit loads (:mod:`casflex.muscles.path`), the muscles' forces at full
activation (:mod:`casflex.muscles.curves`), the reserves (:mod:`casflex.muscles.actuators`), static optimization
(:mod:`casflex.muscles.static_optimization`) and the reactions (:mod:`casflex.muscles.reaction`). The bands
(:mod:`casflex.muscles.bands`) differentiate that function as the inverse's bands differentiate its loads.

The root's coordinates (the pelvis' pose) are no muscle's: a muscle pulls its two bodies together and moves
nothing when the whole body turns or slides. Their loads, the inverse dynamics' residuals, go to the residual
actuators (a PointActuator or TorqueActuator on the root's body, a CoordinateActuator on a root coordinate) at
least cost, as OpenSim's static optimization, whose muscles cannot reach them either, gives them; the joints'
coordinates go to static optimization, with the CoordinateActuators on them as its reserves.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from casflex.inverse.bands import rigid_load_function
from casflex.inverse.lab_names import lab_name
from casflex.inverse.tree import KinematicTree
from casflex.muscles.actuators import actuator_columns, check_actuators
from casflex.muscles.compliant import solve_compliant
from casflex.muscles.curves import muscle_curves, rigid_tendon
from casflex.muscles.path import MusclePaths
from casflex.muscles.reaction import JointReaction, JointReactions, joint_reactions
from casflex.muscles.static_optimization import (
    DEFAULT_BOUNDS,
    StaticOptimization,
    StaticOptimizationResult,
    solve_static_optimization,
)
from casflex.scene.from_osim import node_name

__all__ = ["FrameOutputs", "TrialMuscles", "muscle_result", "reserve_actuators", "residual_warnings",
           "uncrossed_notes"]

#: The least a muscle must pull at full activation, at its best frame of the trial, as a fraction of its max
#: isometric force (:meth:`TrialMuscles._check_capacity`); a real muscle pulls 0.9-1.3 there.
WEAKEST = 0.01
#: The residual force (RMS over the trial, in body weights) beyond which the root's balance is said: Hamner's run
#: with its plates 0.19 BW (FY), without them 1.4 BW (the residuals carry the body's weight and the muscles carry
#: what the ground's push would have made them carry: the hip's peak 4.8 BW for 10.4).
RESIDUAL_WARNING = 0.5


@dataclass(frozen=True, eq=False)
class FrameOutputs:
    """What :meth:`TrialMuscles.solve` gives for k frames.

    so : static optimization over the joints' coordinates (``TrialMuscles.joint_coordinates``)
    residuals : (k, n_r) the residual actuators' controls (``TrialMuscles.residuals``' order)
    reactions : joint -> :class:`JointReactions` (loads (k, 1, 3): fx, fy N and mz N m as the options express them)
    lengths, speeds : (k, n_m) m, m/s; arms (k, n_m, n_c) m along ``TrialMuscles.joint_coordinates``
    active, passive : (k, n_m) N each muscle's force at full activation along its tendon, and its passive force
    moments : (k, n_c) the generalised forces static optimization carried (N m, N)
    """

    so: StaticOptimizationResult
    residuals: np.ndarray
    reactions: dict[str, JointReactions]
    lengths: np.ndarray
    speeds: np.ndarray
    arms: np.ndarray
    active: np.ndarray
    passive: np.ndarray
    moments: np.ndarray


class TrialMuscles:
    """A trial's muscles: the model (its tree, muscles, actuators), the trial's times and plates and the choices,
    fixed; :meth:`solve` maps the frames' coordinates to the outputs. ``osim``: the
    :class:`~casflex.scene.from_osim.OsimScene` read with its muscles; ``tree`` its kinematic tree; ``joints``: the
    hinges whose reactions are computed (() every one). ValueError in one line for what cannot be honoured."""

    def __init__(self, osim, tree: KinematicTree, t: np.ndarray, plates=(), actuators=(), *,
                 optimization: StaticOptimization | None = None, reaction: JointReaction | None = None,
                 joints: tuple[str, ...] = (), source: str = "actuators") -> None:
        self.osim, self.tree, self.t, self.plates = osim, tree, np.asarray(t, dtype=float), tuple(plates)
        self.source = source
        self.scene = tree.model.scene
        self.muscles = tuple(osim.muscles)
        if not self.muscles:
            raise ValueError("the model has no muscle casflex computes (Millard2012EquilibriumMuscle, "
                             "Thelen2003Muscle, DeGrooteFregly2016Muscle)")
        for m in self.muscles:  # a curve's bad property refused now, naming the model, not after the inverse
            try:
                muscle_curves(m)
            except ValueError as exc:
                raise ValueError(f"{osim.source}: {exc}" if osim.source else str(exc)) from None
        #: lines said on stderr and in the report: muscles stronger than a human's (:mod:`casflex.muscles.strength`)
        self.warnings = self._check_strength()
        self.optimization = optimization or StaticOptimization()
        bounds_note = self._muscle_bounds()
        self.reaction = reaction or JointReaction()
        hinges = list(tree.hinges)
        self.joints = tuple(joints) or tuple(hinges)
        unknown = [j for j in self.joints if j not in hinges]
        if unknown:
            raise ValueError(f"joints: no hinge {unknown[0]!r} in the scene; its hinges are {hinges}")
        twice = [j for i, j in enumerate(self.joints) if j in self.joints[:i]]
        if twice:
            raise ValueError(f"joints: {twice[0]!r} given twice; give each joint once")
        self.paths = MusclePaths(tree, self.muscles)
        coords = list(self.scene.coordinates)
        root = f"{tree.root}."
        self.root_coordinates = tuple(c for c in coords if c.of.startswith(root))
        self.joint_coordinates = tuple(c for c in coords if not c.of.startswith(root))
        self.notes = [*self.warnings, *check_actuators(tuple(actuators), self.scene, source,
                                                       bodies=set(osim.frames) - {"ground"},
                                                       muscles=[m.name for m in self.muscles]), *bounds_note]
        self._split_actuators(tuple(actuators), source)
        if not self.residuals:
            self.notes.append(f"no residual actuator on the root ({tree.root}): its loads (the inverse dynamics' "
                              "residuals) are not balanced by static optimization; give them as PointActuator and "
                              "TorqueActuator (e.g. OpenSim's FX, FY, MZ) or --reserves")
        self._slide = self._slides()

    def _check_strength(self) -> list[str]:
        """The lines that say a muscle is stronger than a human's against the body's weight; ValueError naming
        the muscle whose max isometric force no body has (:func:`casflex.muscles.strength.check_strength`): the
        model's weight, or a third of the plates' largest total force where that is more (a model of a leg)."""
        from casflex.lab.plate_checks import scene_mass
        from casflex.muscles.strength import check_strength

        weight = scene_mass(self.scene) * float(np.hypot(*self.scene.gravity))
        total = sum((np.linalg.norm(p.at(self.t)[0], axis=1) for p in self.plates), np.zeros(self.t.size))
        head = f"{self.osim.source}: ForceSet: " if self.osim.source else ""
        return check_strength(self.muscles, weight, head, float(total.max(initial=0.0)))

    def _muscle_bounds(self) -> list[str]:
        """Each muscle's activation bounds as OpenSim's SO takes them (StaticOptimization.cpp, ``record``: each
        actuator's ``getMinControl()``, ``getMaxControl()``): its own ``min_control`` / ``max_control`` where its
        file gives them, else static optimization's ``activation_bounds`` (--activation-bounds) where given, else
        its kind's OpenSim default (:data:`casflex.muscles.static_optimization.DEFAULT_BOUNDS`: a
        DeGrooteFregly2016Muscle's min_control 0, a Millard's or Thelen's 0.01); a Millard or Thelen muscle's
        ``minimum_activation`` raises its lower bound to it (OpenSim refuses a ``min_control`` below it). Set as
        ``muscle_bounds`` when any differs from (0.01, 1) (or the bounds given); the report's lines naming those
        muscles. ValueError naming the muscle and the tag for bounds no activation can take."""
        given_bounds = self.optimization.activation_bounds
        lo, hi = given_bounds or DEFAULT_BOUNDS["Millard2012EquilibriumMuscle"]
        head = f"{self.osim.source}: " if self.osim.source else ""
        pairs, own, kind = [], [], []
        for m in self.muscles:
            where = f"{head}ForceSet: {m.kind} {m.name!r}"
            a = m.property("minimum_activation", 0.0)
            if m.kind == "Millard2012EquilibriumMuscle" and not 0.0 <= a < 1.0:
                raise ValueError(f"{where}.minimum_activation: must be in [0, 1) (OpenSim refuses it below 0; at 1 "
                                 f"the muscle could never relax), got {a:g}")
            a = a if m.kind in ("Millard2012EquilibriumMuscle", "Thelen2003Muscle") else 0.0
            given = {tag: m.property(tag, math.nan) for tag in ("min_control", "max_control")}
            if given["min_control"] < a:
                raise ValueError(f"{where}.min_control: {given['min_control']:g} is below its minimum_activation "
                                 f"{a:g} (OpenSim refuses the model): give min_control >= minimum_activation")
            mlo, mhi = given_bounds or DEFAULT_BOUNDS.get(m.kind, (lo, hi))
            pair = (max(mlo if math.isnan(given["min_control"]) else given["min_control"], a),
                    mhi if math.isnan(given["max_control"]) else given["max_control"])
            if not (math.isfinite(pair[1]) and 0.0 <= pair[0] < pair[1] <= 1.0):
                tag = "max_control" if not math.isnan(given["max_control"]) else "min_control"
                raise ValueError(f"{where}.{tag}: its activation bounds would be [{pair[0]:g}, {pair[1]:g}] (its own "
                                 "min_control / max_control, the others from the activation bounds "
                                 f"[{mlo:g}, {mhi:g}]): expected 0 <= lower < upper <= 1 (an activation is the "
                                 "fraction of its force)")
            pairs.append(pair)
            if pair != (lo, hi):
                mine = not (math.isnan(given["min_control"]) and math.isnan(given["max_control"])) or pair[0] == a > mlo
                (own if mine or (mlo, mhi) == (lo, hi) else kind).append(f"{m.name} [{pair[0]:g}, {pair[1]:g}]")
        if not own and not kind:
            return []
        self.optimization = dataclasses.replace(self.optimization, muscle_bounds=tuple(pairs))
        lines = [f"muscles {', '.join(own)} bounded by their own min_control / max_control (or minimum_activation; "
                 f"as OpenSim's static optimization), the others by the activation bounds [{lo:g}, {hi:g}]"] if own \
            else []
        return lines + ([f"muscles {', '.join(kind)} bounded by their kind's OpenSim default (a "
                         "DeGrooteFregly2016Muscle's min_control 0; --activation-bounds sets every muscle's)"]
                        if kind else [])

    def _split_actuators(self, actuators, source: str) -> None:
        """The reserves (a CoordinateActuator on a joint's coordinate: static optimization's) and the residuals
        (on the root: balanced apart); ValueError for what static optimization cannot take (two reserves on one
        coordinate, reserves of different bounds, a force on a body other than the root's)."""
        joint = {c.name for c in self.joint_coordinates}
        root_node = self.tree.root
        self.reserves, self.residuals = {}, []
        bounds = set()
        for a in actuators:
            if a.kind == "CoordinateActuator" and a.coordinate in joint:
                if a.coordinate in self.reserves:
                    raise ValueError(f"{source}: {a.name!r}: a second reserve on {a.coordinate!r}; give one per "
                                     "coordinate")
                self.reserves[a.coordinate] = a
                bounds.add((a.min_control, a.max_control))
            elif a.kind == "CoordinateActuator" and a.coordinate not in {c.name for c in self.root_coordinates}:
                continue  # on a coordinate the scene holds still: no effect (check_actuators said so)
            elif a.kind != "CoordinateActuator" and node_name(a.body) != root_node:
                raise ValueError(f"{source}: {a.kind} {a.name!r}: on {a.body!r}; casflex's static optimization "
                                 f"takes forces and torques on the root's body ({root_node!r}) only, and reserves "
                                 "as CoordinateActuators")
            else:
                self.residuals.append(a)
        self.used = tuple(a for a in actuators if a in self.residuals or a in self.reserves.values())
        if len(bounds) > 1:
            raise ValueError(f"{source}: the reserves' control bounds differ ({sorted(bounds)}); give them one pair")
        if bounds:
            lo, hi = bounds.pop()
            self.optimization = _with_reserve_bounds(self.optimization, (lo, hi))

    def _slides(self) -> ca.Function:
        """``slide(z) -> (2, n_h)``: how far each hinge's point moves (m/rad, ground axes) per radian of its angle,
        the rest held (0 for a hinge whose centre is fixed in both segments): the reactions' ``lever``."""
        z = ca.SX.sym("z", self.tree.n)
        q = self.tree.forward(z)
        cols = []
        for h in self.tree.hinges:
            j = self.scene.item(h)
            i = self.tree.model.node_names.index(j.nodes[1])
            x0 = np.asarray(self.tree.model.q0[3 * i: 3 * i + 3], dtype=float).ravel()
            P0 = np.asarray(self.scene.joint_point(j), dtype=float) - x0[:2]
            th = q[3 * i + 2] - x0[2]
            P = q[3 * i: 3 * i + 2] + ca.vertcat(ca.cos(th) * P0[0] - ca.sin(th) * P0[1],
                                                 ca.sin(th) * P0[0] + ca.cos(th) * P0[1])
            cols.append(ca.jacobian(P, z)[:, self.tree.names.index(f"{h}.angle")])
        return ca.Function("hinge_slides", [z], [ca.horzcat(*cols)])

    def bare_coordinates(self, arms: np.ndarray | None = None) -> list[bool]:
        """Per joint coordinate (``joint_coordinates``' order): True where no muscle crosses it (moment arms below
        1e-9 m in ``arms`` (k, n_m, n_c), default at the model's default pose) and no reserve acts on it: static
        optimization has nothing to carry its moment."""
        if arms is None:
            z0 = self.tree.coordinates(np.asarray(self.tree.model.q0, dtype=float).ravel())
            geo = self.paths.evaluate(np.atleast_2d(z0), np.zeros((1, np.size(z0))))
            cols = [list(self.scene.coordinates).index(c) for c in self.joint_coordinates]
            arms = geo["moment_arms"][:, :, cols]
        held = {c for c, a in self.reserves.items() if a.optimal_force > 0.0}
        return [bool(np.abs(arms[:, :, i]).max(initial=0.0) < 1e-9 and c.name not in held)
                for i, c in enumerate(self.joint_coordinates)]

    def capacity(self, lengths: np.ndarray, speeds: np.ndarray, muscles=None) -> tuple[np.ndarray, np.ndarray]:
        """(active, passive) (k, n_m) N: each muscle's force along its tendon at full activation and its passive
        force (:func:`casflex.muscles.curves.rigid_tendon`, OpenSim's values), at the paths' lengths and speeds."""
        act, pas = [], []
        for i, m in enumerate(muscles or self.muscles):
            active, passive = rigid_tendon(m, lengths[:, i], speeds[:, i])
            act.append(active)
            pas.append(passive)
        return np.column_stack(act), np.column_stack(pas)

    def solve(self, z: np.ndarray, zd: np.ndarray, zdd: np.ndarray, p: np.ndarray | None = None, muscles=None,
              optimization: StaticOptimization | None = None, loads: dict[str, np.ndarray] | None = None,
              near: FrameOutputs | None = None) -> FrameOutputs:
        """The outputs at the frames' coordinates z, z', z'' (k, n_z), with the model's properties p (default its
        nominal ones), ``muscles`` (default the model's: the bands pass perturbed copies) and ``optimization``
        (default the trial's: the criteria's spread passes another exponent); ``loads``: the inverse's loads at
        those frames (name -> (k,), N, N m) when computed elsewhere (the bands': by a model whose uncertain
        properties are parameters), instead of the trial's rigid inverse at p; ``near``: :meth:`solve_variants`'."""
        return self.solve_variants(z, zd, zdd, [muscles or self.muscles], p, optimization, loads, near)[0]

    def solve_variants(self, z: np.ndarray, zd: np.ndarray, zdd: np.ndarray, variants, p: np.ndarray | None = None,
                       optimization: StaticOptimization | None = None, loads: dict[str, np.ndarray] | None = None,
                       near: FrameOutputs | None = None) -> list[FrameOutputs]:
        """:meth:`solve` for each of ``variants`` (each a tuple of muscles, the model's with some properties
        changed: the bands'), at once: the loads, paths and reaction geometry computed once, the forces at full
        activation only of the muscles that differ from the model's (one variant per solve of static
        optimization: on the Rajagopal walk 24 variants stacked as one problem took 18 s CPU, solved one by one
        11 s); ``near``: the outputs of nearby inputs at the same frames (the bands' perturbations): with p = 2
        each variant's frames are solved on their active set, the QP only where it changed (1.4 s for those 24:
        :func:`~casflex.muscles.static_optimization.solve_static_optimization`'s ``near``)."""
        options = optimization or self.optimization
        p = self.tree.model.p_nominal if p is None else p
        loads = rigid_load_function(self.tree, self.t, self.plates, p)(z, zd, zdd) if loads is None else loads
        geo = self.paths.evaluate(z, zd)
        cols = [list(self.scene.coordinates).index(c) for c in self.joint_coordinates]
        arms = geo["moment_arms"][:, :, cols]
        moments = np.column_stack([loads[lab_name(c)] for c in self.joint_coordinates])
        active0, passive0 = self.capacity(geo["lengths"], geo["speeds"])
        self._check_capacity(active0, passive0, geo, options)
        capacity = [self._capacity_of(v, geo, active0, passive0) for v in variants]
        reserves = np.array([self.reserves[c.name].optimal_force if c.name in self.reserves else 0.0
                             for c in self.joint_coordinates])
        bare = [c.name for i, (c, b) in enumerate(zip(self.joint_coordinates, self.bare_coordinates(arms), strict=True))
                if b and np.abs(moments[:, i]).max() > 1e-6]
        if bare:
            raise ValueError(f"{', '.join(bare)}: no muscle crosses it and no reserve acts on it: its moment has "
                             "nothing to carry it; give reserves (an actuator file, or --reserves / actuators=N)")
        names = [c.name for c in self.joint_coordinates]
        if options.tendon == "compliant":
            sos = [solve_compliant(moments, arms, geo["lengths"], v, reserves, options, coordinates=names)
                   for v in variants]
        else:
            sos = [solve_static_optimization(moments, arms, a, ps, reserves, options, coordinates=names,
                                             max_isometric=[m.max_isometric_force for m in v],
                                             near=None if near is None else near.so, times=self.t)
                   for v, (a, ps) in zip(variants, capacity, strict=True)]
        residuals, geometry = self._residuals(loads, z), self._reaction_geometry(z)
        out = []
        for s, (active, passive) in zip(sos, capacity, strict=True):
            out.append(FrameOutputs(s, residuals, self._reactions(loads, geometry, s.forces), geo["lengths"],
                                    geo["speeds"], arms, active, passive, moments))
        return out

    def _check_capacity(self, active: np.ndarray, passive: np.ndarray, geo, options: StaticOptimization) -> None:
        """ValueError naming the muscle whose force at full activation or passive force is not finite at a frame
        (a fibre stretched to 1e5 optimal lengths: an optimal fibre length or a path point off by orders), or,
        with the force-length-velocity curves, that pulls with less than :data:`WEAKEST` of its max isometric force
        at every frame of the trial (a tendon slack length longer than the path, an optimal fibre length ten times
        too long, a path point on the wrong body): it could carry nothing, and static optimization would hand its
        share to the others and the reserves without a word. The models' own muscles pull 0.9-1.3 times their max
        isometric force at their best frame over a run or a walk (Hamner's 92, Rajagopal's 80)."""
        for i, m in enumerate(self.muscles):
            bad = ~(np.isfinite(active[:, i]) & np.isfinite(passive[:, i]))
            best = np.max(active[:, i], initial=0.0, where=~bad) / m.max_isometric_force
            if not bad.any() and (best >= WEAKEST or not options.force_length_velocity):
                continue
            r = rigid_tendon(m, geo["lengths"][:, i], geo["speeds"][:, i])
            lm, lt = r.norm_fiber_length, geo["lengths"][:, i]
            where = f"its path {np.nanmin(lt):.3g}-{np.nanmax(lt):.3g} m long, "
            where += (f"shorter than its tendon slack length {m.tendon_slack_length:g} m at every frame"
                      if np.nanmax(lt) <= m.tendon_slack_length else
                      f"its tendon at its slack length {m.tendon_slack_length:g} m, its fibre {np.nanmin(lm):.3g}-"
                      f"{np.nanmax(lm):.3g} optimal fibre lengths ({m.optimal_fiber_length:g} m)")
            head = f"{self.osim.source}: ForceSet: {m.kind} {m.name!r}" if self.osim.source else f"muscle {m.name!r}"
            if bad.any():
                k = int(np.argmax(bad))
                why = f"its {'active' if not np.isfinite(active[k, i]) else 'passive'} force is not finite at t = " \
                      f"{self.t[k]:g} s"
            else:
                why = (f"at full activation it pulls at most {100 * best:.2g} % of its max isometric force over the "
                       "trial")
            raise ValueError(f"{head}: {why} ({where}): check its tendon_slack_length, optimal_fiber_length and path "
                             "points")

    def _capacity_of(self, muscles, geo, active0, passive0) -> tuple[np.ndarray, np.ndarray]:
        """(active, passive) (k, n_m) of ``muscles``: the model's (``active0``, ``passive0``) but in the columns
        of the muscles that differ from the model's."""
        if len(muscles) != len(self.muscles):
            raise ValueError(f"muscles: expected {len(self.muscles)} (the model's), got {len(muscles)}")
        active, passive = active0.copy(), passive0.copy()
        for i, (m, m0) in enumerate(zip(muscles, self.muscles, strict=True)):
            if m is not m0 and m != m0:
                active[:, i], passive[:, i] = rigid_tendon(m, geo["lengths"][:, i], geo["speeds"][:, i])
        return active, passive

    def _residuals(self, loads: dict[str, np.ndarray], z: np.ndarray) -> np.ndarray:
        """(k, n_r): the residual actuators' controls that carry the root's loads at least cost (sum u^2: the
        least-norm solution; with one actuator per root coordinate, OpenSim's FX, FY, MZ, the only one)."""
        k = z.shape[0]
        if not self.residuals:
            return np.zeros((k, 0))
        rows = [list(self.scene.coordinates).index(c) for c in self.root_coordinates]
        A = actuator_columns(self.tree, self.scene, tuple(self.residuals), self.osim.frames, z)[:, rows, :]
        tau = np.column_stack([loads[lab_name(c)] for c in self.root_coordinates])
        u = np.stack([np.linalg.lstsq(A[i], tau[i], rcond=None)[0] for i in range(k)])
        for j, a in enumerate(self.residuals):  # no muscle reaches the root: its loads are theirs, bounds or not
            out = (u[:, j] < a.min_control - 1e-9 * (1 + abs(a.min_control))) | \
                  (u[:, j] > a.max_control + 1e-9 * (1 + abs(a.max_control)))
            if out.any():
                i = int(np.argmax(out))
                raise ValueError(f"{self.source}: {a.kind} {a.name!r}: the root's balance (the inverse dynamics' "
                                 f"residual) needs a control of {u[i, j]:.4g} at t = {self.t[i]:g} s, outside its "
                                 f"bounds [{a.min_control:g}, {a.max_control:g}] ({int(out.sum())} of {k} frames): "
                                 "widen min_control and max_control (the residuals carry the root's loads whole)")
        return u

    def _reaction_geometry(self, z: np.ndarray) -> dict[str, tuple]:
        """joint -> (unit (k, 3, n_m), lever (k, 1, 2), child and parent angles (k, 1), offset (k, 1, 2) or None):
        what its reaction takes from the frames' coordinates (:func:`casflex.muscles.reaction.joint_reactions`)."""
        k, n_m = z.shape[0], len(self.muscles)
        unit = np.array(self.paths.unit_loads.map(k)(z.T)).reshape(-1, n_m, k, order="F").transpose(2, 0, 1)
        slide = np.array(self._slide.map(k)(z.T)).reshape(2, -1, k, order="F").transpose(2, 1, 0)
        q = np.array(self.tree.forward.map(k)(z.T)).T
        out = {}
        for h in self.joints:
            i = self.tree.hinges.index(h)
            parent, child, origin = self.osim.joint_frames[h]
            angles = {s: self._body_angle(body, q)[:, None] for s, body in (("parent", parent), ("child", child))}
            offset = self._offset(h, parent, origin, q, k) if self.reaction.on == "parent" else None
            out[h] = (unit[:, 3 * i:3 * i + 3, :], slide[:, i:i + 1, :], angles["child"], angles["parent"], offset)
        return out

    def _reactions(self, loads: dict[str, np.ndarray], geometry: dict[str, tuple], forces: np.ndarray
                   ) -> dict[str, JointReactions]:
        """joint -> its reaction (:func:`casflex.muscles.reaction.joint_reactions`) with the muscles' ``forces``,
        the frames' ``geometry`` (:meth:`_reaction_geometry`)."""
        out = {}
        for h, (unit, lever, child, parent, offset) in geometry.items():
            net = np.column_stack([loads[f"{h}.fx"], loads[f"{h}.fy"], loads[f"{h}.moment"]])[:, None, :]
            out[h] = joint_reactions(net, unit, forces, child, parent, self.reaction, lever=lever, offset=offset)
        return out

    def _node_pose(self, body: str, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(position (k, 2), its turn from the default pose (k,), the default (x, y, theta)) of the OpenSim body's
        node."""
        return self._node_of(node_name(body), q)

    def _body_angle(self, body: str, q: np.ndarray) -> np.ndarray:
        """(k,) rad: the body frame's angle in the ground (the ground's: 0)."""
        if body == "ground":
            return np.zeros(q.shape[0])
        R = self.osim.frames[body][0]
        return self._node_pose(body, q)[1] + math.atan2(R[1, 0], R[0, 0])

    def _offset(self, hinge: str, parent: str, origin: np.ndarray, q: np.ndarray, k: int) -> np.ndarray:
        """(k, 1, 2) m: the parent joint frame's origin (which moves with the parent) minus the hinge's point."""
        j = self.scene.item(hinge)
        b = j.nodes[1]
        pb, turn_b, xb = self._node_of(b, q)
        P0 = np.asarray(self.scene.joint_point(j), dtype=float) - xb[:2]
        P = pb + _turn(turn_b, P0)
        if parent == "ground":
            F = np.broadcast_to(np.asarray(origin, dtype=float)[:2], (k, 2))
        else:
            pa, turn_a, xa = self._node_pose(parent, q)
            F = pa + _turn(turn_a, np.asarray(origin, dtype=float)[:2] - xa[:2])
        return (F - P)[:, None, :]

    def reaction_point(self, hinge: str, on: str, frame: str, q: np.ndarray) -> np.ndarray:
        """(k, 3) m: where the reaction on body ``on`` acts (the hinge's point on the child; the parent joint
        frame's origin on the parent), from body ``frame``'s origin in its axes ("ground": the ground's). The
        point's out-of-plane coordinate is the parent joint frame's (the joint's frames share it in a plane)."""
        parent, child, origin = self.osim.joint_frames[hinge]
        j = self.scene.item(hinge)
        pb, turn_b, xb = self._node_of(j.nodes[1], q)
        P = pb + _turn(turn_b, np.asarray(self.scene.joint_point(j), dtype=float) - xb[:2])
        if on != child:
            P = P + self._offset(hinge, parent, origin, q, q.shape[0])[:, 0, :]
        z = float(origin[2])
        if frame == "ground":
            return np.column_stack([P, np.full(q.shape[0], z)])
        R, p = self.osim.frames[frame]
        pn, turn, x0 = self._node_pose(frame, q)
        rel = P - (pn + _turn(turn, p[:2] - x0[:2]))  # from the frame's origin now, in the ground's axes
        c, s = np.cos(turn), np.sin(turn)
        back = np.column_stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1],
                                np.full(q.shape[0], z - p[2])])  # the body's turn undone: its default pose
        return back @ R  # each row R^T v: in the body's axes

    def _node_of(self, node: str, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`_node_pose` of the scene node ``node``."""
        i = self.tree.model.node_names.index(node)
        x0 = np.asarray(self.tree.model.q0[3 * i: 3 * i + 3], dtype=float).ravel()
        return q[:, 3 * i:3 * i + 2], q[:, 3 * i + 2] - x0[2], x0


def reserve_actuators(scene, root: str, optimal_force: float) -> tuple:
    """A reserve (CoordinateActuator) of ``optimal_force`` (N m or N) on every lab coordinate of ``scene`` and the
    residuals on the root's body: a force along x and y at its node and a torque about the plane's normal (as
    OpenSim's reserve files give them, ``FX``, ``FY``, ``MZ``), all with free controls."""
    from casflex.scene.osim_actuators import Actuator

    if not (math.isfinite(optimal_force) and optimal_force > 0):
        raise ValueError(f"reserves: expected an optimal force > 0 (N m or N), got {optimal_force!r}")
    coords = [c for c in scene.coordinates if not c.of.startswith(f"{root}.")]
    return (Actuator("FX", "PointActuator", optimal_force, body=root, direction=(1.0, 0.0, 0.0), force_is_global=True),
            Actuator("FY", "PointActuator", optimal_force, body=root, direction=(0.0, 1.0, 0.0), force_is_global=True),
            Actuator("MZ", "TorqueActuator", optimal_force, body=root, other="ground"),
            *(Actuator(f"{c.name}_reserve", "CoordinateActuator", optimal_force, coordinate=c.name) for c in coords))


def residual_warnings(trial: TrialMuscles, out: FrameOutputs) -> list[str]:
    """The lines that say a residual force on the root carries more than :data:`RESIDUAL_WARNING` body weights RMS
    over the trial (its ground reactions missing, on the wrong body or scaled wrong): the muscles then carry another
    motion's loads, whatever their own numbers look like."""
    from casflex.lab.plate_checks import scene_mass

    w = scene_mass(trial.scene) * float(np.hypot(*trial.scene.gravity))
    lines = []
    for j, a in enumerate(trial.residuals):
        if a.kind != "PointActuator" or not w > 0:
            continue
        f = out.residuals[:, j] * a.optimal_force
        rms = float(np.sqrt(np.mean(f ** 2)))
        if rms > RESIDUAL_WARNING * w:
            lines.append(f"residual {a.name!r} carries {rms / w:.2f} body weights RMS over the trial (at most "
                         f"{np.abs(f).max() / w:.2f}; a trial with its ground reactions, a few tenths): the ground "
                         "reactions are missing, on another body or in other units; the muscles carry another motion")
    return lines


def uncrossed_notes(trial: TrialMuscles, out: FrameOutputs) -> list[str]:
    """The line naming the muscles that cross no coordinate of the plane (both ends on one segment, or crossing only
    coordinates the plane holds still), if any."""
    idle = [m.name for i, m in enumerate(trial.muscles) if np.abs(out.arms[:, i, :]).max() < 1e-9]
    return [f"muscles {', '.join(idle)} cross no coordinate of the plane (moment arms 0 at every frame): they "
            "carry no moment, their activations stay at the lower bound"] if idle else []


def _turn(angle: np.ndarray, v: np.ndarray) -> np.ndarray:
    """v (2,) turned by the angles (k,): (k, 2)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.column_stack([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def _with_reserve_bounds(options: StaticOptimization, bounds: tuple[float, float]) -> StaticOptimization:
    return dataclasses.replace(options, reserve_bounds=bounds)


def muscle_result(trial: TrialMuscles, out: FrameOutputs, z: np.ndarray, report=(), settings=None):
    """The :class:`~casflex.muscles.result.MuscleResult` of :meth:`TrialMuscles.solve`'s ``out`` at the frames'
    coordinates z (k, n_z): OpenSim's column labels for the reactions, each reaction's point, the actuators in
    the order given (reserves from static optimization, residuals from the root's balance)."""
    from casflex.lab.plate_checks import scene_mass
    from casflex.muscles.result import MuscleResult

    k = z.shape[0]
    names = [c.name for c in trial.joint_coordinates]
    controls, forces, actuators = [], [], []
    for a in trial.used:  # the order given (OpenSim writes its actuator set's)
        if a.kind == "CoordinateActuator" and a.coordinate in trial.reserves:
            u = out.so.reserve_controls[:, names.index(a.coordinate)]
        else:
            u = out.residuals[:, trial.residuals.index(a)]
        actuators.append(a.name)
        controls.append(u)
        forces.append(u * a.optimal_force)
    q = np.array(trial.tree.forward.map(k)(z.T)).T
    columns, resultants = {}, {}
    for h, r in out.reactions.items():
        parent, child, _ = trial.osim.joint_frames[h]
        on = child if trial.reaction.on == "child" else parent
        frame = {"child": child, "parent": parent, "ground": "ground"}[trial.reaction.frame]
        load = r.loads[:, 0, :]
        point = trial.reaction_point(h, on, frame, q)
        values = (load[:, 0], load[:, 1], 0 * load[:, 0], 0 * load[:, 0], 0 * load[:, 0], load[:, 2], *point.T)
        for suffix, v in zip(("fx", "fy", "fz", "mx", "my", "mz", "px", "py", "pz"), values, strict=True):
            columns[f"{h}_on_{on}_in_{frame}_{suffix}"] = v
        resultants[h] = np.hypot(load[:, 0], load[:, 1]) * (trial.reaction.body_weight or 1.0)
    report = (*report, *uncrossed_notes(trial, out))
    g = float(np.hypot(*trial.scene.gravity))
    empty = np.zeros((k, 0))
    return MuscleResult(t=trial.t, muscles=tuple(m.name for m in trial.muscles), activations=out.so.activations,
                        forces=out.so.forces, actuators=tuple(actuators),
                        controls=np.column_stack(controls) if controls else empty,
                        actuator_forces=np.column_stack(forces) if forces else empty, coordinates=tuple(names),
                        reserve_share=out.so.reserve_share, reactions=columns, resultants=resultants,
                        body_weight=scene_mass(trial.scene) * g, report=tuple(report), settings=dict(settings or {}),
                        uncrossed=tuple(n for i, n in enumerate(names) if np.abs(out.arms[:, :, i]).max() < 1e-9))
