"""Time integrators for the index-3 DAE of a model."""

from casflex.integrators.hht import HHT, hht_coefficients

__all__ = ["HHT", "hht_coefficients"]
