"""Static optimization with compliant tendons: each muscle's tension is its tendon's force, the fibre and the tendon
in static equilibrium at the frame's muscle-tendon length (``StaticOptimization(tendon="compliant")``).

OpenSim's StaticOptimization always takes the tendon as rigid (``calcInextensibleTendonActiveFiberForce``); a long
tendon (the soleus's and gastrocnemii's, some 0.25-0.4 m beside a 5 cm fibre) stretches some 3-5 % at the forces
of gait and running, so that its fibre is shorter than the rigid tendon's and works elsewhere on its force-length
curve. Here the equilibrium is a constraint of the sparse problem, with the normalised fibre length l~ = l/l_opt of
every muscle at every frame an unknown beside its activation a:

    F_iso (a f_L(l~) [+ f_PE(l~)]) cos(phi) = F_iso f_T(l_T / l_Ts),    l_T = L_MT - l cos(phi)    (equilibrium)
    sum_m r_mc F_iso f_T(l_T,m / l_Ts,m) + R_c u_c = tau_c                                           (balance)

with the fixed-width pennation (l sin(phi) = l_opt sin(phi_opt)), the muscle's own curves (:mod:`casflex.muscles.
curves`; f_PE only with ``passive=True``, as the rigid problem applies passive forces only then) and the fibre's
velocity taken as 0 (f_V = 1, no damping): OpenSim's ``Millard2012EquilibriumMuscle::computeFiberEquilibrium(s,
solveForVelocity=false)``, the equilibrium its tools start a simulation from. The cost is the rigid problem's,
sum a^p + sum |u|^p. All frames are one sparse problem (each frame's unknowns meet only its own rows), solved by
IPOPT from the rigid tendon's fibre lengths. The forces reported are the tendons'.
"""

from __future__ import annotations

import math
import time

import casadi as ca
import numpy as np

from casflex.muscles.curves import muscle_curves, pennation
from casflex.muscles.static_optimization import (
    StaticOptimization,
    StaticOptimizationResult,
    _check,
    _report,
    finite_array,
)

__all__ = ["solve_compliant", "tendon_equilibrium"]

#: fibre minus tendon force over F_iso at which :func:`tendon_equilibrium` takes IPOPT's point as the equilibrium
EQUILIBRIUM_TOL = 1e-9


def _frame_terms(m, lmt, a, ln, passive: bool):
    """(tendon force N, fibre force along the tendon N) of muscle m at muscle-tendon length lmt (m), activation a and
    normalised fibre length ln (CasADi expressions); the fibre's velocity 0 (f_V = 1)."""
    c, pen = muscle_curves(m), pennation(m)
    lopt, fiso = m.optimal_fiber_length, m.max_isometric_force
    lce = ln * lopt
    along = ca.sqrt(lce ** 2 - pen.width ** 2) if pen.width > 0 else lce
    cos = along / lce
    tendon = fiso * c.tendon_force_length((lmt - along) / m.tendon_slack_length)
    fibre = fiso * (a * c.active_force_length(ln) + (c.passive_force_length(ln) if passive else 0.0)) * cos
    return tendon, fibre


def _fibre_bounds(m) -> tuple[float, float]:
    """The normalised fibre length's lower bound (above the pennation model's minimum: cos(phi) > 0, and 0.05) and
    a nominal upper one (2; the frames' own: :func:`_rigid_start`)."""
    pen = pennation(m)
    low = max(pen.minimum_fiber_length / m.optimal_fiber_length, 0.05) * (1 + 1e-9)
    return low, 2.0


def _rigid_start(m, lmt: np.ndarray) -> np.ndarray:
    """The rigid tendon's normalised fibre lengths (the tendon at its slack length), at least the lower bound: the
    fibre's longest (a longer one would leave the tendon slack, pulling nothing, while the fibre pulls)."""
    at = np.maximum(lmt - m.tendon_slack_length, 0.0)
    ln = np.sqrt(at ** 2 + pennation(m).width ** 2) / m.optimal_fiber_length
    return np.maximum(ln, _fibre_bounds(m)[0] * (1 + 1e-9))


def tendon_equilibrium(m, lmt: float, a: float, *, passive: bool = True) -> tuple[float, float]:
    """(tendon force N, normalised fibre length) of muscle m at muscle-tendon length lmt (m) and activation a, the
    fibre's velocity 0 (module docstring): the fibre-tendon equilibrium solved by IPOPT (a scalar root); a muscle
    too short to be in equilibrium (:func:`_slack`: its tendon slack) carries nothing, (0, its shortest fibre)
    as :func:`solve_compliant` takes it; ValueError naming the muscle where IPOPT finds no equilibrium else (its
    last iterate is none: it was returned)."""
    ln = ca.SX.sym("ln")
    tendon, fibre = _frame_terms(m, lmt, a, ln, passive)
    lo = _fibre_bounds(m)[0]
    if _slack(m, np.array([lmt]), a, passive)[0]:
        return 0.0, lo
    solver = ca.nlpsol("equilibrium", "ipopt", {"x": ln, "f": 0, "g": (fibre - tendon) / m.max_isometric_force},
                       {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes", "ipopt.tol": 1e-14})
    top = float(_rigid_start(m, np.array([lmt]))[0])
    out = solver(x0=top, lbx=lo, ubx=max(top, lo), lbg=0, ubg=0)
    x, miss = float(out["x"]), abs(float(out["g"]))
    # the equilibrium is the root, whatever IPOPT's status: at its 1e-14 it may stop with a search direction too small
    # on a root it has (glut_med3_r); what it returns off a root (a slack tendon's 15.5 N) is refused. 1e-9 of F_iso:
    # a micronewton on a muscle of 1 kN, far below OpenSim's own equilibrium tolerance
    if not (solver.stats()["success"] or miss <= EQUILIBRIUM_TOL):
        raise ValueError(f"muscle {m.name!r}: no fibre-tendon equilibrium at a muscle-tendon length of {lmt:g} m and "
                         f"activation {a:g} (IPOPT: {solver.stats()['return_status']}, its fibre and tendon forces "
                         f"{miss:.2g} F_iso apart)")
    return float(ca.Function("t", [ln], [tendon])(x)), x


def _frame_function(muscles, n_c: int, n_r: int, held: np.ndarray, reserves: np.ndarray, scale: np.ndarray,
                    passive: bool, p: float) -> ca.Function:
    """One frame's (cost, rows) of v = [a, l~, u+, u-] and the frame's (lmt, arms (n_m n_c, muscle-major), target):
    rows = [equilibrium over F_iso (n_m); balance over the coordinates' scale (n_c)]."""
    n_m = len(muscles)
    v, lmt, live = ca.SX.sym("v", 2 * n_m + 2 * n_r), ca.SX.sym("lmt", n_m), ca.SX.sym("live", n_m)
    arms, target = ca.SX.sym("arms", n_m * n_c), ca.SX.sym("target", n_c)
    a, ln, up, um = v[:n_m], v[n_m:2 * n_m], v[2 * n_m:2 * n_m + n_r], v[2 * n_m + n_r:]
    eq, T = [], []
    for i, m in enumerate(muscles):
        tendon, fibre = _frame_terms(m, lmt[i], a[i], ln[i], passive)
        # a slack muscle (:func:`_slack`) carries nothing; its fibre length is held at the bound
        eq.append(live[i] * (fibre - tendon) / m.max_isometric_force + (1 - live[i]) * (ln[i] - _fibre_bounds(m)[0]))
        T.append(live[i] * tendon)
    carried = ca.mtimes(ca.reshape(arms, n_c, n_m), ca.vertcat(*T)) if n_m else ca.SX.zeros(n_c)
    for j, c in enumerate(held):
        carried[int(c)] += reserves[int(c)] * (up[j] - um[j])
    rows = ca.vertcat(*eq, (carried - target) / ca.DM(scale))
    cost = ca.sum1(a ** p) + ca.sum1(up ** p) + ca.sum1(um ** p)
    return ca.Function("compliant_frame", [v, lmt, live, arms, target], [cost, rows, ca.vertcat(*T)])


def _slack(m, lmt: np.ndarray, lowest: float, passive: bool) -> np.ndarray:
    """Where (frames) the muscle is too short to be in equilibrium at the lowest activation: even at its shortest
    fibre (the longest tendon) the tendon pulls less than the fibre does at that activation, so the tendon is slack
    and the muscle carries nothing (as the rigid tendon's muscle, whose force is 0 at or below its minimum fibre
    length)."""
    c, pen = muscle_curves(m), pennation(m)
    ln = _fibre_bounds(m)[0]
    lce = ln * m.optimal_fiber_length
    along = math.sqrt(max(lce ** 2 - pen.width ** 2, 0.0))
    tendon = np.asarray(c.tendon_force_length((lmt - along) / m.tendon_slack_length), dtype=float)
    fibre = lowest * float(c.active_force_length(ln)) + (float(c.passive_force_length(ln)) if passive else 0.0)
    return tendon < fibre * along / lce


def solve_compliant(moments, arms, lengths, muscles, reserves=None, options: StaticOptimization | None = None, *,
                    coordinates=None) -> StaticOptimizationResult:
    """Static optimization of k frames with compliant tendons (module docstring): moments (k, n_c) N m, arms
    (k, n_m, n_c) m, lengths (k, n_m) the muscle-tendon lengths (m), ``muscles`` (n_m,) their
    :class:`~casflex.scene.muscles.Muscle`; reserves and ``options`` as :func:`~casflex.muscles.static_optimization.
    solve_static_optimization`'s. The result's forces are the tendons' (N); ``stats["norm_fiber_length"]`` (k, n_m)
    the fibres' normalised lengths. ValueError for a frame the activations cannot carry (IPOPT's status)."""
    options = options or StaticOptimization(tendon="compliant")
    k = np.asarray(moments).shape[0]
    m_, arms, _, _, r, names = _check(moments, arms, np.zeros((k, len(muscles))), None, reserves, coordinates)
    k, n_m, n_c = arms.shape
    lmt = finite_array("lengths", lengths, (k, n_m))
    start = time.perf_counter()
    held = np.flatnonzero(r > 0.0)
    n_r = held.size
    # rows nothing acts on (a coordinate no muscle crosses and no reserve holds) are left out, as the rigid problem
    # leaves them (their moment then out of reach): a row of zeros makes IPOPT's constraint Jacobian singular
    acts = (np.abs(arms).max(axis=(0, 1)) > 1e-9) | (r > 0.0)
    sub = np.flatnonzero(acts)
    scale = np.maximum(np.sqrt(np.mean(m_ ** 2, axis=0)), 1e-6)
    held_sub = np.flatnonzero(r[sub] > 0.0)
    f = _frame_function(muscles, sub.size, n_r, held_sub, r[sub], scale[sub], options.passive, options.exponent)
    n_v = 2 * n_m + 2 * n_r
    x = ca.MX.sym("x", n_v, k)
    fm = f.map(k)
    lo, hi = options.bounds(n_m)
    live = np.column_stack([~_slack(m, lmt[:, i], lo[i], options.passive)
                            for i, m in enumerate(muscles)]).astype(float) if n_m else np.zeros((k, 0))
    args = (lmt.T, live.T, arms[:, :, sub].reshape(k, n_m * sub.size).T, m_[:, sub].T)
    cost, rows, _ = fm(x, *args)
    rlo, rhi = options.reserve_bounds
    bounds = [_fibre_bounds(m) for m in muscles]
    longest = np.column_stack([_rigid_start(m, lmt[:, i]) for i, m in enumerate(muscles)]) if n_m else \
        np.zeros((k, 0))
    lbx = np.tile(np.r_[lo, [b[0] for b in bounds], np.zeros(2 * n_r)], (k, 1))
    ubx = np.column_stack([np.broadcast_to(hi, (k, n_m)), longest, np.full((k, n_r), rhi), np.full((k, n_r), -rlo)])
    x0 = np.column_stack([np.broadcast_to(lo, (k, n_m)), longest, np.zeros((k, 2 * n_r))])
    tol = options.tolerance
    solver = ca.nlpsol("compliant_static_optimization", "ipopt",
                       {"x": ca.vec(x), "f": ca.sum2(cost), "g": ca.vec(rows)},
                       {"ipopt.tol": max(tol, 1e-9), "ipopt.constr_viol_tol": max(tol, 1e-9),
                        "ipopt.max_iter": options.max_iterations, "ipopt.print_level": 0, "print_time": False,
                        "ipopt.sb": "yes", "ipopt.mu_strategy": "adaptive"})
    sol = solver(x0=x0.ravel(), lbx=lbx.ravel(), ubx=ubx.ravel(), lbg=0, ubg=0)
    stats = solver.stats()
    v = np.array(sol["x"]).reshape(k, n_v)
    if not stats["success"]:
        raise ValueError(f"static optimization (compliant tendons): IPOPT stopped ({stats['return_status']}) after "
                         f"{stats['iter_count']} iterations: the moments may be out of the muscles' reach with their "
                         "tendons stretched; add reserves, or solve with rigid tendons to find the frames")
    a = v[:, :n_m]
    T = np.array(ca.Function("tendons", [x], [fm(x, *args)[2]])(v.T)).T
    u = np.zeros((k, n_c))
    u[:, held] = v[:, 2 * n_m:2 * n_m + n_r] - v[:, 2 * n_m + n_r:]
    moments_r = u * r
    carried = np.einsum("kmc,km->kc", arms, T) + moments_r
    rms = np.sqrt(np.mean(m_ ** 2, axis=0))
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(rms > 0.0, np.sqrt(np.mean(moments_r ** 2, axis=0)) / rms, np.nan)
    violation = carried - m_
    out_of_reach = [(0, names[c], float(np.abs(m_[:, c]).max())) for c in np.flatnonzero(~acts)
                    if np.abs(m_[:, c]).max() > 1e3 * tol * scale[c]]
    report = _report(tuple(out_of_reach), len(out_of_reach), m_, names) if out_of_reach else ""
    if out_of_reach and options.infeasible == "raise":
        raise ValueError(report)
    extra = {"norm_fiber_length": v[:, n_m:2 * n_m], "slack": live < 0.5, "return_status": stats["return_status"]}
    return StaticOptimizationResult(a, T, u, moments_r, share, violation, tuple(out_of_reach), report,
                                    int(stats["iter_count"]), time.perf_counter() - start, extra)
