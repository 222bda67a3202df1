"""Benchmark: what does an identification cost the first time (cold cache), and every later time?
Run: ``python studies/bench_identification.py [--quick]`` (about 10 min); data, cases and what is timed:
docs/studies/bench_identification.md.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
from _shared import cold_and_cached, exudyn_recording
from _study import Banner, assert_checks, checks, cli, png, table, write_outputs

NOISE, SEED, START = 5e-4, 0, 0.8
CASES = {  # name: (method, horizon (s), options); the default fit with and without its model-error refit, ...
    **{f"default{' without model-error refit' * bool(o)}, {h:g} s": ("indirect", h, o)
       for o in ({}, {"model_error": "none"}) for h in (0.69, 3.0)},
    **{f"IPOPT {tr} shooting (compiled NLP), 0.69 s": (  # ... the seed paper's NLP transcriptions, ...
        "indirect", 0.69, {"solver": "ipopt", "compiled": True, "transcription": f"{tr}-shooting"})
       for tr in ("single", "multiple")},
    "direct, simulated set, t = 0.69 s (compiled)": ("direct", 0.69, {"compiled": True}),  # ... the direct method
}
QUICK = ("default without model-error refit, 0.69 s", "direct, simulated set, t = 0.69 s (compiled)")


def worker(case: str) -> dict:
    """One identification in this (fresh) process: its recorded times and result."""
    import casflex
    from casflex.data import simulated_set
    from casflex.identification import identify_direct, identify_indirect

    method, horizon, opts = CASES[case]
    model = casflex.assemble(casflex.load_scene("twobar"))
    if method == "direct":
        r = identify_direct(model, simulated_set(model, 1.0), [horizon], start=START, **opts)
    else:
        data = exudyn_recording("twobar_exudyn", ("x3", "y3", "x5", "y5"), 0.0, horizon, NOISE, SEED)
        r = identify_indirect(model, data, dt=1e-3, start=START, noise=NOISE, **opts)
    err, kt = np.abs(r.p / model.p_nominal - 1), np.array([n.startswith("kt") for n in model.parameter_names])
    return {"build_s": r.wall_build_s, "solve_s": r.wall_solve_s, "iterations": r.iterations,
            "success": bool(r.success), "k_err": float(err[~kt].max()), "kt_err": float(err[kt].max())}


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    from casflex.plotting._figure import _new_figure

    banner = Banner("bench_identification", quick)
    rows = [(case, *cold_and_cached(__file__, ["--worker", case], ["--worker", case]))  # (case, cold, warm)
            for case in (QUICK if quick else CASES)]
    lines, failed = checks([(f"{case}: the cache changes neither the outcome nor the k error",
                             f"{w['k_err'] - c['k_err']:.0e}", w["success"] == c["success"]
                             and abs(w["k_err"] - c["k_err"]) <= 1e-12) for case, c, w in rows])
    ax, y = _new_figure((9, 1.2 + 0.6 * len(rows))).subplots(), np.arange(len(rows))
    for which, dy, label in ((1, -0.2, "first process (code generation, gcc)"), (2, 0.2, "later process")):
        ax.barh(y + dy, [r[which]["build_s"] + r[which]["solve_s"] for r in rows], 0.4, label=label)
    ax.set_yticks(y, [r[0] for r in rows], fontsize="small")
    ax.invert_yaxis()  # the table's order, top down
    ax.set(xscale="log", xlabel="build + solve wall time (s)", title="twobar identification: first and later runs")
    ax.legend(fontsize="small")
    ax.grid(True, axis="x", which="both", alpha=0.3)
    write_outputs("bench_identification", out_dir, quick, "\n".join([
        "# Identification benchmark: first and later runs", "", f"{banner.line()} Data, cases and what is timed: "
        "[studies/bench_identification.md](../studies/bench_identification.md).", "",
        f"![build + solve per case](../figures/bench_identification{'_quick' * quick}.png)", "",
        *table(["case", "first process: build + solve (s)", "later process: build (s)", "later: solve (s)",
                "later: total (s)", "iterations", "k error", "kt error", "success"],
               [[case, f"{c['build_s'] + c['solve_s']:.1f}", f"{w['build_s']:.2f}", f"**{w['solve_s']:.2f}**",
                 f"{w['build_s'] + w['solve_s']:.2f}", w["iterations"], f"{w['k_err']:.1e}", f"{w['kt_err']:.1e}",
                 w["success"]] for case, c, w in rows], "lrrrrrrrl"), "", *lines]),
                  png(ax.figure))
    assert_checks(failed)
    return {"rows": rows}


if __name__ == "__main__":
    if sys.argv[1:2] == ["--worker"]:  # hidden: one case in this fresh process, JSON on stdout
        print(json.dumps(worker(sys.argv[2])))
    else:
        cli(__doc__, main)
