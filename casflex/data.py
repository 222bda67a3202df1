"""Measurement sets: the paper's "simulated set" and "measured set", with optional noise.

- simulated set: every nodal dof with velocities and accelerations, from an HHT simulation
  (run at a tight Newton tolerance so that the data satisfy Eq. 1 to round-off at alpha = 0);
- measured set: positions only (optionally with Gaussian noise, sigma in m for x, y and rad
  for theta); velocities and accelerations by central differences (2nd order), so the first
  and last samples are dropped.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from casflex.model import Model

__all__ = ["MeasurementSet", "simulated_set", "measured_set"]


@dataclass(frozen=True, eq=False)
class MeasurementSet:
    """Kinematic data: t (n,) s; q, qd, qdd (n, k) for the dofs named in ``channels``.

    ``qd`` and ``qdd`` may be None when only positions are known.
    """

    t: np.ndarray
    channels: tuple[str, ...]
    q: np.ndarray
    qd: np.ndarray | None
    qdd: np.ndarray | None
    source: str = "user"
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        t = np.asarray(self.t, dtype=float)
        if t.ndim != 1 or t.size < 1 or not np.isfinite(t).all():
            raise ValueError("data.t: expected a 1-d array of finite times (s)")
        if t.size > 1 and np.any(np.diff(t) <= 0):
            i = int(np.argmax(np.diff(t) <= 0)) + 1
            raise ValueError(f"data.t: times must increase strictly; t[{i}] = {t[i]:g} follows {t[i - 1]:g}")
        for name in ("q", "qd", "qdd"):
            a = getattr(self, name)
            if a is None:
                continue
            a = np.asarray(a, dtype=float)
            if a.shape != (t.size, len(self.channels)):
                raise ValueError(f"data.{name}: expected shape ({t.size}, {len(self.channels)}), got {a.shape}")
            if not np.isfinite(a).all():
                r, c = np.argwhere(~np.isfinite(a))[0]
                raise ValueError(f"data.{name}: non-finite value for channel {self.channels[c]} at t = {t[r]:g} s")
        if self.q is None:
            raise ValueError("data.q: positions are required")

    def index(self, t: float) -> int:
        """Index of the sample at time ``t`` (s); error if none lies within half a sample."""
        i = int(np.argmin(np.abs(self.t - t)))
        tol = 0.5 * (np.min(np.diff(self.t)) if self.t.size > 1 else 1e-9)
        if abs(self.t[i] - t) > tol:
            raise ValueError(f"instant t = {t:g} s: no sample there (data cover {self.t[0]:g} .. {self.t[-1]:g} s)")
        return i

    def select(self, model: Model) -> np.ndarray:
        """Column of each model dof in the data (-1 where the dof is not measured)."""
        unknown = [c for c in self.channels if c not in model.dof_names]
        if unknown:
            raise ValueError(f"data: unknown channels {unknown}; the model's dofs are {list(model.dof_names)}")
        return np.array([self.channels.index(d) if d in self.channels else -1 for d in model.dof_names])


def simulated_set(model: Model, t_end: float = 3.0, *, dt: float = 1e-3, alpha: float = 0.0,
                  p: dict[str, float] | np.ndarray | None = None, tol: float = 1e-14) -> MeasurementSet:
    """All nodal kinematics of an HHT simulation (the paper's simulated set)."""
    from casflex.simulate import simulate

    tr = simulate(model, t_end, dt=dt, alpha=alpha, p=p, tol=tol)
    return MeasurementSet(tr.t, tr.dof_names, tr.q, tr.qd, tr.qdd, source="simulated",
                          meta={"lam": tr.lam, "p": tr.p, "alpha": alpha, "dt": dt})


def measured_set(data: MeasurementSet, *, noise: float = 0.0, seed: int | None = None) -> MeasurementSet:
    """Positions of ``data`` (plus Gaussian noise of std ``noise``), derivatives by central
    differences: qd_i = (q_{i+1} - q_{i-1}) / 2h, qdd_i = (q_{i+1} - 2 q_i + q_{i-1}) / h^2."""
    if noise < 0 or not np.isfinite(noise):
        raise ValueError(f"noise: expected a standard deviation >= 0 (m, rad), got {noise!r}")
    h = np.diff(data.t)
    if data.t.size < 3 or np.ptp(h) > 1e-9 * h.mean():
        raise ValueError("measured set: central differences need at least 3 equally spaced samples")
    h = float(h.mean())
    q = data.q + (np.random.default_rng(seed).normal(0.0, noise, data.q.shape) if noise > 0 else 0.0)
    qd = (q[2:] - q[:-2]) / (2 * h)
    qdd = (q[2:] - 2 * q[1:-1] + q[:-2]) / h**2
    return MeasurementSet(data.t[1:-1], data.channels, q[1:-1], qd, qdd, source="measured",
                          meta={"noise": noise, "seed": seed, "from": data.source})
