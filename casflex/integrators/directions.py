"""Forward sensitivities of one HHT step in D directions, by the implicit-function theorem.

A step solves G(z, prm(w)) = 0 for the scaled unknowns z and returns x1 = X(z, prm(w)), w = (x0,
t0, p, h). Carried in directions E = dw/dtheta (nw, D), the state's sensitivities are

    dz = -G_z^-1 (G_prm dprm),    dprm = prm_w E,    S1 = X_z dz + X_prm dprm,

exact to the Newton tolerance. Every product is a forward directional derivative (D sweeps of the
residual, not its Jacobian in the nw = nx + n_p + 2 inputs) and G_z is the Newton matrix at the
solution, from the kernels' exact tangents (``hht_jacobian``), factorised by the step's banded LU
(:mod:`.band`, O(n b^2)) and applied to the D columns. The cost grows with the mesh as a step does:
twobar, D = 4, 2.8-3.1 simulated steps a step at 1-8 elements per bar, where differentiating the
mapped kernels' MX graph (the previous way) cost 40 steps at 8 elements per bar, and a QR written
out in SX lost 8 digits at 4 (a Householder QR without pivoting on the Newton matrix).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from casflex.integrators.hht_pieces import Layout, hht_coefficients
from casflex.model import Model

__all__ = ["step_directions", "EXPAND_DIRECTIONS"]

#: Up to this many beam elements the directional derivatives are flat SX code: the mapped kernels'
#: MX costs 1.7x at 8 elements per bar (twobar), while flat code compiles in a time that grows with
#: the mesh (twobar, D = 4: 5.7 s at 16 elements, 13 s at 32).
EXPAND_DIRECTIONS = 32
#: Directions written out together (their derivatives share the nominal values), the blocks mapped: the
#: leg's 14 directions (4 parameters, 10 initial-state unknowns) as one block were 3.1 MB of C, 19 s of gcc.
BLOCK = 4


def step_directions(m: Model, lay: Layout, alpha: float, fn: dict, n_dir: int) -> ca.Function:
    """``hht_directions(x0, S0, P, t0, p, h, d, x1) -> S1``: the sensitivities (nx, D) after the step
    x0 -> x1 of those before it, S0 = dx0/dtheta (nx, D), with P = dp/dtheta (n_p, D).

    ``fn``: the integrator's Functions (prepare, residual, jacobian, finish, band_factor, band_apply).
    """
    n, nx, npar, nd = m.n_dof, 3 * m.n_dof + m.n_con, m.n_p, int(n_dir)
    B = min(nd, BLOCK)
    blocks = -(-nd // B)
    expand = sum(g.n for g in m.groups if g.kind == "beam") <= EXPAND_DIRECTIONS
    prepare, resid, finish = fn["prepare"], fn["residual"], fn["finish"]
    o = np.cumsum([0, nx, 1, npar, 1])
    w, d, E = ca.MX.sym("w", int(o[-1])), ca.MX.sym("d", n), ca.MX.sym("E", int(o[-1]), B)
    _, prm = prepare(*(w[o[i]:o[i + 1]] for i in range(4)), d)
    z, P = ca.MX.sym("z", resid.nnz_in(0)), ca.MX.sym("prm", resid.nnz_in(1))
    dP, dz = ca.MX.sym("dprm", P.numel(), B), ca.MX.sym("dz", z.numel(), B)
    pieces = [ca.Function("hht_dprm", [w, d, E], [ca.jtimes(prm, w, E)]),
              ca.Function("hht_dG", [z, P, dP], [ca.jtimes(resid(z, P), P, dP)]),
              ca.Function("hht_dX", [z, P, dz, dP], [ca.jtimes(finish(z, P)[0], ca.vertcat(z, P), ca.vertcat(dz, dP))])]
    # each block of B directions once in the code, mapped over the blocks (the first two inputs shared)
    d_prm, d_G, d_X = ((f.expand() if expand else f).map(f"{f.name()}_{blocks}", "serial", blocks, [0, 1], [])
                       for f in pieces)
    solve = fn["band_apply"].map(f"hht_band_apply_{blocks * B}", "serial", blocks * B, [0], [])

    x0, t0, p, h = ca.MX.sym("x0", nx), ca.MX.sym("t0"), ca.MX.sym("p", npar), ca.MX.sym("h")
    x1, S0, P0 = ca.MX.sym("x1", nx), ca.MX.sym("S0", nx, nd), ca.MX.sym("P", npar, nd)
    _, beta = hht_coefficients(alpha)
    q_pred = x0[:n] + h * x0[n:2 * n] + (0.5 - beta) * h**2 * x0[2 * n:3 * n]
    z1 = ((x1[:n] - q_pred) / lay.ell)[lay.free]  # the unknowns that give x1
    if lay.n_mu:
        z1 = ca.vertcat(z1, x1[nx - lay.n_mu:] / lay.mu_scale(d))
    pad = blocks * B - nd  # zero directions filling the last block
    Ew = ca.vertcat(ca.horzcat(S0, ca.MX(nx, pad)), ca.MX(1, blocks * B), ca.horzcat(P0, ca.MX(npar, pad)),
                    ca.MX(1, blocks * B))
    w0 = ca.vertcat(x0, t0, p, h)
    prm1 = prepare(x0, t0, p, h, d)[1]
    dprm = d_prm(w0, d, Ew)
    F = fn["band_factor"](fn["jacobian"](z1, prm1)[0].nz[:])
    dz1 = -solve(F, d_G(z1, prm1, dprm))
    S1 = d_X(z1, prm1, dz1, dprm)[:, :nd]
    return ca.Function("hht_directions", [x0, S0, P0, t0, p, h, d, x1], [S1],
                       ["x0", "S0", "P", "t0", "p", "h", "d", "x1"], ["S1"])
