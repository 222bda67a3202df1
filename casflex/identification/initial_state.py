"""The initial state of a recording that does not start at the scene's: a guess, and the few
numbers a fit may adjust.

**Guess** (:func:`initial_guess`): the measured dofs as measured, the supports' dofs as fixed, the
others from a constrained kinematic fit, the configuration of least elastic energy through the
measured positions, at each of the first samples; velocities from a quadratic through those
configurations at the first sample. The first fit starts from the scene's configuration and
moves the measured dofs to their first values along straight lines (:func:`first_fit`): a
large motion taken in one step can end in a local minimum (threelink 1 s into its motion:
its last joint stretched by 8 cm, 0.43 rad off), so paths of several lengths are taken and the
end of least elastic energy is kept.

**What the fit adjusts** (:class:`InitialState`): only the *slow* part of the state. The model
is linearised at the guess (tangent of the elastic and gravity forces, mass) and its modes are
split at the samples' Nyquist frequency (:func:`slow_modes`). A faster mode (a steel bar's
bending or stretching, at hundreds of hertz) cannot be seen in the samples, only aliased: left
free, the fit uses it to follow the noise (twobar, 0.25 s at 100 Hz: initial rotation rates 19
rad/s off, torsion stiffnesses 6 times too large). The unknowns are the slow-mode amplitudes
a (positions) and v (velocities), and the state lies on the *slow manifold*:

    q0(a) = argmin V_el(q)  subject to  C (q - q_g) = a,     qd0 = dq0/da v,

C = B^T M the modal projection: the fast components take their quasi-static values for the slow
ones, and move with them. A linear modal correction would not do: turning a bar by a few
centimetres along its linearised mode stretches it by millimetres (megaNewtons in steel). The
projection is a Newton solve of its optimality conditions (CasADi's rootfinder), with exact
derivatives through it by the implicit-function theorem. The supports' dofs are never unknowns,
so every estimated state satisfies the constraints.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import casadi as ca
import numpy as np
from scipy.linalg import LinAlgError, eigh, null_space

from casflex.identification.measurement import Experiment, free_dofs, nyquist
from casflex.model import Model

__all__ = ["InitialState", "initial_guess", "slow_modes", "slow_projection", "relaxed_projection", "initial_state_of",
           "initial_states", "slow_manifold", "kinematic_fits"]

_FITS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_LINEAR: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_MANIFOLDS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_ELASTIC: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()

#: Step counts of the paths from the scene's configuration to the first sample (first_fit).
HOMOTOPY_STEPS = (1, 4, 16)


def _placement(model: Model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(free dofs, keep (n,) 1 on the fixed dofs, put (n, n_free) placing the free dofs)."""
    free = free_dofs(model)
    keep = np.ones(model.n_dof)
    keep[free] = 0.0
    put = np.zeros((model.n_dof, free.size))
    put[free, np.arange(free.size)] = 1.0
    return free, keep, put


def _kinematic_fit(model: Model, measured: tuple[int, ...], markers: tuple[int, ...] = ()) -> ca.Function:
    """``kinematic_fit(q_known, q_start, y_known) -> q``: the configuration of least elastic energy
    whose measured and supported dofs take their values in ``q_known``, whose ideal joints are closed
    and whose markers ``markers`` (indices into :func:`casflex.model.markers.marker_channels`) are nearest
    ``y_known``, by IPOPT with the exact Hessian; built once per model, dofs and markers.

    The markers are fitted in the least-squares sense, with the elastic energy weighted so that the
    scene's stiffest motion costs as much as the markers' misfit (1 / max diag of its Hessian
    times the largest squared column of the markers' Jacobian, both at q0): soft motions follow the
    markers, stiff ones stay near their least-energy values. On the leg mid-stride with 1 mm of
    noise this puts the nodes within 0.7 mm, where exact marker constraints bent the bones into a
    configuration 0.2 m and 10 rad off (and five markers on two rigid links have no exact fit)."""
    cache = _FITS.setdefault(model, {})
    key = (measured, markers)
    if key in cache:
        return cache[key]
    n = model.n_dof
    unknown = [i for i in free_dofs(model) if i not in measured]
    QK, Q0, YK = ca.MX.sym("q_known", n), ca.MX.sym("q_start", n), ca.MX.sym("y_known", len(markers))
    names = ["q_known", "q_start", "y_known"]
    if not unknown:  # every free dof is measured: nothing to fit
        cache[key] = ca.Function("kinematic_fit", [QK, Q0, YK], [QK], names, ["q"])
        return cache[key]
    keep = np.ones(n)
    keep[unknown] = 0.0
    put = np.zeros((n, len(unknown)))
    put[unknown, np.arange(len(unknown))] = 1.0
    qk, u, u_ref = ca.SX.sym("q_known", n), ca.SX.sym("u", len(unknown)), ca.SX.sym("u_ref", len(unknown))
    yk = ca.SX.sym("y_known", len(markers))
    q = ca.DM(keep) * qk + ca.mtimes(ca.DM(put), u)
    _, V_el, _ = model.energy(q, ca.DM.zeros(n), model.p_nominal)
    ell = np.where(model.is_rotation[unknown], 1.0, model.length_scale)
    # a weak pull toward the start fixes motions that cost no energy (e.g. a free spin)
    reg = 1e-9 * ca.mmax(ca.fabs(ca.diag(ca.hessian(V_el, u)[0]))) + 1e-12
    f = V_el + 0.5 * reg * model.length_scale**2 * ca.sumsqr((u - u_ref) / ell)
    g = ca.SX(0, 1)
    if markers:
        from casflex.model.markers import marker_kinematics

        y = marker_kinematics(model)(q, ca.DM.zeros(n))[0]
        g = (y[list(markers)] - yk) / model.length_scale
        # least squares, not equalities: noisy markers admit no exact fit where they outnumber the soft
        # motions, and an exact one would bend stiff elements to follow the noise. The elastic energy,
        # scaled so that the stiffest motion weighs as much as the markers, keeps such motions near
        # their least-energy values and chooses among those the markers do not see.
        J = np.array(ca.Function("dg", [u, qk], [ca.jacobian(g, u)])(model.q0[unknown], model.q0))
        H = np.array(ca.Function("h", [u, qk], [ca.hessian(V_el, u)[0]])(model.q0[unknown], model.q0))
        # the stiffest translation: a beam's stretch, a bushing's; a torsion spring (a soft joint, the
        # kind of property identified) is no structural motion to hold and sets no weight: on rigid
        # links between hinges the markers alone decide (a pull toward the springs' nominal rest
        # angles would bias the joint angles that the direct method then fits)
        trans = ~model.is_rotation[unknown]
        stiff = float(np.abs(np.diag(H))[trans].max(initial=0.0))
        mu = float((J**2).sum(axis=0).max()) / stiff if stiff > 0 else 0.0
        f = 0.5 * ca.sumsqr(g) + mu * f
        g = ca.SX(0, 1)
    if model.joint_row_names:  # the ideal joints closed: equalities (the inverse kinematics of a jointed chain)
        g = model.constraint(q)[0][model.n_fixed:] / model.length_scale
    solver = ca.nlpsol("kinematic_fit_nlp", "ipopt", {"x": u, "p": ca.vertcat(qk, u_ref, yk), "f": f, "g": g},
                       {"print_time": False, "ipopt": {"print_level": 0, "sb": "yes", "tol": 1e-12, "max_iter": 200}})
    U = solver(x0=Q0[unknown], p=ca.vertcat(QK, Q0[unknown], YK), lbg=0.0, ubg=0.0)["x"]
    cache[key] = ca.Function("kinematic_fit", [QK, Q0, YK], [ca.DM(keep) * QK + ca.mtimes(ca.DM(put), U)], names,
                             ["q"])
    return cache[key]


def _elastic_energy(model: Model) -> ca.Function:
    """V_el(q) (J) at the nominal parameters, the kinematic fit's objective without its pull."""
    if model not in _ELASTIC:
        q = ca.SX.sym("q", model.n_dof)
        _, V_el, _ = model.energy(q, ca.DM.zeros(model.n_dof), model.p_nominal)
        _ELASTIC[model] = ca.Function("elastic_energy", [q], [V_el])
    return _ELASTIC[model]


def first_fit(model: Model, fit: ca.Function, dofs: list[int], values: np.ndarray, t: float = 0.0,
              markers: tuple[int, ...] = (), y: np.ndarray | None = None) -> np.ndarray:
    """The kinematic fit (``fit``, from :func:`_kinematic_fit`) at the first sample (time t, s), whose
    measured ``dofs`` take ``values`` and ``markers`` the positions ``y``: reached from the scene's
    configuration q0 by paths of :data:`HOMOTOPY_STEPS` steps (the measured dofs, markers and
    supports on the straight line from their scene values to the sample's, each step's fit
    started at the previous one); the end of least elastic energy."""
    energy = _elastic_energy(model)
    fixed = [con.dof for con in model.constraints]
    support, _ = model.supports_at(t)
    y = np.zeros(0) if y is None else np.asarray(y, dtype=float)
    y0 = _marker_values(model, model.q0, markers)
    best, best_v = None, np.inf
    for n in HOMOTOPY_STEPS:
        q = model.q0.copy()
        for s in np.arange(1, n + 1) / n:
            known = q.copy()
            known[dofs] = (1.0 - s) * model.q0[dofs] + s * values
            known[fixed] = (1.0 - s) * model.q0[fixed] + s * support
            q = fit_step(model, fit, known, q, (1.0 - s) * y0 + s * y)
        v = float(energy(q))
        if np.isfinite(v) and v < best_v:
            best, best_v = q, v
    if best is None:
        raise ValueError("data: the kinematic fit at the first sample failed (no finite elastic energy); check "
                         "that the channels are the scene's dofs and markers in m and rad")
    return best


def fit_step(model: Model, fit: ca.Function, known: np.ndarray, q_start: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``fit(known, q_start, y)``, kept within half a turn of ``q_start`` in every rotation: the beams
    cannot tell a node turned by whole turns (their local rotations are wrapped) and IPOPT may land
    there, the torsion springs can (leg from its markers mid-motion: the shank's knee node 3 turns
    off, 1528 J of elastic energy instead of 6). Such a fit is redone from the unwound point."""
    q = np.array(fit(known, q_start, y)).ravel()
    turns = np.where(model.is_rotation, np.round((q - q_start) / (2 * np.pi)), 0.0)
    if turns.any():
        q = np.array(fit(known, q - 2 * np.pi * turns, y)).ravel()
    return q


def _marker_values(model: Model, q: np.ndarray, markers: tuple[int, ...]) -> np.ndarray:
    """Positions (m) of the marker coordinates ``markers`` (indices into the marker channels) at q."""
    if not markers:
        return np.zeros(0)
    from casflex.model.markers import marker_positions

    return marker_positions(model, q)[0][list(markers)]


def initial_guess(model: Model, experiment: Experiment, m: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """(q0, qd0), shape (n_dof,) each: a first guess of the state at the first sample.

    Positions: the scene's for ``initial_state`` "scene" and "velocities"; for "estimate", the
    kinematic fit at the first sample. Velocities: the scene's for "scene"; otherwise the
    derivative at the first sample of a quadratic through the kinematic fits at the first ``m``
    samples that have every compared channel.
    """
    data = experiment.data
    fixed = [con.dof for con in model.constraints]
    if experiment.initial_state == "scene":
        q0, qd0 = model.q0.copy(), model.qd0.copy()
        q0[fixed], qd0[fixed] = model.supports_at(float(data.t[0]))
        return q0, qd0
    tt, Q = kinematic_fits(model, data, list(experiment.compared(model)), limit=m)
    tt = tt - data.t[0]
    q0 = Q[0] if experiment.initial_state == "estimate" else model.q0.copy()
    degree = min(2, len(tt) - 1)
    qd0 = np.polynomial.polynomial.polyfit(tt, Q, degree)[1] if degree >= 1 else np.zeros(model.n_dof)
    q0[fixed], qd0[fixed] = model.supports_at(float(data.t[0]))
    return q0, qd0


def kinematic_fits(model: Model, data, names: list[str], limit: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(times (s, m), configurations (m, n_dof)): the kinematic fit at each sample that has every
    channel of ``names`` (node dofs and markers), the first one by :func:`first_fit`, each later
    one started at the one before; the first ``limit`` such samples (default all)."""
    from casflex.model.markers import marker_channels

    channels = marker_channels(model)
    dof_names = [c for c in names if c in model.dof_names]
    marker_names = [c for c in names if c in channels]
    dofs = [model.dof(c) for c in dof_names]
    markers = tuple(channels.index(c) for c in marker_names)
    order = np.argsort(dofs)
    fit = _kinematic_fit(model, tuple(np.asarray(dofs, dtype=int)[order].tolist()), markers)
    fixed = [con.dof for con in model.constraints]
    cols = [data.channels.index(c) for c in dof_names]
    mcols = [data.channels.index(c) for c in marker_names]
    fits, times = [], []
    for i in range(data.t.size):
        if len(fits) == limit:
            break
        values, y = data.q[i, cols], data.q[i, mcols]
        if not (np.isfinite(values).all() and np.isfinite(y).all()):
            continue
        if not fits:
            q_prev = first_fit(model, fit, dofs, values, float(data.t[i]), markers, y)
        else:
            known = q_prev.copy()
            known[dofs] = values
            known[fixed] = model.supports_at(float(data.t[i]))[0]
            q_prev = fit_step(model, fit, known, q_prev, y)
        fits.append(q_prev)
        times.append(data.t[i])
    if not fits:
        raise ValueError("data: no sample has every compared channel; cannot estimate the initial state")
    return np.array(times), np.array(fits)


def slow_modes(model: Model, q: np.ndarray, p: np.ndarray, omega_cut: float) -> np.ndarray:
    """Mode shapes (n_free, k) over the free dofs of the model linearised at q whose
    |omega| < ``omega_cut`` (rad/s), M-orthonormal; with ideal joints, among the motions that keep
    them closed (the null space of their B). Modes of negative stiffness (a pendulum away from its
    rest) count as slow. Where the reduced mass is singular (free dofs without mass), every free
    motion is kept."""
    if model not in _LINEAR:
        qs, ps = ca.SX.sym("q", model.n_dof), ca.SX.sym("p", model.n_p)
        _, f_int, g = model.forces(qs, ca.DM.zeros(model.n_dof), ps)
        _LINEAR[model] = ca.Function("linearise", [qs, ps], [ca.jacobian(f_int - g, qs), model.mass(qs, ps)])
    free = free_dofs(model)
    K, M = (np.asarray(v, dtype=float)[np.ix_(free, free)] for v in _LINEAR[model](q, p))
    N = np.eye(free.size)  # the motions: the free dofs, or those that keep the ideal joints closed
    if model.joint_row_names:
        N = null_space(np.array(model.constraint(q)[1])[model.n_fixed:][:, free])
    try:
        w2, V = eigh(N.T @ (0.5 * (K + K.T)) @ N, N.T @ (0.5 * (M + M.T)) @ N)
    except LinAlgError:  # singular mass: no modal reduction
        return N
    return N @ V[:, np.abs(w2) < omega_cut**2]


def slow_manifold(model: Model, k: int, codegen: bool = False) -> tuple[ca.Function, ca.Function]:
    """The slow-manifold map and its Jacobian for k slow modes (module docstring):
    ``slow_state(a, v, q_g, C, B, p, d) -> (q0, qd0)`` on all dofs and
    ``slow_state_jac(...) -> (dq0/da, dqd0/da, dqd0/dv)``. d scales the force rows (stiffness).
    ``codegen``: for a graph that is compiled to C (a compiled NLP): the Newton solve is CasADi's
    ``fast_newton``, the only rootfinder its code generator supports; where it does not converge
    it gives NaN, not an exception (an NLP solver then shortens its step)."""
    cache = _MANIFOLDS.setdefault(model, {})
    if (k, codegen) in cache:
        return cache[(k, codegen)]
    n = model.n_dof
    free, keep, put = _placement(model)
    nf = free.size
    qf, mu = ca.SX.sym("qf", nf), ca.SX.sym("mu", k)
    a, qg, C, p, d = (ca.SX.sym(s, *shape) for s, shape in (("a", (k,)), ("q_g", (n,)), ("C", (k, nf)),
                                                            ("p", (model.n_p,)), ("d", (nf,))))
    q = ca.DM(keep) * qg + ca.mtimes(ca.DM(put), qf)
    _, V_el, _ = model.energy(q, ca.DM.zeros(n), p)
    # ideal joints: closed on the manifold (their multipliers nu join the unknowns), so that the state
    # and its velocities dq0/da v satisfy them for every a
    phi_j = model.constraint(q)[0][model.n_fixed:] / model.length_scale
    nu = ca.SX.sym("nu", phi_j.numel())
    force = ca.gradient(V_el, qf) + ca.mtimes(C.T, mu) + ca.mtimes(ca.jacobian(phi_j, qf).T, nu)
    kkt = ca.vertcat(force / d, ca.mtimes(C, qf - qg[free]) - a, phi_j)
    G = ca.Function("slow_manifold_kkt", [ca.vertcat(qf, mu, nu), ca.vertcat(a, qg, ca.vec(C), p, d)], [kkt])
    # plain Newton steps: CasADi's line search on |kkt| stalls near the solution where the KKT matrix
    # is ill-conditioned (threelink mid-motion: cond 6e9, a residual of 2e-8 never decreased)
    tols = {"abstol": 1e-13, "abstolStep": 1e-14, "max_iter": 50}
    rf = (ca.rootfinder("slow_manifold", "fast_newton", G, tols) if codegen else
          ca.rootfinder("slow_manifold", "newton", G, {**tols, "line_search": False, "error_on_fail": True}))
    A, Vv, QG, CM, BM, P, D = (ca.MX.sym(s, *shape) for s, shape in (
        ("a", (k,)), ("v", (k,)), ("q_g", (n,)), ("C", (k, nf)), ("B", (nf, k)), ("p", (model.n_p,)), ("d", (nf,))))
    z = rf(ca.vertcat(QG[free] + ca.mtimes(BM, A), ca.DM.zeros(k + nu.numel())), ca.vertcat(A, QG, ca.vec(CM), P, D))
    q0 = ca.DM(keep) * QG + ca.mtimes(ca.DM(put), z[:nf])
    qd0 = ca.mtimes(ca.DM(put), ca.mtimes(ca.jacobian(z[:nf], A), Vv))
    args = [A, Vv, QG, CM, BM, P, D]
    names = ["a", "v", "q_g", "C", "B", "p", "d"]
    cache[(k, codegen)] = (
        ca.Function("slow_state", args, [q0, qd0], names, ["q0", "qd0"]),
        ca.Function("slow_state_jac", args, [ca.jacobian(q0, A), ca.jacobian(qd0, A), ca.jacobian(qd0, Vv)],
                    names, ["dq0_da", "dqd0_da", "dqd0_dv"]))
    return cache[(k, codegen)]


@dataclass(frozen=True, eq=False)
class InitialState:
    """An experiment's initial state as a function of its unknowns xi (module docstring).

    kind "scene": no unknowns. "velocities": xi = v (positions q_g trusted). "estimate":
    xi = (a, v). ``xi0`` puts the state at the guess, its velocity projected on the manifold.
    """

    model: Model
    kind: str
    q_guess: np.ndarray
    qd_guess: np.ndarray
    basis: np.ndarray
    projection: np.ndarray
    p: np.ndarray
    scale: np.ndarray

    @property
    def k(self) -> int:
        return self.basis.shape[1]

    @property
    def size(self) -> int:
        return {"scene": 0, "velocities": 1, "estimate": 2}[self.kind] * self.k

    @property
    def xi0(self) -> np.ndarray:
        v = self.projection @ self.qd_guess[free_dofs(self.model)]
        return {"scene": np.zeros(0), "velocities": v, "estimate": np.concatenate([np.zeros(self.k), v])}[self.kind]

    def _split(self, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return (xi[:self.k], xi[self.k:]) if self.kind == "estimate" else (np.zeros(self.k), xi)

    def _args(self, xi: np.ndarray) -> list:
        a, v = self._split(xi)
        return [a, v, self.q_guess, self.projection, self.basis, self.p, self.scale]

    def state(self, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(q0, qd0), full dof vectors."""
        if self.kind == "scene":
            return self.q_guess.copy(), self.qd_guess.copy()
        q0, qd0 = (np.array(v).ravel() for v in slow_manifold(self.model, self.k)[0](*self._args(xi)))
        fixed = [con.dof for con in self.model.constraints]
        qd0[fixed] = self.qd_guess[fixed]  # a moving support's rates (the manifold keeps the supports still)
        return q0, qd0

    def jacobian(self, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(dq0/dxi, dqd0/dxi), each (n_dof, size)."""
        n = self.model.n_dof
        if self.kind == "scene":
            return np.zeros((n, 0)), np.zeros((n, 0))
        dq_da, dqd_da, dqd_dv = (np.array(v) for v in slow_manifold(self.model, self.k)[1](*self._args(xi)))
        if self.kind == "velocities":
            return np.zeros((n, self.k)), dqd_dv
        return np.hstack([dq_da, np.zeros((n, self.k))]), np.hstack([dqd_da, dqd_dv])


def initial_state_of(model: Model, experiment: Experiment, p: np.ndarray,
                     guess: tuple[np.ndarray, np.ndarray] | None = None) -> InitialState:
    """The :class:`InitialState` of ``experiment`` from its guess (or the given one) relaxed onto
    its slow manifold, the slow modes there below the recording's Nyquist frequency, and the
    parameters p."""
    q_g, qd_g = initial_guess(model, experiment) if guess is None else guess
    free = free_dofs(model)
    if experiment.initial_state == "scene":
        empty = np.zeros((free.size, 0))
        return InitialState(model, "scene", q_g, qd_g, empty, empty.T, p, np.ones(free.size))
    q_g, B, C, d = relaxed_projection(model, q_g, p, nyquist(experiment))
    return InitialState(model, experiment.initial_state, q_g, qd_g, B, C, p, d)


def relaxed_projection(model: Model, q: np.ndarray, p: np.ndarray, omega_cut: float
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(q_r, B, C, d): q relaxed onto its slow manifold (a = 0: the fast components quasi-static)
    and :func:`slow_projection` there. A kinematic fit through channels that over-determine a body
    (a node and a marker on one bar) stretches it by the noise (twobar at 0.1 mm: 2e5 N), whose
    geometric stiffness distorts the modes at q: fits linearised there ended far off (k3 55-92 %)."""
    B, C, d = slow_projection(model, q, p, omega_cut)
    k = B.shape[1]
    if k == 0:
        return q, B, C, d
    q_r = np.array(slow_manifold(model, k)[0](np.zeros(k), np.zeros(k), q, C, B, p, d)[0]).ravel()
    return (q_r, *slow_projection(model, q_r, p, omega_cut))


def slow_projection(model: Model, q: np.ndarray, p: np.ndarray, omega_cut: float
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The slow manifold's data at q (module docstring): the slow modes B (n_free, k) below
    ``omega_cut`` (rad/s), their projection C = B^T M (k, n_free) and the force rows' scales d (n_free,)."""
    free = free_dofs(model)
    B = slow_modes(model, q, p, omega_cut)
    K, M = (np.asarray(v, dtype=float)[np.ix_(free, free)] for v in _LINEAR[model](q, p))
    C = B.T @ M
    if np.linalg.matrix_rank(C) < B.shape[1]:  # no modal reduction (massless free dofs): C = B^T
        C = B.T
    d = np.abs(np.diag(K))
    return B, C, np.maximum(d, 1e-9 * d.max(initial=0.0) + 1e-300)


def initial_states(model: Model, experiments: list[Experiment], p: np.ndarray,
                   states: list[tuple[np.ndarray, np.ndarray]] | None = None) -> list:
    """Every experiment's :class:`InitialState` at its guess (or the given states)."""
    return [initial_state_of(model, e, p, None if states is None else states[i]) for i, e in enumerate(experiments)]
