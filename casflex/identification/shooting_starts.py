"""The starts of the shooting intervals of :mod:`.shooting_nlp` and their exact Jacobians.

An interval starts either at the scene's state (the first interval, ``initial_state="scene"``):

    x_0(p) = [q0, q0', q0''(p), lambda_0(p)],

or on the *slow manifold* through the recording (every later interval, and the first one for
``initial_state="estimate"``; :class:`SlowStart`, :mod:`.initial_state`): its unknowns are the
slow-mode amplitudes and rates xi = (a / s_a, v / s_v), and

    q(a; p) = argmin V_el  s.t.  C (q - q_g) = a,    q' = dq/da v,    (q'', lambda) consistent (Eq. 1).

Each kind has a *value* Function (what the NLP's objective and constraints evaluate) and a
*Jacobian* Function giving the state and dx/dxi, dx/dp. The slow start's Jacobian is the
implicit-function theorem written out on the manifold's optimality conditions G(z; a, p) = 0
(z = (q_free, mu, nu)): with y = dz/da v,

    dz/d(a, p) = -G_z^-1 G_(a,p),     dy/d(a, p) = -G_z^-1 d/d(a,p) [G_z y + G_a v],

the second-order term one directional derivative of G's directional derivative, mapped over the
k + n_p directions. CasADi differentiating the manifold's Function instead nests its forward
derivatives (16 directions over the 6 of dz/da for twobar), which was ~330k of the 700k lines of
the compiled multiple-shooting NLP's C; this is ~4k. Consistent accelerations and multipliers
take their derivatives from ``hht_initial``'s one-direction forward derivative, mapped likewise.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import casadi as ca
import numpy as np

from casflex.identification.initial_state import _placement, relaxed_projection, slow_manifold
from casflex.model import Model

if TYPE_CHECKING:
    from casflex.data import MeasurementSet
    from casflex.integrators.hht import HHT

__all__ = ["SlowStart", "data_states", "slow_start_functions", "scene_start", "initial_directions"]


def data_states(model: Model, data: MeasurementSet, names: list[str], times: list[float]
                ) -> list[tuple[np.ndarray, np.ndarray]]:
    """(q, qd) (m, rad; per second) at each of ``times`` (s) from the recording: the kinematic fits
    at the samples (:func:`.initial_state.kinematic_fits`), a quadratic in time through the 5 nearest."""
    from casflex.identification.initial_state import kinematic_fits

    if not times:
        return []
    tk, Q = kinematic_fits(model, data, names)
    out = []
    for t in times:
        near = np.sort(np.argsort(np.abs(tk - t))[:5])
        deg = min(2, near.size - 1)
        c = np.polynomial.polynomial.polyfit(tk[near] - t, Q[near], deg)
        out.append((c[0], c[1] if deg >= 1 else np.zeros(model.n_dof)))
    return out


class SlowStart:
    """The start of a multiple-shooting interval on the slow manifold (module docstring).

    At the recording's state (q_g, qd_g) there (:func:`data_states`), relaxed onto the slow
    manifold (its fast components quasi-static), the modes below ``omega_cut`` (rad/s) are the slow
    ones (:func:`.initial_state.slow_projection`): B (n_free, k), C = B^T M (k, n_free) and the force
    rows' scales d (n_free,). The unknowns are their amplitudes a and rates v, scaled: xi = (a / s_a,
    v / s_v), s_a (k,) the modal size of one length scale per dof, s_v = s_a / T (T: the horizon, s).
    ``t`` (s) is the start's time, ``xi0`` (2k,) its unknowns at the recording's state.
    """

    def __init__(self, model: Model, q_g: np.ndarray, qd_g: np.ndarray, t: float, p0: np.ndarray,
                 omega_cut: float, ell: np.ndarray, T: float) -> None:
        from casflex.identification.initial_state import free_dofs

        self.free = free_dofs(model)
        # relaxed first: from a fit that stretches a bar by the noise, IPOPT stopped 'acceptable'
        # with k3 55-92 % off (twobar, node 3 and two markers)
        q_g, self.B, self.C, self.d = relaxed_projection(model, q_g, p0, omega_cut)
        self.model, self.q_g, self.t = model, q_g, float(t)
        self.k = self.B.shape[1]
        s_a = np.abs(self.C) @ ell[self.free]
        self.s_a = np.where(s_a > 0, s_a, 1.0)
        self.s_v = self.s_a / T
        self.xi0 = np.concatenate([np.zeros(self.k), self.C @ qd_g[self.free] / self.s_v])

    @property
    def size(self) -> int:
        """Number of unknowns, 2k."""
        return 2 * self.k

    def constants(self) -> list[np.ndarray]:
        """The start's numbers in the order of :func:`slow_start_functions`' inputs after (xi, p):
        q_g (n,), C (k, n_free), B (n_free, k), d (n_free,), s_a (k,), s_v (k,), t."""
        return [self.q_g, self.C, self.B, self.d, self.s_a, self.s_v, np.array([self.t])]


def initial_directions(model: Model, integ: HHT, n_dir: int) -> ca.Function:
    """``hht_initial_dirs(q, qd, t, p, dq, dqd, dp) -> (qdd, lam, dqdd, dlam)``: the consistent
    accelerations and multipliers (``integ.initial``) and their derivatives along ``n_dir``
    directions (dq, dqd: (n, n_dir), dp: (n_p, n_dir)); one direction's code, mapped."""
    init = integ.initial
    fwd = init.forward(1)
    q, qd, t, p = init.mx_in()
    qdd, lam = init(q, qd, t, p)
    dq, dqd, dp = ca.MX.sym("dq", model.n_dof, n_dir), ca.MX.sym("dqd", model.n_dof, n_dir), ca.MX.sym(
        "dp", model.n_p, n_dir)
    if n_dir == 0:
        return ca.Function("hht_initial_dirs_0", [q, qd, t, p, dq, dqd, dp],
                           [qdd, lam, ca.MX(qdd.numel(), 0), ca.MX(lam.numel(), 0)])
    mapped = fwd.map(f"hht_initial_fwd_{n_dir}", "serial", n_dir, [0, 1, 2, 3, 4, 5], [])
    dqdd, dlam = mapped(q, qd, t, p, qdd, lam, dq, dqd, ca.MX(1, n_dir), dp)
    return ca.Function(f"hht_initial_dirs_{n_dir}", [q, qd, t, p, dq, dqd, dp], [qdd, lam, dqdd, dlam],
                       ["q", "qd", "t", "p", "dq", "dqd", "dp"], ["qdd", "lam", "dqdd", "dlam"])


def scene_start(model: Model, integ: HHT, t0: float, p: ca.MX) -> tuple[ca.MX, ca.MX]:
    """The scene's state at t0 (s) as a function of the parameters p, and dx/dp (nx, n_p)."""
    n, n_p = model.n_dof, model.n_p
    q0, qd0 = ca.DM(model.q0), ca.DM(model.qd0)
    qdd, lam, dqdd, dlam = initial_directions(model, integ, n_p)(q0, qd0, t0, p, ca.DM.zeros(n, n_p),
                                                                  ca.DM.zeros(n, n_p), ca.DM.eye(n_p))
    x = ca.vertcat(q0, qd0, qdd, lam)
    return x, ca.vertcat(ca.MX(2 * n, n_p), dqdd, dlam)


def slow_start_functions(model: Model, integ: HHT, k: int, in_c: bool) -> tuple[ca.Function, ca.Function]:
    """The slow start's value and Jacobian Functions for k slow modes (module docstring):

    ``slow_start_<k>(xi, p, q_g, C, B, d, s_a, s_v, t) -> x`` (nx,) and
    ``slow_start_jac_<k>(...) -> (x, dx_dxi (nx, 2k), dx_dp (nx, n_p))``, the inputs as
    :meth:`SlowStart.constants`. ``in_c``: the NLP is compiled to C (the manifold's Newton is then
    CasADi's ``fast_newton``, :func:`.initial_state.slow_manifold`)."""
    fn = slow_manifold(model, k, codegen=in_c)[0]
    n_p = model.n_p
    xi = ca.MX.sym("xi", 2 * k)
    _, _, QG, CM, BM, P, D = fn.mx_in()
    SA, SV, T = ca.MX.sym("s_a", k), ca.MX.sym("s_v", k), ca.MX.sym("t")
    a, v = xi[:k] * SA, xi[k:] * SV
    args = [xi, P, QG, CM, BM, D, SA, SV, T]
    names = ["xi", "p", "q_g", "C", "B", "d", "s_a", "s_v", "t"]
    q, qd = fn(a, v, QG, CM, BM, P, D)
    qdd, lam = integ.initial(q, qd, T, P)
    value = ca.Function(f"slow_start_{k}", args, [ca.vertcat(q, qd, qdd, lam)], names, ["x"])
    q, qd, dq, dqd = _manifold_derivatives(model, fn, k, a, v, QG, CM, BM, P, D)
    # columns: xi's a (scaled by s_a), xi's v (by s_v), then p
    scale = ca.diag(ca.vertcat(SA, SV))
    dq = ca.horzcat(ca.mtimes(dq[:, :2 * k], scale), dq[:, 2 * k:])
    dqd = ca.horzcat(ca.mtimes(dqd[:, :2 * k], scale), dqd[:, 2 * k:])
    dp = ca.horzcat(ca.DM.zeros(n_p, 2 * k), ca.DM.eye(n_p))
    qdd, lam, dqdd, dlam = initial_directions(model, integ, 2 * k + n_p)(q, qd, T, P, dq, dqd, dp)
    x, S = ca.vertcat(q, qd, qdd, lam), ca.vertcat(dq, dqd, dqdd, dlam)
    jac = ca.Function(f"slow_start_jac_{k}", args, [x, S[:, :2 * k], S[:, 2 * k:]], names,
                      ["x", "dx_dxi", "dx_dp"])
    return value, jac


def _manifold_derivatives(model: Model, fn: ca.Function, k: int, a, v, QG, CM, BM, P, D) -> tuple:
    """(q, qd, dq, dqd) of the slow manifold's state, the derivatives (n, 2k + n_p) in (a, v, p),
    by the implicit-function theorem on its optimality conditions (module docstring). The
    rootfinder is the manifold Function's own, called as it calls it, so q is the value's."""
    G = fn.find_function("slow_manifold_kkt")
    rf = fn.find_function("slow_manifold")
    free, keep, put = _placement(model)
    n, nf, n_p = model.n_dof, free.size, model.n_p
    nz = G.size1_in(0)
    first, second = _kkt_derivatives(G, k, n, nf, n_p)
    z = rf(ca.vertcat(QG[free.tolist()] + ca.mtimes(BM, a), ca.DM.zeros(nz - nf)),
           ca.vertcat(a, QG, ca.vec(CM), P, D))
    G_z, G_th = first(z, a, QG, CM, P, D)
    Z = -ca.solve(G_z, G_th, "qr")  # dz/d(a, p)
    y = ca.mtimes(Z[:, :k], v)  # dz/da v
    second_dirs = second.map(f"slow_second_dirs_{k}", "serial", k + n_p, list(range(8)), [])
    Y = -ca.solve(G_z, second_dirs(z, y, v, a, QG, CM, P, D, Z, ca.DM.eye(k + n_p)), "qr")  # dy/d(a, p)
    put = ca.DM(put)
    q = ca.DM(keep) * QG + ca.mtimes(put, z[:nf])
    qd = ca.mtimes(put, y[:nf])
    Zq, Yq = ca.mtimes(put, Z[:nf, :]), ca.mtimes(put, Y[:nf, :])
    dq = ca.horzcat(Zq[:, :k], ca.DM.zeros(n, k), Zq[:, k:])
    dqd = ca.horzcat(Yq[:, :k], Zq[:, :k], Yq[:, k:])
    return q, qd, dq, dqd


def _kkt_derivatives(G: ca.Function, k: int, n: int, nf: int, n_p: int) -> tuple[ca.Function, ca.Function]:
    """SX derivatives of the manifold's conditions G(z; a, q_g, C, p, d): ``slow_first`` -> (G_z,
    G_(a,p)) and ``slow_second`` -> d/ds [G_z y + G_a v] along one direction s = (dz, d(a, p))."""
    nz = G.size1_in(0)
    z, y = ca.SX.sym("z", nz), ca.SX.sym("y", nz)
    a, v, qg, C, p, d = (ca.SX.sym(s, *shape) for s, shape in (
        ("a", (k,)), ("v", (k,)), ("q_g", (n,)), ("C", (k, nf)), ("p", (n_p,)), ("d", (nf,))))
    g = G(z, ca.vertcat(a, qg, ca.vec(C), p, d))
    th = ca.vertcat(a, p)
    first = ca.Function(f"slow_first_{k}", [z, a, qg, C, p, d], [ca.jacobian(g, z), ca.jacobian(g, th)])
    F = ca.jtimes(g, ca.vertcat(z, a), ca.vertcat(y, v))
    dz, dth = ca.SX.sym("dz", nz), ca.SX.sym("dth", k + n_p)
    second = ca.Function(f"slow_second_{k}", [z, y, v, a, qg, C, p, d, dz, dth],
                         [ca.jtimes(F, ca.vertcat(z, th), ca.vertcat(dz, dth))])
    return first, second
