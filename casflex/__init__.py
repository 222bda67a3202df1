"""casflex: planar flexible multibody dynamics and parameter identification on CasADi.

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
}

__all__ = [*sorted(_EXPORTS), "__version__"]


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        value = getattr(importlib.import_module(_EXPORTS[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'casflex' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
