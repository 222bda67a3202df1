"""Benchmark: what does a twobar simulation cost as the mesh grows, how accurate is it per step, and
what does modified Newton save?

Set-up and how to read the page: docs/studies/bench_simulate.md. Run: ``python studies/bench_simulate.py`` (about 5
min; ``--quick``).
"""

from __future__ import annotations

import json
import platform
import resource
import sys
import time
from pathlib import Path

import numpy as np
from _shared import cold_and_cached, twobar
from _study import Banner, best_of, cli, png, table, write_outputs

from casflex.simulate import simulate

KINDS_T = 1.0  # s of twobar for the comparison of Newton variants


def mesh_worker(elements: int, t_end: float, repeat: int) -> dict:
    """In a fresh process: build (or load) the compiled step, then time simulate() (JSON on stdout)."""
    from casflex.simulate import compiled_library, integrator_for

    base_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0 = time.perf_counter()
    model = twobar(elements)
    lib = compiled_library(integrator_for(model, alpha=0.0))
    build_s = time.perf_counter() - t0
    t_sim, tr = best_of(lambda: simulate(model, t_end, dt=1e-3, compiled=True), repeat, enough=float("inf"))
    return {"elements": elements, "dofs": model.n_dof, "build_s": build_s, "cached": lib.cached,
            "simulate_s": t_sim, "run_s": tr.stats["run_s"], "steps": tr.stats["steps"],
            "code_kb": lib.path.stat().st_size // 1024, "base_mb": base_kb / 1024,
            "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, "y5": float(tr.dof("y5")[-1])}


def scaling(meshes: tuple[int, ...], t_end: float, repeat: int) -> list[dict]:
    """Per mesh: a cold build, then a cached build and the timed simulations, in two fresh processes."""
    rows = []
    for ne in meshes:
        cold, warm = cold_and_cached(__file__, *(["--mesh-worker", str(ne), repr(t_end), str(n)] for n in (1, repeat)),
                                     timeout=1800)
        assert not cold["cached"] and warm["cached"], "the second process must find the first one's library"
        rows.append({**warm, "cold_build_s": cold["build_s"], "cached_build_s": warm["build_s"],
                     "per_step_us": 1e6 * warm["run_s"] / warm["steps"]})
        print(f"{ne:3d} el./bar: build cold {cold['build_s']:5.1f} s, simulate {warm['simulate_s'] * 1e3:7.1f} ms",
              flush=True)
    return rows


def exponent(x, y) -> float:
    """Slope of the least-squares line through the log-log points."""
    return float(np.polyfit(np.log(x), np.log(y), 1)[0])


def accuracy(t_end: float, dts: list[float]) -> tuple[list[dict], float]:
    """Per dt: both paths' times, Newton iterations, node 5's error; the fitted convergence order."""
    model = twobar(1)
    dt_ref = dts[-1] / 10
    ref = simulate(model, t_end, dt=dt_ref, alpha=0.0, compiled=True)
    ref5 = ref.q[np.round(np.arange(0, t_end + 1e-12, dts[0]) / dt_ref).astype(int)][:, 12:14]
    rows = []
    for dt in dts:
        t_c, tc = best_of(lambda dt=dt: simulate(model, t_end, dt=dt, alpha=0.0, compiled=True), 5, float("inf"))
        t_i, ti = best_of(lambda dt=dt: simulate(model, t_end, dt=dt, alpha=0.0), 1 if dt < 1e-3 else 2, float("inf"))
        idx = np.round(np.arange(0, t_end + 1e-12, dts[0]) / dt).astype(int)
        rows.append({"dt": dt, "steps": ti.stats["steps"], "interpreted_s": t_i, "compiled_s": t_c,
                     "speedup": t_i / t_c, "compiled_run_s": tc.stats["run_s"],
                     "newton_per_step": ti.stats["newton_iterations"] / ti.stats["steps"],
                     "err_node5_m": float(np.linalg.norm(ti.q[idx][:, 12:14] - ref5, axis=1).max()),
                     "max_diff_paths": float(np.abs(tc.q - ti.q).max())})
        print(f"dt = {dt:7.0e}: error node 5 {rows[-1]['err_node5_m']:.3e} m", flush=True)
    d = np.array([r["dt"] for r in rows])
    fit = d <= 2e-3  # the asymptotic range: coarser steps are pre-asymptotic on this motion
    return rows, exponent(d[fit], [r["err_node5_m"] for r, f in zip(rows, fit, strict=True) if f])


def newton_kinds(meshes: tuple[int, ...], dts: tuple[float, ...], t_end: float) -> list[dict]:
    """Exact and modified Newton side by side, compiled, per mesh and step."""
    rows = []
    for ne in meshes:
        model = twobar(ne)
        for dt in dts:
            runs = {}
            for kind in ("exact", "modified"):
                simulate(model, t_end, dt=dt, newton=kind, compiled=True)  # build, not timed
                runs[kind] = best_of(lambda k=kind, m=model, dt=dt: simulate(m, t_end, dt=dt, newton=k, compiled=True),
                                     3, float("inf"))
            (te, ex), (tm, mo) = runs["exact"], runs["modified"]
            rows.append({"elements": ne, "dt": dt, "t_end": t_end, "exact_s": te, "modified_s": tm,
                         "refresh": mo.stats["jacobian_refreshes"] / mo.stats["steps"],
                         "deviation_m": float(np.abs(mo.q - ex.q).max())})
    return rows


def page(scale: list[dict], acc: list[dict], order: float, expo: dict, t_end: float, kinds: list[dict],
         banner: str, quick: bool) -> str:
    """The three tables and the fitted exponents and order."""
    L = ["# Simulation benchmark: twobar", "", f"{banner} What is measured and what the numbers mean: "
         "[studies/bench_simulate.md](../studies/bench_simulate.md).", "",
         f"![cost against the mesh, time and error against dt](../figures/bench_simulate{'_quick' * quick}.png)", "",
         f"## Cost against the mesh ({t_end:g} s, dt = 1e-3, compiled)", "",
         *table(["el./bar", "dofs", "cold build (s)", "cached build (s)", "library (kB)", "simulate (ms)",
                 "integration (ms)", "per step (us)", "peak memory (MB)"],
                [[r["elements"], r["dofs"], f"{r['cold_build_s']:.1f}", f"{r['cached_build_s']:.2f}", r["code_kb"],
                  f"{r['simulate_s'] * 1e3:.1f}", f"{r['run_s'] * 1e3:.1f}", f"{r['per_step_us']:.1f}",
                  f"{r['peak_mb']:.0f}"] for r in scale], "r" * 9),
         "", f"Growth of the per-step cost from {scale[0]['elements']} to {scale[-1]['elements']} elements per bar: "
         f"exponent **{expo['elements']:.2f}** against the number of elements, {expo['dofs']:.2f} against the number "
         "of dofs.", "", "## Accuracy and the two paths (1 element per bar)", "",
         *table(["dt (s)", "steps", "interpreted (ms)", "compiled (ms)", "compiled, integration only (ms)", "speed-up",
                 "Newton it./step", "error node 5 (m)", "max abs interp - compiled"],
                [[f"{r['dt']:.0e}", r["steps"], f"{r['interpreted_s'] * 1e3:.1f}", f"{r['compiled_s'] * 1e3:.2f}",
                  f"{r['compiled_run_s'] * 1e3:.2f}", f"{r['speedup']:.1f}", f"{r['newton_per_step']:.2f}",
                  f"{r['err_node5_m']:.3e}", f"{r['max_diff_paths']:.1e}"] for r in acc], "r" * 9),
         "", f"Error: against a dt = {acc[-1]['dt'] / 10:g} s reference. Fitted convergence order over dt <= 2e-3: "
         f"**{order:.3f}**.", "", f"## Exact and modified Newton ({kinds[0]['t_end']:g} s, compiled)", "",
         *table(["el./bar", "dt (s)", "exact (ms)", "modified (ms)", "modified / exact",
                 "steps that refresh the Jacobian", "node 5 from the exact Newton's (m)"],
                [[r["elements"], f"{r['dt']:g}", f"{r['exact_s'] * 1e3:.1f}", f"{r['modified_s'] * 1e3:.1f}",
                  f"{r['modified_s'] / r['exact_s']:.2f}", f"{100 * r['refresh']:.0f} %", f"{r['deviation_m']:.1e}"]
                 for r in kinds], "r" * 7)]
    return "\n".join(L + [""])


def figure(scale: list[dict], acc: list[dict]) -> bytes:
    """Cost against the mesh; both paths' time and node 5's error against dt (1 element per bar)."""
    from casflex.plotting._figure import _new_figure

    fig = _new_figure((12, 4))
    ax1, ax2, ax3 = fig.subplots(1, 3)
    dofs, d = [r["dofs"] for r in scale], [r["dt"] for r in acc]
    cost = (("per_step_us", 1, "o-", "per step (us)"), ("cold_build_s", 1e3, "s-", "cold build (ms)"),
            ("peak_mb", 1, "^-", "peak memory (MB)"))
    for key, f, mark, label in cost:
        ax1.loglog(dofs, [r[key] * f for r in scale], mark, label=label)
    ax1.set_xticks(dofs, [str(n) for n in dofs])
    ax1.tick_params(axis="x", which="minor", labelbottom=False)  # the dofs themselves are the ticks
    ax1.set(xlabel=f"dofs ({scale[0]['elements']} ... {scale[-1]['elements']} elements per bar)",
            title="cost against the mesh (compiled)")
    ax2.loglog(d, [r["interpreted_s"] for r in acc], "o-", label="interpreted")
    ax2.loglog(d, [r["compiled_s"] for r in acc], "s-", label="compiled C")
    ax2.set(xlabel="dt (s)", ylabel="wall time of simulate() (s)", title="the two paths")
    ax3.loglog(d, [r["err_node5_m"] for r in acc], "o-", label="against a 10x finer dt")
    ax3.set(xlabel="dt (s)", ylabel="max error of node 5 (m)", title="accuracy (HHT-alpha, order 2)")
    for ax in (ax1, ax2, ax3):
        ax.legend()
        ax.grid(True, which="both", alpha=0.3)
    return png(fig)


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    banner = Banner("bench_simulate", quick)
    t_end = 0.3 if quick else 3.0
    scale = scaling((1, 2) if quick else (1, 2, 4, 8, 16, 32), t_end, 2 if quick else 7)
    expo = {k: exponent([r[k] for r in scale], [r["per_step_us"] for r in scale]) for k in ("dofs", "elements")}
    acc, order = accuracy(0.5 if quick else 3.0,
                          [1e-2, 5e-3, 2e-3, 1e-3] if quick else [1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4])
    kinds = newton_kinds((1,) if quick else (1, 8, 32), (1e-3,) if quick else (1e-3, 2e-4), 0.2 if quick else KINDS_T)
    write_outputs("bench_simulate", out_dir, quick, page(scale, acc, order, expo, t_end, kinds, banner.line(), quick),
                  figure(scale, acc))
    # self-checks: what the docs claim
    same = 0.0 if platform.machine() in ("x86_64", "AMD64") else 1e-10  # bitwise where claimed (codegen.CFLAGS)
    assert all(r["max_diff_paths"] <= same for r in acc), "compiled and interpreted paths disagree"
    assert 1.8 < order < 2.2, f"convergence order {order} is not 2"
    y5 = [r["y5"] for r in scale]
    assert np.ptp(y5) < 1e-3, f"the meshes disagree on node 5 by {np.ptp(y5):.2e} m"  # mesh error of 1 el./bar: 6e-5 m
    return {"scale": scale, "exponent": expo, "accuracy": acc, "order": order, "newton": kinds}


if __name__ == "__main__":
    if sys.argv[1:2] == ["--mesh-worker"]:  # hidden: one mesh in this fresh process, JSON on stdout
        print(json.dumps(mesh_worker(int(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4]))))
    else:
        cli(__doc__, main)
