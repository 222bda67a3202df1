"""casflex: planar flexible multibody dynamics and parameter identification on CasADi.

The verbs a user types first: ``casflex.simulate(model, t_end)`` (a :class:`~casflex.results.Trajectory`),
``casflex.identify(model, data)`` (:func:`casflex.identification.identify_indirect`),
``casflex.inverse_dynamics(scene, trial)`` (:func:`casflex.inverse.inverse_dynamics`, ``trial`` a
:class:`casflex.inverse.Trial`) and
``casflex.study("study.toml", "records")`` (a lab's whole study, :func:`casflex.study.run`; its file alone:
``casflex.load_study``). ``casflex.simulate`` and ``casflex.study`` are the packages of those names, callable.

The public names are imported on first use (PEP 562), so that ``import casflex`` and the command
line's start stay light: a Ctrl-C while CasADi and numpy load is then still caught by the command.
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

_EXPORTS = {
    "Model": "casflex.model", "assemble": "casflex.model",
    "Beam": "casflex.scene", "Joint": "casflex.scene", "Load": "casflex.scene", "Node": "casflex.scene",
    "Parameter": "casflex.scene",
    "RigidBody": "casflex.scene", "RunSettings": "casflex.scene", "Scene": "casflex.scene",
    "SceneError": "casflex.scene",
    "Spring": "casflex.scene", "Support": "casflex.scene", "TorsionSpring": "casflex.scene",
    "Marker": "casflex.scene", "Uncertain": "casflex.scene",
    "builtin_scenes": "casflex.scene", "dumps_scene": "casflex.scene", "load_scene": "casflex.scene",
    "loads_scene": "casflex.scene", "save_scene": "casflex.scene",
    "Stepping": "casflex.simulate.options", "Start": "casflex.simulate.options",
    "inverse_dynamics": "casflex.inverse", "load_study": "casflex.study.study_file",
}
#: Verbs under another name in their module: name -> (module, attribute).
_ALIASES = {"identify": ("casflex.identification", "identify_indirect")}
#: Verbs that are packages of the same name, callable (``casflex.simulate(...)``): importing one binds it here.
_PACKAGES = ("simulate", "study")

__all__ = [*sorted([*_EXPORTS, *_ALIASES, *_PACKAGES]), "__version__"]


def __getattr__(name: str) -> Any:
    if name in _PACKAGES:  # the import binds the package here as casflex.<name>, as any subpackage's
        return importlib.import_module(f"casflex.{name}")
    if name in _EXPORTS or name in _ALIASES:
        module, attribute = _ALIASES.get(name, (_EXPORTS.get(name), name))
        value = getattr(importlib.import_module(module), attribute)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'casflex' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS) | set(_ALIASES) | set(_PACKAGES))
