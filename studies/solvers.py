"""NLP solver comparison: every CasADi nlpsol plugin that runs here, on the identification NLPs.

Problems (twobar scene, simulated set, p* = [k1 kt1 k3 kt3] = [700 0.5 400 0.5]):

- ``direct``: direct identification (Eqs. 11-13) at t = 0.69 s;
- ``adapted``: adapted direct (Eq. 14) on the paper's third instant set [0.4 1.1 1.6 1.9 2.3] s;
- ``ss``, ``ms``: indirect (Eq. 16, positions) over a short horizon (0..0.1 s), single and
  multiple shooting (intervals of 20 steps).

Solvers: IPOPT (exact Hessian, Gauss-Newton, L-BFGS), sqpmethod with each QP solver that loads
(Gauss-Newton Hessian; with qpOASES also exact and L-BFGS), feasiblesqpmethod, qrsqp, fatrop,
Uno (two presets), SLEQP, alpaqa, Bonmin and blockSQP. One tolerance (TOL = 1e-8) is mapped onto
each solver's own optimality measure, with the same iteration cap, and every run has a wall-time
cap. Every start runs in its own Python process, so a solver that crashes (hpipm and blockSQP
with its default HSL linear solver do) or stalls is recorded, not fatal. The grid goes through
``casflex.sweep.run_sweep`` (one JSON record per problem and solver; ``--record DIR`` resumes).

Stage 1 runs every configuration on the direct and adapted problems; stage 2 runs those that
solved the direct problem from at least one start on the indirect problems.

Measures per (problem, solver, start): the solver's success flag; whether p is right (max
relative error of p after the library's Gauss-Newton polish <= 1e-6; adapted direct: k1, k3
within 1e-4, as in basins.md); the error of the solver's own p (before the polish); iterations;
build and solve time; then the cross-solver spread of p among runs that report success, and a
Dolan-More performance profile.

Writes docs/tables/solvers.md and docs/figures/solvers.png (quick mode: solvers_quick.* under
``out_dir``). Run: ``python studies/solvers.py`` (``--quick``: IPOPT and sqpmethod on the direct
problem; ``--scheduler tcp://host:8786`` to use a dask cluster; ``--record DIR`` to keep and
resume the run records).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from casflex.results import atomic_write_bytes, atomic_write_text

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = Path(__file__).resolve()

TOL = 1e-8  # the one optimality tolerance, mapped onto every solver
MAX_ITER = 200  # iteration cap (solvers that take one)
CAP = 120.0  # wall-time cap per run (s): the solver's own option where it has one, else the process is killed
HARD_MARGIN = 30.0  # a run's process is killed at CAP + HARD_MARGIN s (build, start-up, a solver without a cap)
QP_TOL = 1e-10  # QP subproblem tolerance of the iterative QP solvers (osqp, proxqp, piqp, ipqp, superscs)
P_TOL = 1e-6  # p is right: max_j |p_j / p*_j - 1| <= P_TOL ...
P_TOL_ADAPTED = 1e-4  # ... adapted direct: k1, k3 within this (kt1, kt3 are weakly identifiable by design)
P_STAR = [700.0, 0.5, 400.0, 0.5]  # twobar's nominal parameters (checked against the model in main)
T_DIRECT = [0.69]
T_ADAPTED = [0.4, 1.1, 1.6, 1.9, 2.3]
HORIZON = 0.1
T_DATA = 2.4  # simulated set 0..T_DATA s (covers the adapted instants and their t + dt)
STARTS = [0.8, 1.2, 0.5, 2.0]  # nearest first: after a start hits the cap, the farther ones are skipped
QUICK_STARTS = [0.8, 2.0]

# key: (label, identify_* keyword arguments)
PROBLEMS = {
    "direct": ("direct, t = 0.69 s", {"method": "direct", "instants": T_DIRECT}),
    "adapted": ("adapted direct, [0.4 1.1 1.6 1.9 2.3] s", {"method": "adapted", "instants": T_ADAPTED}),
    "ss": (f"indirect Eq. 16, single shooting, 0..{HORIZON:g} s",
           {"method": "indirect", "horizon": HORIZON, "transcription": "single-shooting", "residue": "positions"}),
    "ms": (f"indirect Eq. 16, multiple shooting, 0..{HORIZON:g} s",
           {"method": "indirect", "horizon": HORIZON, "transcription": "multiple-shooting", "residue": "positions"}),
}
METHOD_OF = {"direct": "direct", "adapted": "adapted direct", "ss": "indirect, single shooting",
             "ms": "indirect, multiple shooting"}


def _ipopt(extra: dict | None = None) -> dict:
    ip = {"print_level": 0, "sb": "yes", "tol": TOL, "acceptable_iter": 0, "mu_strategy": "adaptive",
          "max_iter": MAX_ITER, "max_wall_time": CAP}
    ip.update(extra or {})
    return {"print_time": False, "ipopt": ip}


_QUIET_QP = {"print_iter": False, "print_header": False, "print_info": False}
#: sqpmethod's QP solvers and their options (error_on_fail False: a failed QP is sqpmethod's to handle)
QP_OPTIONS = {
    "qpoases": {"printLevel": "none"},
    "qrqp": dict(_QUIET_QP),
    "osqp": {"osqp": {"verbose": False, "eps_abs": QP_TOL, "eps_rel": QP_TOL, "max_iter": 100000, "polish": True}},
    "proxqp": {"proxqp": {"eps_abs": QP_TOL, "max_iter": 100000, "verbose": False}},
    "daqp": {},
    "highs": {"highs": {"output_flag": False}},
    "piqp": {"piqp": {"eps_abs": QP_TOL, "eps_rel": QP_TOL, "verbose": False}},
    "ipqp": dict(_QUIET_QP, constr_viol_tol=QP_TOL, dual_inf_tol=QP_TOL),
    "superscs": {"superscs": {"eps": QP_TOL, "verbose": 0}},
    "nlpsol": {"nlpsol": "ipopt", "nlpsol_options": {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
                                                     "ipopt.tol": QP_TOL}},
    "hpipm": {},
}


def _sqp(qp: str, extra: dict | None = None, plugin: str = "sqpmethod") -> dict:
    o = {"print_time": False, "print_header": False, "print_iteration": False, "print_status": False,
         "tol_pr": TOL, "tol_du": TOL, "max_iter": MAX_ITER, "qpsol": qp,
         "qpsol_options": dict(QP_OPTIONS[qp], error_on_fail=False)}
    o.update(extra or {})
    return o


def _config(key: str, problem: str) -> tuple[str, str, dict]:
    """(nlpsol plugin, the API's hessian argument, solver_options) of a solver configuration."""
    if key == "ipopt":
        return "ipopt", "exact", _ipopt()
    if key == "ipopt-gn":
        return "ipopt", "gauss-newton", _ipopt()
    if key == "ipopt-lbfgs":
        return "ipopt", "exact", _ipopt({"hessian_approximation": "limited-memory"})
    if key == "sqp-qpoases-exact":
        return "sqpmethod", "exact", _sqp("qpoases")
    if key == "sqp-lbfgs":
        return "sqpmethod", "exact", _sqp("qpoases", {"hessian_approximation": "limited-memory"})
    if key.startswith("sqp-"):
        return "sqpmethod", "gauss-newton", _sqp(key[4:])
    if key == "feasiblesqp":
        o = _sqp("qpoases", plugin="feasiblesqpmethod")
        o.update(optim_tol=TOL, feas_tol=TOL)
        return "feasiblesqpmethod", "gauss-newton", o
    if key == "qrsqp":
        return "qrsqp", "exact", {"print_time": False, "print_header": False, "print_iteration": False,
                                  "tol_pr": TOL, "tol_du": TOL, "max_iter": MAX_ITER}
    if key in ("fatrop", "fatrop-auto"):
        o = {"print_time": False, "fatrop": {"tol": TOL, "max_iter": MAX_ITER,
                                             "print_level": 0}}
        if key == "fatrop-auto":
            o["structure_detection"] = "auto"
        return "fatrop", "exact", o
    if key in ("uno-filtersqp", "uno-ipopt"):
        return "uno", "exact", {"print_time": False, "uno": {"preset": key[4:]}}
    if key == "sleqp":
        return "sleqp", "exact", {"print_time": False, "print_level": 0, "max_iter": MAX_ITER, "max_wall_time": CAP,
                                  "sleqp": {"stat_tol": TOL, "feas_tol": TOL, "slack_tol": TOL}}
    if key == "alpaqa":
        return "alpaqa", "exact", {"print_time": False}
    if key == "bonmin":
        return "bonmin", "gauss-newton", {"print_time": False, "bonmin": {
            "tol": TOL, "acceptable_iter": 0, "max_iter": MAX_ITER, "print_level": 0, "time_limit": CAP}}
    if key in ("blocksqp", "blocksqp-ma27"):
        o = {"print_time": False, "print_header": False, "print_iteration": False, "print_maxit_reached": False,
             "opttol": TOL, "nlinfeastol": TOL, "max_iter": MAX_ITER}
        if key == "blocksqp":
            o["linsol"] = "ldl"
        return "blocksqp", "exact", o
    raise KeyError(key)


# key: (description, Hessian as given to the solver)
CONFIGS = {
    "ipopt": ("IPOPT, MUMPS", "exact (CasADi AD)"),
    "ipopt-gn": ("IPOPT, MUMPS", "Gauss-Newton J^T J"),
    "ipopt-lbfgs": ("IPOPT, MUMPS", "L-BFGS"),
    "sqp-qpoases": ("sqpmethod + qpOASES", "Gauss-Newton"),
    "sqp-qpoases-exact": ("sqpmethod + qpOASES", "exact"),
    "sqp-lbfgs": ("sqpmethod + qpOASES", "BFGS (limited-memory)"),
    "sqp-qrqp": ("sqpmethod + qrqp", "Gauss-Newton"),
    "sqp-osqp": ("sqpmethod + OSQP", "Gauss-Newton"),
    "sqp-proxqp": ("sqpmethod + ProxQP", "Gauss-Newton"),
    "sqp-daqp": ("sqpmethod + DAQP", "Gauss-Newton"),
    "sqp-highs": ("sqpmethod + HiGHS", "Gauss-Newton"),
    "sqp-piqp": ("sqpmethod + PIQP", "Gauss-Newton"),
    "sqp-ipqp": ("sqpmethod + ipqp", "Gauss-Newton"),
    "sqp-superscs": ("sqpmethod + SuperSCS", "Gauss-Newton"),
    "sqp-nlpsol": ("sqpmethod + IPOPT as QP solver", "Gauss-Newton"),
    "sqp-hpipm": ("sqpmethod + HPIPM", "Gauss-Newton"),
    "feasiblesqp": ("feasiblesqpmethod + qpOASES", "Gauss-Newton"),
    "qrsqp": ("qrsqp (SQP + qrqp)", "exact"),
    "fatrop": ("fatrop, no structure (one stage)", "exact"),
    "fatrop-auto": ("fatrop, structure detection 'auto'", "exact"),
    "uno-filtersqp": ("Uno, preset filtersqp", "exact"),
    "uno-ipopt": ("Uno, preset ipopt", "exact"),
    "sleqp": ("SLEQP", "as the CasADi interface sets it (not an option)"),
    "alpaqa": ("alpaqa (ALM + PANOC)", "L-BFGS (inside PANOC)"),
    "bonmin": ("Bonmin (continuous: IPOPT inside)", "Gauss-Newton"),
    "blocksqp": ("blockSQP, linsol ldl", "SR1/BFGS blockwise"),
    "blocksqp-ma27": ("blockSQP, its default linsol ma27", "SR1/BFGS blockwise"),
}
QUICK_CONFIGS = ["ipopt", "sqp-qpoases"]

#: what is known about a plugin's behaviour here (for the page)
PLUGIN_NOTES = {
    "sqp-hpipm": "HPIPM solves QPs with an optimal-control stage structure (N, nx, nu, ng); sqpmethod hands it a "
                 "general QP without one and the process dies with a segmentation fault instead of an error.",
    "blocksqp-ma27": "blockSQP's default linear solver is HSL MA27 (libhsl.so), which is not installed: the solve "
                     "stops with 'libhsl.so: cannot open shared object file'. With `linsol` = 'ldl' (CasADi's own "
                     "LDL) it runs (`blocksqp`); 'mumps' and 'qr' fail ('neig' not defined).",
    "blocksqp": "reports neither an iteration count (-1) nor a status ('unknown'); success only.",
    "fatrop-auto": "structure detection needs the `equality` option (the study passes it) and an optimal-control "
                   "layout, which our multiple-shooting NLP is not: the parameters are decision variables of the "
                   "first stage that every later continuity constraint depends on ('Constraint found depending on "
                   "a state of the previous interval'), so the solver cannot be created. On the direct and adapted "
                   "problems there are no constraints to detect a structure in. What fatrop needs from casflex: "
                   "the parameters carried as states of every interval (theta_{k+1} = theta_k as extra gap "
                   "constraints), the decision variables ordered stage by stage [theta_0; S_1, theta_1; ...], "
                   "each continuity constraint written as S_{k+1} - F(S_k, theta_k) = 0, and the residue split "
                   "into per-interval terms.",
    "fatrop": "without structure fatrop is a one-stage interior-point method (IPOPT-like); its `acceptable_iter` "
              "= 0 makes it stop at once with status 1, so it keeps its default.",
    "sleqp": "the CasADi interface sets success = true whatever SLEQP's status (e.g. 'iteration limit'); the study "
             "counts only the status 'optimal' as success. Its time is erratic: the same direct run (start 0.8) "
             "repeated 6 times outside the study took 0.6-9 ms five times and 11 s once; in the study 2 of 4 "
             "direct starts took 15-22 s for 4-5 iterations.",
    "alpaqa": "the interface takes no options (ALM tolerances 1e-10 and 3000 outer iterations are hard-coded), "
              "reports no iteration count nor status, and prints its statistics to stdout whatever the options; "
              "it reports success with its own p far from p* (see the solver's p error), and CasADi builds its "
              "exact Hessians symbolically, which on the multiple-shooting problem does not finish within the cap.",
    "uno-filtersqp": "only the option `preset` reaches Uno through the CasADi 3.8.2 interface.",
    "uno-ipopt": "only the option `preset` reaches Uno through the CasADi 3.8.2 interface.",
    "bonmin": "an MINLP solver (B-BB); with no integer variable it makes one IPOPT solve and reports 0 iterations.",
    "sqp-superscs": "a first-order conic solver: each QP subproblem takes long and is inexact, so sqpmethod makes "
                    "slow progress.",
    "sqp-osqp": "a first-order QP solver, asked for 1e-10: many ADMM iterations per subproblem.",
    "sqp-nlpsol": "IPOPT solving each QP subproblem: accurate but with IPOPT's overhead per SQP iteration.",
}

#: how TOL maps onto each plugin's options (for the page)
TOL_MAP = [
    ("ipopt, bonmin", f"`tol` = {TOL:g} (IPOPT's scaled overall NLP error), `acceptable_iter` = 0 (no early "
     f"'acceptable' exit), `max_iter` = {MAX_ITER}, `max_wall_time` = {CAP:g} s (Bonmin: `bonmin.time_limit`)"),
    ("sqpmethod, qrsqp, feasiblesqpmethod", f"`tol_pr` = `tol_du` = {TOL:g} (inf-norms of the constraint "
     f"violation and of the Lagrangian gradient; feasiblesqpmethod also `optim_tol`, `feas_tol`), `max_iter` = "
     f"{MAX_ITER}; QP solvers at their defaults except OSQP, ProxQP, PIQP, ipqp, SuperSCS and IPOPT-as-QP at "
     f"{QP_TOL:g}; no wall-time option: killed at the cap"),
    ("fatrop", f"`fatrop.tol` = {TOL:g} (IPOPT-like scaled error), `max_iter` = {MAX_ITER} (fatrop's "
     "`acceptable_iter` = 0 makes it return status 1 at once, so it keeps its default); no wall-time option: "
     "killed at the cap"),
    ("uno", "the CasADi 3.8.2 interface passes only `preset`; Uno runs at its defaults: `tolerance` 1e-8 "
     "(`loose_tolerance` 1e-6 after 15 iterations), 2000 iterations, no time limit: killed at the cap"),
    ("sleqp", f"`stat_tol` = `feas_tol` = `slack_tol` = {TOL:g}, `max_iter` = {MAX_ITER}, `max_wall_time` = "
     f"{CAP:g} s"),
    ("alpaqa", "the interface takes no options: its ALM tolerance and dual tolerance are hard-coded to 1e-10, "
     "3000 outer and 500 inner iterations; killed at the cap"),
    ("blocksqp", f"`opttol` = `nlinfeastol` = {TOL:g}, `max_iter` = {MAX_ITER}; killed at the cap"),
]


# ----------------------------------------------------------------------------------------------
# one start, in its own process
# ----------------------------------------------------------------------------------------------

class _Spy:
    """Wraps the nlpsol Function the library builds: times the solver call alone and keeps the
    solver's own x (before the library's Gauss-Newton polish). Observation only."""

    def __init__(self, fn, log: dict) -> None:
        self._fn, self._log = fn, log

    def __call__(self, *args, **kwargs):
        t0 = time.perf_counter()
        out = self._fn(*args, **kwargs)
        self._log["nlp_s"] = time.perf_counter() - t0
        self._log["x"] = np.array(out["x"]).ravel()
        st = self._fn.stats()
        self._log["solver_status"] = str(st.get("return_status", "?"))
        self._log["solver_iterations"] = int(st.get("iter_count", -1))
        return out

    def __getattr__(self, name):
        return getattr(self._fn, name)


_LOG: dict = {}


def _one(spec: dict) -> dict:
    """Run one identification (in a child process) and measure it."""
    import casadi as ca

    from casflex.data import load_measurements
    from casflex.identification import identify_adapted_direct, identify_direct, identify_indirect
    from casflex.identification.problem import ParameterMap
    from casflex.model import assemble
    from casflex.scene_io import load_scene

    log = _LOG
    real = ca.nlpsol

    def spy(*args, **kwargs):
        try:
            fn = real(*args, **kwargs)
            log.pop("nlpsol_errors", None)  # an earlier attempt failed, this one did not
            return _Spy(fn, log)
        except RuntimeError as exc:  # keep CasADi's full reason (the library passes on its last line)
            keep = [ln.strip()[:170] for ln in str(exc).splitlines()[1:]
                    if any(w in ln for w in ("Assertion", "rror", "nknown option", "failed", "not", "requires"))]
            log.setdefault("nlpsol_errors", []).append(" / ".join(keep)[:600])
            raise

    ca.nlpsol = spy
    model = assemble(load_scene("twobar"))
    data = load_measurements(spec["data"])
    plugin, hessian, opts = _config(spec["config"], spec["problem"])
    if opts.get("structure_detection") == "auto" and spec["problem"] == "ms":
        # fatrop's structure detection needs every constraint marked as an equality; the
        # multiple-shooting NLP has one continuity block of nx = 3 n + n_c rows per interval joint
        n_steps = round(PROBLEMS[spec["problem"]][1]["horizon"] / float(np.min(np.diff(data.t))))
        opts["equality"] = [True] * ((3 * model.n_dof + model.n_con) * (max(1, round(n_steps / 20)) - 1))
    kw = dict(PROBLEMS[spec["problem"]][1])
    method = kw.pop("method")
    common = {"start": spec["start"], "solver": plugin, "solver_options": opts, "hessian": hessian}
    t0 = time.perf_counter()
    if method == "direct":
        r = identify_direct(model, data, kw["instants"], **common)
    elif method == "adapted":
        r = identify_adapted_direct(model, data, kw["instants"], **common)
    else:
        h = kw.pop("horizon")
        # the seed paper's NLP formulation, as this page was measured (model Newton tolerance 1e-14)
        r = identify_indirect(model, data, h, **kw, **common, newton_tol=1e-14, model_error="none")
    wall = time.perf_counter() - t0
    ps = model.p_nominal
    rel = np.abs(r.p / ps - 1.0)
    out = {"success": bool(r.success), "status": str(r.status), "iterations": int(r.iterations),
           "build_s": r.wall_build_s, "solve_s": r.wall_solve_s, "wall_s": wall, "p": r.p.tolist(),
           "err": float(rel.max()), "err_k": float(rel[[0, 2]].max()), "objective": r.objective,
           "polish": int(r.extra.get("gauss_newton_polish", -1)), "message": r.message}
    if "x" in log:
        p_solver = ParameterMap.of(model).p(log["x"][:model.n_p])
        out.update(p_solver=p_solver.tolist(), err_solver=float(np.abs(p_solver / ps - 1.0).max()),
                   nlp_s=log["nlp_s"])
    return out


def _child_main(spec_path: str, out_path: str) -> None:
    spec = json.loads(Path(spec_path).read_text())
    try:
        res = _one(spec)
    except Exception as exc:  # noqa: BLE001 - the failure is the measurement
        msg = " / ".join(ln.strip() for ln in str(exc).splitlines() if ln.strip())
        if len(msg) > 300:
            msg = msg[:110] + " ... " + msg[-185:]
        res = {"error": f"{type(exc).__name__}: {msg}"}
        if _LOG.get("nlpsol_errors"):
            res["error"] += " [CasADi: " + _LOG["nlpsol_errors"][-1] + "]"
        if "x" in _LOG:  # the solver ran; the library failed after it
            res["error"] = (f"solver returned ({_LOG['solver_status']}, {_LOG['solver_iterations']} it, x "
                            f"{'finite' if np.isfinite(_LOG['x']).all() else 'not finite'}), then the library "
                            f"raised {res['error']}")
    Path(out_path).write_text(json.dumps(res))


# ----------------------------------------------------------------------------------------------
# one (problem, solver) pair: its starts in turn, each in a child process (runs on a dask worker)
# ----------------------------------------------------------------------------------------------

def run_pair(*, problem: str, config: str, starts: list[float], data: str, script: str, workdir: str,
             cap: float = CAP, margin: float = HARD_MARGIN) -> dict:
    """Run ``config`` on ``problem`` from each start, each in a fresh Python process with a
    wall-time limit; a start after one that hit the cap is skipped."""
    import json as _json
    import subprocess as _sp
    import sys as _sys
    import tempfile as _tf
    import time as _time
    from pathlib import Path as _P

    runs = []
    capped = None
    for st in starts:
        if capped is not None:
            runs.append({"start": st, "skipped": f"start {capped:g} hit the {cap:g} s cap", "success": False})
            continue
        with _tf.TemporaryDirectory(dir=workdir) as tmp:
            spec_p, out_p = _P(tmp) / "spec.json", _P(tmp) / "out.json"
            spec_p.write_text(_json.dumps({"problem": problem, "config": config, "start": st, "data": data}))
            t0 = _time.perf_counter()
            try:
                proc = _sp.run([_sys.executable, script, "--one", str(spec_p), str(out_p)], cwd=tmp,
                               capture_output=True, text=True, errors="replace", timeout=cap + margin)
                rc, tail = proc.returncode, (proc.stderr or "")[-1500:] + (proc.stdout or "")[-500:]
            except _sp.TimeoutExpired:
                rc, tail = None, ""
            wall = _time.perf_counter() - t0
            res = _json.loads(out_p.read_text()) if out_p.exists() else None
        if rc is None:
            res = {"killed": True, "status": f"killed at the cap ({cap + margin:g} s of wall time)"}
        elif res is None:
            sig = f"signal {-rc}" if rc < 0 else f"exit status {rc}"
            last = [ln for ln in tail.splitlines() if ln.strip()]
            res = {"crashed": True, "status": f"crashed ({sig})", "tail": " / ".join(last[-3:])[-400:]}
        res.update(start=st, process_s=wall)
        res.setdefault("success", False)
        if res.get("killed") or _hit_cap(res, cap):
            capped = st
        runs.append(res)
    return {"problem": problem, "config": config, "runs": runs}


def _hit_cap(res: dict, cap: float) -> bool:
    s = str(res.get("status", "")).lower()
    return ("time" in s and ("exceed" in s or "limit" in s)) or res.get("solve_s", 0.0) >= cap


# ----------------------------------------------------------------------------------------------
# the study
# ----------------------------------------------------------------------------------------------

def _criterion(problem: str, r: dict) -> bool:
    if "err" not in r:
        return False
    return r["err_k"] <= P_TOL_ADAPTED if problem == "adapted" else r["err"] <= P_TOL


def _flag(config: str, r: dict) -> bool:
    """The solver's success flag. SLEQP's CasADi interface sets success = true whatever its status
    (e.g. 'iteration limit'), so for SLEQP the flag is its status 'optimal'."""
    if config == "sleqp":
        return r.get("status") == "optimal"
    return bool(r.get("success"))


def _solver_err(problem: str, r: dict) -> float:
    """Relative error of the solver's own p (before the library's polish): max over k1, k3 for
    the adapted direct problem, over every parameter otherwise."""
    if "p_solver" not in r:
        return math.nan
    rel = np.abs(np.asarray(r["p_solver"], dtype=float) / np.asarray(P_STAR) - 1.0)
    return float(rel[[0, 2]].max()) if problem == "adapted" else float(rel.max())


def _criterion_solver(problem: str, r: dict) -> bool:
    """The criterion on the solver's own p."""
    e = _solver_err(problem, r)
    return math.isfinite(e) and e <= (P_TOL_ADAPTED if problem == "adapted" else P_TOL)


@contextlib.contextmanager
def _importable_on_local_workers():
    """``run_pair`` travels to the dask workers by reference when this file was imported as a
    module (e.g. by tests/test_studies.py, which registers it in sys.modules) and by value when
    it runs as a script. For the first case, put this file's directory on sys.path while the
    local cluster starts: its worker processes (multiprocessing 'spawn') take the parent's
    sys.path, so they can import the module too. A remote cluster's workers need it on their path."""
    d = str(SCRIPT.parent)
    add = __name__ != "__main__" and d not in sys.path
    if add:
        sys.path.insert(0, d)
    try:
        yield
    finally:
        if add and d in sys.path:
            sys.path.remove(d)


def _sweep(pairs, record: Path, data: Path, scheduler, n_workers, starts, label) -> dict:
    from casflex.sweep import Run, run_sweep

    workdir = record / "work"
    workdir.mkdir(parents=True, exist_ok=True)
    runs = [Run(f"{pb}--{cf}", run_pair, {"problem": pb, "config": cf, "starts": list(starts), "data": str(data),
                                         "script": str(SCRIPT), "workdir": str(workdir)})
            for pb, cf in pairs]
    t0 = time.perf_counter()

    def progress(done: int, total: int, key: str) -> None:
        print(f"  [{label} {done:3d}/{total}] {key:<28s} {time.perf_counter() - t0:6.0f} s", flush=True)

    with _importable_on_local_workers():
        sw = run_sweep(runs, record, scheduler=scheduler, n_workers=n_workers, progress=progress)
    if sw.interrupted:
        raise KeyboardInterrupt
    if sw.executed:  # the sweeps' wall time, accumulated over the calls that produced the records
        acc = record / "sweep_wall_s.json"
        prev = json.loads(acc.read_text()) if acc.exists() else {}
        prev[label] = prev.get(label, 0.0) + sw.wall_s
        # the 5-minute load average at the end of the sweep (the largest over the calls)
        prev[f"load {label}"] = max(prev.get(f"load {label}", 0.0), os.getloadavg()[1])
        acc.write_text(json.dumps(prev))
    out = {}
    for k, v in sw.results.items():
        pb, cf = k.split("--")
        if "error" in v:  # the pair's function itself raised (not a solver failure)
            v = {"problem": pb, "config": cf, "runs": [{"start": s, "success": False, "status": "sweep error",
                                                        "tail": v["error"]} for s in starts]}
        out[(pb, cf)] = [_clean(r) for r in v["runs"]]
    return out


def _clean(x):
    """Undo the sweep record's JSON form of non-finite numbers ("nan", "inf")."""
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_clean(v) for v in x]
    if isinstance(x, str) and x in ("nan", "inf", "-inf"):
        return float(x)
    return x


def _print_pair(pb: str, cf: str, runs: list[dict]) -> None:
    for r in runs:
        ok = _criterion(pb, r)
        flag = "  ** success reported at a wrong p **" if _flag(cf, r) and not ok else ""
        if "err" in r:
            print(f"    {pb:<7s} {cf:<18s} start {r['start']:>3g}: {'OK ' if _flag(cf, r) and ok else 'no '} "
                  f"{r['status'][:34]:<34s} {r['iterations']:>4d} it  build {r['build_s']:6.2f} s  solve "
                  f"{r['solve_s']:7.2f} s  err {r['err']:.1e} (solver's p {r.get('err_solver', math.nan):.1e}){flag}",
                  flush=True)
        else:
            what = r.get("skipped") or r.get("error") or r.get("status", "?")
            print(f"    {pb:<7s} {cf:<18s} start {r['start']:>3g}: no  {str(what)[:110]}", flush=True)


def main(quick: bool = False, out_dir: Path | None = None, scheduler: str | None = None,
         record: Path | None = None, n_workers: int = 2) -> dict:
    """Run the comparison; write the page and the performance profile under ``out_dir``
    (default docs/). ``record``: keep the per-run records there (and resume from them)."""
    from casflex.data import save_measurements, simulated_set
    from casflex.model import assemble
    from casflex.scene_io import load_scene

    out_dir = ROOT / "docs" if out_dir is None else Path(out_dir)
    wall0 = time.perf_counter()
    print("=" * 78)
    print(f"solvers: NLP solver comparison on the identification problems ({'quick' if quick else 'full'} mode)")
    print("=" * 78, flush=True)
    tmp_ctx = tempfile.TemporaryDirectory(prefix="casflex-solvers-") if record is None else None
    rec = Path(tmp_ctx.name) if tmp_ctx is not None else Path(record)
    rec.mkdir(parents=True, exist_ok=True)
    try:
        data = rec / "simulated_set.npz"
        if not data.exists():
            model = assemble(load_scene("twobar"))
            assert np.allclose(model.p_nominal, P_STAR), "twobar's nominal parameters changed: update P_STAR"
            save_measurements(simulated_set(model, T_DATA), data)
        starts = QUICK_STARTS if quick else STARTS
        configs = QUICK_CONFIGS if quick else list(CONFIGS)
        stage1_problems = ["direct"] if quick else ["direct", "adapted"]
        print(f"stage 1: {len(configs)} solver configurations on {', '.join(stage1_problems)}, starts "
              f"{', '.join(f'{s:g}' for s in starts)} x p*", flush=True)
        results = _sweep([(pb, cf) for pb in stage1_problems for cf in configs], rec, data, scheduler, n_workers,
                         starts, "stage 1")
        for (pb, cf), runs in sorted(results.items()):
            _print_pair(pb, cf, runs)
        screened = [cf for cf in configs if any(_flag(cf, r) and _criterion("direct", r)
                                                for r in results[("direct", cf)])]
        dropped = [cf for cf in configs if cf not in screened]
        stage2_problems = [] if quick else ["ss", "ms"]
        if stage2_problems:
            print(f"stage 2: {len(screened)} configurations that solved the direct problem on "
                  f"{', '.join(stage2_problems)} (not run: {', '.join(dropped) or 'none'})", flush=True)
            pairs2 = [(pb, cf) for pb in stage2_problems for cf in screened]
            if "fatrop-auto" in configs and "fatrop-auto" not in screened:
                pairs2.append(("ms", "fatrop-auto"))  # its structure detection is meant for multiple shooting
            res2 = _sweep(pairs2, rec, data, scheduler, n_workers, starts, "stage 2")
            for (pb, cf), runs in sorted(res2.items()):
                _print_pair(pb, cf, runs)
            results.update(res2)

        acc = rec / "sweep_wall_s.json"
        sweep_s = json.loads(acc.read_text()) if acc.exists() else {}
    finally:
        if tmp_ctx is not None:
            tmp_ctx.cleanup()

    problems = stage1_problems + stage2_problems
    raw = {"sweep_s": sweep_s, "quick": quick, "starts": starts, "configs": configs, "problems": problems,
           "screened": screened,
           "results": {f"{pb}--{cf}": runs for (pb, cf), runs in results.items()},
           "total_s": time.perf_counter() - wall0, "machine": platform.machine(),
           "python": platform.python_version(), "load": os.getloadavg()[0]}
    summary = write_outputs(raw, out_dir)

    # self-checks
    for st in starts:
        r = next(x for x in results[("direct", "ipopt")] if x["start"] == st)
        assert r.get("success") and _criterion("direct", r), f"IPOPT must solve the direct problem from {st:g} x p*"
    for pb in problems:
        sp = summary["spread"].get(pb)
        if sp is not None and pb != "adapted":  # the consensus of the runs that report success is p*
            dev = float(np.abs(np.asarray(sp["median_p"]) / np.asarray(P_STAR) - 1.0).max())
            assert dev <= P_TOL, f"{pb}: the median p of the runs that report success is {dev:.1e} off p*"
    return {"raw": raw, "summary": summary}


# ----------------------------------------------------------------------------------------------
# analysis, page and figure
# ----------------------------------------------------------------------------------------------

def _med(v):
    v = [x for x in v if x is not None and math.isfinite(x)]
    return float(np.median(v)) if v else math.nan


def _analyse(raw: dict) -> dict:
    res = {tuple(k.split("--")): v for k, v in raw["results"].items()}
    rows = {}
    for (pb, cf), runs in res.items():
        ok = [_flag(cf, r) and _criterion(pb, r) for r in runs]
        measured = [r for r in runs if "err" in r]
        rows[(pb, cf)] = {
            "n": len(runs), "solved": sum(ok), "flag": sum(_flag(cf, r) for r in runs),
            "wrong": sum(_flag(cf, r) and not o for r, o in zip(runs, ok, strict=True)),
            "rescued": sum((not _flag(cf, r)) and _criterion(pb, r) for r in runs),
            "solver_off": sum(_flag(cf, r) and not _criterion_solver(pb, r) for r in runs),
            "it": [r["iterations"] for r in measured], "build": [r["build_s"] for r in measured],
            "solve": [r["solve_s"] for r in measured], "err": [r["err"] for r in measured],
            "err_k": [r["err_k"] for r in measured],
            "err_solver": [_solver_err(pb, r) for r in measured],
            "statuses": sorted({str(r.get("status") or r.get("skipped") or r.get("error", "?"))[:60] for r in runs}),
            "runs": runs, "ok": ok,
        }
    # cross-solver consistency: the spread of p among runs that report success
    spread = {}
    for pb in raw["problems"]:
        P, Ps = [], []
        for (p2, cf), row in rows.items():
            if p2 != pb:
                continue
            for r in row["runs"]:
                if _flag(cf, r) and "p" in r:
                    P.append(r["p"])
                    if "p_solver" in r:
                        Ps.append(r["p_solver"])
        if len(P) >= 2:
            P, Ps = np.array(P), np.array(Ps) if Ps else None
            ref = np.median(P, axis=0)
            rel = np.abs(P / ref - 1.0)
            spread[pb] = {"n": len(P), "median_p": ref.tolist(), "final": float(rel.max()),
                          "final_per_param": rel.max(axis=0).tolist(),
                          "solver": float(np.abs(Ps / ref - 1.0).max()) if Ps is not None and len(Ps) else math.nan,
                          "solver_per_param": (np.abs(Ps / ref - 1.0).max(axis=0).tolist()
                                               if Ps is not None and len(Ps) else None)}
    return {"rows": rows, "spread": spread}


def _profile(raw: dict, rows: dict, key: str) -> tuple[list[str], np.ndarray]:
    """Dolan-More ratios: (configs, ratios[config, problem instance]) with inf where not solved."""
    cfgs = raw["configs"]
    inst = [(pb, st) for pb in raw["problems"] for st in raw["starts"]]
    T = np.full((len(cfgs), len(inst)), np.inf)
    for i, cf in enumerate(cfgs):
        for j, (pb, st) in enumerate(inst):
            row = rows.get((pb, cf))
            if row is None:
                continue
            for r, o in zip(row["runs"], row["ok"], strict=True):
                if r["start"] == st and o:
                    T[i, j] = r["solve_s"] if key == "solve" else r["build_s"] + r["solve_s"]
    best = T.min(axis=0)
    with np.errstate(invalid="ignore"):
        R = np.where(np.isfinite(T) & np.isfinite(best), T / np.where(best > 0, best, 1.0), np.inf)
    return cfgs, R


def write_outputs(raw: dict, out_dir: Path) -> dict:
    an = _analyse(raw)
    lines = _page(raw, an)
    suffix = "_quick" if raw["quick"] else ""
    p = atomic_write_text(out_dir / "tables" / f"solvers{suffix}.md", "\n".join(lines))
    print(f"wrote {p}")
    p = atomic_write_bytes(out_dir / "figures" / f"solvers{suffix}.png", _figure(raw, an))
    print(f"wrote {p}")
    print(f"total {raw['total_s']:.0f} s", flush=True)
    return an


def _f(x, fmt=".2g") -> str:
    return "–" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, fmt)


def _rng(v, fmt=".2g") -> str:
    v = [x for x in v if x is not None and math.isfinite(x)]
    if not v:
        return "–"
    lo, md, hi = min(v), float(np.median(v)), max(v)
    return format(md, fmt) if lo == hi else f"{format(md, fmt)} ({format(lo, fmt)}-{format(hi, fmt)})"


#: configurations not considered for the library default, and why
NOT_DEFAULT = {"bonmin": "an MINLP solver: on this continuous NLP it makes one IPOPT solve (here with the "
                         "Gauss-Newton Hessian), i.e. it is `ipopt-gn` with more set-up"}
#: the library's current default per problem (identify_*'s solver and hessian arguments)
CURRENT = {"direct": "ipopt", "adapted": "ipopt", "ss": "ipopt-gn", "ms": "ipopt-gn"}
SPEEDUP, SAVING = 1.5, 0.1  # a faster solver must be this many times and this many seconds faster per run


def _choice(raw: dict, rows: dict, pb: str) -> tuple[str | None, list[tuple]]:
    """Ranking of the configurations on one problem: most starts solved, fewest successes at a
    wrong p, then the smallest median build + solve time of the solved starts. Entries:
    (config, solved, n, median time, wrong, starts whose own p (before the polish) is right)."""
    ranked = []
    for cf in raw["configs"]:
        row = rows.get((pb, cf))
        if row is None or row["solved"] == 0:
            continue
        t = [r["build_s"] + r["solve_s"] for r, o in zip(row["runs"], row["ok"], strict=True) if o]
        own = sum(o and _criterion_solver(pb, r) for r, o in zip(row["runs"], row["ok"], strict=True))
        ranked.append((cf, row["solved"], row["n"], float(np.median(t)), row["wrong"], own))
    ranked.sort(key=lambda x: (-x[1], x[4], x[3]))
    return (ranked[0][0] if ranked else None), ranked


def _page(raw: dict, an: dict) -> list[str]:
    rows, spread = an["rows"], an["spread"]
    quick = raw["quick"]
    cmd = f"python studies/solvers.py{' --quick' if quick else ''}"
    n_st = len(raw["starts"])
    L = [
        "# NLP solver comparison" + (" (quick mode)" if quick else ""), "",
        f"Generated by `{cmd}` on {raw['machine']} (Python {raw['python']}, CasADi {_casadi_version()}); wall time "
        "of the sweeps: " + ", ".join(f"{k} {v:.0f} s" for k, v in raw.get("sweep_s", {}).items()
                                      if not k.startswith("load"))
        + " (run records in a resumable directory; the page is rendered from them), two worker processes on a "
        "shared 2-core machine (5-minute load average at the end of the sweeps: "
        + (", ".join(f"{v:.1f}" for k, v in raw.get("sweep_s", {}).items() if k.startswith("load")) or "?")
        + "; other jobs ran at the same time, so times are comparable within this page only). "
        "Twobar scene, simulated set (HHT alpha = 0, dt = 1e-3 s), p* = [k1 kt1 k3 kt3] = [700 0.5 400 0.5]; "
        f"starts {', '.join(f'{s:g}' for s in sorted(raw['starts']))} x p* (all four parameters scaled alike).", "",
        "Problems:", "",
    ]
    for pb in raw["problems"]:
        L.append(f"- `{pb}`: {PROBLEMS[pb][0]}")
    L += ["", "Each start runs in its own Python process (`casflex.sweep.run_sweep` on dask.distributed, one record "
          "per problem and solver), so crashes and stalls are recorded, not fatal. Every run is capped at "
          f"{CAP:g} s of solve time (the solver's own wall-time option where it has one; otherwise the process is "
          f"killed at {CAP + HARD_MARGIN:g} s of wall time); after a start hits the cap, the farther starts of that "
          f"problem and solver are skipped (counted as not solved). Starts run nearest first "
          f"({', '.join(f'{s:g}' for s in raw['starts'])}).", "",
          "**Measures.** *flag*: the solver reports success (for the indirect method also: the HHT Newton "
          "iterations converge at the identified p). *p right*: the identified p (as the library returns it, after "
          f"its Gauss-Newton polish of at most 3 steps) is within {P_TOL:g} relative of p* in every parameter "
          f"(adapted direct: k1 and k3 within {P_TOL_ADAPTED:g}, as in basins.md: kt1 and kt3 are weakly "
          "identifiable by design and their minimiser is 1e-4 off p*). *Solved* = flag and p right. "
          "*✗!* = flag at a wrong p. *Rescued* = no flag, but the polish put p right. *Solver's p error*: the "
          "same error measured on the solver's own answer, before the polish; *flag, solver's p off*: the solver "
          "reports success but its own p misses the criterion (the polish had to finish the job). "
          "*Solve time* is the library's "
          "`wall_solve_s` (solver and polish); *build* is `wall_build_s` (problem and derivative construction, "
          "solver creation).", "",
          "## Tolerances", "", f"One tolerance, TOL = {TOL:g} on each solver's own optimality (KKT) measure, the "
          f"same iteration cap ({MAX_ITER}), the same wall-time cap ({CAP:g} s):", "",
          "| plugin | options |", "|---|---|"]
    for pl, txt in TOL_MAP:
        L.append(f"| {pl} | {txt} |")
    L += ["", "The measures differ in their scaling (IPOPT's is scaled by the multipliers' size, sqpmethod's is "
          "absolute), which is the part of 'identical' no option can reach.", ""]

    # survey
    L += ["## Which plugins work here", "",
          "| configuration | plugin, linear/QP solver | Hessian | direct problem (stage 1) |", "|---|---|---|---|"]
    for cf in raw["configs"]:
        desc, hess = CONFIGS[cf]
        row = rows.get(("direct", cf))
        L.append(f"| `{cf}` | {desc} | {hess} | {_survey_text(row, n_st)} |")
    if not quick:
        dropped = [cf for cf in raw["configs"] if cf not in raw["screened"]]
        L += ["", f"Stage 2 (indirect problems) runs the {len(raw['screened'])} configurations that solved the direct "
              "problem from at least one start" + (f"; not run there: {', '.join(f'`{c}`' for c in dropped)}."
                                                     if dropped else ".")]
    L += ["", "Not available in this CasADi build: knitro, snopt, worhp (their libraries are absent), madnlp and ccopt "
          "(libMad.so missing), conopt (libconopt.so.4 missing); ampl needs an external AMPL solver executable; "
          "scpgen refuses an SX problem ('generate_lifted' only defined for 'MXFunction'). QP solvers cplex, gurobi, "
          "mosek, xpress are absent; clp and cbc are LP solvers ('Not an LP'). Solvers without a `hess_lag` option "
          "(fatrop, Uno, SLEQP, alpaqa, blockSQP, qrsqp) cannot take the Gauss-Newton Hessian through casflex "
          "(`hessian=\"gauss-newton\"` fails at creation with 'Unknown option hess_lag'): they get the exact "
          "Hessian or their own quasi-Newton one.", ""]

    # per problem tables
    for pb in raw["problems"]:
        L += [f"## {PROBLEMS[pb][0]}", "",
              "| configuration | solved | flag | ✗! | rescued | flag, solver's p off | iterations | build (s) | "
              "solve (s) | error of p (final) | solver's p error | status |",
              "|---|:-:|:-:|:-:|:-:|:-:|---:|---:|---:|---:|---:|---|"]
        for cf in raw["configs"]:
            row = rows.get((pb, cf))
            if row is None:
                continue
            errs = row["err_k"] if pb == "adapted" else row["err"]
            L.append(f"| `{cf}` | {row['solved']}/{row['n']} | {row['flag']} | {row['wrong'] or ''} | "
                     f"{row['rescued'] or ''} | {row['solver_off'] or ''} | {_rng(row['it'], 'g')} | "
                     f"{_f(_med(row['build']), '.3g')} | "
                     f"{_rng(row['solve'], '.3g')} | {_rng(errs, '.1e')} | {_rng(row['err_solver'], '.1e')} | "
                     f"{'; '.join(row['statuses'])[:160]} |")
        L += ["", "Cells: median (min-max) over the starts that ran to the end"
              + ("; errors of p: of k1 and k3." if pb == "adapted" else "."), ""]

    # consistency
    L += ["## Cross-solver consistency", "",
          "Among all runs that report success on a problem (any solver, any start): the median p, and the largest "
          "relative deviation from it, of the final p and of the solvers' own p (before the polish).", "",
          "| problem | runs | median p = [k1 kt1 k3 kt3] | max deviation, final p (per parameter) | "
          "max deviation, solvers' own p (per parameter) |", "|---|---:|---|---|---|"]
    for pb in raw["problems"]:
        sp = spread.get(pb)
        if sp is None:
            continue
        per = " / ".join(f"{v:.1e}" for v in sp["final_per_param"])
        pers = " / ".join(f"{v:.1e}" for v in sp["solver_per_param"]) if sp["solver_per_param"] else "–"
        L.append(f"| `{pb}` | {sp['n']} | [{' '.join(f'{v:.7g}' for v in sp['median_p'])}] | {sp['final']:.1e} "
                 f"({per}) | {_f(sp['solver'], '.1e')} ({pers}) |")
    L += [""]

    # profile
    fig = "solvers_quick.png" if quick else "solvers.png"
    L += ["## Performance profile", "", f"![performance profile](../figures/{fig})", "",
          "Dolan-More profile over the problem instances (problem x start): for each configuration, the fraction of "
          "instances it solves (flag and p right) within a factor tau of the fastest configuration on that "
          "instance. Left: solve time; right: build + solve time. A curve's value at tau = 1 is how often that "
          "configuration was the fastest; its right end is the fraction solved at all.", ""]
    cfgs, R = _profile(raw, rows, "solve")
    _, Rt = _profile(raw, rows, "total")
    L += ["| configuration | solved | fastest (solve) | within 2x | within 10x | fastest (build + solve) |",
          "|---|---:|---:|---:|---:|---:|"]
    order = sorted(range(len(cfgs)), key=lambda i: (-np.isfinite(R[i]).sum(), -(R[i] <= 2).sum()))
    for i in order:
        n = R.shape[1]
        L.append(f"| `{cfgs[i]}` | {np.isfinite(R[i]).sum()}/{n} | {(R[i] <= 1.0).sum()} | {(R[i] <= 2).sum()} | "
                 f"{(R[i] <= 10).sum()} | {(Rt[i] <= 1.0).sum()} |")
    L += [""]

    # notes on the plugins
    L += ["## Notes on the plugins", ""]
    for cf, txt in PLUGIN_NOTES.items():
        if any(k[1] == cf for k in rows):
            L.append(f"- `{cf}`: {txt}")
    L += [""]

    # conclusions and the default
    L += ["## What the numbers say", ""]
    L += _conclusions(raw, an)
    return L


def _casadi_version() -> str:
    try:
        import casadi

        return casadi.__version__
    except ImportError:  # pragma: no cover
        return "?"


def _survey_text(row: dict | None, n: int) -> str:
    if row is None:
        return "not run"
    runs = row["runs"]
    if any(r.get("crashed") for r in runs):
        r = next(r for r in runs if r.get("crashed"))
        sig = r["status"].replace("crashed (", "").rstrip(")")
        what = " (segmentation fault)" if sig == "signal 11" else ""
        return f"**crashes**: {sig}{what}" + (f": {r['tail'][:160]}" if r.get("tail") else "")
    errs = [r for r in runs if "error" in r]
    if len(errs) == len(runs):
        return f"**cannot run**: {errs[0]['error'].split(' [CasADi:')[0][:200]}"
    s = f"solved {row['solved']}/{row['n']}"
    if row["wrong"]:
        s += f", {row['wrong']} ✗!"
    if row["solved"] < row["n"]:
        s += " (" + "; ".join(row["statuses"])[:140] + ")"
    return s


def _conclusions(raw: dict, an: dict) -> list[str]:
    rows = an["rows"]
    out = []
    for pb in raw["problems"]:
        best, ranked = _choice(raw, rows, pb)
        n_cfg = sum(1 for k in rows if k[0] == pb)
        if best is None:
            out.append(f"- **{METHOD_OF[pb]}** (`{pb}`): none of the {n_cfg} configurations solved it.")
            continue
        top = ", ".join(f"`{c}` {s_}/{n} in {t:.3g} s" for c, s_, n, t, _w, _o in ranked[:6])
        s = (f"- **{METHOD_OF[pb]}** (`{pb}`): {len(ranked)} of {n_cfg} configurations solve it from at least one "
             f"start. Best (starts solved, then median build + solve time of the solved starts): {top}.")
        for name in ("ipopt", "ipopt-gn"):
            x = next((x for x in ranked if x[0] == name), None)
            if x is not None:
                s += f" `{name}`: {x[1]}/{x[2]} in {x[3]:.3g} s (rank {ranked.index(x) + 1})."
        own = [c for c, s_, _n, _t, _w, o in ranked if o == s_]
        off = [c for c, s_, _n, _t, _w, o in ranked if o < s_]
        if off:
            e_off = [_med(rows[(pb, c)]["err_solver"]) for c in off]
            s += (" The solver's own p (before the polish) meets the criterion on every solved start for "
                  + (", ".join(f"`{c}`" for c in own) if own else "none") + f"; the other {len(off)} report "
                  f"success with their own p off by a median {min(e_off):.0e} to {max(e_off):.0e} ("
                  + ", ".join(f"`{c}` {_med(rows[(pb, c)]['err_solver']):.0e}" for c in off if c.startswith("ipopt"))
                  + ") and rely on the library's Gauss-Newton polish.")
        wrong = [(cf, rows[(pb, cf)]["wrong"]) for cf in raw["configs"] if (pb, cf) in rows and rows[(pb, cf)]["wrong"]]
        if wrong:
            s += " **Success reported at a wrong p** (after the polish): " + ", ".join(
                f"`{c}` ({w})" for c, w in wrong) + "."
        resc = [(cf, rows[(pb, cf)]["rescued"]) for cf in raw["configs"]
                if (pb, cf) in rows and rows[(pb, cf)]["rescued"]]
        if resc:
            s += (" No success flag, but p right after the polish: " + ", ".join(f"`{c}` ({w})" for c, w in resc)
                  + ".")
            near = [c for c, _w in resc if all(_criterion_solver(pb, r) for r in rows[(pb, c)]["runs"]
                                                if not _flag(c, r) and _criterion(pb, r))]
            if near:
                s += (" Of these, " + ", ".join(f"`{c}`" for c in near) + " had their own p right already: they "
                      "reached the solution but stopped without declaring success (line search stalled, or the "
                      "iteration cap on a stationarity test they could not meet at this problem's round-off "
                      "floor).")
        out.append(s)
    out += ["", "### Default solver", ""]
    out += _default_text(raw, an)
    return out


def _default_text(raw: dict, an: dict) -> list[str]:
    rows = an["rows"]
    out = []
    for pb in raw["problems"]:
        _best, ranked = _choice(raw, rows, pb)
        cands = [x for x in ranked if x[0] not in NOT_DEFAULT]
        cur = CURRENT[pb]
        x_cur = next((x for x in cands if x[0] == cur), None)
        head = f"- **{METHOD_OF[pb]}** (library default `{cur}`): "
        if not cands:
            out.append(head + "nothing solved it; keep the default.")
            continue
        b = cands[0]
        if x_cur is None:
            out.append(head + f"the default solved no start; **recommend `{b[0]}`** ({b[1]}/{b[2]} starts, median "
                       f"{b[3]:.3g} s).")
        elif (b[1], -b[4]) > (x_cur[1], -x_cur[4]):
            out.append(head + f"**recommend `{b[0]}`**: {b[1]}/{b[2]} starts solved against {x_cur[1]}/{x_cur[2]}.")
        elif b[0] != cur and x_cur[3] > SPEEDUP * b[3] and x_cur[3] - b[3] > SAVING:
            out.append(head + f"**recommend `{b[0]}`**: as robust ({b[1]}/{b[2]} starts) and faster, median "
                       f"{b[3]:.3g} s against {x_cur[3]:.3g} s build + solve ({x_cur[3] / b[3]:.1f}x, "
                       f"{x_cur[3] - b[3]:.2g} s per run).")
        else:
            why = "it is the best" if b[0] == cur else (
                f"the fastest at equal robustness, `{b[0]}` ({b[3]:.3g} s), saves {x_cur[3] - b[3]:.2g} s per run "
                f"({x_cur[3] / b[3]:.1f}x)")
            out.append(head + f"**keep it**: {x_cur[1]}/{x_cur[2]} starts, median {x_cur[3]:.3g} s build + solve; "
                       f"{why}.")
    out += ["", f"Rule: robustness first (starts solved, then no success at a wrong p), then time: a configuration "
            f"replaces the default only if it solves more starts, or as many and is both {SPEEDUP:g}x and "
            f"{SAVING:g} s per run faster (medians of build + solve; the machine was shared, so smaller "
            "differences are not evidence). Not candidates: "
            + "; ".join(f"`{k}`: {v}" for k, v in NOT_DEFAULT.items()) + ". The study's IPOPT runs use its "
            f"tolerance {TOL:g} without the 'acceptable' exit; the library's own IPOPT options differ per method "
            "(e.g. tol 1e-14 for the direct method, 1e-8 with acceptable 1e-6 for the indirect one).", ""]
    return out


def _figure(raw: dict, an: dict) -> bytes:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    rows = an["rows"]
    fig = Figure(figsize=(13, 6.5))
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, 2, sharey=True)
    import matplotlib

    c10, c20 = matplotlib.colormaps["tab10"], matplotlib.colormaps["tab20b"]
    for ax, key, title in ((axes[0], "solve", "solve time"), (axes[1], "total", "build + solve time")):
        cfgs, R = _profile(raw, rows, key)
        n = R.shape[1]
        finite = R[np.isfinite(R)]
        tmax = max(2.0, float(finite.max()) * 1.5) if finite.size else 10.0
        taus = np.logspace(0, math.log10(tmax), 400)
        # legend order: most instances solved, then the most often within 4x of the best
        order = sorted((i for i in range(len(cfgs)) if np.isfinite(R[i]).any()),
                       key=lambda i: (-np.isfinite(R[i]).sum(), -(R[i] <= 4).sum()))
        for rank, i in enumerate(order):
            rho = [(R[i] <= t).sum() / n for t in taus]
            main = rank < 8 or cfgs[i] in ("ipopt", "ipopt-gn")
            color = c10(rank) if rank < 10 else c20((rank - 10) % 20)
            ax.step(taus, rho, where="post", label=cfgs[i], color=color, ls="-" if rank < 10 else "--",
                    lw=2.4 if main else 1.0, alpha=1.0 if main else 0.6)
        ax.set_xscale("log")
        ax.set_xlabel("tau (time / best time on the instance)")
        ax.set_title(f"Dolan-More profile: {title}\n{n} instances = {len(raw['problems'])} problems x "
                     f"{len(raw['starts'])} starts", fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.set_ylim(-0.02, 1.02)
    axes[0].set_ylabel("fraction of instances solved within tau x best")
    h, lab = axes[0].get_legend_handles_labels()
    fig.legend(h, lab, loc="center right", fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0, 0.84, 1))
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return buf.getvalue()


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[1] == "--one":
        _child_main(sys.argv[2], sys.argv[3])
        sys.exit(0)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="IPOPT and sqpmethod on the direct problem only")
    ap.add_argument("--scheduler", help="address of a dask scheduler (default: a local cluster of 2 workers)")
    ap.add_argument("--record", type=Path, help="keep the run records in DIR and resume from them")
    ap.add_argument("--workers", type=int, default=2, help="local cluster size (default 2)")
    args = ap.parse_args()
    main(quick=args.quick, scheduler=args.scheduler, record=args.record, n_workers=args.workers)
