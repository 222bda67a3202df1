"""The measurements of one simulation at the extremes, shared by studies/extremes.py (the stability map) and
studies/extremes_rotations.py (full turns, a finer mesh): the run's status and its parsed failure message,
the energy drift, the co-rotational local rotations computed independently of ``simulate``, Newton
iterations of sampled steps, and replays of the step that failed or that ``simulate`` rejected.
"""

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


def local_rotations(model, q: np.ndarray) -> dict[str, np.ndarray]:
    """Co-rotational local rotations at both ends of every beam element, computed here as the element
    does (atan2, wrapped to (-pi, pi]): the study's own view, independent of simulate's check."""
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


def wraps(model, q: np.ndarray) -> tuple[int, float, int | None]:
    """(local-rotation jumps through +-pi, max |local rotation|, index of the first jump)."""
    rots = local_rotations(model, q).values()
    jumps = [np.flatnonzero(np.abs(np.diff(th)) > math.pi) for th in rots]
    firsts = [int(j[0]) for j in jumps if j.size]
    mx = max(float(np.abs(th).max()) for th in rots)
    return sum(j.size for j in jumps), mx, min(firsts) if firsts else None


def finite(tr) -> bool:
    return all(np.isfinite(a).all() for a in (tr.t, tr.q, tr.qd, tr.qdd, tr.lam, tr.outputs, *tr.energies.values()))


def energy(tr, scale: float | None = None) -> dict:
    """Drift max|E - E(0)| and the end / max gain / max loss, in units of ``scale`` (default the run's own
    max (T + V_el)); the grid passes its case's finest converged alpha = 0 run's, so a blow-up shows as >> 1."""
    E, moving = tr.energies["total"], tr.energies["kinetic"] + tr.energies["elastic"]
    own = float(moving.max()) if moving.size and moving.max() > 0 else 1.0
    s = own if scale is None else scale
    dE = E - E[0]
    return {"scale_J": s, "own_scale_J": own, "drift": float(np.abs(dE).max() / s), "end": float(dE[-1] / s),
            "max_gain": float(dE.max() / s), "max_loss": float(-dE.min() / s)}


def _states(integ, tr, p, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """The run's stacked states and its Newton scaling d, for replaying its steps."""
    n = integ.model.n_dof
    X = np.hstack([tr.q, tr.qd, tr.qdd, tr.lam])
    return X, np.array(integ.scale(X[0, :n], X[0, n:2 * n], p, dt)).ravel()


def _newton_sample(integ, tr, p, dt: float, n_samples: int) -> dict:
    """Newton iterations of evenly spaced steps and of the last 20, re-run from the run's own states with
    the interpreted step; the largest relative difference from the compiled states."""
    X, d = _states(integ, tr, p, dt)
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


def _failing_step(integ, tr, p, dt: float, tol: float) -> dict:
    """A Newton failure's step replayed with a plain Newton iteration (CasADi's fast_newton update, no line
    search): the residual after each iteration, the condition number at the predictor, and whether two
    half steps from the same state converge. ``tol``: the message's tolerance."""
    import casadi as ca

    X, d = _states(integ, tr, p, dt)
    k, n = X.shape[0] - 1, integ.model.n_dof
    if integ not in _GJ:
        z, prm = ca.SX.sym("z", integ.residual.nnz_in(0)), ca.SX.sym("prm", integ.residual.nnz_in(1))
        g = integ.residual(z, prm)
        _GJ[integ] = ca.Function("gj", [z, prm], [g, ca.jacobian(g, z)])
    z0, prm = integ.prepare(X[k], k * dt, p, dt, d)
    z, trace, cond0 = np.array(z0).ravel(), [], math.nan
    for i in range(integ.max_iter + 1):
        g, J = (np.array(v) for v in _GJ[integ](z, prm))
        g = g.ravel()
        trace.append(float(np.abs(g).max()) if np.isfinite(g).all() else math.nan)
        cond0 = (float(np.linalg.cond(J)) if np.isfinite(J).all() else math.nan) if i == 0 else cond0
        if not (np.isfinite(g).all() and np.isfinite(J).all()) or i == integ.max_iter:
            break
        try:
            z = z - np.linalg.solve(J, g)
        except np.linalg.LinAlgError:
            break
    x, half_ok = X[k], True
    dh = np.array(integ.scale(X[0, :n], X[0, n:2 * n], p, dt / 2)).ravel()
    for j in range(2):
        x, r, _ = integ.step_interpreted(x, k * dt + j * dt / 2, p, dt / 2, dh)
        if not (np.isfinite(x).all() and float(r) <= float(integ.tolerance(x[:n]))):
            half_ok = False
            break
    tr_, tol = np.array(trace), tol if math.isfinite(tol) else integ.tol
    fin = tr_[np.isfinite(tr_)]
    kind = ("NaN/inf in the residual" if not np.isfinite(tr_).all() else "stalls at the round-off floor"
            if fin.min() <= 100 * tol else "oscillates, no convergence" if fin[1:].min(initial=np.inf) < fin[0]
            else "diverges from the predictor")
    return {"cond_predictor": cond0, "min_residual": float(fin.min()) if fin.size else math.nan, "kind": kind,
            "half_steps_converge": half_ok}


def _cross_check(integ, tr, p, dt: float) -> dict:
    """The step simulate rejected, replayed (the interpreted step is the compiled one bitwise): did Newton
    converge, which local rotations jump through +-pi, how much energy does it hold above E(0)?"""
    X, d = _states(integ, tr, p, dt)
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
    row = {"k_scale": k_scale, "e_scale": e_scale, "alpha": alpha, "dt": dt, "t_end": t_end, "omega_dt": omega_max * dt}
    tr = simulate(model, t_end, dt=dt, alpha=alpha, p=p, qd0=qd0, compiled=True, raise_on_failure=False)
    row.update({"success": bool(tr.success), "status": tr.status, "message": tr.message,
                "steps": int(tr.stats["steps"]),
                "t_reached": float(tr.t[-1]), "finite": finite(tr), "energy": energy(tr, ref_scale),
                "failure": None if tr.success else parse_failure(tr.message, dt)})
    row["wraps"], row["max_local_rot"], first = wraps(model, tr.q)
    row["t_first_wrap"] = None if first is None else float(tr.t[first + 1])
    integ = integrator_for(model, alpha=alpha)
    row["newton"] = _newton_sample(integ, tr, p, dt, n_samples)
    if tr.status == "newton_failed":
        row["failing_step"] = _failing_step(integ, tr, p, dt, row["failure"]["tol"] if row["failure"] else math.nan)
    if tr.status in ("element_range", "energy_growth"):
        row["flagged"] = _cross_check(integ, tr, p, dt)
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
    """The highest circular frequency about the initial configuration. The start is not an equilibrium
    (modes warn); the stiff axial modes that set omega_max do not feel the missing preload."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StabilityWarning)
        return float(np.max(modes(model, p=p).omega))


def label(ks: float, es: float) -> str:
    return f"springs x{ks:g}, E x{es:g}"


def detail(f: dict) -> str:
    """What a failure message says beyond the time."""
    return {"newton_failed": lambda: f"{f['iterations']} it., residual {f['residual']:.2g} (tol {f['tol']:.2g})",
            "element_range": lambda: f"{f['element']} end {f['end']}: {f['theta0']:+.3f} -> {f['theta1']:+.3f} rad",
            "energy_growth": lambda: f"+{f['grew_J']:.3g} J, {f['percent']:.0f} % of {f['in_motion_J']:.3g} J in "
                                     "motion"}[f["kind"]]()


