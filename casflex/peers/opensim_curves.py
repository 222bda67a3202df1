"""OpenSim 4.6's own muscle curves and rigid-tendon muscle: the reference :mod:`casflex.muscles.curves` is
measured against.

A muscle is given as plain data (:func:`muscle_data` of a :class:`casflex.scene.muscles.Muscle`: its kind,
name, five common properties and its (tag, value) properties, booleans as 1 / 0), set on a new OpenSim muscle
of that kind through OpenSim's property API (the tags are the .osim's: ``ActiveForceLengthCurve.minimum_value``
sets the ``minimum_value`` of the muscle's ``ActiveForceLengthCurve``), in OpenSim's worker process (see
:mod:`casflex.peers.opensim`). :func:`curve_values` reads the curves themselves (Millard's curve objects as
the muscle has finalized them, DeGroote's calc* methods); :func:`muscle_values` puts the muscle in a model of
its own, the path from the ground's origin to a body on a slider along x, so that the path's length is the
slider's coordinate and its lengthening speed the coordinate's speed, and reads the muscle there.
"""

from __future__ import annotations

import os
from typing import Any

from casflex.peers.opensim import _opensim, _run

__all__ = ["curve_values", "file_muscle_values", "muscle_data", "muscle_values", "property_names"]

_HERE = "casflex.peers.opensim_curves"
_COMMON = ("max_isometric_force", "optimal_fiber_length", "tendon_slack_length", "pennation_angle_at_optimal",
           "max_contraction_velocity")
_MILLARD = {"active_force_length": "ActiveForceLengthCurve", "passive_force_length": "FiberForceLengthCurve",
            "force_velocity": "ForceVelocityCurve", "tendon_force_length": "TendonForceLengthCurve"}
_DEGROOTE = {"active_force_length": "calcActiveForceLengthMultiplier",
             "passive_force_length": "calcPassiveForceMultiplier",
             "force_velocity": "calcForceVelocityMultiplier", "tendon_force_length": "calcTendonForceMultiplier"}


def muscle_data(muscle: Any) -> dict:
    """The plain data of a casflex Muscle that the worker needs (picklable without casflex.scene)."""
    return {"kind": muscle.kind, "name": muscle.name, "common": {k: float(getattr(muscle, k)) for k in _COMMON},
            "properties": [(k, float(v)) for k, v in muscle.properties]}


def _set(osim, obj, tag: str, value: float) -> None:
    prop = obj.updPropertyByName(tag)
    if prop.getTypeName() == "bool":
        osim.PropertyHelper.setValueBool(bool(value), prop)
    elif prop.size() == 0:  # an optional property left empty (e.g. FiberForceLengthCurve's stiffnesses)
        osim.PropertyHelper.appendValueDouble(float(value), prop)
    else:
        osim.PropertyHelper.setValueDouble(float(value), prop)


def _muscle(osim, data: dict):
    if "file" in data:  # the muscle as OpenSim reads it from a ForceSet document
        forces = osim.ForceSet.safeDownCast(osim.OpenSimObject.makeObjectFromFile(data["file"]))
        copy = forces.get(data["name"]).clone()
        copy.thisown = False  # the model the muscle is added to owns it, not this proxy
        return getattr(osim, data["kind"]).safeDownCast(copy)
    muscle = getattr(osim, data["kind"])()
    muscle.setName(data["name"])
    for tag, value in data["common"].items():
        _set(osim, muscle, tag, value)
    for tag, value in data["properties"]:
        if "." in tag:
            curve, sub = tag.split(".", 1)
            _set(osim, getattr(muscle, f"upd_{curve}")(), sub, value)
        else:
            _set(osim, muscle, tag, value)
    return muscle


def _curves_here(data: dict, x: dict[str, list[float]]) -> dict[str, dict[str, list[float]]]:
    osim = _opensim()
    muscle = _muscle(osim, data)
    muscle.finalizeFromProperties()
    out = {}
    for curve, xs in x.items():
        if data["kind"] == "Millard2012EquilibriumMuscle":
            obj = getattr(muscle, f"get_{_MILLARD[curve]}")()
            out[curve] = {"value": [obj.calcValue(v) for v in xs], "slope": [obj.calcDerivative(v, 1) for v in xs]}
        else:
            method = getattr(muscle, _DEGROOTE[curve])
            out[curve] = {"value": [method(v) for v in xs]}
    return out


def curve_values(muscle: Any, x: dict[str, list[float]], *, worker: bool | None = None) -> dict:
    """OpenSim's curves of ``muscle`` (Millard2012EquilibriumMuscle or DeGrooteFregly2016Muscle) at the points
    x = {curve: [normalised lengths or velocities]} (curves: active_force_length, passive_force_length,
    force_velocity, tendon_force_length): {curve: {"value": [...], "slope": [...] (Millard: dy/dx)}}."""
    points = {k: [float(v) for v in xs] for k, xs in x.items()}
    return _run(f"{_HERE}:_curves_here", worker, muscle_data(muscle), points)


_READ = {"fal": "getActiveForceLengthMultiplier", "fpe": "getPassiveForceMultiplier", "lce": "getFiberLength",
         "phi": "getPennationAngle", "v_n": "getNormalizedFiberVelocity", "fv": "getForceVelocityMultiplier",
         "passive": "getPassiveFiberForceAlongTendon", "tendon_force": "getTendonForce"}


def _muscle_here(data: dict, lmt: list[float], vmt: list[float], lce: list[float] | None) -> dict[str, list[float]]:
    osim = _opensim()
    model = osim.Model()
    body = osim.Body("block", 1.0, osim.Vec3(0), osim.Inertia(1, 1, 1))
    model.addBody(body)
    zero = osim.Vec3(0)
    joint = osim.SliderJoint("slide", model.getGround(), zero, zero, body, zero, zero)
    coord = joint.updCoordinate()
    coord.setName("q")
    coord.setRangeMin(-100.0)
    coord.setRangeMax(100.0)
    model.addJoint(joint)
    muscle = _muscle(osim, data)
    muscle.addNewPathPoint("origin", model.getGround(), zero)
    muscle.addNewPathPoint("insertion", body, zero)
    model.addForce(muscle)
    state = model.initSystem()
    muscle = getattr(osim, data["kind"]).safeDownCast(model.updForceSet().get(data["name"]))
    reads = dict(_READ)
    if data["kind"] != "Thelen2003Muscle":
        reads.update(elastic="getPassiveFiberElasticForceAlongTendon", damping="getPassiveFiberDampingForceAlongTendon")
    out: dict[str, list[float]] = {k: [] for k in [*reads, "active", "length"]}
    for i, (length, speed) in enumerate(zip(lmt, vmt, strict=True)):
        coord.setValue(state, length, False)
        coord.setSpeedValue(state, speed)
        muscle.setActivation(state, 1.0)
        if lce is not None:
            muscle.setFiberLength(state, lce[i])
        model.realizeDynamics(state)
        for key, getter in reads.items():
            out[key].append(getattr(muscle, getter)(state))
        out["length"].append(muscle.getLength(state))
        out["active"].append(muscle.calcInextensibleTendonActiveFiberForce(state, 1.0))
    return out


def muscle_values(muscle: Any, lmt: list[float], vmt: list[float], *, fiber_length: list[float] | None = None,
                  worker: bool | None = None) -> dict[str, list[float]]:
    """OpenSim's ``muscle`` (its properties as the .osim gives them: set ``ignore_tendon_compliance`` 1 for
    Millard's and DeGroote's rigid tendon) alone in a model, at activation 1, path lengths ``lmt`` (m) and
    lengthening speeds ``vmt`` (m/s); ``fiber_length`` (m): the fibre length state set at each point
    (Thelen2003Muscle has no rigid tendon). Returns lists: fal, fpe, lce, phi, v_n, fv, passive (along the
    tendon, N), tendon_force, active (calcInextensibleTendonActiveFiberForce(s, 1.0), N), length (the path's,
    m), and for Millard and DeGroote elastic and damping (along the tendon, N)."""
    return _run(f"{_HERE}:_muscle_here", worker, muscle_data(muscle), [float(v) for v in lmt],
                [float(v) for v in vmt], None if fiber_length is None else [float(v) for v in fiber_length])


def file_muscle_values(path: str, kind: str, name: str, lmt: list[float], vmt: list[float], *,
                       fiber_length: list[float] | None = None, worker: bool | None = None) -> dict[str, list[float]]:
    """:func:`muscle_values` of the muscle ``name`` (of class ``kind``) as OpenSim reads it from the document
    ``path`` holding a ForceSet (e.g. a model's muscles cut without their paths)."""
    data = {"file": os.path.abspath(path), "kind": kind, "name": name}
    return _run(f"{_HERE}:_muscle_here", worker, data, [float(v) for v in lmt], [float(v) for v in vmt],
                None if fiber_length is None else [float(v) for v in fiber_length])


def _names_here(kind: str) -> list[str]:
    osim = _opensim()
    muscle = getattr(osim, kind)()
    names = []
    for i in range(muscle.getNumProperties()):
        prop = muscle.getPropertyByIndex(i)
        if prop.getName().endswith("Curve"):
            curve = getattr(muscle, f"get_{prop.getName()}")()
            names += [f"{prop.getName()}.{curve.getPropertyByIndex(j).getName()}"
                      for j in range(curve.getNumProperties())]
        else:
            names.append(prop.getName())
    return names


def property_names(kind: str, *, worker: bool | None = None) -> list[str]:
    """The property names (the .osim's tags) of OpenSim's muscle class ``kind``, its curve objects' as
    ``<Curve>.<tag>``."""
    return _run(f"{_HERE}:_names_here", worker, kind)
