"""OpenSim's own tools on a lab's files: the reference answer casflex's ``inverse`` is measured against.

``ScaleTool`` (a lab's scale setups), ``InverseKinematicsTool`` (a model file, a marker file, an IK task
set) and ``InverseDynamicsTool`` (the model, the coordinates, the ground reactions as an ``ExternalLoads``
file, the coordinates' cut-off), as a gait lab runs them from its setup files, here from Python. They run
in OpenSim's worker process (see :mod:`casflex.peers.opensim`: OpenSim and CasADi do not share a
process); each returns its output file and the seconds its ``run()`` took, so that
studies/opensim_gait.py can set them beside casflex's.
"""

from __future__ import annotations

import os
import time
import xml.etree.ElementTree as ET
from collections.abc import Mapping

from casflex.peers.opensim import _opensim, _run

__all__ = ["exact_times", "external_loads", "inverse_kinematics", "inverse_dynamics", "scale"]

_HERE = "casflex.peers.opensim_tools"


def external_loads(path: str | os.PathLike[str], data_file: str | os.PathLike[str], plates: Mapping[str, str]) -> str:
    """Write OpenSim's ``ExternalLoads`` file ``path`` for the ground reactions of ``data_file`` (a .mot):
    plates = {body: column prefix} (e.g. {"calcn_r": "ground_"}), each applying ``<prefix>force_v*`` (N) at
    ``<prefix>force_p*`` (m) plus ``<prefix>torque_*`` (N m), all in the ground, as OpenSim's examples do.
    Needs no OpenSim; returns the path."""
    root = ET.Element("OpenSimDocument", Version="40000")
    loads = ET.SubElement(root, "ExternalLoads", name="plates")
    objects = ET.SubElement(loads, "objects")
    for body, prefix in plates.items():
        ef = ET.SubElement(objects, "ExternalForce", name=f"plate_{body}")
        for tag, text in (("applied_to_body", body), ("force_expressed_in_body", "ground"),
                          ("point_expressed_in_body", "ground"), ("force_identifier", f"{prefix}force_v"),
                          ("point_identifier", f"{prefix}force_p"), ("torque_identifier", f"{prefix}torque_"),
                          ("data_source_name", "plates")):
            ET.SubElement(ef, tag).text = text
    ET.SubElement(loads, "datafile").text = os.path.abspath(data_file)
    ET.ElementTree(root).write(os.fspath(path), encoding="UTF-8", xml_declaration=True)
    return os.fspath(path)


def exact_times(src: str | os.PathLike[str], dest: str | os.PathLike[str], t0: float, rate: float) -> str:
    """Write ``dest``: the .mot / .sto ``src`` with its rows' times set to the frames' exact times t0 + k / rate
    (s). OpenSim's IK writes the trial's times rounded to the ms; its ID tool resamples such times at the
    smallest step and its ExternalForce splines the plates through them. Needs no OpenSim; returns dest."""
    with open(src) as fh:
        lines = fh.read().splitlines()
    head = next(i for i, ln in enumerate(lines) if ln.strip().lower() == "endheader") + 2
    rows = [ln.split("\t") for ln in lines[head:] if ln.strip()]
    with open(dest, "w") as fh:
        fh.write("\n".join(lines[:head] + ["\t".join([f"{t0 + k / rate:.10f}", *r[1:]])
                                           for k, r in enumerate(rows)]) + "\n")
    return os.fspath(dest)


def _ik_here(model: str, markers: str, tasks: str, out: str, t_start: float, t_end: float, accuracy: float
             ) -> dict:
    osim = _opensim()
    tool = osim.InverseKinematicsTool()
    model = osim.Model(model)  # held here: the tool keeps a pointer to it
    tool.setModel(model)
    tool.setMarkerDataFileName(markers)
    tool.set_IKTaskSet(osim.IKTaskSet(tasks))
    tool.setStartTime(t_start)
    tool.setEndTime(t_end)
    tool.set_accuracy(accuracy)
    tool.set_report_marker_locations(False)
    tool.set_report_errors(False)
    tool.setResultsDir(os.path.dirname(out))
    tool.setOutputMotionFileName(out)
    start = time.perf_counter()
    tool.run()
    return {"path": out, "seconds": time.perf_counter() - start}


def _id_here(model: str, coordinates: str, loads: str | None, out: str, cutoff: float | None, t_start: float,
             t_end: float) -> dict:
    osim = _opensim()
    tool = osim.InverseDynamicsTool()
    model = osim.Model(model)  # held here: the tool keeps a pointer to it
    tool.setModel(model)
    tool.setCoordinatesFileName(coordinates)
    tool.setLowpassCutoffFrequency(-1.0 if cutoff is None else float(cutoff))
    if loads:
        tool.setExternalLoadsFileName(loads)
    excluded = osim.ArrayStr()
    excluded.append("Muscles")
    tool.setExcludedForces(excluded)
    tool.setStartTime(t_start)
    tool.setEndTime(t_end)
    tool.setResultsDir(os.path.dirname(out))
    tool.setOutputGenForceFileName(os.path.basename(out))
    start = time.perf_counter()
    tool.run()
    return {"path": out, "seconds": time.perf_counter() - start}


def inverse_kinematics(model, markers, tasks, out, *, t_start: float = 0.0, t_end: float = 1e9,
                       accuracy: float = 1e-5, worker: bool | None = None) -> dict:
    """OpenSim's inverse kinematics of the marker file ``markers`` (.trc) with the model file ``model`` and the
    IK task set ``tasks`` (an ``IKTaskSet`` file: the lab's weights), from ``t_start`` to ``t_end`` (s), written
    to ``out`` (.mot, degrees). Returns {"path": out, "seconds": the tool's run time}."""
    return _run(f"{_HERE}:_ik_here", worker, *map(os.path.abspath, (model, markers, tasks, out)), float(t_start),
                float(t_end), float(accuracy))


def inverse_dynamics(model, coordinates, out, *, loads=None, cutoff: float | None = None, t_start: float = 0.0,
                     t_end: float = 1e9, worker: bool | None = None) -> dict:
    """OpenSim's inverse dynamics tool: the generalized forces (``<coordinate>_moment`` N m, ``_force`` N) of
    the model file ``model`` along the coordinates file ``coordinates`` (.mot, e.g. :func:`inverse_kinematics`'s),
    the coordinates low-pass filtered at ``cutoff`` Hz (None: not; the tool pads them by half their length and
    runs a 3rd-order Butterworth forward and back) and the ``ExternalLoads`` file ``loads`` applied (muscles
    excluded), from ``t_start`` to ``t_end`` (s), written to ``out`` (.sto). Returns {"path", "seconds"}."""
    loads = os.path.abspath(loads) if loads else None
    return _run(f"{_HERE}:_id_here", worker, *map(os.path.abspath, (model, coordinates)), loads, os.path.abspath(out),
                cutoff, float(t_start), float(t_end))


def _scale_here(setups: list[str]) -> dict:
    osim = _opensim()
    start, here = time.perf_counter(), os.getcwd()
    try:
        for setup in setups:
            os.chdir(os.path.dirname(setup))  # the setups name their files relative to themselves
            if not osim.ScaleTool(setup).run():
                raise RuntimeError(f"{setup}: OpenSim's ScaleTool failed")
    finally:
        os.chdir(here)
    return {"seconds": time.perf_counter() - start}


def scale(*setups, worker: bool | None = None) -> dict:
    """OpenSim's ScaleTool run on each setup file in turn, in that file's directory (a lab's setups name the
    generic model, the static trial and the outputs relative to themselves; a two-step pipeline scales in the
    first and places the markers in the second). Returns {"seconds": the tools' run time}."""
    return _run(f"{_HERE}:_scale_here", worker, [os.path.abspath(s) for s in setups])
