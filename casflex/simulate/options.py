"""The forward simulation's choices as values (:func:`casflex.simulate.simulate`): one small frozen object per
question, each checking its own fields when it is made, with the messages the run gave before it had them.

- :class:`Stepping`: HHT's step and its Newton iterations (step ``dt``, ``alpha``, Newton variant, tolerance,
  iteration limit, compiled C);
- :class:`Start`: the initial state (``q0``, ``qd0``) and its time ``t0``.

What only the model decides (the initial state's length, its constraints; a horizon that is a whole number of
steps) is checked by the run (:func:`casflex.simulate.run.initial_state`, :func:`casflex.simulate.run.step_count`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from casflex.integrators.hht import check_newton
from casflex.integrators.hht_pieces import hht_coefficients

if TYPE_CHECKING:
    import numpy as np

    from casflex.scene import Scene

__all__ = ["Stepping", "Start"]


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _real(value: Any) -> bool:
    """A real number, numpy's included (a scene's run settings and sweeps give numpy floats)."""
    try:
        return not isinstance(value, (bool, str)) and math.isfinite(float(value))
    except (TypeError, ValueError):
        return False


@dataclass(frozen=True)
class Stepping:
    """How HHT steps: ``dt`` (s) and ``alpha`` (in [-1/3, 0]; None: the scene's run settings), the Newton
    iterations of a step (``newton`` "exact": a Jacobian per step, "modified": the factorised Jacobian kept while
    it converges the steps; ``tol`` the scaled residual's tolerance, see :class:`~casflex.integrators.HHT`;
    ``max_iter`` per step) and ``compiled`` (run generated C, :mod:`casflex.codegen`)."""

    dt: float | None = None
    alpha: float | None = None
    newton: str = "exact"
    tol: float = 1e-12
    max_iter: int = 25
    compiled: bool = False

    def __post_init__(self) -> None:
        if self.dt is not None and not (_real(self.dt) and float(self.dt) > 0):
            raise ValueError(f"dt: must be a positive number of seconds, got {self.dt!r}")
        if self.alpha is not None:
            if not _real(self.alpha):
                raise ValueError(f"alpha: must lie in [-1/3, 0], got {self.alpha!r}")
            hht_coefficients(float(self.alpha))
        # the run takes float(tol) and int(max_iter) (as simulate always has); what they cannot convert is refused
        check_newton(float(self.tol) if _real(self.tol) else self.tol,
                     int(self.max_iter) if _real(self.max_iter) else self.max_iter, self.newton)
        if self.compiled not in (True, False):
            raise ValueError(f"compiled: expected True or False, got {self.compiled!r}")

    def of(self, scene: Scene) -> tuple[float, float]:
        """(dt, alpha): these, or the scene's run settings where None."""
        run = scene.run
        return float(run.dt if self.dt is None else self.dt), float(run.alpha if self.alpha is None else self.alpha)


@dataclass(frozen=True, eq=False)
class Start:
    """The initial state: positions ``q0`` and velocities ``qd0`` (n_dof,) (None: the scene's; qd0 must satisfy
    the velocity constraints, the run checks their length and constraints) at time ``t0`` (s; the run covers
    t0 .. t0 + t_end, loads are taken at absolute time)."""

    q0: np.ndarray | None = None
    qd0: np.ndarray | None = None
    t0: float = 0.0

    def __post_init__(self) -> None:
        if not _real(self.t0):
            raise ValueError(f"t0: expected a finite time in s, got {self.t0!r}")
