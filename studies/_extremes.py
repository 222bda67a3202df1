"""One simulation at the extremes measured, for studies/extremes.py and studies/extremes_rotations.py: its
status, the energy drift, the local rotations computed independently of ``simulate``, and a replay of the step
``simulate`` rejected (docs/studies/extremes.md)."""

from __future__ import annotations

import math
import re
import warnings

import numpy as np

from casflex.simulate import Start, Stepping, integrator_for, simulate
from casflex.statics import StabilityWarning, modes

ALPHAS = (0.0, -1.0 / 3.0)
HORIZONS = (3.0, 30.0)
DRIFT_TOL = {3.0: 1e-3, 30.0: 1e-2}  # asserted: alpha = 0, converged, no wrap, dt <= 1e-3 (and full turns)
# each failure status, the words of simulate's message that name its cause, and the map cell's code
CAUSES = {"element_range": ("passed +-pi", "range"), "energy_growth": ("energy grew", "energy"),
          "newton_failed": ("iterations (max_iter", "Newton")}


def local_rotations(model, q: np.ndarray) -> dict[str, np.ndarray]:
    """Co-rotational local rotations at both ends of every beam element, as the element computes them (atan2)."""
    out, q0 = {}, model.q0
    for kind, name, ia, ib in model.segments:
        if kind == "beam":
            a, b = 3 * ia, 3 * ib
            beta0 = math.atan2(q0[b + 1] - q0[a + 1], q0[b] - q0[a])
            dx, dy = q[:, b] - q[:, a], q[:, b + 1] - q[:, a + 1]
            for end, k in (("a", a), ("b", b)):
                phi = q[:, k + 2] - q0[k + 2] + beta0
                out[f"{name}.{end}"] = np.arctan2(np.sin(phi) * dx - np.cos(phi) * dy,
                                                  np.cos(phi) * dx + np.sin(phi) * dy)
    return out


def finite(tr) -> bool:
    return all(np.isfinite(a).all() for a in (tr.t, tr.q, tr.qd, tr.qdd, tr.lam, tr.outputs, *tr.energies.values()))


def energy(tr, scale: float | None = None) -> dict:
    """Drift max|E - E(0)|, the end and the max gain, in units of ``scale`` (default the run's own max T + V_el;
    the grid passes its case's finest converged alpha = 0 run's, so that a blow-up shows as >> 1)."""
    E, moving = tr.energies["total"], tr.energies["kinetic"] + tr.energies["elastic"]
    own = float(moving.max()) if moving.size and moving.max() > 0 else 1.0
    s, dE = own if scale is None else scale, E - E[0]
    return {"scale_J": s, "own_scale_J": own, "drift": float(np.abs(dE).max() / s), "end": float(dE[-1] / s),
            "max_gain": float(dE.max() / s)}


def _rejected_step(model, tr, alpha: float, p, dt: float) -> dict:
    """The step simulate rejected, replayed (the interpreted step is the compiled one bitwise): did Newton
    converge, which local rotations jump through +-pi, how much energy does it hold above E(0)?"""
    integ, n = integrator_for(model, alpha=alpha), model.n_dof
    X = np.hstack([tr.q, tr.qd, tr.qdd, tr.lam])
    d = np.array(integ.scale(X[0, :n], X[0, n:2 * n], p, dt)).ravel()  # the run's Newton scaling
    x1, res, _ = integ.step_interpreted(X[-1], (X.shape[0] - 1) * dt, p, dt, d)
    out = {"finite": bool(np.isfinite(x1).all()), "wrap": [], "dE_J": math.nan, "moving_max_J": math.nan}
    out["converged"] = bool(out["finite"] and res <= float(integ.tolerance(x1[:n])))
    if out["finite"]:
        th = local_rotations(model, np.vstack([tr.q[-1], x1[:n]]))
        out["wrap"] = [(k, float(v[0]), float(v[1])) for k, v in th.items() if abs(v[1] - v[0]) > math.pi]
        T, Ve, Vg = (float(v) for v in model.energy(x1[:n], x1[n:2 * n], p))
        E = tr.energies
        out["dE_J"] = T + Ve + Vg - float(E["total"][0])
        out["moving_max_J"] = max(float((E["kinetic"] + E["elastic"]).max()), T + Ve)
    return out


def run_case(model, *, k_scale: float, e_scale: float, alpha: float, dt: float, t_end: float, omega_max: float,
             p: np.ndarray | None = None, qd0: np.ndarray | None = None, interpreted_check: bool = False,
             ref_scale: float | None = None) -> tuple[dict, object]:
    """One simulation with every measurement of the study: (row, trajectory)."""
    p = model.p_nominal * k_scale if p is None else p
    tr = simulate(model, t_end, stepping=Stepping(dt=dt, alpha=alpha, compiled=True), p=p, start=Start(qd0=qd0),
                  raise_on_failure=False)
    row = {"k_scale": k_scale, "e_scale": e_scale, "alpha": alpha, "dt": dt, "t_end": t_end, "omega_dt": omega_max * dt,
           "success": bool(tr.success), "status": tr.status, "message": tr.message, "steps": int(tr.stats["steps"]),
           "t_reached": float(tr.t[-1]), "finite": finite(tr), "energy": energy(tr, ref_scale)}
    rots = local_rotations(model, tr.q).values()  # the study's own wrap check: a jump of more than pi
    jumps = [np.flatnonzero(np.abs(np.diff(th)) > math.pi) for th in rots]
    first = min((int(j[0]) for j in jumps if j.size), default=None)
    row.update(wraps=sum(j.size for j in jumps), max_local_rot=max(float(np.abs(th).max()) for th in rots),
               t_first_wrap=None if first is None else float(tr.t[first + 1]))
    if tr.status in ("element_range", "energy_growth"):
        row["flagged"] = _rejected_step(model, tr, alpha, p, dt)
    big = np.flatnonzero(np.abs(tr.energies["total"] - tr.energies["total"][0]) > 0.01 * row["energy"]["scale_J"])
    row["t_drift_1pct"] = float(tr.t[big[0]]) if big.size else None
    if interpreted_check:  # the whole run on the interpreted path: the same steps, the same message
        ti = simulate(model, t_end, stepping=Stepping(dt=dt, alpha=alpha), p=p, start=Start(qd0=qd0),
                      raise_on_failure=False)
        row["interpreted_same"] = bool(ti.success == tr.success and ti.stats["steps"] == tr.stats["steps"]
                                       and ti.message == tr.message and finite(ti))
    return row, tr


def omega_max_of(model, p) -> float:
    """The highest circular frequency about the initial configuration (an axial mode: no preload needed)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StabilityWarning)
        return float(np.max(modes(model, p=p).omega))


def reason(message: str) -> str:
    """simulate's failure message cut to what failed, where and when (without its why and its advice)."""
    return re.split(r"\. |: the ", message)[0]
