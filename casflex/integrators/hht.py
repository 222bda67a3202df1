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
(``expand``, :func:`expand_by_default`). On the mapped path the step's own update assembles the
Jacobian straight into the banded LU's storage, unscaled (:mod:`casflex.integrators.newton_band`);
``hht_jacobian`` (the sparse scaled dG/dz) serves CasADi's Newton and the derivatives.

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

from casflex.integrators.band import band_lu
from casflex.integrators.directions import step_directions
from casflex.integrators.hht_pieces import (
    ROUNDOFF_FLOOR,
    Layout,
    hht_coefficients,
    initial_function,
    newton_functions,
    newton_updates,
    post_function,
    prepare_function,
    roundoff_tolerance,
    scale_function,
    step_blocks,
)
from casflex.integrators.modified import ModifiedNewton
from casflex.integrators.newton_band import band_newton
from casflex.model import Model

__all__ = ["HHT", "check_newton", "hht_coefficients", "roundoff_tolerance", "ROUNDOFF_FLOOR", "NEWTON"]

#: The Newton variants of simulate (HHT.newton).
NEWTON = ("exact", "modified")
#: Up to this many elements the Newton functions are expanded into flat SX (see expand_by_default).
EXPAND_ELEMENTS = 8


def check_newton(tol: float, max_iter: int, newton: str) -> None:
    """ValueError naming the field when the Newton settings of a step are not usable (the one place that says
    so: :class:`HHT` and :class:`casflex.simulate.Stepping`)."""
    if not (isinstance(tol, float) and 0.0 < tol < 1e-2):
        raise ValueError(f"tol: expected a float in (0, 1e-2), got {tol!r}")
    if not (isinstance(max_iter, int) and max_iter >= 1):
        raise ValueError(f"max_iter: expected an integer >= 1, got {max_iter!r}")
    if newton not in NEWTON:
        raise ValueError(f"newton: expected one of {NEWTON}, got {newton!r}")


def _inline(f: ca.Function, *args: ca.MX) -> list[ca.MX]:
    """``f(*args)``, an MX Function's graph written into the caller's: each Function boundary in the
    generated code copies the outputs (the band storage's 2324 numbers at 32 elements per bar, twobar)."""
    return f.call(list(args), f.is_a("MXFunction"), False)


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
    _band: int = field(default=0, init=False, repr=False)  # the Newton matrix's bandwidth (band.py)

    def __post_init__(self) -> None:
        hht_coefficients(self.alpha)
        check_newton(self.tol, self.max_iter, self.newton)
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
        lay = Layout.of(m, ell)
        expand = self.expand if self.expand is not None else expand_by_default(m)
        prepare = prepare_function(m, lay, self.alpha)
        resid, jac, finish = newton_functions(m, lay, self.alpha, self.tol, prepare.nnz_out(1), expand)

        # The first Newton update solves with the banded LU (band.py); when the residual after it is
        # above tol, CasADi's Newton (sparse QR) goes on, from that point or, if the update made things
        # worse, from the guess. Even a guess with G just under tol gets its update: G scales a force by
        # d ~ M / (beta h^2), so at a small step such a guess carries acceleration errors up to
        # tol l / (beta h^2): 0.05 m/s^2 at h = 1.25e-5 s, which accumulate in the velocities (7.6e-6 m
        # over 0.4 s).
        band = band_lu(jac.sparsity_out(0), "hht_band", late=lay.n_mu)
        factor, apply = (band.factor.expand(), band.apply.expand()) if expand else (band.factor, band.apply)
        object.__setattr__(self, "_band", band.bandwidth)
        z0, P = ca.MX.sym("z0", resid.nnz_in(0)), ca.MX.sym("prm", resid.nnz_in(1))
        if expand or not m.groups:  # (the band path gathers from an element group's kernel output)
            J0, G0 = jac(z0, P)
            F0 = factor(J0.nz[:])
            dz0 = dz0_step = apply(F0, G0)
            F, r = ca.MX.sym("F", band.size), ca.MX.sym("r", resid.nnz_out(0))
            fast = {"rhs": ca.Function("hht_rhs", [z0, P], [resid(z0, P)] * 2, ["z", "prm"], ["G", "r"]),
                    "band_update": ca.Function("hht_band_update", [F, r, P], [apply(F, r)], ["F", "r", "prm"], ["dz"]),
                    "finish_step": finish}
        else:  # the same update, assembled straight into the band storage (newton_band.py)
            fast = band_newton(m, lay, self.alpha, self.tol, prepare.nnz_out(1), band)
            first, cols, rows, G0, r0, cols_s = _inline(fast["jacobian_band"], z0, P)
            piv, U, L = band.factor_parts(first, cols, rows)
            F0 = ca.vertcat(piv, ca.vec(U), ca.vec(L))
            dz0 = band.solve_parts(piv, U, L, r0) / cols_s
            dz0_step = band.factor_solve_parts(first, cols, rows, r0) / cols_s  # the same numbers, L not kept
        update = ca.Function("hht_update", [z0, P], [z0 - dz0, ca.norm_inf(G0), F0], ["z0", "prm"],
                             ["z1", "g0", "F"])
        # the step's: without the factors, which it does not keep (an output is computed and copied when unused), and
        # with the guess's residual G0 itself: its norm only matters when the update did not converge the step, and is
        # taken there (hht_more; a pass over G0 with a libm call per entry, 4k of 399k instructions at 32 el./bar)
        fast["update_step"] = ca.Function("hht_update_step", [z0, P], [z0 - dz0_step, ca.densify(G0)], ["z0", "prm"],
                                          ["z1", "G0"])
        # CasADi's Newton on the step's own residual and end (the same numbers as resid's and finish's, one copy of
        # the code in a compiled step), with the sparse scaled Jacobian
        G_step = fast["rhs"](z0, P)[0]
        newton = ca.rootfinder("hht_newton", "fast_newton", ca.Function("hht_residual_step", [z0, P], [G_step]), {
            "abstol": self.tol, "abstolStep": 1e-2 * self.tol**0.5, "max_iter": max(self.max_iter - 1, 1),
            "error_on_fail": False, "jacobian_function": jac})
        xa, ra = ca.MX.sym("x1", self.nx), ca.MX.sym("res")
        keep = ca.Function("hht_done", [z0, P, xa, ra], [xa, ra])
        more = ca.Function("hht_more", [z0, P, xa, ra],
                           fast["finish_step"](newton(z0, P), P)[:2] if self.max_iter > 1 else [xa, ra])
        # the step's: Newton goes on from the update or, if the update made things worse, from the guess
        z1, G0 = ca.MX.sym("z1", z0.numel()), ca.MX.sym("G0", resid.nnz_out(0))
        keep_step = ca.Function("hht_done_step", [z0, z1, G0, P, xa, ra], [xa, ra])
        more_step = ca.Function("hht_more_step", [z0, z1, G0, P, xa, ra],
                                more(ca.if_else(ra < ca.norm_inf(G0), z1, z0), P, xa, ra))
        post = post_function(m)
        post = post.expand() if expand else post  # per state, and for a few elements flat code is 3x faster
        self._fn.update(prepare=prepare, residual=resid, jacobian=jac, finish=finish, flat=expand or not m.groups,
                        scale=scale_function(m, self.alpha), initial=initial_function(m, lay), post=post,
                        update=update, newton=newton, band_factor=factor, band_apply=apply,
                        more=ca.Function.conditional("hht_converge", [keep], more),
                        more_step=ca.Function.conditional("hht_converge_step", [keep_step], more_step), **fast)
        self._fn["sensitivity"] = step_blocks(m, lay, self.alpha, prepare, resid, finish, expand)
        self._fn["step"] = self._step_with_derivative()

    def _step_with_derivative(self) -> ca.Function:
        """prepare -> newton -> finish as one Function, whose Jacobian is the implicit-function
        derivative written out (:func:`step_blocks`): dx1/dw = X_w - X_z G_z^-1 G_w."""
        m = self.model
        n, nx, npar = m.n_dof, self.nx, m.n_p
        x0, t0, p, h, d = self._fn["prepare"].mx_in()
        # on the mapped path the pieces stay Functions: written into one, their loops made gcc's value-range
        # passes superlinear (twobar, 8 el./bar: 43 % more of cc1's instructions for the library); the flat
        # path's are small, and written into the step they save their outputs' copies (3 % at 1 el./bar)
        call = _inline if self._fn["flat"] else (lambda f, *a: f(*a))
        zg, pr = call(self._fn["prepare"], x0, t0, p, h, d)
        z1, G0 = call(self._fn["update_step"], zg, pr)
        xa, ra, done = call(self._fn["finish_step"], z1, pr)
        X1, res1 = self._fn["more_step"](1 - done, zg, z1, G0, pr, xa, ra)
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

    @property
    def bandwidth(self) -> int:
        """The bandwidth of the Newton matrix in the banded LU's order (:mod:`casflex.integrators.band`):
        a step's factorisation costs O(n b^2) for n unknowns."""
        return self._band

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
        z1, G0 = self._fn["update_step"](z0, prm)
        x1, res, done = self._fn["finish_step"](z1, prm)
        updates = 1
        if not bool(done) and self.max_iter > 1:
            z = self._fn["newton"](z1 if float(res) < float(ca.norm_inf(G0)) else z0, prm)
            updates += newton_updates(self._fn["newton"])
            x1, res, _ = self._fn["finish_step"](z, prm)
        return np.array(x1).ravel(), float(res), updates

    def step_residual(self, x0: np.ndarray, x1: np.ndarray, t0: float, p: np.ndarray, h: float,
                      d: np.ndarray) -> float:
        """The scaled residual (max norm, Eq. 4 on the free dofs) that the step x0 -> x1 from t0 leaves
        in the equations as this process evaluates them: how well a state x1 computed elsewhere
        (compiled code, another machine) solves this step; a step is accepted at :meth:`tolerance`."""
        n, ell = self.model.n_dof, self._ell
        lay = Layout.of(self.model, ell)
        _, prm = self._fn["prepare"](x0, t0, p, h, d)
        q_pred = np.array(prm[:n]).ravel()  # the unknowns are z = (q_{n+1} - q_pred) / l on the free dofs
        z = ((np.asarray(x1[:n]) - q_pred) / ell)[lay.free]
        if lay.n_mu:  # and nu = mu / s for the joints' multipliers
            s = np.array(lay.mu_scale(ca.DM(d))).ravel()
            z = np.concatenate([z, np.asarray(x1[len(x1) - lay.n_mu:]) / s])
        return float(np.max(np.abs(np.array(self._fn["residual"](z, prm)).ravel()), initial=0.0))

    def sensitivity(self, n_steps: int, n_dir: int | None = None) -> ca.Function:
        """``hht_sensitivity_<N>_<D>(x0, S0, P, t0, p, h, d) -> (X, S, res)``: N steps that also carry
        D forward sensitivities S = dx/dw of the state in D directions of the unknowns w.

        S0 (nx, D) is dx0/dw and P (n_p, D) is dp/dw, both constant along the run; the default
        D = nx + n_p with S0 = [I 0] and P = [0 I] gives every derivative in (x_0, p), while a fit
        seeds only its own unknowns' directions (four parameters: D = 4, a thirteenth of twobar's 52).
        S (nx, N D) holds dx_k/dw after each step, side by side; X and res as in :meth:`trajectory`.
        Each step carries them by the implicit-function derivative of its Newton solve
        (:func:`~casflex.integrators.directions.step_directions`).
        """
        nx, npar = self.nx, self.model.n_p
        nd = nx + npar if n_dir is None else int(n_dir)
        key, one_key = f"sens{n_steps}_{nd}", f"sens_step_{nd}"
        if one_key not in self._fn:
            # one step, shared by every chunk length in D directions: a library holding the chunk and the single
            # step (casflex.identification.sensitivity) then carries its code once, not twice (the leg's 14
            # directions: 1.6 MB of C and 39 s of gcc -O1 before, half that after)
            X0, T0, Pm, H, D = self.step.mx_in()
            S0, P0 = ca.MX.sym("S0", nx, nd), ca.MX.sym("P", npar, nd)
            carry = step_directions(self.model, Layout.of(self.model, self._ell), self.alpha, self._fn, nd)
            X1, res = self.step(X0, T0, Pm, H, D)
            self._fn[one_key] = ca.Function("hht_sensitivity_step", [X0, S0, P0, T0, Pm, H, D],
                                            [X1, carry(X0, S0, P0, T0, Pm, H, D, X1), res],
                                            ["x0", "S0", "P", "t0", "p", "h", "d"], ["x1", "S1", "res"])
        if key not in self._fn:
            one = self._fn[one_key]
            X0, S0, P0, T0, Pm, H, D = one.mx_in()
            acc = one.mapaccum(f"hht_sensitivity_steps_{n_steps}_{nd}", n_steps, [0, 1], [0, 1])
            grid = T0 + H * ca.DM(np.arange(n_steps)).T
            X, S, R = acc(X0, S0, ca.repmat(P0, 1, n_steps), grid, ca.repmat(Pm, 1, n_steps),
                          ca.repmat(H, 1, n_steps), ca.repmat(D, 1, n_steps))
            self._fn[key] = ca.Function(f"hht_sensitivity_{n_steps}_{nd}", [X0, S0, P0, T0, Pm, H, D], [X, S, R],
                                        ["x0", "S0", "P", "t0", "p", "h", "d"], ["X", "S", "res"])
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
