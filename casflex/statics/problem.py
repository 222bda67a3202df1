"""The statics problem of a model: its CasADi Functions (built once per model), the options,
the reduced and scaled form the solvers work in, and the stability of an equilibrium.

Assumptions, checked when the problem is built (:class:`StaticsError` otherwise):

- every constraint fixes a dof, q_i = value (the supports of casflex today), so the constraint
  set is an affine subspace: the solvers work in the free dofs only and recover the multipliers
  of the fixed dofs from their residual rows, lambda_j = -dPi/dq_i;
- the loads are conservative: f_ext(t, p) does not depend on q (tabulated loads are evaluated at
  a fixed t) and gravity derives from the potential V_g; or, with follower loads (which turn with
  their nodes: no potential), the residual below gains their forces and its tangent their load
  stiffness, non-symmetric, and only Newton (``seek = "nearest"``) applies.

Static equilibrium at load factor s is then a stationary point of the total potential

    Pi(q) = V_el(q) + s (V_g(q) - f_ext(t) . q)

on that subspace, and a stable equilibrium is a strict local minimum: the tangent K = d2Pi/dq2
restricted to the free dofs (the *reduced tangent*) is positive definite there.

Scaling. The free dofs are scaled to u_i = q_i / l_i, l_i = ``model.length_scale`` (m) for
translations and 1 (rad) for rotations: a step in u is a motion in structure lengths and
radians. The gradient and the Hessian in u are l_i dPi/dq_i and l_i l_j K_ij (J). The residual
row i is measured as an equivalent displacement, |dPi/dq_i| / (d_i l_i), d_i the diagonal of the
tangent at the start (full load) with the x and y entries of each node averaged (invariant under
a rotation of the scene), so one dimensionless ``tol`` serves stiffnesses from 1e-3 to 1e12.
"""

from __future__ import annotations

import math
import threading
import weakref
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from functools import cached_property

import casadi as ca
import numpy as np
import scipy.linalg

from casflex.integrators.hht import roundoff_tolerance
from casflex.model import Model
from casflex.model.constraints import FixedDof

__all__ = [
    "StaticsError", "ModesError", "StabilityWarning", "StaticOptions", "StaticProblem", "Stability",
    "problem_for", "SEEK",
]

#: What the solver looks for: a stable equilibrium (minimum of Pi), or the nearest stationary point.
SEEK = ("stable", "nearest")


class StaticsError(RuntimeError):
    """A static solve failed, or the model breaks an assumption of statics; the message says
    where and what to try. ``path`` holds the points a path-following run traced before it
    failed (a :class:`~casflex.statics.path.PathResult`), else None."""

    def __init__(self, message: str, path=None):
        super().__init__(message)
        self.path = path


class ModesError(ValueError):
    """The model has no well-posed modal problem (e.g. massless free dofs); the message names the dofs."""


class StabilityWarning(UserWarning):
    """A configuration that is returned or used is not a stable equilibrium (unstable, neutral,
    or not an equilibrium at all)."""


@dataclass(frozen=True)
class StaticOptions:
    """How a static solve runs (shared by :func:`equilibrium`, :func:`equilibrium_path` and the
    equilibrium that ``casflex modes --about equilibrium`` linearises about).

    Attributes
    ----------
    steps : int
        The first load increment is 1/steps of the full load (default 1: the full load at once);
        later increments adapt (halved when one fails, doubled after an easy one).
    tol : float
        Tolerance on the scaled residual (dimensionless: an equivalent displacement in structure
        lengths, see :mod:`casflex.statics.problem`); raised to the round-off floor of far-off
        coordinates. A point is an equilibrium when the scaled residual is at most ``tol`` and the
        Newton update computed there (and applied) is at most 0.01 sqrt(tol) (structure lengths, rad).
    max_iter : int
        Newton (trust-region) iterations allowed per load increment.
    min_increment : float
        Smallest load increment (fraction of the full load) before the solve gives up.
    seek : {"stable", "nearest"}
        ``"stable"`` (default): minimise the total potential, leaving unstable stationary points
        along their unstable modes; the result is a stable (or neutral) equilibrium.
        ``"nearest"``: plain Newton on the residual (the nearest stationary point, which may be
        unstable; a warning says so).
    """

    steps: int = 1
    tol: float = 1e-10
    max_iter: int = 100
    min_increment: float = 1e-3
    seek: str = "stable"

    def __post_init__(self) -> None:
        for name in ("steps", "max_iter"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < 1:
                raise ValueError(f"{name}: expected an integer >= 1, got {v!r}")
        for name in ("tol", "min_increment"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float | np.floating) or not (0.0 < v < math.inf):
                raise ValueError(f"{name}: expected a number > 0, got {v!r}")
        if self.min_increment > 1.0:
            raise ValueError(f"min_increment: expected at most 1 (the full load), got {self.min_increment!r}")
        if self.seek not in SEEK:
            raise ValueError(f"seek: expected one of {SEEK}, got {self.seek!r}")


def resolve_options(options: StaticOptions | None, settings: Mapping[str, object]) -> StaticOptions:
    """``options`` (default :class:`StaticOptions`) with the keyword ``settings`` applied; a
    TypeError names an unknown setting."""
    known = {f.name for f in fields(StaticOptions)}
    unknown = sorted(set(settings) - known)
    if unknown:
        raise TypeError(f"unknown static option(s) {unknown}; expected some of {sorted(known)}")
    return replace(options or StaticOptions(), **settings)


def spell(names: Mapping[str, str] | None, field: str, value: object) -> str:
    """How the caller sets option ``field`` to ``value``: ``steps=40`` in Python, ``--steps 40``
    when ``names`` maps the field to a command-line option."""
    name = (names or {}).get(field, field)
    return f"{name} {value}" if name.startswith("-") else f"{name}={value!r}"


class _Dense:
    """A CasADi Function with dense inputs and outputs evaluated straight into numpy arrays
    (CasADi's buffer interface): no DM round trip, which costs 0.8 ms for a 123 x 123 Hessian
    against 0.25 ms for the evaluation itself. One set of buffers per thread; falls back to the
    ordinary call where the interface is missing."""

    def __init__(self, fn: ca.Function):
        self.fn = fn
        self._shapes = [fn.size_out(i) for i in range(fn.n_out())]
        self._local = threading.local()

    def _buffers(self):
        b = getattr(self._local, "buffers", None)
        if b is None:
            fn = self.fn
            try:
                buf, evaluate = fn.buffer()
            except (AttributeError, RuntimeError):  # pragma: no cover - older CasADi
                b = self._local.buffers = (None, None, None, None)
                return b
            args = [np.zeros(fn.nnz_in(i)) for i in range(fn.n_in())]
            res = [np.zeros(fn.nnz_out(i)) for i in range(fn.n_out())]
            for i, a in enumerate(args):
                buf.set_arg(i, memoryview(a))
            for i, r in enumerate(res):
                buf.set_res(i, memoryview(r))
            b = self._local.buffers = (buf, evaluate, args, res)  # buf must outlive evaluate
        return b

    def __call__(self, *args) -> list[np.ndarray]:
        _, evaluate, inputs, res = self._buffers()
        if evaluate is None:  # pragma: no cover - older CasADi
            out = self.fn(*args)
            out = out if isinstance(out, tuple | list) else [out]
            return [np.asarray(o.full()).reshape(s) for o, s in zip(out, self._shapes, strict=True)]
        for a, v in zip(inputs, args, strict=True):
            a[:] = np.ravel(v)
        evaluate()
        return [r.reshape(s, order="F").copy() for r, s in zip(res, self._shapes, strict=True)]


class StaticProblem:
    """The statics Functions of one model, built once (:func:`problem_for`) and reused by every
    solve, path and modal analysis of that model.

    Functions (named, with named inputs and outputs; q (n_dof,) in m and rad, factor the load
    factor s, t (s) the time at which tabulated loads are evaluated, p the parameters):

    - ``potential(q, factor, t, p) -> (Pi, grad, load, magnitude)``: the total potential Pi (J),
      its gradient dPi/dq (N, N m), the reference load f_ext + g = -d(grad)/d(factor) and
      |V_el| + |s| (|V_g| + sum |f_i q_i|) (J), the size of the terms whose round-off Pi carries;
    - ``tangent(q, factor, t, p) -> K``: the exact Hessian d2Pi/dq2 by AD, dense (n_dof, n_dof);
    - ``residual(q, lam, factor, t, p) -> (r, J)``: the equilibrium equations in their general
      constrained form, r = [grad + B^T lam; Phi] and J = dr/d(q, lam) (built on first use).

    Attributes
    ----------
    free, fixed : ndarray of int
        Indices of the free dofs and of the fixed dofs (in constraint order).
    fixed_values : ndarray, shape (n_con,)
        The values the supports hold the fixed dofs at (moving supports: at t = 0; :meth:`fixed_at`).
    ell : ndarray, shape (n_dof,)
        Characteristic length per dof: ``model.length_scale`` for translations, 1 for rotations.
    """

    def __init__(self, model: Model):
        for c in model.constraints:
            if not isinstance(c, FixedDof):
                raise StaticsError(
                    f"statics assumes supports that fix dofs (q_i = value), which make the constraint set "
                    f"linear; constraint {c.name!r} is a {type(c).__name__}: not supported")
        if model.load.n_in() != 2 or list(model.load.name_in()) != ["t", "p"]:
            raise StaticsError(
                "statics assumes conservative loads f_ext(t, p), independent of q (a potential exists); "
                f"this model's load Function takes {list(model.load.name_in())}: not supported")
        fixed = np.array([c.dof for c in model.constraints], dtype=int)
        if np.unique(fixed).size != fixed.size:
            twice = sorted({model.dof_names[i] for i in fixed if np.sum(fixed == i) > 1})
            raise StaticsError(f"dofs {twice} are fixed by more than one support: their reactions are "
                               "indeterminate; keep one support per dof")
        n = model.n_dof
        self.n_dof = n
        self.n_con = model.n_con
        self.n_p = model.n_p
        self.fixed = fixed
        self.free = np.setdiff1d(np.arange(n), fixed)
        self.fixed_values = np.array([c.value for c in model.constraints], dtype=float)
        self._prescribed = model.prescribed if model.moving else None
        self.is_rotation = np.asarray(model.is_rotation, dtype=bool)
        self.ell = np.where(self.is_rotation, 1.0, model.length_scale)
        self.dof_names = model.dof_names

        q, s, t, p = ca.SX.sym("q", n), ca.SX.sym("factor"), ca.SX.sym("t"), ca.SX.sym("p", model.n_p)
        _, v_el, v_g = model.energy(q, ca.DM.zeros(n), p)
        f_ext = model.load(t, p)
        work = ca.dot(f_ext, q)
        pi = v_el + s * (v_g - work)
        #: False with follower loads: the "gradient" is then a residual and K its non-symmetric Jacobian
        self.conservative = not any(grp.kind == "follower" for grp in model.groups)
        follower = ca.SX.zeros(n) if self.conservative else model.forces(q, ca.DM.zeros(n), p)[0]  # -R(theta) f
        grad = ca.gradient(pi, q) + s * follower
        hess = ca.jacobian(grad, q)
        load = f_ext - ca.gradient(v_g, q) - follower  # f_ext + g (+ the follower loads), g = -dV_g/dq
        magnitude = ca.fabs(v_el) + ca.fabs(s) * (ca.fabs(v_g) + ca.sum1(ca.fabs(f_ext * q)))
        self._sym = (q, s, t, p, pi, grad, model.constraint)
        # No common-subexpression elimination: it costs 0.3 s to build at 40 elements and saves
        # only 0.08 ms per evaluation.
        self.potential = ca.Function("statics_potential", [q, s, t, p], [pi, grad, load, magnitude],
                                     ["q", "factor", "t", "p"], ["Pi", "grad", "load", "magnitude"])
        self.tangent = ca.Function("statics_tangent", [q, s, t, p], [ca.densify(hess)],
                                   ["q", "factor", "t", "p"], ["K"])
        self.local_rotations = model.local_rotations
        self.mass = model.mass
        self._potential = _Dense(self.potential)
        self._tangent = _Dense(self.tangent)
        self._rotations = _Dense(model.local_rotations) if model.local_rotation_names else None

    @cached_property
    def residual(self) -> ca.Function:
        """``residual(q, lam, factor, t, p) -> (r, J)``, the general constrained form."""
        q, s, t, p, _, grad, constraint = self._sym
        lam = ca.SX.sym("lam", self.n_con)
        phi, B = constraint(q)
        r = ca.vertcat(grad + ca.mtimes(B.T, lam), phi)
        return ca.Function("statics_residual", [q, lam, s, t, p], [r, ca.jacobian(r, ca.vertcat(q, lam))],
                           ["q", "lam", "factor", "t", "p"], ["r", "J"])

    def fixed_at(self, t: float) -> np.ndarray:
        """The values of the fixed dofs at time t (s): a moving support where its path has it then."""
        if self._prescribed is None:
            return self.fixed_values
        return np.array(self._prescribed(t)[0], dtype=float).ravel()

    def evaluate(self, q: np.ndarray, factor: float, t: float, p: np.ndarray):
        """(Pi, grad, load, magnitude) at q, as floats and arrays of shape (n_dof,)."""
        pi, grad, load, mag = self._potential(q, factor, t, p)
        return float(pi[0, 0]), grad.reshape(-1), load.reshape(-1), float(mag[0, 0])

    def hessian(self, q: np.ndarray, factor: float, t: float, p: np.ndarray) -> np.ndarray:
        """The tangent K (n_dof, n_dof) at q, symmetrised (as it is exactly) when the loads are
        conservative; with follower loads the Jacobian of the residual as it is."""
        K = self._tangent(q, factor, t, p)[0]
        return 0.5 * (K + K.T) if self.conservative else K

    def rotations(self, q: np.ndarray) -> np.ndarray:
        """The co-rotational local end rotations of the beam elements (rad), shape (n_local,)."""
        return np.zeros(0) if self._rotations is None else self._rotations(q)[0].reshape(-1)


_PROBLEMS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def problem_for(model: Model) -> StaticProblem:
    """The :class:`StaticProblem` of ``model``, built on first use and kept as long as the model lives."""
    prob = _PROBLEMS.get(model)
    if prob is None:
        prob = _PROBLEMS[model] = StaticProblem(model)
    return prob


def _invariant_diagonal(diag: np.ndarray) -> np.ndarray:
    """|diag| with the x and y entries of each node averaged, floored at 1e-12 of the max."""
    d = np.abs(np.asarray(diag, dtype=float)).copy()
    xy = 0.5 * (d[0::3] + d[1::3])
    d[0::3] = xy
    d[1::3] = xy
    return np.maximum(d, 1e-12 * d.max(initial=0.0) + 1e-300)


class Scaled:
    """One model at given parameters and time, reduced to its free dofs and scaled: u = q_free / l.

    Built per solve (the scaling depends on the start); the Functions come from the model's
    :class:`StaticProblem`. ``rms`` turns a root-mean-square motion per node into a 2-norm in u:
    trust radii and arc lengths are given per node, so that they mean the same for any mesh.
    """

    def __init__(self, problem: StaticProblem, p: np.ndarray, t: float, q_start: np.ndarray):
        self.problem = problem
        self.p = np.asarray(p, dtype=float)
        self.t = float(t)
        q = np.array(q_start, dtype=float).reshape(-1)
        q[problem.fixed] = problem.fixed_at(t)
        self.base = q
        self.free = problem.free
        self.ell = problem.ell[self.free]
        d = _invariant_diagonal(np.diag(problem.hessian(q, 1.0, self.t, self.p)))
        self.d = d[self.free]
        self.n = self.free.size
        self.rms = math.sqrt(max(self.n, 3) / 3.0)

    def q(self, u: np.ndarray) -> np.ndarray:
        """The full configuration (n_dof,) of the scaled free dofs u."""
        q = self.base.copy()
        q[self.free] = u * self.ell
        return q

    def u(self, q: np.ndarray) -> np.ndarray:
        return np.asarray(q, dtype=float)[self.free] / self.ell

    def gradient(self, u: np.ndarray, s: float) -> tuple[float, float, np.ndarray]:
        """(Pi (J), its round-off (J), the scaled gradient dPi/du (J), shape (n,))."""
        pi, grad, _, mag = self.problem.evaluate(self.q(u), s, self.t, self.p)
        return pi, 64.0 * np.finfo(float).eps * mag, grad[self.free] * self.ell

    def hessian(self, u: np.ndarray, s: float) -> np.ndarray:
        """The scaled reduced tangent d2Pi/du2 (J), shape (n, n)."""
        K = self.problem.hessian(self.q(u), s, self.t, self.p)
        return K[np.ix_(self.free, self.free)] * np.outer(self.ell, self.ell)

    def tangent_eigenvalues(self, u: np.ndarray, s: float) -> np.ndarray:
        """The eigenvalues (ascending) of the scaled reduced tangent: the stability of u at load factor s."""
        return scipy.linalg.eigvalsh(self.hessian(u, s))

    def load(self, u: np.ndarray) -> np.ndarray:
        """d(dPi/du)/ds = -(f_ext + g) l on the free dofs (J), shape (n,)."""
        _, _, load, _ = self.problem.evaluate(self.q(u), 0.0, self.t, self.p)
        return -load[self.free] * self.ell

    def reactions(self, u: np.ndarray, s: float, du: np.ndarray | None = None) -> np.ndarray:
        """The multipliers lambda (n_con,) of the fixed dofs, -dPi/dq_i (N, N m), at u + du,
        linearised about u when the last Newton update du (scaled, shape (n,)) is given: like the
        update itself, and unlike a fresh evaluation, the linearisation does not carry the
        round-off of the elastic forces (eps EA/L_e l per row), so the reactions balance the loads
        to ~1e-10 relative."""
        q = self.q(u)
        _, grad, _, _ = self.problem.evaluate(q, s, self.t, self.p)
        fixed = self.problem.fixed
        lam = -grad[fixed]
        if du is not None and fixed.size and self.n:
            K = self.problem.hessian(q, s, self.t, self.p)
            lam -= K[np.ix_(fixed, self.free)] @ (du * self.ell)
        return lam

    def check_supported(self) -> None:
        """StaticsError when no support fixes any x (or any y) dof and the loads have a net x (or
        y) component: the elastic energies are invariant under a rigid translation, along which
        Pi then falls linearly without bound (the tangent is singular along it)."""
        _, _, load, _ = self.problem.evaluate(self.base, 1.0, self.t, self.p)
        fixed = set(self.problem.fixed.tolist())
        for k, axis in enumerate("xy"):
            rows = np.arange(k, self.problem.n_dof, 3)
            if fixed.intersection(rows.tolist()):
                continue
            net = float(np.sum(load[rows]))
            if abs(net) > 1e-12 * float(np.sum(np.abs(load[rows]))):
                raise StaticsError(
                    f"no static equilibrium: no support fixes any {axis} dof, and the loads (gravity included) have "
                    f"a net {axis} component of {net:.6g} N at full load; the structure would translate without "
                    f"bound (the tangent is singular along that rigid motion). Add a support that fixes {axis}.")

    def residual(self, g: np.ndarray) -> float:
        """The scaled residual (max norm) of a scaled gradient g: |dPi/dq_i| / (d_i l_i)."""
        return float(np.max(np.abs(g) / (self.d * self.ell**2), initial=0.0))

    def tol(self, tol: float, u: np.ndarray) -> float:
        """``tol`` raised to the round-off floor of the coordinates."""
        return float(roundoff_tolerance(tol, self.q(u), self.problem.ell))

    def turn(self, u: np.ndarray, v: np.ndarray) -> float:
        """Largest change (rad) of an element's local end rotation between u and v, wrapped."""
        a, b = self.problem.rotations(self.q(u)), self.problem.rotations(self.q(v))
        if a.size == 0:
            return 0.0
        return float(np.max(np.abs(np.angle(np.exp(1j * (b - a))))))

    def moving(self, v: np.ndarray, share: float = 0.1) -> list[str]:
        """Names of the dofs with a scaled component above ``share`` of the largest in v (n,)."""
        a = np.abs(v)
        big = self.free[a >= share * a.max(initial=0.0)] if a.size else []
        return [self.problem.dof_names[i] for i in big]


def neutral_band(eigenvalues: np.ndarray) -> float:
    """The round-off of the eigenvalues of a symmetric matrix: n eps max|eigenvalue| (J)."""
    n = eigenvalues.size
    return max(n, 1) * np.finfo(float).eps * float(np.max(np.abs(eigenvalues), initial=0.0))


@dataclass(frozen=True)
class Stability:
    """The stability of an equilibrium, from the eigenvalues of its reduced tangent (the Hessian
    of the total potential in the free dofs, scaled: translations in structure lengths,
    rotations in rad).

    Attributes
    ----------
    min_eigenvalue : float
        Smallest eigenvalue relative to the largest in magnitude (dimensionless); > threshold:
        stable, < -threshold: unstable, else neutral (a critical point or a mechanism).
    threshold : float
        The neutral band n eps (dimensionless): the round-off of eigenvalues relative to the
        largest, n the number of free dofs.
    negative : int
        Number of eigenvalues below -threshold (the number of independent unstable modes).
    scale : float
        Largest eigenvalue in magnitude (J per structure length or rad, squared).
    mode : ndarray, shape (n_dof,)
        Eigenvector of the smallest eigenvalue (the critical mode) in q units (m, rad), zero on
        the fixed dofs, scaled so that its largest component in structure lengths or rad is 1.
    """

    min_eigenvalue: float
    threshold: float
    negative: int
    scale: float
    mode: np.ndarray
    assessed: bool = True

    @property
    def kind(self) -> str:
        """``"stable"``, ``"neutral"``, ``"unstable"`` or, with follower loads, ``"not assessed"``."""
        if not self.assessed:
            return "not assessed"
        if self.min_eigenvalue > self.threshold:
            return "stable"
        return "unstable" if self.min_eigenvalue < -self.threshold else "neutral"

    @property
    def stable(self) -> bool:
        """True when the reduced tangent is positive definite beyond round-off."""
        return self.kind == "stable"

    def describe(self) -> str:
        """One line: the verdict and the smallest tangent eigenvalue."""
        if not self.assessed:
            return "stability not assessed: with follower loads it is a question of dynamics (modes: flutter)"
        if not math.isfinite(self.min_eigenvalue):
            return "stable (the supports fix every dof)"
        ev = f"smallest tangent eigenvalue {self.min_eigenvalue:.3g} of the largest"
        if self.kind == "stable":
            return f"stable ({ev})"
        if self.kind == "neutral":
            return f"NEUTRAL: {ev}, within round-off ({self.threshold:.1g}) of zero: a critical point or a mechanism"
        more = f", {self.negative} unstable modes" if self.negative > 1 else ""
        return f"UNSTABLE: {ev}{more}"


def stability_of(sp: Scaled, H: np.ndarray) -> tuple[Stability, np.ndarray]:
    """The :class:`Stability` of the scaled reduced tangent H (n, n), and its eigenvalues (ascending)."""
    if H.shape[0] == 0:
        return Stability(math.inf, 0.0, 0, 0.0, np.zeros(sp.problem.n_dof)), np.zeros(0)
    if not sp.problem.conservative:  # a non-symmetric tangent: stability needs the mass (modes)
        return Stability(math.nan, 0.0, 0, 0.0, np.zeros(sp.problem.n_dof), assessed=False), np.zeros(0)
    lam, V = scipy.linalg.eigh(H, check_finite=True)
    scale = float(np.max(np.abs(lam)))
    band = neutral_band(lam)
    v = V[:, 0] / np.max(np.abs(V[:, 0]))
    v = v if v[np.argmax(np.abs(v))] > 0 else -v
    mode = np.zeros(sp.problem.n_dof)
    mode[sp.free] = v * sp.ell
    rel = float(lam[0] / scale) if scale > 0 else 0.0
    return Stability(rel, band / scale if scale > 0 else 0.0, int(np.sum(lam < -band)), scale, mode), lam
