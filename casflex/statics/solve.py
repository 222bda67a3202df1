"""Equilibrium at one load factor: trust-region minimisation of the total potential (``seek =
"stable"``) or Newton's method on its gradient (``seek = "nearest"``), in the scaled free dofs
of :class:`~casflex.statics.problem.Scaled`.

Trust region (Conn, Gould & Toint 2000, ch. 6-7). Each iteration takes the eigen-decomposition
H = V diag(lambda) V^T of the scaled reduced tangent (``scipy.linalg.eigh``) and solves the
subproblem min g.y + y.H.y/2, |y| <= radius exactly: y = -(H + mu I)^-1 g with mu >= max(0,
-lambda_1) from the secular equation |y(mu)| = radius, or, in the hard case (g orthogonal to the
lowest eigenvector), the step along that eigenvector which fills the region. Negative curvature
is thereby followed, and a stationary point that is not a minimum (a saddle: the straight
column past its buckling load, an inverted pendulum) is left along its unstable mode: such a
point is recorded (``left``) before it is left. The step is accepted when Pi decreases by at least
1e-3 of the decrease the quadratic model predicts.

Second-order correction. A stiff structure that swings as a mechanism (steel bars on a pin) has
a narrow curved valley: a straight step along the swing stretches the bars to second order,
and that stretch energy (EA/L (L phi^2 / 2)^2) rejects any step larger than milliradians.
When a step is poor, up to three corrections re-solve the same subproblem at the trial point,
(H(u_t) + mu I) c = -(g(u_t) + mu (u_t - u)): Newton on the proximal problem
min Pi(v) + mu/2 |v - u|^2 whose first iterate the trust-region step was. The stiff directions
relax (the bars return to length) while mu keeps the soft ones where the step put them, and
the acceptance test then sees the energy of the swing, not the stretch (the Maratos effect of
constrained optimisation, here with stiff elements as the constraints).

Safeguards: a trial that turns an element end by more than 90 degrees relative to its chord is
rejected (the co-rotational local rotation is an angle mod 2 pi).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from casflex.statics.problem import Scaled, StaticOptions, neutral_band

#: Initial and largest trust radius: root-mean-square motion per node (structure lengths, rad).
RADIUS0 = 0.1
RADIUS_MAX = 1.0
#: A step is accepted when Pi decreases by this share of the model's prediction.
_ACCEPT = 1e-3
#: Second-order corrections tried on a poor step.
_CORRECTIONS = 3
#: Largest change of an element's local end rotation in one step (rad).
_MAX_TURN = 0.5 * math.pi
#: A Newton update larger than this (structure lengths or rad) means a singular tangent (nearest).
_STEP_LIMIT = 1e3
#: Relative singular-value cutoff of the minimum-norm Newton update taken then.
_RCOND = 1e-12


@dataclass
class Outcome:
    """What a solve at one load factor ended with (internal)."""

    u: np.ndarray
    converged: bool
    iterations: int
    residual: float
    tol: float
    update: float
    radius: float
    reason: str = ""
    left: list[tuple[float, float, np.ndarray]] = field(default_factory=list)
    singular: int = 0
    previous: np.ndarray | None = None  # the iterate before the final (applied) Newton update


def trust_step(lam: np.ndarray, gam: np.ndarray, radius: float, band: float) -> tuple[np.ndarray, float]:
    """Exact trust-region step in the eigenbasis: y minimising gam.y + sum(lam y^2)/2, |y| <= radius.

    lam (ascending) and gam = V^T g have shape (n,); ``band`` is the round-off of the eigenvalues.
    Returns y (n,) and the multiplier mu >= 0 (0 for an interior Newton step).
    """
    l1 = lam[0]
    if l1 > band:
        y = -gam / lam
        if np.linalg.norm(y) <= radius:
            return y, 0.0
    shift = max(0.0, -l1)
    den = (lam - l1) if l1 < 0.0 else lam.copy()  # lam + shift, exactly 0 for the lowest when l1 < 0
    low = den <= band
    y0 = np.zeros_like(gam)
    y0[~low] = -gam[~low] / den[~low]
    n0 = float(np.linalg.norm(y0))
    g_low = float(np.linalg.norm(gam[low]))
    if n0 <= radius and (g_low == 0.0 or g_low <= 1e-300):
        if l1 >= -band:  # neutral, nothing to gain along it: the Newton step on the rest
            return y0, shift
        y0[0] = math.sqrt(max(radius**2 - n0**2, 0.0)) * (-1.0 if gam[0] > 0 else 1.0)  # hard case
        return y0, shift

    def norm(theta: float) -> float:
        return float(np.linalg.norm(gam / (den + theta)))

    # |y(theta)| = radius, theta = mu - shift in (0, |g| / radius]: Newton on 1/|y| - 1/radius,
    # which is concave and increasing in theta, safeguarded by bisection.
    lo, hi = 0.0, float(np.linalg.norm(gam)) / radius
    theta = hi
    for _ in range(200):
        d = den + theta
        y = gam / d
        ny = float(np.linalg.norm(y))
        if abs(ny - radius) <= 1e-12 * radius:
            break
        if ny > radius:
            lo = theta
        else:
            hi = theta
        dny = -float(np.sum(y**2 / d)) / ny  # d|y|/dtheta
        new = theta + (1.0 / ny - 1.0 / radius) * ny**2 / dny
        theta = new if lo < new < hi else 0.5 * (lo + hi)
        if hi - lo <= 1e-15 * hi:
            break
    y = -gam / (den + theta)
    return y, shift + theta


def _reduction(pi: float, pi_t: float, noise: float, g: np.ndarray, g_t: np.ndarray, du: np.ndarray) -> float:
    """Pi(u) - Pi(u + du); from the trapezoidal rule on the gradients when the difference of the
    values is lost in their round-off (near convergence, or far from the origin)."""
    d = pi - pi_t
    if abs(d) <= 10.0 * noise:
        d = -0.5 * float((g + g_t) @ du)
    return d


def minimise(sp: Scaled, u: np.ndarray, s: float, opts: StaticOptions, radius: float = RADIUS0) -> Outcome:
    """Trust-region minimisation of Pi at load factor s from u (scaled free dofs, shape (n,))."""
    step_tol = 1e-2 * math.sqrt(opts.tol)
    pi, noise, g = sp.gradient(u, s)
    out = Outcome(u, False, 0, math.inf, opts.tol, math.inf, radius)
    if not (math.isfinite(pi) and np.all(np.isfinite(g))):
        out.reason = "the potential is not finite at the start"
        return out
    recorded = None  # the iterate last recorded as a stationary unstable point
    while out.iterations < opts.max_iter:
        out.iterations += 1
        if sp.n == 0:
            out.converged, out.residual, out.update, out.previous = True, 0.0, 0.0, u
            return out
        lam, V = scipy.linalg.eigh(sp.hessian(u, s), check_finite=False)
        if not np.all(np.isfinite(lam)):
            out.reason = "the tangent is not finite"
            return out
        band = neutral_band(lam)
        gam = V.T @ g
        inv = np.where(np.abs(lam) > band, 1.0 / np.where(lam == 0.0, 1.0, lam), 0.0)
        newton = -(V @ (gam * inv))
        out.residual, out.tol = sp.residual(g), sp.tol(opts.tol, u)
        out.update = float(np.max(np.abs(newton)))
        if out.residual <= out.tol and out.update <= step_tol:
            if lam[0] >= -band:
                out.u, out.previous, out.converged = u + newton, u, True
                return out
            if recorded is not u:
                out.left.append((s, float(lam[0] / np.max(np.abs(lam))), sp.q(u)))
                recorded = u
        bound = out.radius * sp.rms
        y, mu = trust_step(lam, gam, bound, band)
        pred = -float(gam @ y + 0.5 * np.sum(lam * y**2))
        step = V @ y
        norm = float(np.linalg.norm(step))
        if pred <= 0.0 or norm == 0.0:  # nothing left to gain: stationary to round-off
            if out.residual <= out.tol:
                out.u, out.previous, out.converged = u + newton, u, True
            else:
                out.reason = "no descent step (the residual is at its round-off floor: raise tol)"
            return out
        rho, u_t, pi_t, noise_t, g_t = -math.inf, None, math.nan, 0.0, None
        if sp.turn(u, u + step) <= _MAX_TURN:
            u_t = u + step
            pi_t, noise_t, g_t = sp.gradient(u_t, s)
            if math.isfinite(pi_t) and np.all(np.isfinite(g_t)):
                rho = _reduction(pi, pi_t, noise + noise_t, g, g_t, u_t - u) / pred
            else:
                u_t = None
        if u_t is not None and rho < 0.25:
            # Second-order correction: Newton on the proximal problem at the trial point.
            for _ in range(_CORRECTIONS):
                A = sp.hessian(u_t, s) + mu * np.eye(sp.n)
                try:
                    c = np.linalg.solve(A, -(g_t + mu * (u_t - u)))
                except np.linalg.LinAlgError:
                    break
                u_c = u_t + c
                if not np.all(np.isfinite(c)) or np.linalg.norm(u_c - u) > 2.0 * bound \
                        or sp.turn(u, u_c) > _MAX_TURN:
                    break
                pi_c, noise_c, g_c = sp.gradient(u_c, s)
                if not (math.isfinite(pi_c) and np.all(np.isfinite(g_c))):
                    break
                u_t, pi_t, noise_t, g_t = u_c, pi_c, noise_c, g_c
                rho = _reduction(pi, pi_t, noise + noise_t, g, g_t, u_t - u) / pred
                if rho >= 0.25 or np.linalg.norm(c) <= 1e-3 * norm:
                    break
        if rho < 0.25:
            out.radius = 0.25 * norm / sp.rms
        elif rho > 0.75 and norm >= 0.99 * bound:
            out.radius = min(2.0 * out.radius, RADIUS_MAX)
        if u_t is None or rho < _ACCEPT:
            if out.radius * sp.rms <= 1e-14 * max(1.0, float(np.linalg.norm(u))):
                out.reason = "the trust region collapsed"
                return out
            continue
        u, pi, noise, g = u_t, pi_t, noise_t, g_t
    out.u = u
    out.reason = out.reason or "max_iter"
    return out


def newton(sp: Scaled, u: np.ndarray, s: float, opts: StaticOptions) -> Outcome:
    """Newton's method on the scaled gradient at load factor s from u: the nearest stationary point.

    A (nearly) singular tangent (an update above 1000 structure lengths, an unstressed mechanism)
    gives the minimum-norm least-squares update, which leaves the mechanism motion alone."""
    step_tol = 1e-2 * math.sqrt(opts.tol)
    out = Outcome(u, False, 0, math.inf, opts.tol, math.inf, 0.0)
    while out.iterations < opts.max_iter:
        out.iterations += 1
        _, _, g = sp.gradient(u, s)
        out.residual, out.tol = sp.residual(g), sp.tol(opts.tol, u)
        if not math.isfinite(out.residual):
            out.reason = "the residual is not finite (the iterate diverged)"
            return out
        if sp.n == 0:
            out.converged, out.update, out.previous = True, 0.0, u
            return out
        H = sp.hessian(u, s)
        try:
            du = np.linalg.solve(H, -g)
        except np.linalg.LinAlgError:
            du = np.full_like(g, np.inf)
        if not np.all(np.isfinite(du)) or np.max(np.abs(du)) > _STEP_LIMIT:
            out.singular += 1
            du = np.linalg.lstsq(H, -g, rcond=_RCOND)[0]
        out.update = float(np.max(np.abs(du)))
        out.previous, u = u, u + du
        out.u = u
        if out.residual <= out.tol and out.update <= step_tol:
            out.converged = True
            return out
    out.reason = "max_iter"
    return out


def solve_at(sp: Scaled, u: np.ndarray, s: float, opts: StaticOptions, radius: float = RADIUS0) -> Outcome:
    """Equilibrium at load factor s from u, by the method ``opts.seek`` asks for."""
    return minimise(sp, u, s, opts, radius) if opts.seek == "stable" else newton(sp, u, s, opts)
