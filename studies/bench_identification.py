"""Benchmark: what does an identification cost the first time (cold cache), every later time, and in
simulations of the same scene (measured side by side, with callgrind's instruction counts)?
Run: ``python studies/bench_identification.py [--quick]`` (about 90 min with callgrind, 15 without valgrind);
``python studies/bench_identification.py --against-simulation``: the table "Identification against simulation"
alone (a few minutes, no instruction counts), rewritten in place in docs/tables/bench_identification.md.
Data, cases and what is timed: docs/studies/bench_identification.md.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
from _bench_fit import (
    AS_BEFORE,
    CALLGRIND,
    count_worker,
    expand_rows,
    instructions,
    mesh_rows,
    scene_rows,
    twobar_side_by_side,
)
from _shared import cold_and_cached, exudyn_recording
from _study import ROOT, Banner, assert_checks, checks, cli, png, table, write_outputs

from casflex.identification import Shooting, Solver, Uncertainty

NOISE, SEED, START = 5e-4, 0, 0.8
CASES = {  # name: (method, horizon (s), options); the default fit with and without its model-error refit, ...
    **{f"default{' without model-error refit' * bool(o)}, {h:g} s": ("indirect", h, o)
       for o in ({}, {"uncertainty": Uncertainty(model_error="none")}) for h in (0.69, 3.0)},
    **{f"IPOPT {tr} shooting (compiled NLP), 0.69 s": (  # ... the seed paper's NLP transcriptions, ...
        "indirect", 0.69, {"solver": Solver("ipopt", compiled=True), "shooting": Shooting(f"{tr}-shooting")})
       for tr in ("single", "multiple")},
    # ... the direct method
    "direct, simulated set, t = 0.69 s (compiled)": ("direct", 0.69, {"solver": Solver(compiled=True)}),
}
QUICK = ("default without model-error refit, 0.69 s", "direct, simulated set, t = 0.69 s (compiled)")


def worker(case: str) -> dict:
    """One identification in this (fresh) process: its recorded times and result."""
    import casflex
    from casflex.identification import Experiment, ModelRun, identify_direct, identify_indirect
    from casflex.simulate import simulated_set

    method, horizon, opts = CASES[case]
    model = casflex.assemble(casflex.load_scene("twobar"))
    if method == "direct":
        r = identify_direct(model, simulated_set(model, 1.0), [horizon], start=START, **opts)
    else:
        data = exudyn_recording("twobar_exudyn", ("x3", "y3", "x5", "y5"), 0.0, horizon, NOISE, SEED)
        r = identify_indirect(model, Experiment(data, noise=NOISE), start=START, run=ModelRun(dt=1e-3), **opts)
    err, kt = np.abs(r.p / model.p_nominal - 1), np.array([n.startswith("kt") for n in model.parameter_names])
    return {"build_s": r.wall_build_s, "solve_s": r.wall_solve_s, "iterations": r.iterations,
            "success": bool(r.success), "k_err": float(err[~kt].max()), "kt_err": float(err[kt].max())}


def _cold_warm(rows: list) -> tuple[list[str], list[tuple], bytes]:
    """The first part's table, checks and figure from (case, cold, warm) records."""
    from casflex.plotting._figure import _new_figure

    ms = [(c["build_s"] + c["solve_s"]) for case, c, _ in rows if "multiple" in case]
    checks_ = [(f"{case}: the cache changes neither the outcome nor the k error", f"{w['k_err'] - c['k_err']:.0e}",
                w["success"] == c["success"] and abs(w["k_err"] - c["k_err"]) <= 1e-12) for case, c, w in rows]
    checks_ += [("multiple shooting's compiled NLP builds and solves in under 30 s in a first process",
                 f"{t:.1f} s", t < 30.0) for t in ms]
    ax, y = _new_figure((9, 1.2 + 0.6 * len(rows))).subplots(), np.arange(len(rows))
    for which, dy, label in ((1, -0.2, "first process (code generation, gcc)"), (2, 0.2, "later process")):
        ax.barh(y + dy, [r[which]["build_s"] + r[which]["solve_s"] for r in rows], 0.4, label=label)
    ax.set_yticks(y, [r[0] for r in rows], fontsize="small")
    ax.invert_yaxis()  # the table's order, top down
    ax.set(xscale="log", xlabel="build + solve wall time (s)", title="twobar identification: first and later runs")
    ax.legend(fontsize="small")
    ax.grid(True, axis="x", which="both", alpha=0.3)
    lines = table(["case", "first process: build + solve (s)", "later process: build (s)", "later: solve (s)",
                   "later: total (s)", "iterations", "k error", "kt error", "success"],
                  [[case, f"{c['build_s'] + c['solve_s']:.1f}", f"{w['build_s']:.2f}", f"**{w['solve_s']:.2f}**",
                    f"{w['build_s'] + w['solve_s']:.2f}", w["iterations"], f"{w['k_err']:.1e}", f"{w['kt_err']:.1e}",
                    w["success"]] for case, c, w in rows], "lrrrrrrrl")
    return lines, checks_, png(ax.figure)


def _side_by_side(tb: dict, counts: dict) -> tuple[list[str], list[tuple]]:
    """The second part: twobar's operations in simulations, instructions, and the estimates against the reference."""
    ref = tb["reference"]
    rows, checks_, sim_ins = [], [], counts.get("simulation, 3 s")
    for case in [*(k for k in tb if k not in ("simulation_s", "simulation_cpu_s", "reference")), "reference"]:
        r = tb[case]
        ins = counts.get(case)
        rows.append([case if case != "reference" else "reference: every stage to the full tolerance",
                     f"{1e3 * r['wall_s']:.1f}", f"{r['sims']:.1f}", f"{1e3 * r['cpu_s']:.1f}",
                     f"**{r['sims_cpu']:.1f}**", r.get("runs", "-"),
                     "-" if ins is None else f"{ins / 1e9:.2f}",
                     "-" if ins is None or sim_ins is None else f"{ins / sim_ins:.1f}",
                     r.get("success", "-")])
        if "p" in r and case != "reference" and "uncertain" not in case:  # its SEs hold the priors
            dp = max(abs(a - b) / s for a, b, s in zip(r["p"], ref["p"], ref["se_noise"], strict=True))
            ds = max(abs(a - b) / s for a, b, s in zip(r["se_noise"], ref["se_noise"], ref["se_noise"], strict=True))
            checks_.append((f"{case}: the estimates and noise SEs of the reference, to 1/100 of an SE",
                            f"{max(dp, ds):.1e} SE", max(dp, ds) <= 0.01))
    before = tb[AS_BEFORE]
    for case in ("default fit", "default fit without chord steps (exact refits)",
                 "default fit without continued stages"):
        r = tb[case]
        d = max(abs(a - b) / s for key in ("p", "se", "model_error")
                for a, b, s in zip(r[key], before[key], before["se_noise"], strict=True))
        checks_.append((f"{case}: the estimates, standard errors and model errors of the default fit as before "
                        "issue 49, to 1/100 of a noise SE, and the same form verdicts", f"{d:.1e} SE",
                        d <= 0.01 and r["verdicts"] == before["verdicts"] and r["success"] == before["success"]))
    for case, limit in (("default fit", 30), ("without model-error refit or form comparison", 30)):
        checks_.append((f"{case}: at most {limit} simulations' CPU time (issue 49)", f"{tb[case]['sims_cpu']:.1f}",
                        tb[case]["sims_cpu"] <= limit))
    u = tb["default fit, 4 uncertain properties"]["sims_cpu"]
    checks_ += [("default fit with 4 uncertain properties: at most 2 x the default fit's CPU time as issue 37 measured "
                 "it (before issue 49)", f"{u / before['sims_cpu']:.2f} x", u <= 2.0 * before["sims_cpu"]),
                ("default fit with 4 uncertain properties: at most 2 x today's default fit (its model with the "
                 "densities and moduli as parameters runs 2.5-3 x slower, with sensitivities in 8 directions or "
                 "without)", f"{u / tb['default fit']['sims_cpu']:.2f} x",
                 u <= 2.0 * tb["default fit"]["sims_cpu"], False)]
    lines = table(["twobar, 3 s (Exudyn's recording, 0.5 mm, from 0.8 x)", "wall (ms)", "in simulations (wall)",
                   "CPU (ms)", "in simulations (CPU)", "model runs", "instructions (1e9)",
                   "in simulations' instructions", "success"], rows, "lrrrrrrrl")
    return lines, checks_


def _savings(tb: dict) -> list[str]:
    """What each change of issue 49 saves, in simulations' time, from the rows measured side by side."""
    new, old = tb["default fit"]["sims_cpu"], tb[AS_BEFORE]["sims_cpu"]
    chord = tb["default fit without chord steps (exact refits)"]["sims_cpu"] - new
    cont = tb["default fit without continued stages"]["sims_cpu"] - new
    return [f"In CPU time (this process's; the wall time also waits for the host's other processes): "
            f"the default fit takes {new:.1f} simulations' time against {old:.1f} the way before issue 49 "
            f"({old / new:.2f} x less): the model-error refit and the alternative form's rejection by chord steps "
            f"on the fit's Jacobian (model runs without sensitivities) save {chord:.1f}, each growing-horizon "
            f"stage's first run carried on from the last stage's run saves {cont:.1f}."]


SECTION, NEXT = "## Identification against simulation (one process, side by side)", "### Against the mesh"


def _section(tb: dict, counts: dict, line: str = "") -> tuple[list[str], list[str]]:
    """The section "Identification against simulation": its table, the savings and its checks (``line``: the
    banner of a run of this section alone); and its failed asserted checks."""
    sbs, checks_ = _side_by_side(tb, counts)
    lines, failed = checks(checks_)
    return [SECTION, "", *([line, ""] if line else []), *sbs, "", *_savings(tb), "",
            *(ln.replace("## Self-checks", "Checks of this table:") for ln in lines), ""], failed


def against_simulation(out_dir: Path | None = None) -> dict:
    """The section "Identification against simulation" alone (no instruction counts), rewritten in place in the
    page of the full run; its checks asserted after the page is written."""
    page = Path(out_dir or ROOT / "docs") / "tables" / "bench_identification.md"
    text = page.read_text() if page.exists() else ""
    if SECTION not in text or NEXT not in text.split(SECTION, 1)[1]:
        raise SystemExit(f"{page}: no section {SECTION!r} to rewrite; run the whole benchmark first")
    banner = Banner("bench_identification", False)
    tb = twobar_side_by_side()
    line = banner.line().replace("bench_identification.py`", "bench_identification.py --against-simulation`", 1)
    section, failed = _section(tb, {}, f"{line} Instruction counts: the whole benchmark's only (valgrind).")
    head, rest = text.split(SECTION, 1)
    page.write_text(head + "\n".join(section) + "\n" + NEXT + rest.split(NEXT, 1)[1])
    assert_checks(failed)
    return tb


def _mesh(mesh: list[dict]) -> tuple[list[str], list[tuple], bytes]:
    from casflex.plotting._figure import _new_figure

    first = mesh[0]
    worst = max(r["fit_sims"] / first["fit_sims"] for r in mesh)
    checks_ = [("fit without refit, 1-8 elements per bar: its cost in simulations grows by at most 1.3 x "
                "(the mesh's own effect on the iterations and timing noise; measured 0.91-1.0 x)", f"{worst:.2f} x",
                worst <= 1.3)]
    ax = _new_figure((6, 4)).subplots()
    ne = [r["elements"] for r in mesh]
    for key, label in (("sim_s", "simulation, 3 s"), ("sens_s", "model run with sensitivities"),
                       ("fit_wall_s", "fit without model-error refit")):
        ax.loglog(ne, [r[key] for r in mesh], "o-", label=label)
    ax.set(xlabel="elements per bar", ylabel="wall time (s)", title="twobar: identification against simulation")
    ax.set_xticks(ne, [str(n) for n in ne])
    ax.legend(fontsize="small")
    ax.grid(True, which="both", alpha=0.3)
    lines = table(["elements per bar", "simulation (ms)", "model run with sensitivities (ms)", "in simulations",
                   "fit without refit (s)", "in simulations", "model runs"],
                  [[r["elements"], f"{1e3 * r['sim_s']:.1f}", f"{1e3 * r['sens_s']:.1f}", f"{r['sens_sims']:.1f}",
                    f"{r['fit_wall_s']:.2f}", f"**{r['fit_sims']:.1f}**", r["fit_runs"]] for r in mesh], "rrrrrrr")
    return lines, checks_, png(ax.figure)


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    banner = Banner("bench_identification", quick)
    rows = [(case, *cold_and_cached(__file__, ["--worker", case], ["--worker", case]))  # (case, cold, warm)
            for case in (QUICK if quick else CASES)]
    first, checks_, fig = _cold_warm(rows)
    figures, second, failed_section = {"bench_identification": fig}, [], []
    if not quick:
        tb, mesh, scenes, flat = twobar_side_by_side(), mesh_rows(), scene_rows(), expand_rows()
        counts = {case: instructions(__file__, case) for case in CALLGRIND}
        section, failed_section = _section(tb, {k: v for k, v in counts.items() if v is not None})
        mesh_lines, c3, figures["bench_identification_mesh"] = _mesh(mesh)
        checks_ += c3
        second = [*section, "",
                  NEXT, "", "![time against mesh](../figures/bench_identification_mesh.png)", "",
                  *mesh_lines, "", "Simulated steps at the expand threshold (250 compiled steps, per step):", "",
                  *table(["elements per bar", "code", "per step (us)", "build (s)"],
                         [[r["elements"], r["code"], f"{r['step_us']:.2f}", f"{r['build_s']:.1f}"] for r in flat],
                         "rlrr"), "", "### Other scenes (default fit)", "",
                  *table(["scene", "simulation (ms)", "default fit (s)", "in simulations", "model runs", "success"],
                         [[r["scene"], f"{1e3 * r['sim_s']:.1f}", f"{r['wall_s']:.2f}", f"**{r['sims']:.1f}**",
                           r["runs"], r["success"]] for r in scenes], "lrrrrl"), ""]
    lines, failed = checks(checks_)
    write_outputs("bench_identification", out_dir, quick, "\n".join([
        "# Identification benchmark: first and later runs, and against simulation", "",
        f"{banner.line()} Data, cases and what is timed: "
        "[studies/bench_identification.md](../studies/bench_identification.md).", "",
        f"![build + solve per case](../figures/bench_identification{'_quick' * quick}.png)", "",
        *first, "", *second, *lines]), figures)
    assert_checks(failed + failed_section)
    return {"rows": rows}


if __name__ == "__main__":
    if sys.argv[1:2] == ["--worker"]:  # hidden: one case in this fresh process, JSON on stdout
        print(json.dumps(worker(sys.argv[2])))
    elif sys.argv[1:2] == ["--count"]:  # hidden: callgrind's process (_bench_fit.instructions)
        count_worker(sys.argv[2], int(sys.argv[3]))
    elif sys.argv[1:2] == ["--against-simulation"]:  # the side-by-side section alone, rewritten in place
        against_simulation()
    else:
        cli(__doc__, main)
