"""OpenSim's own scaling of a model's muscles: ``Model::scale`` with one factor per body, the reference
:mod:`casflex.muscles.scaling` is measured against. Runs in OpenSim's worker process (:mod:`casflex.peers.opensim`:
OpenSim and CasADi do not share a process)."""

from __future__ import annotations

import os
from collections.abc import Mapping

from casflex.peers.opensim import _opensim, _run

__all__ = ["scaled_muscles", "write_scaled"]

_HERE = "casflex.peers.opensim_scale"


def _scaled_model(model_path: str, factors: dict[str, float]):
    osim = _opensim()
    model = osim.Model(model_path)
    state = model.initSystem()
    scales = osim.ScaleSet()
    for body, f in factors.items():
        s = osim.Scale()
        s.setSegmentName(body)
        s.setScaleFactors(osim.Vec3(f, f, f))
        s.setApply(True)
        scales.cloneAndAppend(s)
    model.scale(state, scales, False, -1.0)  # the masses as they are: casflex scales them apart
    return model


def _write_scaled_here(model_path: str, factors: dict[str, float], out: str) -> str:
    _scaled_model(model_path, factors).printToXML(out)
    return out


def _scaled_here(model_path: str, factors: dict[str, float]) -> dict:
    model = _scaled_model(model_path, factors)
    state = model.initSystem()
    model.realizePosition(state)
    muscles = model.getMuscles()
    out = {}
    for i in range(muscles.getSize()):
        m = muscles.get(i)
        out[m.getName()] = (m.getLength(state), m.getOptimalFiberLength(), m.getTendonSlackLength(),
                            m.getMaxIsometricForce())
    return out


def scaled_muscles(model_path: str | os.PathLike[str], factors: Mapping[str, float], *,
                   worker: bool | None = None) -> dict[str, tuple[float, float, float, float]]:
    """OpenSim 4's ``Model::scale`` of the model at ``model_path`` with ``factors`` (body -> one factor, the same
    along its three axes; bodies not named keep their size), masses kept: each muscle's (muscle-tendon length m at
    the default pose, optimal fibre length m, tendon slack length m, maximum isometric force N) after it."""
    return _run(f"{_HERE}:_scaled_here", worker, os.fspath(model_path), {str(k): float(v) for k, v in factors.items()})


def write_scaled(model_path: str | os.PathLike[str], factors: Mapping[str, float], out: str | os.PathLike[str], *,
                 worker: bool | None = None) -> str:
    """Write OpenSim 4's ``Model::scale`` of the model at ``model_path`` (``factors`` as :func:`scaled_muscles`',
    masses kept) to the model file ``out``: its markers, joints and a custom joint's translation functions scaled
    as OpenSim scales them; returns the path."""
    return _run(f"{_HERE}:_write_scaled_here", worker, os.fspath(model_path),
                {str(k): float(v) for k, v in factors.items()}, os.fspath(out))
