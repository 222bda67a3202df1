"""Element energies: each element returns kinetic, strain and gravity energy as CasADi
expressions of its nodal dofs; forces and tangents follow by automatic differentiation."""

from casflex.elements.beam import BeamElement
from casflex.elements.springs import LinearSpring, TorsionalSpring

__all__ = ["BeamElement", "LinearSpring", "TorsionalSpring"]
