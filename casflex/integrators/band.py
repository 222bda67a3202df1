"""A banded LU solve for the HHT Newton matrix: a CasADi Function of constant code size and linear cost.

The matrix of a chain of beams and joints is banded once its dofs are ordered along the chain;
reverse Cuthill-McKee (scipy) finds such an order for any scene, and the bandwidth b is what it
achieves (5 for twobar or threelink at any mesh: three dofs per node, each node coupled to its two
neighbours). The LU factorisation without pivoting of a band matrix stays in the band: elimination
step k works on the (b + 1) x (b + 1) window of rows and columns k .. k + b. Blocks of
:data:`BLOCK` steps are one SX Function (written out for a window, so its size depends on b only),
chained over the matrix with ``mapaccum``; forward and back substitution likewise. The cost is
O(n b^2), where CasADi's sparse QR clears an n-vector per column (O(n^2): 34 us against 12 us for
twobar with 32 elements per bar, 198 unknowns).

Without pivoting, the pivots are the diagonal of the Schur complements: safe for the Newton matrix
of a step, M / (beta h^2) + gamma / (beta h) C + K, whose mass term makes it diagonally dominant
in practice. The HHT step checks the residual after the update this solve gives and, if the step
did not converge, continues with CasADi's Newton and its QR (pivoting by Householder reflections).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

__all__ = ["BandLU", "band_lu", "BLOCK"]

#: Elimination steps written out in one block Function.
BLOCK = 16


def _order(sp: ca.Sparsity, late: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """(permutation, its inverse, nonzero (row, col) in the new order, bandwidth).

    ``late``: the last ``late`` unknowns (Lagrange multipliers, whose diagonal is zero) are each put
    right after the last of the other unknowns they couple to, so that their pivot is the Schur
    complement -B S^-1 B^T of the unknowns eliminated before them, not the zero of the matrix."""
    from scipy.sparse import csc_matrix
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    n = sp.size1()
    rows, colind = np.array(sp.row()), np.array(sp.colind())
    cols = np.repeat(np.arange(sp.size2()), np.diff(colind))
    lead = n - late
    keep = (rows < lead) & (cols < lead)
    perm = np.asarray(reverse_cuthill_mckee(csc_matrix((np.ones(keep.sum()), (rows[keep], cols[keep])),
                                                       shape=(lead, lead)), symmetric_mode=True), dtype=int)
    if late:
        pos = np.empty(lead, dtype=int)
        pos[perm] = np.arange(lead)
        anchor = np.full(late, -1)  # the position of the last unknown each couples to (-1: none, at the end)
        for r, c in zip(rows, cols, strict=True):
            if r >= lead > c:
                anchor[r - lead] = max(anchor[r - lead], pos[c])
        order = []
        for k in range(lead):
            order += [perm[k], *(lead + j for j in np.flatnonzero(anchor == k))]
        order += [lead + j for j in np.flatnonzero(anchor < 0)]
        perm = np.array(order, dtype=int)
    inv = np.empty(n, dtype=int)
    inv[perm] = np.arange(n)
    rc = np.stack([inv[rows], inv[cols]], axis=1)
    return perm, inv, rc, max(int(np.abs(rc[:, 0] - rc[:, 1]).max(initial=0)), 1)


def _blocks(b: int) -> tuple[ca.Function, ca.Function, ca.Function, ca.Function]:
    """The block Functions for bandwidth b: elimination, forward and back substitution, and elimination with the
    forward substitution of one right-hand side (the same operations as the first two)."""
    w, K = b + 1, BLOCK
    cse = {"cse": True}
    W0, C, R = ca.SX.sym("W", w, w), ca.SX.sym("C", w, K), ca.SX.sym("R", w - 1, K)
    W, piv, ups, lows = W0, [], [], []
    for j in range(K):  # one elimination step: pivot row and column out, the next window's border in
        l = W[1:, 0] / W[0, 0]
        u = W[0, 1:]
        piv.append(W[0, 0])
        ups.append(u.T)
        lows.append(l)
        nxt = ca.SX(w, w)
        nxt[:b, :b] = W[1:, 1:] - ca.mtimes(l, u)
        nxt[:, b] = C[:, j]
        nxt[b, :b] = R[:, j].T
        W = nxt
    lu = ca.Function("band_lu_block", [W0, C, R], [W, ca.vertcat(*piv), ca.horzcat(*ups), ca.horzcat(*lows)],
                     ["W", "C", "R"], ["W_next", "pivots", "U", "L"], cse)
    a0, rhs, lk = ca.SX.sym("a", b), ca.SX.sym("rhs", K), ca.SX.sym("l", b, K)

    def forward(ls: list) -> tuple[ca.SX, list]:
        a, out = a0, []
        for j in range(K):  # by columns: y_k = rhs_k - a_k, then L's column k (rows k+1 .. k+b) times y_k joins the
            out.append(rhs[j] - a[0])  # sums a of the next b rows: L is used as the elimination stores it
            a = (ca.vertcat(a[1:b], 0) if b > 1 else ca.SX.zeros(1)) + ls[j] * out[-1]
        return a, out

    a, out = forward([lk[:, j] for j in range(K)])
    fwd = ca.Function("band_forward_block", [a0, rhs, lk], [a, ca.vertcat(*out)], cse)
    a, out = forward(lows)  # with the elimination: L is neither stored nor read back (a step does not keep it)
    lu_fwd = ca.Function("band_lu_forward_block", [W0, a0, C, R, rhs],  # the carried ones first (mapaccum)
                         [W, a, ca.vertcat(*piv), ca.horzcat(*ups), ca.vertcat(*out)],
                         ["W", "a", "C", "R", "rhs"], ["W_next", "a_next", "pivots", "U", "y"], cse)
    x0, yk, uk, pk = ca.SX.sym("x", b), ca.SX.sym("y", K), ca.SX.sym("u", b, K), ca.SX.sym("piv", K)
    x, out = x0, []
    for j in reversed(range(K)):  # backwards: x_k = (y_k - sum_i U[k, k+1+i] x_{k+1+i}) / pivot_k
        out.append((yk[j] - ca.dot(uk[:, j], x)) / pk[j])
        x = ca.vertcat(out[-1], x[:b - 1]) if b > 1 else out[-1]
    bwd = ca.Function("band_backward_block", [x0, yk, uk, pk], [x, ca.vertcat(*out[::-1])], cse)
    return lu, fwd, bwd, lu_fwd


@dataclass(frozen=True)
class BandLU:
    """The banded LU of matrices of one sparsity, as three CasADi Functions.

    ``factor(nz) -> F``: the factors of the matrix with nonzeros ``nz`` (CasADi's column-major
    order), packed in one vector F = [pivots, U, L] (size :attr:`size`); ``apply(F, rhs) -> x``:
    the solution of A x = rhs with them; ``solve(nz, rhs) -> x``: both in one. A factorisation can
    thus be kept and applied again (the modified Newton of :class:`~casflex.integrators.HHT`).

    A caller that assembles the matrix straight into the band storage (:mod:`.newton_band`) builds
    the same graph with :meth:`factor_parts` and :meth:`solve_parts`: the storage's three parts are
    ``nz_ext[i]`` for the index lists :attr:`entries` into nz_ext = [nz, 0, 1].
    """

    factor: ca.Function
    apply: ca.Function
    solve: ca.Function
    bandwidth: int
    entries: tuple[np.ndarray, np.ndarray, np.ndarray]  # first window (w x w), columns' (w x N), rows' borders (b x N)
    # elimination, forward (mapped), back, elimination with the forward substitution (mapped)
    _acc: tuple[ca.Function, ca.Function, ca.Function, ca.Function] = field(repr=False)
    _perm: tuple[np.ndarray, np.ndarray] = field(repr=False)  # the order and its inverse

    @property
    def size(self) -> int:
        return self.factor.nnz_out(0)

    def factor_parts(self, first: ca.MX, cols: ca.MX, rows: ca.MX) -> tuple[ca.MX, ca.MX, ca.MX]:
        """(pivots (N,), U (b, N), L (b, N)) of the matrix in band storage (vectors as :attr:`entries` lists them)."""
        b, w = self.bandwidth, self.bandwidth + 1
        N = cols.numel() // w
        _, piv, U, L = self._acc[0](ca.reshape(first, w, w), ca.reshape(cols, w, N), ca.reshape(rows, b, N))
        return ca.vec(piv), U, L

    def solve_parts(self, piv: ca.MX, U: ca.MX, L: ca.MX, rhs: ca.MX) -> ca.MX:
        """The solution x of A x = rhs from A's factors (:meth:`factor_parts`)."""
        b = self.bandwidth
        N, K = piv.numel(), BLOCK
        blocks, n = N // K, rhs.numel()
        perm, inv = self._perm
        _, y = self._acc[1](ca.MX.zeros(b), ca.reshape(ca.vertcat(rhs[perm.tolist()], ca.MX.zeros(N - n)), K, blocks),
                            ca.reshape(L, b, N))
        return self._back(piv, U, ca.vec(y))

    def factor_solve_parts(self, first: ca.MX, cols: ca.MX, rows: ca.MX, rhs: ca.MX) -> ca.MX:
        """``solve_parts(*factor_parts(first, cols, rows), rhs)``, the same operations, with the forward
        substitution done during the elimination: L is neither stored nor read back (twobar, 32 el./bar:
        4.6k of a step's 381k instructions, and L's copies)."""
        b, w = self.bandwidth, self.bandwidth + 1
        N, K, n = cols.numel() // w, BLOCK, rhs.numel()
        perm, _ = self._perm
        _, _, piv, U, y = self._acc[3](ca.reshape(first, w, w), ca.MX.zeros(b), ca.reshape(cols, w, N),
                                       ca.reshape(rows, b, N),
                                       ca.reshape(ca.vertcat(rhs[perm.tolist()], ca.MX.zeros(N - n)), K, N // K))
        return self._back(ca.vec(piv), U, ca.vec(y))

    def _back(self, piv: ca.MX, U: ca.MX, y: ca.MX) -> ca.MX:
        """The back substitution of the forward solution y (N,), back in the unknowns' order."""
        b, K = self.bandwidth, BLOCK
        blocks = piv.numel() // K
        _, inv = self._perm
        # the blocks from the last, each a slice of the factors in their order (a reversed copy cost 10 % more)
        x, xs = ca.MX.zeros(b), [None] * blocks
        for j in reversed(range(blocks)):
            x, xs[j] = self._acc[2](x, y[j * K:(j + 1) * K], U[:, j * K:(j + 1) * K], piv[j * K:(j + 1) * K])
        return ca.vertcat(*xs)[inv.tolist()]


def band_lu(sp: ca.Sparsity, name: str = "band", late: int = 0) -> BandLU:
    """The :class:`BandLU` of matrices with sparsity ``sp`` (square, structurally symmetric); ``late``:
    the number of trailing unknowns with a zero diagonal block (multipliers, see :func:`_order`)."""
    n = sp.size1()
    perm, inv, rc, b = _order(sp, late)
    w, K = b + 1, BLOCK
    blocks = -(-n // K)
    N = blocks * K  # padded with the identity, so that every block has K steps
    where = {(int(r), int(c)): k for k, (r, c) in enumerate(rc)}
    zero, one = sp.nnz(), sp.nnz() + 1

    def at(i: int, j: int) -> int:  # index into [nz, 0, 1] of entry (i, j) of the permuted, padded matrix
        return (one if i == j else zero) if i >= n or j >= n else where.get((i, j), zero)

    lu, fwd, bwd, lu_fwd = _blocks(b)
    entries = (np.array([at(i, j) for j in range(w) for i in range(w)], dtype=int),
               np.array([at(k + 1 + i, k + w) for k in range(N) for i in range(w)], dtype=int),
               np.array([at(k + w, k + 1 + j) for k in range(N) for j in range(b)], dtype=int))
    # one level of calls (not CasADi's tower of 10): the tower copies each level's outputs into the next
    one = {"base": -1}
    acc = (lu.mapaccum(f"{name}_lu_{blocks}", blocks, [0], [0], one),
           fwd.mapaccum(f"{name}_forward_{blocks}", blocks, [0], [0], one),
           bwd,
           lu_fwd.mapaccum(f"{name}_lu_forward_{blocks}", blocks, [0, 1], [0, 1], one))
    lu = BandLU(None, None, None, b, entries, acc, (perm, inv))
    nz = ca.MX.sym("nz", sp.nnz())
    ext = ca.vertcat(nz, ca.DM([0.0, 1.0]))
    factor = ca.Function(f"{name}_factor", [nz], [ca.vertcat(*map(ca.vec, lu.factor_parts(*(ext[e.tolist()]
                                                                                         for e in entries))))],
                         ["nz"], ["F"])
    F, rhs = ca.MX.sym("F", N * (1 + 2 * b)), ca.MX.sym("rhs", n)
    apply = ca.Function(f"{name}_apply", [F, rhs], [lu.solve_parts(F[:N], ca.reshape(F[N:N + b * N], b, N),
                                                                   F[N + b * N:], rhs)], ["F", "rhs"], ["x"])
    nz2, rhs2 = ca.MX.sym("nz", sp.nnz()), ca.MX.sym("rhs", n)
    solve = ca.Function(f"{name}_solve", [nz2, rhs2], [apply(factor(nz2), rhs2)], ["nz", "rhs"], ["x"])
    return dataclasses.replace(lu, factor=factor, apply=apply, solve=solve)
