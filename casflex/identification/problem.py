"""What every identification method shares: parameter scaling, starts, the result record and
the Gauss-Newton statistics (standard errors, correlations, identifiability)."""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from casflex.codegen import compiled_nlpsol, log
from casflex.identification.choices import (  # noqa: F401 (re-exported)
    BEAM_FORCES,
    GAUSS_NEWTON,  # noqa: F401 (re-exported)
    HESSIANS,
    TRANSFORMS,
)
from casflex.identification.result import IdentificationResult
from casflex.model import Model

__all__ = ["IdentificationResult", "parameter_scale", "start_values", "bound_flags", "pressed_on_bounds",
           "gauss_newton_statistics", "gauss_newton_polish", "robust_statistics", "solver_options_for",
           "least_squares_nlp", "ParameterMap",
           "TRANSFORMS", "HESSIANS", "GAUSS_NEWTON", "NLPOptions", "solve_and_polish", "failure_reasons",
           "casadi_reason", "smoothed_if_needed", "undetermined_reasons"]


def parameter_scale(model: Model) -> np.ndarray:
    """Typical magnitude of each parameter: its declared ``scale``, else |nominal|, else 1; a rest
    angle's at least 1 rad (an offset, not a magnitude: a joint recorded near its rest has a nominal of
    a few hundredths of a radian, and the fit crawled at that scale, issue 26). Decision variables are
    p / scale, so they are O(1)."""
    out = []
    for par, nom in zip(model.parameters, model.p_nominal, strict=True):
        floor = 1.0 if par.target.endswith(".rest_angle") else 0.0
        out.append(par.scale if par.scale else max(abs(nom), floor) if nom != 0 else 1.0)
    return np.array(out, dtype=float)




@dataclass(frozen=True, eq=False)
class ParameterMap:
    """Decision variables theta of the parameters p, all O(1):

    - ``linear``: p = s theta, s the parameter scale (:func:`parameter_scale`);
    - ``log``: p = s exp(theta), for parameters that must stay positive; their relative
      changes become additive, which evens out parameters of very different sensitivity.
    """

    names: tuple[str, ...]
    scale: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    transform: str = "linear"

    @classmethod
    def of(cls, model: Model, transform: str = "linear") -> ParameterMap:
        if transform not in TRANSFORMS:
            raise ValueError(f"transform: expected one of {TRANSFORMS}, got {transform!r}")
        lower = np.array([par.lower for par in model.parameters], dtype=float)
        if transform == "log":
            bad = [par.name for par in model.parameters if par.lower < 0]
            if bad:
                raise ValueError(f"transform 'log': parameters {bad} may be negative (lower < 0); declare lower = 0 "
                                 "or use the linear transform")
        return cls(model.parameter_names, parameter_scale(model), lower,
                   np.array([par.upper for par in model.parameters], dtype=float), transform)

    def p(self, theta: Any) -> Any:
        """Parameters from decision variables (numbers or CasADi symbols)."""
        if self.transform == "linear":
            return theta * self.scale
        return (np.exp(theta) if isinstance(theta, np.ndarray) else ca.exp(theta)) * self.scale

    def theta(self, p: np.ndarray) -> np.ndarray:
        """Decision variables of parameter values ``p`` (e.g. a start)."""
        p = np.asarray(p, dtype=float)
        if self.transform == "linear":
            return p / self.scale
        if np.any(p <= 0):
            bad = [nm for nm, v in zip(self.names, p, strict=True) if v <= 0]
            raise ValueError(f"start: parameters {bad} must be > 0 for the log transform")
        return np.log(p / self.scale)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) bounds on theta."""
        if self.transform == "linear":
            return self.lower / self.scale, self.upper / self.scale
        # |theta| <= 40 (p within e^40 of its scale) keeps exp() finite during line searches
        with np.errstate(divide="ignore"):
            lo, hi = np.log(np.maximum(self.lower, 0.0) / self.scale), np.log(self.upper / self.scale)
        return np.maximum(lo, -40.0), np.minimum(hi, 40.0)

    def dp_dtheta(self, theta: np.ndarray) -> np.ndarray:
        return self.scale if self.transform == "linear" else self.scale * np.exp(theta)


def require_fixed_supports(model: Model, method: str) -> None:
    """ValueError when a support moves: ``method`` takes the supports' values as constants (only the
    default indirect method, single shooting by Gauss-Newton, follows their paths)."""
    if model.moving:
        moving = sorted({c.name.rsplit(".", 1)[0] for c in model.constraints if c.path is not None})
        raise ValueError(f"supports {moving} move (motion): {method} takes fixed supports only; use the indirect "
                         "method's default (single shooting by Gauss-Newton), which follows their paths")


def require_no_uncertain(model: Model, method: str, uncertain: object = None) -> None:
    """ValueError naming the properties when the scene (or ``uncertain``) declares uncertain ones: ``method``
    cannot estimate them, and holding them at the scene's values would claim more than is known."""
    targets = [u.target for u in (*model.scene.uncertain, *(uncertain or ()))]
    if targets:
        raise ValueError(f"uncertain properties {targets}: {method} cannot estimate them (it would hold them at the "
                         "scene's values and claim the parameters more precisely than they are known); use the "
                         "indirect method's default (single shooting by Gauss-Newton)")


def require_no_joints(model: Model, method: str) -> None:
    """ValueError naming the joints when ``model`` has ideal joints, which ``method`` does not take yet."""
    if model.joint_row_names:
        joints = [jt.name for jt in model.scene.joints]
        raise ValueError(f"ideal joints {joints}: {method} does not take them: a rigid body's rotation between "
                         "joints is not in its nodes' translations; use the direct method (nodes' dofs or markers) "
                         "or the indirect method")


def start_values(model: Model, start: float | dict[str, float] | np.ndarray | None) -> np.ndarray:
    """Starting parameters: None (nominal), a factor times nominal, a dict, or an array."""
    if start is None:
        return model.p_nominal.copy()
    if isinstance(start, (int, float)) and not isinstance(start, bool):
        if not (math.isfinite(start) and start > 0):
            raise ValueError(f"start: a factor must be a positive number, got {start!r}")
        return model.p_nominal * float(start)
    return model.params(start)


def bound_flags(model: Model, p: np.ndarray, scale: np.ndarray, pressed: np.ndarray | None = None
                ) -> dict[str, bool]:
    """{name: True} for parameters within 1e-8 of their scale from a bound, or ``pressed`` against
    one (:func:`pressed_on_bounds`: an interior-point solver's answer stops short of it)."""
    pressed = np.zeros(len(p), dtype=bool) if pressed is None else pressed
    return {par.name: bool(min(abs(v - par.lower), abs(v - par.upper)) <= 1e-8 * s or on)
            for v, par, s, on in zip(p, model.parameters, scale, pressed, strict=True)}


#: A parameter (decision variable, O(1)) this close to a bound, whose Gauss-Newton step leaves the box
#: through it, is on that bound: IPOPT stops a barrier-size distance inside (twobar's kt3 direct at 1.6e-7)
PRESSED = 1e-4


def pressed_on_bounds(J: np.ndarray, z: np.ndarray, w: np.ndarray, lb: np.ndarray, ub: np.ndarray) -> np.ndarray:
    """(len(lb),) True for the first len(lb) unknowns w (the parameters' decision variables, bounds lb, ub)
    within :data:`PRESSED` of a bound that the unconstrained Gauss-Newton step on z(w) (Jacobian J) crosses:
    the least-squares optimum lies beyond the bound, the answer is held there."""
    n_p = len(lb)
    if not (np.isfinite(J).all() and np.isfinite(z).all()):
        return np.zeros(n_p, dtype=bool)
    step = -np.linalg.lstsq(J, z.ravel(), rcond=None)[0][:n_p]
    th = w[:n_p]
    low = (th - lb <= PRESSED * np.maximum(1.0, np.abs(lb))) & (th + step < lb)
    high = (ub - th <= PRESSED * np.maximum(1.0, np.abs(ub))) & (th + step > ub)
    return low | high


def gauss_newton_statistics(J: np.ndarray, r: np.ndarray, n_p: int, names: tuple[str, ...],
                            dp_dtheta: np.ndarray | None = None, p: np.ndarray | None = None) -> dict[str, Any]:
    """Standard errors, correlations and identifiability of the first ``n_p`` unknowns of a
    least-squares fit.

    J : (m, n) Jacobian of the residual r (m,) in the unknowns' own units; the first n_p
    unknowns are the decision variables theta of the parameters p (see :class:`ParameterMap`).
    Covariance s^2 (J^T J)^-1 with s^2 = r^T r / (m - n) (Gauss-Newton); standard errors are
    returned in the parameters' units (times |dp/dtheta|, the delta method).

    The identifiability report gives the rank and condition number of J's columns scaled to
    unit norm. The rest is about the parameter block with the other unknowns profiled out
    (projected off the span of their columns): the parameter combination the data pin down
    least (its last right singular vector); the collinearity index 1 / sigma_min of its
    unit-norm columns (Brun et al. 2001: above ~15 the parameters cannot be told apart); each
    parameter's relative sensitivity |dr/d ln p_j| / max_k |dr/d ln p_k|, and ``weak``: those
    relative sensitivity is below 1e-2 (a 1 % change of it moves the residual less than a
    hundredth of what 1 % of the leading parameter does) or whose relative standard error
    exceeds 10 %.
    """
    m, n = J.shape
    norms = np.linalg.norm(J, axis=0)
    norms[norms == 0] = 1.0
    Js = J / norms
    sv = np.linalg.svd(Js, compute_uv=False)
    tol = max(m, n) * np.finfo(float).eps * (sv[0] if sv.size else 0.0)
    rank = int((sv > tol).sum())
    cond = float(sv[0] / sv[-1]) if sv.size and sv[-1] > 0 else math.inf
    dof = m - n
    s2 = float(r @ r) / dof if dof > 0 else math.nan
    # The parameter block with the other unknowns (multipliers, rotations, states) profiled
    # out: what the residual still feels of a parameter change once they re-adjust.
    Jp = J[:, :n_p]
    if n > n_p:
        Q, R_ = np.linalg.qr(J[:, n_p:])
        Q = Q[:, np.abs(np.diag(R_)) > max(m, n) * np.finfo(float).eps * (np.abs(R_).max() if R_.size else 0.0)]
        Jp = Jp - Q @ (Q.T @ Jp)
    pn = np.linalg.norm(Jp, axis=0)
    _, svp, vtp = np.linalg.svd(Jp / np.where(pn > 0, pn, 1.0), full_matrices=False)
    # Covariance of the parameters = s^2 (Jp^T Jp)^-1 (the Schur complement of J^T J), from the
    # SVD of Jp: positive semi-definite by construction, where inverting J^T J with condition
    # ~1e18 gave negative variances. A direction the data do not determine (singular value at
    # round-off) gives an infinite variance to every parameter it involves.
    resolved = svp > max(m, n_p) * np.finfo(float).eps * (svp[0] if svp.size else 0.0)
    inv_s = np.where(resolved, 1.0 / np.where(resolved, svp, 1.0), 0.0)
    scale = np.where(pn > 0, 1.0 / np.where(pn > 0, pn, 1.0), np.inf)
    with np.errstate(invalid="ignore"):
        cov = s2 * (vtp.T * inv_s**2) @ vtp * np.outer(scale, scale) if n_p else np.zeros((0, 0))
    var = np.diag(cov).copy() if n_p else np.zeros(0)
    undetermined = (np.abs(vtp[~resolved]) > 1e-8).any(axis=0) | (pn == 0) if n_p else np.zeros(0, bool)
    var[undetermined] = math.inf
    se = np.sqrt(var)
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(se, se)
    weakest = {nm: float(v) for nm, v in zip(names, vtp[-1], strict=True)} if n_p else {}
    dpdt = np.ones(n_p) if dp_dtheta is None else np.abs(np.asarray(dp_dtheta, dtype=float))
    p_abs = np.full(n_p, np.nan) if p is None else np.abs(np.asarray(p, dtype=float))
    se = se * dpdt
    with np.errstate(invalid="ignore", divide="ignore"):
        sens = pn * (p_abs / dpdt if p is not None else 1.0)  # |dr / d ln p|, others profiled out
        rel_sens = sens / sens.max() if n_p and sens.max() > 0 else np.zeros(n_p)
        rel_se = se / p_abs
    weak = [nm for nm, s_, e_ in zip(names, rel_sens, rel_se, strict=True)
            if s_ < 1e-2 or (not np.isnan(e_) and e_ > 0.1)]
    return {
        "std_errors": {nm: float(v) for nm, v in zip(names, se, strict=True)},
        "relative_std_errors": {nm: float(v) for nm, v in zip(names, rel_se, strict=True)},
        "relative_sensitivity": {nm: float(v) for nm, v in zip(names, rel_sens, strict=True)},
        "collinearity_index": float(1.0 / svp[-1]) if n_p and svp[-1] > 0 else math.inf,
        "weak": weak,
        "correlation": np.nan_to_num(corr).tolist(),
        "rank": rank, "n_unknowns": n, "condition": cond,
        "parameter_condition": float(svp[0] / svp[-1]) if n_p and svp[-1] > 0 else math.inf,
        "weakest_direction": weakest, "residual_variance": s2,
    }


def robust_statistics(stats: dict[str, Any], J: np.ndarray, r: np.ndarray, n_instants: int, dp_dtheta: np.ndarray,
                      p: np.ndarray) -> dict[str, dict[str, float]]:
    """The direct methods' standard errors: ``stats`` (from :func:`gauss_newton_statistics`) updated
    in place with the larger of Gauss-Newton's and the instant-clustered sandwich's
    (:func:`~casflex.identification.statistics.instant_robust_std_errors`), ``weak`` recomputed;
    returns both for the result's ``extra["uncertainty"]``."""
    from casflex.identification.statistics import instant_robust_std_errors

    names = list(stats["std_errors"])
    se_gn = np.array([stats["std_errors"][k] for k in names])
    se, se_cl = instant_robust_std_errors(J, r, n_instants, se_gn, dp_dtheta)
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = se / np.abs(p)
    stats["std_errors"] = dict(zip(names, se.tolist(), strict=True))
    stats["relative_std_errors"] = dict(zip(names, rel.tolist(), strict=True))
    stats["weak"] = [k for k, e in zip(names, rel, strict=True)
                     if k in stats["weak"] or (not np.isnan(e) and e > 0.1)]
    return {"gauss_newton": dict(zip(names, se_gn.tolist(), strict=True)),
            "instant_robust": dict(zip(names, se_cl.tolist(), strict=True))}


def merge_options(opts: dict, extra: dict) -> dict:
    """``opts`` updated by ``extra``, nested dicts merged (``{"ipopt": {"max_wall_time": 60}}``
    adds to casflex's IPOPT settings instead of replacing them all)."""
    for k, v in extra.items():
        if isinstance(v, dict) and isinstance(opts.get(k), dict):
            merge_options(opts[k], v)
        else:
            opts[k] = v
    return opts


def solver_options_for(solver: str, verbose: bool, extra: dict | None, tol: float = 1e-14) -> dict:
    """nlpsol options: quiet unless ``verbose``, IPOPT's tolerance ``tol`` (acceptable 100 tol,
    adaptive barrier), then the user's options."""
    opts: dict = {"print_time": False}
    if solver == "ipopt":
        opts["ipopt"] = {"print_level": 5 if verbose else 0, "tol": tol, "acceptable_tol": 100 * tol,
                         "acceptable_iter": 5, "sb": "yes", "mu_strategy": "adaptive", "max_iter": 500}
    elif solver == "sqpmethod" and not verbose:
        opts["print_status"] = False
    merge_options(opts, extra or {})
    return opts



@dataclass(frozen=True)
class NLPOptions:
    """How an NLP is solved, resolved from a :class:`.options.Solver` with a front end's defaults
    (:meth:`.options.Solver.nlp_options`; the values are checked there).

    solver : a CasADi nlpsol plugin (``ipopt``, ``sqpmethod``, ...).
    solver_options : nlpsol options merged into casflex's (nested dicts merged, :func:`merge_options`).
    transform : {"linear", "log"}, the decision variables (:class:`ParameterMap`).
    hessian : {"exact", "gauss-newton"}, the NLP solver's Hessian of the Lagrangian (:func:`least_squares_nlp`).
    compiled : generate and compile C for the solver's functions.
    verbose : the solver's iteration log.
    """

    solver: str = "ipopt"
    solver_options: dict | None = None
    transform: str = "linear"
    hessian: str = "gauss-newton"
    compiled: bool | None = None
    verbose: bool = False

    def nlp(self, name: str, w: Any, r: Any, g: Any = None, *, f_scale: float = 1.0, tol: float = 1e-14) -> ca.Function:
        """:func:`least_squares_nlp` with these options."""
        return least_squares_nlp(name, self.solver, w, r, g, f_scale=f_scale, hessian=self.hessian,
                                 compiled=bool(self.compiled), verbose=self.verbose,
                                 solver_options=self.solver_options, tol=tol)

    def record(self) -> dict[str, Any]:
        """What a result's ``extra`` says of how it was solved."""
        return {"transform": self.transform, "hessian": self.hessian, "compiled": bool(self.compiled)}


def hessian_refused(msg: str, triu: bool | None, solver: str) -> str | None:
    """What ``solver``'s refusal ``msg`` of a ``hess_lag`` given as upper triangle (``triu``) or whole
    means: "symmetric" (try the other form), "none" (it takes no Hessian: warned, its own is used) or
    None (another error)."""
    if triu is True and "symmetric" in msg:
        return "symmetric"
    if triu is not None and "hess_lag" in msg:
        warnings.warn(f"solver {solver!r} takes no Hessian function: hessian='gauss-newton' is not used, the "
                      "solver runs with its own Hessian (approximation)", stacklevel=4)
        return "none"
    return None


def least_squares_nlp(name: str, solver: str, w: Any, r: Any, g: Any = None, *, f_scale: float = 1.0,
                      hessian: str = "exact", compiled: bool = False, verbose: bool = False,
                      solver_options: dict | None = None, tol: float = 1e-14) -> ca.Function:
    """The NLP  min_w 1/2 f_scale |r(w)|^2  s.t. g(w) = 0  as a CasADi nlpsol.

    hessian: ``"exact"`` lets CasADi differentiate the Lagrangian twice; ``"gauss-newton"`` gives
    the solver f_scale J^T J (J = dr/dw) as ``hess_lag``, constraint curvature ignored: exact at a
    zero-residual fit and free of second derivatives through the model.
    compiled: every function the solver evaluates is generated as C and compiled (build time
    goes up by the compile, solve time down).
    """
    if hessian not in HESSIANS:
        raise ValueError(f"hessian: expected one of {HESSIANS}, got {hessian!r}")
    sym = ca.SX if isinstance(w, ca.SX) else ca.MX
    g = sym(0, 1) if g is None else g
    opts = solver_options_for(solver, verbose, None, tol=tol)
    hess = None
    if hessian == "gauss-newton":
        J = ca.jacobian(r, w)
        lam_f = sym.sym("lam_f")
        H = lam_f * f_scale * ca.mtimes(J.T, J)
        lam_g = sym.sym("lam_g", g.numel())

        def hess(triu: bool) -> ca.Function:
            return ca.Function(f"{name}_hess_l", [w, sym(0, 1), lam_f, lam_g], [ca.triu(H) if triu else H],
                               ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x" if triu else "hess_gamma_x_x"])

    nlp = {"x": w, "f": 0.5 * f_scale * ca.sumsqr(r), "g": g}
    # IPOPT and its kin take the upper triangle, the SQP methods the whole symmetric matrix;
    # some plugins (fatrop, uno, sleqp, alpaqa, blocksqp, ...) take no Hessian at all
    # (tried in that order, the likely form first: each attempt may cost a compile)
    first_full = solver in ("sqpmethod", "feasiblesqpmethod", "scpgen")
    attempts = ([False, True, None] if first_full else [True, False, None]) if hess is not None else [None]
    no_hessian = False
    for triu in attempts:
        if no_hessian and triu is not None:
            continue
        opts.pop("hess_lag", None)
        if triu is not None:
            opts["hess_lag"] = hess(triu)
        merge_options(opts, solver_options or {})
        try:
            S = ca.nlpsol(name, solver, nlp, opts)
        except RuntimeError as exc:
            msg = casadi_reason(exc)
            refused = hessian_refused(msg, triu, solver)
            if refused is None:
                raise ValueError(f"solver {solver!r}: cannot be created ({msg})") from None
            no_hessian = no_hessian or refused == "none"
            continue
        if compiled:  # the same solver on its functions compiled (cached on disk: a later process pays nothing)
            log.info("compiling the %s NLP's functions", name)
            S = compiled_nlpsol(name, solver, nlp, opts)
        return S
    raise AssertionError("unreachable")


def solve_and_polish(S: ca.Function, zJ: Any, w0: np.ndarray, lbw: np.ndarray, ubw: np.ndarray,
                     **bounds: float) -> dict[str, Any]:
    """Run the NLP solver ``S`` from ``w0`` within [lbw, ubw] (``bounds``: lbg, ubg), then polish its
    answer by Gauss-Newton steps on ``zJ`` (:func:`gauss_newton_polish`): ``w_solver`` (the solver's
    answer), ``w`` (polished), ``polished`` (steps taken), ``stats`` (the solver's), ``solver_s``
    and ``solve_s`` (s, the solver alone and with the polish)."""
    t0 = time.perf_counter()
    sol = S(x0=w0, lbx=lbw, ubx=ubw, **bounds)
    solver_s = time.perf_counter() - t0
    w_solver = np.array(sol["x"]).ravel()
    w, polished = gauss_newton_polish(zJ, w_solver, lbw, ubw)
    return {"w_solver": w_solver, "w": w, "polished": polished, "stats": S.stats(), "solver_s": solver_s,
            "solve_s": time.perf_counter() - t0}


def undetermined_reasons(std_errors: dict[str, float], weakest: dict[str, float] | None) -> list[str]:
    """Why a result whose parameters the data do not determine is not a success: an infinite standard error
    (the data fix only a combination: two springs in parallel, k1 + k1b; the values are the start's split).
    ``weakest``: the least determined direction ({name: weight}, :func:`gauss_newton_statistics`)."""
    names = [k for k, v in std_errors.items() if math.isinf(v)]
    if not names:
        return []
    if len(names) == 1:
        return [f"{names[0]} is not determined by the data (infinite standard error): the fitted motion does not "
                "depend on it here"]
    combo = " ".join(f"{w:+.2f} {k}" for k, w in (weakest or {}).items() if abs(w) > 0.05)
    return [f"{', '.join(names)} are not determined by the data (infinite standard errors"
            f"{f'; the undetermined combination: {combo}' if combo else ''}): hold all but one of them in the scene, "
            "or record motion that separates them"]


def failure_reasons(stats: dict, at_bound: dict[str, bool]) -> list[str]:
    """Why an NLP result is not a success: the solver did not converge, a parameter ended on a bound."""
    reasons = [] if stats.get("success", False) else [f"the solver did not converge ({stats.get('return_status')})"]
    bound = [k for k, v in at_bound.items() if v]
    if bound:
        reasons.append(f"{', '.join(bound)} ended on a bound: the best fit lies outside the parameters' range, "
                       "or the fit left its start's basin (try other starts: --starts N, or start values nearer)")
    return reasons


def smoothed_if_needed(data: Any, smoothing: str, cutoff: float | None) -> tuple[Any, dict | None]:
    """``data`` with velocities and accelerations (:func:`casflex.identification.smoothing.smooth` when it has none)
    and the smoothing's report (None: the data brought their own)."""
    if data.qd is not None and data.qdd is not None:
        return data, None
    from casflex.identification.smoothing import smooth

    data = smooth(data, smoothing, cutoff)
    return data, data.meta["smoothing"]


def casadi_reason(exc: Exception) -> str:
    """The informative line of a CasADi error: its last, without its suggestions and pointers to the docs
    (the first lines only locate the failing call), and without the source file that raised it. The one
    rule of the library and the command line."""
    skip = (">", "Did you mean", "Use print_options", "https://", "Tried ", "Error code:")
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip() and not ln.strip().startswith(skip)]
    if not lines:
        return type(exc).__name__
    ln = lines[-1]
    return ln.split(": ", 1)[-1] if ln.startswith(".../") else ln


def gauss_newton_polish(zJ: Any, w: np.ndarray, lb: np.ndarray, ub: np.ndarray,
                        steps: int = 3) -> tuple[np.ndarray, int]:
    """Gauss-Newton steps on 1/2 |z(w)|^2 from an NLP solution, kept only while they stay inside
    the bounds and lower the objective: an interior-point solver stops a barrier-size distance
    (~1e-8 relative here) from the least-squares optimum of weakly determined parameters.

    zJ: w -> (z, dz/dw). Returns the polished w and the number of steps taken. w is first put
    back inside [lb, ub]: IPOPT relaxes the bounds slightly (``bound_relax_factor``), so a
    parameter pinned at a bound such as a stiffness of 0 comes back just outside it."""
    taken = 0
    w = np.minimum(np.maximum(w, lb), ub)
    if not np.isfinite(w).all():  # the solver failed: nothing to polish
        return w, 0
    z, J = (np.array(v) for v in zJ(w))
    if not (np.isfinite(z).all() and np.isfinite(J).all()):
        return w, 0
    f = float(z.ravel() @ z.ravel())
    for _ in range(steps):
        w_new = w - np.linalg.lstsq(J, z.ravel(), rcond=None)[0]
        if np.any(w_new < lb) or np.any(w_new > ub):
            break
        z_new, J_new = (np.array(v) for v in zJ(w_new))
        f_new = float(z_new.ravel() @ z_new.ravel())
        if not (np.isfinite(f_new) and f_new < f):
            break
        w, z, J, f, taken = w_new, z_new, J_new, f_new, taken + 1
    return w, taken




def beam_forces_mode(model: Model, beam_forces: str | None, smoothed: bool) -> str:
    """The direct methods' treatment of the deformation forces of beam elements that the data
    measure: ``"model"`` computes them from the measured positions (the seed paper; exact data only:
    a steel bar's EA/L = 5e8 N/m turns 1 um of measurement error into 500 N), ``"unknown"`` solves
    for them at every sample like constraint forces (:func:`beam_force_basis`: the axial force
    where both ends' translations are measured, the end moments where their rotations are too).
    What the data do not measure stays modelled: an unknown rotation then follows the measured
    chord, an unmeasured end stays at the bar's length. Default: "unknown" for a recording of
    positions (``smoothed``: the method derived its velocities and accelerations), "model" for data
    that bring their own (the paper's simulated and measured sets), and "model" whenever a
    parameter is a beam property (its forces must then be modelled)."""
    beams = {b.name for b in model.scene.beams}
    beam_parameter = any(par.target.split(".")[0] in beams for par in model.parameters)
    mode = beam_forces or ("unknown" if smoothed and not beam_parameter else "model")
    if mode not in BEAM_FORCES:
        raise ValueError(f"beam_forces: expected one of {BEAM_FORCES}, got {beam_forces!r}")
    if mode == "unknown" and beam_parameter:
        raise ValueError("beam_forces 'unknown': a parameter is a beam property, whose forces must then be modelled "
                         "(beam_forces='model', exact data)")
    return mode


def beam_force_basis(model: Model, measured: set[int]) -> ca.Function:
    """``beam_force_basis(q) -> T``, T of shape (n_dof, k): the nodal forces of the beam deformation
    forces that ``measured`` (dof indices) pins down: a unit axial force in each element whose two
    ends' translations are measured, and unit end moments where both end rotations are measured
    too; T = (d d / d q)^T, d = (L - L0, theta_a, theta_b) (co-rotational stretch and local end
    rotations)."""
    q = ca.SX.sym("q", model.n_dof)
    th = model.local_rotations(q)
    cols = []
    for k, (_, _, a, b) in enumerate(s for s in model.segments if s[0] == "beam"):
        if {3 * a, 3 * a + 1, 3 * b, 3 * b + 1} <= measured:
            L = ca.sqrt((q[3 * b] - q[3 * a]) ** 2 + (q[3 * b + 1] - q[3 * a + 1]) ** 2)
            cols.append(ca.gradient(L, q))
            if {3 * a + 2, 3 * b + 2} <= measured:
                cols += [ca.gradient(th[2 * k], q), ca.gradient(th[2 * k + 1], q)]
    T = ca.horzcat(*cols) if cols else ca.SX(model.n_dof, 0)
    return ca.Function("beam_force_basis", [q], [T], ["q"], ["T"])
