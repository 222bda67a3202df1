"""Identification of scene parameters from measured motion (Eqs. 11-17 of the seed paper)."""

from casflex.identification.adapted import identify_adapted_direct
from casflex.identification.direct import identify_direct
from casflex.identification.indirect import INITIAL_STATES, MODEL_ERRORS, RESIDUES, TRANSCRIPTIONS, identify_indirect
from casflex.identification.measurement import Experiment
from casflex.identification.output_error import Budget
from casflex.identification.problem import HESSIANS, TRANSFORMS, ParameterMap
from casflex.identification.result import IdentificationResult

__all__ = ["identify_direct", "identify_adapted_direct", "identify_indirect", "IdentificationResult", "ParameterMap",
           "Experiment", "Budget", "RESIDUES", "TRANSCRIPTIONS", "TRANSFORMS", "HESSIANS", "INITIAL_STATES",
           "MODEL_ERRORS"]
