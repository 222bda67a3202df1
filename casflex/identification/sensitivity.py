"""Forward sensitivities of HHT trajectories: the states at chosen steps and their derivatives
with respect to the initial state and the parameters, for output-error identification.

:meth:`HHT.sensitivity <casflex.integrators.hht.HHT.sensitivity>` carries, through every step,
the state x_k and S_k = dx_k/dw in the directions of the unknowns w (a fit's parameters and
initial state; by default every direction of (x_0, p)), shape (nx, D), by the implicit-function
derivative of each Newton solve: exact to the Newton tolerance, not finite differences. Chunks
of :data:`CHUNK` steps run as one compiled C function (generated once per integrator and number of
directions, cached on disk by :func:`casflex.codegen.compile_functions`), the remainder step by
step; without a C compiler the same Functions run in CasADi's virtual machine, some tens of times
slower.

The cost is linear in the number of steps and grows with D: twobar (15 dofs, 4 parameters, D = 4),
3000 steps take about 3 simulations' time compiled (docs/tables/bench_identification.md).
"""

from __future__ import annotations

import functools
import shutil
import weakref
from dataclasses import dataclass

import numpy as np

from casflex import interrupt
from casflex.codegen import BufferedCall, compile_functions, log
from casflex.integrators.hht import HHT
from casflex.model import Model, form_inputs

__all__ = ["SensitivityRun", "run_sensitivities", "run_states", "CHUNK"]

#: Steps per compiled call.
CHUNK = 250
#: The properties an identification's other forms vary: ((target, (lower, upper)), ...) (hashable)
Vary = tuple[tuple[str, tuple[float, float]], ...]

_LIBS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
#: integrator -> {vary: (the integrator whose compiled code runs its steps, the run-time inputs)}
_FORMS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


@dataclass(frozen=True)
class SensitivityRun:
    """States and sensitivities at the kept step ends.

    steps : (m,) kept step-end indices (0: the initial state); X : (m, nx) states; S : (m, nw, nx)
    with S[i, j, :] = dx_steps[i] / dw_j, w = (x_0, p); converged : every step's Newton met its
    tolerance (if not, ``failed_step`` is the first that did not and the arrays stop before it);
    scale : the run's Newton scaling (``HHT.scale`` at its first state), for a run that continues it.
    """

    steps: np.ndarray
    X: np.ndarray
    S: np.ndarray
    converged: bool
    failed_step: int | None
    scale: np.ndarray | None = None


def _form_integrator(integ: HHT, vary: Vary = ()) -> tuple[HHT, np.ndarray]:
    """The integrator whose compiled code runs ``integ``'s steps, and the run-time inputs appended to p for it:
    that of the model with the beams' rotary inertia and the properties in ``vary`` ((target, (lower, upper)),
    ...) as inputs (:func:`casflex.model.form_inputs`), so that a fit and its refits in other forms (:mod:`.form`)
    share one library; ``integ`` itself for a scene without beams and nothing to vary."""
    cache = _FORMS.setdefault(integ, {})
    if vary not in cache:
        found = form_inputs(integ.model, dict(vary))
        if found is None:
            cache[vary] = (integ, np.zeros(0))
        else:
            model, values = found
            cache[vary] = (_integrator(model, integ.alpha, integ.tol, integ.max_iter, integ.expand), values)
    return cache[vary]


@functools.lru_cache(maxsize=8)
def _integrator(model: Model, alpha: float, tol: float, max_iter: int, expand: bool | None) -> HHT:
    return HHT(model, alpha=alpha, tol=tol, max_iter=max_iter, expand=expand)


def _functions(integ: HHT, compiled: bool, n_dir: int, vary: Vary | None = ()) -> tuple:
    """(chunk call, one-step call, run-time inputs appended to p) in ``n_dir`` directions: BufferedCalls of
    compiled code (:func:`_form_integrator`'s), or the CasADi Functions (no inputs)."""
    key = (bool(compiled), n_dir, vary)
    cache = _LIBS.setdefault(integ, {})
    if key not in cache:
        if compiled and shutil.which("gcc") is None:
            log.warning("no C compiler (gcc): the sensitivities run interpreted, some tens of times slower")
            compiled = False
        if compiled:
            code, inputs = (integ, np.zeros(0)) if vary is None else _form_integrator(integ, vary)
            funcs = [code.sensitivity(CHUNK, n_dir), code.sensitivity(1, n_dir)]
            lib = compile_functions(funcs, stem="casflex_sensitivity", optimise="-O1")
            cache[key] = (*(BufferedCall(lib[f.name()]) for f in funcs), inputs)
        else:
            cache[key] = (integ.sensitivity(CHUNK, n_dir), integ.sensitivity(1, n_dir), np.zeros(0))
    return cache[key]


def run_sensitivities(integ: HHT, x0: np.ndarray, p: np.ndarray, t0: float, dt: float, n_steps: int,
                      keep: np.ndarray, *, seed: tuple[np.ndarray, np.ndarray] | None = None,
                      compiled: bool = True, scale: np.ndarray | None = None, vary: Vary | None = ()
                      ) -> SensitivityRun:
    """Step from x0 at t0 (s) ``n_steps`` steps of ``dt`` (s) with parameters p; keep the states
    and sensitivities at the step ends in ``keep`` (sorted indices in 0..n_steps).

    ``seed``: (dx0/dw (nx, D), dp/dw (n_p, D)), the directions w to carry; default every direction
    of w = (x_0, p). A fit carries its unknowns' directions only: the cost per step grows with D.
    ``scale``: the Newton scaling of the run this one continues (its ``scale``; default from x0), so that
    the continued steps are those of one run. ``vary``: the properties the fit's other forms vary, ((target,
    (lower, upper)), ...), run-time inputs of the compiled code (:func:`_form_integrator`); None: the compiled code
    of ``integ``'s model itself (a model never refitted in another form)."""
    model = integ.model
    n, nx = model.n_dof, integ.nx
    if seed is None:
        seed = (np.eye(nx, nx + model.n_p), np.eye(model.n_p, nx + model.n_p, nx))
    S0, P = (np.asarray(a, dtype=float) for a in seed)
    nw = S0.shape[1]
    if S0.shape != (nx, nw) or P.shape != (model.n_p, nw):
        raise ValueError(f"seed: expected shapes ({nx}, D) and ({model.n_p}, D), got {S0.shape} and {P.shape}")
    chunk_fn, step_fn, inputs = _functions(integ, compiled, nw, vary)
    d = np.array(integ.scale(x0[:n], x0[n:2 * n], p, dt)).ravel() if scale is None else np.asarray(scale, float)
    keep = np.asarray(keep, dtype=int)
    Xk = np.empty((keep.size, nx))
    Sk = np.empty((keep.size, nw, nx))
    x = np.ascontiguousarray(x0, dtype=float)
    S = np.ascontiguousarray(S0.T)  # S^T: row j = dx/dw_j (a column-major nx x nw matrix)
    # the run-time inputs (constant: no directions) after the parameters
    Pv = np.ascontiguousarray(np.hstack([P.T, np.zeros((nw, inputs.size))]))
    pv = np.ascontiguousarray(np.concatenate([np.asarray(p, dtype=float), inputs]))
    hv = np.array([float(dt)])
    j = 0
    if keep.size and keep[0] == 0:
        Xk[0], Sk[0], j = x, S, 1
    X = np.empty((CHUNK, nx))
    SS = np.empty((CHUNK * nw, nx))
    R = np.empty(CHUNK)
    done = 0
    while done < n_steps:
        m = CHUNK if n_steps - done >= CHUNK else 1
        fn = chunk_fn if m == CHUNK else step_fn
        t_in = np.array([t0 + done * dt])
        if isinstance(fn, BufferedCall):
            fn([x, S, Pv, t_in, pv, hv, d], [X[:m], SS[:m * nw], R[:m]])
        else:
            out = fn(x, S.T, Pv.T, t_in, pv, hv, d)
            X[:m] = np.array(out[0]).T
            SS[:m * nw] = np.array(out[1]).T
            R[:m] = np.array(out[2]).ravel()
        bad = ~(np.isfinite(X[:m]).all(axis=1) & (R[:m] <= integ.tolerance(X[:m, :n])))
        good = int(np.argmax(bad)) if bad.any() else m
        while j < keep.size and keep[j] <= done + good:
            i = keep[j] - done - 1
            Xk[j], Sk[j] = X[i], SS[i * nw:(i + 1) * nw]
            j += 1
        if good < m:
            return SensitivityRun(keep[:j], Xk[:j], Sk[:j], False, done + good + 1, d)
        done += m
        x = X[m - 1].copy()
        S = SS[(m - 1) * nw:m * nw].copy()
        interrupt.check()
    return SensitivityRun(keep, Xk, Sk, True, None, d)


def _state_functions(integ: HHT, compiled: bool, vary: Vary | None) -> tuple:
    """(chunk call, one-step call, steps per chunk, run-time inputs appended to p) of the plain HHT run: the
    simulator's compiled library (BufferedCalls) of ``integ`` itself (``vary`` None: the trajectories at a fit's answer,
    :func:`casflex.simulate.simulate`, run on it) or of :func:`_form_integrator`'s (a refit in another form), or
    the CasADi Functions."""
    from casflex.simulate.run import CHUNK as SIM_CHUNK
    from casflex.simulate.run import compiled_library

    if compiled and shutil.which("gcc") is not None:
        code, inputs = (integ, np.zeros(0)) if vary is None else _form_integrator(integ, vary)
        lib = compiled_library(code)
        return BufferedCall(lib[code.trajectory(SIM_CHUNK).name()]), BufferedCall(lib[code.step.name()]), SIM_CHUNK, \
            inputs
    return integ.trajectory(SIM_CHUNK), integ.step, SIM_CHUNK, np.zeros(0)


def run_states(integ: HHT, x0: np.ndarray, p: np.ndarray, t0: float, dt: float, n_steps: int, keep: np.ndarray, *,
               compiled: bool = True, vary: Vary | None = None) -> SensitivityRun:
    """:func:`run_sensitivities` without the sensitivities (``S`` has no directions): the model run alone, at
    about a third of the cost of one in 4 directions (twobar). The same steps, Newton scaling and step times, so
    the states agree with a run with sensitivities to the Newton tolerance. ``vary``: as :func:`run_sensitivities`'s,
    for a refit in another form (its runs on the library its forms share); None: the model's own library."""
    n = integ.model.n_dof
    chunk_fn, step_fn, chunk, inputs = _state_functions(integ, compiled, vary)
    d = np.array(integ.scale(x0[:n], x0[n:2 * n], p, dt)).ravel()
    keep = np.asarray(keep, dtype=int)
    X = np.empty((n_steps + 1, integ.nx))
    X[0] = x0
    R = np.empty(chunk)
    pv = np.ascontiguousarray(np.concatenate([np.asarray(p, dtype=float), inputs]))
    hv, done = np.array([float(dt)]), 0
    while done < n_steps:
        m = chunk if n_steps - done >= chunk else 1
        fn = chunk_fn if m == chunk else step_fn
        t_in = np.array([t0 + done * dt])
        out = X[done + 1:done + 1 + m]
        if isinstance(fn, BufferedCall):
            fn([np.ascontiguousarray(X[done]), t_in, pv, hv, d], [out, R[:m]])
        else:
            res = fn(X[done], t_in, pv, hv, d)
            out[:] = np.array(res[0]).T.reshape(m, -1)
            R[:m] = np.array(res[1]).ravel()
        bad = ~(np.isfinite(out).all(axis=1) & (R[:m] <= integ.tolerance(out[:, :n])))
        if bad.any():
            good = int(np.argmax(bad))
            kept = keep[keep <= done + good]
            return SensitivityRun(kept, X[kept], np.empty((kept.size, 0, integ.nx)), False, done + good + 1, d)
        done += m
        interrupt.check()
    return SensitivityRun(keep, X[keep], np.empty((keep.size, 0, integ.nx)), True, None, d)
