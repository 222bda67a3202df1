"""Identification of scene parameters from measured motion (Eqs. 11-17 of the seed paper).

The public names are imported on first use (PEP 562), as casflex's own: the command line's parser
takes the option values from :mod:`casflex.identification.choices` without loading the methods. The
choices of each stage are small frozen values (:mod:`.options`): ``Shooting``, ``ModelRun``, ``Solver``,
``Uncertainty``, ``Smoothing``, ``Budget``; a recording with what is known of it is an ``Experiment``."""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "identify_adapted_direct": "adapted", "identify_direct": "direct", "identify_indirect": "indirect",
    "Experiment": "measurement", "Budget": "options", "ParameterMap": "problem",
    "Shooting": "options", "ModelRun": "options", "Solver": "options", "Uncertainty": "options",
    "Smoothing": "options",
    "IdentificationResult": "result",
    "INITIAL_STATES": "choices", "MODEL_ERRORS": "choices", "RESIDUES": "choices", "TRANSCRIPTIONS": "choices",
    "HESSIANS": "choices", "TRANSFORMS": "choices", "FORMS": "choices", "output_band": "bands",
}

__all__ = ["identify_direct", "identify_adapted_direct", "identify_indirect", "IdentificationResult", "ParameterMap",
           "Experiment", "Budget", "Shooting", "ModelRun", "Solver", "Uncertainty", "Smoothing",
           "method_function", "RESIDUES", "TRANSCRIPTIONS", "TRANSFORMS", "HESSIANS", "INITIAL_STATES",
           "MODEL_ERRORS", "FORMS", "output_band"]


def method_function(method: str) -> Any:
    """The identification function of ``method`` ("direct", "adapted-direct", "indirect": choices.METHODS)."""
    from casflex.identification.choices import METHODS

    if method not in METHODS:
        raise ValueError(f"method: expected one of {METHODS}, got {method!r}")
    name = "identify_" + method.replace("-", "_")
    return globals()[name] if name in globals() else __getattr__(name)  # as the package's attribute is now


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        value = getattr(importlib.import_module(f"casflex.identification.{_EXPORTS[name]}"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'casflex.identification' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
