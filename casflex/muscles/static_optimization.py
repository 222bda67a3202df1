"""Static optimization as OpenSim 4.6 computes it, on arrays: the activations that carry a trial's joint moments at
least cost, frame by frame (docs/muscles.md, "What OpenSim's static optimization does").

At each frame k the unknowns are the muscles' activations a (n_m) and the reserves' controls u (one per coordinate
that has a reserve, a ``CoordinateActuator`` of optimal force R_c: its moment is u_c R_c). They minimise

    sum_m a_m^p + sum_c |u_c|^p          (p: OpenSim's activation_exponent; reserves count as muscles do)

subject to the generalized forces' balance on every coordinate c,

    sum_m r_mc(k) a_m F_m(k) + R_c u_c = tau_c(k) - sum_m r_mc(k) P_m(k)        (N m, or N on a translation)

with r (m) the moment arms, F (N) each muscle's active force at full activation (OpenSim's
``calcInextensibleTendonActiveFiberForce(s, 1)``; the max isometric force with ``force_length_velocity=False``),
tau the inverse dynamics' generalized forces and P the passive fibre forces: OpenSim's SO overrides each muscle's
whole tension with a F, so passive forces do not enter (``passive=False``, its behaviour; True applies them as
known forces), and the bounds lo <= a <= hi (OpenSim: the muscles' min_control and max_control; Millard's
min_control is its minimum_activation, 0.01), u free (or within ``reserve_bounds``).

OpenSim states the balance as accelerations (udot(a, u) = the kinematics' udot), the same set of solutions since
the mass matrix is invertible; it solves each frame with IPOPT to its ``optimizer_convergence_criterion`` (1e-4,
loose). Here all frames are one sparse problem (block diagonal: a frame's unknowns meet only its own rows), solved
to ``tolerance``: for p = 2 a QP, by CasADi's interior-point ``ipqp`` (0.45 s CPU for the 166 frames, 80 muscles
and 11 coordinates of the Rajagopal pipeline's walk; IPOPT 1.2-1.5 s, per frame 1.4 s; OpenSim's SO 28 s wall),
else by IPOPT.
The reserves' |u|^p is u+^p + u-^p with u = u+ - u-, u+- >= 0 (exact at the optimum, smooth for any p >= 1).
A frame whose moments no activation within the bounds can carry is found, when the solve fails, by a problem
that minimises the shortfall |A x - b|_1 (an exact measure: the least moment the bounds leave uncarried);
with ``infeasible="raise"`` (default) it is refused naming the frame, the coordinate and the shortfall; with
"report" those frames carry what they can (the moments minus the least shortfall) and the result says so.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

__all__ = ["MAX_EXPONENT", "DEFAULT_BOUNDS", "StaticOptimization", "StaticOptimizationError",
           "StaticOptimizationResult", "solve_static_optimization"]

#: The largest exponent p of the cost sum a^p taken: at p = 20 a^p of an activation at its bound 0.01 is 1e-40 and
#: IPOPT stopped on Hamner's run (Maximum_Iterations, a traceback), at 10 it converged (the literature's criteria
#: are p = 1, 2, 3 and the min-max one, which large p only approaches).
MAX_EXPONENT = 10.0


class StaticOptimizationError(RuntimeError):
    """IPOPT stopped short on moments the activations can carry (an exponent other than 2 at a hard frame); the
    message names the frames (their times where given) and what to try; ``frames`` their indices."""

    def __init__(self, message: str, frames: tuple[int, ...] = ()):
        super().__init__(message)
        self.frames = frames


#: each muscle kind's activation bounds in OpenSim 4.6 where its file gives no min_control / max_control (a new
#: muscle's ``finalizeFromProperties(); getMinControl()``): Millard's min_control is its minimum_activation (0.01)
DEFAULT_BOUNDS = {"Millard2012EquilibriumMuscle": (0.01, 1.0), "Thelen2003Muscle": (0.01, 1.0),
                  "DeGrooteFregly2016Muscle": (0.0, 1.0)}


@dataclass(frozen=True)
class StaticOptimization:
    """Static optimization's choices (OpenSim's names in brackets).

    exponent : p >= 1 of the cost sum a^p + sum |u|^p [activation_exponent, 2]
    force_length_velocity : a muscle's force per unit activation is its active force at full activation along
        the fibres' force-length-velocity curves (True); False: its max isometric force [use_muscle_physiology]
    passive : apply the passive fibre forces as known forces (True); OpenSim's SO does not (False)
    activation_bounds : (lower, upper) of every activation [the muscles' min_control, max_control]; None: each
        muscle kind's OpenSim default (:data:`DEFAULT_BOUNDS`: 0.01, 1 for Millard2012EquilibriumMuscle, whose
        min_control is its minimum_activation, and Thelen2003Muscle; 0, 1 for DeGrooteFregly2016Muscle), which
        :class:`casflex.muscles.analysis.TrialMuscles` sets per muscle in ``muscle_bounds``; without them (this
        class alone) 0.01, 1
    muscle_bounds : ((lower, upper), ...) one pair per muscle, in place of ``activation_bounds`` where the muscles'
        own differ [each muscle's min_control, max_control: OpenSim bounds each by its own]; () every muscle by
        ``activation_bounds``
    reserve_bounds : (lower, upper) of the reserves' controls [their min_control, max_control: -inf, inf]
    tolerance : IPOPT's tol and constr_viol_tol (relative to the moments' scale) [optimizer_convergence_criterion,
        1e-4: loose; 1e-10 here so that the answer is the optimum, not an iterate near it]
    max_iterations : IPOPT's iteration limit for the whole trial [optimizer_max_iterations, 100, per frame]
    infeasible : "raise" (a frame no activation satisfies is refused) or "report" (it carries what it can and
        the result's ``report`` names it)
    tendon : "rigid" (OpenSim's: the tendon at its slack length) or "compliant" (each muscle's fibre and tendon in
        static equilibrium, its fibre length an unknown: :mod:`casflex.muscles.compliant`; needs
        force_length_velocity)
    """

    exponent: float = 2.0
    force_length_velocity: bool = True
    passive: bool = False
    activation_bounds: tuple[float, float] | None = None
    muscle_bounds: tuple[tuple[float, float], ...] = ()
    reserve_bounds: tuple[float, float] = (-math.inf, math.inf)
    tolerance: float = 1e-10
    max_iterations: int = 3000
    infeasible: str = "raise"
    tendon: str = "rigid"

    def __post_init__(self) -> None:
        if not _real(self.exponent) or not 1.0 <= self.exponent <= MAX_EXPONENT:
            raise ValueError(f"exponent: expected a number >= 1 and at most {MAX_EXPONENT:g} (OpenSim's "
                             f"activation_exponent), got {self.exponent!r}")
        for name in ("force_length_velocity", "passive"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name}: expected True or False, got {getattr(self, name)!r}")
        lo, hi = _pair("activation_bounds", self.activation_bounds) if self.activation_bounds is not None else \
            DEFAULT_BOUNDS["Millard2012EquilibriumMuscle"]
        if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo < hi <= 1.0):
            raise ValueError("activation_bounds: expected 0 <= lower < upper <= 1 (an activation is the fraction of "
                             f"the muscle's force it gives), got {self.activation_bounds!r}")
        for i, pair in enumerate(self.muscle_bounds):
            lo, hi = _pair(f"muscle_bounds[{i}]", pair)
            if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo < hi <= 1.0):
                raise ValueError(f"muscle_bounds[{i}]: expected 0 <= lower < upper <= 1, got {pair!r}")
        lo, hi = _pair("reserve_bounds", self.reserve_bounds)
        if not (lo <= 0.0 <= hi and lo < hi):
            raise ValueError(f"reserve_bounds: expected lower <= 0 <= upper, got {self.reserve_bounds!r}")
        if not _real(self.tolerance) or not 0.0 < self.tolerance < 1e-2:
            raise ValueError(f"tolerance: expected a number in (0, 1e-2), got {self.tolerance!r}")
        if isinstance(self.max_iterations, bool) or not isinstance(self.max_iterations, int) or self.max_iterations < 1:
            raise ValueError(f"max_iterations: expected an integer >= 1, got {self.max_iterations!r}")
        if self.infeasible not in ("raise", "report"):
            raise ValueError(f"infeasible: expected 'raise' or 'report', got {self.infeasible!r}")
        if self.tendon not in ("rigid", "compliant"):
            raise ValueError(f"tendon: expected 'rigid' or 'compliant', got {self.tendon!r}")
        if self.tendon == "compliant" and not self.force_length_velocity:
            raise ValueError("tendon: 'compliant' needs force_length_velocity (a tendon's stretch matters through the "
                             "fibre's force-length curve only)")

    def bounds(self, n_m: int) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) (n_m,): each muscle's activation bounds (``muscle_bounds``, else ``activation_bounds``);
        ValueError when ``muscle_bounds`` holds another number of pairs."""
        if not self.muscle_bounds:
            lo, hi = self.activation_bounds or DEFAULT_BOUNDS["Millard2012EquilibriumMuscle"]
            return np.full(n_m, float(lo)), np.full(n_m, float(hi))
        if len(self.muscle_bounds) != n_m:
            raise ValueError(f"muscle_bounds: expected {n_m} pairs (one per muscle), got {len(self.muscle_bounds)}")
        b = np.asarray(self.muscle_bounds, dtype=float)
        return b[:, 0].copy(), b[:, 1].copy()


def _real(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and not math.isnan(x)


def _pair(name: str, value) -> tuple[float, float]:
    if not (isinstance(value, (tuple, list)) and len(value) == 2 and all(_real(v) for v in value)):
        raise ValueError(f"{name}: expected (lower, upper), got {value!r}")
    return float(value[0]), float(value[1])


@dataclass(frozen=True, eq=False)
class StaticOptimizationResult:
    """Static optimization of k frames, n_m muscles, n_c coordinates.

    activations (k, n_m); forces (k, n_m) N: a F (+ P with ``passive=True``); reserve_controls (k, n_c) (0 where a
    coordinate has no reserve); reserve_moments (k, n_c) N m: the controls times the reserves' optimal forces;
    reserve_share (n_c,): RMS over the trial of a coordinate's reserve moment over RMS of its moment (0: the muscles
    carry it all; nan: no moment); violation (k, n_c) N m: what the solution leaves unbalanced (carried minus
    required); infeasible: (frame, coordinate, shortfall N m) of each frame no activation satisfies; report: one
    line per such frame ("" when none); iterations: IPOPT's (-1: the QP solver of p = 2 does not count them);
    seconds: the solve's wall time.
    """

    activations: np.ndarray
    forces: np.ndarray
    reserve_controls: np.ndarray
    reserve_moments: np.ndarray
    reserve_share: np.ndarray
    violation: np.ndarray
    infeasible: tuple[tuple[int, str, float], ...] = ()
    report: str = ""
    iterations: int = 0
    seconds: float = 0.0
    stats: dict = field(default_factory=dict, repr=False)

    @property
    def success(self) -> bool:
        """True when every frame's moments are carried."""
        return not self.infeasible


def finite_array(name: str, value, shape: tuple[int, ...]) -> np.ndarray:
    """``value`` as a float array of ``shape``; ValueError naming ``name`` for another shape or a value not finite."""
    a = np.asarray(value, dtype=float)
    if a.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        i = tuple(int(j) for j in np.argwhere(~np.isfinite(a))[0])
        raise ValueError(f"{name}: not finite at {i} ({a[i]}): the inputs have a gap there; fill or cut it first")
    return a


def _check(moments, arms, active, passive, reserves, coordinates):
    """The inputs as float arrays, each checked for its shape, finiteness and sign, before any work."""
    m = np.asarray(moments, dtype=float)
    if m.ndim != 2 or m.shape[0] < 1 or m.shape[1] < 1:
        raise ValueError(f"moments: expected (frames, coordinates), got shape {m.shape}")
    k, n_c = m.shape
    arms = np.asarray(arms, dtype=float)
    if arms.ndim != 3 or arms.shape[0] != k or arms.shape[2] != n_c:
        raise ValueError(f"arms: expected ({k}, muscles, {n_c}) (frames, muscles, coordinates), got {arms.shape}")
    n_m = arms.shape[1]
    m, arms = finite_array("moments", m, (k, n_c)), finite_array("arms", arms, (k, n_m, n_c))
    if np.abs(arms).max(initial=0.0) > 1.0:  # m, or m/m on a translation: a human muscle's are below 0.2 m
        i = tuple(int(j) for j in np.unravel_index(np.argmax(np.abs(arms)), arms.shape))
        raise ValueError(f"arms: {arms[i]:g} m at (frame, muscle, coordinate) {i}: no muscle's moment arm is past "
                         "1 m; are they in mm or cm?")
    active = finite_array("active", np.broadcast_to(np.asarray(active, dtype=float), (k, n_m)), (k, n_m))
    if np.any(active < 0.0):
        i = tuple(int(j) for j in np.argwhere(active < 0.0)[0])
        raise ValueError(f"active: a muscle's force at full activation is negative at (frame, muscle) {i}: "
                         f"{active[i]:g} N")
    passive = np.zeros((k, n_m)) if passive is None else finite_array("passive", passive, (k, n_m))
    r = np.zeros(n_c) if reserves is None else np.asarray([0.0 if v is None else v for v in reserves], dtype=float)
    r = finite_array("reserves", r, (n_c,))
    if np.any(r < 0.0):
        raise ValueError(f"reserves: an optimal force is negative ({r.min():g}); 0 or None: no reserve")
    names = tuple(coordinates) if coordinates is not None else tuple(f"coordinate {c}" for c in range(n_c))
    if len(names) != n_c:
        raise ValueError(f"coordinates: expected {n_c} names, got {len(names)}")
    return m, arms, active, passive, r, names


def solve_static_optimization(moments, arms, active, passive=None, reserves=None,
                              options: StaticOptimization | None = None, *, max_isometric=None,
                              coordinates: Sequence[str] | None = None,
                              near: StaticOptimizationResult | None = None,
                              times: Sequence[float] | None = None) -> StaticOptimizationResult:
    """Static optimization of k frames (module docstring).

    moments (k, n_c) N m (N on a translation): the generalized forces the muscles and reserves must carry (the
    inverse dynamics', muscles excluded); arms (k, n_m, n_c) m: each muscle's moment arm about each coordinate;
    active (k, n_m) N: each muscle's active force at full activation along the tendon; passive (k, n_m) N: its
    passive fibre force along the tendon (used only with ``options.passive``); reserves (n_c,) N m: each
    coordinate's reserve optimal force (0 or None: no reserve); max_isometric (n_m,) N: the forces per unit
    activation when ``options.force_length_velocity`` is False; coordinates: names for the report; near: the
    result of nearby inputs with the same frames (the bands' perturbations): with p = 2, each frame solved on its
    active set (:func:`_on_active_set`), the QP only for the frames where that set changed; times (k,) s: the
    frames' times, for the messages. Where IPOPT stops short on the whole trial each frame is solved alone; a frame
    that still fails raises :class:`StaticOptimizationError` naming it.
    """
    import time

    options = options or StaticOptimization()
    m, arms, active, passive, r, names = _check(moments, arms, active, passive, reserves, coordinates)
    k, n_m, n_c = arms.shape
    if not options.force_length_velocity:
        if max_isometric is None:
            raise ValueError("max_isometric: needed with force_length_velocity=False (the force per activation)")
        active = np.broadcast_to(finite_array("max_isometric", max_isometric, (n_m,)), (k, n_m))
    target = m - np.einsum("kmc,km->kc", arms, passive) if options.passive else m
    start = time.perf_counter()
    problem = _Problem(arms, active, r, target, options)
    if near is not None and options.exponent == 2.0 and near.activations.shape == (k, n_m):
        x, kept = _on_active_set(problem, target, near)
        infeasible = ()
        if not kept.all():  # the frames whose active set changed: the QP
            sub = solve_static_optimization(moments[~kept], arms[~kept], active[~kept], passive[~kept], r, options,
                                            coordinates=names, times=None if times is None else
                                            np.asarray(times)[~kept])
            v = x.reshape(k, problem.n_v)
            v[~kept, :n_m] = sub.activations
            u = sub.reserve_controls[:, problem.held]
            v[~kept, n_m:] = np.concatenate([np.maximum(u, 0.0), np.maximum(-u, 0.0)], axis=1)
            x = v.ravel()
            frames = np.flatnonzero(~kept)
            infeasible = tuple((int(frames[f]), c, s) for f, c, s in sub.infeasible)
        report = _report(infeasible, len(infeasible), target, names) if infeasible else ""
        return _result(problem, x, target, infeasible, report, passive, options, -1, time.perf_counter() - start,
                       {"kept": kept})
    x, iterations, ok, stats = problem.solve(target)
    short, infeasible = np.zeros((k, n_c)), ()
    if not ok:
        short = problem.shortfall(target)
        if problem.shortfall_status:  # stopped short: its shortfall is no measure; the frames one by one
            short = _shortfall_by_frame(problem, target, times)
        infeasible = _infeasible(short, names, options.tolerance * problem.scale)
        if infeasible and options.infeasible == "raise":
            raise ValueError(_report(infeasible, len(infeasible), target, names))
        goal = target - short if infeasible else target
        x, it2, ok, stats = problem.solve(goal, qp=False)
        iterations += it2
        if not ok or not np.all(np.isfinite(x)):  # the frames one by one: the failing ones named, or all solved
            x, it2, stats = _frame_by_frame(problem, goal, times)
            iterations += it2
    report = _report(infeasible, len(infeasible), target, names) if infeasible else ""
    return _result(problem, x, target, infeasible, report, passive, options, iterations,
                   time.perf_counter() - start, stats)


#: An activation within this of a bound in the nearby solution is taken as held there (on the Rajagopal walk 8196
#: of the QP's 13280 activations lie within 1e-10 of a bound and 30 between 1e-8 and 1e-5: one free by less than
#: this and held moves by less than it; a set that is not the optimum's fails the checks of _on_active_set).
AT_BOUND = 1e-6


def _on_active_set(problem: _Problem, target: np.ndarray, near: StaticOptimizationResult
                   ) -> tuple[np.ndarray, np.ndarray]:
    """(x, kept (k,)): each frame of p = 2 solved on ``near``'s active set: its activations within
    :data:`AT_BOUND` of a bound held there, the others (and the reserves, within theirs) the least-norm solution
    of the balance, exact; ``kept`` where that is the optimum (the balance met, the free unknowns within their
    bounds, the held ones' reduced gradients of the sign that keeps them there; to 1e-9)."""
    k, n_m, n_c = problem.arms.shape
    lo, hi = problem.options.bounds(n_m)
    n_r = problem.held.size
    G = np.zeros((k, n_c, n_m + n_r))
    G[:, :, :n_m] = np.einsum("kmc,km->kcm", problem.arms, problem.active)
    G[:, problem.held, n_m + np.arange(n_r)] = problem.reserves[problem.held]
    a0 = near.activations
    fixed = np.zeros((k, n_m + n_r))
    held = np.zeros((k, n_m + n_r), dtype=bool)
    held[:, :n_m] = (a0 <= lo + AT_BOUND) | (a0 >= hi - AT_BOUND)
    fixed[:, :n_m] = np.where(a0 <= lo + AT_BOUND, lo, hi) * held[:, :n_m]
    rest = target - np.einsum("kcv,kv->kc", G, fixed)
    Gf = np.where(held[:, None, :], 0.0, G)
    pinv = np.linalg.pinv(Gf)
    v = fixed + np.einsum("kvc,kc->kv", pinv, rest)
    lam = -2.0 * np.einsum("kcv,kv->kc", pinv.transpose(0, 2, 1), np.where(held, 0.0, v))
    grad = 2.0 * v + np.einsum("kcv,kc->kv", G, lam)
    rlo, rhi = problem.options.reserve_bounds
    low = np.r_[lo, np.full(n_r, rlo)]
    high = np.r_[hi, np.full(n_r, rhi)]
    lo, hi = np.r_[lo, np.full(n_r, -np.inf)], np.r_[hi, np.full(n_r, np.inf)]  # the reserves are never held
    tol = 1e-9
    balance = np.abs(np.einsum("kcv,kv->kc", G, v) - target) <= tol * problem.scale
    inside = (v >= low - tol) & (v <= high + tol)
    sign = np.where(held & (v <= lo + AT_BOUND), grad >= -tol, True) & np.where(held & (v >= hi - AT_BOUND),
                                                                                grad <= tol, True)
    kept = balance.all(axis=1) & (inside | held).all(axis=1) & sign.all(axis=1)
    x = np.concatenate([v[:, :n_m], np.maximum(v[:, n_m:], 0.0), np.maximum(-v[:, n_m:], 0.0)], axis=1)
    return x.ravel(), kept


def _one_frame(problem: _Problem, target: np.ndarray, f: int) -> _Problem:
    return _Problem(problem.arms[f:f + 1], problem.active[f:f + 1], problem.reserves, target[f:f + 1],
                    problem.options)


def _stopped(problem: _Problem, failed: list[int], status: str, times, doing: str) -> StaticOptimizationError:
    """The error naming the frames where IPOPT stopped short (their times where given) and what to try."""
    at = [f"t = {times[f]:g} s (frame {f})" if times is not None else f"frame {f}" for f in failed[:3]]
    more = f" and {len(failed) - 3} more frames" if len(failed) > 3 else ""
    return StaticOptimizationError(
        f"static optimization (exponent {problem.options.exponent:g}): IPOPT stopped ({status}) at {', '.join(at)}"
        f"{more}, {doing}: try exponent 2 (a QP, which does not stop short), reserves on the joints (--reserves, "
        "options.muscles.reserves), or a smaller exponent", tuple(failed))


def _shortfall_by_frame(problem: _Problem, target: np.ndarray, times) -> np.ndarray:
    """(k, n_c) N m: :meth:`_Problem.shortfall` frame by frame (after the whole trial's stopped short);
    :class:`StaticOptimizationError` naming the frames where it stops short too."""
    out, failed, status = [], [], ""
    for f in range(target.shape[0]):
        one = _one_frame(problem, target, f)
        out.append(one.shortfall(target[f:f + 1]))
        if one.shortfall_status:
            failed.append(f)
            status = status or one.shortfall_status
    if failed:
        raise _stopped(problem, failed, status, times, "finding what the activations cannot carry")
    return np.concatenate(out)


def _frame_by_frame(problem: _Problem, target: np.ndarray, times) -> tuple[np.ndarray, int, dict]:
    """(x, iterations, stats): each frame of ``target`` solved alone by IPOPT (after the whole trial's solve
    stopped short); :class:`StaticOptimizationError` naming the frames that fail alone too."""
    k = target.shape[0]
    xs, failed, iterations, status = [], [], 0, ""
    for f in range(k):
        x, it, ok, stats = _one_frame(problem, target, f).solve(target[f:f + 1], qp=False)
        iterations += it
        if not ok or not np.all(np.isfinite(x)):
            failed.append(f)
            status = status or str(stats.get("return_status"))
        xs.append(x)
    if failed:
        raise _stopped(problem, failed, status, times, "on moments the activations can carry")
    return np.concatenate(xs), iterations, {"return_status": "frame by frame", "success": True}


def _infeasible(short: np.ndarray, names, tol: np.ndarray) -> tuple[tuple[int, str, float], ...]:
    """(frame, coordinate, shortfall) of each frame with a shortfall above the tolerance (its largest)."""
    bad = np.abs(short) > 1e3 * tol
    out = []
    for f in np.flatnonzero(bad.any(axis=1)):
        c = int(np.argmax(np.abs(short[f]) * bad[f]))
        out.append((int(f), names[c], float(short[f, c])))
    return tuple(out)


def _report(infeasible, count: int, target: np.ndarray, names) -> str:
    lines = [f"frame {f}: {name}: no activation within the bounds carries its moment of "
             f"{target[f, names.index(name)]:.6g} N m: {abs(s):.6g} N m out of reach" for f, name, s in infeasible[:5]]
    more = f" (and {count - 5} more frames)" if count > 5 else ""
    return "static optimization: " + "; ".join(lines) + more + ": add a reserve on that coordinate or check the moments"


def _result(problem, x, target, infeasible, report, passive, options, iterations, seconds, stats):
    k, n_m, n_c = problem.arms.shape
    a, u = problem.split(x)
    forces = a * problem.active + (passive if options.passive else 0.0)
    moments = u * problem.reserves
    carried = np.einsum("kmc,km->kc", problem.arms, a * problem.active) + moments
    rms = np.sqrt(np.mean(target ** 2, axis=0))
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(rms > 0.0, np.sqrt(np.mean(moments ** 2, axis=0)) / rms, np.nan)
    return StaticOptimizationResult(a, forces, u, moments, share, carried - target, infeasible, report, iterations,
                                    seconds, stats)


@dataclass(frozen=True)
class _CSC:
    """A sparse matrix in compressed columns (the arrays CasADi's Sparsity takes): shape, indptr, indices (sorted
    in each column), data; explicit zeros kept (a muscle's arm of 0 about a coordinate it does not cross)."""

    shape: tuple[int, int]
    indptr: np.ndarray
    indices: np.ndarray
    data: np.ndarray


def _dm(G: _CSC):
    """G as a CasADi DM, from its arrays (ca.DM of a scipy matrix takes 20 times as long)."""
    import casadi as ca

    sparsity = ca.Sparsity(G.shape[0], G.shape[1], G.indptr.astype(np.int64).tolist(),
                           G.indices.astype(np.int64).tolist())
    return ca.DM(sparsity, G.data)


def _block_diagonal(full: np.ndarray, keep: np.ndarray) -> _CSC:
    """G (rows kept, k n_v): the block diagonal of the frames' blocks ``full`` (k, n_c, n_v) with the rows where
    ``keep`` (k, n_c) is False left out, every entry of a block stored (zeros too), in compressed columns: each
    column (frame f, unknown v) holds full[f, kept rows, v]; built in numpy at once (scipy.sparse's import alone
    took 0.26 s of the command)."""
    k, n_c, n_v = full.shape
    row = np.cumsum(keep.ravel()).reshape(k, n_c) - 1  # each kept row's index in G
    mask = np.broadcast_to(keep[:, None, :], (k, n_v, n_c))
    data = full.transpose(0, 2, 1)[mask]
    indices = np.broadcast_to(row[:, None, :], (k, n_v, n_c))[mask]
    indptr = np.r_[0, np.cumsum(np.repeat(keep.sum(axis=1), n_v))]
    return _CSC((int(keep.sum()), k * n_v), indptr, indices, data)


class _Problem:
    """The trial's frames as one sparse NLP: unknowns frame after frame [a (n_m), u+ (n_r), u- (n_r)], the rows
    (frame, coordinate) scaled by each coordinate's RMS moment (its unit: N m become O(1))."""

    def __init__(self, arms, active, reserves, target, options: StaticOptimization) -> None:
        self.arms, self.active, self.reserves, self.options = arms, active, reserves, options
        k, n_m, n_c = arms.shape
        self.held = np.flatnonzero(reserves > 0.0)
        n_r = self.held.size
        self.n_v = n_m + 2 * n_r
        self.scale = np.maximum(np.sqrt(np.mean(target ** 2, axis=0)), 1e-6)
        full = self._blocks()
        # rows nothing acts on (a coordinate no muscle crosses and no reserve holds, e.g. the root's, where the
        # muscles' arms are 1e-16 m of rounding): out of the NLP (such rows slow IPOPT fourfold or make it declare
        # the problem infeasible); what they require is out of reach as it stands
        rows = np.abs(full).max(axis=2).ravel() * np.tile(self.scale, arms.shape[0])  # N m per unit
        self.keep = rows > 1e-9 * max(float((rows).max()), 1e-300)
        self.G = _block_diagonal(full, self.keep.reshape(k, n_c))
        lo, hi = options.bounds(n_m)
        rlo, rhi = options.reserve_bounds
        one = np.r_[lo, np.zeros(2 * n_r)], np.r_[hi, np.full(n_r, rhi), np.full(n_r, -rlo)]
        self.lbx, self.ubx = np.tile(one[0], k), np.tile(one[1], k)

    def _blocks(self) -> np.ndarray:
        """(k, n_c, n_v): each frame's block [r^T diag(F), R, -R] of the constraints over the rows' scale."""
        k, n_m, n_c = self.arms.shape
        blocks = np.einsum("kmc,km->kcm", self.arms, self.active)
        res = np.zeros((n_c, self.held.size))
        res[self.held, np.arange(self.held.size)] = self.reserves[self.held]
        return np.concatenate([blocks, np.broadcast_to(res, (k, n_c, self.held.size)),
                               np.broadcast_to(-res, (k, n_c, self.held.size))], axis=2) / self.scale[None, :, None]

    def _ipopt(self, x, f, g, linear_objective=False):
        import casadi as ca

        tol = self.options.tolerance
        opts = {"ipopt.tol": tol, "ipopt.constr_viol_tol": tol, "ipopt.max_iter": self.options.max_iterations,
                "ipopt.print_level": 0, "print_time": False, "ipopt.jac_c_constant": "yes",
                "ipopt.hessian_constant": "yes" if (linear_objective or self.options.exponent == 2.0) else "no",
                "ipopt.sb": "yes", "ipopt.mu_strategy": "adaptive"}
        return ca.nlpsol("static_optimization", "ipopt", {"x": x, "f": f, "g": g}, opts)

    def solve(self, target, qp: bool = True):
        """(x, iterations, converged, stats) of the least-cost activations carrying ``target`` (k, n_c); ``qp``
        False: IPOPT even for p = 2 (its relaxed bounds take targets only reached at a bound, where an
        interior-point QP's feasible set has no interior)."""
        import casadi as ca

        b = (target / self.scale).ravel()[self.keep]
        p = self.options.exponent
        if p == 2.0 and qp:
            return self._qp(b, target)
        # SX: evaluated in 0.016 s CPU of IPOPT's 1.2 s on the Rajagopal walk (MX 0.025 s)
        x = ca.SX.sym("x", self.G.shape[1])
        solver = self._ipopt(x, ca.sum1(ca.fabs(x) ** p), ca.mtimes(_dm(self.G), x))
        x0 = np.clip(np.zeros_like(self.lbx), self.lbx, self.ubx)
        sol = solver(x0=x0, lbx=self.lbx, ubx=self.ubx, lbg=b, ubg=b)
        stats = solver.stats()
        ok = bool(stats["success"]) and self._held(target)
        return np.array(sol["x"]).ravel(), int(stats["iter_count"]), ok, stats

    def _held(self, target) -> bool:
        """Whether the rows nothing acts on require nothing."""
        return not np.abs((target / self.scale).ravel()[~self.keep]).max(initial=0.0) > 1e3 * self.options.tolerance

    def _qp(self, b, target):
        """p = 2: a QP (cost x^T x, the rows G x = b, the bounds), by CasADi's sparse interior-point QP solver
        ``ipqp``: 0.45 s CPU on the Rajagopal walk (166 frames, 80 muscles) where IPOPT took 1.2-1.5 s."""
        import casadi as ca

        n = self.G.shape[1]
        H, A = ca.DM(ca.Sparsity.diag(n), 2.0), _dm(self.G)
        tol = self.options.tolerance
        solver = ca.conic("static_optimization", "ipqp", {"h": H.sparsity(), "a": A.sparsity()},
                          {"print_iter": False, "print_header": False, "print_info": False, "error_on_fail": False,
                           "linear_solver": "qr",  # ldl warns on stderr where the frames cannot all be met
                           "constr_viol_tol": tol, "dual_inf_tol": tol, "max_iter": self.options.max_iterations})
        sol = solver(h=H, a=A, g=np.zeros(n), lbx=self.lbx, ubx=self.ubx, lba=b, uba=b)
        stats = solver.stats()
        x = np.clip(np.array(sol["x"]).ravel(), self.lbx, self.ubx)  # an interior point's last 1e-15 past a bound
        return x, int(stats.get("iter_count", 0)), bool(stats["success"]) and self._held(target), stats

    def shortfall(self, target) -> np.ndarray:
        """(k, n_c) N m: the least |s|_1 with G x + s = b within the bounds: what no activation can carry."""
        import casadi as ca

        n, rows = self.G.shape[1], self.G.shape[0]
        b = (target / self.scale).ravel()
        self.shortfall_status = ""  # IPOPT's status where it stopped short, else ""
        if rows == 0:  # nothing acts on any row (no muscle has force there): every row falls short by all it needs
            return b.reshape(target.shape) * self.scale
        z = ca.MX.sym("z", n + 2 * rows)
        x, sp_, sm = z[:n], z[n:n + rows], z[n + rows:]
        solver = self._ipopt(z, ca.sum1(sp_ + sm), ca.mtimes(_dm(self.G), x) + sp_ - sm, linear_objective=True)
        lbz = np.r_[self.lbx, np.zeros(2 * rows)]
        ubz = np.r_[self.ubx, np.full(2 * rows, np.inf)]
        sol = np.array(solver(x0=np.clip(np.zeros(lbz.size), lbz, ubz), lbx=lbz, ubx=ubz, lbg=b[self.keep],
                              ubg=b[self.keep])["x"]).ravel()
        self.shortfall_status = "" if solver.stats()["success"] else str(solver.stats()["return_status"])
        s = b.copy()  # the rows nothing acts on fall short by all they require
        s[self.keep] = sol[n:n + rows] - sol[n + rows:]
        return s.reshape(target.shape) * self.scale

    def split(self, x):
        """(a (k, n_m), u (k, n_c)) of the unknowns x."""
        k, n_m, n_c = self.arms.shape
        v = x.reshape(k, self.n_v)
        n_r = self.held.size
        u = np.zeros((k, n_c))
        u[:, self.held] = v[:, n_m:n_m + n_r] - v[:, n_m + n_r:]
        return v[:, :n_m], u
