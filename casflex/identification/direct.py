"""Direct identification (Eqs. 11-13): the equilibrium residual at measured instants.

For every instant t_i the measured (q, q', q'') enter Eq. 1 and the residual

    z_i(p, lambda_i) = M q'' + h + f_int(p) + B^T lambda_i - f_ext - g           (Eq. 11)

is minimised over p and the multipliers: min 1/2 sum_i |z_i|^2 (Eq. 12). The paper solves it
by Gauss-Newton with finite-difference gradients (Eq. 13); here it is an NLP with exact
derivatives, solved by any CasADi nlpsol (IPOPT by default). Where the parameters enter z
linearly (stiffnesses do), the exact linear least-squares solution is also computed and
returned in ``extra["linear_solution"]``; it seeds the other methods.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import casadi as ca
import numpy as np

from casflex.data import MeasurementSet
from casflex.identification.problem import (
    IdentificationResult,
    bound_flags,
    gauss_newton_statistics,
    parameter_scale,
    start_values,
)
from casflex.model import Model

__all__ = ["identify_direct"]


def _instant_data(model: Model, data: MeasurementSet, instants: Sequence[float]):
    sel = data.select(model)
    missing = [model.dof_names[i] for i in np.flatnonzero(sel < 0)]
    if missing or data.qd is None or data.qdd is None:
        what = f"dofs {missing}" if missing else "velocities and accelerations"
        raise ValueError(f"direct identification needs q, qd and qdd of every dof; the data lack {what} "
                         "(use the adapted direct or indirect method for partial data)")
    if len(instants) == 0:
        raise ValueError("instants: give at least one time (s)")
    rows = [data.index(float(t)) for t in instants]
    return [(data.t[i], data.q[i, sel], data.qd[i, sel], data.qdd[i, sel]) for i in rows]


def identify_direct(
    model: Model,
    data: MeasurementSet,
    instants: Sequence[float],
    *,
    start: float | dict[str, float] | np.ndarray | None = None,
    solver: str = "ipopt",
    solver_options: dict | None = None,
    verbose: bool = False,
) -> IdentificationResult:
    """Identify the model's parameters from full kinematics at ``instants`` (s).

    Parameters
    ----------
    model : Model
        Its declared parameters are the unknowns, with their bounds.
    data : MeasurementSet
        Must hold q, qd, qdd of every dof (e.g. :func:`casflex.data.simulated_set`).
    instants : sequence of float, s
    start : factor, dict or array, optional
        Starting parameters (a number multiplies the nominal values); default nominal.
    solver : str
        A CasADi nlpsol plugin (``ipopt``, ``sqpmethod``, ...).
    """
    t_build = time.perf_counter()
    samples = _instant_data(model, data, instants)
    n_p, n_c = model.n_p, model.n_con
    if n_p == 0:
        raise ValueError("the scene declares no parameters to identify ([[parameters]] in the scene file)")
    scale = parameter_scale(model)
    p0 = start_values(model, start)
    # force scale: the largest inertia or gravity force at the instants, for O(1) residuals
    fs = max(1.0, *(float(np.abs(np.array(model.mass(q, p0)) @ a).max()) +
                    float(np.abs(np.array(model.forces(q, v, p0)[2])).max()) for _, q, v, a in samples))

    th = ca.SX.sym("theta", n_p)
    mus = [ca.SX.sym(f"mu{i}", n_c) for i in range(len(samples))]
    p = th * scale
    z = ca.vertcat(*[model.equilibrium(q, v, a, mu * fs, t, p)[0] / fs
                     for (t, q, v, a), mu in zip(samples, mus, strict=True)])
    w = ca.vertcat(th, *mus)
    lbw = np.concatenate([[par.lower for par in model.parameters] / scale, np.full(n_c * len(samples), -np.inf)])
    ubw = np.concatenate([[par.upper for par in model.parameters] / scale, np.full(n_c * len(samples), np.inf)])
    Jz = ca.jacobian(z, w)
    zJ = ca.Function("direct_residual", [w], [z, Jz], ["w"], ["z", "J"])

    # exact linear least squares where z is affine in (p, lambda)
    linear = not ca.depends_on(Jz, w)
    w_lin = None
    if linear:
        z0, J0 = (np.array(v) for v in zJ(np.zeros(w.numel())))
        w_lin = np.linalg.lstsq(J0, -z0.ravel(), rcond=None)[0]

    opts = {"print_time": False}
    if solver == "ipopt":
        opts["ipopt"] = {"print_level": 5 if verbose else 0, "tol": 1e-14, "acceptable_tol": 1e-12,
                         "sb": "yes"}
    elif solver == "sqpmethod" and not verbose:
        opts["print_status"] = False
    opts.update(solver_options or {})
    try:
        S = ca.nlpsol("direct", solver, {"x": w, "f": 0.5 * ca.sumsqr(z)}, opts)
    except RuntimeError as exc:
        raise ValueError(f"solver {solver!r}: cannot be created ({str(exc).splitlines()[-1]})") from None
    w0 = np.concatenate([p0 / scale, np.zeros(n_c * len(samples))])
    build_s = time.perf_counter() - t_build

    t_solve = time.perf_counter()
    sol = S(x0=w0, lbx=lbw, ubx=ubw)
    solve_s = time.perf_counter() - t_solve
    st = S.stats()
    wv = np.array(sol["x"]).ravel()
    wv, polished = _polish(zJ, wv, lbw, ubw)
    zv, Jv = (np.array(v) for v in zJ(wv))
    stats = gauss_newton_statistics(Jv, zv.ravel(), n_p, model.parameter_names)
    stats["std_errors"] = {k: v * s for (k, v), s in zip(stats["std_errors"].items(), scale, strict=True)}
    p_hat = wv[:n_p] * scale
    names = model.parameter_names
    lams = [list(wv[n_p + i * n_c:n_p + (i + 1) * n_c] * fs) for i in range(len(samples))]
    at_bound = bound_flags(model, p_hat, scale)
    extra = {"force_scale": fs, "residual_norm": float(np.linalg.norm(zv) * fs), "gauss_newton_polish": polished}
    if w_lin is not None:
        extra["linear_solution"] = dict(zip(names, (w_lin[:n_p] * scale).tolist(), strict=True))
    return IdentificationResult(
        method="direct", solver=solver, parameters=dict(zip(names, p_hat.tolist(), strict=True)),
        start=dict(zip(names, p0.tolist(), strict=True)), success=bool(st.get("success", False)),
        status=str(st.get("return_status", "unknown")), message="", iterations=int(st.get("iter_count", -1)),
        wall_build_s=build_s, wall_solve_s=solve_s, objective=float(sol["f"]),
        std_errors=stats.pop("std_errors"), correlation=stats.pop("correlation"), at_bound=at_bound,
        identifiability=stats, instants=[float(t) for t, *_ in samples], multipliers=lams, extra=extra,
    )


def _polish(zJ: ca.Function, w: np.ndarray, lb: np.ndarray, ub: np.ndarray, steps: int = 3) -> tuple[np.ndarray, int]:
    """Gauss-Newton steps on 1/2 |z|^2 from the NLP solution, kept only while they stay inside
    the bounds and lower the objective: an interior-point solver stops a barrier-size distance
    (~1e-8 relative here) from the least-squares optimum of weakly determined parameters."""
    taken = 0
    z, J = (np.array(v) for v in zJ(w))
    f = float(z.ravel() @ z.ravel())
    for _ in range(steps):
        w_new = w - np.linalg.lstsq(J, z.ravel(), rcond=None)[0]
        if np.any(w_new < lb) or np.any(w_new > ub):
            break
        z_new, J_new = (np.array(v) for v in zJ(w_new))
        f_new = float(z_new.ravel() @ z_new.ravel())
        if not f_new < f:
            break
        w, z, J, f, taken = w_new, z_new, J_new, f_new, taken + 1
    return w, taken
