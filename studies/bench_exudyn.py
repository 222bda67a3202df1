"""Benchmark against Exudyn: do the two codes solve the same twobar problem, which is faster at the
same mesh and step, and which is cheaper for a required accuracy of node 5?

Set-up and how to read the page: docs/studies/bench_exudyn.md. Run: ``python studies/bench_exudyn.py`` (about 15 min;
``--quick``: 0.3 s). Without Exudyn the casflex side still runs.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
from _shared import twobar
from _study import Banner, best_of, cli, png, table, write_outputs

import casflex
from casflex.simulate import compiled_library, integrator_for, simulate

GRID = 1e-2  # errors on t = 0, 0.01, ...
#: Physics check, node 5 (m): converged Exudyn against the converged casflex reference of its continuum
#: (why these values: docs/studies/bench_exudyn.md).
TOL_PHYSICS = {"ancf": 2e-6, "ge": 5e-6}
CODES = ("casflex", "ancf", "casflex-rot", "ge")
PAIRS = (("ancf", "casflex"), ("ge", "casflex-rot"))  # each Exudyn beam against casflex on its continuum
LEVELS = (1e-3, 3e-4, 1e-4, 3e-5, 1e-5, 3e-6, 1e-6)  # accuracy levels of the fronts (m)


def _plan(quick: bool) -> dict:
    if quick:
        return {"t_end": 0.3, "meshes": (1, 2), "ref": (4, 1e-4), "checks": ((4, 2e-4), (2, 1e-4)),
                "converged": {"ancf": ((4, 1e-4), (2, 1e-4)), "ge": ((16, 1e-4), (8, 1e-4))},
                "front_meshes": {c: (1, 2) for c in CODES}, "front_hs": (1e-3, 5e-4), "repeat": 2}
    return {"t_end": 3.0, "meshes": (1, 2, 4, 8, 16, 32), "ref": (16, 2.5e-5), "checks": ((8, 2.5e-5), (16, 5e-5)),
            "converged": {"ancf": ((8, 5e-5), (4, 5e-5)), "ge": ((64, 2.5e-5), (32, 5e-5))},
            "front_meshes": {"casflex": (1, 2, 4, 8), "ancf": (1, 2, 4, 8), "casflex-rot": (1, 2, 4, 8),
                             "ge": (4, 8, 16, 32)},
            "front_hs": (2e-3, 1e-3, 5e-4, 2.5e-4, 1e-4), "repeat": 5}


def _node5_grid(p5: np.ndarray, h: float, t_end: float) -> np.ndarray:
    return p5[np.round(np.arange(0.0, t_end + 1e-12, GRID) / h).astype(int)]


def run_casflex(elements: int, h: float, t_end: float, repeat: int = 1, rotary: bool = False) -> dict:
    """casflex's node 5 on the error grid, and the best time of ``repeat`` whole simulate() calls."""
    model = twobar(elements, rotary)
    compiled_library(integrator_for(model, alpha=0.0))  # built (or loaded) once, not timed
    t, tr = best_of(lambda: simulate(model, t_end, dt=h, alpha=0.0, compiled=True), repeat)
    p5 = np.stack([tr.dof("x5"), tr.dof("y5")], axis=1)
    return {"time": t, "run_s": tr.stats["run_s"], "p5": _node5_grid(p5, h, t_end), "ok": tr.success}


def _exudyn():
    try:
        import exudyn
    except ImportError:
        return None
    return exudyn


def run_exudyn(exu, kind: str, elements: int, h: float, t_end: float, repeat: int = 1) -> dict:
    """Exudyn's node 5 on the error grid (its ``kind`` of beam, casflex.peers.exudyn's translation of the scene),
    and the best time of ``repeat`` solves (inf if Exudyn stops)."""
    from casflex.peers.exudyn import build

    scene = casflex.load_scene("twobar")

    def once():
        m = build(scene, elements=elements, h=h, t_end=t_end, beam=kind, record=("5",))
        t0 = time.perf_counter()
        try:
            ok = m.mbs.SolveDynamic(m.settings)
        except exu.SolverError:
            return math.inf, False, np.zeros((0, 2))
        ref = np.asarray(m.mbs.GetNodeParameter(m.nodes["5"][0], "referenceCoordinates"))[:2]
        return time.perf_counter() - t0, ok, np.asarray(m.mbs.GetSensorStoredData(m.sensors["5"]["Coordinates"]))[
            :, 1:3] + ref

    runs = []  # best of repeat, timing SolveDynamic only (the model's set-up apart); one is enough past 2 s
    while len(runs) < repeat and (not runs or min(r[0] for r in runs) <= 2.0):
        runs.append(once())
    t, ok, p5 = min(runs, key=lambda r: r[0])
    n = int(round(t_end / h))
    p5 = p5 if p5.shape[0] >= n + 1 else np.full((n + 1, 2), np.nan)
    return {"time": t, "p5": _node5_grid(p5, h, t_end), "ok": bool(ok)}


def _err(p5: np.ndarray, ref: np.ndarray) -> float:
    e = np.linalg.norm(p5 - ref, axis=1)
    return float(e.max()) if np.isfinite(e).all() else math.inf


def front(points: list[tuple[float, float]], level: float) -> float:
    """The least time among (time, error) points with error <= level (inf if none)."""
    return min((t for t, e in points if e <= level), default=math.inf)


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    banner = Banner("bench_exudyn", quick)
    plan = _plan(quick)
    T = plan["t_end"]
    exu = _exudyn()
    codes = CODES if exu else ("casflex",)
    print(f"exudyn: {exu.__version__ if exu else 'NOT INSTALLED (casflex side only)'}")

    def run(code: str, n: int, h: float, repeat: int = 1) -> dict:
        if code.startswith("casflex"):
            return run_casflex(n, h, T, repeat, rotary=code == "casflex-rot")
        return run_exudyn(exu, code, n, h, T, repeat)

    ne, h = plan["ref"]
    refs, ref_err = {}, {}
    for rot in (False, True):  # the converged motion of each continuum, and its own error
        refs[rot] = run_casflex(ne, h, T, rotary=rot)["p5"]
        ref_err[rot] = max(_err(run_casflex(n2, h2, T, rotary=rot)["p5"], refs[rot]) for n2, h2 in plan["checks"])
        print(f"reference{' with rotary inertia' if rot else ''}: casflex {ne} el./bar, dt = {h:g}; against "
              f"{plan['checks']}: {ref_err[rot]:.1e} m", flush=True)
    ref_of = {c: refs[c in ("ge", "casflex-rot")] for c in CODES}
    physics = {}
    if exu:
        for kind, ((n2, h2), (n3, h3)) in plan["converged"].items():
            p_fine, p_coarse = (run(kind, nn, hh)["p5"] for nn, hh in ((n2, h2), (n3, h3)))
            physics[kind] = {"err": _err(p_fine, ref_of[kind]), "self": _err(p_fine, p_coarse), "setting": (n2, h2),
                             "twin": (n3, h3)}
            if kind == "ge":  # its own continuum's converged motion (shear included)
                ref_of[kind] = p_fine
            print(f"Exudyn {kind} {n2} el./bar, h = {h2:g}: {physics[kind]['err']:.2e} m from the "
                  f"reference (against its {n3}-element twin: {physics[kind]['self']:.1e} m)", flush=True)

    rows = []  # the meshes at h = 1e-3
    for n in plan["meshes"]:
        row = {"elements": n}
        for code in codes:
            r = run(code, n, 1e-3, plan["repeat"])
            row[code], row[f"{code}_err"] = r["time"], _err(r["p5"], ref_of[code])
        rows.append(row)
        print(f"{n:2d} el./bar, h = 1e-3: " + ", ".join(f"{c} {row[c] * 1e3:7.1f} ms ({row[c + '_err']:.1e} m)"
                                                       for c in codes), flush=True)
    pts: dict[str, list[tuple[float, float, int, float]]] = {c: [] for c in codes}
    for code in codes:
        for n in plan["front_meshes"][code]:
            for hh in plan["front_hs"]:
                r = run(code, n, hh, plan["repeat"])
                pts[code].append((r["time"], _err(r["p5"], ref_of[code]), n, hh))
    fronts = {c: [front([(t, e) for t, e, _, _ in pts[c]], lv) for lv in LEVELS] for c in codes}

    banner_line = banner.line(Exudyn=exu.__version__ if exu else "not installed")
    write_outputs("bench_exudyn", out_dir, quick, page(plan, rows, pts, fronts, physics, ref_err, codes, banner_line,
                                                       quick), figure(plan, rows, pts, codes))
    # self-checks: every casflex run finite and converging with the mesh; ANCF is the same physics
    assert all(math.isfinite(r["casflex_err"]) for r in rows)
    for kind, ph in physics.items():
        assert ph["err"] <= TOL_PHYSICS[kind], f"Exudyn's {kind} is {ph['err']:.2e} m from casflex's: another problem"
    return {"rows": rows, "points": pts, "fronts": fronts, "physics": physics}


def page(plan, rows, pts, fronts, physics, ref_err, codes, banner: str, quick: bool) -> str:
    """The physics check, the same-mesh times and the accuracy-against-time fronts."""
    pairs, meshes = [(x, c) for x, c in PAIRS if x in codes], plan["front_meshes"]

    def ratio(t: dict, x: str, c: str) -> str:
        return f"**{t[x] / t[c]:.1f}**" if math.isfinite(t[x]) and math.isfinite(t[c]) else "-"

    L = ["# casflex vs Exudyn: twobar", "", f"{banner} Horizon {plan['t_end']:g} s. The models, the codes' names and "
         "the measurement: [studies/bench_exudyn.md](../studies/bench_exudyn.md).", "",
         f"![time against the mesh, error against time](../figures/bench_exudyn{'_quick' * quick}.png)", "",
         "## The same problem", "",
         f"References: casflex {plan['ref'][0]} elements per bar, dt = {plan['ref'][1]:g} s, without and with rotary "
         f"inertia; their own errors, against {', '.join(f'{n} el. at {h:g} s' for n, h in plan['checks'])}: "
         f"{ref_err[False]:.1e} m and {ref_err[True]:.1e} m."]
    L += [f"Exudyn {kind}, {ph['setting'][0]} elements per bar at h = {ph['setting'][1]:g} s: **{ph['err']:.2e} m** "
          f"from casflex's reference of its continuum (its own error, against {ph['twin'][0]} elements: "
          f"{ph['self']:.1e} m; the physics check's tolerance {TOL_PHYSICS[kind]:g} m)."
          + (" This run is ge's own reference." if kind == "ge" else "") for kind, ph in physics.items()]
    L += ["", "## Same mesh, same step (h = 1e-3 s): time of the whole run", "",
          *table(["el./bar", *(f"{c}{u}" for c in codes for u in (" (ms)", " error (m)")),
                  *(f"{x} / {c}" for x, c in pairs)],
                 [[r["elements"], *(v for c in codes for v in (ms(r[c]), f"{r[c + '_err']:.1e}")),
                   *(ratio(r, x, c) for x, c in pairs)] for r in rows], "r" * (1 + 2 * len(codes) + len(pairs))),
          "", "## Accuracy against time", "",
          "For each accuracy, the least time each code needs among its settings (elements per bar "
          f"{', '.join(f'{c}: {list(meshes[c])}' for c in codes)}; steps "
          f"{', '.join(f'{h:g}' for h in plan['front_hs'])} s); '-': no setting reaches it.", "",
          *table(["error of node 5 at most (m)", *(f"{c} (ms)" for c in codes), *(f"{x} / {c}" for x, c in pairs)],
                 [[f"{lv:.0e}", *(ms(t[c]) if math.isfinite(t[c]) else "-" for c in codes),
                   *(ratio(t, x, c) for x, c in pairs)]
                  for i, lv in enumerate(LEVELS) for t in [{c: fronts[c][i] for c in codes}]],
                 "r" * (1 + len(codes) + len(pairs))), "", "Every setting measured (time in ms, error in m):", ""]
    L += [f"- {c}: " + "; ".join(f"{n} el. h {h:g}: {t * 1e3:.1f} ms, {e:.1e}" for t, e, n, h in pts[c])
          for c in codes]
    return "\n".join(L) + "\n"


def ms(t: float) -> str:
    """A time in ms, or 'failed'."""
    return "failed" if not math.isfinite(t) else f"{t * 1e3:.1f}"


def figure(plan, rows, pts, codes) -> bytes:
    """Time against the mesh at h = 1e-3; every setting's error against time, and each code's Pareto front."""
    from casflex.plotting._figure import _new_figure

    fig = _new_figure((11, 4.2))
    ax1, ax2 = fig.subplots(1, 2)
    for i, c in enumerate(codes):
        style = {"color": f"C{i}", "marker": "osD^"[i], "ls": "-" if c.startswith("casflex") else "--"}
        ax1.loglog([r["elements"] for r in rows], [r[c] for r in rows], label=c, **style)
        p = sorted((t, e) for t, e, _, _ in pts[c] if math.isfinite(t) and math.isfinite(e))
        ax2.loglog([t for t, _ in p], [e for _, e in p], style["marker"], color=style["color"], alpha=0.35)
        fr = [(t, e) for j, (t, e) in enumerate(p) if all(e < e2 for _, e2 in p[:j])]  # faster ones are less accurate
        ax2.loglog([t for t, _ in fr], [e for _, e in fr], label=f"{c}: front", **style)
    ax1.set_xticks(plan["meshes"], [str(n) for n in plan["meshes"]])
    ax1.tick_params(axis="x", which="minor", labelbottom=False)  # the meshes themselves are the ticks
    ax1.set(xlabel="elements per bar", ylabel=f"wall time of {plan['t_end']:g} s at h = 1e-3 s (s)",
            title="same mesh, same step")
    ax2.set(xlabel="wall time (s)", ylabel="max error of node 5 (m)",
            title="accuracy against time (faint: every setting)")
    ax2.tick_params(which="minor", labelsize="x-small")  # a narrow log range labels its minor ticks
    for ax in (ax1, ax2):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize="small")
    return png(fig)


if __name__ == "__main__":
    cli(__doc__, main)
