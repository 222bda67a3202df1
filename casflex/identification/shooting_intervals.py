"""The shooting intervals of :mod:`.shooting_nlp` as ONE CasADi Function, mapped over the intervals.

An interval of multiple shooting (or the whole horizon of single shooting) is K HHT steps from a
start x_s at t_s, compared with the data at the steps that carry a sample. Every interval is the
same Function of its start and numbers:

- ``interval_value_<K>``: the states X (nx, K), Newton residuals (1, K), the weighted residues r
  (n_o, K) (zero at steps without a sample) and the end projected on the next start's slow modes
  e (2 k_max,) (:class:`.shooting_starts.SlowStart`); the NLP's objective and constraints.
- ``interval_sens_<K>_<D>``: the same with forward sensitivities S = dx/dw_j of the state in the D
  directions of the interval's own unknowns w_j = (xi_j, theta) (each step: the HHT step's
  implicit-function Jacobian times S) and the residues' Jacobian.
- ``interval_gn_<K>_<D>``: from those, the interval's share of the Gauss-Newton quantities:
  |r_j|^2, J_j^T r_j (D,), J_j^T J_j (D, D), e and de/dw_j.

Intervals shorter than K (the horizon need not divide evenly) hold their state over their last
steps (``act`` 0: a conditional skips the step). :class:`Transcription` maps the start Functions
(:mod:`.shooting_starts`) and the interval Function over the intervals (``Function.map``) and
assembles the NLP's gradient, constraint Jacobian and Gauss-Newton Hessian J^T J from the mapped
blocks with constant sparse matrices, so the generated code does not grow with the number of
intervals or the horizon, and CasADi never differentiates the whole NLP graph. Chaining the
interval Function (``mapaccum``) from the first start gives the single-shooting residue and its
Jacobian (the polish and the statistics).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import casadi as ca
import numpy as np

from casflex.identification import shooting_starts as st
from casflex.identification.measurement import free_dofs
from casflex.identification.problem import ParameterMap
from casflex.model import Model

if TYPE_CHECKING:
    from casflex.integrators.hht import HHT

__all__ = ["IntervalFunctions", "interval_functions", "Transcription", "StepData"]


@dataclass(frozen=True)
class IntervalFunctions:
    """The interval Functions (module docstring) for K steps and D directions."""

    value: ca.Function
    sens: ca.Function
    gn: ca.Function


def _projection(x: ca.MX, S: ca.MX | None, free: list[int], n: int, C: ca.MX, qg: ca.MX, sa: ca.MX, sv: ca.MX
                ) -> tuple[ca.MX, ca.MX | None]:
    """The next start's slow-mode amplitudes and rates of state x, scaled (e (2k,)), and de = (dx) S."""
    e = ca.vertcat(ca.mtimes(C, x[free] - qg) / sa, ca.mtimes(C, x[[n + i for i in free]]) / sv)
    if S is None:
        return e, None
    D = S.size2()
    E = ca.vertcat(ca.mtimes(C, S[free, :]) / ca.repmat(sa, 1, D),
                   ca.mtimes(C, S[[n + i for i in free], :]) / ca.repmat(sv, 1, D))
    return e, E


def interval_functions(integ: HHT, channels: ca.Function, K: int, m_max: int, k_max: int, free: list[int]
                       ) -> IntervalFunctions:
    """The interval Functions of K steps; D = m_max + n_p directions, the first m_max for the
    start's unknowns (zero-padded), the last n_p for the parameters' decision variables theta.

    ``channels(x) -> (y, dy/dx)``: the compared quantities (n_o,) of a state and their Jacobian;
    ``k_max``: the most slow modes of any start (the projections e are zero-padded to 2 k_max)."""
    model = integ.model
    n, nx, n_p = model.n_dof, integ.nx, model.n_p
    n_o, nf, D = channels.size1_out(0), len(free), m_max + n_p
    step = integ.step
    X0, T0, Pm, H, Dn = step.mx_in()
    S0, Ps = ca.MX.sym("S0", nx, D), ca.MX.sym("P", n_p, D)
    act, Y, W = ca.MX.sym("act"), ca.MX.sym("y", n_o), ca.MX.sym("w", n_o)
    zero = ca.MX.zeros(1, 1)

    # one step or, past the interval's end, its state held
    hold = ca.Function("hht_hold", [X0, T0, Pm, H, Dn], [X0, zero])
    x1, res = ca.Function.conditional("hht_step_or_hold", [hold], step)(act, X0, T0, Pm, H, Dn)
    xsx = ca.SX.sym("x", nx)
    y = ca.Function("channels_value", [xsx], [channels(xsx)[0]])(x1)
    one = ca.Function("interval_value_step", [X0, act, T0, Pm, H, Dn, Y, W], [x1, res, W * (y - Y)])
    X1, R1 = step(X0, T0, Pm, H, Dn)
    jx, _, jp = step.jacobian()(X0, T0, Pm, H, Dn, X1, R1)[:3]
    adv = ca.Function("hht_sens_step", [X0, S0, Ps, T0, Pm, H, Dn], [X1, ca.mtimes(jx, S0) + ca.mtimes(jp, Ps), R1])
    held = ca.Function("hht_sens_hold", [X0, S0, Ps, T0, Pm, H, Dn], [X0, S0, zero])
    x1, s1, res = ca.Function.conditional("hht_sens_step_or_hold", [held], adv)(act, X0, S0, Ps, T0, Pm, H, Dn)
    y, dy = channels(x1)
    one_s = ca.Function("interval_sens_step", [X0, S0, act, T0, Pm, Ps, H, Dn, Y, W],
                        [x1, s1, res, W * (y - Y), ca.repmat(W, 1, D) * ca.mtimes(dy, s1)])

    xs, Ss = ca.MX.sym("x_s", nx), ca.MX.sym("S_s", nx, D)
    A, T, YY, WW = ca.MX.sym("act", 1, K), ca.MX.sym("t", 1, K), ca.MX.sym("Y", n_o, K), ca.MX.sym("W", n_o, K)
    Cn, qg, sa, sv = ca.MX.sym("C_next", k_max, nf), ca.MX.sym("q_g_next", nf), ca.MX.sym("s_a_next", k_max), \
        ca.MX.sym("s_v_next", k_max)
    rep = [ca.repmat(v, 1, K) for v in (Pm, H, Dn)]
    X, R, r = one.mapaccum(f"interval_value_steps_{K}", K, [0], [0])(xs, A, T, rep[0], rep[1], rep[2], YY, WW)
    e, _ = _projection(X[:, K - 1], None, free, n, Cn, qg, sa, sv)
    value = ca.Function(f"interval_value_{K}", [xs, Pm, A, T, H, Dn, YY, WW, Cn, qg, sa, sv], [X, R, r, e],
                        ["x_s", "p", "act", "t", "h", "d", "Y", "W", "C_next", "q_g_next", "s_a_next", "s_v_next"],
                        ["X", "res", "r", "e"])
    X, S, R, r, Jr = one_s.mapaccum(f"interval_sens_steps_{K}_{D}", K, [0, 1], [0, 1])(
        xs, Ss, A, T, rep[0], ca.repmat(Ps, 1, K), rep[1], rep[2], YY, WW)
    sens = ca.Function(f"interval_sens_{K}_{D}", [xs, Ss, Pm, Ps, A, T, H, Dn, YY, WW],
                       [X[:, K - 1], S[:, (K - 1) * D:], X, R, r, Jr],
                       ["x_s", "S_s", "p", "P", "act", "t", "h", "d", "Y", "W"],
                       ["x_end", "S_end", "X", "res", "r", "Jr"])
    return IntervalFunctions(value, sens, _gn_function(sens, K, m_max, n_p, free, n, (Cn, qg, sa, sv)))


def _gn_function(sens: ca.Function, K: int, m_max: int, n_p: int, free: list[int], n: int, nxt: tuple
                 ) -> ca.Function:
    """``interval_gn``: the interval's Gauss-Newton blocks from :func:`interval_functions`' sens."""
    xs, Ss, Pm, _, A, T, H, Dn, YY, WW = sens.mx_in()
    nx, D = xs.numel(), m_max + n_p
    n_o = YY.size1()
    Sxi, Sp, dpdth = ca.MX.sym("S_xi", nx, m_max), ca.MX.sym("S_p", nx, n_p), ca.MX.sym("dp_dtheta", n_p)
    S_s = ca.horzcat(Sxi, ca.mtimes(Sp, ca.diag(dpdth)))
    P = ca.horzcat(ca.DM.zeros(n_p, m_max), ca.diag(dpdth))
    x_end, S_end, _, R, r, Jr = sens(xs, S_s, Pm, P, A, T, H, Dn, YY, WW)
    # the stacked Jacobian (K n_o, D), transposed: column (step i, output o) at i + K o, as vec(r^T)
    Jt = ca.reshape(Jr.T, D, K * n_o)
    rv = ca.vec(r.T)
    e, E = _projection(x_end, S_end, free, n, *nxt)
    return ca.Function(f"interval_gn_{K}_{D}", [xs, Sxi, Sp, Pm, dpdth, A, T, H, Dn, YY, WW, *nxt],
                       [ca.sumsqr(r), ca.mtimes(Jt, rv), ca.mtimes(Jt, Jt.T), e, E, ca.mmax(R)],
                       ["x_s", "S_xi", "S_p", "p", "dp_dtheta", "act", "t", "h", "d", "Y", "W", "C_next",
                        "q_g_next", "s_a_next", "s_v_next"], ["phi", "grad", "JtJ", "e", "E", "max_res"])


@dataclass(frozen=True)
class StepData:
    """What the intervals compare, per HHT step 1..N of the horizon: Y (n_o, N) the measured
    quantities (zero at a step without a sample) and W (n_o, N) their weights (dimensionless
    residue per unit: sqrt(xi) / l, sqrt(psi) T / l, sqrt(phi) T^2 / l; zero without a sample);
    ``order`` (n_r, 2): (output, step) of each residue of the single-shooting residue vector, in its
    order (quantity, sample, channel)."""

    Y: np.ndarray
    W: np.ndarray
    order: np.ndarray


class Transcription:
    """The NLP of :mod:`.shooting_nlp` on the interval Functions (module docstring).

    Unknowns w = (theta (n_p), xi_0 (m_0), xi_1, ..., xi_(M-1)): the parameters' decision variables
    and each interval start's unknowns (m_0 = 0 from the scene's state). ``starts[j]``: None (the
    scene's state, j = 0 only) or a :class:`.shooting_starts.SlowStart`. ``lengths``: steps per
    interval; ``h`` (s) the step, ``t0`` (s) the first sample, ``d`` the Newton scaling (hht_scale).
    """

    def __init__(self, model: Model, integ: HHT, channels: ca.Function, data: StepData, lengths: list[int], h: float,
                 t0: float, d: np.ndarray, starts: list[st.SlowStart | None], pmap: ParameterMap, in_c: bool) -> None:
        self.model, self.integ, self.pmap, self.data = model, integ, pmap, data
        self.lengths, self.h, self.t0, self.d, self.starts = list(lengths), float(h), float(t0), np.asarray(d), starts
        self.M, self.K = len(lengths), max(lengths)
        self.first = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(int)
        self.n_p = model.n_p
        self.sizes = [0 if s is None else s.size for s in starts]
        self.offsets = self.n_p + np.concatenate([[0], np.cumsum(self.sizes)[:-1]]).astype(int)
        self.n_w = self.n_p + int(sum(self.sizes))
        self.n_u = self.n_p + self.sizes[0]
        self.m_max = max(self.sizes)
        self.D = self.m_max + self.n_p
        self.k_max = max([s.k for s in starts if s is not None], default=0)
        self.free = free_dofs(model).tolist()
        self.fns = interval_functions(integ, channels, self.K, self.m_max, self.k_max, self.free)
        kinds = sorted({s.k for s in starts if s is not None})
        self.start_fns = {k: st.slow_start_functions(model, integ, k, in_c) for k in kinds}
        self._columns()

    # -- numbers per interval ------------------------------------------------------------------
    def _columns(self) -> None:
        """Each interval's steps: active flags, times, data and weights, the next start's projection."""
        K, M, N = self.K, self.M, int(sum(self.lengths))
        i = np.arange(K)
        self.act = np.concatenate([(i < L).astype(float) for L in self.lengths])
        # the times as the steps of the old transcription took them: (t0 + first h) + i h per interval,
        # t0 + k h for the single-shooting chain
        self.t_nlp = np.concatenate([(self.t0 + f * self.h) + self.h * i for f in self.first])
        glob = np.concatenate([f + i for f in self.first])
        self.t_chain = self.t0 + self.h * glob.astype(float)
        self.step_col = np.concatenate([j * K + np.arange(L) for j, L in enumerate(self.lengths)])  # step -> column
        cols = np.where(self.act > 0, np.minimum(glob, N - 1), -1)
        Y, W = self.data.Y, self.data.W
        self.Y = np.where(cols >= 0, Y[:, np.maximum(cols, 0)], 0.0)
        self.W = np.where(cols >= 0, W[:, np.maximum(cols, 0)], 0.0)
        nf, km = len(self.free), self.k_max
        C, qg, sa, sv = np.zeros((km, nf * M)), np.zeros((nf, M)), np.ones((km, M)), np.ones((km, M))
        for j, s in enumerate(self.starts[1:]):  # interval j ends at start j + 1
            C[:s.k, j * nf:(j + 1) * nf] = s.C
            qg[:, j], sa[:s.k, j], sv[:s.k, j] = s.q_g[self.free], s.s_a, s.s_v
        self.nxt = [C, qg, sa, sv]

    def local_columns(self, j: int) -> np.ndarray:
        """(D,) the index in w of each of interval j's local directions, -1 for padding."""
        out = np.full(self.D, -1)
        out[:self.sizes[j]] = self.offsets[j] + np.arange(self.sizes[j])
        out[self.m_max:] = np.arange(self.n_p)
        return out

    def defect_rows(self) -> list[tuple[int, int, int]]:
        """(row of g, interval j, row of e_j) of every constraint: start j + 1's (a, v) rows."""
        out, row = [], 0
        for j, s in enumerate(self.starts[1:]):
            for rho in list(range(s.k)) + list(range(self.k_max, self.k_max + s.k)):
                out.append((row, j, rho))
                row += 1
        return out

    def xi_indices(self) -> np.ndarray:
        """Indices in w of the starts 1..M-1's unknowns, in the constraints' order."""
        return np.concatenate([self.offsets[j] + np.arange(self.sizes[j]) for j in range(1, self.M)] or
                              [np.zeros(0, int)]).astype(int)

    def p_of(self, th: ca.MX) -> tuple[ca.MX, ca.MX]:
        """The parameters p of theta and dp/dtheta (n_p,)."""
        p = self.pmap.p(th)
        return p, (ca.DM(self.pmap.scale) if self.pmap.transform == "linear" else p)

    # -- the starts -----------------------------------------------------------------------------
    def _groups(self) -> dict[int, list[int]]:
        """The intervals that start on the slow manifold, by their number of slow modes."""
        out: dict[int, list[int]] = {}
        for j, s in enumerate(self.starts):
            if s is not None:
                out.setdefault(s.k, []).append(j)
        return out

    def _group_inputs(self, w: ca.MX, k: int, members: list[int]) -> list:
        """The mapped slow-start Function's inputs after p for the starts ``members`` (w: unknowns)."""
        idx = np.concatenate([self.offsets[j] + np.arange(2 * k) for j in members]).astype(int)
        c = [self.starts[j].constants() for j in members]
        return [ca.reshape(w[idx.tolist()], 2 * k, len(members)), np.column_stack([x[0] for x in c]),
                np.hstack([x[1] for x in c]), np.hstack([x[2] for x in c]), np.column_stack([x[3] for x in c]),
                np.column_stack([x[4] for x in c]), np.column_stack([x[5] for x in c]),
                np.array([[x[6][0] for x in c]])]

    def _in_order(self, blocks: list[tuple[ca.MX, list[int]]], width: int) -> ca.MX:
        """Column blocks of ``width`` per interval, given per group (block, its intervals), put in interval order."""
        cat = ca.horzcat(*[b for b, _ in blocks])
        where = {j: i for i, j in enumerate(j for _, members in blocks for j in members)}
        if all(where[j] == j for j in range(self.M)):
            return cat
        return cat[:, [where[j] * width + c for j in range(self.M) for c in range(width)]]

    def _pad(self, S: ca.MX, m: int, count: int) -> ca.MX:
        """(nx, m count) blocks of m columns each widened to m_max columns by zeros."""
        if m == self.m_max:
            return S
        nx = S.size1()
        return ca.reshape(ca.vertcat(ca.reshape(S, nx * m, count), ca.DM.zeros(nx * (self.m_max - m), count)),
                          nx, self.m_max * count)

    def start_values(self, w: ca.MX, p: ca.MX) -> ca.MX:
        """The intervals' start states (nx, M) of the unknowns w."""
        blocks = []
        if self.starts[0] is None:
            qdd, lam = self.integ.initial(self.model.q0, self.model.qd0, self.t0, p)
            blocks.append((ca.vertcat(ca.DM(self.model.q0), ca.DM(self.model.qd0), qdd, lam), [0]))
        for k, members in self._groups().items():
            F = self.start_fns[k][0].map(f"slow_start_{k}_map{len(members)}", "serial", len(members), [1], [])
            xi, *consts = self._group_inputs(w, k, members)
            blocks.append((F(xi, p, *consts), members))
        return self._in_order(blocks, 1)

    def start_jacobians(self, w: ca.MX, p: ca.MX) -> tuple[ca.MX, ca.MX, ca.MX]:
        """The start states (nx, M), their derivatives in the starts' own unknowns (nx, m_max M,
        zero-padded) and in p (nx, n_p M)."""
        xs, sxi, sp = [], [], []
        nx = self.integ.nx
        if self.starts[0] is None:
            x0, S0 = st.scene_start(self.model, self.integ, self.t0, p)
            xs.append((x0, [0]))
            sxi.append((ca.DM.zeros(nx, self.m_max), [0]))
            sp.append((S0, [0]))
        for k, members in self._groups().items():
            F = self.start_fns[k][1].map(f"slow_start_jac_{k}_map{len(members)}", "serial", len(members), [1], [])
            xi, *consts = self._group_inputs(w, k, members)
            x, S_xi, S_p = F(xi, p, *consts)
            xs.append((x, members))
            sxi.append((self._pad(S_xi, 2 * k, len(members)), members))
            sp.append((S_p, members))
        return self._in_order(xs, 1), self._in_order(sxi, self.m_max), self._in_order(sp, self.n_p)

    # -- the NLP --------------------------------------------------------------------------------
    def _repeated(self) -> list:
        return [self.act[None, :], self.t_nlp[None, :], self.h, self.d]

    def value(self, w: ca.MX) -> tuple[ca.MX, ca.MX]:
        """(r, g): the weighted residues (n_o, K M) and the constraints (start j's unknowns equal the
        previous interval's end projected on its slow modes) of the unknowns w."""
        p, _ = self.p_of(w[:self.n_p])
        act, t, h, d = self._repeated()
        F = self.fns.value.map(f"interval_value_{self.K}_map{self.M}", "serial", self.M, [1, 4, 5], [])
        _, _, r, e = F(self.start_values(w, p), p, act, t, h, d, self.Y, self.W, *self.nxt)
        return r, self._defects(e, w)

    def _defects(self, e: ca.MX, w: ca.MX) -> ca.MX:
        rows = self.defect_rows()
        if not rows:
            return ca.MX(0, 1)
        ke = 2 * self.k_max
        sel = ca.DM(ca.Sparsity.triplet(len(rows), ke * self.M, [r for r, _, _ in rows],
                                        [j * ke + rho for _, j, rho in rows]), 1.0)
        return ca.mtimes(sel, ca.vec(e)) - w[self.xi_indices().tolist()]

    def gauss_newton(self, f_scale: float, triu: bool) -> ca.Function:
        """``indirect_gn(w) -> (f, g, grad_f, jac_g, H)``: the objective 1/2 f_scale |r|^2, the
        constraints, their first derivatives and the Gauss-Newton Hessian f_scale J^T J (its upper
        triangle if ``triu``), all from the mapped interval blocks."""
        w = ca.MX.sym("x", self.n_w)
        p, dpdth = self.p_of(w[:self.n_p])
        act, t, h, d = self._repeated()
        F = self.fns.gn.map(f"interval_gn_{self.K}_{self.D}_map{self.M}", "serial", self.M, [3, 4, 7, 8], [])
        phi, grad, JtJ, e, E, _ = F(*self.start_jacobians(w, p), p, dpdth, act, t, h, d, self.Y, self.W, *self.nxt)
        A_f, (sp_h, A_h), (sp_g, A_g, c_g) = self._assembly(triu)
        jac_g = ca.MX(sp_g, ca.mtimes(A_g, ca.vec(E)) + c_g) if sp_g.nnz() else ca.MX(0, self.n_w)
        return ca.Function("indirect_gn", [w], [0.5 * f_scale * ca.sum2(phi), self._defects(e, w),
                                                f_scale * ca.mtimes(A_f, ca.vec(grad)), jac_g,
                                                ca.MX(sp_h, f_scale * ca.mtimes(A_h, ca.vec(JtJ)))],
                           ["x"], ["f", "g", "grad_f", "jac_g", "hess"])

    def _assembly(self, triu: bool) -> tuple:
        """Constant sparse matrices from the mapped blocks' entries to the NLP's: gradient (n_w, D M);
        Hessian (its sparsity, (nnz, D^2 M)); constraint Jacobian (sparsity, (nnz, 2 k_max D M),
        constant part: the -1 of each start's own unknowns)."""
        D, M, ke = self.D, self.M, 2 * self.k_max
        cols = [self.local_columns(j) for j in range(M)]
        fr, fc = zip(*[(c, j * D + a) for j in range(M) for a, c in enumerate(cols[j]) if c >= 0], strict=True)
        A_f = ca.DM(ca.Sparsity.triplet(self.n_w, D * M, list(fr), list(fc)), 1.0)
        pairs = [((ca_, cb), (j * D + b) * D + a) for j in range(M) for a, ca_ in enumerate(cols[j])
                 for b, cb in enumerate(cols[j]) if ca_ >= 0 and cb >= 0 and (ca_ <= cb or not triu)]
        sp_h, A_h = self._gather(self.n_w, self.n_w, pairs, D * D * M)
        entries = [((row, c), (j * D + b) * ke + rho) for row, j, rho in self.defect_rows()
                   for b, c in enumerate(cols[j]) if c >= 0]
        own = [(row, i) for row, i in zip(range(len(self.xi_indices())), self.xi_indices(), strict=True)]
        sp_g, A_g = self._gather(len(own), self.n_w, entries + [(rc, -1) for rc in own], ke * D * M)
        c_g = np.zeros(sp_g.nnz())
        nz = {rc: i for i, rc in enumerate(zip(*sp_g.get_triplet(), strict=True))}
        c_g[[nz[rc] for rc in own]] = -1.0
        return A_f, (sp_h, A_h), (sp_g, A_g, ca.DM(c_g))

    @staticmethod
    def _gather(n_rows: int, n_cols: int, pairs: list, n_in: int) -> tuple[ca.Sparsity, ca.DM]:
        """The sparsity of the (row, col) of ``pairs`` ((row, col), source index; source -1: an entry
        without a source) and the 0/1 matrix summing each source into its nonzero."""
        sp = ca.Sparsity.triplet(n_rows, n_cols, [rc[0] for rc, _ in pairs], [rc[1] for rc, _ in pairs])
        nz = {rc: i for i, rc in enumerate(zip(*sp.get_triplet(), strict=True))}
        src = [(nz[rc], s) for rc, s in pairs if s >= 0]
        A = ca.DM(ca.Sparsity.triplet(sp.nnz(), n_in, [a for a, _ in src], [b for _, b in src]), 1.0)
        return sp, A

    # -- single shooting --------------------------------------------------------------------------
    def single_shooting(self) -> ca.Function:
        """``ss_residue(u) -> (r, Jr, X, res)``: the intervals chained from the first start (u = (theta,
        xi_0)): residues (n_o, K M), their derivatives (n_o, K M D), states (nx, K M) and Newton
        residuals (1, K M) over the whole horizon (held steps included)."""
        u = ca.MX.sym("u", self.n_u)
        p, dpdth = self.p_of(u[:self.n_p])
        s0 = self.starts[0]
        if s0 is None:
            x0, S_p = st.scene_start(self.model, self.integ, self.t0, p)
            S_xi = ca.DM.zeros(self.integ.nx, self.m_max)
        else:
            xi, *consts = self._group_inputs(u, s0.k, [0])
            x0, S_xi, S_p = self.start_fns[s0.k][1](xi, p, *consts)
            S_xi = self._pad(S_xi, s0.size, 1)
        S_s = ca.horzcat(S_xi, ca.mtimes(S_p, ca.diag(dpdth)))
        P = ca.horzcat(ca.DM.zeros(self.n_p, self.m_max), ca.diag(dpdth))
        M = self.M
        chain = self.fns.sens if M == 1 else self.fns.sens.mapaccum(f"interval_chain_{self.K}_{M}", M, [0, 1], [0, 1])
        _, _, X, R, r, Jr = chain(x0, S_s, ca.repmat(p, 1, M), ca.repmat(P, 1, M), self.act[None, :],
                                  self.t_chain[None, :], ca.repmat(ca.DM(self.h), 1, M),
                                  ca.repmat(ca.DM(self.d), 1, M), self.Y, self.W)
        return ca.Function("ss_residue", [u], [r, Jr, X, R], ["u"], ["r", "Jr", "X", "res"])


class SingleShooting:
    """The single-shooting residue of u = (theta, xi_0) from :meth:`Transcription.single_shooting`'s
    Function ``fn``, its entries in the residue vector's order (:class:`StepData`)."""

    def __init__(self, fn: ca.Function, tr: Transcription, tol_acc: float) -> None:
        self.fn, self.tol_acc = fn, tol_acc
        order = tr.data.order
        self.rows, self.cols = order[:, 0], tr.step_col[order[:, 1]]
        self.step_col, self.D = tr.step_col, tr.D
        self.ucols = np.concatenate([tr.m_max + np.arange(tr.n_p), np.arange(tr.sizes[0])]).astype(int)

    def evaluate(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """(z (n_r,), dz/du (n_r, n_u), states (nx, N) after steps 1..N, largest Newton residual)."""
        r, Jr, X, R = (np.array(v) for v in self.fn(u))
        J3 = Jr.reshape(Jr.shape[0], -1, self.D)
        z = r[self.rows, self.cols]
        J = J3[self.rows, self.cols][:, self.ucols]
        return z, J, X[:, self.step_col], float(np.max(R[0, self.step_col]))

    def __call__(self, u: np.ndarray) -> list[np.ndarray]:
        """[z, dz/du] with z NaN where a step's Newton did not converge (the polish then refuses the step)."""
        z, J, _, res = self.evaluate(u)
        return [z if res <= self.tol_acc else np.full_like(z, np.nan), J]
