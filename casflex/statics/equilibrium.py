"""Static equilibrium under the full load, by adaptive load stepping over the solvers of
:mod:`casflex.statics.solve`.

The load factor s scales the nodal loads and gravity together. The first increment is
1/``steps`` of the load (the whole load by default). An increment that does not converge within
``max_iter`` iterations is halved and retried from the last equilibrium; one that converged in
at most 6 iterations doubles the next. Below ``min_increment`` the solve gives up with a message
that says what to try, in the caller's terms (``names``: the command line passes its option names).
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from casflex.model import Model
from casflex.statics.problem import (
    Scaled,
    Stability,
    StabilityWarning,
    StaticOptions,
    StaticsError,
    problem_for,
    resolve_options,
    spell,
    stability_of,
)
from casflex.statics.solve import RADIUS0, Outcome, solve_at

__all__ = ["StaticResult", "UnstableEquilibrium", "equilibrium"]

#: An increment that converged in at most this many iterations doubles the next one.
_EASY = 6


@dataclass(frozen=True)
class UnstableEquilibrium:
    """An unstable equilibrium that the minimisation reached and left along its unstable mode.

    Attributes
    ----------
    load_factor : float
        Load factor at which it was found.
    min_eigenvalue : float
        Smallest eigenvalue of its reduced tangent relative to the largest (< 0).
    q : ndarray, shape (n_dof,)
        The configuration (m, rad).
    """

    load_factor: float
    min_eigenvalue: float
    q: np.ndarray


@dataclass(frozen=True)
class StaticResult:
    """A static equilibrium.

    Attributes
    ----------
    q : ndarray, shape (n_dof,)
        Equilibrium configuration (m for translations, rad for rotations).
    lam : ndarray, shape (n_con,)
        Constraint multipliers (N or N m); the reaction a support exerts is ``-lam``.
    success : bool
        True (a failure raises :class:`StaticsError` instead).
    message : str
        A one-line summary: iterations, increments, final residual and stability.
    iterations : int
        Newton (trust-region) iterations over all load increments, failed ones included.
    load_factors : tuple of float
        The load factors of the converged increments, ending with 1.0.
    stability : Stability
        The stability of the equilibrium (smallest reduced tangent eigenvalue, critical mode).
    left : tuple of UnstableEquilibrium
        Unstable equilibria that the minimisation reached and left on its way (``seek =
        "stable"``): e.g. the straight column past its buckling load.
    cuts : int
        Load increments that failed and were halved.
    """

    q: np.ndarray
    lam: np.ndarray
    success: bool
    message: str
    iterations: int
    load_factors: tuple[float, ...]
    stability: Stability
    left: tuple[UnstableEquilibrium, ...] = ()
    cuts: int = 0

    @property
    def stable(self) -> bool:
        """True when the reduced tangent is positive definite (see :class:`Stability`)."""
        return self.stability.stable


def _start(model: Model, q_start) -> np.ndarray:
    q = np.array(model.q0 if q_start is None else q_start, dtype=float).reshape(-1)
    if q.shape != (model.n_dof,):
        raise ValueError(f"q_start: expected shape ({model.n_dof},), got {q.shape}")
    if not np.all(np.isfinite(q)):
        raise ValueError("q_start: must be finite")
    return q


def _failure(out: Outcome, s_try: float, s_done: float, inc: float, cuts: int, total: int,
             opts: StaticOptions, names: Mapping[str, str] | None, sp: Scaled, u_done: np.ndarray) -> StaticsError:
    drift = float(np.linalg.norm(out.u - u_done)) / sp.rms
    if drift > 3.0:
        dofs = sp.moving(out.u - u_done)
        drifted = (f" The iterate drifted {drift:.3g} structure lengths or rad (root mean square per node) from the "
                   f"last equilibrium, mostly in {dofs[:6]}: the structure may be a mechanism that this load drives "
                   "on without end (check the supports).")
    else:
        drifted = ""
    why = {"max_iter": f"no convergence in {opts.max_iter} iteration(s)"}.get(out.reason, out.reason)
    singular = (f" The tangent was (nearly) singular in {out.singular} iteration(s): the structure may be a "
                "mechanism or unsupported (check the supports).") if out.singular else ""
    more = [spell(names, "max_iter", 4 * opts.max_iter)]
    if opts.min_increment > 1e-6:
        more.append(spell(names, "min_increment", opts.min_increment / 100))
    if opts.seek == "nearest":
        more.append(spell(names, "seek", "stable"))
    return StaticsError(
        f"static equilibrium not reached: the last attempt, from load factor {s_done:.4g} to {s_try:.4g}, failed "
        f"({why}; scaled residual {out.residual:.3e}, tol {out.tol:.1e}; last scaled update {out.update:.3e}), "
        f"and the next load increment, {inc:.3g}, would be below "
        f"{spell(names, 'min_increment', opts.min_increment)} (the increment was cut {cuts} times, {total} "
        f"iterations in all).{singular}{drifted} Try {', '.join(more)}, or start from a configuration nearer the "
        "equilibrium.")


def _jointed(model: Model, prob, p, t: float, q_start, opts: StaticOptions, names) -> StaticResult:
    """:func:`equilibrium` of a model with ideal joints (:mod:`casflex.statics.jointed`)."""
    from casflex.statics.jointed import solve_jointed

    if not prob.conservative:
        raise StaticsError("follower loads and ideal joints together are not solved by the statics")
    pv = model.p_nominal.copy() if p is None else model.params(p)
    sp = Scaled(prob, pv, t, _start(model, q_start))
    q, lam, total, factors, cuts, stab, left = solve_jointed(model, sp, opts)
    unstable = tuple(UnstableEquilibrium(f, ev, qq) for f, ev, qq in left)
    msg = (f"converged: {total} Newton iterations on the joints' Lagrangian over {len(factors)} load increment(s)"
           f"{f' ({cuts} cut)' if cuts else ''}; {stab.describe()}")
    if unstable:
        msg += "; left an unstable equilibrium along its unstable mode"
    if stab.assessed and not stab.stable:
        warnings.warn(f"the static equilibrium is {stab.describe()}"
                      + (f"; {spell(names, 'seek', 'stable')} looks for a stable one" if opts.seek == "nearest"
                         else ""), StabilityWarning, stacklevel=3)
    return StaticResult(q=q, lam=lam, success=True, message=msg, iterations=total, load_factors=factors,
                        stability=stab, left=unstable, cuts=cuts)


def equilibrium(
    model: Model,
    *,
    p: np.ndarray | dict[str, float] | None = None,
    t: float = 0.0,
    q_start: np.ndarray | None = None,
    options: StaticOptions | None = None,
    names: Mapping[str, str] | None = None,
    **settings,
) -> StaticResult:
    """Static equilibrium under the loads at time ``t`` and gravity, by adaptive load stepping.

    Parameters
    ----------
    model : Model
        From :func:`casflex.assemble`.
    p : array (n_p,) or dict, optional
        Parameter values; default ``model.p_nominal``.
    t : float
        Time (s) at which tabulated loads are evaluated.
    q_start : array (n_dof,), optional
        Starting configuration (m, rad); default ``model.q0``. The fixed dofs are set to their
        supports' values.
    options : StaticOptions, optional
        The solver settings; default :class:`StaticOptions` ().
    names : mapping of str to str, optional
        How the caller names the options, for the hints in error messages (e.g. ``{"max_iter":
        "--max-iter"}``); default the Python names.
    **settings
        Fields of :class:`StaticOptions` overriding ``options``: ``steps``, ``tol``, ``max_iter``,
        ``min_increment``, ``seek``.

    Returns
    -------
    StaticResult
        With ``seek = "stable"`` (default) a stable equilibrium (or a neutral one); with ``seek =
        "nearest"`` the nearest, which may be unstable. A result that is not stable also warns
        (:class:`StabilityWarning`).

    Raises
    ------
    StaticsError
        If the load increment falls below ``min_increment`` without convergence, if the loads
        have a net component along a direction no support fixes (no equilibrium exists), or if
        the model breaks an assumption of statics (constraints other than fixed dofs, loads
        that depend on q).
    """
    opts = resolve_options(options, settings)
    prob = problem_for(model)
    if model.joint_row_names:
        return _jointed(model, prob, p, t, q_start, opts, names)
    if not prob.conservative and opts.seek == "stable":
        raise StaticsError(f"the scene has follower loads: they have no potential to minimise; solve with "
                           f"{spell(names, 'seek', 'nearest')} (Newton on the residual)")
    pv = model.p_nominal.copy() if p is None else model.params(p)
    sp = Scaled(prob, pv, t, _start(model, q_start))
    sp.check_supported()
    u = sp.u(sp.base)

    s_done, inc, cuts, total = 0.0, 1.0 / opts.steps, 0, 0
    factors: list[float] = []
    left = []
    radius = RADIUS0
    last = None
    while s_done < 1.0:
        s_try = 1.0 if s_done + inc >= 1.0 - 1e-12 else s_done + inc
        out = solve_at(sp, u, s_try, opts, radius)
        total += out.iterations
        if out.converged:
            u, s_done, last = out.u, s_try, out
            factors.append(s_try)
            left += out.left
            radius = out.radius
            if out.iterations <= _EASY:
                inc *= 2.0
            continue
        if inc / 2.0 < opts.min_increment:
            raise _failure(out, s_try, s_done, inc / 2.0, cuts + 1, total, opts, names, sp, u)
        inc /= 2.0
        cuts += 1
        radius = RADIUS0

    q = sp.q(u)
    stab, _ = stability_of(sp, sp.hessian(u, 1.0))
    _, _, g = sp.gradient(u, 1.0)
    res = sp.residual(g)
    unstable = tuple(UnstableEquilibrium(f, ev, qq) for f, ev, qq in left)
    msg = (f"converged: {total} iterations over {len(factors)} load increment(s)"
           f"{f' ({cuts} cut)' if cuts else ''}; scaled residual {res:.1e} (tol {opts.tol:.0e}); {stab.describe()}")
    if unstable:
        msg += (f"; left {len(unstable)} unstable equilibri{'a' if len(unstable) > 1 else 'um'} on the way "
                f"(first at load factor {unstable[0].load_factor:.4g})")
    if stab.assessed and not stab.stable:
        warnings.warn(f"the static equilibrium is {stab.describe()}"
                      + (f"; {spell(names, 'seek', 'stable')} looks for a stable one" if opts.seek == "nearest"
                         else ""), StabilityWarning, stacklevel=2)
    lam = sp.reactions(last.previous, 1.0, u - last.previous)
    return StaticResult(q=q, lam=lam, success=True, message=msg, iterations=total,
                        load_factors=tuple(factors), stability=stab, left=unstable, cuts=cuts)
