"""Output-error identification by single shooting with forward sensitivities (Eq. 16 on real data).

The unknowns are the parameters (decision variables theta, :class:`ParameterMap`) and, per
experiment, the unknown part of its initial state (:mod:`.measurement`). For given unknowns every
experiment is simulated from its first sample on the model's own grid (``dt``, HHT ``alpha``) with
the sensitivities of :mod:`.sensitivity`; the residuals are the measured positions minus the
model's, Hermite-interpolated at the sample times, divided by the declared noise (or in metres,
rotations times the scene's length), and their Jacobian follows exactly from the sensitivities.

The least-squares problem is solved by scipy's trust-region reflective Gauss-Newton
(``least_squares(method="trf")``, bounds from the parameters, unknowns scaled by the Jacobian's
columns), within an explicit :class:`Budget` of iterations and wall time: the reason for stopping
is always reported. Its answer is then polished by Gauss-Newton steps until it lies within 0.01
standard errors of the least-squares solution (Bates & Watts' relative offset, :func:`offset_in_se`):
scipy's tests on relative changes of cost and step stop early in flat valleys. A trial point at
which the model does not run (a Newton failure) is rejected like a bad step.
"""

from __future__ import annotations

import time
import weakref
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import casadi as ca
import numpy as np
from scipy.optimize import least_squares

from casflex import interrupt
from casflex.identification.initial_state import InitialState, initial_state_of
from casflex.identification.measurement import Experiment, SampleMap, free_dofs
from casflex.identification.options import Budget  # noqa: F401 (re-exported)
from casflex.identification.problem import ParameterMap
from casflex.identification.sensitivity import SensitivityRun, run_sensitivities, run_states
from casflex.model import Model
from casflex.model.markers import marker_states

__all__ = ["Budget", "OutputError", "Fit", "fit", "chord_fit"]


class StartDoesNotRun(ValueError):
    """The model does not run through the recording at the start of a fit."""


class _Diverged(Exception):
    """The model did not run at these unknowns (a Newton step failed)."""


class _OverBudget(Exception):
    """The time budget ran out."""


class _CloseEnough(Exception):
    """A point within the requested standard errors of the least-squares solution (``fit(tol_se=)``)."""

    def __init__(self, w: np.ndarray, offset: float):
        super().__init__()
        self.w, self.offset = w, offset


_X0: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _x0_map(integ, of_state: bool = True) -> ca.Function:
    """``x0_map(q0, qd0, t0, p) -> (x0, dx0/dq0, dx0/dqd0, dx0/dp)``: the consistent initial state; without
    ``of_state`` ``(x0, dx0/dp)`` only, for an initial state without unknowns (twobar: 0.3 ms a call against 1.6,
    in every model run)."""
    if integ not in _X0:
        m = integ.model
        q, qd, t, p = ca.MX.sym("q0", m.n_dof), ca.MX.sym("qd0", m.n_dof), ca.MX.sym("t0"), ca.MX.sym("p", m.n_p)
        qdd, lam = integ.initial(q, qd, t, p)
        x0 = ca.vertcat(q, qd, qdd, lam)
        _X0[integ] = (ca.Function("x0_map", [q, qd, t, p],
                                  [x0, ca.jacobian(x0, q), ca.jacobian(x0, qd), ca.jacobian(x0, p)]),
                      ca.Function("x0_map_p", [q, qd, t, p], [x0, ca.jacobian(x0, p)]))
    return _X0[integ][0 if of_state else 1]


class OutputError:
    """Residuals and Jacobian of the output error of ``experiments`` in the unknowns
    w = (theta, xi_1, ..., xi_E).

    ``initial``: per experiment its :class:`~.initial_state.InitialState` (default: the scene's),
    which maps xi_e to (q0, qd0) and gives the derivatives.

    A parameter with a ``prior`` (mean, sd) adds the row (p - mean) / sd after the data's rows (``n_prior`` of
    them, the parameters ``prior_index``): the maximum a posteriori fit. The row is in standard deviations, so
    the data's rows must be too: every experiment's noise declared or estimated (:mod:`.priors`).
    """

    def __init__(self, model: Model, experiments: list[Experiment], *, dt: float, alpha: float,
                 pmap: ParameterMap, compiled: bool, newton_tol: float,
                 initial: list[InitialState] | None = None, previous: OutputError | None = None,
                 vary: Mapping[str, tuple[float, float]] | None = None, refit: bool = False,
                 forms: bool = True) -> None:
        from casflex.simulate import integrator_for

        self.model, self.experiments, self.dt, self.pmap, self.compiled = model, experiments, dt, pmap, compiled
        self.integ = integrator_for(model, alpha=alpha, tol=newton_tol)
        # the properties the fit's other forms vary: run-time inputs of the compiled code, one library for them all
        # (None: a model never refitted in another form, e.g. the model error's refined mesh, runs its own)
        self.vary = tuple((t, (float(lo), float(hi))) for t, (lo, hi) in (vary or {}).items()) if forms else None
        self.refit = refit  # a refit in another form: its model runs without sensitivities on the forms' library too
        self.maps = [SampleMap.of(model, e, dt) for e in experiments]
        self.row_offsets = np.concatenate([[0], np.cumsum([sm.y.size for sm in self.maps])]).astype(int)
        self.free = free_dofs(model)
        npar = model.n_p
        if initial is None:
            initial = [initial_state_of(model, e, model.p_nominal) for e in experiments]
        self.initial = initial
        sizes = [s.size for s in initial]
        self.offsets = np.concatenate([[npar], npar + np.cumsum(sizes)]).astype(int)
        self.n_unknowns = int(self.offsets[-1])
        ell = model.length_scale
        self.sigma = []
        for e, sm in zip(experiments, self.maps, strict=True):
            rot = np.append(model.is_rotation, np.zeros(2 * len(model.scene.markers), bool))[sm.dof]
            base = np.where(rot, 1.0 / ell, 1.0)  # rotations compared as arc lengths at the scene's size
            if isinstance(e.noise, Mapping):  # one value per channel, in the channel's unit
                sigma = np.array([e.noise[c] for c in sm.channels])[sm.channel]
            else:
                sigma = base * (e.noise if e.noise is not None else 1.0)
            if e.loss_weights is not None:  # a robust loss's weights: a sample's noise counts as noise / sqrt(w)
                sigma = sigma / np.sqrt(e.loss_weights[sm.sample, sm.channel])
            self.sigma.append(sigma)
        self.evaluations = 0
        priors = [(j, par.prior) for j, par in enumerate(model.parameters) if par.prior is not None]
        self.prior_index = np.array([j for j, _ in priors], dtype=int)
        self.prior_mean = np.array([pr[0] for _, pr in priors], dtype=float)
        self.prior_sd = np.array([pr[1] for _, pr in priors], dtype=float)
        self.n_prior = len(priors)
        # a growing horizon's earlier stage (the first part of each recording, the same unknowns): a run at the
        # point where it ran last goes on from its end instead of from t0 (:meth:`_continued`)
        self.previous = previous
        self.last_runs: list[tuple[np.ndarray, object] | None] = [None] * len(experiments)

    # -- unknowns ----------------------------------------------------------------------------
    def pack(self, theta: np.ndarray) -> np.ndarray:
        """w from theta, every initial state at its guess."""
        return np.concatenate([np.asarray(theta, dtype=float), *(s.xi0 for s in self.initial)])

    def state(self, w: np.ndarray, e: int) -> tuple[np.ndarray, np.ndarray]:
        """(q0, qd0) of experiment e at unknowns w."""
        return self.initial[e].state(w[self.offsets[e]:self.offsets[e + 1]])

    def state_errors(self, w: np.ndarray, C: np.ndarray, e: int) -> tuple[np.ndarray, np.ndarray]:
        """Standard errors of experiment e's q0 and qd0 (all dofs) from the covariance C of w."""
        lo, hi = self.offsets[e], self.offsets[e + 1]
        Ce = C[lo:hi, lo:hi]
        return tuple(np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", D, Ce, D), 0.0))
                     for D in self.initial[e].jacobian(w[lo:hi]))

    def channel_residuals(self, r: np.ndarray) -> dict[tuple[int, str], np.ndarray]:
        """The residuals r (weighted, as :meth:`evaluate` returns them) in data units, per (experiment,
        channel name), in time order."""
        out, start = {}, 0
        for e, sm in enumerate(self.maps):
            rr = r[start:start + sm.y.size] * self.sigma[e]
            start += sm.y.size
            for c, name in enumerate(sm.channels):
                sel = sm.channel == c
                if sel.any():
                    out[(e, name)] = rr[sel][np.argsort(sm.time[sel], kind="stable")]
        return out

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lb, ub = self.pmap.bounds()
        extra = self.n_unknowns - lb.size
        return np.concatenate([lb, np.full(extra, -np.inf)]), np.concatenate([ub, np.full(extra, np.inf)])

    # -- evaluation --------------------------------------------------------------------------
    def evaluate(self, w: np.ndarray, jacobian: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """Residuals r (m,) (dimensionless: data units over noise) and, if asked, J = dr/dw (m, n)."""
        n, npar = self.model.n_dof, self.model.n_p
        theta = w[:npar]
        p = self.pmap.p(theta)
        dp = self.pmap.dp_dtheta(theta)
        rs, Js = [], []
        self.evaluations += 1
        for e, sm in enumerate(self.maps):
            try:
                q0, qd0 = self.state(w, e)
            except RuntimeError:  # CasADi's Newton on the slow manifold found no state there
                raise _Diverged(f"experiment {e + 1}: no initial state on the slow manifold at these unknowns") \
                    from None
            # carry the directions of the local unknowns (p, xi_e) only: d x0 / d(p, xi_e), (nx, npar + n_xi)
            if self.initial[e].size:
                x0, Jq, Jqd, Jp = (np.array(v) for v in _x0_map(self.integ)(q0, qd0, sm.t0, p))
                dq, dqd = self.initial[e].jacobian(w[self.offsets[e]:self.offsets[e + 1]])
                M0 = np.hstack([Jp, Jq @ dq + Jqd @ dqd])
            else:  # the scene's initial state: no unknowns of its own
                x0, M0 = (np.array(v) for v in _x0_map(self.integ, of_state=False)(q0, qd0, sm.t0, p))
            if jacobian:
                run = self._continued(e, w, p, M0.shape[1]) or run_sensitivities(
                    self.integ, x0.ravel(), p, sm.t0, sm.dt, sm.n_steps, np.union1d(sm.needed_steps, [sm.n_steps]),
                    seed=(M0, np.eye(npar, M0.shape[1])), compiled=self.compiled, vary=self.vary)
                self.last_runs[e] = (w.copy(), run) if run.converged else None
            else:  # the model run alone: the same states, a third of the cost (twobar, 4 directions)
                run = run_states(self.integ, x0.ravel(), p, sm.t0, sm.dt, sm.n_steps, sm.needed_steps,
                                 compiled=self.compiled, vary=self.vary if self.refit else None)
            if not run.converged:
                raise _Diverged(f"experiment {e + 1}: the model's Newton failed at t = "
                                f"{sm.t0 + run.failed_step * sm.dt:.6g} s")
            i0 = np.searchsorted(run.steps, sm.step)
            i1 = np.searchsorted(run.steps, sm.step + 1)
            X = run.X
            wts = sm.weights
            marked = bool(sm.dof.max() >= n)  # some channels are markers' (casflex.model.markers)
            Z, ZD = X[:, :n], X[:, n:2 * n]
            if marked:  # the markers' positions, velocities and Jacobians at every recorded step, at once
                Y, YD, Jy, Jyd = marker_states(self.model, Z, ZD)
                Z, ZD = np.hstack([Z, Y]), np.hstack([ZD, YD])
            y = (wts[:, 0] * Z[i0, sm.dof] + wts[:, 1] * ZD[i0, sm.dof]
                 + wts[:, 2] * Z[i1, sm.dof] + wts[:, 3] * ZD[i1, sm.dof])
            rs.append((y - sm.y) / self.sigma[e])
            if not jacobian:
                continue
            sel = np.arange(2 * n) if marked else np.unique(np.concatenate([sm.dof, n + sm.dof]))
            G = np.transpose(run.S[:, :, sel], (0, 2, 1))  # (k, nsel, npar + n_xi): d x_k / d(p, xi_e)
            if marked:  # a marker's sensitivities by the chain rule: y = y(q), yd = (dy/dq) qd
                GP = np.concatenate([G[:, :n], np.einsum("kmn,knc->kmc", Jy, G[:, :n])], axis=1)
                GV = np.concatenate([G[:, n:], np.einsum("kmn,knc->kmc", Jyd, G[:, :n])
                                     + np.einsum("kmn,knc->kmc", Jy, G[:, n:])], axis=1)
                pos = vel = sm.dof
            else:
                GP = GV = G
                pos, vel = np.searchsorted(sel, sm.dof), np.searchsorted(sel, n + sm.dof)
            D = (wts[:, 0, None] * GP[i0, pos] + wts[:, 1, None] * GV[i0, vel]
                 + wts[:, 2, None] * GP[i1, pos] + wts[:, 3, None] * GV[i1, vel]) / self.sigma[e][:, None]
            Je = np.zeros((sm.y.size, self.n_unknowns))
            Je[:, :npar] = D[:, :npar] * dp
            Je[:, self.offsets[e]:self.offsets[e + 1]] = D[:, npar:]
            Js.append(Je)
        if self.n_prior:  # the priors' rows (p - mean) / sd
            j = self.prior_index
            rs.append((p[j] - self.prior_mean) / self.prior_sd)
            if jacobian:
                Jp = np.zeros((self.n_prior, self.n_unknowns))
                Jp[np.arange(self.n_prior), j] = dp[j] / self.prior_sd
                Js.append(Jp)
        if jacobian:  # a stage's first run is the one that may go on from the earlier stage's: let that go
            self.previous = None
        return np.concatenate(rs), (np.vstack(Js) if jacobian else None)

    def _continued(self, e: int, w: np.ndarray, p: np.ndarray, nw: int):
        """Experiment e's run with sensitivities at w as the earlier stage's last run there, carried on from its
        end (state and sensitivities at its last step, its Newton scaling) to this stage's; None where there is
        no such run or it does not hold every step this stage's samples need. The growing horizon's first run
        of a stage is at the last one's answer: twobar 3 s saves 3750 of its 13750 steps with sensitivities."""
        prev = self.previous if CONTINUE_STAGES else None
        last = prev.last_runs[e] if prev is not None and e < len(prev.last_runs) else None
        if last is None or not np.array_equal(last[0], w):
            return None
        run, sm, psm = last[1], self.maps[e], prev.maps[e]
        n0 = psm.n_steps
        if (prev.integ is not self.integ or psm.t0 != sm.t0 or psm.dt != sm.dt or n0 >= sm.n_steps
                or run.S.shape[1] != nw or run.steps[-1] != n0):
            return None
        need = np.union1d(sm.needed_steps, [sm.n_steps])
        early, later = need[need <= n0], need[need > n0]
        idx = np.minimum(np.searchsorted(run.steps, early), run.steps.size - 1)
        if not np.array_equal(run.steps[idx], early):
            return None
        npar = self.model.n_p
        tail = run_sensitivities(self.integ, run.X[-1], p, sm.t0 + n0 * sm.dt, sm.dt, sm.n_steps - n0, later - n0,
                                 seed=(run.S[-1].T, np.eye(npar, nw)), compiled=self.compiled, scale=run.scale,
                                 vary=self.vary)
        return SensitivityRun(np.concatenate([early, tail.steps + n0]), np.concatenate([run.X[idx], tail.X]),
                              np.concatenate([run.S[idx], tail.S]), tail.converged,
                              None if tail.converged else n0 + tail.failed_step, run.scale)

    def prior_information(self, w: np.ndarray) -> np.ndarray:
        """(n, n) J_prior^T J_prior at unknowns w: the priors' information in the unknowns (zero without priors)."""
        info = np.zeros((self.n_unknowns, self.n_unknowns))
        if self.n_prior:
            j = self.prior_index
            d = self.pmap.dp_dtheta(w[:self.model.n_p])[j] / self.prior_sd
            info[j, j] = d**2
        return info

    def groups(self) -> list[list[np.ndarray]]:
        """Rows of the residual vector per experiment and sample time, in time order."""
        out, start = [], 0
        for sm in self.maps:
            _, inv = np.unique(sm.time, return_inverse=True)
            out.append([start + np.flatnonzero(inv == k) for k in range(inv.max() + 1)])
            start += sm.y.size
        return out


@dataclass(frozen=True)
class Fit:
    """The outcome of :func:`fit`: unknowns w, residuals r and Jacobian J there, the solver's
    status (scipy's ``least_squares`` status or "time_limit"), iterations, wall time and the
    distance to the least-squares solution in standard errors (:func:`offset_in_se`; nan when not
    measured)."""

    w: np.ndarray
    r: np.ndarray
    J: np.ndarray
    status: str
    converged: bool
    iterations: int
    solve_s: float
    message: str
    offset: float = float("nan")


OFFSET_TOL = 0.01  # standard errors: the estimate is within 1 % of an SE of the least-squares solution
OFFSET_ACCEPT = 0.1  # beyond a tenth of an SE the reported estimate and errors mislead


def offset_in_se(r: np.ndarray, J: np.ndarray, free: np.ndarray) -> tuple[float, np.ndarray]:
    """Distance from the current point to the least-squares solution in standard errors, and the
    Gauss-Newton step.

    The residual r (N,) splits into its projection on the tangent plane of the free unknowns'
    columns of J (N, P) and the rest: d = |Q1^T r| / s with s = |Q2^T r| / sqrt(N - P) the residual
    scale, the Mahalanobis length of the Gauss-Newton step, an upper bound of every unknown's
    distance to the solution in its own (Gauss-Newton) standard errors. It is Bates & Watts' (1981)
    relative offset times sqrt(P): statistical and scale-free, unlike scipy's relative changes of
    cost and step. Zero for an exact fit (no residual to be uncertain with).
    """
    step = np.zeros(J.shape[1])
    Jf = J[:, free]
    if Jf.shape[1] == 0:
        return 0.0, step
    sol, _, rank, _ = np.linalg.lstsq(Jf, -r, rcond=1e-12)
    step[free] = sol
    along = float(np.linalg.norm(Jf @ sol))
    across = float(np.sqrt(max(float(r @ r) - along**2, 0.0)))
    n, p = r.size, int(rank)
    if along == 0.0:
        return 0.0, step
    if across == 0.0 or n <= p:
        return (0.0 if along <= 1e-12 * max(float(np.linalg.norm(r)), 1e-300) else np.inf), step
    return along / across * np.sqrt(n - p), step


def _on_bound(w: np.ndarray, lb: np.ndarray, ub: np.ndarray) -> np.ndarray:
    near = 1e-10 * np.maximum(np.abs(w), 1.0)
    return (w - lb <= near) | (ub - w <= near)


def _polish(evaluate, w: np.ndarray, lb: np.ndarray, ub: np.ndarray, runs_left: int,
            iters: int) -> tuple[np.ndarray, int, float, bool]:
    """Gauss-Newton steps (halved until the misfit falls) from scipy's answer until it is within
    OFFSET_TOL standard errors of the least-squares solution (:func:`offset_in_se`); unknowns on a
    bound stay there. scipy's step and cost tests stop early in flat valleys: threelink mid-motion
    at 1 mm, seed 9, stopped 0.4 SE away (k3 3.1 SE from the truth, 2.4 SE at the minimum). A step
    that no halving makes descend ends the polish: the point is a minimum to the precision of the
    model runs (exact data: the residual is Newton's and the step's noise). Returns the point, the
    model runs used in all, its offset and whether the runs ran out while the misfit still fell.
    """
    while True:
        r, J = evaluate(w)
        free = np.flatnonzero(~_on_bound(w, lb, ub))
        offset, step = offset_in_se(r, J, free)
        if offset <= OFFSET_TOL or runs_left <= 0:
            return w, iters, offset, offset > OFFSET_TOL
        cost, s = float(r @ r), 1.0
        while runs_left > 0:
            trial = np.clip(w + s * step, lb, ub)
            runs_left, iters = runs_left - 1, iters + 1
            try:
                rt, _ = evaluate(trial)
            except _Diverged:
                rt = None
            if rt is not None and float(rt @ rt) < cost:
                w = trial
                break
            s /= 2
            if s < 1 / 16:  # five tries: a step this short only creeps
                return w, iters, offset, False
        else:
            return w, iters, offset, True


class _Runs:
    """The model runs of one :func:`fit`: ``self(w)`` is (r, J) at w, remembered for the next call at the
    same point, with the best point so far (``best``), the time budget (:class:`_OverBudget`) and the early
    stops ``tol_se`` and ``enough`` (:class:`_CloseEnough`, not where a bound was run onto: there the trust
    region decides)."""

    def __init__(self, problem: OutputError, budget: Budget, lb: np.ndarray, ub: np.ndarray, start_bound: np.ndarray,
                 tol_se: float | None, enough: Callable[[np.ndarray, float], bool] | None) -> None:
        self.problem, self.budget, self.lb, self.ub, self.start_bound = problem, budget, lb, ub, start_bound
        self.tol_se, self.enough = tol_se, enough
        self.t0, self.runs0 = time.perf_counter(), problem.evaluations
        self.memo: dict[str, object] = {}
        self.best = {"cost": np.inf, "w": None}

    def __call__(self, w: np.ndarray, limited: bool = True) -> tuple[np.ndarray, np.ndarray]:
        memo = self.memo
        if memo.get("w") is not None and np.array_equal(memo["w"], w):
            return memo["r"], memo["J"]
        if limited and time.perf_counter() - self.t0 > self.budget.max_time:
            raise _OverBudget
        interrupt.check()
        r, J = self.problem.evaluate(w)
        memo.update(w=w.copy(), r=r, J=J)
        if (cost := 0.5 * float(r @ r)) < self.best["cost"]:
            self.best.update(cost=cost, w=w.copy())
        bound = _on_bound(w, self.lb, self.ub)
        if (self.tol_se, self.enough) != (None, None) and not np.any(bound & ~self.start_bound):
            offset = offset_in_se(r, J, np.flatnonzero(~bound))[0]
            if (self.tol_se is not None and offset <= self.tol_se) or (self.enough is not None
                                                                          and self.enough(r, offset)):
                raise _CloseEnough(w.copy(), offset)
        return r, J

    def close_fit(self, close: _CloseEnough) -> Fit:
        """The fit that stopped early at ``close``."""
        return Fit(close.w, self.memo["r"], self.memo["J"], "within_se", True, self.problem.evaluations - self.runs0,
                   time.perf_counter() - self.t0, "", close.offset)


_STATUS = {-1: "improper_input", 0: "iteration_limit", 1: "gradient_tolerance", 2: "cost_tolerance",
           3: "step_tolerance", 4: "cost_and_step_tolerance"}


def fit(problem: OutputError, w0: np.ndarray, budget: Budget, *, verbose: bool = False, near: bool = False,
        tol_se: float | None = None, enough: Callable[[np.ndarray, float], bool] | None = None) -> Fit:
    """Minimise 1/2 |r(w)|^2 from w0 within ``budget`` (trust-region reflective Gauss-Newton).

    ``tol_se``: stop at the first model run within that many standard errors of the least-squares
    solution (:func:`offset_in_se`), as converged (status "within_se"): for a fit whose answer is only
    a start, such as a growing horizon's early stage. Default: to OFFSET_TOL and scipy's tolerances.
    ``enough(r, offset)``: a further test of that kind, on the residuals and offset of each model run.

    ``near``: w0 is another fit's answer to a nearby problem (a refined model, other weights, another
    form): Gauss-Newton steps from it first (:func:`_polish`, one model run a step when the full step
    descends), scipy's trust region from w0 where they do not reach the solution or run onto a bound.
    On twobar's model-error refit they took 2 model runs where the trust region took 7, to the same
    0.01 SE."""
    lb, ub = problem.bounds()
    w_start = np.clip(np.asarray(w0, dtype=float), lb, ub)
    evaluate = _Runs(problem, budget, lb, ub, _on_bound(w_start, lb, ub), tol_se, enough)
    t0, best = evaluate.t0, evaluate.best
    best["w"] = w_start
    try:
        r0, _ = evaluate(np.asarray(w0, dtype=float))
    except _CloseEnough as close:
        return evaluate.close_fit(close)
    except _Diverged as exc:
        raise StartDoesNotRun(f"the model does not run at the start: {exc}; try a start closer to the expected "
                              "parameters, a smaller dt or a more negative alpha") from None
    big = 1e3 * max(float(np.abs(r0).max()), 1.0)

    def fun(w: np.ndarray) -> np.ndarray:
        try:
            return evaluate(w)[0]
        except _Diverged:  # a trial point where the model does not run: a step to reject
            return np.full(r0.size, big)

    def jac(w: np.ndarray) -> np.ndarray:
        return evaluate(w)[1]

    offset, spent = float("nan"), 0
    try:
        if near:
            w, spent, offset, _ = _polish(evaluate, w_start, lb, ub, budget.max_iterations, 0)
            # a bound reached on the way is a clipped step's doing, not a minimum: the trust region decides
            if offset <= OFFSET_TOL and not np.any(_on_bound(w, lb, ub) & ~evaluate.start_bound):
                r, J = evaluate(w, limited=False)
                return Fit(w, r, J, "gauss_newton", True, spent, time.perf_counter() - t0, "", offset)
        # no gtol: scipy's gradient test is absolute, and a weakly felt parameter of a zero-residual
        # fit (kt1 over 0.1 s of exact data: 2.5e-8 m for 20 %) would stop it 20 % short
        sol = least_squares(fun, w_start, jac=jac, bounds=(lb, ub), method="trf", x_scale="jac", xtol=1e-10,
                            ftol=1e-10, gtol=None, max_nfev=max(1, budget.max_iterations - spent),
                            verbose=1 if verbose else 0)
        w, status, iters = sol.x, _STATUS.get(sol.status, str(sol.status)), int(sol.nfev) + spent
        converged = sol.status > 0
        message = "" if converged else f"stopped at the iteration limit ({budget.max_iterations} model runs)"
        if converged:
            w, iters, offset, exhausted = _polish(evaluate, w, lb, ub, budget.max_iterations - iters, iters)
            if exhausted and offset > OFFSET_ACCEPT:
                converged, status = False, "iteration_limit"
                message = (f"stopped at the iteration limit ({budget.max_iterations} model runs) "
                           f"{offset:.2g} standard errors from the least-squares solution, still descending")
    except _OverBudget:
        w, status, iters, converged = best["w"], "time_limit", problem.evaluations, False
        message = f"stopped at the time limit ({budget.max_time:g} s); the best point so far is reported"
    except _CloseEnough as close:
        return evaluate.close_fit(close)
    r, J = evaluate(w, limited=False)
    return Fit(w, r, J, status, converged, iters, time.perf_counter() - t0, message, offset)


#: Chord steps (:func:`chord_fit`) and growing-horizon stages continued from the last one's run
#: (:meth:`OutputError._continued`); False: every refit exact and every run from t0, the way before issue 49
#: (studies/bench_identification.py measures both)
CHORD_STEPS, CONTINUE_STAGES = True, True
#: The fall of the distance to the solution a chord step must bring (:func:`chord_fit`): less, and the borrowed
#: Jacobian is too far from the problem's own to trust its fixed point
CHORD_RATE = 0.1


def chord_fit(problem: OutputError, w0: np.ndarray, J: np.ndarray, budget: Budget, *,
              enough: Callable[[np.ndarray, float], bool] | None = None) -> Fit | None:
    """Gauss-Newton steps on ``problem``'s residuals with a fixed Jacobian ``J``, another fit's at ``w0``, of a
    nearby problem with the same unknowns and rows (the model refined, the same model of another form): the
    chord method. Every model run goes without sensitivities (twobar refined: a fifth of one with them).

    It stops, as :func:`fit` does, within OFFSET_TOL standard errors of the least-squares solution, or when
    ``enough(r, offset)``, the offset measured with ``J``. The point reached solves J^T r = 0, not the problem's
    own J_own^T r = 0: they differ by (J^T J)^-1 (J_own - J)^T r, of the order of the relative difference of the
    Jacobians in standard errors, which the chord's contraction per step measures too. Returns None, for an exact
    fit to decide, where a step does not bring the distance down by CHORD_RATE (the Jacobians differ too much), a
    step leaves the bounds or does not descend, the model does not run, or the budget's runs or time run out.
    The Fit's J is the borrowed one."""
    if not CHORD_STEPS:
        return None
    lb, ub = problem.bounds()
    t0, runs0 = time.perf_counter(), problem.evaluations
    w = np.asarray(w0, dtype=float)
    if J.shape[1] != w.size or np.any(_on_bound(w, lb, ub)):  # on a bound: the trust region decides
        return None
    try:
        r, _ = problem.evaluate(w, jacobian=False)
    except _Diverged:
        return None
    if r.size != J.shape[0]:
        return None
    last = np.inf
    while True:
        offset, step = offset_in_se(r, J, np.arange(w.size))
        runs = problem.evaluations - runs0 - 1  # the steps taken, as fit(near=True) counts them
        if enough is not None and enough(r, offset):
            return Fit(w, r, J, "within_se", True, runs, time.perf_counter() - t0, "", offset)
        if offset <= OFFSET_TOL:
            return Fit(w, r, J, "chord", True, runs, time.perf_counter() - t0, "", offset)
        if offset > CHORD_RATE * last or runs >= budget.max_iterations \
                or time.perf_counter() - t0 > budget.max_time:
            return None
        trial = w + step
        if np.any((trial <= lb) | (trial >= ub)):
            return None
        interrupt.check()
        try:
            rt, _ = problem.evaluate(trial, jacobian=False)
        except _Diverged:
            return None
        if not float(rt @ rt) < float(r @ r):
            return None
        w, r, last = trial, rt, offset
