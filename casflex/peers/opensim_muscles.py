"""OpenSim's own muscle geometry: each muscle's path length and moment arms at given poses, the reference
:mod:`casflex.muscles.path` is measured against. Runs in OpenSim's worker process (:mod:`casflex.peers.opensim`:
OpenSim and CasADi do not share a process)."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence

import numpy as np

from casflex.peers.opensim import _opensim, _run

__all__ = ["fiber_equilibrium", "muscle_geometry"]

_HERE = "casflex.peers.opensim_muscles"


def _geometry_here(model_path: str, poses: list[dict[str, float]]) -> dict:
    osim = _opensim()
    model = osim.Model(model_path)
    state = model.initSystem()
    cs = model.getCoordinateSet()
    coords = [cs.get(i) for i in range(cs.getSize()) if not cs.get(i).getDefaultLocked()]
    muscles = model.getMuscles()
    ms = [muscles.get(i) for i in range(muscles.getSize())]
    L = np.zeros((len(poses), len(ms)))
    r = np.zeros((len(poses), len(ms), len(coords)))
    for k, pose in enumerate(poses):
        for name, value in pose.items():
            cs.get(name).setValue(state, float(value), False)
        model.realizePosition(state)
        for i, m in enumerate(ms):
            L[k, i] = m.getLength(state)
            for j, c in enumerate(coords):
                r[k, i, j] = m.computeMomentArm(state, c)
    return {"muscles": [m.getName() for m in ms], "coordinates": [c.getName() for c in coords], "lengths": L,
            "moment_arms": r}


def muscle_geometry(model_path: str | os.PathLike[str], poses: Sequence[Mapping[str, float]], *,
                    worker: bool | None = None) -> dict:
    """OpenSim 4's ``getLength`` and ``computeMomentArm`` of each muscle of the model file ``model_path`` at each
    pose (coordinate name -> value, rad or m; the others at their default values): {"muscles": names,
    "coordinates": the unlocked coordinates' names, "lengths": (k, n_m) m, "moment_arms": (k, n_m, n_c)}."""
    return _run(f"{_HERE}:_geometry_here", worker, os.path.abspath(model_path),
                [{str(c): float(v) for c, v in p.items()} for p in poses])


def _equilibrium_here(model_path: str, poses: list[dict[str, float]], activation: float) -> dict:
    osim = _opensim()
    model = osim.Model(model_path)
    state = model.initSystem()
    cs = model.getCoordinateSet()
    muscles = model.getMuscles()
    ms = [muscles.get(i) for i in range(muscles.getSize())]
    T = np.zeros((len(poses), len(ms)))
    ln = np.zeros((len(poses), len(ms)))
    L = np.zeros((len(poses), len(ms)))
    for k, pose in enumerate(poses):
        for name, value in pose.items():
            cs.get(name).setValue(state, float(value), False)
            cs.get(name).setSpeedValue(state, 0.0)
        for m in ms:
            m.setActivation(state, activation)
        model.equilibrateMuscles(state)
        model.realizeDynamics(state)
        for i, m in enumerate(ms):
            T[k, i], ln[k, i], L[k, i] = m.getTendonForce(state), m.getNormalizedFiberLength(state), m.getLength(state)
    return {"muscles": [m.getName() for m in ms], "tendon_forces": T, "norm_fiber_lengths": ln, "lengths": L}


def fiber_equilibrium(model_path: str | os.PathLike[str], poses: Sequence[Mapping[str, float]], activation: float,
                      *, worker: bool | None = None) -> dict:
    """OpenSim 4's fibre-tendon equilibrium (``Model::equilibrateMuscles``, the speeds 0) of each muscle of the model
    file at each pose, every muscle at ``activation``: {"muscles": names, "tendon_forces": (k, n_m) N,
    "norm_fiber_lengths": (k, n_m), "lengths": (k, n_m) m}."""
    return _run(f"{_HERE}:_equilibrium_here", worker, os.path.abspath(model_path),
                [{str(c): float(v) for c, v in p.items()} for p in poses], float(activation))
