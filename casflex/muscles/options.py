"""The muscle analyses' choices as values (docs/architecture.md, "Choices are values"): which muscle properties
are uncertain. Static optimization's own are :class:`casflex.muscles.static_optimization.StaticOptimization`, the
joint reactions' :class:`casflex.muscles.reaction.JointReaction`. Each checks its fields when made; a value refused
is a ValueError ``"<field>: <reason>"`` that the command line and the study file say with their own names.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["MuscleUncertainty", "UNCERTAIN_PROPERTIES"]

#: The muscle properties whose uncertainty casflex propagates (:class:`MuscleUncertainty`).
UNCERTAIN_PROPERTIES = ("max_isometric_force", "optimal_fiber_length", "tendon_slack_length")


@dataclass(frozen=True)
class MuscleUncertainty:
    """Each muscle's properties known within a relative uncertainty (one standard deviation, a fraction: 0.1 is
    10 %), independent between muscles and properties; 0 (the default) holds a property exact. The bands of the
    muscle forces and joint reactions are propagated from them to first order (:mod:`casflex.muscles.bands`)."""

    max_isometric_force: float = 0.0
    optimal_fiber_length: float = 0.0
    tendon_slack_length: float = 0.0

    def __post_init__(self) -> None:
        for name in UNCERTAIN_PROPERTIES:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and 0.0 <= v < 0.5):
                raise ValueError(f"{name}: expected a relative standard deviation in [0, 0.5) (0.1: 10 %), got {v!r}")

    @property
    def declared(self) -> tuple[tuple[str, float], ...]:
        """(property, relative SD) of each uncertain property."""
        return tuple((n, float(getattr(self, n))) for n in UNCERTAIN_PROPERTIES if getattr(self, n) > 0)
