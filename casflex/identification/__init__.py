"""Identification of model parameters from measured motion (Eqs. 11-17)."""

from casflex.identification.direct import identify_direct
from casflex.identification.problem import IdentificationResult

__all__ = ["IdentificationResult", "identify_direct"]
