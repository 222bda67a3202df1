"""Static equilibrium and linearised vibration modes of an assembled model.

Statics solves, for the configuration q (n_dof,) and the support multipliers lambda (n_con,),

    f_int(q, p) + B(q)^T lambda - s (f_ext(t, p) + g(q, p)) = 0,        Phi(q) = 0,

by Newton's method with the exact tangent from CasADi's automatic differentiation, raising
the load factor s in equal steps 1/steps, 2/steps, ..., 1. Both the nodal loads and the
gravity (field) forces are scaled by s. The support reaction on a constrained dof is
``-lambda`` (see :mod:`casflex.constraints`).

Modes linearise the undamped equations of motion about a configuration q (the initial one,
or a static equilibrium):

    M(q) dq'' + K(q) dq = 0,    K = d(f_int - g)/dq  (+ d(B^T lambda)/dq),    B(q) dq = 0,

eliminate the constraints with an orthonormal null-space basis of B and solve the symmetric
generalised eigenproblem K v = omega^2 M v with numpy (Cholesky of the reduced mass matrix,
then ``eigh``). The eigenvalues are then recomputed as Rayleigh quotients of the original K
and M: ``eigh`` alone loses digits in proportion to omega_max^2 / omega^2 (7e-9 relative on the
first mode of a 64-element cantilever; the Rayleigh quotient ~1e-11). The tangent K contains
the geometric stiffness of the preload (e.g. of gravity about a hanging equilibrium), since it
is the exact derivative at q.

Scaling (statics): the force rows are divided by d_i l_i, where d_i is a rotation-invariant
diagonal of the tangent at the start (the x and y entries of a node averaged, as in
:mod:`casflex.integrators.hht`) and l_i = ``model.length_scale`` for translations, 1 rad for
rotations; the constraint rows by l_i. A scaled residual is then an equivalent displacement
relative to the size of the structure, so one dimensionless ``tol`` serves stiffnesses from
1e-3 to 1e12. The unknowns are scaled alike (q by l_i, lambda by d_i l_i). A load step has
converged when the scaled residual (infinity norm) is at most ``tol`` *and* the scaled Newton
update computed there (which is applied) is at most 0.01 sqrt(tol). The second test matters
for soft motions: the rotation of a pendulum about its pin, resisted only by the geometric
stiffness of gravity, leaves a tiny scaled residual while still far from equilibrium.

A stress-free mechanism (e.g. a pendulum started at rest away from its equilibrium) has a
singular tangent at the start. A Newton update larger than 1000 (structure lengths or rad) is
taken as that sign, and replaced by the minimum-norm least-squares update, which leaves the
mechanism motion alone; the stress it builds then supplies the missing geometric stiffness.
Newton converges to the equilibrium nearest in its basin, which may be an unstable one (an
inverted pendulum started above the horizontal); check with :func:`modes` (negative omega).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from casflex.integrators.hht import roundoff_tolerance
from casflex.model import Model

__all__ = ["StaticsError", "ModesError", "StaticResult", "ModesResult", "equilibrium", "modes"]


class StaticsError(RuntimeError):
    """The static Newton iteration failed; the message says where and what to try."""


class ModesError(ValueError):
    """The model has no well-posed modal problem (e.g. massless free dofs); the message names the dofs."""


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
        A one-line summary: iterations and the final scaled residual.
    iterations : int
        Total Newton iterations over all load steps.
    load_factors : tuple of float
        The load factors solved in turn, ending with 1.0.
    """

    q: np.ndarray
    lam: np.ndarray
    success: bool
    message: str
    iterations: int
    load_factors: tuple[float, ...]


@dataclass(frozen=True)
class ModesResult:
    """Undamped linear vibration modes about a configuration, ascending in frequency.

    Attributes
    ----------
    freq_hz : ndarray, shape (k,)
        Natural frequencies omega / (2 pi) (Hz).
    omega : ndarray, shape (k,)
        Circular frequencies (rad/s). A negative value -w flags an unstable (divergent) mode,
        K having the negative eigenvalue -w^2 in that direction; rigid-body modes give ~0.
    shapes : ndarray, shape (n_dof, k)
        Mode shapes, mass-normalised: ``shapes.T @ M @ shapes = I``; they satisfy the
        linearised constraints ``B @ shapes = 0``.
    dof_names : tuple of str, length n_dof
        Names of the rows of ``shapes``.
    """

    freq_hz: np.ndarray
    omega: np.ndarray
    shapes: np.ndarray
    dof_names: tuple[str, ...]


#: A Newton update larger than this (scaled: structure lengths or rad) means a singular tangent.
_STEP_LIMIT = 1e3
#: Relative singular-value cutoff of the minimum-norm step taken then.
_RCOND = 1e-12


def _params(model: Model, p) -> np.ndarray:
    return model.p_nominal.copy() if p is None else model.params(p)


def _dof_lengths(model: Model) -> np.ndarray:
    """l_i: model.length_scale (m) for translations, 1 (rad) for rotations, shape (n_dof,)."""
    return np.where(model.is_rotation, 1.0, model.length_scale)


def _invariant_diagonal(diag: np.ndarray) -> np.ndarray:
    """|diag| with the x and y entries of each node averaged, floored at 1e-12 of the max."""
    d = np.abs(np.asarray(diag, dtype=float)).copy()
    xy = 0.5 * (d[0::3] + d[1::3])
    d[0::3] = xy
    d[1::3] = xy
    return np.maximum(d, 1e-12 * d.max(initial=0.0) + 1e-300)


def equilibrium(
    model: Model,
    *,
    p: np.ndarray | dict[str, float] | None = None,
    t: float = 0.0,
    steps: int = 10,
    tol: float = 1e-10,
    max_iter: int = 50,
    q_start: np.ndarray | None = None,
) -> StaticResult:
    """Static equilibrium under the loads at time ``t`` and gravity, by load-stepped Newton.

    Parameters
    ----------
    model : Model
        From :func:`casflex.assemble`.
    p : array (n_p,) or dict, optional
        Parameter values; default ``model.p_nominal``.
    t : float
        Time (s) at which tabulated loads are evaluated.
    steps : int
        Number of equal load increments; the factors are 1/steps, ..., 1.
    tol : float
        Tolerance on the scaled residual (dimensionless; see the module docstring).
    max_iter : int
        Newton iterations allowed per load step.
    q_start : array (n_dof,), optional
        Starting configuration; default ``model.q0``. Multipliers start at zero.

    Returns
    -------
    StaticResult

    Raises
    ------
    StaticsError
        If a load step does not converge within ``max_iter`` iterations, the residual becomes
        non-finite or the tangent is singular (a mechanism at that configuration).
    """
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
        raise ValueError(f"steps: expected an integer >= 1, got {steps!r}")
    if isinstance(max_iter, bool) or not isinstance(max_iter, int) or max_iter < 1:
        raise ValueError(f"max_iter: expected an integer >= 1, got {max_iter!r}")
    if not tol > 0.0:
        raise ValueError(f"tol: must be > 0, got {tol!r}")
    n, nc = model.n_dof, model.n_con
    pv = _params(model, p)
    q = np.array(model.q0 if q_start is None else q_start, dtype=float).reshape(-1)
    if q.shape != (n,):
        raise ValueError(f"q_start: expected shape ({n},), got {q.shape}")
    lam = np.zeros(nc)

    # One residual/tangent Function per call: (q, lam, factor, p) -> (r, J), r = [force; Phi].
    qs, ls, fs, ps = ca.SX.sym("q", n), ca.SX.sym("lam", nc), ca.SX.sym("factor"), ca.SX.sym("p", model.n_p)
    _, f_int, g = model.forces(qs, ca.DM.zeros(n), ps)
    phi, B = model.constraint(qs)
    f_ext = model.load(float(t), ps)
    r = ca.vertcat(f_int + ca.mtimes(B.T, ls) - fs * (f_ext + g), phi)
    z = ca.vertcat(qs, ls)
    fn = ca.Function("statics_newton", [qs, ls, fs, ps], [r, ca.jacobian(r, z)],
                     ["q", "lam", "factor", "p"], ["r", "J"], {"cse": True})

    # Scaling from the tangent at the start, full load.
    ell = _dof_lengths(model)
    cdof = [c.dof for c in model.constraints]
    _, J0 = fn(q, lam, 1.0, pv)
    d = _invariant_diagonal(np.diag(np.asarray(J0)[:n, :n]))
    row = np.concatenate([d * ell, ell[cdof]])  # residual rows: force / (d l), Phi / l
    col = np.concatenate([ell, d[cdof] * ell[cdof]])  # unknowns: q in l, lam in d l

    factors = tuple((k + 1) / steps for k in range(steps))
    total = 0
    singular = 0
    res = step = np.inf
    step_tol = 1e-2 * tol**0.5
    for k, s in enumerate(factors):
        converged = False
        for it in range(1, max_iter + 1):
            total += 1
            rv, Jv = fn(q, lam, s, pv)
            rs = np.asarray(rv).reshape(-1) / row
            res = float(np.max(np.abs(rs))) if rs.size else 0.0
            if not np.isfinite(res):
                raise StaticsError(
                    f"static equilibrium failed at load factor {s:.4g} (step {k + 1}/{steps}), Newton iteration "
                    f"{it}: the residual is not finite (scaled norm {res}); the iterate diverged. "
                    f"Try more load steps (e.g. steps={4 * steps}) or a q_start closer to the solution."
                )
            Js = np.asarray(Jv) / row[:, None] * col[None, :]
            try:
                du = np.linalg.solve(Js, -rs)
            except np.linalg.LinAlgError:
                du = np.full_like(rs, np.inf)
            if not np.all(np.isfinite(du)) or np.max(np.abs(du), initial=0.0) > _STEP_LIMIT:
                # (Nearly) singular tangent: an unstressed mechanism (e.g. a pendulum started at rest
                # away from its equilibrium). Take the minimum-norm step, which leaves the
                # mechanism motion alone; the stress it builds supplies the geometric stiffness.
                singular += 1
                du = np.linalg.lstsq(Js, -rs, rcond=_RCOND)[0]
            step = float(np.max(np.abs(du), initial=0.0))
            dz = du * col
            q, lam = q + dz[:n], lam + dz[n:]
            tol_k = float(roundoff_tolerance(tol, q, ell))
            if res <= tol_k and step <= step_tol:
                converged = True
                break
        if not converged:
            hint = ""
            if singular:
                hint = (f" The tangent was (nearly) singular in {singular} iteration(s): the structure may be a "
                        "mechanism or unsupported (check the supports), or start from a stressed q_start nearer "
                        "equilibrium.")
            raise StaticsError(
                f"static equilibrium did not converge at load factor {s:.4g} (step {k + 1}/{steps}) after "
                f"{max_iter} Newton iterations in that step ({total} in all): scaled residual norm {res:.3e} "
                f"(tol {tol_k:.1e}), last scaled Newton update {step:.3e} (tol {step_tol:.1e}). "
                f"Try more load steps (e.g. steps={4 * steps}), a larger max_iter, "
                f"or a q_start closer to the solution.{hint}"
            )
    msg = (f"converged: {total} Newton iterations in {steps} load steps; last scaled residual {res:.2e} "
           f"<= {tol_k:.1e}, last scaled update {step:.2e} <= {step_tol:.1e}")
    return StaticResult(q=q, lam=lam, success=True, message=msg, iterations=total, load_factors=factors)


def _null_space(B: np.ndarray, n: int) -> np.ndarray:
    """Orthonormal basis (n, n - rank B) of the null space of B (m, n), by SVD."""
    if B.shape[0] == 0:
        return np.eye(n)
    _, sv, Vt = np.linalg.svd(B, full_matrices=True)
    rank = int(np.sum(sv > max(B.shape) * np.finfo(float).eps * (sv[0] if sv.size else 0.0)))
    return Vt[rank:].T


def modes(
    model: Model,
    *,
    q: np.ndarray | None = None,
    p: np.ndarray | dict[str, float] | None = None,
    count: int | None = None,
    lam: np.ndarray | None = None,
) -> ModesResult:
    """Undamped vibration modes linearised about the configuration ``q``.

    Parameters
    ----------
    model : Model
        From :func:`casflex.assemble`.
    q : array (n_dof,), optional
        Linearisation point (m, rad); default ``model.q0``. Pass ``equilibrium(model).q`` for
        modes about a static equilibrium (the tangent then includes the geometric stiffness of
        the preload, e.g. of gravity).
    p : array (n_p,) or dict, optional
        Parameter values; default ``model.p_nominal``.
    count : int, optional
        Number of modes returned (the lowest); default all n_dof - rank(B).
    lam : array (n_con,), optional
        Multipliers at q (e.g. ``equilibrium(model).lam``); adds d(B^T lambda)/dq to K, which
        is zero for the fixed-dof supports of casflex.

    Returns
    -------
    ModesResult

    Raises
    ------
    ModesError
        If the mass matrix restricted to the unconstrained motions is singular (free dofs
        without mass, e.g. a node joined only by massless springs); the dofs are named.
    """
    n, nc = model.n_dof, model.n_con
    pv = _params(model, p)
    qv = np.array(model.q0 if q is None else q, dtype=float).reshape(-1)
    if qv.shape != (n,):
        raise ValueError(f"q: expected shape ({n},), got {qv.shape}")
    lv = np.zeros(nc) if lam is None else np.asarray(lam, dtype=float).reshape(-1)
    if lv.shape != (nc,):
        raise ValueError(f"lam: expected shape ({nc},), got {lv.shape}")

    qs, ls, ps = ca.SX.sym("q", n), ca.SX.sym("lam", nc), ca.SX.sym("p", model.n_p)
    _, f_int, g = model.forces(qs, ca.DM.zeros(n), ps)
    _, Bs = model.constraint(qs)
    K_expr = ca.jacobian(f_int - g + ca.mtimes(Bs.T, ls), qs)
    fn = ca.Function("modes_linearise", [qs, ls, ps], [K_expr, model.mass(qs, ps), Bs],
                     ["q", "lam", "p"], ["K", "M", "B"])
    K, M, B = (np.asarray(v, dtype=float) for v in fn(qv, lv, pv))
    K = 0.5 * (K + K.T)
    M = 0.5 * (M + M.T)

    N = _null_space(B.reshape(nc, n), n)
    nf = N.shape[1]
    if nf == 0:
        raise ModesError("the supports fix every dof: there are no free motions and hence no modes")
    Kr = N.T @ K @ N
    Mr = N.T @ M @ N
    Mr = 0.5 * (Mr + Mr.T)

    # Massless free motions: eigenvectors of the reduced mass with ~zero eigenvalue.
    mu, W = np.linalg.eigh(Mr)
    scale = float(np.max(np.abs(mu))) if mu.size else 0.0
    small = mu <= 1e-12 * scale if scale > 0.0 else np.ones(nf, dtype=bool)
    if np.any(small):
        V = N @ W[:, small]
        weight = np.max(np.abs(V), axis=1)
        names = [model.dof_names[i] for i in np.flatnonzero(weight > 1e-6 * weight.max())]
        raise ModesError(
            f"the reduced mass matrix is singular: {int(small.sum())} free motion(s) carry no mass, involving "
            f"dofs {names}. Massless springs alone give a node no inertia; support those dofs, attach a beam, "
            "or remove the node."
        )
    try:
        L = np.linalg.cholesky(Mr)
    except np.linalg.LinAlgError as exc:  # pragma: no cover - guarded by the eigenvalue test above
        raise ModesError(f"the reduced mass matrix is not positive definite: {exc}") from None
    k = nf if count is None else int(count)
    if not 1 <= k <= nf:
        raise ValueError(f"count: expected 1 <= count <= {nf} (free motions), got {count!r}")
    Linv = np.linalg.inv(L)
    A = Linv @ Kr @ Linv.T
    _, Y = np.linalg.eigh(0.5 * (A + A.T))
    V = Linv.T @ Y  # reduced shapes, M-orthonormal
    # eigh gives eigenvalues to eps * max|omega^2|: the low modes of a fine mesh (omega^2 range
    # ~1e9) lose digits. The Rayleigh quotient of the original K, M with these vectors is
    # accurate to second order in the vector error, restoring them.
    mv = np.einsum("ij,ij->j", V, Mr @ V)
    w2 = np.einsum("ij,ij->j", V, Kr @ V) / mv
    V = V / np.sqrt(mv)
    order = np.argsort(w2)[:k]
    w2 = w2[order]
    shapes = N @ V[:, order]
    omega = np.sign(w2) * np.sqrt(np.abs(w2))
    return ModesResult(freq_hz=omega / (2.0 * np.pi), omega=omega, shapes=shapes, dof_names=model.dof_names)
