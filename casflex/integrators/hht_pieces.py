"""The pieces of an HHT-alpha step (:mod:`casflex.integrators.hht`): the free and fixed dofs and the
joints' multipliers (:class:`Layout`), the step's known quantities (``prepare``), its scaled
residual, Jacobian and final state (``newton_functions``), the Newton scaling, consistent initial
accelerations and multipliers, what a result reports per state, and the blocks of the step's exact
derivative. Each is a named CasADi Function built from the element and joint kernels.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from casflex.elements.kernels import hht_kernel, kernel
from casflex.model import Model
from casflex.model.assembly import MatrixAssembly, gather, scatter, scatter_add, scatter_at
from casflex.model.constraints import gather_at, mapped_joint, split

__all__ = ["Layout", "ROUNDOFF_FLOOR", "newton_updates", "hht_coefficients", "roundoff_tolerance", "prm_layout",
           "prepare_function", "newton_functions", "newton_terms", "group_args", "mapped_hht",
           "finish_outputs", "scale_function", "initial_function", "post_function", "step_blocks"]

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


@dataclass(frozen=True)
class Layout:
    """The unknowns of Newton: the free dofs (not held by a support) and the joints' multipliers.

    A joint's multipliers mu are solved for with the free dofs as nu = mu / s, s per row the mean
    of d_i l_i over the translations of the joint's nodes (d the Newton scaling, l the lengths): a
    multiplier then enters the scaled rows of its nodes with weights of order 1, as their own
    unknowns do. The constraint rows are scaled by ``ell_mu``: the length scale for rows in metres
    (hinge x, y, a slider's across), 1 for rows in radians.
    """

    n: int
    free: list[int]
    fixed: list[int]
    fixed_to: np.ndarray  # (n,): the supports' values on the fixed dofs, 0 elsewhere
    ell: np.ndarray  # (n,): characteristic length (m) of translations, 1 for rotations
    n_mu: int = 0  # the joints' rows (multipliers)
    ell_mu: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (n_mu,): their rows' scale
    mu_trans: tuple[tuple[int, ...], ...] = ()  # per row: the translations of the joint's nodes

    @classmethod
    def of(cls, m: Model, ell: np.ndarray) -> Layout:
        fixed = [c.dof for c in m.constraints]
        if len(set(fixed)) != len(fixed):
            dup = sorted({m.dof_names[i] for i in fixed if fixed.count(i) > 1})
            raise ValueError(f"dofs {dup} are fixed by more than one support: their reactions are not determined")
        to = np.zeros(m.n_dof)
        to[fixed] = [c.value for c in m.constraints]
        n_mu = len(m.joint_row_names)
        ell_mu = m.joint_scales
        trans: list[tuple[int, ...]] = [()] * n_mu
        for grp in m.joint_groups:
            at, mu_at = split(grp)
            for e in range(grp.n):
                for r in mu_at[e] - m.n_dof:
                    trans[r] = tuple(int(i) for i in at[e] if not m.is_rotation[i])
        return cls(m.n_dof, [i for i in range(m.n_dof) if i not in set(fixed)], fixed, to, ell, n_mu, ell_mu,
                   tuple(trans))

    def mu_scale(self, d: ca.MX | ca.DM) -> ca.MX | ca.DM:
        """s (n_mu,): mu = s nu, from the Newton scaling d (n,) (see the class)."""
        if not self.n_mu:
            return ca.DM(0, 1)
        dl = d * ca.DM(self.ell)
        return ca.vertcat(*[sum(dl[i] for i in t) / len(t) for t in self.mu_trans])

    def spread(self, z: ca.MX) -> ca.MX:
        """The free dofs' values z (n_free,) in a vector of all dofs (zeros at the fixed ones)."""
        slot = np.full(self.n, len(self.free))  # the 0 appended to z
        slot[self.free] = np.arange(len(self.free))
        return ca.vertcat(z, 0)[slot.tolist()]

    def reactions(self) -> ca.DM:
        """B^T (n, n_fixed): the supports' multipliers act on the fixed dofs' rows."""
        B_T = ca.DM.zeros(self.n, len(self.fixed))
        for j, i in enumerate(self.fixed):
            B_T[i, j] = 1.0
        return B_T


def prm_layout(m: Model) -> list[tuple[str, int]]:
    """The known quantities a step's Newton solve takes (``prm``), in this order, with their sizes."""
    n = m.n_dof
    # moving supports: values at t_n and t_{n+1}, rates and accelerations at t_{n+1}
    moving = [("to0", n), ("to1", n), ("vd1", n), ("vdd1", n)] if m.moving else []
    return [("q_pred", n), ("qd_pred", n), ("f_n", n), ("f_ext", n), ("p", m.n_p), ("h", 1), ("d", n), ("q0", n),
            *moving, ("phi0", len(m.joint_row_names))]


def prepare_function(m: Model, lay: Layout, alpha: float) -> ca.Function:
    """``hht_prepare(x0, t0, p, h, d) -> (z0, prm)``: the Newton guess and everything known at the
    start of the step (the Newmark predictors, F_n, the loads at t_alpha, the joints' Phi(q_n))."""
    n, nf = m.n_dof, m.n_fixed
    gamma, beta = hht_coefficients(alpha)
    x0, t0, h, p, d = (ca.MX.sym(k, s) for k, s in (("x0", 3 * n + m.n_con), ("t0", 1), ("h", 1), ("p", m.n_p),
                                                    ("d", n)))
    q0, qd0, qdd0, lam0, mu0 = x0[:n], x0[n:2 * n], x0[2 * n:3 * n], x0[3 * n:3 * n + nf], x0[3 * n + nf:]
    f_n = ca.MX.zeros(n)  # F_n has the weight -alpha
    if alpha != 0.0:
        hh, f_int, g = m.forces(q0, qd0, p)
        f_n = hh + f_int - g + ca.mtimes(lay.reactions(), lam0)
        if lay.n_mu:
            f_n += joint_forces(m, q0, mu0)
    prm = ca.vertcat(q0 + h * qd0 + (0.5 - beta) * h**2 * qdd0, qd0 + (1 - gamma) * h * qdd0, f_n,
                     m.load(t0 + (1 + alpha) * h, p), p, h, d, q0)
    if m.moving:
        v1 = m.prescribed(t0 + h)
        prm = ca.vertcat(prm, *(ca.mtimes(lay.reactions(), v) for v in (m.prescribed(t0)[0], *v1)))
    z_guess = (beta * h**2 * qdd0 / lay.ell)[lay.free]
    if lay.n_mu:  # the multipliers start from the last step's
        prm = ca.vertcat(prm, m.constraint(q0)[0][nf:])
        z_guess = ca.vertcat(z_guess, mu0 / lay.mu_scale(d))
    return ca.Function("hht_prepare", [x0, t0, p, h, d], [ca.densify(z_guess), ca.densify(prm)],
                       ["x0", "t0", "p", "h", "d"], ["z0", "prm"])


def joint_forces(m: Model, q: ca.MX, mu: ca.MX) -> ca.MX:
    """B_J(q)^T mu (n,): the joints' multipliers as generalised forces on the dofs."""
    f = ca.MX.zeros(m.n_dof)
    for grp in m.joint_groups:
        at, mu_at = split(grp)
        out = mapped_joint(grp, "reaction", gather_at(q, at), gather_at(mu, mu_at - m.n_dof), ca.DM(grp.base))
        f += scatter_at(out, at, m.n_dof)
    return f


def _joint_terms(m: Model, lay: Layout, q1: ca.MX, mu1: ca.MX, alpha: float) -> tuple[ca.MX, ca.MX, list]:
    """The joints' part of the HHT equations at (q_{n+1}, mu_{n+1}): (1 + alpha) B^T mu (n,), (1 + alpha)
    Phi (n_mu,), and each joint group's element matrices in (q, mu) for the assembly."""
    n = m.n_dof
    aug, blocks = ca.MX.zeros(n + lay.n_mu), []
    for grp in m.joint_groups:
        at, mu_at = split(grp)
        r_e, K_e = mapped_joint(grp, "hht", gather_at(q1, at), gather_at(mu1, mu_at - n), ca.DM(grp.base),
                                alpha=alpha)
        aug += scatter(r_e, grp, n + lay.n_mu)
        blocks.append(K_e)
    return aug[:n], aug[n:], blocks


def _state(m: Model, lay: Layout, alpha: float, z: ca.MX, parts: dict) -> tuple[ca.MX, ...]:
    """(q1, qd1, qdd1, q_alpha, mu1) at t_{n+1} from the unknowns z = (u, nu) (Newmark's relations)."""
    n, ell, nf = m.n_dof, lay.ell, len(lay.free)
    gamma, beta = hht_coefficients(alpha)
    hp, qp, q0 = parts["h"], parts["q_pred"], parts["q0"]
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
    u = z[:nf] if lay.n_mu else z
    du = ell * lay.spread(u) + ca.DM(is_fixed) * (q_fix - qp)  # q_{n+1} - q_pred: never formed as a difference
    q1 = qp + du
    qdd1 = du / (beta * hp**2)
    qd1 = parts["qd_pred"] + gamma * hp * qdd1
    if m.moving and alpha == 0.0:
        free_mask = ca.DM(1.0 - is_fixed)
        qdd1 = free_mask * qdd1 + parts["vdd1"]
        qd1 = free_mask * qd1 + parts["vd1"]
    q_alpha = (1 + alpha) * q1 - alpha * q0  # where q''_{n+1} and the weighted forces act
    mu1 = lay.mu_scale(parts["d"]) * z[nf:] if lay.n_mu else ca.MX(0, 1)
    return q1, qd1, qdd1, q_alpha, mu1


def group_args(m: Model, alpha: float, z: ca.MX, P: ca.MX, lay: Layout, dofs=gather) -> tuple[dict, tuple, list[list]]:
    """(prm's parts by name, the state (q1, qd1, qdd1, q_alpha, mu1) of the unknowns z, and per element
    group the arguments of its HHT kernel: the element dofs of each state vector (``dofs(v, group)``, by
    default :func:`gather`), properties, gravity g and c)."""
    parts, o = {}, 0
    for key, size in prm_layout(m):
        parts[key], o = P[o:o + size], o + size
    state = _state(m, lay, alpha, z, parts)
    q1, qd1, qdd1, q_alpha, _ = state
    gamma, beta = hht_coefficients(alpha)
    coef = ca.vertcat(gamma / (beta * parts["h"]), 1 / (beta * parts["h"] ** 2))
    g, args = m.gravity(parts["p"]), []
    for grp in m.groups:
        a = [dofs(v, grp) for v in (q1, qd1, qdd1)] + ([dofs(q_alpha, grp)] if alpha != 0.0 else [])
        args.append(a + [grp.props(parts["p"]), g, coef])
    return parts, state, args


def mapped_hht(m: Model, alpha: float, tangent: bool):
    """``evaluate(k, args)`` for :func:`newton_terms`: group k's HHT kernel (``tangent``: with K) mapped
    over its elements, g and c the same for all."""
    def evaluate(k: int, args: list):
        grp = m.groups[k]
        # the padded tangent kernel, which the step's own update maps (newton_band.py): one copy of its code
        f = hht_kernel(grp.kind, alpha, m.inertia, tangent, tangent)
        out = f.map(f"{f.name()}_{grp.n}", "serial", grp.n, [f.n_in() - 2, f.n_in() - 1], [])(*args)
        nd = grp.spec.n_dof
        return (out[0], ca.reshape(out[1][:nd * nd, :], nd, nd * grp.n)) if tangent else out
    return evaluate


def newton_terms(m: Model, lay: Layout, alpha: float, z: ca.MX, P: ca.MX, residual, tangent, dofs=gather) -> dict:
    """The HHT equations of the unknowns z (see :func:`newton_functions`) with the element groups'
    kernel outputs from ``residual(k, args) -> r`` and ``tangent(k, args) -> (r, K)`` (k: the group,
    args: its kernel's arguments, :func:`group_args` with ``dofs``; ``residual`` None: R is R_t): R, R_t (the same
    residual from the two kernels), G, G_t (scaled), the Jacobian's scaled nonzeros jnz and its
    assembly, the state, the element matrices and the unscaled residuals."""
    n, free, ell, nmu = m.n_dof, lay.free, lay.ell, lay.n_mu
    parts, state, args = group_args(m, alpha, z, P, lay, dofs)
    q1, _, _, _, mu1 = state
    dp = parts["d"]
    R = R_t = -alpha * parts["f_n"] - parts["f_ext"]
    blocks = []
    for k, grp in enumerate(m.groups):
        if residual is not None:
            R = scatter_add(R, residual(k, args[k]), grp)
        r_e, K_e = tangent(k, args[k])
        R_t = scatter_add(R_t, r_e, grp)  # the same residual, from the kernel that also gives K
        blocks.append(K_e)
    R = R if residual is not None else R_t
    row = -np.ones(n + nmu, dtype=int)
    row[free] = np.arange(len(free))
    row[n:] = len(free) + np.arange(nmu)
    asm = MatrixAssembly(m.groups + m.joint_groups, row, row)
    scale_f = (dp * ell)[free]
    if nmu:
        f_j, phi_j, j_blocks = _joint_terms(m, lay, q1, mu1, alpha)
        R, R_t, blocks = R + f_j, R_t + f_j, blocks + j_blocks
        phi = phi_j - alpha * parts["phi0"]
        G_phi = phi / ca.DM(lay.ell_mu)
        rows_s = ca.vertcat(scale_f, ca.DM(lay.ell_mu))  # the rows' and the unknowns' scales
        cols_s = ca.vertcat(ca.DM(ell[free]), lay.mu_scale(dp))
        jnz = asm.nonzeros(blocks) * cols_s[asm.nz_cols.tolist()] / rows_s[asm.nz_rows.tolist()]
        G, G_t = ca.vertcat(R[free] / scale_f, G_phi), ca.vertcat(R_t[free] / scale_f, G_phi)
        rhs, rhs_t = ca.vertcat(R[free], phi), ca.vertcat(R_t[free], phi)
    else:
        fr_idx = np.array(free, dtype=int)
        jnz = asm.nonzeros(blocks) * ca.DM(ell[fr_idx[asm.nz_cols]]) / (dp * ell)[fr_idx[asm.nz_rows].tolist()]
        G, G_t = R[free] / scale_f, R_t[free] / scale_f
        rhs, rhs_t, cols_s = R[free], R_t[free], ca.DM(ell[free])
    # rhs, rhs_t: the residuals unscaled (G = rhs / rows' scales); blocks: the element matrices unscaled, whose
    # assembly A gives the scaled Jacobian dG/dz = diag(rows' scales)^-1 A diag(cols_s)
    return {"R": R, "R_t": R_t, "G": G, "G_t": G_t, "jnz": jnz, "asm": asm, "state": state, "blocks": blocks,
            "rhs": rhs, "rhs_t": rhs_t, "cols_s": cols_s}


def finish_outputs(m: Model, lay: Layout, alpha: float, tol: float, G1: ca.MX, r_fixed: ca.MX,
                   state: tuple) -> list:
    """[x1, res, done] of ``hht_finish`` from the residual G1 and the fixed rows r_fixed at the solution."""
    q1, qd1, qdd1, _, mu1 = state
    lam1 = -r_fixed / (1 + alpha) if lay.fixed else ca.MX(0, 1)
    x1 = ca.densify(ca.vertcat(q1, qd1, qdd1, lam1, mu1))  # dense: the C interface is plain arrays
    res = ca.norm_inf(G1) if lay.free or lay.n_mu else ca.MX(0)
    # res <= max(tol, floor), the floor's pass over q1 (4.4k of a step's 399k instructions at 32 el./bar, twobar)
    # taken only for a residual above tol: a branch of a conditional, the same truth value (NaN included)
    floor = ROUNDOFF_FLOOR * np.finfo(float).eps * ca.mmax(ca.fabs(q1 / lay.ell))
    return [x1, res, ca.if_else(res <= tol, 1, res <= floor, True)]


def newton_functions(m: Model, lay: Layout, alpha: float, tol: float, n_prm: int, expand: bool):
    """(residual, jacobian, finish) of the unknowns z = (u, nu): the free dofs' scaled updates u and
    the joints' scaled multipliers nu (:class:`Layout`), and the known ``prm``.

    ``hht_residual(z, prm) -> G``, the scaled residual: the free rows (Eq. 4), then the joints' rows
    (Eq. 5, (1 + alpha) Phi(q_{n+1}) - alpha Phi(q_n)); ``hht_jacobian(z, prm) -> (dG/dz, G)``, sparse;
    ``hht_finish(z, prm) -> (x1, res, done)``, the state after the step (the supports' multipliers
    from the fixed rows), the final max |G|, and whether that converges the step: res at most tol, or
    the round-off floor of the coordinates (:func:`roundoff_tolerance`).
    """
    z, P = ca.MX.sym("z", len(lay.free) + lay.n_mu), ca.MX.sym("prm", n_prm)
    t = newton_terms(m, lay, alpha, z, P, mapped_hht(m, alpha, False), mapped_hht(m, alpha, True))
    cse = {"cse": True}
    resid = ca.Function("hht_residual", [z, P], [t["G"]], ["z", "prm"], ["G"], cse)
    jac = ca.Function("hht_jacobian", [z, P], [ca.MX(t["asm"].sparsity, t["jnz"]), t["G_t"]], ["z", "prm"],
                      ["jac_G_z", "G"], cse)
    # the residual once more at the solution, with the fixed rows that give the multipliers
    resid_all = ca.Function("hht_residual_all", [z, P], [t["G"], t["R"][lay.fixed]], ["z", "prm"], ["G", "r_fixed"],
                            cse)
    if expand:
        resid, jac, resid_all = resid.expand(), jac.expand(), resid_all.expand()
    G1, r_fixed = resid_all(z, P)
    finish = ca.Function("hht_finish", [z, P], finish_outputs(m, lay, alpha, tol, G1, r_fixed, t["state"]),
                         ["z", "prm"], ["x1", "res", "done"])
    return resid, jac, finish


def _mapped(grp, f: ca.Function, *args):
    """``f`` of every element of ``grp``; its inputs named g (gravity) are the same for all."""
    rep = [i for i in range(f.n_in()) if f.name_in(i) == "g"]
    return f.map(f"{f.name()}_{grp.n}", "serial", grp.n, rep, [])(*args)


def scale_function(m: Model, alpha: float) -> ca.Function:
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


def initial_function(m: Model, lay: Layout) -> ca.Function:
    """``hht_initial(q, qd, t, p) -> (qdd, lam)``: consistent accelerations and multipliers (index-1
    form of Eq. 1): the fixed dofs accelerate as their supports do (not at all unless they move),
    M_ff qdd_f = -(h + f_int - g - f_ext + M qdd_c)_f, and the multipliers balance the fixed rows.
    With joints, their multipliers mu join: M_ff qdd_f + B_f^T mu = ..., B qdd + (dB/dq qd) qd = 0."""
    n = m.n_dof
    q, qd, t, p = ca.MX.sym("q", n), ca.MX.sym("qd", n), ca.MX.sym("t"), ca.MX.sym("p", m.n_p)
    hh, f_int, g = m.forces(q, qd, p)
    rhs = hh + f_int - g - m.load(t, p)
    M = m.mass(q, p)
    qdd_c = ca.mtimes(lay.reactions(), m.prescribed(t)[2]) if m.moving else ca.MX.zeros(n)
    shifted = rhs + ca.mtimes(M, qdd_c) if m.moving else rhs
    mu = ca.MX(0, 1)
    if lay.n_mu:
        B = m.constraint(q)[1][m.n_fixed:, :]
        gamma = ca.jtimes(ca.mtimes(B, qd), q, qd) + ca.mtimes(B, qdd_c)
        F = lay.free
        kkt = ca.blockcat([[M[F, F], B[:, F].T], [B[:, F], ca.MX(lay.n_mu, lay.n_mu)]])
        sol = ca.solve(kkt, -ca.vertcat(shifted[F], gamma), "qr")
        qdd, mu = qdd_c + lay.spread(sol[:len(F)]), sol[len(F):]
        rhs = rhs + ca.mtimes(B.T, mu)
    else:
        qdd = qdd_c + lay.spread(-ca.solve(M[lay.free, lay.free], shifted[lay.free], "qr") if lay.free
                                 else ca.MX(0, 1))
    lam = -(ca.mtimes(M, qdd) + rhs)[lay.fixed] if lay.fixed else ca.MX(0, 1)
    return ca.Function("hht_initial", [q, qd, t, p], [ca.densify(qdd), ca.densify(ca.vertcat(lam, mu))],
                       ["q", "qd", "t", "p"], ["qdd", "lam"])


def post_function(m: Model) -> ca.Function:
    """``hht_post(x, t, p) -> y``: what a result reports per state (see :attr:`HHT.post`)."""
    n = m.n_dof
    x, t, p = ca.MX.sym("x", 3 * n + m.n_con), ca.MX.sym("t"), ca.MX.sym("p", m.n_p)
    q, qd, lam = x[:n], x[n:2 * n], x[3 * n:]
    T, Ve, Vg = m.energy(q, qd, p)
    power = ca.dot(m.load(t, p), qd) + m.follower_power(q, qd, p)
    if m.moving:  # a moving support works on the structure: -lambda (its force) times its velocity
        power -= ca.dot(lam[:m.n_fixed], qd[[c.dof for c in m.constraints]])
    y = ca.vertcat(T, Ve, Vg, power, m.dissipation(q, qd, p),
                   m.outputs(q, qd, lam, p), m.local_rotations(q))
    return ca.Function("hht_post", [x, t, p], [ca.densify(y)], ["x", "t", "p"], ["y"])


def step_blocks(m: Model, lay: Layout, alpha: float, prepare: ca.Function, resid: ca.Function,
                 finish: ca.Function, expand: bool) -> ca.Function:
    """``hht_step_sensitivity(x0, t0, p, h, d, x1) -> (G_z, G_w, X_z, X_w)``: the blocks of the step's
    exact derivative by the implicit-function theorem. With G(z, prm(w)) = 0 and x1 = X(z, prm(w)),
    w = (x0, t0, p, h): dx1/dw = X_w - X_z G_z^-1 G_w, one sparse QR of G_z per step: the step's
    custom Jacobian (``jac_hht_step``, for CasADi's derivatives of trajectories, as in the NLP
    transcriptions). CasADi's generic rootfinder derivative gives the same numbers but differentiates
    through the Newton solve in every direction: about twice the run time. A fit's own sensitivities
    take directional derivatives instead (:mod:`casflex.integrators.directions`)."""
    n, nx = m.n_dof, 3 * m.n_dof + m.n_con
    _, beta = hht_coefficients(alpha)
    z = ca.MX.sym("z", len(lay.free) + lay.n_mu)
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
    if lay.n_mu:
        z_of_x1 = ca.vertcat(z_of_x1, x1[nx - lay.n_mu:] / lay.mu_scale(d))
    return ca.Function("hht_step_sensitivity", [x0, t0, p, h, d, x1],
                       list(blocks(z_of_x1, ca.vertcat(x0, t0, p, h), d)),
                       ["x0", "t0", "p", "h", "d", "x1"], ["G_z", "G_w", "X_z", "X_w"])


def newton_updates(newton: ca.Function) -> int:
    """Newton updates made by a fast_newton rootfinder's last call: its iterations, plus the last
    update when it stopped on the update's size (counted before the iteration ends)."""
    st = newton.stats()
    return int(st["iter_count"]) + (st["return_status"] == "converged_abstol_step")
