"""Linearised undamped vibration modes about a configuration.

The equations of motion linearised about q (the initial configuration or a static equilibrium),

    M(q) dq'' + K(q) dq = 0,    K = d(f_int - g)/dq = d2Pi/dq2 at load factor 1,    B dq = 0,

are restricted to the free dofs (the supports fix dofs, so B dq = 0 leaves exactly the free
ones) and solved as the symmetric generalised eigenproblem K v = omega^2 M v by
``scipy.linalg.eigh``. Ideal joints restrict the motions further, to the null space N of their
B_J on the free dofs: the eigenproblem is then N^T K_L N v = omega^2 N^T M N v, with K_L = K +
sum_j mu_j d2Phi_j/dq2 the tangent of the Lagrangian (the joints' reactions' own stiffness, mu their
multipliers at q: given as ``lam``, else the least-squares static balance of the free rows).
The eigenvalues are then recomputed as Rayleigh quotients of K and M:
``eigh`` gives them to eps * max|omega^2| only, which loses digits in proportion to omega_max^2 /
omega^2 (7e-9 relative on the first mode of a 64-element cantilever; the Rayleigh quotient
~1e-11). K is the exact tangent at q and contains the geometric stiffness of the preload (e.g.
of gravity about a hanging equilibrium).

These are small vibrations about a rest state only if q is a static equilibrium: the static
residual at q is computed (multipliers of the fixed dofs from their rows, the least-squares
multipliers) and a :class:`~casflex.statics.problem.StabilityWarning` is raised when it is not
small; the frequencies about, e.g., the unstressed initial configuration of a hanging chain
lack the stiffness of the preload and can even come out negative.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from casflex.model import Model
from casflex.statics.problem import ModesError, Scaled, StabilityWarning, problem_for

__all__ = ["ModesResult", "modes"]


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
    residual : float
        The scaled static residual at q (dimensionless, as the statics ``tol``).
    equilibrium : bool
        Whether q is a static equilibrium (residual within ``tol``, supports satisfied).
    omega2 : ndarray, shape (k,), complex
        The eigenvalues omega^2 (rad^2/s^2), ascending in real part. Real for conservative loads;
        with follower loads K is not symmetric and a complex pair is flutter: motions that grow
        as they oscillate. ``omega`` is then Re sqrt(omega^2) and ``shapes`` are complex.
    flutter : bool
        Whether a complex pair is among the modes (relative imaginary part above 1e-8).
    """

    freq_hz: np.ndarray
    omega: np.ndarray
    shapes: np.ndarray
    dof_names: tuple[str, ...]
    residual: float = 0.0
    equilibrium: bool = True
    omega2: np.ndarray | None = None
    flutter: bool = False


def modes(
    model: Model,
    *,
    q: np.ndarray | None = None,
    p: np.ndarray | dict[str, float] | None = None,
    t: float = 0.0,
    count: int | None = None,
    lam: np.ndarray | None = None,
    tol: float = 1e-8,
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
    t : float
        Time (s) at which tabulated loads are evaluated for the equilibrium check.
    count : int, optional
        Number of modes returned (the lowest); default all free dofs.
    lam : array (n_con,), optional
        Multipliers at q, accepted for symmetry with the equations of motion: d(B^T lambda)/dq
        is zero for the fixed-dof supports of casflex, so they do not change K.
    tol : float
        Largest scaled static residual (dimensionless, as the statics ``tol``) at which q counts
        as an equilibrium; above it (or with the supports violated) a StabilityWarning says that
        the frequencies are not small vibrations about a rest state.

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
    prob = problem_for(model)
    pv = model.p_nominal.copy() if p is None else model.params(p)
    qv = np.array(model.q0 if q is None else q, dtype=float).reshape(-1)
    if qv.shape != (n,):
        raise ValueError(f"q: expected shape ({n},), got {qv.shape}")
    lv = np.zeros(nc) if lam is None else np.asarray(lam, dtype=float).reshape(-1)
    if lv.shape != (nc,):
        raise ValueError(f"lam: expected shape ({nc},), got {lv.shape}")
    if not tol > 0.0:
        raise ValueError(f"tol: must be > 0, got {tol!r}")
    free = prob.free
    nf = free.size
    if nf == 0:
        raise ModesError("the supports fix every dof: there are no free motions and hence no modes")
    k = nf if count is None else count
    if isinstance(k, bool) or not isinstance(k, int | np.integer) or not 1 <= k <= nf:
        raise ValueError(f"count: expected 1 <= count <= {nf} (free motions), got {count!r}")

    K = prob.hessian(qv, 1.0, float(t), pv)
    M = np.asarray(prob.mass(qv, pv).full(), dtype=float)
    Kr, Mr = K[np.ix_(free, free)], M[np.ix_(free, free)]
    basis = np.eye(nf)  # the motions: the free dofs, or the joints' null space in them
    if model.joint_row_names:
        Kr, Mr, basis, residual, is_eq = _joints(model, prob, qv, pv, float(t), lv, Kr, Mr, tol)
        k = basis.shape[1] if count is None else k
        if k > basis.shape[1]:
            raise ValueError(f"count: expected 1 <= count <= {basis.shape[1]} (motions the joints leave), "
                             f"got {count!r}")
    else:
        residual, is_eq = _equilibrium_check(prob, pv, t, qv, tol)
    Mr = 0.5 * (Mr + Mr.T)

    # Massless free motions: eigenvectors of the reduced mass with ~zero eigenvalue.
    mu, W = scipy.linalg.eigh(Mr)
    scale = float(np.max(np.abs(mu)))
    small = mu <= 1e-12 * scale if scale > 0.0 else np.ones(Mr.shape[0], dtype=bool)
    if np.any(small):
        weight = np.max(np.abs(basis @ W[:, small]), axis=1)
        names = [model.dof_names[free[i]] for i in np.flatnonzero(weight > 1e-6 * weight.max())]
        raise ModesError(
            f"the reduced mass matrix is singular: {int(small.sum())} free motion(s) carry no mass, involving "
            f"dofs {names}. Massless springs alone give a node no inertia; support those dofs, attach a beam, "
            "or remove the node."
        )
    if not prob.conservative:
        return _nonsymmetric(model, Kr, Mr, free, k, residual, is_eq, basis)
    _, V = scipy.linalg.eigh(Kr, Mr, subset_by_index=None)
    # eigh gives eigenvalues to eps * max|omega^2|: the low modes of a fine mesh (omega^2 range
    # ~1e9) lose digits. The Rayleigh quotient of the original K, M with these vectors is
    # accurate to second order in the vector error, restoring them.
    mv = np.einsum("ij,ij->j", V, Mr @ V)
    w2 = np.einsum("ij,ij->j", V, Kr @ V) / mv
    V = V / np.sqrt(mv)
    order = np.argsort(w2)[:k]
    w2 = w2[order]
    shapes = np.zeros((n, k))
    shapes[free] = basis @ V[:, order]
    omega = np.sign(w2) * np.sqrt(np.abs(w2))
    return ModesResult(freq_hz=omega / (2.0 * np.pi), omega=omega, shapes=shapes, dof_names=model.dof_names,
                       residual=residual, equilibrium=is_eq, omega2=w2.astype(complex), flutter=False)


def _nonsymmetric(model: Model, Kr: np.ndarray, Mr: np.ndarray, free: np.ndarray, k: int, residual: float,
                  is_eq: bool, basis: np.ndarray) -> ModesResult:
    """Modes of a non-symmetric tangent (follower loads): K v = omega^2 M v by ``scipy.linalg.eig``."""
    w2, V = scipy.linalg.eig(Kr, Mr)
    top = float(np.max(np.abs(w2)))
    order = np.argsort(w2.real)[:k]
    w2, V = w2[order], V[:, order]
    V = V / np.sqrt(np.abs(np.einsum("ij,ij->j", V.conj(), Mr @ V)))
    # a pair is complex beyond round-off: eig's absolute error is ~eps max|omega^2| (the stiff axial
    # modes), far above the low modes' own digits; relative to each eigenvalue, 1e-8
    pair = np.abs(w2.imag) > np.maximum(1e-8 * np.abs(w2), 1e3 * np.finfo(float).eps * top)
    flutter = bool(np.any(pair))
    root = np.sqrt(w2.astype(complex))
    omega = np.where(pair, root.real, np.sign(w2.real) * np.sqrt(np.abs(w2.real)))
    shapes = np.zeros((model.n_dof, k), dtype=complex)
    shapes[free] = basis @ V
    return ModesResult(freq_hz=omega / (2.0 * np.pi), omega=omega, shapes=shapes if flutter else shapes.real,
                       dof_names=model.dof_names, residual=residual, equilibrium=is_eq, omega2=w2, flutter=flutter)


def _joints(model: Model, prob, q: np.ndarray, p: np.ndarray, t: float, lam: np.ndarray, Kr: np.ndarray,
            Mr: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, bool]:
    """(N^T K_L N, N^T M N, N, static residual, equilibrium?) with the ideal joints' rows: N an
    orthonormal basis of the free motions that keep the joints closed, K_L the Lagrangian's tangent; the
    residual is the free rows' imbalance relative to the largest force in them."""
    free, nf = prob.free, model.n_fixed
    phi, B = (np.array(v) for v in model.constraint(q))
    Bj = B[nf:][:, free]
    sp = Scaled(prob, p, t, q)
    _, _, g = sp.gradient(sp.u(q), 1.0)  # the free rows' dPi/dq, scaled by their lengths
    react = (Bj * sp.ell[None, :]).T  # B_J^T in the scaled rows of g
    mu = lam[nf:] if np.any(lam[nf:]) else np.linalg.lstsq(react, -g, rcond=None)[0]
    # the balance relative to the forces in it: the statics scaling d (the diagonal of K) says nothing
    # of dofs that only the joints hold (a rigid body's translations: d at its 1e-12 floor)
    res = float(np.abs(g + react @ mu).max() / max(np.abs(g).max(), np.abs(react @ mu).max(), 1e-300))
    closed = np.abs(phi.ravel()[nf:]).max() <= 1e-9 * model.length_scale
    H = np.array(model.joint_rows(q, mu)[2])[np.ix_(free, free)]
    N = scipy.linalg.null_space(Bj)
    is_eq = bool(res <= tol and closed)
    if not is_eq:
        why = f"the free rows' imbalance is {res:.1e} of the forces" + ("" if closed else ", a joint is open")
        warnings.warn(f"modes about a configuration that is not a static equilibrium of the jointed system ({why}): "
                      "the frequencies are not those of small vibrations about a rest state", StabilityWarning,
                      stacklevel=3)
    return N.T @ (Kr + H) @ N, N.T @ Mr @ N, N, float(res), is_eq


def _equilibrium_check(prob, pv: np.ndarray, t: float, q: np.ndarray, tol: float) -> tuple[float, bool]:
    """The scaled static residual at q (free rows; the fixed rows are balanced by the
    multipliers) and whether q is an equilibrium; warns when it is not."""
    sp = Scaled(prob, pv, t, q)
    u = sp.u(q)
    _, _, g = sp.gradient(u, 1.0)
    res = sp.residual(g)
    tol_k = sp.tol(tol, u)
    off = np.abs(q[prob.fixed] - prob.fixed_at(t)) / prob.ell[prob.fixed]
    violated = float(np.max(off, initial=0.0))
    if res <= tol_k and violated <= tol_k:
        return res, True
    if violated > tol_k:
        worst = prob.dof_names[prob.fixed[int(np.argmax(off))]]
        why = f"the supports are not satisfied ({worst} is {violated:.1e} structure lengths or rad off)"
    else:
        worst = prob.dof_names[sp.free[int(np.argmax(np.abs(g) / (sp.d * sp.ell**2)))]]
        why = f"its scaled static residual is {res:.1e} > {tol_k:.0e}, largest on {worst}"
    warnings.warn(f"modes about a configuration that is not a static equilibrium: {why}. The frequencies "
                  "are not those of small vibrations about a rest state (the preload's stiffness is missing or "
                  "wrong; negative or near-zero values may come from that alone); linearise about a static "
                  "equilibrium instead.", StabilityWarning, stacklevel=3)
    return res if math.isfinite(res) else math.inf, False
