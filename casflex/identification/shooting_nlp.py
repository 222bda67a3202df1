"""Indirect identification as an NLP (Eqs. 15-17): single or multiple shooting for CasADi's NLP
solvers (IPOPT by default), the transcription of the seed paper and of :mod:`casflex.identification`'s
solver comparisons. The default, single shooting by Gauss-Newton on forward sensitivities, is in
:mod:`.estimate`; this transcription hands its answer to it for the final polish and the
statistics when the residue is Eq. 16.

The model is simulated by HHT-alpha from the scene's initial state at the first sample t0 over
[t0, t0 + horizon] and its kinematics are compared with the measured ones at every sample on
the step grid t0 + k dt:

    J = xi |q^ - q|^2 + psi |q'^ - q'|^2 + phi |q''^ - q''|^2                      (Eq. 15)

q being the compared channels: nodes' dofs, or markers' coordinates y(q) with their rates
y' = J q' and y'' = J q'' + (dJ/dq q') q' (J = dy/dq, :func:`casflex.markers.marker_kinematics`).

``residue="positions"`` is Eq. 16 (xi only), ``"full"`` Eq. 17. Each residue is made
dimensionless by the scene's length scale l (rotations by 1 rad), velocities by l / T and
accelerations by l / T^2 with T the horizon, so the weights (xi, psi, phi) compare like with like.

The initial state x_0 = [q0, q0', q0''(p), lambda_0(p)] takes the scene's q0, q0' and the
consistent accelerations and multipliers of Eq. 1, which move with p.

Transcriptions:

- ``single-shooting``: the unknowns are p only; the trajectory is one differentiable CasADi
  Function (HHT steps chained by ``mapaccum``, derivatives through the Newton rootfinder by the
  implicit-function theorem).
- ``multiple-shooting``: the horizon is cut into intervals of ``interval`` steps. Each interval
  after the first starts on the *slow manifold* (:mod:`.initial_state`) through the recording:
  the kinematic fit of the measured dofs and markers at the samples, a quadratic in time through
  the five nearest, gives (q_g, qd_g) at the interval's start, relaxed onto the slow manifold
  (the fit may stretch a bar by the noise where channels over-determine it); its modes below the
  samples' Nyquist frequency are the slow ones, and the decision variables are their amplitudes
  and rates (a, v). The fast components (the bars' stretching and bending, hundreds of hertz) take their
  quasi-static values, the accelerations and multipliers their consistent ones (Eq. 1). The end
  of an interval, projected on the next start's slow modes, must equal its (a, v) (equality
  constraints, scaled by the modal size of one length scale). Full HHT states as unknowns made
  the NLP as stiff as the bars' axial modes (accelerations respond to positions with ~1e8 s^-2)
  and IPOPT regularised its KKT matrix by 1e8-1e17 on 3 s of twobar; starts simulated at the
  starting parameters drifted from the data and IPOPT crawled. The transcription's optimum
  drops the fast modes' motion at each interval start, so it is near, not at, the
  single-shooting optimum: the Gauss-Newton polish (``polish``) and the statistics are single
  shooting's.

Both hand the NLP solver the Gauss-Newton Hessian J_r^T J_r (r the residue, exact first
derivatives). For Eq. 17, Gauss-Newton steps on the single-shooting problem polish p after the
solver and the standard errors come from the same Jacobian.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Sequence
from typing import Unpack

import casadi as ca
import numpy as np

from casflex import codegen
from casflex.data import MeasurementSet
from casflex.identification import problem as pb
from casflex.identification.choices import RESIDUES, TRANSCRIPTIONS  # noqa: F401 (re-exported)
from casflex.identification.measurement import Experiment
from casflex.identification.problem import IdentificationResult, NLPKeywords
from casflex.model import Model

__all__ = ["identify_nlp", "RESIDUES", "TRANSCRIPTIONS"]



def _grid(data: MeasurementSet, horizon: float, dt: float) -> tuple[float, int, np.ndarray]:
    """HHT step h, number of steps N, and the data row of each step 1..N from the first sample
    (-1: no sample)."""
    if data.t.size < 2:
        raise ValueError("data: the indirect method needs a time series (at least 2 samples)")
    h = float(dt)
    if not (np.isfinite(h) and h > 0):
        raise ValueError(f"dt: must be a positive number of seconds, got {dt!r}")
    if not (np.isfinite(horizon) and horizon > 0):
        raise ValueError(f"horizon: must be a positive number of seconds, got {horizon!r}")
    N = int(round(horizon / h))
    if N < 1 or abs(N * h - horizon) > 1e-6 * h:
        raise ValueError(f"horizon: {horizon:g} s is not a whole number of steps dt = {h:g} s")
    t0 = float(data.t[0])
    if horizon > data.t[-1] - t0 + 1e-9 * h:
        raise ValueError(f"horizon: {horizon:g} s goes beyond the data ({data.t[-1] - t0:g} s from its first sample)")
    k = (data.t - t0) / h
    on_grid = np.abs(k - np.round(k)) <= 1e-6
    rows = np.full(N, -1)
    for i in np.flatnonzero(on_grid):
        step = int(round(k[i]))
        if 1 <= step <= N:
            rows[step - 1] = i
    return h, N, rows


def _intervals(N: int, interval: int | None, transcription: str) -> list[int]:
    """Step counts of the shooting intervals (as equal as possible)."""
    if transcription == "single-shooting":
        return [N]
    K = 20 if interval is None else interval
    if not (isinstance(K, int) and K >= 1):
        raise ValueError(f"interval: expected a whole number of steps >= 1, got {interval!r}")
    M = max(1, round(N / K))
    base, extra = divmod(N, M)
    return [base + 1] * extra + [base] * (M - extra)


def _channel_kinematics(model: Model, names: list[str], orders: int) -> ca.Function:
    """``channels(q, qd, qdd) -> (y, y', y'')[:orders]`` of the channels ``names``: a node's dof is
    its own value; a marker's coordinate its position y(q) (:func:`casflex.markers.marker_kinematics`),
    velocity y' = J qd and acceleration y'' = J qdd + (dJ/dq qd) qd, J = dy/dq."""
    from casflex.markers import channel_index, marker_kinematics

    q, qd, qdd = (ca.SX.sym(s, model.n_dof) for s in ("q", "qd", "qdd"))
    idx = [channel_index(model, c) for c in names]
    if max(idx) < model.n_dof:  # nodes' dofs only: plain selections
        out = [q[idx], qd[idx], qdd[idx]]
    else:
        y, yd, J, Jd = marker_kinematics(model)(q, qd)
        out = [ca.vertcat(q, y)[idx], ca.vertcat(qd, yd)[idx],
               ca.vertcat(qdd, ca.mtimes(J, qdd) + ca.mtimes(Jd, qd))[idx]]
    return ca.Function("channels", [q, qd, qdd], out[:orders])


def _data_states(model: Model, data: MeasurementSet, names: list[str], times: list[float]
                 ) -> list[tuple[np.ndarray, np.ndarray]]:
    """(q, qd) at each of ``times`` (s) from the recording: the kinematic fits at the samples
    (:func:`.initial_state.kinematic_fits`), a quadratic in time through the 5 nearest."""
    from casflex.identification.initial_state import kinematic_fits

    if not times:
        return []
    tk, Q = kinematic_fits(model, data, names)
    out = []
    for t in times:
        near = np.sort(np.argsort(np.abs(tk - t))[:5])
        deg = min(2, near.size - 1)
        c = np.polynomial.polynomial.polyfit(tk[near] - t, Q[near], deg)
        out.append((c[0], c[1] if deg >= 1 else np.zeros(model.n_dof)))
    return out


class _SlowStart:
    """The start of a multiple-shooting interval on the slow manifold (module docstring).

    At the recording's state (q_g, qd_g) there (:func:`_data_states`), relaxed onto the slow
    manifold (its fast components quasi-static), the modes below ``omega_cut`` (rad/s) are the
    slow ones (:func:`.initial_state.slow_projection`). The unknowns
    are their amplitudes a and rates v, scaled: xi = (a / s_a, v / s_v), s_a the modal size of one length scale per dof,
    s_v = s_a / T. The state is the slow manifold's point (q, qd)(a, v; p), its accelerations and
    multipliers consistent (Eq. 1). The fast components take their quasi-static values.
    """

    def __init__(self, model: Model, integ, q_g: np.ndarray, qd_g: np.ndarray, t: float, p0: np.ndarray,
                 omega_cut: float, ell: np.ndarray, T: float, in_c: bool) -> None:
        from casflex.identification.initial_state import free_dofs, relaxed_projection, slow_manifold

        self.free = free_dofs(model)
        # relaxed first: from a fit that stretches a bar by the noise, IPOPT stopped 'acceptable'
        # with k3 55-92 % off (twobar, node 3 and two markers)
        q_g, self.B, self.C, self.d = relaxed_projection(model, q_g, p0, omega_cut)
        self.model, self.integ, self.q_g, self.t = model, integ, q_g, t
        self.k = self.B.shape[1]
        self.fn = slow_manifold(model, self.k, codegen=in_c)[0]  # in_c: the NLP is compiled to C
        s_a = np.abs(self.C) @ ell[self.free]
        self.s_a = np.where(s_a > 0, s_a, 1.0)
        self.s_v = self.s_a / T
        self.xi0 = np.concatenate([np.zeros(self.k), self.C @ qd_g[self.free] / self.s_v])

    @property
    def size(self) -> int:
        return 2 * self.k

    def state(self, xi: ca.MX, p: ca.MX) -> ca.MX:
        """The HHT state [q, qd, qdd, lambda] at the start of the interval."""
        a, v = xi[:self.k] * ca.DM(self.s_a), xi[self.k:] * ca.DM(self.s_v)
        q, qd = self.fn(a, v, self.q_g, self.C, self.B, p, self.d)
        qdd, lam = self.integ.initial(q, qd, self.t, p)
        return ca.vertcat(q, qd, qdd, lam)

    def defect(self, x_end: ca.MX, xi: ca.MX) -> ca.MX:
        """The previous interval's end projected on the slow modes, minus this start's (a, v), scaled."""
        n = self.model.n_dof
        a = ca.mtimes(ca.DM(self.C), x_end[self.free.tolist()] - ca.DM(self.q_g[self.free])) / ca.DM(self.s_a)
        v = ca.mtimes(ca.DM(self.C), x_end[(n + self.free).tolist()]) / ca.DM(self.s_v)
        return ca.vertcat(a - xi[:self.k], v - xi[self.k:])


def identify_nlp(
    model: Model,
    data: MeasurementSet,
    horizon: float,
    *,
    transcription: str = "multiple-shooting",
    residue: str = "positions",
    dofs: Sequence[str] | None = None,
    weights: tuple[float, float, float] = (1.0, 1.0, 1.0),
    alpha: float = 0.0,
    dt: float = 1e-3,
    interval: int | None = None,
    start: float | dict[str, float] | np.ndarray | None = None,
    initial_state: str = "scene",
    newton_tol: float = 1e-14,
    polish: int = 3,
    **options: Unpack[NLPKeywords],
) -> IdentificationResult:
    """Output-error identification over [t0, t0 + ``horizon``] s as an NLP (t0: the first sample).

    Parameters
    ----------
    model : Model
        Its declared parameters are the unknowns, with their bounds.
    data : MeasurementSet
        Samples on the step grid t0 + k dt (others are ignored); positions for Eq. 16, plus
        velocities and accelerations for Eq. 17.
    horizon : float, s
        End of the compared window (a whole number of steps).
    transcription : {"multiple-shooting", "single-shooting"}
    residue : {"positions", "full"}
        Eq. 16 or Eq. 17.
    dofs : names of the compared channels, nodes' dofs and markers' coordinates (e.g.
        ``["x3", "y3", "xm2", "ym2"]``); default every channel of the data. A marker is compared
        through its kinematics y(q), y' = J q', y'' = J q'' + (dJ/dq q') q' (:mod:`casflex.markers`).
    weights : (xi, psi, phi)
        Eq. 15 weights of the dimensionless position, velocity and acceleration residues.
    alpha, dt : HHT parameter and step (s).
    interval : int
        Steps per shooting interval (multiple shooting; default 20).
    start : factor, dict or array, optional
        Starting parameters (a number multiplies the nominal values).
    initial_state : {"scene", "estimate"}
        The state at the first sample: the scene's, or on the slow manifold through the
        recording's first samples with its slow-mode amplitudes and rates as unknowns (as the
        interval starts of multiple shooting; positions residue only).
    newton_tol : float
        Tolerance of the HHT Newton iterations inside the model (scaled, see HHT).
    polish : int
        Gauss-Newton steps on the single-shooting problem after the solver (0: none).
    **options : solver, solver_options, transform, hessian, compiled, verbose
        How the NLP is solved (:class:`.problem.NLPOptions`; here IPOPT, the Gauss-Newton Hessian,
        not compiled by default). ``hessian="exact"`` means second derivatives through every HHT
        Newton solve, several times slower.
    """
    from casflex.simulate import integrator_for, simulate

    opts = pb.NLPOptions.of("identify_nlp", options)
    opts.nlp_solver("the NLP transcription")
    if transcription not in TRANSCRIPTIONS:
        raise ValueError(f"transcription: expected one of {TRANSCRIPTIONS}, got {transcription!r}")
    if residue not in RESIDUES:
        raise ValueError(f"residue: expected one of {RESIDUES}, got {residue!r}")
    if model.n_p == 0:
        raise ValueError("the scene declares no parameters to identify ([[parameters]] in the scene file)")
    if len(weights) != 3 or not all(np.isfinite(w) and w >= 0 for w in weights):
        raise ValueError(f"weights: expected three numbers >= 0 (xi, psi, phi), got {weights!r}")
    if initial_state not in ("scene", "estimate"):
        raise ValueError(f"initial_state: expected 'scene' or 'estimate' for the NLP transcription, got "
                         f"{initial_state!r}")
    if initial_state == "estimate" and residue != "positions":
        raise ValueError("initial_state 'estimate': with residue 'positions' (Eq. 16) only")
    if residue == "full" and (data.qd is None or data.qdd is None):
        raise ValueError("residue 'full' (Eq. 17) needs velocities and accelerations in the data")
    if transcription == "multiple-shooting" and residue == "full":
        warnings.warn("multiple shooting with residue 'full' (Eq. 17) is slow: on twobar 45 s for 0.69 s of data, "
                      "not done in 200 s for 3 s (docs/identification.md, Known limits); single shooting is "
                      "recommended for Eq. 17", stacklevel=2)
    t_build = time.perf_counter()
    h, N, rows = _grid(data, horizon, dt)
    steps = np.flatnonzero(rows >= 0)  # steps (0-based: state after step k+1) with a sample
    if steps.size == 0:
        raise ValueError(f"data: no sample lies on the step grid k * {h:g} s within the horizon")
    # the compared channels, nodes' dofs and markers' coordinates, checked against model and data
    names = list(Experiment(data, channels=None if dofs is None else tuple(dofs)).compared(model))
    dcols = [data.channels.index(c) for c in names]
    n, n_p = model.n_dof, model.n_p
    integ = integrator_for(model, alpha=alpha, tol=newton_tol)
    pmap = pb.ParameterMap.of(model, opts.transform)
    scale = pmap.scale
    pb.require_fixed_supports(model, "the NLP transcription (solver other than gauss-newton)")
    p0 = pb.start_values(model, start)
    ell = np.where(model.is_rotation, 1.0, model.length_scale)
    T = N * h

    # residue r(X): dimensionless, (n_samples * len(names) * (1 or 3),)
    sq = np.sqrt(np.asarray(weights, dtype=float))
    drows = rows[steps]
    inv_l = 1.0 / np.array([1.0 if c in model.dof_names and model.is_rotation[model.dof(c)] else model.length_scale
                            for c in names])
    obs = [(sq[0], inv_l, data.q[np.ix_(drows, dcols)])]
    if residue == "full":
        obs += [(sq[1], T * inv_l, data.qd[np.ix_(drows, dcols)]),
                (sq[2], T**2 * inv_l, data.qdd[np.ix_(drows, dcols)])]
    channels = _channel_kinematics(model, names, len(obs)).map(steps.size)

    def residue_of(X: ca.MX) -> ca.MX:
        """X: (nx, N) states after steps 1..N."""
        Xs = X[:, steps.tolist()]
        sims = channels.call([Xs[:n, :], Xs[n:2 * n, :], Xs[2 * n:3 * n, :]])
        return ca.vertcat(*[ca.vec(wgt * (sim - Y.T) * ca.repmat(ca.DM(inv_s), 1, steps.size))
                            for sim, (wgt, inv_s, Y) in zip(sims, obs, strict=True)])

    # typical magnitudes of the state components, from a simulation at the start
    t0 = float(data.t[0])
    guess = simulate(model, T, dt=h, alpha=alpha, p=p0, tol=newton_tol, t0=t0, raise_on_failure=False)
    G = np.hstack([guess.q, guess.qd, guess.qdd, guess.lam])
    if G.shape[0] < N + 1:  # the start diverged: hold its last state
        G = np.vstack([G, np.repeat(G[-1:], N + 1 - G.shape[0], axis=0)])
    omega_cut = float(np.pi / np.median(np.diff(data.t)))  # the samples' Nyquist: faster modes only alias
    d = np.array(integ.scale(model.q0, model.qd0, p0, h)).ravel()
    # a step converged when its residual is within newton_tol, or the round-off floor of the
    # scene's coordinates where that is higher (see HHT.tolerance)
    tol_acc = float(np.max(integ.tolerance(G[:, :n])))

    th = ca.MX.sym("theta", n_p)
    p = pmap.p(th)
    lengths = _intervals(N, interval, transcription)
    first = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(int).tolist()
    M = len(lengths)
    # the recording's states at the interval starts (and at t0 for an estimated initial state): one
    # pass of kinematic fits over the samples serves them all
    est = initial_state == "estimate"
    in_c = bool(opts.compiled)  # the slow manifold's Newton solve then one C code generation takes
    guesses = _data_states(model, data, names, [t0] * est + [t0 + first[j] * h for j in range(1, M)])
    if est:  # the first state on the slow manifold through the first samples
        q_g, qd_g = guesses.pop(0)
        first_start = [_SlowStart(model, integ, q_g, qd_g, t0, p0, omega_cut, ell, T, in_c)]
        xi_init = ca.MX.sym("xi_init", first_start[0].size)
        x0 = first_start[0].state(xi_init, p)
    else:
        first_start, xi_init = [], ca.MX.sym("xi_init", 0)
        qdd0, lam0 = integ.initial(model.q0, model.qd0, t0, p)
        x0 = ca.vertcat(ca.DM(model.q0), ca.DM(model.qd0), qdd0, lam0)
    u = ca.vertcat(th, xi_init)  # the single-shooting problem's unknowns
    n_u = u.numel()

    def simulate_from(nodes: list[ca.MX], lengths: list[int], first: list[int]) -> tuple[ca.MX, ca.MX]:
        """States after every step (nx, N) and Newton residuals (1, N), intervals mapped by length."""
        out_x, out_r = [None] * len(lengths), [None] * len(lengths)
        for K in sorted(set(lengths)):
            idx = [j for j, k in enumerate(lengths) if k == K]
            F = integ.trajectory(K)
            if len(idx) > 1:
                F = F.map(len(idx), "serial")
            Xk, Rk = F(ca.horzcat(*[nodes[j] for j in idx]), ca.DM([t0 + first[j] * h for j in idx]).T, p, h, d)
            for i, j in enumerate(idx):
                out_x[j] = Xk[:, i * K:(i + 1) * K]
                out_r[j] = Rk[:, i * K:(i + 1) * K]
        return ca.horzcat(*out_x), ca.horzcat(*out_r)

    # the interval starts 1..M-1 on the slow manifold through the recording's states there
    starts = [_SlowStart(model, integ, q_g, qd_g, t0 + first[j] * h, p0, omega_cut, ell, T, in_c)
              for j, (q_g, qd_g) in enumerate(guesses, 1)]
    xi = [ca.MX.sym(f"xi{j}", s.size) for j, s in enumerate(starts, 1)]  # scaled (a, v) of each start
    nodes = [x0] + [s.state(x, p) for s, x in zip(starts, xi, strict=True)]
    X, R = simulate_from(nodes, lengths, first)
    r = residue_of(X)
    ends = [X[:, first[j] + lengths[j] - 1] for j in range(M - 1)]
    g = ca.vertcat(*[s.defect(e, x) for s, e, x in zip(starts, ends, xi, strict=True)]) if M > 1 else ca.MX(0, 1)
    w = ca.vertcat(u, *xi)

    w0 = np.concatenate([pmap.theta(p0), *[s.xi0 for s in first_start + starts]])
    lb_th, ub_th = pmap.bounds()
    n_xi = w0.size - n_p
    lbw = np.concatenate([lb_th, np.full(n_xi, -np.inf)])
    ubw = np.concatenate([ub_th, np.full(n_xi, np.inf)])

    # the objective scaled to ~1 at the start: solver tolerances then mean the same on any data
    fr = ca.Function("residue", [w], [r])
    r_start = np.array(fr(w0)).ravel()
    f_scale = 1.0 / max(float(r_start @ r_start), 1e-30) if float(r_start @ r_start) > 0 else 1.0
    # IPOPT's dual infeasibility has a floor of ~1e-8 of its start from the HHT Newton tolerance
    # inside the model: it stops there and the Gauss-Newton polish finishes the job
    nlp = opts.nlp("indirect", w, r, g, f_scale=f_scale, tol=1e-8)
    # single-shooting residue of p alone: polish and statistics
    Xf, Rf = (X, R) if transcription == "single-shooting" else simulate_from([x0], [N], [0])
    ss_r = residue_of(Xf)
    # NaN where a step's Newton did not converge, so that the polish rejects such a step
    ss_ok = ca.if_else(ca.mmax(Rf) <= tol_acc, ss_r, np.nan * ss_r)
    ss_all = ca.Function("ss_residue", [u], [ss_ok, ca.jacobian(ss_r, u), ss_r])
    ss_all = codegen.compiled(ss_all) if opts.compiled else ss_all

    def ss(t: np.ndarray) -> list:
        return ss_all(t)[:2]

    build_s = time.perf_counter() - t_build

    t_solve = time.perf_counter()
    sol = nlp(x0=w0, lbx=lbw, ubx=ubw, lbg=0.0, ubg=0.0)
    solver_s = time.perf_counter() - t_solve
    st = nlp.stats()
    wv = np.array(sol["x"]).ravel()
    u_v, polished = pb.gauss_newton_polish(ss, wv[:n_u], lbw[:n_u], ubw[:n_u], polish)
    th_v = u_v[:n_p]
    solve_s = time.perf_counter() - t_solve
    p_hat = pmap.p(th_v)
    # statistics from the residue as computed, also where a step missed the Newton tolerance
    # (then reported in the message below) rather than from its NaN-guarded form
    _, Jv, rv = (np.array(v) for v in ss_all(u_v))
    stats = pb.gauss_newton_statistics(Jv, rv.ravel(), n_p, model.parameter_names, pmap.dp_dtheta(th_v), p_hat)

    # states over the window at the identified parameters: multipliers (joint reactions)
    xr = ca.Function("states", [u], [Xf, ca.mmax(Rf)])
    Xv, newton_res = np.array(xr(u_v)[0]), float(xr(u_v)[1])
    converged = bool(newton_res <= tol_acc and np.isfinite(Xv).all())
    pn = model.parameter_names
    success = bool(st.get("success", False)) and converged
    message = "" if converged else (f"HHT Newton did not converge within the horizon at the identified parameters "
                                    f"(largest scaled residual {newton_res:.3g} > tol {tol_acc:g})")
    return IdentificationResult(
        method="indirect", solver=opts.solver, parameters=dict(zip(pn, p_hat.tolist(), strict=True)),
        start=dict(zip(pn, p0.tolist(), strict=True)), success=success,
        status=str(st.get("return_status", "unknown")), message=message, iterations=int(st.get("iter_count", -1)),
        wall_build_s=build_s, wall_solve_s=solve_s, objective=0.5 * float(rv.ravel() @ rv.ravel()),
        std_errors=stats.pop("std_errors"), correlation=stats.pop("correlation"),
        at_bound=pb.bound_flags(model, p_hat, scale), identifiability=stats,
        instants=(t0 + h * np.arange(1, N + 1)).tolist(), multipliers=Xv[3 * n:, :].T.tolist(),
        extra={**opts.record(),
               "transcription": transcription, "residue": residue, "dofs": names,
               "weights": list(weights), "initial_state": initial_state,
               "steps": N, "dt": h, "intervals": M, "samples": int(steps.size),
               "constraint_violation": float(np.abs(np.array(sol["g"])).max()) if M > 1 else 0.0,
               "gauss_newton_polish": polished, "solver_s": solver_s,
               "solver_parameters": dict(zip(pn, pmap.p(wv[:n_p]).tolist(), strict=True))},
    )

