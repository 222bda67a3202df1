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


def _plain_map(m: Model, alpha: float, tangent: bool):
    """``evaluate(k, args)`` for :func:`newton_terms`: group k's kernel mapped over its elements, its
    shared inputs (g, c: the last two) repeated for each."""
    def evaluate(k: int, args: list):
        grp = m.groups[k]
        f = hht_kernel(grp.kind, alpha, m.inertia, tangent).map(grp.n, "serial")
        return f(*args[:-2], *(ca.repmat(a, 1, grp.n) for a in args[-2:]))
    return evaluate


def band_storage(t: dict, band: BandLU) -> list[ca.MX]:
    """The assembled element matrices (unscaled, ``t["blocks"]`` of :func:`newton_terms`) in ``band``'s
    storage (its three parts, :attr:`BandLU.entries`): one gather of the element matrices straight into
    the band's layout, then the second (third, ...) element that adds to an entry added where there is one."""
    asm, blocks = t["asm"], t["blocks"]
    blocks = [ca.vec(K) if K is not None else ca.DM.zeros(b - a)
              for K, a, b in zip(blocks, asm.offsets[:-1], asm.offsets[1:], strict=True)]
    zero = asm.offsets[-1]  # where the element matrices' sources hold 0 (sum_lists), then 1 for the padding
    ext = ca.vertcat(*blocks, ca.DM([0.0, 1.0]))
    lists = [np.append(np.asarray(s, dtype=int), [zero, zero + 1 if c == 0 else zero])
             for c, s in enumerate(asm.lists or [[]])]
    parts = []
    for entries in band.entries:
        out = ext[lists[0][entries].tolist()]
        for sources in lists[1:]:
            at = np.flatnonzero(sources[entries] != zero)
            if at.size:
                out[at.tolist()] = out[at.tolist()] + ext[sources[entries][at].tolist()]
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
    t = newton_terms(m, lay, alpha, z, P, None, _plain_map(m, alpha, True))
    cse = {"cse": True}
    jac = ca.Function("hht_jacobian_band", [z, P], [*band_storage(t, band), t["G_t"], t["rhs_t"], t["cols_s"]],
                      ["z", "prm"], ["first", "cols", "rows", "G", "r", "cols_s"], cse)
    r = _plain_map(m, alpha, False)
    t = newton_terms(m, lay, alpha, z, P, r, lambda k, args: (r(k, args), None))
    rhs = ca.Function("hht_rhs", [z, P], [t["G"], t["rhs"]], ["z", "prm"], ["G", "r"], cse)
    outs = finish_outputs(m, lay, alpha, tol, t["G"], t["R"][lay.fixed], t["state"])
    finish = ca.Function("hht_finish_band", [z, P], outs,
                         ["z", "prm"], ["x1", "res", "done"], cse)
    F, rr = ca.MX.sym("F", band.size), ca.MX.sym("r", z.numel())
    update = ca.Function("hht_band_update", [F, rr, P], [band.apply(F, rr) / t["cols_s"]], ["F", "r", "prm"], ["dz"])
    return {"jacobian_band": jac, "rhs": rhs, "band_update": update, "finish_step": finish}
