"""Benchmark: what an identification costs the first time and every later time.

Twobar measured by Exudyn (tests/data/twobar_exudyn.npz: 8 ANCF elements per bar), the paper's
channels x, y of nodes 3 and 5 at 100 Hz with 0.5 mm of noise, from rest, start 0.8 x p*. Each case
runs in two fresh processes that share a new, empty cache directory: the first builds every
compiled function (cold), the second finds them on disk (cached). Reported per process: the
identification's build and solve times as it records them (``wall_build_s``, ``wall_solve_s``; a
compile happens inside whichever phase first needs the function) and their sum.

Cases: the default output-error fit (Gauss-Newton single shooting on compiled forward sensitivities)
with and without its model-error refit (the same fit on a refined model), over 0.69 s (the paper's
horizon) and 3 s; the seed paper's NLP transcriptions with IPOPT and compiled functions (single
and multiple shooting, 0.69 s); the direct method on the simulated set (compiled residual).

Writes docs/tables/bench_identification.md and docs/figures/bench_identification.png.
Run: ``python studies/bench_identification.py`` (about 10 min; ``--quick``: two short cases).
"""

from __future__ import annotations

import argparse
import io
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from casflex.results import atomic_write_bytes, atomic_write_text

ROOT = Path(__file__).resolve().parents[1]
NOISE, SEED, START = 5e-4, 0, 0.8
CASES = {  # name: (method, horizon (s), options)
    "default, 0.69 s": ("indirect", 0.69, {}),
    "default, 3 s": ("indirect", 3.0, {}),
    "default without model-error refit, 0.69 s": ("indirect", 0.69, {"model_error": "none"}),
    "default without model-error refit, 3 s": ("indirect", 3.0, {"model_error": "none"}),
    "IPOPT single shooting (compiled NLP), 0.69 s": ("indirect", 0.69, {"transcription": "single-shooting",
                                                                         "solver": "ipopt", "compiled": True}),
    "IPOPT multiple shooting (compiled NLP), 0.69 s": ("indirect", 0.69, {"transcription": "multiple-shooting",
                                                                           "solver": "ipopt", "compiled": True}),
    "direct, simulated set, t = 0.69 s (compiled)": ("direct", 0.69, {"compiled": True}),
}
QUICK = ("default without model-error refit, 0.69 s", "direct, simulated set, t = 0.69 s (compiled)")


def _recording(t_end: float):
    from casflex.data import MeasurementSet

    z = np.load(ROOT / "tests" / "data" / "twobar_exudyn.npz")
    names = ("x3", "y3", "x5", "y5")
    cols = [[str(c) for c in z["channels"]].index(c) for c in names]
    rows = np.arange(0, int(round(t_end * 1000)) + 1, 10)  # 100 Hz from the 1 kHz recording
    q = z["q"][np.ix_(rows, cols)]
    return MeasurementSet(z["t"][rows], names, q + np.random.default_rng(SEED).normal(0, NOISE, q.shape), None, None)


def _worker(case: str) -> dict:
    """One identification in this (fresh) process: its recorded times, result and the process's."""
    t0 = time.perf_counter()
    import casflex
    from casflex.identification import identify_direct, identify_indirect

    method, horizon, opts = CASES[case]
    model = casflex.assemble(casflex.load_scene("twobar"))
    if method == "direct":
        from casflex.data import simulated_set

        r = identify_direct(model, simulated_set(model, 1.0), [horizon], start=START, **opts)
    else:
        r = identify_indirect(model, _recording(horizon), dt=1e-3, start=START, noise=NOISE, **opts)
    err = np.abs(r.p / model.p_nominal - 1)
    names = model.parameter_names
    return {"build_s": r.wall_build_s, "solve_s": r.wall_solve_s, "process_s": time.perf_counter() - t0,
            "iterations": r.iterations, "success": bool(r.success),
            "k_err": float(max(err[i] for i, n in enumerate(names) if n.startswith("k") and not n.startswith("kt"))),
            "kt_err": float(max(err[i] for i, n in enumerate(names) if n.startswith("kt")))}


def _run(case: str, env: dict) -> dict:
    out = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--worker", case], env=env, text=True,
                         capture_output=True, timeout=3600, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    out_dir = ROOT / "docs" if out_dir is None else Path(out_dir)
    print("=" * 78)
    print("bench_identification: cold and cached builds, solve times, twobar from Exudyn's recording")
    print("=" * 78, flush=True)
    rows = []
    for case in QUICK if quick else CASES:
        with tempfile.TemporaryDirectory(prefix="casflex-bench-cache-") as cache:
            env = dict(os.environ, CASFLEX_CACHE=cache)
            cold, warm = _run(case, env), _run(case, env)
        rows.append({"case": case, "cold": cold, "warm": warm})
        print(f"{case:<48s} cold {cold['build_s'] + cold['solve_s']:7.1f} s, cached: build {warm['build_s']:5.2f} s "
              f"+ solve {warm['solve_s']:6.2f} s ({warm['iterations']} it.), k {warm['k_err']:.1e}, kt "
              f"{warm['kt_err']:.1e}, success {warm['success']}", flush=True)
    suffix = "_quick" if quick else ""
    print("wrote", atomic_write_text(out_dir / "tables" / f"bench_identification{suffix}.md", _page(rows, quick)))
    print("wrote", atomic_write_bytes(out_dir / "figures" / f"bench_identification{suffix}.png", _figure(rows)))
    # self-checks: the second process compiles nothing (its build is at most a few seconds of set-up), and
    # the answers do not depend on the cache
    for r in rows:
        assert r["warm"]["success"] == r["cold"]["success"], f"{r['case']}: the cache changed the outcome"
        assert abs(r["warm"]["k_err"] - r["cold"]["k_err"]) <= 1e-12, f"{r['case']}: the cache changed the answer"
    return {"rows": rows}


def _page(rows: list[dict], quick: bool) -> str:
    L = ["# Identification benchmark: first and later runs", "",
         f"Generated by `python studies/bench_identification.py{' --quick' if quick else ''}` on "
         f"{platform.machine()} ({os.cpu_count()} CPUs, Python {platform.python_version()}); load average at the end "
         f"{os.getloadavg()[0]:.2f}. Data, cases and what is timed: the script's docstring. Errors are the largest "
         "relative error of the spring stiffnesses k and of the torsion stiffnesses kt (truth: Exudyn's parameters, "
         "the scene's nominal values).", "",
         "| case | first process: build + solve (s) | later process: build (s) | later: solve (s) | later: total (s) "
         "| iterations | k error | kt error | success |", "|---|---:|---:|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        c, w = r["cold"], r["warm"]
        L.append(f"| {r['case']} | {c['build_s'] + c['solve_s']:.1f} | {w['build_s']:.2f} | **{w['solve_s']:.2f}** | "
                 f"{w['build_s'] + w['solve_s']:.2f} | {w['iterations']} | {w['k_err']:.1e} | {w['kt_err']:.1e} | "
                 f"{w['success']} |")
    L += ["", "The first process pays for code generation and gcc once; every later process, on this machine or "
          "any sharing `CASFLEX_CACHE`, loads the compiled functions from disk (`casflex cache` lists them).", ""]
    return "\n".join(L)


def _figure(rows: list[dict]) -> bytes:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 4.5))
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    x = np.arange(len(rows))
    ax.bar(x - 0.2, [r["cold"]["build_s"] + r["cold"]["solve_s"] for r in rows], 0.4, label="first process")
    ax.bar(x + 0.2, [r["warm"]["build_s"] + r["warm"]["solve_s"] for r in rows], 0.4, label="later process")
    ax.set_xticks(x, [r["case"].replace(", ", ",\n", 1) for r in rows], fontsize=7)
    ax.set_yscale("log")
    ax.set_ylabel("build + solve (s)")
    ax.legend()
    ax.grid(True, axis="y", which="both", alpha=0.3)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return buf.getvalue()


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out-dir", type=Path)
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.worker:
        print(json.dumps(_worker(a.worker)))
    else:
        main(quick=a.quick, out_dir=a.out_dir)
