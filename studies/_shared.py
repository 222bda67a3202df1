"""What several studies share beyond the harness (:mod:`_study`): to be hoisted there or into the
library. Not a study itself (no ``main``).

- :func:`paper_nlp`, :func:`capped_ipopt`: the seed paper's NLP formulation with a wall-time cap
  (table1, basins);
- :func:`exudyn_recording`: channels of an Exudyn reference recording at 100 Hz with noise
  (dampers, realdata, bench_identification);
- :func:`twobar`: the twobar model meshed into n elements per bar (bench_simulate, bench_exudyn, tradeoff,
  extremes);
- :func:`in_fresh_process`, :func:`cold_and_cached`: a study's hidden worker switch run in a new Python
  process (twice, sharing a new cache), its JSON answer (bench_simulate, bench_identification);
- :func:`fit_errors`: a fit's errors and z-scores against the truth (dampers, leg, realdata);
- :func:`honesty`: success, coverage and "dishonest" successes of repeated fits (dampers, leg,
  realdata).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[1] / "tests" / "data"


def paper_nlp(cap_s: float, transform: str = "linear") -> dict:
    """identify_indirect's ``solver``, ``run`` and ``uncertainty`` of the seed paper's NLP formulation, as table1 and
    basins were measured (IPOPT capped at ``cap_s`` s, :func:`capped_ipopt`; model Newton tolerance 1e-14; no
    model-error refit)."""
    from casflex.identification import ModelRun, Solver, Uncertainty

    return {"solver": Solver("ipopt", options=capped_ipopt(cap_s), transform=transform),
            "run": ModelRun(newton_tol=1e-14), "uncertainty": Uncertainty(model_error="none")}


def capped_ipopt(cap_s: float) -> dict:
    """identify_indirect's IPOPT options (tolerance 1e-8, see casflex/identification/shooting_nlp.py)
    with a wall-time cap: a stalled run would otherwise go on for IPOPT's 500 iterations."""
    from casflex.identification.problem import solver_options_for

    ip = dict(solver_options_for("ipopt", False, None, tol=1e-8)["ipopt"])
    ip["max_wall_time"] = float(cap_s)
    return {"ipopt": ip}


def exudyn_recording(file: str, names: tuple[str, ...], t_from: float, t_to: float, noise: float, seed: int):
    """The channels ``names`` of tests/data/<file>.npz (Exudyn's motion at 1 kHz) from t_from to t_to
    at 100 Hz, with Gaussian noise of std ``noise`` (m, rad) drawn from ``seed``."""
    from casflex.data import MeasurementSet

    z = np.load(DATA / f"{file}.npz")
    ch = [str(c) for c in z["channels"]]
    rows = np.arange(int(round(t_from * 1000)), int(round(t_to * 1000)) + 1, 10)
    q = z["q"][np.ix_(rows, [ch.index(c) for c in names])]
    return MeasurementSet(z["t"][rows], names, q + np.random.default_rng(seed).normal(0, noise, q.shape), None, None)


def twobar(elements: int, rotary: bool = False, inertia: str = "lagrange", e_scale: float = 1.0):
    """The twobar scene's model with ``elements`` beam elements per bar (and rotary inertia), the inertia
    form ``inertia``, the beams' Young's modulus times ``e_scale``."""
    import dataclasses

    import casflex

    scene = casflex.load_scene("twobar")
    return casflex.assemble(dataclasses.replace(scene, beams=tuple(
        dataclasses.replace(b, elements=elements, rotary_inertia=rotary, E=b.E * e_scale) for b in scene.beams)),
        inertia=inertia)


def in_fresh_process(script: str, args: list[str], env: dict, timeout: float = 3600) -> dict:
    """Run ``python <script> <args>`` in a new process; the JSON on its last line of output."""
    out = subprocess.run([sys.executable, script, *args], env=env, capture_output=True, text=True, check=True,
                         timeout=timeout)
    return json.loads(out.stdout.strip().splitlines()[-1])


def cold_and_cached(script: str, cold: list[str], cached: list[str], timeout: float = 3600,
                    env: dict | None = None, cache: str | None = None) -> tuple[dict, dict]:
    """``in_fresh_process`` twice with one new, empty ``CASFLEX_CACHE`` (and the variables ``env``): the first
    process builds every compiled function (cold), the second finds them on disk (cached). Their JSON answers.
    ``cache``: that directory instead of a new one (kept; cold as long as it holds nothing the first process builds,
    e.g. one cache for several meshes, each with its own libraries, which a later process then finds)."""
    with tempfile.TemporaryDirectory(prefix="casflex-bench-cache-") as new:
        env = dict(os.environ, **(env or {}), CASFLEX_CACHE=cache or new)
        return in_fresh_process(script, cold, env, timeout), in_fresh_process(script, cached, env, timeout)


def fit_errors(model, r) -> dict:
    """A fit ``r`` of ``model`` against the scene's nominal parameters (the truth): names, truth, standard
    errors, relative errors, z = (estimate - truth) / SE, success and message. z is 0 where the SE is
    infinite (it claims nothing) and infinite where an SE of 0 misses (it claims everything)."""
    se, err = np.array([r.std_errors[k] for k in model.parameter_names]), r.p - model.p_nominal
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(np.isinf(se) | (err == 0), 0.0, err / se)
    return {"names": list(model.parameter_names), "truth": model.p_nominal.tolist(), "se": se.tolist(),
            "rel_error": (err / model.p_nominal).tolist(), "z": z.tolist(), "se_finite": np.isfinite(se).tolist(),
            "success": bool(r.success), "message": r.message}


def honesty(recs: list[dict], finite: np.ndarray | None = None) -> dict:
    """Over fits (dicts with "z" (estimate - truth) / SE per parameter and "success"): the success
    rate, the coverage of the truth by the 2- and 3-SE intervals per parameter, and the "dishonest"
    successes (a parameter more than 3 SE from the truth). ``finite``: where the SE is finite (an
    infinite SE claims nothing and covers the truth)."""
    z = np.abs(np.array([r["z"] for r in recs], dtype=float))  # a resumed record spells inf 'inf' (strict JSON)
    ok = np.ones_like(z, dtype=bool) if finite is None else np.asarray(finite)
    succ = np.array([r["success"] for r in recs])
    return {"z": z, "success": succ, "cover2": (z <= 2) | ~ok, "cover3": (z <= 3) | ~ok,
            "dishonest": int(np.sum(succ & ((z > 3) & ok).any(axis=1)))}
