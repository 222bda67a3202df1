"""Benchmark: what does a twobar simulation cost as the mesh grows, how accurate is it per step, and what does
modified Newton save? Run: ``python studies/bench_simulate.py [--quick]`` (about 5 min); set-up and how to read
the page: docs/studies/bench_simulate.md.
"""

from __future__ import annotations

import json
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _callgrind import instructions
from _shared import cold_and_cached, in_fresh_process, twobar
from _study import Banner, assert_checks, best_of, checks, cli, paths_check, png, table, write_outputs

from casflex.simulate import Stepping, simulate

#: the environment of the runs built for this processor instead of the generic target (casflex.codegen)
NATIVE = {"CASFLEX_CFLAGS": "-march=native"}
#: rounds of the interleaved timing of the meshes (each mesh's CPU time per step: the best of the rounds, as the
#: other agents' load only adds to it; the median and the spread beside it)
ROUNDS = 11
TABLES = (  # the page's tables: (title, {column: format over a row's numbers})
    ("Cost against the mesh ({t_end:g} s, dt = 1e-3, compiled)",
     {"el./bar": "{elements}", "dofs": "{dofs}", "cold build (s)": "{cold_build_s:.1f}",
      "cached build (s)": "{build_s:.2f}", "library (kB)": "{code_kb}", "simulate (ms)": "{simulate_ms:.1f}",
      "integration (ms)": "{run_ms:.1f}", "per step, CPU (us)": "{per_step_us:.1f}",
      "CPU, median (us)": "{cpu_median_us:.1f}", "CPU spread (%)": "{cpu_spread:.0f}",
      "per step, wall (us)": "{wall_step_us:.1f}",
      "per step and dof (ns)": "{per_dof_ns:.0f}", "instructions / step (k)": "{kinstr:.1f}",
      "bandwidth": "{bandwidth}",
      "Newton updates / step": "{updates:.2f}", "per step, -march=native (us)": "{native_per_step_us:.1f}",
      "default / native": "{native_gain:.2f}",
      "peak memory (MB)": "{peak_mb:.0f}"}),
    ("Accuracy and the two paths (1 element per bar; error against a dt = {dt_ref:g} s reference)",
     {"dt (s)": "{dt:.0e}", "steps": "{steps}", "interpreted (ms)": "{interpreted_ms:.1f}",
      "compiled (ms)": "{compiled_ms:.2f}", "compiled, integration only (ms)": "{compiled_run_ms:.2f}",
      "speed-up": "{speedup:.1f}", "Newton it./step": "{newton_per_step:.2f}",
      "error node 5 (m)": "{err_node5_m:.3e}", "max abs interp - compiled": "{max_diff_paths:.1e}"}),
    ("Exact and modified Newton ({kinds_t:g} s, compiled)",
     {"el./bar": "{elements}", "dt (s)": "{dt:g}", "exact (ms)": "{exact_ms:.1f}", "modified (ms)": "{modified_ms:.1f}",
      "modified / exact": "{ratio:.2f}", "steps that refresh the Jacobian": "{refresh:.0f} %",
      "node 5 from the exact Newton's (m)": "{deviation_m:.1e}"}))


def mesh_worker(elements: int, t_end: float, repeat: int) -> dict:
    """In a fresh process: build (or load) the compiled step, then time simulate() (JSON on stdout)."""
    from casflex.simulate import CHUNK, compiled_library, initial_state, integrator_for

    t0 = time.perf_counter()
    model = twobar(elements)
    integ = integrator_for(model, alpha=0.0)
    lib = compiled_library(integ)
    build_s = time.perf_counter() - t0
    t_sim, tr = best_of(lambda: simulate(model, t_end,
                                         stepping=Stepping(dt=1e-3, compiled=True)), repeat, enough=float("inf"))
    counted = simulate(model, min(t_end, 0.2), stepping=Stepping(dt=1e-3))  # interpreted: Newton updates counted
    p, n = model.params(None), model.n_dof
    x0 = initial_state(integ, p)
    d = np.array(integ.scale(x0[:n], x0[n:2 * n], p, 1e-3)).ravel()
    count = instructions(lib.path, f"hht_trajectory_{CHUNK}", [x0, np.zeros(1), p, np.array([1e-3]), d])
    return {"elements": elements, "dofs": model.n_dof, "build_s": build_s, "cached": lib.cached,
            "bandwidth": integ.bandwidth, "kinstr": np.nan if count is None else count / CHUNK / 1e3,
            "updates": counted.stats["newton_iterations"] / counted.stats["steps"],
            "simulate_ms": 1e3 * t_sim, "run_ms": 1e3 * tr.stats["run_s"], "steps": tr.stats["steps"],
            "code_kb": lib.path.stat().st_size // 1024, "y5": float(tr.dof("y5")[-1]),
            "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def timing_worker(meshes: list[int], t_end: float, rounds: int) -> dict:
    """In a fresh process: ``rounds`` rounds that each run every mesh's compiled simulation once, interleaved (the
    order reversed every other round), so that a change of the machine's load or clock reaches every mesh alike;
    per mesh and round the integration's wall and CPU time per step (s). The libraries are loaded (or built) and
    warmed up first, untimed."""
    models = {ne: twobar(ne) for ne in meshes}
    for m in models.values():
        simulate(m, 0.05, stepping=Stepping(dt=1e-3, compiled=True))
    wall, cpu = {ne: [] for ne in meshes}, {ne: [] for ne in meshes}
    for r in range(rounds):
        for ne in meshes if r % 2 == 0 else meshes[::-1]:
            st = simulate(models[ne], t_end, stepping=Stepping(dt=1e-3, compiled=True)).stats
            wall[ne].append(st["run_s"] / st["steps"])
            cpu[ne].append(st["run_cpu_s"] / st["steps"])
    return {"wall": {str(k): v for k, v in wall.items()}, "cpu": {str(k): v for k, v in cpu.items()}}


def interleaved(meshes: list[int], t_end: float, rounds: int, cache: str | None = None) -> dict:
    """:func:`timing_worker` in a fresh process (``cache``: the ``CASFLEX_CACHE`` that holds the libraries; a new
    one by default, where the worker builds them first). Per mesh: the median, best and spread (max - min over
    the median, %) of the rounds' wall and CPU time per step (us); per round the growth exponents of the CPU time
    against the dofs and the elements (``spread_fits``)."""
    with tempfile.TemporaryDirectory(prefix="casflex-bench-cache-") as new:
        env = dict(os.environ, CASFLEX_CACHE=cache or new)
        raw = in_fresh_process(__file__, ["--timing-worker", ",".join(map(str, meshes)), repr(t_end), str(rounds)],
                               env, timeout=3600)
    out = {}
    for ne in meshes:
        w, c = 1e6 * np.array(raw["wall"][str(ne)]), 1e6 * np.array(raw["cpu"][str(ne)])
        out[ne] = {"wall_us": float(np.median(w)), "cpu_us": float(np.median(c)), "cpu_best_us": float(c.min()),
                   "cpu_spread": 100 * float(np.ptp(c) / np.median(c)),
                   "wall_spread": 100 * float(np.ptp(w) / np.median(w)),
                   "cpu_rounds": c.tolist()}
    return out


def spread_fits(meshes: list[int], dofs: list[int], times: dict) -> dict:
    """The growth exponent of the CPU time per step against the dofs and the elements fitted in each round
    (least-squares line through the log-log points): their median and range, a spread the machine's noise gives;
    and the exponent of the best of the even and of the odd rounds (``halves``): how far the best's moves."""
    per_round = np.array([times[ne]["cpu_rounds"] for ne in meshes])  # (meshes, rounds)
    k_dofs = [slope(dofs, per_round[:, r]) for r in range(per_round.shape[1])]
    k_el = [slope(meshes, per_round[:, r]) for r in range(per_round.shape[1])]
    halves = [slope(dofs, per_round[:, h::2].min(axis=1)) for h in (0, 1)]  # the best of each half of the rounds
    return {"dofs_median": float(np.median(k_dofs)), "dofs_min": min(k_dofs), "dofs_max": max(k_dofs),
            "el_median": float(np.median(k_el)), "el_min": min(k_el), "el_max": max(k_el), "rounds": len(k_dofs),
            "halves": halves}


#: the parts of a step (breakdown): the first pattern a CasADi Function's name matches (re.search) names its part
PARTS = (("map loops (a call per element)", r"^map\d+_"), ("kernels, tangent (r and K)", r"_padded"),
         ("kernels, residual", r"_hht_a\d+_\w+_r(_|$)"), ("libm (atan2, sincos)", r"^ext:(__)?(atan2|sincos|ieee754)"),
         ("flat: kernels + band assembly", r"^hht_jacobian$"), ("flat: residual", r"^hht_residual_all$"),
         ("band LU", r"band_"), ("update: band assembly, state passes", r"^hht_update_step$"),
         ("step end (residual's sums, state, test)", r"^hht_finish_band$"), ("copies, clears", r"casadi_(copy|clear)$"),
         ("step and chunk (Function boundaries)", r"^hht_(step|steps|trajectory|done|converge)"))


def breakdown(elements: int) -> dict[str, float]:
    """Instructions per step of the compiled 250-step chunk (twobar, ``elements`` per bar, dt = 1e-3) per part of
    the step (:data:`PARTS`; the rest as "other"), from callgrind on the library's C built with -g
    (``_callgrind.per_function``)."""
    import re

    from _callgrind import per_function

    from casflex.codegen import build_flags, generate_c
    from casflex.simulate import CHUNK, initial_state, integrator_for
    from casflex.simulate.run import _library_functions

    model = twobar(elements)
    integ = integrator_for(model, alpha=0.0)
    p, n = model.params(None), model.n_dof
    x0 = initial_state(integ, p)
    d = np.array(integ.scale(x0[:n], x0[n:2 * n], p, 1e-3)).ravel()
    with tempfile.TemporaryDirectory(prefix="casflex-bd-") as tmp:
        c_file, _ = generate_c(_library_functions(integ), tmp, "lib")
        per = per_function(c_file, f"hht_trajectory_{CHUNK}", [x0, np.zeros(1), p, np.array([1e-3]), d],
                           build_flags("-O3"))
    out: dict[str, float] = {}
    for name, count in (per or {}).items():
        part = next((label for label, pattern in PARTS if re.search(pattern, name)), "other")
        out[part] = out.get(part, 0.0) + count / CHUNK
    return out


def slope(x, y) -> float:  # of the least-squares line through the log-log points
    return float(np.polyfit(np.log(x), np.log(y), 1)[0])


def growth(rows: list[dict], key: str = "per_step_us") -> dict:
    """How the per step cost t (us) grows with the dofs n: the log-log slope (t = b n^k, no constant), the
    slope with a constant (t = a + b n^k, least squares in log t over a grid of k), the straight line
    t = a + b n (b: the marginal cost of a dof) and the slope over the last three meshes."""
    n, t = np.array([r["dofs"] for r in rows], float), np.array([r[key] for r in rows])

    def with_constant(k: float) -> tuple[float, float, float]:  # (misfit, a, b) of t = a + b n^k
        A = np.stack([np.ones_like(n), n**k], axis=1)
        (a, b), *_ = np.linalg.lstsq(A / t[:, None], np.ones_like(t), rcond=None)  # relative residuals
        fit = a + b * n**k
        return (float(np.sum(np.log(np.maximum(fit, 1e-12) / t) ** 2)) if (fit > 0).all() else np.inf), a, b

    ks = np.arange(0.5, 2.001, 0.005)
    k1 = float(ks[np.argmin([with_constant(k)[0] for k in ks])])
    b_lin, a_lin = np.polyfit(n, t, 1)
    return {"elements": slope([r["elements"] for r in rows], t), "dofs": slope(n, t), "dofs_const": k1,
            "const_us": with_constant(k1)[1], "line_a_us": float(a_lin), "line_b_ns": 1e3 * float(b_lin),
            "dofs_tail": slope(n[-3:], t[-3:]) if len(n) >= 3 else float("nan")}


def figure(scale: list[dict], acc: list[dict]) -> bytes:
    """Cost against the mesh; both paths' time and node 5's error against dt (1 element per bar)."""
    from casflex.plotting._figure import _new_figure

    fig = _new_figure((12, 4))
    dofs, d = [r["dofs"] for r in scale], [r["dt"] for r in acc]
    panels = (  # x, rows, [(key, factor, label)], x label, y label, title
        (dofs, scale, [("per_step_us", 1, "per step (us)"), ("cold_build_s", 1e3, "cold build (ms)"),
                       ("peak_mb", 1, "peak memory (MB)")], f"dofs ({scale[0]['elements']} ... "
         f"{scale[-1]['elements']} elements per bar)", "", "cost against the mesh (compiled)"),
        (d, acc, [("interpreted_ms", 1e-3, "interpreted"), ("compiled_ms", 1e-3, "compiled C")], "dt (s)",
         "wall time of simulate() (s)", "the two paths"),
        (d, acc, [("err_node5_m", 1, "against a dt 10x below the smallest")], "dt (s)", "max error of node 5 (m)",
         "accuracy (HHT-alpha, order 2)"))
    for ax, (x, rows, series, xlabel, ylabel, title) in zip(fig.subplots(1, 3), panels, strict=True):
        for (key, f, label), mark in zip(series, "os^", strict=False):
            ax.loglog(x, [r[key] * f for r in rows], mark + "-", label=label)
        ax.set(xlabel=xlabel, ylabel=ylabel, title=title)
        ax.legend()
        ax.grid(True, which="both", alpha=0.3)
    fig.axes[0].set_xticks(dofs, [str(n) for n in dofs])
    fig.axes[0].tick_params(axis="x", which="minor", labelbottom=False)  # the dofs themselves are the ticks
    return png(fig)


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    banner = Banner("bench_simulate", quick)
    t_end, kinds_t, scale = 0.3 if quick else 3.0, 0.2 if quick else 1.0, []
    meshes = [1, 2] if quick else [1, 2, 4, 8, 16, 32]
    with tempfile.TemporaryDirectory(prefix="casflex-bench-cache-") as shared:  # the default builds of every mesh
        for ne in meshes:  # a cold build, then a cached one and the timed runs
            cold, warm = cold_and_cached(__file__, *(["--mesh-worker", str(ne), repr(t_end), str(n)]
                                                     for n in (1, 2 if quick else 7)), timeout=1800, cache=shared)
            # the same, built for this processor (CASFLEX_CFLAGS=-march=native): the speed the default's
            # bitwise promise costs, measured right after it
            _, native = cold_and_cached(__file__, *(["--mesh-worker", str(ne), repr(t_end), str(n)]
                                                    for n in (1, 2 if quick else 7)), timeout=1800, env=NATIVE)
            scale.append({**warm, "cold_build_s": cold["build_s"], "cold_cached": cold["cached"],
                          "native_per_step_us": 1e3 * native["run_ms"] / native["steps"],
                          "native_gain": warm["run_ms"] / native["run_ms"]})
        # the per-step cost: every mesh's run interleaved in one process, ROUNDS times (CPU time: the best, the median)
        times = interleaved(meshes, t_end, 3 if quick else ROUNDS, shared)
    for r in scale:
        t = times[r["elements"]]
        r.update(per_step_us=t["cpu_best_us"], cpu_median_us=t["cpu_us"], wall_step_us=t["wall_us"],
                 cpu_spread=t["cpu_spread"], wall_spread=t["wall_spread"],
                 per_dof_ns=1e3 * t["cpu_best_us"] / r["dofs"])
    spread = spread_fits(meshes, [r["dofs"] for r in scale], times)
    expo = growth(scale)
    counted = all(np.isfinite(r["kinstr"]) for r in scale)
    expo_i = growth(scale, "kinstr") if counted else None
    # per dt, 1 element per bar: both paths; node 5's error against a dt 10x below the smallest (coarsest grid)
    acc_t, dts, acc = 0.5 if quick else 3.0, [1e-2, 5e-3, 2e-3, 1e-3] + ([] if quick else [5e-4, 2e-4, 1e-4]), []
    model, grid, fine = twobar(1), np.arange(0, acc_t + 1e-12, dts[0]), dts[-1] / 10
    ref = simulate(model, acc_t,
                   stepping=Stepping(dt=fine, alpha=0.0, compiled=True)).q[np.round(grid / fine).astype(int)][:, 12:14]
    for dt in dts:
        t_c, tc = best_of(lambda dt=dt: simulate(model, acc_t,
                                                 stepping=Stepping(dt=dt, alpha=0.0, compiled=True)), 5, float("inf"))
        t_i, ti = best_of(lambda dt=dt: simulate(model, acc_t, stepping=Stepping(dt=dt, alpha=0.0)),
                          1 if dt < 1e-3 else 2, float("inf"))
        err = np.linalg.norm(ti.q[np.round(grid / dt).astype(int)][:, 12:14] - ref, axis=1).max()
        acc.append({"dt": dt, "steps": ti.stats["steps"], "interpreted_ms": 1e3 * t_i, "compiled_ms": 1e3 * t_c,
                    "speedup": t_i / t_c, "compiled_run_ms": 1e3 * tc.stats["run_s"], "err_node5_m": float(err),
                    "newton_per_step": ti.stats["newton_iterations"] / ti.stats["steps"],
                    "max_diff_paths": float(np.abs(tc.q - ti.q).max())})
    fit = [r for r in acc if r["dt"] <= 2e-3]  # the asymptotic range: coarser steps are pre-asymptotic here
    order = slope([r["dt"] for r in fit], [r["err_node5_m"] for r in fit])
    kinds = []  # exact and modified Newton side by side, compiled, per mesh and step
    for ne in (1,) if quick else (1, 8, 32):
        model = twobar(ne)
        for dt in (1e-3,) if quick else (1e-3, 2e-4):
            t, tr = {}, {}
            for kind in ("exact", "modified"):
                simulate(model, kinds_t, stepping=Stepping(dt=dt, newton=kind, compiled=True))  # build, not timed
                t[kind], tr[kind] = best_of(lambda k=kind, m=model, dt=dt: simulate(
                    m, kinds_t, stepping=Stepping(dt=dt, newton=k, compiled=True)), 3, float("inf"))
            kinds.append({"elements": ne, "dt": dt, "exact_ms": 1e3 * t["exact"], "modified_ms": 1e3 * t["modified"],
                          "ratio": t["modified"] / t["exact"],
                          "refresh": 100 * tr["modified"].stats["jacobian_refreshes"] / tr["modified"].stats["steps"],
                          "deviation_m": float(np.abs(tr["modified"].q - tr["exact"].q).max())})
    y5 = np.ptp([r["y5"] for r in scale])  # the mesh error of 1 element per bar is 6e-5 m
    lines, failed = checks([
        ("the first process builds the library, the second loads it", "every mesh",
         not any(r["cold_cached"] for r in scale) and all(r["cached"] for r in scale)),
        paths_check(max(r["max_diff_paths"] for r in acc), "on q, every step size"),
        ("HHT-alpha's convergence order over dt <= 2e-3 is 2 (1.8 .. 2.2)", f"{order:.3f}", 1.8 < order < 2.2),
        ("the meshes agree on node 5's final y (< 1e-3 m)", f"{y5:.1e} m", y5 < 1e-3),
        ("the bandwidth is the same at every mesh", ", ".join(str(r["bandwidth"]) for r in scale),
         len({r["bandwidth"] for r in scale}) == 1)])
    page = ["# Simulation benchmark: twobar", "", f"{banner.line()} What is measured and what the numbers mean: "
            "[studies/bench_simulate.md](../studies/bench_simulate.md).", "",
            f"![cost against the mesh, time and error against dt](../figures/bench_simulate{'_quick' * quick}.png)",
            "", f"Per-step CPU time from {scale[0]['elements']} to {scale[-1]['elements']} elements per bar "
            f"({scale[0]['dofs']} to {scale[-1]['dofs']} dofs; each mesh's best of {spread['rounds']} interleaved "
            f"rounds): growth exponent **{expo['dofs']:.2f}** against the dofs (least-squares line through the log-log "
            f"points, t = b n^k; the best of the even and of the odd rounds: {spread['halves'][0]:.2f} and "
            f"{spread['halves'][1]:.2f}; fitted in each round: median {spread['dofs_median']:.2f}, range "
            f"{spread['dofs_min']:.2f} .. {spread['dofs_max']:.2f}), {expo['elements']:.2f} against the elements "
            f"(rounds: {spread['el_min']:.2f} .. {spread['el_max']:.2f}), {expo['dofs_const']:.2f} with a constant "
            f"(t = a + b n^k, a = {expo['const_us']:.2f} us), {expo['dofs_tail']:.2f} over the last three meshes. "
            f"Straight line: t = {expo['line_a_us']:.2f} us + {expo['line_b_ns']:.0f} ns per dof (the marginal cost "
            f"of a dof). On the medians of the rounds: {growth(scale, 'cpu_median_us')['dofs']:.2f} against the dofs; "
            f"in wall time (medians): {growth(scale, 'wall_step_us')['dofs']:.2f}.", ""]
    if expo_i:  # the same fits on the instructions, which the machine's load does not change
        page += [f"In instructions per step (callgrind): exponent **{expo_i['dofs']:.2f}** against the dofs, "
                 f"{expo_i['dofs_const']:.2f} with a constant, {expo_i['dofs_tail']:.2f} over the last three meshes, "
                 f"{expo_i['elements']:.2f} against the elements; straight line: "
                 f"{expo_i['line_b_ns']:.0f} instructions per dof.", ""]
    for (title, spec), rows in zip(TABLES, (scale, acc, kinds), strict=True):
        page += [f"## {title.format(t_end=t_end, dt_ref=acc[-1]['dt'] / 10, kinds_t=kinds_t)}", "",
                 *table(list(spec), [[f.format(**r) for f in spec.values()] for r in rows], "r" * len(spec)), ""]
    write_outputs("bench_simulate", out_dir, quick, "\n".join(page + lines), figure(scale, acc))
    assert_checks(failed)
    return {"scale": scale, "exponent": expo, "exponent_rounds": spread, "exponent_instructions": expo_i,
            "accuracy": acc, "order": order,
            "newton": kinds}


if __name__ == "__main__":
    if sys.argv[1:2] == ["--mesh-worker"]:  # hidden: one mesh in this fresh process, JSON on stdout
        print(json.dumps(mesh_worker(int(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4]))))
    elif sys.argv[1:2] == ["--timing-worker"]:  # hidden: the interleaved rounds, JSON on stdout
        print(json.dumps(timing_worker([int(e) for e in sys.argv[2].split(",")], float(sys.argv[3]),
                                       int(sys.argv[4]))))
    elif sys.argv[1:2] == ["--breakdown"]:  # where a step's instructions go: --breakdown 1,8,32 (k a step)
        els = [int(e) for e in sys.argv[2].split(",")]
        parts = {e: breakdown(e) for e in els}
        print("| part | " + " | ".join(f"{e} el./bar" for e in els) + " |")
        print("|---|" + "--:|" * len(els))
        for label in [lab for lab, _ in PARTS] + ["other"]:
            print(f"| {label} | " + " | ".join(f"{parts[e].get(label, 0) / 1e3:.1f}" for e in els) + " |")
        print("| total | " + " | ".join(f"{sum(parts[e].values()) / 1e3:.1f}" for e in els) + " |")
    elif sys.argv[1:2] == ["--mesh-part"]:  # the interleaved timing alone: --mesh-part 1,32 [rounds], no page
        els, n_rounds = [int(e) for e in sys.argv[2].split(",")], int(sys.argv[3]) if len(sys.argv) > 3 else ROUNDS
        res = interleaved(els, 3.0, n_rounds)
        for e in els:
            print(f"{e:3d} el./bar: CPU {res[e]['cpu_us']:.2f} us a step (best {res[e]['cpu_best_us']:.2f}, spread "
                  f"{res[e]['cpu_spread']:.0f} %), wall {res[e]['wall_us']:.2f} us "
                  f"(spread {res[e]['wall_spread']:.0f} %)")
        if len(els) > 1:
            dofs, med = [6 * e + 9 for e in els], [res[e]["cpu_us"] for e in els]  # twobar: 6 e + 9 dofs
            k = spread_fits(els, dofs, res)
            best = [res[e]["cpu_best_us"] for e in els]
            print(f"exponent of the CPU time against the dofs: {slope(dofs, best):.2f} (best), {slope(dofs, med):.2f} "
                  f"(medians), best of the even and odd rounds {k['halves'][0]:.2f}, {k['halves'][1]:.2f} (rounds "
                  f"{k['dofs_min']:.2f} .. {k['dofs_max']:.2f}), against the elements {slope(els, med):.2f} "
                  f"(rounds {k['el_min']:.2f} .. {k['el_max']:.2f})")
    else:
        cli(__doc__, main)
