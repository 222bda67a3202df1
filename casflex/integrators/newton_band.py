"""The exact Newton update of an HHT step on a mapped mesh, assembled straight into the banded LU's storage.

:func:`~casflex.integrators.hht_pieces.newton_functions` gives the scaled Jacobian dG/dz as a sparse
matrix: the element matrices summed into its nonzeros, each scaled by its column's and row's scale,
then gathered once more into the storage that the banded LU (:mod:`.band`) factorises. Each of these is
a pass over some 2000 numbers at 32 elements per bar (twobar), and all of them together cost more
instructions than the element kernels. Here the element matrices are summed into the band storage
directly (one gather per contribution depth, i.e. 2) and are not scaled: with the scales D_r of the
rows and D_c of the unknowns, dG/dz = D_r^-1 A D_c for the assembled matrix A, so the update is

    dz = (dG/dz)^-1 G = D_c^-1 A^-1 (D_r G) = D_c^-1 A^-1 r,

r the unscaled residual, which the step has before it scales it. The LU has no pivoting, and without
pivoting elimination does the same operations on A as on D_r^-1 A D_c up to the scales: the updates
agree to round-off (the states to the Newton tolerance, tests/test_hht.py). The kernels are mapped
without the wrapper that repeats their shared inputs (gravity, the Newmark coefficients) and copies
their outputs: the inputs are repeated in the graph, the outputs stay where the map wrote them.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from casflex.elements.kernels import hht_kernel
from casflex.integrators.band import BandLU
from casflex.integrators.hht_pieces import Layout, finish_outputs, newton_terms
from casflex.model import Model

__all__ = ["band_newton", "band_storage"]


def _node_blocks(dofs: np.ndarray) -> list[tuple[int, int]]:
    """The rows [a, b) of an element dof table (n_el, n_dof) that are consecutive dofs in every element (a
    node's dofs): the kernels' dof inputs split at these rows (:func:`_split_kernel`)."""
    cuts = [0] + [r for r in range(1, dofs.shape[1]) if np.any(dofs[:, r] != dofs[:, r - 1] + 1)] + [dofs.shape[1]]
    return list(zip(cuts[:-1], cuts[1:], strict=True))


def _node_dofs(v: ca.MX, grp) -> list[ca.MX]:
    """The group's element dofs of v (n,) as one (b - a, n_el) matrix per node block [a, b) (:func:`_node_blocks`):
    side by side slices of v where consecutive elements' nodes are consecutive (along a meshed bar), which the
    generated code reads in place (a gather through an index list costs 6-7 instructions a number; twobar,
    32 el./bar: 6 of them a step, 15k of its instructions); elsewhere gathers."""
    out = []
    for a, b in _node_blocks(grp.dofs):
        first, w = grp.dofs[:, a], b - a
        runs = np.split(np.arange(grp.n), np.flatnonzero(np.diff(first) != w) + 1)
        if len(runs) > max(4, grp.n // 4):  # no chains: one gather, not many small copies
            out.append(ca.reshape(v[grp.dofs[:, a:b].ravel().tolist()], w, grp.n))
            continue
        out.append(ca.horzcat(*(ca.reshape(v[int(first[r[0]]):int(first[r[0]]) + w * r.size], w, r.size)
                                for r in runs)))
    return out


def _split_kernel(f: ca.Function, n_vec: int, blocks: list[tuple[int, int]], fixed: dict | None = None) -> ca.Function:
    """``f`` with each of its first ``n_vec`` inputs (the element dofs of q, qd, ...) split into the node
    ``blocks``: the same expressions (f called on the blocks stacked), read from the slices of :func:`_node_dofs`.
    ``fixed``: {input: (entries, values)}, entries of inputs that are the same numbers for every element, written
    into the code as constants (:func:`_shared_entries`): the input keeps only its other entries, or goes."""
    fixed = fixed or {}
    ins, call, names = [], [], []
    for i in range(f.n_in()):
        if i < n_vec:
            parts = [ca.SX.sym(f"{f.name_in(i)}{j}", b - a) for j, (a, b) in enumerate(blocks)]
            ins, names, call = ins + parts, names + [f"{f.name_in(i)}{j}" for j in range(len(blocks))], \
                call + [ca.vertcat(*parts)]
        elif i in fixed:
            known, values = fixed[i]
            free = ca.SX.sym(f.name_in(i), int((~known).sum()))
            free_at = np.cumsum(~known) - 1
            call.append(ca.vertcat(*(ca.SX(values[j]) if known[j] else free[int(free_at[j])]
                                     for j in range(known.size))))
            if not known.all():
                ins, names = ins + [free], names + [f.name_in(i)]
        else:
            ins, names, call = ins + [f.sx_in(i)], names + [f.name_in(i)], call + [f.sx_in(i)]
    tag = "".join(f"_c{i}_{''.join('k' if k else 'v' for k in fixed[i][0])}" for i in sorted(fixed))
    return ca.Function(f"{f.name()}_nodes{len(blocks)}{tag}", ins, f.call(call), names, f.name_out(), {"cse": True})


def _shared_entries(a, n_el: int, g: ca.Function | None = None) -> tuple[np.ndarray, np.ndarray] | None:
    """(entries, values): the entries of the kernel input ``a`` that are the same number for every element of a
    group and known when the step is built: the rows of a property table (n_props, n_el) without a parameter
    and with one value along the mesh (twobar's E, A, I, density; the element lengths and angles differ at
    round-off), or all of gravity ``g`` when it does not depend on the parameters; None if there are none.
    Written into the kernel as constants, the operations on them alone are done once when the code is generated
    instead of in every element's call, and the terms a 0 multiplies go (twobar's beam without rotary inertia:
    1311 -> 1223 operations of the tangent kernel, 447 -> 404 of the residual's). The numbers change at round-off
    only (CasADi's simplifications with constants; twobar's trajectories moved by 2e-14 m at most)."""
    if g is not None:
        if g.sparsity_jac(0, 0).nnz() != 0:
            return None
        v = np.array(g(ca.DM.zeros(g.nnz_in(0)))).ravel()
        return np.ones(v.size, bool), v
    if not isinstance(a, ca.DM):
        return None
    v = np.array(a).reshape(-1, n_el)
    known = (v == v[:, :1]).all(axis=1)
    return (known, v[:, 0]) if known.any() else None


def _plain_map(m: Model, alpha: float, tangent: bool, padded: dict | None = None):
    """``evaluate(k, args)`` for :func:`newton_terms` with ``dofs=_node_dofs``: group k's kernel, its dof inputs
    split into node blocks, mapped over its elements, its shared inputs (g, c: the last two) repeated for each
    by one gather; the property table and g written into the kernel as constants where they are the same numbers
    for every element (:func:`_shared_entries`). ``padded``: the kernels give K padded with 0 and 1
    (:func:`hht_kernel`), kept in ``padded[k]``; K itself is then a view of it."""
    def evaluate(k: int, args: list):
        grp = m.groups[k]
        n_vec = sum(isinstance(a, list) for a in args)
        kern = hht_kernel(grp.kind, alpha, m.inertia, tangent, padded is not None)
        props, g = kern.n_in() - 3, kern.n_in() - 2  # the inputs after the dofs: props, g, c
        fixed = {i: v for i, v in ((props, _shared_entries(args[n_vec], grp.n)),
                                   (g, _shared_entries(args[-2], grp.n, m.gravity))) if v is not None}
        f = _split_kernel(kern, n_vec, _node_blocks(grp.dofs), fixed).map(grp.n, "serial")
        dofs = [b for a in args[:n_vec] for b in a]
        table = args[n_vec]
        if props in fixed:
            table = table[np.flatnonzero(~fixed[props][0]).tolist(), :] if not fixed[props][0].all() else None
        shared = ([] if g in fixed else args[-2:-1]) + args[-1:]  # the same for every element: repeated
        out = f(*dofs, *([] if table is None else [table]),
                *(ca.reshape(a[list(range(a.numel())) * grp.n], a.numel(), grp.n) for a in shared))
        if padded is None:
            return out
        nd = grp.spec.n_dof
        padded[k] = out[1]
        return out[0], ca.reshape(out[1][:nd * nd, :], nd, nd * grp.n)
    return evaluate


def _sources(asm, blocks: list, padded: dict, entries: np.ndarray) -> tuple[int, list[tuple[int, int, np.ndarray]]]:
    """How the band entries ``entries`` (positions in [nz, 0, 1]) are summed from the element matrices:
    (the group whose padded output the first gather reads, [(depth, group, where in its output or -1)])."""
    nnz, zero = asm.sparsity.nnz(), asm.offsets[-1]
    size = [b - a for a, b in zip(asm.offsets[:-1], asm.offsets[1:], strict=True)]
    base = max(padded, key=lambda g: size[g])
    terms = []
    for c, src in enumerate(asm.lists or [[]]):
        src = np.append(np.asarray(src, dtype=int), [zero, zero])[entries]
        grp = np.searchsorted(asm.offsets, src, side="right") - 1  # the group of each source (len: none)
        for g, K in enumerate(blocks):
            nd2 = int(K.size1()) ** 2 if K is not None else 0
            loc = src - asm.offsets[g]
            at = np.where(grp == g, loc // max(nd2, 1) * (nd2 + 2 * (g in padded)) + loc % max(nd2, 1), -1)
            if c == 0 and g == base:  # its own 0 and 1 (after element 0's K) stand for no source and the padding
                at = np.where(grp == g, at, nd2)
                at[entries == nnz + 1] = nd2 + 1
            terms.append((c, g, at))
    return base, terms


def band_storage(t: dict, band: BandLU, padded: dict) -> list[ca.MX]:
    """The assembled element matrices (unscaled, ``t["blocks"]`` of :func:`newton_terms`) in ``band``'s
    storage (its three parts, :attr:`BandLU.entries`): one gather straight into the band's layout from
    the largest group's padded kernel output, then each other contribution (a second element at a
    shared node, another group) added where there is one."""
    asm, blocks = t["asm"], t["blocks"]
    parts = []
    for entries in band.entries:
        base, terms = _sources(asm, blocks, padded, entries)
        out = next(padded[g][at.tolist()] for c, g, at in terms if c == 0 and g == base)
        for c, g, at in terms:
            if c == 0 and g == base:
                continue
            where = np.flatnonzero(at >= 0)
            if where.size:
                src = padded[g] if g in padded else ca.vec(blocks[g])
                out[where.tolist()] = out[where.tolist()] + src[at[where].tolist()]
        parts.append(out)
    return parts


def band_newton(m: Model, lay: Layout, alpha: float, tol: float, n_prm: int,
                band: BandLU) -> dict[str, ca.Function]:
    """The step's Functions on the band (see the module): ``hht_jacobian_band(z, prm) -> (first, cols, rows,
    G, r, cols_s)``, the assembled matrix A in ``band``'s storage (:meth:`BandLU.factor_parts`), the scaled
    and unscaled residuals at z and the unknowns' scales;
    ``hht_rhs(z, prm) -> (G, r)``, the residuals alone; ``hht_band_update(F, r, prm) -> dz``, the update
    from A's packed factors F (as :attr:`BandLU.factor` packs them); ``hht_finish_band(z, prm) -> (x1, res, done)``, as
    ``hht_finish`` (:func:`~casflex.integrators.hht_pieces.newton_functions`)."""
    z, P = ca.MX.sym("z", len(lay.free) + lay.n_mu), ca.MX.sym("prm", n_prm)
    padded = {}
    t = newton_terms(m, lay, alpha, z, P, None, _plain_map(m, alpha, True, padded), _node_dofs)
    cse = {"cse": True}
    jac = ca.Function("hht_jacobian_band", [z, P], [*band_storage(t, band, padded), t["G_t"], t["rhs_t"], t["cols_s"]],
                      ["z", "prm"], ["first", "cols", "rows", "G", "r", "cols_s"], cse)
    r = _plain_map(m, alpha, False)
    t = newton_terms(m, lay, alpha, z, P, r, lambda k, args: (r(k, args), None), _node_dofs)
    rhs = ca.Function("hht_rhs", [z, P], [t["G"], t["rhs"]], ["z", "prm"], ["G", "r"], cse)
    outs = finish_outputs(m, lay, alpha, tol, t["G"], t["R"][lay.fixed], t["state"])
    finish = ca.Function("hht_finish_band", [z, P], outs,
                         ["z", "prm"], ["x1", "res", "done"], cse)
    F, rr = ca.MX.sym("F", band.size), ca.MX.sym("r", z.numel())
    update = ca.Function("hht_band_update", [F, rr, P], [band.apply(F, rr) / t["cols_s"]], ["F", "r", "prm"], ["dz"])
    return {"jacobian_band": jac, "rhs": rhs, "band_update": update, "finish_step": finish}
