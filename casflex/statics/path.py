"""Equilibrium paths by arc-length continuation: load-deflection curves through limit points
(snap-through) with the stability of every point and the critical points located on the way.

The unknowns are the scaled free dofs u and the load factor s; the path is the curve
g(u, s) = dPi/du = 0. From a point z_i = (u_i, s_i) with unit tangent tau_i (metric |du|^2 +
psi^2 ds^2, psi = |du/ds| at the start, so that load and displacement count alike there), the
predictor is z_i + h tau_i and the corrector is Newton's method on the bordered system

    [ H        dg/ds        ] [du]     [ g                                   ]
    [ tau_u^T  psi^2 tau_s  ] [ds] = - [ tau . (z - z_i - h tau_i) (metric)  ]

(pseudo-arc-length, Keller 1977; Riks 1979): the corrector stays in the hyperplane normal to
the tangent, which crosses the path transversally at limit points, where the tangent H alone is
singular and load control fails. The next tangent solves [H, dg/ds; tau_i^T (metric)] tau = [0;
1], which keeps its orientation (tau_i . tau > 0): the path goes on through a limit point
instead of turning back. The arc length h grows by 1.5 after a step that converged in at most 3
iterations, shrinks by 0.6 after one that took 7 or more, and is halved after a failed one.

Stability along the path: the number of negative eigenvalues of H (below the round-off band,
:class:`~casflex.statics.problem.Stability`). Where it changes between two points, a critical
point lies between them: it is located by regula falsi (Illinois) on the arc length, on the
eigenvalue that changes sign, and classified as a *limit* point if the load factor turns there
(tau_s changes sign) and as a *bifurcation* point otherwise (another branch crosses; the path
goes on along the one it was on).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from casflex.model import Model
from casflex.statics.jointed import JointedPath
from casflex.statics.problem import (
    Scaled,
    StaticOptions,
    StaticsError,
    neutral_band,
    problem_for,
    resolve_options,
    spell,
)
from casflex.statics.solve import solve_at

__all__ = ["CriticalPoint", "PathResult", "equilibrium_path"]

#: Newton iterations per path step (at most; also bounded by the options' max_iter).
_CORRECTOR_ITER = 15
#: Largest change of an element's local end rotation in one path step (rad).
_MAX_TURN = 0.5 * math.pi
#: Smallest cosine of the angle between consecutive tangents (25 degrees): a sharper turn
#: halves the step, so that the curvature is resolved and a snap-through is not jumped over.
_MIN_COS = math.cos(math.radians(25.0))


@dataclass(frozen=True)
class CriticalPoint:
    """A point of the path where the reduced tangent is singular.

    Attributes
    ----------
    kind : str
        ``"limit"`` (the load factor turns: snap-through under load control) or ``"bifurcation"``
        (the stability changes while the load factor goes on: another branch crosses).
    load_factor : float
        Load factor at the point.
    q : ndarray, shape (n_dof,)
        Configuration (m, rad).
    lam : ndarray, shape (n_con,)
        Multipliers (N, N m); reactions are ``-lam``.
    eigenvalue : float
        The eigenvalue that changes sign there, relative to the largest (~0: located to round-off).
    after : int
        Index of the path point it follows (it lies between points ``after`` and ``after + 1``).
    """

    kind: str
    load_factor: float
    q: np.ndarray
    lam: np.ndarray
    eigenvalue: float
    after: int


@dataclass(frozen=True)
class PathResult:
    """An equilibrium path, from the unloaded structure on.

    Attributes
    ----------
    load_factors : ndarray, shape (k,)
        Load factor at each point (the first is 0).
    q : ndarray, shape (k, n_dof)
        Configurations (m, rad).
    lam : ndarray, shape (k, n_con)
        Multipliers (N, N m); reactions are ``-lam``.
    arc_length : ndarray, shape (k,)
        Arc length from the start (scaled: structure lengths, see the module docstring).
    min_eigenvalue : ndarray, shape (k,)
        Smallest eigenvalue of the reduced tangent relative to the largest.
    negative : ndarray of int, shape (k,)
        Number of negative eigenvalues (unstable modes) at each point.
    stable : ndarray of bool, shape (k,)
        Whether each point is a stable equilibrium.
    critical : tuple of CriticalPoint
        Limit and bifurcation points located between the points, in path order.
    success : bool
        True; a failure raises :class:`StaticsError`, whose ``path`` holds the points traced so far
        with ``success`` False and ``status`` ``"failed"``.
    status : str
        ``"reached"`` (the load factor reached ``to_factor``; the last point is there exactly) or
        ``"max_points"`` (stopped after ``max_points`` points).
    message : str
        One-line summary.
    iterations : int
        Newton iterations, all steps and the location of critical points included.
    dof_names : tuple of str
        Names of the columns of ``q``.
    """

    load_factors: np.ndarray
    q: np.ndarray
    lam: np.ndarray
    arc_length: np.ndarray
    min_eigenvalue: np.ndarray
    negative: np.ndarray
    stable: np.ndarray
    critical: tuple[CriticalPoint, ...]
    success: bool
    status: str
    message: str
    iterations: int
    dof_names: tuple[str, ...]


@dataclass
class _Point:
    u: np.ndarray
    s: float
    lam: np.ndarray
    eig: np.ndarray  # eigenvalues of the scaled reduced tangent, ascending
    band: float
    iterations: int

    @property
    def negative(self) -> int:
        return int(np.sum(self.eig < -self.band))

    @property
    def relative(self) -> float:
        if self.eig.size == 0:
            return math.inf
        return float(self.eig[0] / max(np.max(np.abs(self.eig)), 1e-300))


class _Tracer:
    """Predictor, corrector and tangent of one path."""

    def __init__(self, sp: Scaled, opts: StaticOptions, psi: float):
        self.sp, self.opts, self.psi2 = sp, opts, psi**2
        self.iterations = 0
        self.max_iter = min(opts.max_iter, _CORRECTOR_ITER)

    def correct(self, z: _Point, tau: np.ndarray, h: float, fixed_s: float | None = None,
                guess: tuple[np.ndarray, float] | None = None) -> _Point | None:
        """Newton from the predictor z + h tau (or ``guess``) onto the path: in the hyperplane
        normal to tau, or at load factor ``fixed_s``. None if it does not converge."""
        sp, n = self.sp, self.sp.n
        u, s = guess if guess is not None else (z.u + h * tau[:n], z.s + h * tau[n])
        u_p, s_p = u.copy(), s
        step_tol = 1e-2 * math.sqrt(self.opts.tol)
        for it in range(1, self.max_iter + 1):
            self.iterations += 1
            _, _, g = sp.gradient(u, s)
            if not np.all(np.isfinite(g)) or sp.turn(z.u, u) > _MAX_TURN:
                return None
            res, tol_k = sp.residual(g), sp.tol(self.opts.tol, u)
            H = sp.hessian(u, s)
            b = sp.load(u)
            A = np.zeros((n + 1, n + 1))
            A[:n, :n], A[:n, n] = H, b
            if fixed_s is None:
                A[n, :n], A[n, n] = tau[:n], self.psi2 * tau[n]
                c = float(tau[:n] @ (u - u_p) + self.psi2 * tau[n] * (s - s_p))
            else:
                A[n, n], c = 1.0, s - fixed_s
            try:
                d = np.linalg.solve(A, -np.append(g, c))
            except np.linalg.LinAlgError:
                return None
            if not np.all(np.isfinite(d)):
                return None
            upd = max(float(np.max(np.abs(d[:n]), initial=0.0)), math.sqrt(self.psi2) * abs(d[n]))
            u_prev, s_prev = u, s
            u, s = u + d[:n], s + d[n]
            if res <= tol_k and upd <= step_tol:
                eig = sp.tangent_eigenvalues(u, s) if n else np.zeros(0)
                lam = sp.reactions(u_prev, s_prev, u - u_prev)
                return _Point(u, s, lam, eig, neutral_band(eig), it)
        return None

    def tangent(self, z: _Point, tau: np.ndarray) -> np.ndarray:
        """Unit tangent at z (metric |du|^2 + psi^2 ds^2), oriented along tau (the previous one)."""
        n = self.sp.n
        A = np.zeros((n + 1, n + 1))
        A[:n, :n], A[:n, n] = self.sp.hessian(z.u, z.s), self.sp.load(z.u)
        A[n, :n], A[n, n] = tau[:n], self.psi2 * tau[n]
        rhs = np.zeros(n + 1)
        rhs[n] = 1.0
        t = np.linalg.solve(A, rhs)
        return t / self.norm(t)

    def inner(self, a: np.ndarray, b: np.ndarray) -> float:
        return float(a[:-1] @ b[:-1]) + self.psi2 * float(a[-1] * b[-1])

    def norm(self, t: np.ndarray) -> float:
        return math.sqrt(self.inner(t, t))

    def locate(self, z0: _Point, tau: np.ndarray, h: float, z1: _Point) -> _Point:
        """The point between z0 and z1 (= correct(z0, tau, h)) where the eigenvalue that changes
        sign is zero: regula falsi (Illinois) on the arc length."""
        k = min(z0.negative, z1.negative)
        a, fa, b, fb = 0.0, z0.eig[k], h, z1.eig[k]
        best = z1 if abs(fb) < abs(fa) else z0
        for _ in range(40):
            c = b - fb * (b - a) / (fb - fa)
            if not (min(a, b) < c < max(a, b)):
                c = 0.5 * (a + b)
            z = self.correct(z0, tau, c)
            if z is None:
                break
            fc = z.eig[k]
            if abs(fc) < abs(best.eig[k]):
                best = z
            if abs(fc) <= 10.0 * z.band or abs(b - a) <= 1e-12 * h:
                break
            if (fc < 0) != (fb < 0):
                a, fa = b, fb
            else:
                fa *= 0.5
            b, fb = c, fc
        return best


def _validate(to_factor: float, max_points: int, arc_length: float | None, names: Mapping[str, str] | None) -> None:
    if isinstance(to_factor, bool) or not isinstance(to_factor, int | float) or not 0 < to_factor < math.inf:
        raise ValueError(f"{spell(names, 'to_factor', to_factor)}: the load factor to reach must be a number > 0")
    if isinstance(max_points, bool) or not isinstance(max_points, int) or max_points < 2:
        raise ValueError(f"{spell(names, 'max_points', max_points)}: expected an integer >= 2")
    if arc_length is not None and not (isinstance(arc_length, int | float) and 0 < arc_length < math.inf):
        raise ValueError(f"{spell(names, 'arc_length', arc_length)}: expected a number > 0")


def equilibrium_path(
    model: Model,
    *,
    p: np.ndarray | dict[str, float] | None = None,
    t: float = 0.0,
    q_start: np.ndarray | None = None,
    to_factor: float = 1.0,
    max_points: int = 200,
    arc_length: float | None = None,
    options: StaticOptions | None = None,
    names: Mapping[str, str] | None = None,
    **settings,
) -> PathResult:
    """Trace the equilibrium path from the unloaded structure to load factor ``to_factor`` by
    arc-length continuation, through limit points (see the module docstring).

    Parameters
    ----------
    model : Model
        From :func:`casflex.assemble`.
    p : array (n_p,) or dict, optional
        Parameter values; default ``model.p_nominal``.
    t : float
        Time (s) at which tabulated loads are evaluated.
    q_start : array (n_dof,), optional
        Start (m, rad); default ``model.q0``. The path starts at the equilibrium at load factor
        0 found from it (the start itself for a stress-free scene).
    to_factor : float
        The path ends when the load factor reaches this value (> 0; the last point is solved
        at exactly this factor).
    max_points : int
        Largest number of points, the start included.
    arc_length : float, optional
        First arc length (scaled: structure lengths); default: the one that raises the load
        factor by ``to_factor`` / 20 along the initial tangent.
    options : StaticOptions, optional
        ``tol`` and ``max_iter`` (at most 15 Newton iterations per step are used) apply; the
        start is solved with all of them.
    names : mapping of str to str, optional
        How the caller names the arguments, for error messages (e.g. ``{"to_factor": "--to-factor"}``).
    **settings
        Fields of :class:`StaticOptions` overriding ``options``.

    Returns
    -------
    PathResult

    Raises
    ------
    StaticsError
        If the start has no equilibrium, its tangent is singular (no load path is defined from a
        mechanism at rest), or the arc length falls below 1e-8 of the first one; the error's
        ``path`` holds the points traced so far.
    """
    opts = resolve_options(options, settings)
    _validate(to_factor, max_points, arc_length, names)
    prob = problem_for(model)
    if not prob.conservative:  # the path's stability tests read the symmetric tangent of a potential
        raise StaticsError("the scene has follower loads: equilibrium paths are traced for conservative loads only; "
                           "step the follower load as a parameter with equilibrium(seek='nearest') instead")
    pv = model.p_nominal.copy() if p is None else model.params(p)
    q0 = np.array(model.q0 if q_start is None else q_start, dtype=float).reshape(-1)
    if q0.shape != (model.n_dof,):
        raise ValueError(f"q_start: expected shape ({model.n_dof},), got {q0.shape}")
    sp = Scaled(prob, pv, t, q0)
    if model.joint_row_names:  # the joints' multipliers join the unknowns (casflex.statics.jointed)
        sp = JointedPath(model, sp)
        ok, x0, its = sp.start(opts)
        start = SimpleNamespace(converged=ok, u=x0, previous=x0, iterations=its, reason="Newton on the joints' "
                                "Lagrangian did not converge")
    else:
        sp.check_supported()
        start = solve_at(sp, sp.u(sp.base), 0.0, opts)
    n = sp.n
    if n == 0:
        raise StaticsError("the supports fix every dof: there is no path to trace")
    if not start.converged:
        raise StaticsError(f"no equilibrium of the unloaded structure from the start ({start.reason}); the path "
                           "begins there")
    H0, b0 = sp.hessian(start.u, 0.0), sp.load(start.u)
    try:
        du = np.linalg.solve(H0, -b0)
    except np.linalg.LinAlgError:
        du = np.full(n, np.inf)
    eig0 = sp.tangent_eigenvalues(start.u, 0.0)
    if eig0.size == 0:
        raise StaticsError("the supports and joints leave no motion: there is no path to trace")
    if not np.all(np.isfinite(du)) or eig0[0] <= neutral_band(eig0) * 10:
        raise StaticsError(
            "the tangent of the unloaded structure is singular or not positive definite (smallest eigenvalue "
            f"{eig0[0] / np.max(np.abs(eig0)):.2e} of the largest): the load path from there is not defined (a "
            "mechanism at rest has no stiffness to balance a load). Trace from a stiff start (a preloaded "
            "equilibrium), or solve for the equilibrium at the load itself.")
    psi = float(np.linalg.norm(du))
    if psi == 0.0:
        raise StaticsError("the loads (gravity included) are zero: there is no path to trace")
    tr = _Tracer(sp, opts, psi)
    tau = np.append(du, 1.0)
    tau /= tr.norm(tau)
    lam0 = sp.reactions(start.previous, 0.0, start.u - start.previous)
    z = _Point(start.u, 0.0, lam0, eig0, neutral_band(eig0), start.iterations)
    points, arcs, critical = [z], [0.0], []
    h0 = arc_length if arc_length is not None else (to_factor / 20.0) / tau[n]
    h, h_max = h0, 4.0 * h0
    status = "max_points"

    def result(status: str, message: str, success: bool = True) -> PathResult:
        eig_rel = np.array([pt.relative for pt in points])
        neg = np.array([pt.negative for pt in points], dtype=int)
        stable = np.array([pt.negative == 0 and pt.eig.size > 0 and pt.eig[0] > pt.band for pt in points])
        return PathResult(
            load_factors=np.array([pt.s for pt in points]), q=np.array([sp.q(pt.u) for pt in points]),
            lam=np.array([pt.lam for pt in points]).reshape(len(points), -1), arc_length=np.array(arcs),
            min_eigenvalue=eig_rel, negative=neg, stable=stable, critical=tuple(critical), success=success,
            status=status, message=message, iterations=start.iterations + tr.iterations,
            dof_names=model.dof_names)

    while len(points) < max_points:
        z1 = tr.correct(z, tau, h)
        if z1 is None:
            h *= 0.5
            if h < 1e-8 * h0:
                partial = result("failed", "stopped: the corrector did not converge", success=False)
                raise StaticsError(
                    f"path following stopped at load factor {z.s:.6g} after {len(points)} points: the corrector did "
                    f"not converge even with the arc length cut to {h:.2e} (1e-8 of the first). Try "
                    f"{spell(names, 'arc_length', f'{h0 / 10:.3g}')} or a larger "
                    f"{spell(names, 'tol', opts.tol * 100)}.", path=partial)
            continue
        step = h
        landed = False
        if z1.s >= to_factor > z.s:  # land on to_factor exactly
            w = (to_factor - z.s) / (z1.s - z.s)
            zl = tr.correct(z, tau, h, fixed_s=to_factor, guess=(z.u + w * (z1.u - z.u), to_factor))
            if zl is not None:
                z1, step, landed = zl, w * h, True
        tau1 = tr.tangent(z1, tau)
        if tr.inner(tau, tau1) < _MIN_COS and h > 1e-3 * h0 and not landed:
            h *= 0.5  # the path turns by more than 25 degrees in one step: resolve its curvature
            continue
        if z1.negative != z.negative:
            zc = tr.locate(z, tau, step, z1)
            kind = "limit" if (tau[n] > 0) != (tau1[n] > 0) else "bifurcation"
            k = min(z.negative, z1.negative)
            ev = float(zc.eig[k] / max(np.max(np.abs(zc.eig)), 1e-300))
            critical.append(CriticalPoint(kind, zc.s, sp.q(zc.u), zc.lam, ev, len(points) - 1))
        points.append(z1)
        arcs.append(arcs[-1] + step)
        z, tau = z1, tau1
        if landed:
            status = "reached"
            break
        if z1.iterations <= 3:
            h = min(1.5 * h, h_max)
        elif z1.iterations >= 7:
            h *= 0.6
    crit = ", ".join(f"{c.kind} point at load factor {c.load_factor:.6g}" for c in critical) or "no critical point"
    end = (f"reached load factor {to_factor:g}" if status == "reached"
           else f"stopped after {max_points} points at load factor {z.s:.6g} before reaching {to_factor:g}")
    return result(status, f"{len(points)} points; {end}; {crit}")
