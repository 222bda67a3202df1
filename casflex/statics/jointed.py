"""Static equilibrium of a model with ideal joints: Newton on the stationarity of the Lagrangian.

With the joints' constraints Phi_J(q) = 0 (:mod:`casflex.elements.joints`) an equilibrium is a
stationary point of L = Pi(q) + mu^T Phi_J(q) over the free dofs and the joints' multipliers mu:

    F(u, mu) = [ dPi/du + B^T mu ;  Phi_J / l ] = 0,     u = q_free / l (scaled as the statics are),

solved by Newton on the saddle-point matrix [[H + d2(mu^T Phi)/du2, B^T], [B / l, 0]] with a
backtracking line search on |F|, over the same adaptive load steps as :func:`~casflex.statics.equilibrium`.
Where Newton does not converge (a mechanism whose only stiffness is the load's, e.g. a pendulum
started level) the potential is first descended on the joints' manifold (:func:`_descend`).
The force rows are measured relative to the largest force in them: the statics' scaling by the
tangent's diagonal says nothing of dofs that only the joints hold (a rigid link's translations).
Stability is that of the reduced tangent N^T (H + d2(mu^T Phi)/du2) N on the motions N that keep
the joints closed (the null space of B). With ``seek = "stable"`` an unstable equilibrium is left
along its unstable mode (both ways, a tenth of a structure length or radian) and the stable one
found from there is returned, the unstable one listed in ``left``.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from casflex.model import Model
from casflex.model.consistent import project_positions
from casflex.statics.problem import Scaled, Stability, StaticOptions, StaticsError, neutral_band

__all__ = ["solve_jointed"]

#: A try along an unstable mode: this far in structure lengths or rad.
LEAVE = 0.1


class _Lagrangian:
    """The joints' rows at a scaled state: Phi / l, B (scaled columns), d2(mu^T Phi)/du2 (scaled)."""

    def __init__(self, model: Model, sp: Scaled):
        self.model, self.sp, self.f = model, sp, model.joint_rows

    def __call__(self, u: np.ndarray, mu: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        sp, ell = self.sp, self.sp.ell
        phi, B, H = (np.array(v) for v in self.f(sp.q(u), mu))
        return phi.ravel() / self.model.length_scale, B[:, sp.free] * ell, H[np.ix_(sp.free, sp.free)] * np.outer(
            ell, ell)


def _residual(sp: Scaled, rows: _Lagrangian, u: np.ndarray, mu: np.ndarray, s: float, scale: float):
    """(F with the force rows divided by ``scale``, the force rows' and the joints' largest entries, B, the
    joints' Hessian term)."""
    _, _, g = sp.gradient(u, s)
    phi, B, Hphi = rows(u, mu)
    force = (g + B.T @ mu) / scale
    return np.concatenate([force, phi]), float(np.abs(force).max(initial=0.0)), float(np.abs(phi).max(initial=0.0)), \
        B, Hphi


def _newton(sp: Scaled, rows: _Lagrangian, u: np.ndarray, mu: np.ndarray, s: float, opts: StaticOptions):
    """(converged, u, mu, iterations) at load factor s. The force rows are relative to the larger of
    the loads (gravity included) and the start's forces, fixed for the solve so that the line search's
    measure |F| does not change with the iterate."""
    _, _, g0 = sp.gradient(u, s)
    scale = max(s * np.abs(sp.load(u)).max(initial=0.0), np.abs(g0).max(initial=0.0), 1e-300)
    F, rf, rp, B, Hphi = _residual(sp, rows, u, mu, s, scale)
    nu, nm = u.size, mu.size
    for it in range(1, opts.max_iter + 1):
        if rf <= opts.tol and rp <= opts.tol:
            return True, u, mu, it - 1
        K = np.block([[(sp.hessian(u, s) + Hphi) / scale, B.T / scale], [B, np.zeros((nm, nm))]])
        try:
            step = np.linalg.solve(K, -F)
        except np.linalg.LinAlgError:
            step = np.linalg.lstsq(K, -F, rcond=None)[0]
        for t in (1.0, 0.5, 0.25, 0.125, 0.0625, 1.0):  # backtracking on |F|; the full step if none is better
            cand = _residual(sp, rows, u + t * step[:nu], mu + t * step[nu:], s, scale)
            if np.linalg.norm(cand[0]) < np.linalg.norm(F):
                break
        u, mu = u + t * step[:nu], mu + t * step[nu:]
        F, rf, rp, B, Hphi = cand
    return bool(rf <= opts.tol and rp <= opts.tol), u, mu, opts.max_iter


def _descend(model: Model, sp: Scaled, rows: _Lagrangian, u: np.ndarray, mu: np.ndarray, opts: StaticOptions,
             s: float = 1.0) -> tuple[np.ndarray, int]:
    """Down the potential on the joints' manifold from u, until its reduced tangent is positive definite
    and Newton's step from there is short (Newton then takes the last steps): Newton steps in the
    joints' null space N, shifted where the tangent is not positive, at most LEAVE long, each
    followed by closing the joints again. (u, iterations)."""
    for it in range(1, opts.max_iter + 1):
        _, _, g = sp.gradient(u, s)
        _, B, Hphi = rows(u, mu)
        mu = np.linalg.lstsq(B.T, -g, rcond=None)[0]  # the multipliers that balance what they can
        _, B, Hphi = rows(u, mu)
        N = scipy.linalg.null_space(B)
        Hr, r = N.T @ (sp.hessian(u, s) + Hphi) @ N, N.T @ g
        lam = np.linalg.eigvalsh(Hr) if Hr.size else np.zeros(1)
        shift = 0.0 if lam[0] > neutral_band(lam) else -lam[0] + 1e-3 * np.abs(lam).max() + 1e-300
        z = -np.linalg.solve(Hr + shift * np.eye(Hr.shape[0]), r)
        if shift == 0.0 and np.abs(z).max() <= LEAVE:  # convex here and the minimum near: Newton's basin
            return u, it
        z *= min(1.0, LEAVE / max(np.abs(z).max(), 1e-300))
        u = sp.u(project_positions(model, sp.q(u + N @ z), what="q", report=False))
    return u, opts.max_iter


def _stability(sp: Scaled, rows: _Lagrangian, u: np.ndarray, mu: np.ndarray) -> Stability:
    """Of the reduced tangent on the motions that keep the joints closed (scaled, as the statics')."""
    _, B, Hphi = rows(u, mu)
    N = scipy.linalg.null_space(B)
    if N.shape[1] == 0:
        return Stability(np.inf, 0.0, 0, 0.0, np.zeros(sp.problem.n_dof))
    lam, V = scipy.linalg.eigh(N.T @ (sp.hessian(u, 1.0) + Hphi) @ N)
    scale, band = float(np.max(np.abs(lam))), neutral_band(lam)
    v = N @ V[:, 0]
    v = v / np.max(np.abs(v))
    mode = np.zeros(sp.problem.n_dof)
    mode[sp.free] = (v if v[np.argmax(np.abs(v))] > 0 else -v) * sp.ell
    rel = float(lam[0] / scale) if scale > 0 else 0.0
    return Stability(rel, band / scale if scale > 0 else 0.0, int(np.sum(lam < -band)), scale, mode)


def solve_jointed(model: Model, sp: Scaled, opts: StaticOptions):
    """(q, lam, iterations, load factors, cuts, stability, left) of a model with joints (module docstring);
    StaticsError when the load increment falls below ``opts.min_increment``."""
    rows = _Lagrangian(model, sp)
    u = sp.u(project_positions(model, sp.base, what="q_start"))
    mu = np.zeros(len(model.joint_row_names))
    s_done, inc, cuts, total, factors = 0.0, 1.0 / opts.steps, 0, 0, []
    while s_done < 1.0:
        s_try = 1.0 if s_done + inc >= 1.0 - 1e-12 else s_done + inc
        ok, u_new, mu_new, its = _newton(sp, rows, u, mu, s_try, opts)
        total += its
        if not ok:  # no Newton basin here (a mechanism whose only stiffness is the load's): go down first
            u_d, its = _descend(model, sp, rows, u, mu, opts, s_try)
            ok, u_new, mu_new, more = _newton(sp, rows, u_d, mu, s_try, opts)
            total += its + more
        if ok:
            u, mu, s_done = u_new, mu_new, s_try
            factors.append(s_try)
            inc *= 2.0 if its <= 6 else 1.0
            continue
        if inc / 2.0 < opts.min_increment:
            raise StaticsError(f"no static equilibrium found with the joints: Newton did not converge at load factor "
                               f"{s_try:.4g} ({total} iterations; the increment fell below min_increment "
                               f"{opts.min_increment:g}); try more steps, or check that the joints and supports hold "
                               "every rigid motion")
        inc, cuts = inc / 2.0, cuts + 1
    stab, left = _stability(sp, rows, u, mu), []
    if opts.seek == "stable" and stab.kind == "unstable":
        for sign in (1.0, -1.0):  # leave it along its unstable mode, as the minimisation does
            away = sp.u(project_positions(model, sp.q(u + sign * LEAVE * stab.mode[sp.free] / sp.ell), what="q",
                                          report=False))
            u2, its = _descend(model, sp, rows, away, mu, opts)
            ok, u2, mu2, more = _newton(sp, rows, u2, mu, 1.0, opts)
            total += its + more
            if ok and (st2 := _stability(sp, rows, u2, mu2)).kind != "unstable":
                left.append((1.0, stab.min_eigenvalue, sp.q(u)))
                u, mu, stab = u2, mu2, st2
                break
    return sp.q(u), _multipliers(model, sp, sp.q(u), mu, 1.0), total, tuple(factors), cuts, stab, left


def _multipliers(model: Model, sp: Scaled, q: np.ndarray, mu: np.ndarray, s: float) -> np.ndarray:
    """(the supports' multipliers, the joints' mu) at q: the fixed rows balanced, -(dPi/dq + B^T mu) (N, N m)."""
    _, grad, _, _ = sp.problem.evaluate(q, s, sp.t, sp.p)
    B = np.array(model.joint_rows(q, mu)[1])
    return np.concatenate([-(grad + B.T @ mu)[sp.problem.fixed], mu])


class JointedPath:
    """A model with ideal joints presented to the path tracer (:mod:`casflex.statics.path`) as
    :class:`~casflex.statics.problem.Scaled` presents one without: unknowns x = (u, nu), the joints'
    multipliers mu = (f / l) nu with f the loads' scale (J per scaled unit), so that the bordered
    Jacobian [[H + d2(mu^T Phi)/du2, (f / l) B^T], [(f / l) B, 0]] is symmetric and its rows alike; the
    "gradient" is F = (dPi/du + B^T mu, (f / l) Phi); stability from the reduced tangent on the joints'
    null space (:meth:`tangent_eigenvalues`)."""

    def __init__(self, model: Model, sp: Scaled):
        self.model, self.sp, self.rows = model, sp, _Lagrangian(model, sp)
        self.nu, self.nm = sp.n, len(model.joint_row_names)
        self.n = self.nu + self.nm
        self.base = sp.base
        self.f = max(float(np.abs(sp.load(sp.u(sp.base))).max(initial=0.0)), 1e-300)

    def _split(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return x[:self.nu], x[self.nu:] * self.f

    def q(self, x: np.ndarray) -> np.ndarray:
        return self.sp.q(x[:self.nu])

    def u(self, q: np.ndarray) -> np.ndarray:
        return np.concatenate([self.sp.u(q), np.zeros(self.nm)])

    def gradient(self, x: np.ndarray, s: float) -> tuple[float, float, np.ndarray]:
        u, mu = self._split(x)
        pi, err, g = self.sp.gradient(u, s)
        phi, B, _ = self.rows(u, mu)
        return pi, err, np.concatenate([g + B.T @ mu, self.f * phi])

    def hessian(self, x: np.ndarray, s: float) -> np.ndarray:
        u, mu = self._split(x)
        _, B, Hphi = self.rows(u, mu)
        return np.block([[self.sp.hessian(u, s) + Hphi, self.f * B.T], [self.f * B, np.zeros((self.nm, self.nm))]])

    def tangent_eigenvalues(self, x: np.ndarray, s: float) -> np.ndarray:
        u, mu = self._split(x)
        _, B, Hphi = self.rows(u, mu)
        N = scipy.linalg.null_space(B)
        return scipy.linalg.eigvalsh(N.T @ (self.sp.hessian(u, s) + Hphi) @ N) if N.size else np.zeros(0)

    def load(self, x: np.ndarray) -> np.ndarray:
        return np.concatenate([self.sp.load(x[:self.nu]), np.zeros(self.nm)])

    def residual(self, F: np.ndarray) -> float:
        """The largest entry of F relative to the loads' scale (the rows of rigid links' translations have no
        stiffness of their own to scale them by)."""
        return float(np.abs(F).max(initial=0.0) / self.f)

    def tol(self, tol: float, x: np.ndarray) -> float:
        return self.sp.tol(tol, x[:self.nu])

    def turn(self, x: np.ndarray, y: np.ndarray) -> float:
        return self.sp.turn(x[:self.nu], y[:self.nu])

    def reactions(self, x: np.ndarray, s: float, dx: np.ndarray | None = None) -> np.ndarray:
        """(the supports' multipliers, the joints') at x + dx (N, N m)."""
        u, mu = self._split(x if dx is None else x + dx)
        return _multipliers(self.model, self.sp, self.sp.q(u), mu, s)

    def start(self, opts: StaticOptions):
        """The unloaded equilibrium the path starts from: (converged, x, iterations)."""
        u0 = self.sp.u(project_positions(self.model, self.sp.base, what="q_start"))
        ok, u, mu, its = _newton(self.sp, self.rows, u0, np.zeros(self.nm), 0.0, opts)
        return ok, np.concatenate([u, mu / self.f]), its
