"""Modified Newton for HHT: the factorised Jacobian kept from step to step (``HHT(newton="modified")``).

Each step first makes one update with the banded LU factors carried over from an earlier step
(a chord update: one residual and a forward and back substitution, no Jacobian, no
factorisation). When the residual after it is at most tol, the step is done and the factors go
on to the next step. Otherwise the step is taken as the exact Newton takes it (the Jacobian at the
better of the two points, factorised anew, CasADi's Newton with QR if needed), and its factors
are kept from then on: a refresh.

An update with a Jacobian one step old contracts the error by about 7e-3 on twobar at dt = 1e-3
(measured), so at casflex's tolerance 1e-12 a chord update converges a step when the predictor is
already close: on twobar at dt = 2e-4 with 1 or 8 elements per bar, 8 or 9 steps in 10, where the
modified Newton costs 0.83-1.0 of the exact one's time; at dt = 1e-3, or with 32 elements per bar,
it refreshes in 8 or 9 steps of 10 and is up to 1.5x slower (docs/tables/bench_simulate.md). A
looser tol does not help: the residual is scaled by M / (beta h^2), and chord iterates accepted at
1e-8 moved twobar's node 5 by 9 mm in 3 s.

A state accepted after a chord update carries up to cond(G_z) tol of error (the exact Newton's
final update leaves round-off): on twobar, 2.5e-7 m over 0.5 s at dt = 2e-4, as much as the
step's own error there. The trajectory Function (:meth:`HHT.trajectory`), whose derivatives come
from the implicit-function theorem, stays the exact Newton's.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from casflex.integrators.hht_pieces import newton_updates

__all__ = ["ModifiedNewton"]


@dataclass(frozen=True, eq=False)
class ModifiedNewton:
    """The Functions of the modified Newton of an :class:`~casflex.integrators.HHT` (built by it).

    ``step``: ``hht_step_modified(x0, t0, p, h, d, F) -> (x1, res, F1, refreshed)``, F the packed
    band factors (:class:`~casflex.integrators.band.BandLU`); ``factor_at``:
    ``hht_factor_at(x0, t0, p, h, d) -> F``, the factors at the predictor of the step from x0.
    """

    fn: dict
    max_iter: int
    step: ca.Function = field(init=False)
    factor_at: ca.Function = field(init=False)
    _chunks: dict = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        f = self.fn
        prepare, rhs, finish, update = f["prepare"], f["rhs"], f["finish_step"], f["update"]
        band_update = f["band_update"]
        nF = update.nnz_out(2)
        nx = finish.nnz_out(0)
        x0, t0, p, h, d = prepare.mx_in()
        F = ca.MX.sym("F", nF)
        zg, pr = prepare(x0, t0, p, h, d)
        G0, r0 = rhs(zg, pr)
        z1 = zg - band_update(F, r0, pr)
        xa, ra, done = finish(z1, pr)
        # refresh: the exact step from the better point, its factors kept
        zs, P, X, R, FF = (ca.MX.sym(k, s) for k, s in (("z", rhs.nnz_in(0)), ("prm", rhs.nnz_in(1)), ("x1", nx),
                                                          ("res", 1), ("F", nF)))
        z2, g, F2 = update(zs, P)
        xb, rb, db = finish(z2, P)
        xr, rr = f["more"](1 - db, ca.if_else(rb < g, z2, zs), P, xb, rb)
        keep = ca.Function("hht_chord_done", [zs, P, X, R, FF], [X, R, FF])
        refresh = ca.Function("hht_refresh", [zs, P, X, R, FF], [xr, rr, F2])
        branch = ca.Function.conditional("hht_chord", [keep], refresh)
        x1, r1, F1 = branch(1 - done, ca.if_else(ra < ca.norm_inf(G0), z1, zg), pr, xa, ra, F)
        step = ca.Function("hht_step_modified", [x0, t0, p, h, d, F], [x1, r1, F1, 1 - done],
                           ["x0", "t0", "p", "h", "d", "F"], ["x1", "res", "F1", "refreshed"])
        object.__setattr__(self, "step", step)
        object.__setattr__(self, "factor_at", ca.Function("hht_factor_at", [x0, t0, p, h, d], [update(zg, pr)[2]],
                                                          ["x0", "t0", "p", "h", "d"], ["F"]))

    def chunk(self, n_steps: int) -> ca.Function:
        """``hht_chunk_modified_<N>(x0, F0, t0, p, h, d) -> (X, res, F, refreshes)``: N steps from t0
        (X (nx, N), res (1, N) as in :meth:`HHT.trajectory`), the factors after them and the number
        of refreshes."""
        if n_steps not in self._chunks:
            acc = self.step.mapaccum(f"hht_steps_modified_{n_steps}", n_steps, [0, 5], [0, 2])
            x0, t0, p, h, d, F = self.step.mx_in()
            grid = t0 + h * ca.DM(np.arange(n_steps)).T
            X, res, Fs, refreshed = acc(x0, grid, ca.repmat(p, 1, n_steps), ca.repmat(h, 1, n_steps),
                                        ca.repmat(d, 1, n_steps), F)
            self._chunks[n_steps] = ca.Function(
                f"hht_chunk_modified_{n_steps}", [x0, F, t0, p, h, d], [X, res, Fs[:, -1], ca.sum2(refreshed)],
                ["x0", "F0", "t0", "p", "h", "d"], ["X", "res", "F", "refreshes"])
        return self._chunks[n_steps]

    def step_interpreted(self, x0: np.ndarray, t0: float, p: np.ndarray, h: float, d: np.ndarray,
                         F: np.ndarray) -> tuple[np.ndarray, float, np.ndarray, int, bool]:
        """:attr:`step` driven from Python (bitwise the same): (x1, res, F1, Newton updates, refreshed)."""

        f = self.fn
        zg, pr = f["prepare"](x0, t0, p, h, d)
        G0, r0 = f["rhs"](zg, pr)
        z1 = zg - f["band_update"](F, r0, pr)
        xa, ra, done = f["finish_step"](z1, pr)
        if bool(done):
            return np.array(xa).ravel(), float(ra), F, 1, False
        zs = z1 if float(ra) < float(ca.norm_inf(G0)) else zg
        z2, g, F2 = f["update"](zs, pr)
        xb, rb, db = f["finish_step"](z2, pr)
        updates = 2
        if not bool(db) and self.max_iter > 1:
            z = f["newton"](z2 if float(rb) < float(g) else zs, pr)
            updates += newton_updates(f["newton"])
            xb, rb, _ = f["finish_step"](z, pr)
        return np.array(xb).ravel(), float(rb), np.array(F2).ravel(), updates, True
