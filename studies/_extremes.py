"""One simulation at the extremes measured, for studies/extremes.py and studies/extremes_rotations.py: its
status and parsed failure message, the energy drift, the local rotations computed independently of ``simulate``,
Newton iterations of sampled steps, replays of the failing or rejected step (docs/studies/extremes.md)."""

from __future__ import annotations

import math
import re
import warnings

import numpy as np

from casflex.simulate import integrator_for, simulate
from casflex.statics import StabilityWarning, modes

ALPHAS = (0.0, -1.0 / 3.0)
HORIZONS = (3.0, 30.0)
DRIFT_TOL = {3.0: 1e-3, 30.0: 1e-2}  # asserted: alpha = 0, converged, no wrap, dt <= 1e-3 (and full turns)
STATUSES = ("element_range", "energy_growth", "newton_failed")
# simulate's three failure messages, parsed: the check that each gives its time and its details
_MESSAGES = {
    "newton_failed": r"from t = (?P<t>\S+) s to (?P<t1>\S+) s \(step \d+\): (?P<iterations>\d+) iterations \(max_iter "
                     r"\d+\) (?:left the scaled residual at (?P<residual>\S+) \(tol (?P<tol>\S+)\)|produced NaN/inf)",
    "element_range": r"beam element (?P<element>\S+): its co-rotational local rotation at end (?P<end>[ab]) passed "
                     r"\+-pi between t = (?P<t>\S+) s and (?P<t1>\S+) s \((?P<theta0>\S+) -> (?P<theta1>\S+) rad\)",
    "energy_growth": r"the total energy grew by (?P<grew_J>\S+) J more than the loads supplied, by t = (?P<t1>\S+) s "
                     r"\((?P<percent>\S+) % of the energy in motion, (?P<in_motion_J>\S+) J\)"}


def parse_failure(msg: str, dt: float) -> dict | None:
    """Kind, time (``t``: where the failing step starts, the last returned state) and details of a message."""
    for kind, rx in _MESSAGES.items():
        if (m := re.search(rx, msg)) is not None:
            f = {k: v if k in ("element", "end") else int(v) if k == "iterations" else float(v or "nan")
                 for k, v in m.groupdict().items()}
            return {"kind": kind, "t": f["t1"] - dt, **f} if kind == "energy_growth" else {"kind": kind, **f}
    return None


def detail(f: dict) -> str:
    """What a failure message says beyond the time."""
    return {"newton_failed": lambda: f"{f['iterations']} it., residual {f['residual']:.2g} (tol {f['tol']:.2g})",
            "element_range": lambda: f"{f['element']} end {f['end']}: {f['theta0']:+.3f} -> {f['theta1']:+.3f} rad",
            "energy_growth": lambda: f"+{f['grew_J']:.3g} J, {f['percent']:.0f} % of {f['in_motion_J']:.3g} J in "
                                     "motion"}[f["kind"]]()


def local_rotations(model, q: np.ndarray) -> dict[str, np.ndarray]:
    """Co-rotational local rotations at both ends of every beam element, computed as the element does
    (atan2, in (-pi, pi])."""
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


def _newton_sample(integ, X, d, p, dt: float, n_samples: int) -> dict:
    """Newton iterations of evenly spaced steps and of the last 20, re-run from the run's states ``X`` with the
    interpreted step; the largest relative difference from the compiled states."""
    done = X.shape[0] - 1
    last = set(range(max(done - 20, 0), done))
    idx = sorted(last | (set(np.linspace(0, done - 1, min(done, n_samples)).astype(int).tolist()) if done else set()))
    its, mismatch = {}, 0.0
    for k in idx:
        x1, _r, its[k] = integ.step_interpreted(X[k], k * dt, p, dt, d)
        mismatch = max(mismatch, float(np.max(np.abs(x1 - X[k + 1]) / np.maximum(np.abs(X[k + 1]), 1.0))))
    a, b = list(its.values()), [its[k] for k in last]
    return {"sampled": len(a), "mean": float(np.mean(a)) if a else math.nan, "max": int(max(a, default=0)),
            "max_last20": int(max(b, default=0)), "mean_last20": float(np.mean(b)) if b else math.nan,
            "replay_mismatch": mismatch}


_GJ: dict = {}  # residual and Jacobian Function of each integrator's Newton problem


def _failing_step(integ, X, d, p, dt: float, tol: float) -> dict:
    """A Newton failure's step replayed with a plain Newton iteration (fast_newton's update, no line search):
    its kind, min residual and condition number at the predictor; and as two half steps from the same state."""
    import casadi as ca

    k, n = X.shape[0] - 1, integ.model.n_dof
    if integ not in _GJ:
        z, prm = ca.SX.sym("z", integ.residual.nnz_in(0)), ca.SX.sym("prm", integ.residual.nnz_in(1))
        g = integ.residual(z, prm)
        _GJ[integ] = ca.Function("gj", [z, prm], [g, ca.jacobian(g, z)])
    z, prm = integ.prepare(X[k], k * dt, p, dt, d)
    z, trace, cond0 = np.array(z).ravel(), [], math.nan
    for i in range(integ.max_iter + 1):
        g, J = (np.array(v) for v in _GJ[integ](z, prm))
        ok = np.isfinite(g).all() and np.isfinite(J).all()
        trace.append(float(np.abs(g).max()) if np.isfinite(g).all() else math.nan)
        cond0 = (float(np.linalg.cond(J)) if np.isfinite(J).all() else math.nan) if i == 0 else cond0
        if not ok or i == integ.max_iter:
            break
        try:
            z = z - np.linalg.solve(J, g.ravel())
        except np.linalg.LinAlgError:
            break
    x, half_ok, dh = X[k], True, np.array(integ.scale(X[0, :n], X[0, n:2 * n], p, dt / 2)).ravel()
    for j in range(2):
        x, r, _ = integ.step_interpreted(x, k * dt + j * dt / 2, p, dt / 2, dh)
        if not (np.isfinite(x).all() and float(r) <= float(integ.tolerance(x[:n]))):
            half_ok = False
            break
    tr, tol = np.array(trace), tol if math.isfinite(tol) else integ.tol
    fin = tr[np.isfinite(tr)]
    kind = ("NaN/inf in the residual" if not np.isfinite(tr).all() else "stalls at the round-off floor"
            if fin.min() <= 100 * tol else "oscillates, no convergence" if fin[1:].min(initial=np.inf) < fin[0]
            else "diverges from the predictor")
    return {"cond_predictor": cond0, "min_residual": float(fin.min()) if fin.size else math.nan, "kind": kind,
            "half_steps_converge": half_ok}


def _cross_check(integ, tr, X, d, p, dt: float) -> dict:
    """The step simulate rejected, replayed (the interpreted step is the compiled one bitwise): did Newton
    converge, which local rotations jump through +-pi, how much energy does it hold above E(0)?"""
    n = integ.model.n_dof
    x1, res, _ = integ.step_interpreted(X[-1], (X.shape[0] - 1) * dt, p, dt, d)
    out = {"finite": bool(np.isfinite(x1).all()), "wrap": [], "dE_J": math.nan, "moving_max_J": math.nan}
    out["converged"] = bool(out["finite"] and res <= float(integ.tolerance(x1[:n])))
    if out["finite"]:
        th = local_rotations(integ.model, np.vstack([tr.q[-1], x1[:n]]))
        out["wrap"] = [(k, float(v[0]), float(v[1])) for k, v in th.items() if abs(v[1] - v[0]) > math.pi]
        T, Ve, Vg = (float(v) for v in integ.model.energy(x1[:n], x1[n:2 * n], p))
        E = tr.energies
        out["dE_J"] = T + Ve + Vg - float(E["total"][0])
        out["moving_max_J"] = max(float((E["kinetic"] + E["elastic"]).max()), T + Ve)
    return out


def run_case(model, *, k_scale: float, e_scale: float, alpha: float, dt: float, t_end: float, omega_max: float,
             p: np.ndarray | None = None, qd0: np.ndarray | None = None, n_samples: int = 300,
             interpreted_check: bool = False, ref_scale: float | None = None) -> tuple[dict, object]:
    """One simulation with every measurement of the study: (row, trajectory)."""
    p = model.p_nominal * k_scale if p is None else p
    tr = simulate(model, t_end, dt=dt, alpha=alpha, p=p, qd0=qd0, compiled=True, raise_on_failure=False)
    row = {"k_scale": k_scale, "e_scale": e_scale, "alpha": alpha, "dt": dt, "t_end": t_end, "omega_dt": omega_max * dt,
           "success": bool(tr.success), "status": tr.status, "message": tr.message, "steps": int(tr.stats["steps"]),
           "t_reached": float(tr.t[-1]), "finite": finite(tr), "energy": energy(tr, ref_scale),
           "failure": None if tr.success else parse_failure(tr.message, dt)}
    rots = local_rotations(model, tr.q).values()  # the study's own wrap check: a jump of more than pi
    jumps = [np.flatnonzero(np.abs(np.diff(th)) > math.pi) for th in rots]
    first = min((int(j[0]) for j in jumps if j.size), default=None)
    row.update(wraps=sum(j.size for j in jumps), max_local_rot=max(float(np.abs(th).max()) for th in rots),
               t_first_wrap=None if first is None else float(tr.t[first + 1]))
    integ, n = integrator_for(model, alpha=alpha), model.n_dof
    X = np.hstack([tr.q, tr.qd, tr.qdd, tr.lam])  # the run's states and Newton scaling, to replay its steps
    d = np.array(integ.scale(X[0, :n], X[0, n:2 * n], p, dt)).ravel()
    row["newton"] = _newton_sample(integ, X, d, p, dt, n_samples)
    if tr.status == "newton_failed":
        row["failing_step"] = _failing_step(integ, X, d, p, dt, row["failure"]["tol"] if row["failure"] else math.nan)
    if tr.status in ("element_range", "energy_growth"):
        row["flagged"] = _cross_check(integ, tr, X, d, p, dt)
    lengths = [tr.output(f"{s.name}.length") for s in model.scene.springs]
    row["spring_rel"] = [float(min(L.min() / L[0] for L in lengths)), float(max(L.max() / L[0] for L in lengths))]
    big = np.flatnonzero(np.abs(tr.energies["total"] - tr.energies["total"][0]) > 0.01 * row["energy"]["scale_J"])
    row["t_drift_1pct"] = float(tr.t[big[0]]) if big.size else None
    if interpreted_check:  # the whole run on the interpreted path: the same steps, the same message
        ti = simulate(model, t_end, dt=dt, alpha=alpha, p=p, qd0=qd0, raise_on_failure=False)
        row["interpreted_same"] = bool(ti.success == tr.success and ti.stats["steps"] == tr.stats["steps"]
                                       and ti.message == tr.message and finite(ti))
    return row, tr


def omega_max_of(model, p) -> float:
    """The highest circular frequency about the initial configuration (not an equilibrium, so modes warn; the
    stiff axial modes that set omega_max do not feel the missing preload)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StabilityWarning)
        return float(np.max(modes(model, p=p).omega))
