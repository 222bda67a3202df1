"""Identification of scene parameters from measured motion (Eqs. 11-17 of the seed paper)."""

from casflex.identification.adapted import identify_adapted_direct
from casflex.identification.direct import identify_direct
from casflex.identification.indirect import RESIDUES, TRANSCRIPTIONS, identify_indirect
from casflex.identification.problem import HESSIANS, TRANSFORMS, IdentificationResult, ParameterMap

__all__ = ["identify_direct", "identify_adapted_direct", "identify_indirect", "IdentificationResult", "ParameterMap",
           "RESIDUES", "TRANSCRIPTIONS", "TRANSFORMS", "HESSIANS"]
