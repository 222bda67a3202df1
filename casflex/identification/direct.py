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

from casflex import codegen
from casflex.data import MeasurementSet
from casflex.identification.measurement import check_frozen, check_units
from casflex.identification.options import Smoothing, Solver
from casflex.identification.problem import (
    IdentificationResult,
    ParameterMap,
    beam_force_basis,
    beam_forces_mode,
    bound_flags,
    failure_reasons,
    gauss_newton_statistics,
    pressed_on_bounds,
    require_fixed_supports,
    require_no_uncertain,
    robust_statistics,
    smoothed_if_needed,
    solve_and_polish,
    start_values,
    undetermined_reasons,
)
from casflex.identification.reconstruct import dofs_from_markers
from casflex.model import Model

__all__ = ["identify_direct"]


def _instant_data(model: Model, data: MeasurementSet, instants: Sequence[float]):
    sel = data.select(model)
    missing = [model.dof_names[i] for i in np.flatnonzero(sel < 0)]
    if missing:
        raise ValueError(f"direct identification needs every dof; the data lack {missing} (the adapted direct "
                         "method makes unmeasured dofs unknowns; the indirect method fits any channels)")
    if len(instants) == 0:
        raise ValueError("instants: give at least one time (s)")
    rows = [data.index(float(t)) for t in instants]
    for i in rows:
        for name, arr in (("q", data.q), ("qd", data.qd), ("qdd", data.qdd)):
            if not np.isfinite(arr[i, sel]).all():
                c = data.channels[int(sel[np.flatnonzero(~np.isfinite(arr[i, sel]))[0]])]
                raise ValueError(f"instant t = {data.t[i]:g} s: {name} of {c} is missing in the data; choose another "
                                 "instant")
    return [(data.t[i], data.q[i, sel], data.qd[i, sel], data.qdd[i, sel]) for i in rows]


def identify_direct(model: Model, data: MeasurementSet, instants: Sequence[float], *,
                    start: float | dict[str, float] | np.ndarray | None = None, solver: Solver | None = None,
                    smoothing: Smoothing | None = None, beam_forces: str | None = None) -> IdentificationResult:
    """Identify the model's parameters (its declared ones, within their bounds) from full
    kinematics at ``instants`` (s).

    ``data`` hold q of every dof; qd, qdd from the data (e.g. :func:`casflex.simulate.simulated_set`) or,
    when it has none, by smoothing. A recording with markers' channels is first turned into every
    dof by the kinematic fit through its channels at each sample (:mod:`.reconstruct`, reported in
    ``extra["from_markers"]``); the standard errors then ignore that fit's own uncertainty.
    ``start``: starting parameters, a factor on the nominal values, a dict or an array (default nominal);
    ``solver``: here IPOPT, the exact Hessian, not compiled by default; ``smoothing``: how velocities and
    accelerations are obtained when the data lack them (default a GCV smoothing spline); ``beam_forces``:
    {"unknown", "model"}, beam deformation forces solved for at each instant (default for positions-only
    data) or from the positions (the paper; default when the data bring derivatives),
    :func:`.problem.beam_forces_mode`. The exact linear solution is computed with transform "linear" only.
    """
    opts = (solver or Solver()).nlp_options("identify_direct()", hessian="exact")
    smoothing = smoothing or Smoothing()
    require_fixed_supports(model, "the direct method")
    require_no_uncertain(model, "the direct method")
    t_build = time.perf_counter()
    check_units(model, data)  # millimetres or milliseconds: refused, as by the indirect method
    check_frozen(model, data)
    data, from_markers = dofs_from_markers(model, data, "the direct method")
    data, smoothing_info = smoothed_if_needed(data, smoothing.kind, smoothing.cutoff)
    samples = _instant_data(model, data, instants)
    mode = beam_forces_mode(model, beam_forces, smoothed=smoothing_info is not None)
    basis = beam_force_basis(model, set(range(model.n_dof)) if mode == "unknown" else set())  # every dof measured
    n_ax = basis.size2_out(0)
    n_p, n_c = model.n_p, model.n_con
    if n_p == 0:
        raise ValueError("the scene declares no parameters to identify ([[parameters]] in the scene file)")
    pmap = ParameterMap.of(model, opts.transform)
    scale = pmap.scale
    p0 = start_values(model, start)
    # force scale: the largest inertia or gravity force at the instants, for O(1) residuals
    fs = max(1.0, *(float(np.abs(np.array(model.mass(q, p0)) @ a).max()) +
                    float(np.abs(np.array(model.forces(q, v, p0)[2])).max()) for _, q, v, a in samples))

    th = ca.SX.sym("theta", n_p)
    mus = [ca.SX.sym(f"mu{i}", n_c + n_ax) for i in range(len(samples))]  # multipliers, then beam forces
    p = pmap.p(th)
    z = ca.vertcat(*[(model.equilibrium(q, v, a, mu[:n_c] * fs, t, p)[0] + ca.mtimes(basis(q), mu[n_c:] * fs)) / fs
                     for (t, q, v, a), mu in zip(samples, mus, strict=True)])
    w = ca.vertcat(th, *mus)
    lb_th, ub_th = pmap.bounds()
    lbw = np.concatenate([lb_th, np.full((n_c + n_ax) * len(samples), -np.inf)])
    ubw = np.concatenate([ub_th, np.full((n_c + n_ax) * len(samples), np.inf)])
    Jz = ca.jacobian(z, w)
    zJ = ca.Function("direct_residual", [w], [z, Jz], ["w"], ["z", "J"])
    zJ = codegen.compiled(zJ) if opts.compiled else zJ

    # exact linear least squares where z is affine in (p, lambda)
    linear = not ca.depends_on(Jz, w)
    w_lin = None
    if linear:
        z0, J0 = (np.array(v) for v in zJ(np.zeros(w.numel())))
        w_lin = np.linalg.lstsq(J0, -z0.ravel(), rcond=None)[0]

    S = opts.nlp("direct", w, z)
    w0 = np.concatenate([pmap.theta(p0), np.zeros((n_c + n_ax) * len(samples))])
    build_s = time.perf_counter() - t_build

    out = solve_and_polish(S, zJ, w0, lbw, ubw)
    st, w_solver, wv, polished, solver_s, solve_s = (out[k] for k in ("stats", "w_solver", "w", "polished",
                                                                     "solver_s", "solve_s"))
    zv, Jv = (np.array(v) for v in zJ(wv))
    p_hat = pmap.p(wv[:n_p])
    stats = gauss_newton_statistics(Jv, zv.ravel(), n_p, model.parameter_names, pmap.dp_dtheta(wv[:n_p]), p_hat)
    uncertainty = robust_statistics(stats, Jv, zv.ravel(), len(samples), pmap.dp_dtheta(wv[:n_p]), p_hat)
    names = model.parameter_names
    k = n_c + n_ax
    lams = [list(wv[n_p + i * k:n_p + i * k + n_c] * fs) for i in range(len(samples))]
    at_bound = bound_flags(model, p_hat, scale, pressed_on_bounds(Jv, zv, wv, lb_th, ub_th))
    reasons = failure_reasons(st, at_bound) + undetermined_reasons(stats["std_errors"], stats["weakest_direction"])
    extra = {**opts.record(),
             "force_scale": fs, "residual_norm": float(np.linalg.norm(zv) * fs), "gauss_newton_polish": polished,
             "beam_forces": mode, "smoothing": smoothing_info, "uncertainty": uncertainty,
             "solver_s": solver_s, "solver_parameters": dict(zip(names, pmap.p(w_solver[:n_p]).tolist(), strict=True))}
    if from_markers is not None:
        extra["from_markers"] = from_markers
    if w_lin is not None:
        extra["linear_solution"] = dict(zip(names, (w_lin[:n_p] * scale).tolist(), strict=True))
    return IdentificationResult(
        method="direct", solver=opts.solver, parameters=dict(zip(names, p_hat.tolist(), strict=True)),
        start=dict(zip(names, p0.tolist(), strict=True)), success=not reasons,
        status=str(st.get("return_status", "unknown")), message="; ".join(reasons),
        iterations=int(st.get("iter_count", -1)),
        wall_build_s=build_s, wall_solve_s=solve_s, objective=0.5 * float(zv.ravel() @ zv.ravel()),
        std_errors=stats.pop("std_errors"), correlation=stats.pop("correlation"), at_bound=at_bound,
        identifiability=stats, instants=[float(t) for t, *_ in samples], multipliers=lams, extra=extra,
    )

