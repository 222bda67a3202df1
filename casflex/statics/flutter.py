"""The critical value of a load parameter: where the equilibrium loses stability by divergence or flutter.

Continuation in one declared parameter (e.g. a follower load's magnitude): from a value where the
equilibrium is stable, the equilibrium is followed by Newton (``seek = "nearest"``, each solve
starting from the last) and its modes (:func:`~casflex.statics.modes.modes`) are checked for a
negative omega^2 (divergence, as an Euler column buckles) or a complex pair (flutter, as Beck's
column under a follower load). The first unstable value is bracketed on a grid and refined by
bisection. At flutter the two frequencies that merge are reported at the last stable value.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from casflex.model import Model
from casflex.statics.equilibrium import equilibrium
from casflex.statics.modes import ModesResult, modes
from casflex.statics.problem import StaticsError

__all__ = ["CriticalLoad", "critical_load"]


@dataclass(frozen=True)
class CriticalLoad:
    """Where stability is lost.

    Attributes
    ----------
    parameter : str
    value : float
        The critical value (the parameter's unit), to ``tol`` relative to its change from ``start``.
    kind : {"flutter", "divergence"}
    omega : float
        Flutter: the circular frequency (rad/s) at which the two merging modes meet (the mean of the
        two at the last stable value); divergence: 0.
    q : ndarray, shape (n_dof,)
        The equilibrium at the last stable value (m, rad).
    modes : ModesResult
        Its modes.
    """

    parameter: str
    value: float
    kind: str
    omega: float
    q: np.ndarray
    modes: ModesResult


def _state(model: Model, name: str, value: float, q: np.ndarray, tol: float) -> tuple[np.ndarray, ModesResult]:
    p = dict(zip(model.parameter_names, model.p_nominal.tolist(), strict=True))
    p[name] = value
    eq = equilibrium(model, p=p, q_start=q, seek="nearest", tol=tol)
    return eq.q, modes(model, q=eq.q, p=p)


def _unstable(m: ModesResult) -> str | None:
    if m.flutter:
        return "flutter"
    return "divergence" if np.any(m.omega2.real < 0) else None


def critical_load(model: Model, parameter: str, stop: float, *, start: float | None = None, points: int = 20,
                  tol: float = 1e-6, statics_tol: float = 1e-10) -> CriticalLoad:
    """The first value of ``parameter`` between ``start`` (default its nominal value, where the
    equilibrium must be stable) and ``stop`` at which the equilibrium loses stability.

    ``points`` equal steps bracket it, bisection refines it to ``tol`` times |stop - start|.
    Raises ValueError for an unknown parameter or an unstable start, StaticsError when no loss of
    stability lies within the range or an equilibrium cannot be followed.
    """
    if parameter not in model.parameter_names:
        raise ValueError(f"parameter: {parameter!r} is not declared; declared: {list(model.parameter_names)}")
    if not (isinstance(points, int) and points >= 1):
        raise ValueError(f"points: expected an integer >= 1, got {points!r}")
    a = a0 = float(model.p_nominal[model.parameter_names.index(parameter)] if start is None else start)
    q_a, m_a = _state(model, parameter, a, model.q0, statics_tol)
    if _unstable(m_a):
        raise ValueError(f"start: the equilibrium at {parameter} = {a:g} is already unstable ({_unstable(m_a)})")
    kind = None
    for b in np.linspace(a, float(stop), points + 1)[1:]:
        q_b, m_b = _state(model, parameter, b, q_a, statics_tol)
        kind = _unstable(m_b)
        if kind:
            break
        a, q_a, m_a = b, q_b, m_b
    if kind is None:
        raise StaticsError(f"no loss of stability for {parameter} from {a0:g} to {stop:g}; widen the range")
    width = tol * abs(float(stop) - a0)
    while abs(b - a) > width:
        c = 0.5 * (a + b)
        q_c, m_c = _state(model, parameter, c, q_a, statics_tol)
        if _unstable(m_c):
            b, kind = c, _unstable(m_c)
        else:
            a, q_a, m_a = c, q_c, m_c
    omega = 0.0
    if kind == "flutter":
        w = np.sort(m_a.omega2.real)
        i = int(np.argmin(np.diff(w)))  # the closest pair: the two that merge
        omega = float(np.sqrt(max(0.5 * (w[i] + w[i + 1]), 0.0)))
    return CriticalLoad(parameter, 0.5 * (a + b), kind, omega, q_a, m_a)
