"""OpenSim's own static optimization and joint reactions on a lab's trial: the peer of :mod:`casflex.muscles`.

OpenSim 4.6's ``AnalyzeTool`` run as a gait lab runs it from a setup file, on a :class:`Trial`: the model,
the coordinates (.mot, the IK result), the ground reactions (an ``ExternalLoads`` file), the reserve and
residual actuators (a ``ForceSet`` file appended to the model's forces), the coordinates' cut-off.
:func:`static_optimization` runs its ``StaticOptimization`` analysis, then ``JointReaction`` with SO's forces as
its ``forces_file`` (:func:`joint_reaction`: any forces file); :func:`muscle_inputs` reads, at the same states,
what SO sees of the muscles: each muscle's force at full activation as SO computes it
(``Muscle::calcInextensibleTendonActiveFiberForce(s, 1)``), its passive fibre force, its length, its moment arm
about each coordinate, its load per N on each joint's distal bodies. They run in OpenSim's worker process (see
:mod:`casflex.peers.opensim`) and return the output files and the seconds each ``run()`` took.
:func:`rigid_tendon_model` writes a model's copy with ``ignore_tendon_compliance`` on every muscle (OpenSim's SO
treats a Millard muscle's tendon as rigid either way: docs/muscles.md).
"""

from __future__ import annotations

import os
import time
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass

from casflex.peers.opensim import _opensim, _run

__all__ = ["Trial", "joint_reaction", "muscle_inputs", "rigid_tendon_model", "static_optimization"]

_HERE = "casflex.peers.opensim_analyses"


def rigid_tendon_model(src: str | os.PathLike[str], dest: str | os.PathLike[str]) -> str:
    """Write ``dest``: the .osim ``src`` with ``<ignore_tendon_compliance>true`` on every muscle (added where the
    file leaves it out). Needs no OpenSim; returns dest."""
    tree = ET.parse(os.fspath(src))
    kinds = ("Millard2012EquilibriumMuscle", "Thelen2003Muscle", "DeGrooteFregly2016Muscle",
             "Millard2012AccelerationMuscle")
    for kind in kinds:
        for muscle in tree.getroot().iter(kind):
            tag = muscle.find("ignore_tendon_compliance")
            if tag is None:
                tag = ET.SubElement(muscle, "ignore_tendon_compliance")
            tag.text = "true"
    tree.write(os.fspath(dest), encoding="UTF-8", xml_declaration=True)
    return os.fspath(dest)


@dataclass(frozen=True)
class Trial:
    """A lab trial as OpenSim's AnalyzeTool takes it: the model file, the coordinates (.mot, e.g. the IK result),
    the ``ExternalLoads`` file ``loads`` (None: none), the actuator files ``forces`` (reserves and residuals,
    appended to the model's forces), the coordinates' low-pass ``cutoff`` (Hz; None: not filtered) and the span
    ``t_start`` to ``t_end`` (s). Paths are made absolute here: the worker runs elsewhere."""

    model: str
    coordinates: str
    loads: str | None = None
    forces: tuple[str, ...] = ()
    cutoff: float | None = 6.0
    t_start: float = 0.0
    t_end: float = 1e9

    def __post_init__(self) -> None:
        for name in ("model", "coordinates"):
            object.__setattr__(self, name, os.path.abspath(getattr(self, name)))
        object.__setattr__(self, "loads", os.path.abspath(self.loads) if self.loads else None)
        object.__setattr__(self, "forces", tuple(os.path.abspath(f) for f in self.forces))
        if self.cutoff is not None and not self.cutoff > 0.0:
            raise ValueError(f"cutoff: expected a positive frequency (Hz) or None, got {self.cutoff!r}")
        if not self.t_start < self.t_end:
            raise ValueError(f"t_start, t_end: expected t_start < t_end, got {self.t_start!r}, {self.t_end!r}")


def _setup(path: str, name: str, trial: Trial, results: str, analyses: list[ET.Element]) -> str:
    """Write an ``AnalyzeTool`` setup file (absolute paths) running ``analyses``; returns its path."""
    root = ET.Element("OpenSimDocument", Version="40000")
    tool = ET.SubElement(root, "AnalyzeTool", name=name)
    for tag, text in (("model_file", trial.model), ("replace_force_set", "false"),
                      ("force_set_files", " ".join(trial.forces)), ("results_directory", results),
                      ("output_precision", "12"), ("initial_time", repr(trial.t_start)),
                      ("final_time", repr(trial.t_end)), ("solve_for_equilibrium_for_auxiliary_states", "false")):
        ET.SubElement(tool, tag).text = text
    objects = ET.SubElement(ET.SubElement(tool, "AnalysisSet", name="Analyses"), "objects")
    objects.extend(analyses)
    ET.SubElement(tool, "ControllerSet", name="Controllers").append(ET.Element("objects"))
    ET.SubElement(tool, "external_loads_file").text = trial.loads or ""
    ET.SubElement(tool, "coordinates_file").text = trial.coordinates
    cutoff = "-1" if trial.cutoff is None else repr(trial.cutoff)
    ET.SubElement(tool, "lowpass_cutoff_frequency_for_coordinates").text = cutoff
    ET.ElementTree(root).write(path, encoding="UTF-8", xml_declaration=True)
    return path


def _analysis(kind: str, trial: Trial, **props: str) -> ET.Element:
    el = ET.Element(kind, name=kind)
    for tag, text in (("on", "true"), ("start_time", repr(trial.t_start)), ("end_time", repr(trial.t_end)),
                      ("step_interval", "1"), ("in_degrees", "true"), *props.items()):
        ET.SubElement(el, tag).text = text
    return el


def _so_here(trial: Trial, results: str, exponent: float, tol: float, iters: int, joints: list[str], on: str,
             frame: str) -> dict:
    osim = _opensim()
    os.makedirs(results, exist_ok=True)
    so = _analysis("StaticOptimization", trial, use_model_force_set="true", activation_exponent=repr(exponent),
                   use_muscle_physiology="true", optimizer_convergence_criterion=repr(tol),
                   optimizer_max_iterations=str(iters))
    setup = _setup(os.path.join(results, "setup_so.xml"), "so", trial, results, [so])
    log, level = os.path.join(results, "so.log"), osim.Logger.getLevelString()
    osim.Logger.setLevelString("warn")  # SO's failed frames are warnings: kept in the log, read back below
    osim.Logger.addFileSink(log)
    try:
        start = time.perf_counter()
        osim.AnalyzeTool(setup).run()
        so_seconds = time.perf_counter() - start
    finally:
        osim.Logger.removeFileSink()
        osim.Logger.setLevelString(level)
    force = os.path.join(results, "so_StaticOptimization_force.sto")
    jr = _jr_here(trial, force, results, "jr", joints, on, frame)
    return {"activation": os.path.join(results, "so_StaticOptimization_activation.sto"), "force": force,
            "reactions": jr["path"], "so_seconds": so_seconds, "jr_seconds": jr["seconds"], "log": log,
            "failed": _failed_times(log)}


def _failed_times(log: str) -> list[float]:
    """The times (s) of the frames OpenSim's SO logged as failed ("... could not find a solution at time = t."):
    it records them anyway, with whatever its optimizer left (docs/muscles.md)."""
    import re

    if not os.path.exists(log):  # OpenSim's file sink makes the file at its first line: nothing logged
        return []
    with open(log) as fh:
        text = fh.read()
    return [float(m.group(1).rstrip(".")) for m in re.finditer(r"could not find a solution at time = (\S+)", text)]


def _jr_here(trial: Trial, force_file: str, results: str, name: str, joints: list[str], on: str, frame: str) -> dict:
    osim = _opensim()
    os.makedirs(results, exist_ok=True)
    jr = _analysis("JointReaction", trial, forces_file=force_file, joint_names=" ".join(joints),
                   apply_on_bodies=on, express_in_frame=frame)
    setup = _setup(os.path.join(results, f"setup_{name}.xml"), name, trial, results, [jr])
    start = time.perf_counter()
    osim.AnalyzeTool(setup).run()
    return {"path": os.path.join(results, f"{name}_JointReaction_ReactionLoads.sto"),
            "seconds": time.perf_counter() - start}


def joint_reaction(trial: Trial, force_file, results, *, name: str = "jr", joints: Sequence[str] = ("ALL",),
                   on: str = "child", frame: str = "child", worker: bool | None = None) -> dict:
    """OpenSim's ``JointReaction`` of ``joints`` on ``trial`` with every actuator's force read from ``force_file``
    (a .sto with a column per actuator, N or N m: e.g. SO's forces), on the ``on`` body ("child" or "parent"),
    expressed in ``frame`` ("child", "parent", "ground" or a frame's name); written to
    ``<results>/<name>_JointReaction_ReactionLoads.sto``. Returns {"path", "seconds"}."""
    return _run(f"{_HERE}:_jr_here", worker, trial, os.path.abspath(force_file), os.path.abspath(results), name,
                list(joints), on, frame)


def static_optimization(trial: Trial, results, *, exponent: float = 2.0, tol: float = 1e-4,
                        max_iterations: int = 100, joints: Sequence[str] = ("ALL",), on: str = "child",
                        frame: str = "child", worker: bool | None = None) -> dict:
    """OpenSim's static optimization of ``trial`` with SO's options ``exponent`` (activation_exponent), ``tol``
    (optimizer_convergence_criterion) and ``max_iterations`` (OpenSim's defaults), then its ``JointReaction`` of
    ``joints`` with SO's forces (:func:`joint_reaction`). Outputs in the directory ``results``. Returns
    {"activation", "force", "reactions": .sto paths, "so_seconds", "jr_seconds": the two runs' times, "log": SO's
    warnings (``<results>/so.log``), "failed": the times (s) of the frames SO logged as failed (its optimizer
    stopped, e.g. at ``max_iterations``; OpenSim records them anyway)}."""
    return _run(f"{_HERE}:_so_here", worker, trial, os.path.abspath(results), float(exponent), float(tol),
                int(max_iterations), list(joints), on, frame)


def _states(osim, m, s, trial: Trial):
    """Yield each frame's time, ``s`` set to the states OpenSim's AnalyzeTool makes of the trial's coordinates."""
    t0, t1 = trial.t_start, trial.t_end
    tool = osim.AnalyzeTool(m)
    tool.setCoordinatesFileName(trial.coordinates)
    tool.setLowpassCutoffFrequency(-1.0 if trial.cutoff is None else float(trial.cutoff))
    tool.loadStatesFromFile(s)
    states = tool.getStatesStorage()
    names = list(m.getStateVariableNames().get(i) for i in range(m.getNumStateVariables()))
    labels = states.getColumnLabels()
    cols = {labels.get(i + 1): i for i in range(labels.getSize() - 1)}
    for r in range(states.getSize()):
        time_r = states.getStateVector(r).getTime()
        if time_r < t0 - 1e-5 or time_r > t1 + 1e-5:  # the filtered states keep times within 1e-6 s
            continue
        data = states.getStateVector(r).getData()
        values = m.getStateVariableValues(s)
        for j, name in enumerate(names):
            if name in cols:
                values.set(j, data.get(cols[name]))
        s.setTime(time_r)
        m.setStateVariableValues(s, values)
        m.assemble(s)
        m.realizeVelocity(s)
        yield time_r


def _subtrees(m, joints: list[str]) -> list[set[str]]:
    """The bodies distal to each joint (its child's base body and every body below it)."""
    parent = {}
    for i in range(m.getJointSet().getSize()):
        j = m.getJointSet().get(i)
        parent[j.getChildFrame().findBaseFrame().getName()] = j.getParentFrame().findBaseFrame().getName()
    out = []
    for name in joints:
        child = m.getJointSet().get(name).getChildFrame().findBaseFrame().getName()
        below = set()
        for body in parent:
            b = body
            while b in parent and b != child:
                b = parent[b]
            if b == child:
                below.add(body)
        out.append(below)
    return out


def _angle(frame, s) -> float:
    import math

    rot = frame.getTransformInGround(s).R().asMat33()
    return math.atan2(rot.get(1, 0), rot.get(0, 0))


def _units(osim, m, s, muscles, joints: list[str], below: list[set[str]]) -> list:
    """(n_j * 3, n_m): each muscle's load per N of tension on each joint's distal bodies (fx, fy N/N in the
    ground, mz m about the child frame's origin), from its path's point force directions."""
    import numpy as np

    out = np.zeros((3 * len(joints), len(muscles)))
    centres = [m.getJointSet().get(j).getChildFrame().getTransformInGround(s).p() for j in joints]
    for i, mu in enumerate(muscles):
        path = osim.GeometryPath.safeDownCast(mu.getPath())
        pfds = osim.ArrayPointForceDirection()
        path.getPointForceDirections(s, pfds)
        for n in range(pfds.getSize()):
            pfd = pfds.get(n)
            body = pfd.frame().findBaseFrame().getName()
            p = pfd.frame().findStationLocationInGround(s, pfd.point())
            d = pfd.direction()
            for h, bodies in enumerate(below):
                if body in bodies:
                    c = centres[h]
                    rx, ry = p.get(0) - c.get(0), p.get(1) - c.get(1)
                    out[3 * h:3 * h + 3, i] += (d.get(0), d.get(1), rx * d.get(1) - ry * d.get(0))
    return out


def _lever(m, s, joint) -> tuple[float, float]:
    """d(the child frame's origin in the ground)/d(the joint's first coordinate) at fixed other coordinates (m/rad):
    0 for a pin; a coupled knee's translation. Central differences of 1e-6 rad."""
    coord = joint.get_coordinates(0)
    value, out = coord.getValue(s), []
    for step in (1e-6, -1e-6):
        coord.setValue(s, value + step, False)
        m.realizePosition(s)
        p = joint.getChildFrame().getTransformInGround(s).p()
        out.append((p.get(0), p.get(1)))
    coord.setValue(s, value, False)
    m.realizeVelocity(s)
    return (out[0][0] - out[1][0]) / 2e-6, (out[0][1] - out[1][1]) / 2e-6


def _offset(joint, s) -> tuple[float, float]:
    """The parent joint frame's origin minus the child's, in the ground (m): 0 for a pin; a coupled knee's
    translation (OpenSim reports the reaction on the parent about the parent's origin)."""
    f, c = joint.getParentFrame().getTransformInGround(s).p(), joint.getChildFrame().getTransformInGround(s).p()
    return f.get(0) - c.get(0), f.get(1) - c.get(1)


def _inputs_here(trial: Trial, joints: list[str]) -> dict:
    import numpy as np

    osim = _opensim()
    m = osim.Model(trial.model)
    s = m.initSystem()
    muscles = [m.getMuscles().get(i) for i in range(m.getMuscles().getSize())]
    coords = [m.getCoordinateSet().get(i) for i in range(m.getCoordinateSet().getSize())]
    below = _subtrees(m, joints)
    t, out = [], {k: [] for k in ("active", "passive", "length", "speed", "arms", "units", "child", "parent",
                                 "lever", "offset")}
    for time_r in _states(osim, m, s, trial):
        t.append(time_r)
        out["active"].append([mu.calcInextensibleTendonActiveFiberForce(s, 1.0) for mu in muscles])
        out["passive"].append([mu.getPassiveFiberForceAlongTendon(s) for mu in muscles])
        out["length"].append([mu.getLength(s) for mu in muscles])
        out["speed"].append([mu.getLengtheningSpeed(s) for mu in muscles])
        out["arms"].append([[mu.computeMomentArm(s, c) for c in coords] for mu in muscles])
        out["units"].append(_units(osim, m, s, muscles, joints, below))
        js = [m.getJointSet().get(j) for j in joints]
        out["child"].append([_angle(j.getChildFrame().findBaseFrame(), s) for j in js])
        out["parent"].append([_angle(j.getParentFrame().findBaseFrame(), s) for j in js])
        out["lever"].append([_lever(m, s, j) for j in js])
        out["offset"].append([_offset(j, s) for j in js])
    return {"t": np.array(t), "muscles": [mu.getName() for mu in muscles], "coordinates": [c.getName() for c in coords],
            "joints": list(joints), **{k: np.array(v) for k, v in out.items()}}


def muscle_inputs(trial: Trial, *, joints: Sequence[str] = (), worker: bool | None = None) -> dict:
    """What OpenSim's SO sees of the muscles on ``trial`` (its model, coordinates and cutoff), at the
    states its AnalyzeTool makes of them: per frame, "active" (k, n_m) N each muscle's active force
    at full activation (``calcInextensibleTendonActiveFiberForce(s, 1)``), "passive" (k, n_m) N its passive fibre
    force along the tendon, "length" (k, n_m) m and "speed" (k, n_m) m/s its path's, "arms" (k, n_m, n_c) m its
    moment arm about each coordinate; for each joint of ``joints``, "units" (k, n_j * 3, n_m) each muscle's load
    per N of tension on the joint's distal bodies (fx, fy in the ground, mz m about the child frame's origin: the
    point OpenSim's JointReaction reports at) from its path's point force directions, "child" and "parent" (k, n_j)
    rad the angles of the joint's child and parent bodies in the ground (about z; a planar motion's), "lever"
    (k, n_j, 2) m/rad the child frame origin's motion in the ground per radian of the joint's first coordinate
    (0 for a pin; a coupled knee's translation: the generalized force is the moment about that origin plus the
    joint's force along it), "offset" (k, n_j, 2) m the parent joint frame's origin minus the child's in the
    ground (0 for a pin); with "t" (k,)
    s, "muscles", "coordinates" and "joints" (the model's orders)."""
    return _run(f"{_HERE}:_inputs_here", worker, trial, list(joints))
