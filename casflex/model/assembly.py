"""Element groups and their assembly through the scene's index maps.

All elements of one kind form an :class:`ElementGroup`: a table of their global dofs and of their
properties. A kernel of that kind (:mod:`casflex.elements.kernels`) is evaluated over the whole
group with ``Function.map``: the element dofs are gathered from the global vectors by a constant
index list, and element vectors and matrices are summed into global vectors and sparse matrices
by constant 0/1 matrices. The generated code therefore holds one copy of each kernel whatever
the mesh, and the cost of an evaluation grows linearly with the number of elements.

Works on MX (structured Functions) and on SX (a caller that evaluates the Functions on SX
symbols gets the same expressions flattened).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from casflex.elements.joints import joint_spec
from casflex.elements.kernels import KINDS, Kind

__all__ = ["ElementGroup", "MatrixAssembly", "gather", "scatter", "scatter_add", "scatter_at"]


@dataclass(frozen=True, eq=False)
class ElementGroup:
    """The elements of one kind.

    names : tuple of str, length n_el
    dofs : int ndarray, shape (n_el, n_dof of the kind): global dof indices of each element
    base : ndarray, shape (n_props, n_el): property values (those that are parameters: 0)
    slots : ((prop row, element, parameter index, coefficient), ...): the property is its base value plus
        coefficient x that entry of p (a property that is a parameter itself: base 0, coefficient 1; a body's
        centre of mass in its node's frame: the rotated offset of the scene's com_x, com_y)
    """

    kind: str
    names: tuple[str, ...]
    dofs: np.ndarray
    base: np.ndarray
    slots: tuple[tuple[int, int, int, float], ...] = ()
    _scatter: dict = field(default_factory=dict, init=False, repr=False)

    @property
    def spec(self) -> Kind:
        return KINDS[self.kind] if self.kind in KINDS else joint_spec(self.kind)

    @property
    def n(self) -> int:
        return len(self.names)

    def props(self, p: ca.MX | ca.SX) -> ca.MX | ca.SX | ca.DM:
        """Property table (n_props, n_el) for parameters p: constants with p's entries in their slots."""
        base = ca.DM(self.base)
        if not self.slots:
            return base
        n_pr = self.base.shape[0]
        rows = [e * n_pr + r for r, e, _, _ in self.slots]
        # DM.triplet places each coefficient at its (row, column): a DM built on the sparsity would take them in
        # its column-major order instead
        sel = ca.DM.triplet(rows, [k for _, _, k, _ in self.slots], ca.DM([c for *_, c in self.slots]),
                            n_pr * self.n, p.numel())
        return base + ca.reshape(ca.mtimes(sel, p), n_pr, self.n)

    def scatter_lists(self, n: int) -> list[list[int]]:
        """Index lists that sum element vectors into a global n-vector (see :func:`summed`)."""
        if n not in self._scatter:
            self._scatter[n] = sum_lists(_targets(self.dofs.ravel(), n), self.dofs.size)
        return self._scatter[n]


def gather(v: ca.MX | ca.SX, group: ElementGroup) -> ca.MX | ca.SX:
    """The group's element dofs of a global vector v (n,): shape (n_dof of the kind, n_el)."""
    return ca.reshape(v[group.dofs.ravel().tolist()], group.spec.n_dof, group.n)


def scatter(values: ca.MX | ca.SX, group: ElementGroup, n: int) -> ca.MX | ca.SX:
    """Element vectors (n_dof of the kind, n_el) summed into a global vector (n,)."""
    return summed(ca.vec(values), group.scatter_lists(n))


def scatter_add(base: ca.MX | ca.SX, values: ca.MX | ca.SX, group: ElementGroup) -> ca.MX | ca.SX:
    """``base + scatter(values, group, n)``, the same numbers; for a group that reaches few of the n
    entries (a few springs beside a meshed beam) added in place at those entries only: a full
    scatter costs a gather and a sum over all n entries whatever the group's size."""
    n = base.numel()
    lists = group.scatter_lists(n)
    targets = np.flatnonzero(np.any(np.asarray(lists) != group.dofs.size, axis=0)) if lists else np.zeros(0, int)
    if 2 * targets.size >= n or isinstance(base, ca.DM):
        return base + scatter(values, group, n)
    out = type(base)(base)
    at = targets.tolist()
    out[at] = base[at] + summed(ca.vec(values), [[lst[t] for t in at] for lst in lists])
    return out


def scatter_at(values: ca.MX | ca.SX, at: np.ndarray, n: int) -> ca.MX | ca.SX:
    """Vectors (k, n_el) summed into a global vector (n,) at the indices ``at`` (n_el, k)."""
    return summed(ca.vec(values), sum_lists(_targets(at.ravel(), n), at.size))


def _targets(where: np.ndarray, size: int) -> list[list[int]]:
    """For each target 0..size-1 the source positions i with where[i] == target."""
    out: list[list[int]] = [[] for _ in range(size)]
    for i, t in enumerate(where):
        if t >= 0:
            out[int(t)].append(i)
    return out


def sum_lists(sources: list[list[int]], zero: int) -> list[list[int]]:
    """Gather lists for :func:`summed`: list c holds each target's c-th source (or ``zero``, the
    position of a 0 appended to the sources)."""
    depth = max((len(s) for s in sources), default=0)
    return [[s[c] if c < len(s) else zero for s in sources] for c in range(depth)]


def summed(values: ca.MX | ca.SX, lists: list[list[int]]) -> ca.MX | ca.SX:
    """out[t] = sum of ``values`` at the positions ``lists[c][t]`` (c = 0, 1, ...): sums of element
    contributions as a few plain gathers (a 0/1 matrix product costs CasADi's generated code several
    times more)."""
    ext = ca.vertcat(values, 0)
    if not lists:  # no target has a source (a scene without masses: its mass matrix has no nonzeros)
        return ext[[]]
    out = ext[lists[0]]
    for idx in lists[1:]:
        out = out + ext[idx]
    return out


class MatrixAssembly:
    """Sums element matrices of several groups into one sparse matrix.

    ``rows``/``cols``: for each global dof, its row/column in the assembled matrix, or -1 to
    leave it out (e.g. constrained dofs). The sparsity is the union of the element blocks.
    :meth:`__call__` takes each group's element matrices as the map of a kernel returns them,
    (n_d, n_d * n_el) side by side, and returns the assembled sparse matrix.
    """

    def __init__(self, groups: tuple[ElementGroup, ...], rows: np.ndarray, cols: np.ndarray):
        n_r, n_c = int(rows.max(initial=-1)) + 1, int(cols.max(initial=-1)) + 1
        entries = []  # (group, position in vec(K) of the group, row, col)
        for g, grp in enumerate(groups):
            nd = grp.spec.n_dof
            for e in range(grp.n):
                for b in range(nd):
                    for a in range(nd):
                        r, c = rows[grp.dofs[e, a]], cols[grp.dofs[e, b]]
                        if r >= 0 and c >= 0:
                            entries.append((g, e * nd * nd + b * nd + a, int(r), int(c)))
        self.sparsity = ca.Sparsity.triplet(n_r, n_c, [x[2] for x in entries], [x[3] for x in entries])
        # nonzero index of each (row, col) in the column-major sparsity
        colind, row = self.sparsity.colind(), self.sparsity.row()
        where = {(row[k], c): k for c in range(n_c) for k in range(colind[c], colind[c + 1])}
        self.offsets = np.cumsum([0] + [grp.spec.n_dof ** 2 * grp.n for grp in groups]).tolist()
        sources: list[list[int]] = [[] for _ in range(self.sparsity.nnz())]
        for g, pos, r, c in entries:
            sources[where[(r, c)]].append(self.offsets[g] + pos)
        self.lists = sum_lists(sources, self.offsets[-1])
        self.nz_rows = np.array(row, dtype=int)
        self.nz_cols = np.repeat(np.arange(n_c), np.diff(np.array(colind)))

    def nonzeros(self, blocks: list) -> ca.MX | ca.SX:
        """The assembled nonzeros (nnz,) from each group's element matrices (None: a group without
        this matrix, e.g. the mass of a spring)."""
        parts = [ca.vec(K) if K is not None else ca.DM.zeros(b - a)
                 for K, a, b in zip(blocks, self.offsets[:-1], self.offsets[1:], strict=True)]
        return summed(ca.vertcat(*parts), self.lists)

    def __call__(self, blocks: list) -> ca.MX | ca.SX:
        nz = self.nonzeros(blocks)
        if isinstance(nz, ca.DM):
            return ca.DM(self.sparsity, nz)
        return type(nz)(self.sparsity, nz)
