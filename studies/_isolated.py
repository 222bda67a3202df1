"""One identification of the twobar scene in its own Python process, with a wall-time limit: a solver that
crashes the process (a segmentation fault) or stalls is recorded, not fatal. Used by studies/solvers.py; a
candidate for the harness. Not a study itself (no ``main``).

The child (``python studies/_isolated.py SPEC OUT``) wraps CasADi's nlpsol to keep the solver's own answer
before the library's Gauss-Newton polish, and writes the result (or the error) as JSON.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


class _Spy:
    """Wraps the nlpsol Function the library builds: times the solver call alone and keeps the
    solver's own x (before the library's Gauss-Newton polish). Observation only."""

    def __init__(self, fn, log: dict) -> None:
        self._fn, self._log = fn, log

    def __call__(self, *args, **kwargs):
        t0 = time.perf_counter()
        out = self._fn(*args, **kwargs)
        st = self._fn.stats()
        self._log.update(nlp_s=time.perf_counter() - t0, x=np.array(out["x"]).ravel(),
                         solver_status=str(st.get("return_status", "?")),
                         solver_iterations=int(st.get("iter_count", -1)))
        return out

    def __getattr__(self, name):
        return getattr(self._fn, name)


_LOG: dict = {}


def _one(spec: dict) -> dict:
    """Run one identification (``spec``: see :func:`run_isolated`) and measure it."""
    import casadi as ca

    from casflex.data import load_measurements
    from casflex.identification import identify_adapted_direct, identify_direct, identify_indirect
    from casflex.identification.problem import ParameterMap
    from casflex.model import assemble
    from casflex.scene_io import load_scene

    real = ca.nlpsol
    ca.nlpsol = lambda *args, **kwargs: _Spy(real(*args, **kwargs), _LOG)
    model = assemble(load_scene("twobar"))
    data = load_measurements(spec["data"])
    opts, kw = spec["solver_options"], dict(spec["problem"])
    if opts.get("structure_detection") == "auto" and kw.get("transcription") == "multiple-shooting":
        # fatrop's structure detection needs every constraint marked as an equality; the multiple-
        # shooting NLP has one continuity block of nx = 3 n + n_c rows per interval joint (20 steps each)
        n_steps = round(kw["horizon"] / float(np.min(np.diff(data.t))))
        opts["equality"] = [True] * ((3 * model.n_dof + model.n_con) * (max(1, round(n_steps / 20)) - 1))
    method = kw.pop("method")
    common = {"start": spec["start"], "solver": spec["solver"], "solver_options": opts, "hessian": spec["hessian"]}
    t0 = time.perf_counter()
    if method == "direct":
        r = identify_direct(model, data, kw["instants"], **common)
    elif method == "adapted":
        r = identify_adapted_direct(model, data, kw["instants"], **common)
    else:  # the seed paper's NLP formulation, as this page was measured (model Newton tolerance 1e-14)
        r = identify_indirect(model, data, kw.pop("horizon"), **kw, **common, newton_tol=1e-14, model_error="none")
    wall = time.perf_counter() - t0
    rel = np.abs(r.p / model.p_nominal - 1.0)
    out = {"success": bool(r.success), "status": str(r.status), "iterations": int(r.iterations),
           "build_s": r.wall_build_s, "solve_s": r.wall_solve_s, "wall_s": wall, "p": r.p.tolist(),
           "err": float(rel.max()), "err_k": float(rel[[0, 2]].max()), "objective": r.objective,
           "polish": int(r.extra.get("gauss_newton_polish", -1)), "message": r.message}
    if "x" in _LOG:
        p_solver = ParameterMap.of(model).p(_LOG["x"][:model.n_p])
        out.update(p_solver=p_solver.tolist(), err_solver=float(np.abs(p_solver / model.p_nominal - 1.0).max()),
                   nlp_s=_LOG["nlp_s"])
    return out


def child_main(spec_path: str, out_path: str) -> None:
    try:
        res = _one(json.loads(Path(spec_path).read_text()))
    except Exception as exc:  # noqa: BLE001 - the failure is the measurement
        msg = " / ".join(ln.strip() for ln in str(exc).splitlines() if ln.strip())
        if len(msg) > 300:
            msg = msg[:110] + " ... " + msg[-185:]
        res = {"error": f"{type(exc).__name__}: {msg}"}
        if "x" in _LOG:  # the solver ran; the library failed after it
            res["error"] = (f"solver returned ({_LOG['solver_status']}, {_LOG['solver_iterations']} it, x "
                            f"{'finite' if np.isfinite(_LOG['x']).all() else 'not finite'}), then the library "
                            f"raised {res['error']}")
    Path(out_path).write_text(json.dumps(res))


def run_isolated(spec: dict, timeout: float) -> dict:
    """Run one identification in a fresh process: ``spec`` = {data: measurements file, start: factor on p*,
    solver, hessian, solver_options, problem: {method: direct | adapted | indirect, instants | horizon,
    transcription, residue}}. The result, or {killed} after ``timeout`` s, or {crashed, tail of the output}."""
    with tempfile.TemporaryDirectory() as tmp:
        spec_p, out_p = Path(tmp) / "spec.json", Path(tmp) / "out.json"
        spec_p.write_text(json.dumps(spec))
        t0 = time.perf_counter()
        try:
            proc = subprocess.run([sys.executable, str(Path(__file__).resolve()), str(spec_p), str(out_p)], cwd=tmp,
                                  capture_output=True, text=True, errors="replace", timeout=timeout)
            rc, tail = proc.returncode, (proc.stderr or "")[-1500:] + (proc.stdout or "")[-500:]
        except subprocess.TimeoutExpired:
            rc, tail = None, ""
        wall = time.perf_counter() - t0
        res = json.loads(out_p.read_text()) if out_p.exists() else None
    if rc is None:
        res = {"killed": True, "status": f"killed at the cap ({timeout:g} s of wall time)"}
    elif res is None:
        last = [ln for ln in tail.splitlines() if ln.strip()]
        res = {"crashed": True, "status": f"crashed ({f'signal {-rc}' if rc < 0 else f'exit status {rc}'})",
               "tail": " / ".join(last[-3:])[-400:]}
    return {"success": False, **res, "process_s": wall}


if __name__ == "__main__":
    child_main(sys.argv[1], sys.argv[2])
