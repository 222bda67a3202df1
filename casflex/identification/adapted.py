"""Adapted direct identification (Eq. 14): translations measured, rotations unknown.

Only the nodal translations x, y and their time derivatives are measured. For each instant
t_i, each free rotation is a cubic in the local time tau = t - t_i,

    theta(tau) = theta_i + theta'_i tau + theta''_i tau^2 / 2 + j_i tau^3 / 6        (Eq. 14)

(the paper's c0..c3, written with the rotation, its rate, acceleration and jerk at t_i so the
unknowns have physical scales), and the equilibrium residual of Eq. 1 is written at t_i and at
t_i + dt with the multipliers of both times as unknowns. All instants share the parameters,
which filters noise. The NLP is

    min over p, {theta_i, theta'_i, theta''_i, j_i, lambda_i, lambda_i+}  1/2 sum |z|^2

with exact first and second derivatives (SX), solved by any CasADi nlpsol, then polished by
Gauss-Newton steps. Rotations fixed by a support follow the support (they are not unknowns).

The starting rotations come from the measured translations alone: the chord rotation of a
beam element at the node, with the chord's angular rate and acceleration.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import casadi as ca
import numpy as np

from casflex.codegen import jit_options
from casflex.data import MeasurementSet
from casflex.identification.problem import (
    IdentificationResult,
    ParameterMap,
    bound_flags,
    gauss_newton_polish,
    gauss_newton_statistics,
    least_squares_nlp,
    start_values,
)
from casflex.model import Model

__all__ = ["identify_adapted_direct"]


def _chord_rotations(model: Model, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
    """(rot dofs, 3): rotation, rate, acceleration of each rotation dof from the chord of a beam
    element at its node (0 where no beam touches the node). q, qd, qdd: full dof vectors."""
    n = model.n_dof
    out = np.zeros((n, 3))
    q_init = model.q0
    for _kind, _name, a, b in model.segments:
        for node in (a, b):
            k = 3 * node + 2
            if out[k].any():
                continue
            ia, ib = 3 * a, 3 * b
            r = q[ib:ib + 2] - q[ia:ia + 2]
            r0 = q_init[ib:ib + 2] - q_init[ia:ia + 2]
            v = qd[ib:ib + 2] - qd[ia:ia + 2]
            acc = qdd[ib:ib + 2] - qdd[ia:ia + 2]
            rr = float(r @ r)
            ang = np.arctan2(r0[0] * r[1] - r0[1] * r[0], r0 @ r)
            w = (r[0] * v[1] - r[1] * v[0]) / rr
            al = (r[0] * acc[1] - r[1] * acc[0]) / rr - 2 * float(r @ v) * w / rr
            out[k] = (q_init[k] + ang, w, al)
    return out


def identify_adapted_direct(
    model: Model,
    data: MeasurementSet,
    instants: Sequence[float],
    *,
    start: float | dict[str, float] | np.ndarray | None = None,
    solver: str = "ipopt",
    solver_options: dict | None = None,
    transform: str = "linear",
    hessian: str = "gauss-newton",
    compiled: bool = False,
    verbose: bool = False,
) -> IdentificationResult:
    """Identify the parameters from translations (q, q', q'') at ``instants`` and one sample later.

    Parameters
    ----------
    model : Model
    data : MeasurementSet
        Must hold x, y with velocities and accelerations of every node; measured rotations,
        if any, are ignored (reported in ``extra["ignored_channels"]``).
    instants : sequence of float, s
        Each needs the sample after it (t_i + dt, dt the data's spacing there).
    start : factor, dict or array, optional
        Starting parameters (a number multiplies the nominal values).
    solver : str
        A CasADi nlpsol plugin (IPOPT by default).
    transform : {"linear", "log"}
        Decision variables p / scale or log(p / scale) (see :class:`ParameterMap`).
    hessian : {"exact", "gauss-newton"}
        The solver's Hessian of the Lagrangian (see :func:`least_squares_nlp`).
    compiled : bool
        Generate and compile C for the solver's functions (CasADi JIT with the system compiler).

    Returns
    -------
    IdentificationResult
        ``multipliers`` holds lambda at each t_i; ``extra["rotations"]`` the identified
        [theta, theta', theta''] of every rotation dof at each t_i.
    """
    t_build = time.perf_counter()
    if model.n_p == 0:
        raise ValueError("the scene declares no parameters to identify ([[parameters]] in the scene file)")
    if len(instants) == 0:
        raise ValueError("instants: give at least one time (s)")
    if data.qd is None or data.qdd is None:
        raise ValueError("adapted direct identification needs velocities and accelerations of the translations")
    sel = data.select(model)
    trans = np.flatnonzero(~model.is_rotation)
    missing = [model.dof_names[i] for i in trans if sel[i] < 0]
    if missing:
        raise ValueError(f"adapted direct identification needs every translation; the data lack {missing}")
    fixed = {c.dof: c.value for c in model.constraints}
    rot_free = [i for i in np.flatnonzero(model.is_rotation) if i not in fixed]
    ignored = [model.dof_names[i] for i in np.flatnonzero(model.is_rotation) if sel[i] >= 0]

    n, n_c, n_p = model.n_dof, model.n_con, model.n_p
    samples = []
    for t in instants:
        i = data.index(float(t))
        if i + 1 >= data.t.size:
            raise ValueError(f"instant t = {t:g} s: the method needs the sample after it; the data end at "
                             f"{data.t[-1]:g} s")
        for j in (i, i + 1):
            for name, arr in (("q", data.q), ("qd", data.qd), ("qdd", data.qdd)):
                if not np.isfinite(arr[j, sel[trans]]).all():
                    raise ValueError(f"instant t = {t:g} s: {name} of a translation is missing at t = {data.t[j]:g} s; "
                                     "choose another instant")
        samples.append((i, float(data.t[i]), float(data.t[i + 1] - data.t[i])))

    pmap = ParameterMap.of(model, transform)
    scale = pmap.scale
    p0 = start_values(model, start)
    ell = model.length_scale
    # characteristic angular frequency of the measured motion (1/s): scales rates, accelerations, jerks
    acc_max = max(float(np.abs(data.qdd[[i for i, *_ in samples]][:, sel[trans]]).max()), 1e-12)
    vel_max = max(float(np.abs(data.qd[[i for i, *_ in samples]][:, sel[trans]]).max()), 1e-12)
    om = max(vel_max / ell, np.sqrt(acc_max / ell), 1e-3)
    rs = np.array([1.0, om, om**2, om**3])

    def full(i: int, arr: np.ndarray) -> np.ndarray:
        v = np.zeros(n)
        v[trans] = arr[i, sel[trans]]
        return v

    # force scale: inertia and gravity forces at the instants
    fs = 1.0
    for i, *_ in samples:
        q = full(i, data.q)
        for k, v in fixed.items():
            q[k] = v
        fs = max(fs, float(np.abs(np.array(model.mass(q, p0)) @ full(i, data.qdd)).max()),
                 float(np.abs(np.array(model.forces(q, full(i, data.qd), p0)[2])).max()))

    th = ca.SX.sym("theta", n_p)
    p = pmap.p(th)
    z, w_inst, w0_inst, rot_exprs, lam_syms = [], [], [], [], []
    for k, (i, t_i, h) in enumerate(samples):
        c = ca.SX.sym(f"c{k}", len(rot_free), 4)  # scaled [theta, theta', theta'', jerk]
        cs = c * ca.repmat(ca.DM(rs).T, len(rot_free), 1)
        lam = ca.SX.sym(f"mu{k}", n_c, 2)
        rot_exprs.append(cs[:, :3])
        lam_syms.append(lam[:, 0] * fs)
        for j, tau in enumerate((0.0, h)):
            qv, qdv, qddv = (ca.SX(full(i + j, a)) for a in (data.q, data.qd, data.qdd))
            for kk, v in fixed.items():
                qv[kk] = v
            if rot_free:
                qv[rot_free] = cs[:, 0] + cs[:, 1] * tau + cs[:, 2] * tau**2 / 2 + cs[:, 3] * tau**3 / 6
                qdv[rot_free] = cs[:, 1] + cs[:, 2] * tau + cs[:, 3] * tau**2 / 2
                qddv[rot_free] = cs[:, 2] + cs[:, 3] * tau
            z.append(model.equilibrium(qv, qdv, qddv, lam[:, j] * fs, t_i + tau, p)[0] / fs)
        w_inst += [ca.vec(c), ca.vec(lam)]
        guess = _chord_rotations(model, full(i, data.q), full(i, data.qd), full(i, data.qdd))[rot_free]
        w0_inst += [np.column_stack([guess, np.zeros(len(rot_free))]).ravel(order="F") / np.repeat(rs, len(rot_free)),
                    np.zeros(2 * n_c)]
    z = ca.vertcat(*z)
    w = ca.vertcat(th, *w_inst)
    n_w = w.numel()
    lbw = np.full(n_w, -np.inf)
    ubw = np.full(n_w, np.inf)
    lbw[:n_p], ubw[:n_p] = pmap.bounds()
    w0 = np.concatenate([pmap.theta(p0), *w0_inst])
    zJ = ca.Function("adapted_residual", [w], [z, ca.jacobian(z, w)], ["w"], ["z", "J"],
                     jit_options() if compiled else {})

    # the residual at the optimum is the cubic's truncation error, not 0: the gradient's
    # round-off floor is ~1e-9, the Gauss-Newton polish does the rest
    S = least_squares_nlp("adapted_direct", solver, w, z, hessian=hessian, compiled=compiled, verbose=verbose,
                          solver_options=solver_options, tol=1e-9)
    build_s = time.perf_counter() - t_build

    t_solve = time.perf_counter()
    sol = S(x0=w0, lbx=lbw, ubx=ubw)
    solver_s = time.perf_counter() - t_solve
    st = S.stats()
    w_solver = np.array(sol["x"]).ravel()
    wv, polished = gauss_newton_polish(zJ, w_solver, lbw, ubw)
    solve_s = time.perf_counter() - t_solve

    zv, Jv = (np.array(v) for v in zJ(wv))
    names = model.parameter_names
    p_hat = pmap.p(wv[:n_p])
    stats = gauss_newton_statistics(Jv, zv.ravel(), n_p, names, pmap.dp_dtheta(wv[:n_p]), p_hat)
    rot_fn = ca.Function("rot", [w], [ca.vertcat(*[ca.vec(r) for r in rot_exprs]), ca.vertcat(*lam_syms)])
    rot_v, lam_v = (np.array(v).ravel() for v in rot_fn(wv))
    nr = len(rot_free)
    rotations = {f"{t:.10g}": {model.dof_names[d]: rot_v[k * 3 * nr:(k + 1) * 3 * nr].reshape(3, nr).T[j].tolist()
                               for j, d in enumerate(rot_free)}
                 for k, (_, t, _) in enumerate(samples)}
    return IdentificationResult(
        method="adapted-direct", solver=solver, parameters=dict(zip(names, p_hat.tolist(), strict=True)),
        start=dict(zip(names, p0.tolist(), strict=True)), success=bool(st.get("success", False)),
        status=str(st.get("return_status", "unknown")), message="", iterations=int(st.get("iter_count", -1)),
        wall_build_s=build_s, wall_solve_s=solve_s, objective=0.5 * float(zv.ravel() @ zv.ravel()),
        std_errors=stats.pop("std_errors"), correlation=stats.pop("correlation"),
        at_bound=bound_flags(model, p_hat, scale), identifiability=stats,
        instants=[t for _, t, _ in samples], multipliers=lam_v.reshape(len(samples), n_c).tolist(),
        extra={"transform": transform, "hessian": hessian, "compiled": compiled,
               "force_scale": fs, "residual_norm": float(np.linalg.norm(zv) * fs),
               "gauss_newton_polish": polished, "solver_s": solver_s,
               "solver_parameters": dict(zip(names, pmap.p(w_solver[:n_p]).tolist(), strict=True)),
               "rotations": rotations, "ignored_channels": ignored, "rate_scale": om},
    )
