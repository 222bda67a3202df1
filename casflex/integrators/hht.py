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

Newton (Eqs. 8-10) uses the exact Jacobian from AD (the paper drops the inertia derivatives).
The unknowns and equations are scaled so that one dimensionless tolerance works for any
stiffness or mass: each momentum row i is divided by d_i * l_i, d_i a rotation-invariant
diagonal of the iteration matrix S = M/(beta h^2) + gamma/(beta h) C + K (Eq. 9) at the
initial state and l_i the characteristic length (m) for translations or 1 for rotations;
the unknowns are u = (q_{n+1} - q_guess)/l and mu = lambda / (d l) of the constrained dof.
Newton stops when the scaled residual is below ``tol``, or when a Newton update is below
0.01 sqrt(tol): in the quadratic regime the residual after that update is ~1e-4 tol, which
saves the Jacobian evaluation that would only confirm convergence. Either way the step
returns its final residual, recomputed, and the driver rejects any step above ``tol`` (raised to
the round-off floor of far-off coordinates, :meth:`HHT.tolerance`).
The Newton guess is the constant-acceleration predictor (q''_{n+1} = q''_n, lambda_{n+1} =
lambda_n), better than the paper's q''_{n+1} = 0 (Eq. 6); the converged step is the same.

The step is a CasADi Function built from three pieces, ``prepare`` -> ``newton`` (CasADi's
code-generatable ``fast_newton`` rootfinder) -> ``finish``, so that the Python driver can
call them one by one and read Newton's iteration count, while :meth:`HHT.trajectory` chains
steps with ``mapaccum`` into one differentiable, exportable Function.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from casflex.model import Model

__all__ = ["HHT", "hht_coefficients", "roundoff_tolerance", "ROUNDOFF_FLOOR"]

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

    The state vector x stacks [q, qd, qdd, lam], shape (3 n_dof + n_con,).
    """

    model: Model
    alpha: float = 0.0
    tol: float = 1e-12
    max_iter: int = 25
    _fn: dict = field(default_factory=dict, init=False, repr=False)
    _ell: np.ndarray = field(default=None, init=False, repr=False)  # characteristic length per dof

    def __post_init__(self) -> None:
        hht_coefficients(self.alpha)
        if not (isinstance(self.tol, float) and 0.0 < self.tol < 1e-2):
            raise ValueError(f"tol: expected a float in (0, 1e-2), got {self.tol!r}")
        if not (isinstance(self.max_iter, int) and self.max_iter >= 1):
            raise ValueError(f"max_iter: expected an integer >= 1, got {self.max_iter!r}")
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
        n, nc = m.n_dof, m.n_con
        gamma, beta = hht_coefficients(self.alpha)
        a = self.alpha
        ell = np.where(m.is_rotation, 1.0, m.length_scale)
        object.__setattr__(self, "_ell", ell)
        cdof = [c.dof for c in m.constraints]
        ell_c = ell[cdof] if nc else np.zeros(0)

        x0 = ca.SX.sym("x0", self.nx)
        t0 = ca.SX.sym("t0")
        h = ca.SX.sym("h")
        p = ca.SX.sym("p", m.n_p)
        d = ca.SX.sym("d", n)
        q0, qd0, qdd0, lam0 = x0[:n], x0[n:2 * n], x0[2 * n:3 * n], x0[3 * n:]
        s_lam = d[cdof] * ell_c if nc else ca.SX(0, 1)

        def F(q, qd, lam):
            hh, f_int, g = m.forces(q, qd, p)
            _, B = m.constraint(q)
            return hh + f_int + ca.mtimes(B.T, lam) - g

        # Parameters of the Newton problem: everything known at the start of the step.
        q_pred = q0 + h * qd0 + (0.5 - beta) * h**2 * qdd0
        qd_pred = qd0 + (1 - gamma) * h * qdd0
        f_n = F(q0, qd0, lam0)
        phi_n = m.constraint(q0)[0]
        f_ext = m.load(t0 + (1 + a) * h, p)
        prm = ca.vertcat(q_pred, qd_pred, f_n, phi_n, f_ext, p, h, d, q0)
        z_guess = ca.vertcat(beta * h**2 * qdd0 / ell, lam0 / s_lam if nc else ca.SX(0, 1))
        self._fn["prepare"] = ca.Function("hht_prepare", [x0, t0, p, h, d], [z_guess, prm],
                                          ["x0", "t0", "p", "h", "d"], ["z0", "prm"], {"cse": True})

        z = ca.SX.sym("z", n + nc)
        P = ca.SX.sym("prm", prm.numel())
        o = 0
        parts = {}
        for key, size in (("q_pred", n), ("qd_pred", n), ("f_n", n), ("phi_n", nc), ("f_ext", n),
                          ("p", m.n_p), ("h", 1), ("d", n), ("q0", n)):
            parts[key] = P[o:o + size]
            o += size
        hp, dp, pp = parts["h"], parts["d"], parts["p"]
        u, mu = z[:n], z[n:]
        q1 = parts["q_pred"] + ell * u
        qdd1 = ell * u / (beta * hp**2)
        qd1 = parts["qd_pred"] + gamma * hp * qdd1
        lam1 = (dp[cdof] * ell_c) * mu if nc else ca.SX(0, 1)
        hh1, f_int1, g1 = m.forces(q1, qd1, pp)
        phi1, B1 = m.constraint(q1)
        f1 = hh1 + f_int1 + ca.mtimes(B1.T, lam1) - g1
        q_alpha = (1 + a) * q1 - a * parts["q0"]  # where q''_{n+1} and the weighted forces act
        r = ca.mtimes(m.mass(q_alpha, pp), qdd1) + (1 + a) * f1 - a * parts["f_n"] - parts["f_ext"]
        r_phi = (1 + a) * phi1 - a * parts["phi_n"]
        G = ca.vertcat(r / (dp * ell), r_phi / ell_c if nc else ca.SX(0, 1))
        cse = {"cse": True}  # common subexpression elimination: ~20 % fewer operations
        resid = ca.Function("hht_residual", [z, P], [G], ["z", "prm"], ["G"], cse)
        jac = ca.Function("hht_jacobian", [z, P], [ca.jacobian(G, z), G], ["z", "prm"], ["jac_G_z", "G"], cse)
        self._fn["residual"] = resid
        self._fn["newton"] = ca.rootfinder(
            "hht_newton", "fast_newton", resid,
            {"abstol": self.tol, "abstolStep": 1e-2 * self.tol**0.5, "max_iter": self.max_iter, "error_on_fail": False,
             "jacobian_function": jac},
        )
        x1 = ca.vertcat(q1, qd1, qdd1, lam1)
        self._fn["finish"] = ca.Function("hht_finish", [z, P], [x1, ca.norm_inf(G)], ["z", "prm"], ["x1", "res"], cse)

        # Scaling d: rotation-invariant diagonal of S (Eq. 9) at a given state.
        qs, qds = ca.SX.sym("q", n), ca.SX.sym("qd", n)
        hh, f_int, g = m.forces(qs, qds, p)
        Mq = m.mass(qs, p)
        K = ca.jacobian(f_int - g, qs)
        C = ca.jacobian(hh, qds)
        diag = ca.diag(Mq) / (beta * h**2) + gamma / (beta * h) * ca.fabs(ca.diag(C)) + ca.fabs(ca.diag(K))
        # Average x and y per node: the trace of a 2x2 block does not change under rotation.
        avg = ca.vertcat(*[(diag[3 * k] + diag[3 * k + 1]) / 2 if i < 2 else diag[3 * k + 2]
                           for k in range(n // 3) for i in range(3)])
        floor = 1e-12 * ca.mmax(avg) + 1e-300
        self._fn["scale"] = ca.Function("hht_scale", [qs, qds, p, h], [ca.fmax(avg, floor)],
                                        ["q", "qd", "p", "h"], ["d"])

        # Consistent initial accelerations and multipliers (index-1 form of Eq. 1).
        qdd_s = ca.SX.sym("qdd", n)
        lam_s = ca.SX.sym("lam", nc)
        ts = ca.SX.sym("t")
        r_eq, _ = m.equilibrium(qs, qds, qdd_s, lam_s, ts, p)
        _, Bs = m.constraint(qs)
        A = ca.blockcat([[Mq, Bs.T], [Bs, ca.SX(nc, nc)]])
        rhs0 = -ca.substitute(r_eq, ca.vertcat(qdd_s, lam_s), ca.DM.zeros(n + nc))
        bdot = -ca.jtimes(ca.mtimes(Bs, qds), qs, qds)
        qsm, qdsm, tsm, psm = ca.MX.sym("q", n), ca.MX.sym("qd", n), ca.MX.sym("t"), ca.MX.sym("p", m.n_p)
        sys_fn = ca.Function("initial_system", [qs, qds, ts, p], [A, ca.vertcat(rhs0, bdot)])
        Am, bm = sys_fn(qsm, qdsm, tsm, psm)
        sol = ca.solve(Am, bm, "qr")
        self._fn["initial"] = ca.Function("hht_initial", [qsm, qdsm, tsm, psm], [sol[:n], sol[n:]],
                                          ["q", "qd", "t", "p"], ["qdd", "lam"])

        # What a result reports per state: energies, power of the loads, joint outputs.
        xs = ca.SX.sym("x", self.nx)
        qx, qdx, lamx = xs[:n], xs[n:2 * n], xs[3 * n:]
        T, Ve, Vg = m.energy(qx, qdx, p)
        power = ca.dot(m.load(ts, p), qdx)
        post = ca.vertcat(T, Ve, Vg, power, m.outputs(qx, lamx, p), m.local_rotations(qx))
        self._fn["post"] = ca.Function("hht_post", [xs, ts, p], [post],
                                       ["x", "t", "p"], ["y"], {"cse": True})

        # The step's exact derivative by the implicit-function theorem, written out: with
        # G(z, prm(w)) = 0 and x1 = X(z, prm(w)), w = (x0, t0, p, h),
        #     dx1/dw = X_w - X_z G_z^-1 G_w,
        # one sparse QR of G_z per step. CasADi's generic rootfinder derivative gives the same
        # numbers at about twice the cost; d only scales Newton and has no effect on x1.
        x1s = ca.SX.sym("x1", self.nx)
        zsym = ca.SX.sym("z", n + nc)
        _, prm_w = self._fn["prepare"](x0, t0, p, h, d)
        Gw = resid(zsym, prm_w)
        Xw = self._fn["finish"](zsym, prm_w)[0]
        wsym = ca.vertcat(x0, t0, p, h)
        q_pred_w = x0[:n] + h * x0[n:2 * n] + (0.5 - beta) * h**2 * x0[2 * n:3 * n]
        z_of_x1 = ca.vertcat((x1s[:n] - q_pred_w) / ell, x1s[3 * n:] / s_lam if nc else ca.SX(0, 1))
        blocks = [ca.substitute(e, zsym, z_of_x1) for e in (ca.jacobian(Gw, zsym), ca.jacobian(Gw, wsym),
                                                            ca.jacobian(Xw, zsym), ca.jacobian(Xw, wsym))]
        sens = ca.Function("hht_step_sensitivity", [x0, t0, p, h, d, x1s], blocks,
                           ["x0", "t0", "p", "h", "d", "x1"], ["G_z", "G_w", "X_z", "X_w"], cse)
        self._fn["sensitivity"] = sens

        # The step as one Function.
        X0, T0, Pm, H, D = (ca.MX.sym(k, s) for k, s in (("x0", self.nx), ("t0", 1), ("p", m.n_p), ("h", 1), ("d", n)))
        zg, pr = self._fn["prepare"](X0, T0, Pm, H, D)
        zs = self._fn["newton"](zg, pr)
        X1, res = self._fn["finish"](zs, pr)
        OX1, ORES = ca.MX.sym("out_x1", self.nx), ca.MX.sym("out_res")
        G_z, G_w, X_z, X_w = sens(X0, T0, Pm, H, D, OX1)
        J = X_w - ca.mtimes(X_z, ca.solve(G_z, G_w, "qr"))
        nx, npar = self.nx, m.n_p
        jac = ca.Function("jac_hht_step", [X0, T0, Pm, H, D, OX1, ORES],
                          [J[:, :nx], J[:, nx], J[:, nx + 1:nx + 1 + npar], J[:, nx + 1 + npar], ca.MX(nx, n),
                           ca.MX(1, nx), ca.MX(1, 1), ca.MX(1, npar), ca.MX(1, 1), ca.MX(1, n)],
                          ["x0", "t0", "p", "h", "d", "out_x1", "out_res"],
                          [f"jac_{o}_{i}" for o in ("x1", "res") for i in ("x0", "t0", "p", "h", "d")])
        self._fn["step"] = ca.Function("hht_step", [X0, T0, Pm, H, D], [X1, res],
                                       ["x0", "t0", "p", "h", "d"], ["x1", "res"],
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
        joint outputs (``model.output_names``), local rotations of the beam elements (rad,
        ``model.local_rotation_names``)] of one state."""
        return self._fn["post"]

    @property
    def pieces(self) -> tuple[ca.Function, ca.Function, ca.Function]:
        """(prepare, newton, finish): the step in three calls, for the stepping driver."""
        return self._fn["prepare"], self._fn["newton"], self._fn["finish"]

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
