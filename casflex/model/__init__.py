"""The symbolic model of a scene: ``assemble(scene) -> Model``.

- :mod:`casflex.model.model`: :class:`Model` (CasADi symbols q, qd, qdd, lam, p and named Functions built
  from the element kernels mapped over the scene) and :func:`assemble`;
- :mod:`casflex.model.assembly`: the scene's index maps, gathering and scattering the kernels' blocks;
- :mod:`casflex.model.constraints`: the constraints Phi(q) of supports and joints, their Jacobian;
- :mod:`casflex.model.consistent`: states that satisfy the constraints (positions, velocities);
- :mod:`casflex.model.markers`: where the scene's markers are as the model moves.
"""

from casflex.model.forms import form_inputs
from casflex.model.model import INERTIA_FORMS, Model, assemble, assembled

__all__ = ["Model", "assemble", "assembled", "form_inputs", "INERTIA_FORMS"]
