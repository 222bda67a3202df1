"""Adapted direct identification (Eq. 14): the dofs that are not measured become unknowns.

The seed paper measures the nodal translations and makes each rotation a cubic in time around
each instant. Here every free dof the data do not give (rotations, always: measured rotations are
ignored, as in the paper; and translations that are not measured, e.g. twobar's joint nodes when
only nodes 3 and 5 carry markers) is a cubic in the local time tau = t - t_i,

    u(tau) = u_i + u'_i tau + u''_i tau^2 / 2 + j_i tau^3 / 6                          (Eq. 14)

(the paper's c0..c3, written with the value, rate, acceleration and jerk at t_i so the unknowns
have physical scales), and the equilibrium residual of Eq. 1 is written at the ``window`` samples
t_i, t_i+1, ... with the multipliers of each as unknowns. The paper's window is 2 samples; with
unmeasured translations the default window grows until the equations outnumber the unknowns
(twobar from nodes 3 and 5: 4 samples). All instants share the parameters, which filters noise:

    min over p, {cubic coefficients_i, lambda_i,k}  1/2 sum |z|^2

with exact first and second derivatives (SX), solved by any CasADi nlpsol, then polished by
Gauss-Newton steps. Dofs fixed by a support follow the support.

Velocities and accelerations of the measured dofs come from the data when it has them, else from
:func:`casflex.identification.smoothing.smooth` (``smoothing``: a cross-validated spline by default). The
starting values of the unknown dofs come from the constrained kinematic fit through the measured
positions at each sample of the window (:mod:`.initial_state`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import casadi as ca
import numpy as np

from casflex import codegen
from casflex.data import MeasurementSet
from casflex.identification import problem as pb
from casflex.identification.initial_state import _kinematic_fit
from casflex.identification.measurement import check_frozen, check_units
from casflex.identification.options import Smoothing, Solver
from casflex.identification.problem import IdentificationResult
from casflex.identification.reconstruct import dofs_from_markers
from casflex.model import Model

__all__ = ["identify_adapted_direct"]


def _window(model: Model, n_unknown: int, window: int | None) -> int:
    """Samples per instant: the given one, or the paper's 2, grown until the equations (n_dof per
    sample) exceed the unknowns (4 per unknown dof plus n_con multipliers per sample)."""
    if window is not None:
        if not (isinstance(window, int) and window >= 2):
            raise ValueError(f"window: expected a whole number of samples >= 2, got {window!r}")
        return window
    per_sample = model.n_dof - model.n_con
    need = math.ceil(4 * n_unknown / per_sample) if per_sample > 0 else 2
    return 2 if need <= 2 else need + 1


def _guesses(model: Model, q_rows: np.ndarray, dt: np.ndarray, unknown: list[int], measured: tuple[int, ...]):
    """[value, rate, acceleration] of each unknown dof at t_i from kinematic fits at the window's
    samples (q_rows: (K, n_dof) with the measured and fixed dofs set; dt: (K,) times from t_i)."""
    fit = _kinematic_fit(model, measured)
    q_prev = model.q0.copy()
    Q = []
    for row in q_rows:
        known = q_prev.copy()
        known[list(measured)] = row[list(measured)]
        for c in model.constraints:
            known[c.dof] = c.value
        q_prev = np.array(fit(known, q_prev, np.zeros(0))).ravel()
        Q.append(q_prev)
    Q = np.array(Q)[:, unknown]
    deg = min(2, len(dt) - 1)
    coef = np.polynomial.polynomial.polyfit(dt, Q, deg)
    out = np.zeros((len(unknown), 3))
    out[:, 0] = coef[0]
    out[:, 1] = coef[1]
    if deg == 2:
        out[:, 2] = 2 * coef[2]
    return out


def identify_adapted_direct(model: Model, data: MeasurementSet, instants: Sequence[float], *,
                            window: int | None = None, start: float | dict[str, float] | np.ndarray | None = None,
                            solver: Solver | None = None, smoothing: Smoothing | None = None,
                            beam_forces: str | None = None) -> IdentificationResult:
    """Identify the parameters from the measured dofs around ``instants`` (module docstring).

    Parameters
    ----------
    data : MeasurementSet
        Positions of some translations (m), with or without their velocities and accelerations;
        measured rotations, if any, are ignored (``extra["ignored_channels"]``). Markers' channels
        are first turned into every node's translations by the kinematic fit through the channels
        at each sample (:mod:`.reconstruct`, reported in ``extra["from_markers"]``); the standard
        errors then ignore that fit's own uncertainty.
    instants : sequence of float, s
        Each needs ``window - 1`` samples after it.
    window : int, optional
        Samples per instant (default: module docstring).
    start, smoothing, beam_forces : as :func:`.direct.identify_direct`'s; here ``beam_forces="unknown"``
        frees the axial forces of beams with both ends measured.
    solver : Solver, optional
        IPOPT, the Gauss-Newton Hessian, not compiled by default.

    Returns
    -------
    IdentificationResult
        ``multipliers`` holds lambda at each t_i; ``extra["unknown_dofs"]`` the identified
        [value, rate, acceleration] of every unknown dof at each t_i (key ``rotations`` too, for
        the rotations).
    """
    opts = (solver or Solver()).nlp_options("identify_adapted_direct()")
    smoothing = smoothing or Smoothing()
    pb.require_fixed_supports(model, "the adapted direct method")
    pb.require_no_uncertain(model, "the adapted direct method")
    # a rigid body's rotation between hinges is not in its nodes' translations: its cubic would be free,
    # and the fit "succeeds" far off (the double pendulum's elbow spring: kt 10.0 for 6, ct 0.67 for 0.15)
    pb.require_no_joints(model, "the adapted direct method (rotations fitted to the nodes' translations)")
    t_build = time.perf_counter()
    check_units(model, data)  # millimetres or milliseconds: refused, as by the indirect method
    check_frozen(model, data)
    data, from_markers = dofs_from_markers(model, data, "the adapted direct method", rotations=False)
    if model.n_p == 0:
        raise ValueError("the scene declares no parameters to identify ([[parameters]] in the scene file)")
    if len(instants) == 0:
        raise ValueError("instants: give at least one time (s)")
    sel = data.select(model)
    trans_measured = [i for i in np.flatnonzero(~model.is_rotation) if sel[i] >= 0]
    if not trans_measured:
        raise ValueError("adapted direct identification needs measured translations; the data have none")
    data, smoothing_info = pb.smoothed_if_needed(data, smoothing.kind, smoothing.cutoff)
    mode = pb.beam_forces_mode(model, beam_forces, smoothed=smoothing_info is not None)
    # rotations are unknowns here (measured ones are ignored): only axial forces are freed
    known = {i for i in range(model.n_dof) if (sel[i] >= 0 and not model.is_rotation[i]) or
             (i in {c.dof for c in model.constraints} and not model.is_rotation[i])}
    basis = pb.beam_force_basis(model, known if mode == "unknown" else set())
    n_beam = basis.size2_out(0)
    fixed = {c.dof: c.value for c in model.constraints}
    unknown = [i for i in range(model.n_dof) if i not in fixed and (model.is_rotation[i] or sel[i] < 0)]
    ignored = [model.dof_names[i] for i in np.flatnonzero(model.is_rotation) if sel[i] >= 0]
    K = _window(model, len(unknown), window)

    n, n_c, n_p = model.n_dof, model.n_con, model.n_p
    samples = []
    for t in instants:
        i = data.index(float(t))
        if i + K - 1 >= data.t.size:
            raise ValueError(f"instant t = {t:g} s: the method needs {K - 1} samples after it; the data end at "
                             f"{data.t[-1]:g} s")
        for j in range(i, i + K):
            for name, arr in (("q", data.q), ("qd", data.qd), ("qdd", data.qdd)):
                if not np.isfinite(arr[j, sel[trans_measured]]).all():
                    raise ValueError(f"instant t = {t:g} s: {name} of a measured translation is missing at "
                                     f"t = {data.t[j]:g} s; choose another instant")
        samples.append((i, float(data.t[i]), data.t[i:i + K] - data.t[i]))

    pmap = pb.ParameterMap.of(model, opts.transform)
    scale = pmap.scale
    p0 = pb.start_values(model, start)
    ell = model.length_scale
    unit = np.where(model.is_rotation[unknown], 1.0, ell)  # rad for rotations, m for translations
    idx = [i for i, *_ in samples]
    acc_max = max(float(np.abs(data.qdd[idx][:, sel[trans_measured]]).max()), 1e-12)
    vel_max = max(float(np.abs(data.qd[idx][:, sel[trans_measured]]).max()), 1e-12)
    om = max(vel_max / ell, np.sqrt(acc_max / ell), 1e-3)  # characteristic angular frequency (1/s)
    rs = np.array([1.0, om, om**2, om**3])

    def full(i: int, arr: np.ndarray) -> np.ndarray:
        v = np.zeros(n)
        v[trans_measured] = arr[i, sel[trans_measured]]
        for k, val in fixed.items():
            v[k] = val if arr is data.q else 0.0
        return v

    # force scale: inertia and gravity forces at the instants, for O(1) residuals
    fs = 1.0
    for i, *_ in samples:
        q = full(i, data.q)
        fs = max(fs, float(np.abs(np.array(model.mass(q, p0)) @ full(i, data.qdd)).max()),
                 float(np.abs(np.array(model.forces(q, full(i, data.qd), p0)[2])).max()))

    th = ca.SX.sym("theta", n_p)
    p = pmap.p(th)
    nu = len(unknown)
    z, w_inst, w0_inst, state_exprs, lam_syms = [], [], [], [], []
    measured = tuple(sorted(trans_measured))
    for k, (i, t_i, taus) in enumerate(samples):
        c = ca.SX.sym(f"c{k}", nu, 4)  # scaled [value, rate, acceleration, jerk]
        cs = c * ca.repmat(ca.DM(rs).T, nu, 1) * ca.repmat(ca.DM(unit), 1, 4)
        lam = ca.SX.sym(f"mu{k}", n_c, K)
        sig = ca.SX.sym(f"sigma{k}", n_beam, K)  # axial forces of the measured beams (N), scaled by fs
        state_exprs.append(cs[:, :3])
        lam_syms.append(lam[:, 0] * fs)
        for j, tau in enumerate(taus):
            qv, qdv, qddv = (ca.SX(full(i + j, a)) for a in (data.q, data.qd, data.qdd))
            if nu:
                qv[unknown] = cs[:, 0] + cs[:, 1] * tau + cs[:, 2] * tau**2 / 2 + cs[:, 3] * tau**3 / 6
                qdv[unknown] = cs[:, 1] + cs[:, 2] * tau + cs[:, 3] * tau**2 / 2
                qddv[unknown] = cs[:, 2] + cs[:, 3] * tau
            r = model.equilibrium(qv, qdv, qddv, lam[:, j] * fs, t_i + tau, p)[0] / fs
            if n_beam:  # free forces along the measured beams: the modelled ones no longer matter
                r = r + ca.mtimes(basis(qv), sig[:, j])
            z.append(r)
        w_inst += [ca.vec(c), ca.vec(lam), ca.vec(sig)]
        guess = _guesses(model, np.array([full(i + j, data.q) for j in range(K)]), taus, unknown, measured)
        w0 = np.column_stack([guess, np.zeros(nu)]) / rs[None, :] / unit[:, None]
        w0_inst += [w0.ravel(order="F"), np.zeros(K * n_c), np.zeros(K * n_beam)]
    z = ca.vertcat(*z)
    w = ca.vertcat(th, *w_inst)
    n_w = w.numel()
    lbw = np.full(n_w, -np.inf)
    ubw = np.full(n_w, np.inf)
    lbw[:n_p], ubw[:n_p] = pmap.bounds()
    w0 = np.concatenate([pmap.theta(p0), *w0_inst])
    zJ = ca.Function("adapted_residual", [w], [z, ca.jacobian(z, w)], ["w"], ["z", "J"])
    zJ = codegen.compiled(zJ) if opts.compiled else zJ

    # the residual at the optimum is the cubic's truncation error, not 0: the gradient's
    # round-off floor is ~1e-9, the Gauss-Newton polish does the rest
    S = opts.nlp("adapted_direct", w, z, tol=1e-9)
    build_s = time.perf_counter() - t_build

    out = pb.solve_and_polish(S, zJ, w0, lbw, ubw)
    st, w_solver, wv, polished, solver_s, solve_s = (out[k] for k in ("stats", "w_solver", "w", "polished",
                                                                     "solver_s", "solve_s"))

    zv, Jv = (np.array(v) for v in zJ(wv))
    names = model.parameter_names
    p_hat = pmap.p(wv[:n_p])
    stats = pb.gauss_newton_statistics(Jv, zv.ravel(), n_p, names, pmap.dp_dtheta(wv[:n_p]), p_hat)
    uncertainty = pb.robust_statistics(stats, Jv, zv.ravel(), len(samples), pmap.dp_dtheta(wv[:n_p]), p_hat)
    st_fn = ca.Function("states", [w], [ca.vertcat(*[ca.vec(r) for r in state_exprs]), ca.vertcat(*lam_syms)])
    st_v, lam_v = (np.array(v).ravel() for v in st_fn(wv))
    states = {f"{t:.10g}": {model.dof_names[d]: st_v[k * 3 * nu:(k + 1) * 3 * nu].reshape(3, nu).T[j].tolist()
                            for j, d in enumerate(unknown)}
              for k, (_, t, _) in enumerate(samples)}
    rotations = {t: {d: v for d, v in s.items() if d.startswith("theta")} for t, s in states.items()}
    at_bound = pb.bound_flags(model, p_hat, scale, pb.pressed_on_bounds(Jv, zv, wv, lbw[:n_p], ubw[:n_p]))
    reasons = pb.failure_reasons(st, at_bound) + pb.undetermined_reasons(stats["std_errors"],
                                                                        stats["weakest_direction"])
    return IdentificationResult(
        method="adapted-direct", solver=opts.solver, parameters=dict(zip(names, p_hat.tolist(), strict=True)),
        start=dict(zip(names, p0.tolist(), strict=True)), success=not reasons,
        status=str(st.get("return_status", "unknown")), message="; ".join(reasons),
        iterations=int(st.get("iter_count", -1)), wall_build_s=build_s, wall_solve_s=solve_s,
        objective=0.5 * float(zv.ravel() @ zv.ravel()),
        std_errors=stats.pop("std_errors"), correlation=stats.pop("correlation"), at_bound=at_bound,
        identifiability=stats, instants=[t for _, t, _ in samples],
        multipliers=lam_v.reshape(len(samples), n_c).tolist(),
        extra={**opts.record(),
               "force_scale": fs, "residual_norm": float(np.linalg.norm(zv) * fs),
               "gauss_newton_polish": polished, "solver_s": solver_s, "window": K, "smoothing": smoothing_info,
               "beam_forces": mode, "uncertainty": uncertainty,
               "solver_parameters": dict(zip(names, pmap.p(w_solver[:n_p]).tolist(), strict=True)),
               "unknown_dofs": states, "rotations": rotations, "ignored_channels": ignored, "rate_scale": om,
               **({"from_markers": from_markers} if from_markers is not None else {})},
    )
