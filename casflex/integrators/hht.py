"""HHT-alpha integration of the index-3 DAE (Eqs. 3-10 of the seed paper).

One step from (q_n, q'_n, q''_n, lambda_n) at t_n to t_n + h solves, for q_{n+1} and
lambda_{n+1} (Eqs. 4, 5):

    r   = M(q_alpha) q''_{n+1} + (1+alpha) F_{n+1} - alpha F_n - f_ext(t_alpha) = 0
    r_P = (1+alpha) Phi(q_{n+1}) - alpha Phi(q_n) = 0

with F = h(q, q') + f_int + B^T lambda - g, t_alpha = t_n + (1+alpha) h and the Newmark
relations (gamma = 1/2 - alpha, beta = (1 - alpha)^2 / 4)

    q''_{n+1} = (q_{n+1} - q_n - h q'_n - (1/2 - beta) h^2 q''_n) / (beta h^2)
    q'_{n+1}  = q'_n + h ((1 - gamma) q''_n + gamma q''_{n+1}).

The mass matrix is taken at q_alpha = (1+alpha) q_{n+1} - alpha q_n, where the paper writes
M_{n+1}: q''_{n+1} approximates the acceleration at t_alpha, and pairing it with the mass of
q_{n+1} made the method first order for alpha < 0 once co-rotational masses rotate
(docs/theory.md). At alpha = 0, or with a constant mass matrix, the two forms coincide.

The constraints of casflex's supports fix dofs, Phi_j = q_i - v_j, so r_P gives q_{n+1} of the
fixed dofs outright and B^T lambda acts on their rows only: Newton (Eqs. 8-10) solves the rows
of the free dofs for the free q_{n+1}, and the multipliers follow from the rows of the fixed
dofs. This is the same solution as Newton on (q, lambda) together, with a smaller matrix that
is not a saddle point. The Jacobian is exact (AD; the paper drops the inertia derivatives).
Residual and Jacobian are assembled from element kernels (:mod:`casflex.elements.kernels`)
mapped over the element groups, or, for models of a few elements, expanded into flat code
(``expand``, :func:`expand_by_default`).

The unknowns and equations are scaled so that one dimensionless tolerance works for any
stiffness or mass: each momentum row i is divided by d_i * l_i, d_i a rotation-invariant
diagonal of the iteration matrix S = M/(beta h^2) + gamma/(beta h) C + K (Eq. 9) at the
initial state and l_i the characteristic length (m) for translations or 1 for rotations;
the unknowns are u = (q_{n+1} - q_guess)/l of the free dofs. Newton makes at least one update
unless the guess is (nearly) exact, and stops when the scaled residual is below tol or a Newton
update is below 0.01 sqrt(tol) (in the quadratic regime the residual after it is ~1e-4 tol).
The step returns its final residual, recomputed, and the driver rejects any step above ``tol``
(raised to the round-off floor of far-off coordinates, :meth:`HHT.tolerance`).
The Newton guess is the constant-acceleration predictor (q''_{n+1} = q''_n), better than the
paper's q''_{n+1} = 0 (Eq. 6); the converged step is the same.

The step is a CasADi Function built from pieces: ``prepare``, one Newton update (CasADi's
code-generatable ``fast_newton`` rootfinder, sparse QR), ``finish`` (the state and the residual
there), and only when that update did not converge the step, more Newton iterations (a
conditional call). On a resolved motion one update converges: each step evaluates the Jacobian
once, factorises once and evaluates the residual twice. :meth:`HHT.step_interpreted` drives the
same pieces from Python to count the updates; :meth:`HHT.trajectory` chains steps with
``mapaccum`` into one differentiable, exportable Function.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from casflex.assembly import MatrixAssembly, gather, scatter
from casflex.elements.kernels import hht_kernel, kernel
from casflex.integrators.band import band_lu
from casflex.integrators.modified import ModifiedNewton
from casflex.model import Model

__all__ = ["HHT", "hht_coefficients", "roundoff_tolerance", "ROUNDOFF_FLOOR", "NEWTON"]

#: A scaled residual is accepted down to ROUNDOFF_FLOOR * eps * max|q / l| (see roundoff_tolerance).
ROUNDOFF_FLOOR = 10.0


def roundoff_tolerance(tol: float, q: np.ndarray, ell: np.ndarray) -> np.ndarray:
    """``tol``, raised to the round-off floor of the coordinates q (shape (n,) or (k, n); l the
    characteristic length of each dof, 1 for rotations): a residual scaled by l cannot be
    computed below ~eps max|q / l| (elastic forces are differences of nearly equal
    coordinates), so a scene 10 km from the origin would otherwise fail at tol = 1e-12."""
    q = np.asarray(q, dtype=float)
    return np.maximum(tol, ROUNDOFF_FLOOR * np.finfo(float).eps * np.abs(q / ell).max(axis=-1, initial=0.0))


def hht_coefficients(alpha: float) -> tuple[float, float]:
    """(gamma, beta) = (1/2 - alpha, (1 - alpha)^2 / 4) for alpha in [-1/3, 0]."""
    if not -1.0 / 3.0 - 1e-12 <= alpha <= 0.0:
        raise ValueError(f"alpha: must lie in [-1/3, 0], got {alpha!r}")
    return 0.5 - alpha, (1.0 - alpha) ** 2 / 4.0


#: The Newton variants of simulate (HHT.newton).
NEWTON = ("exact", "modified")
#: Up to this many elements the Newton functions are expanded into flat SX (see expand_by_default).
EXPAND_ELEMENTS = 8


def expand_by_default(model: Model) -> bool:
    """Flat SX code for models of at most EXPAND_ELEMENTS beam elements: a mapped kernel costs a
    call and its index loops, which dominate a step of a few elements (twobar with one element per
    bar: 2x), while flat code grows with the mesh and its compile time with it."""
    return sum(g.n for g in model.groups if g.kind == "beam") <= EXPAND_ELEMENTS


@dataclass(frozen=True, eq=False)
class HHT:
    """HHT-alpha integrator for a :class:`~casflex.model.Model`.

    Parameters
    ----------
    model : Model
    alpha : float
        In [-1/3, 0]; 0 is the trapezoidal rule (no numerical damping).
    tol : float
        Newton tolerance on the inf-norm of the scaled residual (dimensionless; 1e-10 means
        a force error of 1e-10 of what moves a dof by the characteristic length).
    max_iter : int
        Newton iterations per step before the step is declared failed.
    expand : bool or None
        Evaluate the Newton residual and Jacobian as flat SX code (True) or as the element
        kernels mapped over the groups (False); None chooses by size (:func:`expand_by_default`).
    newton : {"exact", "modified"}
        How :func:`~casflex.simulate.simulate` steps: a Jacobian per step, or the factorised
        Jacobian kept while it converges the steps (:attr:`modified`). The Functions :attr:`step`
        and :meth:`trajectory` are the exact Newton's either way.

    The state vector x stacks [q, qd, qdd, lam], shape (3 n_dof + n_con,).
    """

    model: Model
    alpha: float = 0.0
    tol: float = 1e-12
    max_iter: int = 25
    expand: bool | None = None
    newton: str = "exact"
    _fn: dict = field(default_factory=dict, init=False, repr=False)
    _ell: np.ndarray = field(default=None, init=False, repr=False)  # characteristic length per dof

    def __post_init__(self) -> None:
        hht_coefficients(self.alpha)
        if not (isinstance(self.tol, float) and 0.0 < self.tol < 1e-2):
            raise ValueError(f"tol: expected a float in (0, 1e-2), got {self.tol!r}")
        if not (isinstance(self.max_iter, int) and self.max_iter >= 1):
            raise ValueError(f"max_iter: expected an integer >= 1, got {self.max_iter!r}")
        if self.newton not in NEWTON:
            raise ValueError(f"newton: expected one of {NEWTON}, got {self.newton!r}")
        self._build()

    # -- sizes -------------------------------------------------------------------------------
    @property
    def nx(self) -> int:
        return 3 * self.model.n_dof + self.model.n_con

    def split(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(q, qd, qdd, lam) from states x, shape (nx,) or (nx, k)."""
        n = self.model.n_dof
        return x[:n], x[n:2 * n], x[2 * n:3 * n], x[3 * n:]

    # -- construction ------------------------------------------------------------------------
    def _build(self) -> None:
        m = self.model
        ell = np.where(m.is_rotation, 1.0, m.length_scale)
        object.__setattr__(self, "_ell", ell)
        lay = _Layout.of(m, ell)
        expand = self.expand if self.expand is not None else expand_by_default(m)
        prepare = _prepare(m, lay, self.alpha)
        resid, jac, finish = _newton_functions(m, lay, self.alpha, self.tol, prepare.nnz_out(1), expand)

        # The first Newton update solves with the banded LU (band.py); when the residual after it is
        # above tol, CasADi's Newton (sparse QR) goes on, from that point or, if the update made things
        # worse, from the guess. Even a guess with G just under tol gets its update: G scales a force by
        # d ~ M / (beta h^2), so at a small step such a guess carries acceleration errors up to
        # tol l / (beta h^2): 0.05 m/s^2 at h = 1.25e-5 s, which accumulate in the velocities (7.6e-6 m
        # over 0.4 s).
        band = band_lu(jac.sparsity_out(0), "hht_band")
        factor, apply = (band.factor.expand(), band.apply.expand()) if expand else (band.factor, band.apply)
        z0, P = ca.MX.sym("z0", resid.nnz_in(0)), ca.MX.sym("prm", resid.nnz_in(1))
        J0, G0 = jac(z0, P)
        F0 = factor(J0.nz[:])
        update = ca.Function("hht_update", [z0, P], [z0 - apply(F0, G0), ca.norm_inf(G0), F0], ["z0", "prm"],
                             ["z1", "g0", "F"])
        newton = ca.rootfinder("hht_newton", "fast_newton", resid, {
            "abstol": self.tol, "abstolStep": 1e-2 * self.tol**0.5, "max_iter": max(self.max_iter - 1, 1),
            "error_on_fail": False, "jacobian_function": jac})
        xa, ra = ca.MX.sym("x1", self.nx), ca.MX.sym("res")
        keep = ca.Function("hht_done", [z0, P, xa, ra], [xa, ra])
        more = ca.Function("hht_more", [z0, P, xa, ra], finish(newton(z0, P), P)[:2] if self.max_iter > 1 else [xa, ra])
        post = _post(m).expand() if expand else _post(m)  # per state, and for a few elements flat code is 3x faster
        self._fn.update(prepare=prepare, residual=resid, jacobian=jac, finish=finish, scale=_scale(m, self.alpha),
                        initial=_initial(m, lay), post=post, update=update, newton=newton, band_apply=apply,
                        more=ca.Function.conditional("hht_converge", [keep], more))
        self._fn["sensitivity"] = _step_blocks(m, lay, self.alpha, prepare, resid, finish, expand)
        self._fn["step"] = self._step_with_derivative()

    def _step_with_derivative(self) -> ca.Function:
        """prepare -> newton -> finish as one Function, whose Jacobian is the implicit-function
        derivative written out (:func:`_step_blocks`): dx1/dw = X_w - X_z G_z^-1 G_w."""
        m = self.model
        n, nx, npar = m.n_dof, self.nx, m.n_p
        x0, t0, p, h, d = self._fn["prepare"].mx_in()
        zg, pr = self._fn["prepare"](x0, t0, p, h, d)
        z1, g0, _ = self._fn["update"](zg, pr)
        xa, ra, done = self._fn["finish"](z1, pr)
        X1, res1 = self._fn["more"](1 - done, ca.if_else(ra < g0, z1, zg), pr, xa, ra)
        OX1, ORES = ca.MX.sym("out_x1", nx), ca.MX.sym("out_res")
        G_z, G_w, X_z, X_w = self._fn["sensitivity"](x0, t0, p, h, d, OX1)
        J = X_w - ca.mtimes(X_z, ca.solve(G_z, G_w, "qr"))
        jac = ca.Function("jac_hht_step", [x0, t0, p, h, d, OX1, ORES],
                          [J[:, :nx], J[:, nx], J[:, nx + 1:nx + 1 + npar], J[:, nx + 1 + npar], ca.MX(nx, n),
                           ca.MX(1, nx), ca.MX(1, 1), ca.MX(1, npar), ca.MX(1, 1), ca.MX(1, n)],
                          ["x0", "t0", "p", "h", "d", "out_x1", "out_res"],
                          [f"jac_{o}_{i}" for o in ("x1", "res") for i in ("x0", "t0", "p", "h", "d")])
        return ca.Function("hht_step", [x0, t0, p, h, d], [X1, res1], ["x0", "t0", "p", "h", "d"], ["x1", "res"],
                           {"custom_jacobian": jac, "jac_penalty": 0})

    def tolerance(self, q: np.ndarray) -> np.ndarray:
        """Largest accepted scaled residual of a step ending at q, shape (n_dof,) or (k, n_dof):
        ``tol`` or the round-off floor of q (:func:`roundoff_tolerance`)."""
        return roundoff_tolerance(self.tol, q, self._ell)

    # -- public Functions --------------------------------------------------------------------
    @property
    def step(self) -> ca.Function:
        """``hht_step(x0, t0, p, h, d) -> (x1, res)``: one HHT step; res = final scaled residual."""
        return self._fn["step"]

    @property
    def scale(self) -> ca.Function:
        """``hht_scale(q, qd, p, h) -> d``: the Newton scaling, computed once per run."""
        return self._fn["scale"]

    @property
    def initial(self) -> ca.Function:
        """``hht_initial(q, qd, t, p) -> (qdd, lam)``: consistent accelerations and multipliers."""
        return self._fn["initial"]

    @property
    def post(self) -> ca.Function:
        """``hht_post(x, t, p) -> y``: [kinetic, elastic, gravity energy (J), power of the loads (W),
        power dissipated by the dampers (W), joint outputs (``model.output_names``), local rotations
        of the beam elements (rad, ``model.local_rotation_names``)] of one state."""
        return self._fn["post"]

    @property
    def modified(self) -> ModifiedNewton:
        """The modified Newton's Functions (:mod:`casflex.integrators.modified`), built on first use."""
        if "modified" not in self._fn:
            self._fn["modified"] = ModifiedNewton(self._fn, self.max_iter)
        return self._fn["modified"]

    @property
    def prepare(self) -> ca.Function:
        """``hht_prepare(x0, t0, p, h, d) -> (z0, prm)``: the Newton guess (the free dofs' scaled
        unknowns) and the known quantities of a step."""
        return self._fn["prepare"]

    @property
    def residual(self) -> ca.Function:
        """``hht_residual(z, prm) -> G``: the scaled residual of the free dofs' rows (Eq. 4)."""
        return self._fn["residual"]

    def step_interpreted(self, x0: np.ndarray, t0: float, p: np.ndarray, h: float,
                         d: np.ndarray) -> tuple[np.ndarray, float, int]:
        """One step as :attr:`step` takes it (bitwise), driven from Python so that the Newton
        updates can be counted: (x1, final scaled residual, Newton updates)."""
        z0, prm = self._fn["prepare"](x0, t0, p, h, d)
        z1, g0, _ = self._fn["update"](z0, prm)
        x1, res, done = self._fn["finish"](z1, prm)
        updates = 1
        if not bool(done) and self.max_iter > 1:
            z = self._fn["newton"](z1 if float(res) < float(g0) else z0, prm)
            updates += _updates(self._fn["newton"])
            x1, res, _ = self._fn["finish"](z, prm)
        return np.array(x1).ravel(), float(res), updates

    def step_residual(self, x0: np.ndarray, x1: np.ndarray, t0: float, p: np.ndarray, h: float,
                      d: np.ndarray) -> float:
        """The scaled residual (max norm, Eq. 4 on the free dofs) that the step x0 -> x1 from t0 leaves
        in the equations as this process evaluates them: how well a state x1 computed elsewhere
        (compiled code, another machine) solves this step; a step is accepted at :meth:`tolerance`."""
        n, ell = self.model.n_dof, self._ell
        free = _Layout.of(self.model, ell).free
        _, prm = self._fn["prepare"](x0, t0, p, h, d)
        q_pred = np.array(prm[:n]).ravel()  # the unknowns are z = (q_{n+1} - q_pred) / l on the free dofs
        z = ((np.asarray(x1[:n]) - q_pred) / ell)[free]
        return float(np.max(np.abs(np.array(self._fn["residual"](z, prm)).ravel()), initial=0.0))

    def sensitivity(self, n_steps: int) -> ca.Function:
        """``hht_sensitivity_<N>(x0, S0, t0, p, h, d) -> (X, S, res)``: N steps that also carry the
        forward sensitivities S = dx/dw of the state to w = (x_0, p), w of size nx + n_p.

        S0 (nx, nx + n_p) is dx0/dw (the identity beside zeros for a fixed start); S (nx, N (nx + n_p))
        holds dx_k/dw after each step, side by side; X and res as in :meth:`trajectory`. Each step
        propagates S_{k+1} = X_w E - X_z G_z^-1 G_w E with E = d(x_k, t_k, p, h)/dw: the implicit-
        function derivative of the Newton solve, one small QR per step.
        """
        key = f"sens{n_steps}"
        if key not in self._fn:
            m = self.model
            nx, npar = self.nx, m.n_p
            nw = nx + npar
            X0, T0, Pm, H, D = self.step.mx_in()
            S0 = ca.MX.sym("S0", nx, nw)
            X1, res = self.step(X0, T0, Pm, H, D)
            G_z, G_w, X_z, X_w = self._fn["sensitivity"](X0, T0, Pm, H, D, X1)
            E = ca.vertcat(S0, ca.MX(1, nw), ca.horzcat(ca.MX(npar, nx), ca.MX.eye(npar)), ca.MX(1, nw))
            S1 = ca.mtimes(X_w, E) - ca.mtimes(X_z, ca.solve(G_z, ca.mtimes(G_w, E), "qr"))
            one = ca.Function("hht_sensitivity_step", [X0, S0, T0, Pm, H, D], [X1, S1, res],
                              ["x0", "S0", "t0", "p", "h", "d"], ["x1", "S1", "res"])
            acc = one.mapaccum(f"hht_sensitivity_steps_{n_steps}", n_steps, 2)
            grid = T0 + H * ca.DM(np.arange(n_steps)).T
            X, S, R = acc(X0, S0, grid, ca.repmat(Pm, 1, n_steps), ca.repmat(H, 1, n_steps),
                          ca.repmat(D, 1, n_steps))
            self._fn[key] = ca.Function(f"hht_sensitivity_{n_steps}", [X0, S0, T0, Pm, H, D], [X, S, R],
                                        ["x0", "S0", "t0", "p", "h", "d"], ["X", "S", "res"])
        return self._fn[key]

    def trajectory(self, n_steps: int) -> ca.Function:
        """``hht_trajectory_<N>(x0, t0, p, h, d) -> (X, res)``: N steps chained by mapaccum.

        Steps start at t0 + k h, k = 0..N-1. X has shape (nx, N): the states after each step;
        res (1, N) the final scaled Newton residual of each step. Differentiable with respect
        to x0 and p (through the rootfinder's implicit-function derivative), exportable to C.
        """
        key = f"traj{n_steps}"
        if key not in self._fn:
            acc = self.step.mapaccum(f"hht_steps_{n_steps}", n_steps, 1)
            X0, T0, Pm, H, D = self.step.mx_in()
            grid = T0 + H * ca.DM(np.arange(n_steps)).T
            X, res = acc(X0, grid, ca.repmat(Pm, 1, n_steps), ca.repmat(H, 1, n_steps), ca.repmat(D, 1, n_steps))
            self._fn[key] = ca.Function(f"hht_trajectory_{n_steps}", [X0, T0, Pm, H, D], [X, res],
                                        ["x0", "t0", "p", "h", "d"], ["X", "res"])
        return self._fn[key]


def _updates(newton: ca.Function) -> int:
    """Newton updates made by a fast_newton rootfinder's last call: its iterations, plus the last
    update when it stopped on the update's size (counted before the iteration ends)."""
    st = newton.stats()
    return int(st["iter_count"]) + (st["return_status"] == "converged_abstol_step")


# -- the pieces of a step ----------------------------------------------------------------------
@dataclass(frozen=True)
class _Layout:
    """Free and fixed dofs: the unknowns of Newton and the dofs the supports hold."""

    n: int
    free: list[int]
    fixed: list[int]
    fixed_to: np.ndarray  # (n,): the supports' values on the fixed dofs, 0 elsewhere
    ell: np.ndarray  # (n,): characteristic length (m) of translations, 1 for rotations

    @classmethod
    def of(cls, m: Model, ell: np.ndarray) -> _Layout:
        fixed = [c.dof for c in m.constraints]
        if len(set(fixed)) != len(fixed):
            dup = sorted({m.dof_names[i] for i in fixed if fixed.count(i) > 1})
            raise ValueError(f"dofs {dup} are fixed by more than one support: their reactions are not determined")
        to = np.zeros(m.n_dof)
        to[fixed] = [c.value for c in m.constraints]
        return cls(m.n_dof, [i for i in range(m.n_dof) if i not in set(fixed)], fixed, to, ell)

    def spread(self, z: ca.MX) -> ca.MX:
        """The free dofs' values z (n_free,) in a vector of all dofs (zeros at the fixed ones)."""
        slot = np.full(self.n, len(self.free))  # the 0 appended to z
        slot[self.free] = np.arange(len(self.free))
        return ca.vertcat(z, 0)[slot.tolist()]

    def reactions(self) -> ca.DM:
        """B^T (n, n_con): the multipliers act on the fixed dofs' rows."""
        B_T = ca.DM.zeros(self.n, len(self.fixed))
        for j, i in enumerate(self.fixed):
            B_T[i, j] = 1.0
        return B_T


def _prm_layout(m: Model) -> list[tuple[str, int]]:
    """The known quantities a step's Newton solve takes (``prm``), in this order, with their sizes."""
    n = m.n_dof
    # moving supports: values at t_n and t_{n+1}, rates and accelerations at t_{n+1}
    moving = [("to0", n), ("to1", n), ("vd1", n), ("vdd1", n)] if m.moving else []
    return [("q_pred", n), ("qd_pred", n), ("f_n", n), ("f_ext", n), ("p", m.n_p), ("h", 1), ("d", n), ("q0", n),
            *moving]


def _prepare(m: Model, lay: _Layout, alpha: float) -> ca.Function:
    """``hht_prepare(x0, t0, p, h, d) -> (z0, prm)``: the Newton guess and everything known at the
    start of the step (the Newmark predictors, F_n, the loads at t_alpha)."""
    n = m.n_dof
    gamma, beta = hht_coefficients(alpha)
    x0, t0, h, p, d = (ca.MX.sym(k, s) for k, s in (("x0", 3 * n + m.n_con), ("t0", 1), ("h", 1), ("p", m.n_p),
                                                    ("d", n)))
    q0, qd0, qdd0, lam0 = x0[:n], x0[n:2 * n], x0[2 * n:3 * n], x0[3 * n:]
    f_n = ca.MX.zeros(n)  # F_n has the weight -alpha
    if alpha != 0.0:
        hh, f_int, g = m.forces(q0, qd0, p)
        f_n = hh + f_int - g + ca.mtimes(lay.reactions(), lam0)
    prm = ca.vertcat(q0 + h * qd0 + (0.5 - beta) * h**2 * qdd0, qd0 + (1 - gamma) * h * qdd0, f_n,
                     m.load(t0 + (1 + alpha) * h, p), p, h, d, q0)
    if m.moving:
        v1 = m.prescribed(t0 + h)
        prm = ca.vertcat(prm, *(ca.mtimes(lay.reactions(), v) for v in (m.prescribed(t0)[0], *v1)))
    z_guess = (beta * h**2 * qdd0 / lay.ell)[lay.free]
    return ca.Function("hht_prepare", [x0, t0, p, h, d], [ca.densify(z_guess), ca.densify(prm)],
                       ["x0", "t0", "p", "h", "d"], ["z0", "prm"])


def _newton_functions(m: Model, lay: _Layout, alpha: float, tol: float, n_prm: int, expand: bool):
    """(residual, jacobian, finish) of the free dofs' unknowns z and the known ``prm``.

    ``hht_residual(z, prm) -> G``, the scaled residual of the free rows; ``hht_jacobian(z, prm) ->
    (dG/dz, G)``, sparse; ``hht_finish(z, prm) -> (x1, res, done)``, the state after the step (the
    multipliers from the fixed rows), the final max |G|, and whether that converges the step: res at
    most tol, or the round-off floor of the coordinates (:func:`roundoff_tolerance`).
    """
    n, free, ell = m.n_dof, lay.free, lay.ell
    gamma, beta = hht_coefficients(alpha)
    z, P = ca.MX.sym("z", len(free)), ca.MX.sym("prm", n_prm)
    parts, o = {}, 0
    for key, size in _prm_layout(m):
        parts[key], o = P[o:o + size], o + size
    hp, dp, pp, qp, q0 = parts["h"], parts["d"], parts["p"], parts["q_pred"], parts["q0"]
    # HHT on Phi = q_c - v: (1 + alpha) Phi(q_{n+1}) = alpha Phi(q_n)
    # a moving support: Phi = q_c - v(t), HHT on it as on a fixed one. With alpha < 0 its rates and
    # accelerations follow from Newmark's relations like every dof's (the path's own, taken at t_{n+1},
    # are only first order there: the balance is struck at t_{n+1+alpha}); at alpha = 0 they are the
    # path's, since Newmark's accelerations of a prescribed path oscillate undamped (a pendulum on a
    # shaking pivot, dt = 1 ms: its reaction 223 N off instead of 57 N, the rest being the stress-free
    # rod's own undamped axial vibration; the energy balance of order 2 instead of 1.2)
    to0, to1 = (parts["to0"], parts["to1"]) if m.moving else (ca.DM(lay.fixed_to), ca.DM(lay.fixed_to))
    q_fix = to1 + alpha / (1 + alpha) * (q0 - to0)
    is_fixed = np.zeros(n)
    is_fixed[lay.fixed] = 1.0
    du = ell * lay.spread(z) + ca.DM(is_fixed) * (q_fix - qp)  # q_{n+1} - q_pred: never formed as a difference
    q1 = qp + du
    qdd1 = du / (beta * hp**2)
    qd1 = parts["qd_pred"] + gamma * hp * qdd1
    if m.moving and alpha == 0.0:
        free_mask = ca.DM(1.0 - is_fixed)
        qdd1 = free_mask * qdd1 + parts["vdd1"]
        qd1 = free_mask * qd1 + parts["vd1"]
    q_alpha = (1 + alpha) * q1 - alpha * q0  # where q''_{n+1} and the weighted forces act
    coef = ca.vertcat(gamma / (beta * hp), 1 / (beta * hp**2))
    g = m.gravity(pp)
    R = R_t = -alpha * parts["f_n"] - parts["f_ext"]
    blocks = []
    for grp in m.groups:
        args = [gather(v, grp) for v in (q1, qd1, qdd1)] + ([gather(q_alpha, grp)] if alpha != 0.0 else [])
        args += [grp.props(pp), g, coef]
        fr, fk = (hht_kernel(grp.kind, alpha, m.inertia, tangent) for tangent in (False, True))
        rep = [fr.n_in() - 2, fr.n_in() - 1]  # g and c: the same for every element
        R = R + scatter(fr.map(f"{fr.name()}_{grp.n}", "serial", grp.n, rep, [])(*args), grp, n)
        r_e, K_e = fk.map(f"{fk.name()}_{grp.n}", "serial", grp.n, rep, [])(*args)
        R_t = R_t + scatter(r_e, grp, n)  # the same residual, from the kernel that also gives K
        blocks.append(K_e)
    row = -np.ones(n, dtype=int)
    row[free] = np.arange(len(free))
    asm = MatrixAssembly(m.groups, row, row)
    fr_idx = np.array(free, dtype=int)
    jnz = asm.nonzeros(blocks) * ca.DM(ell[fr_idx[asm.nz_cols]]) / (dp * ell)[fr_idx[asm.nz_rows].tolist()]
    scale_f = (dp * ell)[free]
    cse = {"cse": True}
    resid = ca.Function("hht_residual", [z, P], [R[free] / scale_f], ["z", "prm"], ["G"], cse)
    jac = ca.Function("hht_jacobian", [z, P], [ca.MX(asm.sparsity, jnz), R_t[free] / scale_f], ["z", "prm"],
                      ["jac_G_z", "G"], cse)
    # the residual once more at the solution, with the fixed rows that give the multipliers
    resid_all = ca.Function("hht_residual_all", [z, P], [R[free] / scale_f, R[lay.fixed]], ["z", "prm"],
                            ["G", "r_fixed"], cse)
    if expand:
        resid, jac, resid_all = resid.expand(), jac.expand(), resid_all.expand()
    G1, r_fixed = resid_all(z, P)
    lam1 = -r_fixed / (1 + alpha) if lay.fixed else ca.MX(0, 1)
    x1 = ca.densify(ca.vertcat(q1, qd1, qdd1, lam1))  # dense: the C interface is plain arrays
    res = ca.norm_inf(G1) if free else ca.MX(0)
    floor = ROUNDOFF_FLOOR * np.finfo(float).eps * ca.mmax(ca.fabs(q1 / ell))
    done = res <= ca.fmax(tol, floor)
    finish = ca.Function("hht_finish", [z, P], [x1, res, done], ["z", "prm"], ["x1", "res", "done"])
    return resid, jac, finish


def _mapped(grp, f: ca.Function, *args):
    """``f`` of every element of ``grp``; its inputs named g (gravity) are the same for all."""
    rep = [i for i in range(f.n_in()) if f.name_in(i) == "g"]
    return f.map(f"{f.name()}_{grp.n}", "serial", grp.n, rep, [])(*args)


def _scale(m: Model, alpha: float) -> ca.Function:
    """``hht_scale(q, qd, p, h) -> d``: the rotation-invariant diagonal of S (Eq. 9) at a state."""
    n = m.n_dof
    gamma, beta = hht_coefficients(alpha)
    q, qd, p, h = ca.MX.sym("q", n), ca.MX.sym("qd", n), ca.MX.sym("p", m.n_p), ca.MX.sym("h")
    diag = [ca.MX.zeros(n) for _ in range(3)]
    for grp in m.groups:
        out = _mapped(grp, kernel(grp.kind, "scale", m.inertia), gather(q, grp), gather(qd, grp), grp.props(p),
                      m.gravity(p))
        diag = [dg + scatter(v, grp, n) for dg, v in zip(diag, out, strict=True)]
    dm, dc, dk = diag
    dS = dm / (beta * h**2) + gamma / (beta * h) * ca.fabs(dc) + ca.fabs(dk)
    # Average x and y per node: the trace of a 2x2 block does not change under rotation.
    avg = ca.vertcat(*[(dS[3 * k] + dS[3 * k + 1]) / 2 if i < 2 else dS[3 * k + 2]
                       for k in range(n // 3) for i in range(3)])
    floor = 1e-12 * ca.mmax(avg) + 1e-300
    return ca.Function("hht_scale", [q, qd, p, h], [ca.densify(ca.fmax(avg, floor))], ["q", "qd", "p", "h"], ["d"])


def _initial(m: Model, lay: _Layout) -> ca.Function:
    """``hht_initial(q, qd, t, p) -> (qdd, lam)``: consistent accelerations and multipliers (index-1
    form of Eq. 1): the fixed dofs accelerate as their supports do (not at all unless they move),
    M_ff qdd_f = -(h + f_int - g - f_ext + M qdd_c)_f, and the multipliers balance the fixed rows."""
    n = m.n_dof
    q, qd, t, p = ca.MX.sym("q", n), ca.MX.sym("qd", n), ca.MX.sym("t"), ca.MX.sym("p", m.n_p)
    hh, f_int, g = m.forces(q, qd, p)
    rhs = hh + f_int - g - m.load(t, p)
    M = m.mass(q, p)
    qdd_c = ca.mtimes(lay.reactions(), m.prescribed(t)[2]) if m.moving else ca.MX.zeros(n)
    shifted = rhs + ca.mtimes(M, qdd_c) if m.moving else rhs
    qdd = qdd_c + lay.spread(-ca.solve(M[lay.free, lay.free], shifted[lay.free], "qr") if lay.free else ca.MX(0, 1))
    lam = -(ca.mtimes(M, qdd) + rhs)[lay.fixed] if lay.fixed else ca.MX(0, 1)
    return ca.Function("hht_initial", [q, qd, t, p], [ca.densify(qdd), ca.densify(lam)], ["q", "qd", "t", "p"],
                       ["qdd", "lam"])


def _post(m: Model) -> ca.Function:
    """``hht_post(x, t, p) -> y``: what a result reports per state (see :attr:`HHT.post`)."""
    n = m.n_dof
    x, t, p = ca.MX.sym("x", 3 * n + m.n_con), ca.MX.sym("t"), ca.MX.sym("p", m.n_p)
    q, qd, lam = x[:n], x[n:2 * n], x[3 * n:]
    T, Ve, Vg = m.energy(q, qd, p)
    power = ca.dot(m.load(t, p), qd) + m.follower_power(q, qd, p)
    if m.moving:  # a moving support works on the structure: -lambda (its force) times its velocity
        power -= ca.dot(lam, qd[[c.dof for c in m.constraints]])
    y = ca.vertcat(T, Ve, Vg, power, m.dissipation(q, qd, p),
                   m.outputs(q, qd, lam, p), m.local_rotations(q))
    return ca.Function("hht_post", [x, t, p], [ca.densify(y)], ["x", "t", "p"], ["y"])


def _step_blocks(m: Model, lay: _Layout, alpha: float, prepare: ca.Function, resid: ca.Function,
                 finish: ca.Function, expand: bool) -> ca.Function:
    """``hht_step_sensitivity(x0, t0, p, h, d, x1) -> (G_z, G_w, X_z, X_w)``: the blocks of the step's
    exact derivative by the implicit-function theorem. With G(z, prm(w)) = 0 and x1 = X(z, prm(w)),
    w = (x0, t0, p, h): dx1/dw = X_w - X_z G_z^-1 G_w, one sparse QR of G_z per step. CasADi's
    generic rootfinder derivative gives the same numbers but differentiates through the Newton
    solve in every direction: about twice the run time, and for the sensitivities' 50-odd
    directions 3x the code to compile."""
    n, nx = m.n_dof, 3 * m.n_dof + m.n_con
    _, beta = hht_coefficients(alpha)
    z = ca.MX.sym("z", len(lay.free))
    w = ca.MX.sym("w", nx + 1 + m.n_p + 1)  # the blocks are differentiated in w, then called on the inputs
    o = np.cumsum([0, nx, 1, m.n_p, 1])
    d = ca.MX.sym("d", n)
    _, prm = prepare(*(w[o[i]:o[i + 1]] for i in range(4)), d)
    G, X = resid(z, prm), finish(z, prm)[0]
    blocks = ca.Function("hht_step_blocks", [z, w, d], [ca.jacobian(e, v) for e in (G, X) for v in (z, w)],
                         ["z", "w", "d"], ["G_z", "G_w", "X_z", "X_w"])
    if expand:
        blocks = blocks.expand()
    x0, t0, p, h = ca.MX.sym("x0", nx), ca.MX.sym("t0"), ca.MX.sym("p", m.n_p), ca.MX.sym("h")
    x1 = ca.MX.sym("x1", nx)
    q_pred = x0[:n] + h * x0[n:2 * n] + (0.5 - beta) * h**2 * x0[2 * n:3 * n]
    z_of_x1 = ((x1[:n] - q_pred) / lay.ell)[lay.free]  # the unknowns that give x1
    return ca.Function("hht_step_sensitivity", [x0, t0, p, h, d, x1],
                       list(blocks(z_of_x1, ca.vertcat(x0, t0, p, h), d)),
                       ["x0", "t0", "p", "h", "d", "x1"], ["G_z", "G_w", "X_z", "X_w"])
