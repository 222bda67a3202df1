"""Benchmark against Exudyn: do the two codes solve the same twobar problem, which is faster at the same mesh and
step, and which is cheaper for a required accuracy of node 5? Run: ``python studies/bench_exudyn.py [--quick]``
(about 15 min; without Exudyn the casflex side only). The models and the measurement: docs/studies/bench_exudyn.md.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
from _shared import twobar
from _study import Banner, assert_checks, best_of, checks, cli, png, table, write_outputs

import casflex
from casflex.simulate import compiled_library, integrator_for, simulate

GRID = 1e-2  # errors on t = 0, 0.01, ...
TOL_PHYSICS = {"ancf": 2e-6, "ge": 5e-6}  # converged Exudyn from casflex's converged reference, node 5 (m; why: docs)
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


def run(code: str, elements: int, h: float, t_end: float, repeat: int = 1) -> tuple[float, np.ndarray]:
    """(best time of ``repeat`` runs, node 5 on the error grid) of casflex's whole simulate() calls (``casflex-rot``:
    with rotary inertia) or of Exudyn's SolveDynamic, the model's set-up apart (its beam ``code`` in
    casflex.peers.exudyn's translation of the scene; inf if Exudyn stops; one run is enough past 2 s)."""
    n = int(round(t_end / h))
    if code.startswith("casflex"):
        model = twobar(elements, code == "casflex-rot")
        compiled_library(integrator_for(model, alpha=0.0))  # built (or loaded) once, not timed
        t, tr = best_of(lambda: simulate(model, t_end, dt=h, alpha=0.0, compiled=True), repeat)
        p5 = np.stack([tr.dof("x5"), tr.dof("y5")], axis=1)
    else:
        import exudyn

        from casflex.peers.exudyn import build

        runs = []
        while len(runs) < repeat and min((t for t, _ in runs), default=0.0) <= 2.0:
            m = build(casflex.load_scene("twobar"), elements=elements, h=h, t_end=t_end, beam=code, record=("5",))
            t0 = time.perf_counter()
            try:
                m.mbs.SolveDynamic(m.settings)
            except exudyn.SolverError:
                runs.append((math.inf, np.zeros((0, 2))))
                continue
            t = time.perf_counter() - t0
            ref = np.asarray(m.mbs.GetNodeParameter(m.nodes["5"][0], "referenceCoordinates"))[:2]
            runs.append((t, np.asarray(m.mbs.GetSensorStoredData(m.sensors["5"]["Coordinates"]))[:, 1:3] + ref))
        t, p5 = min(runs, key=lambda r: r[0])
        p5 = p5 if len(p5) > n else np.full((n + 1, 2), np.nan)
    return t, p5[np.round(np.arange(0.0, t_end + 1e-12, GRID) / h).astype(int)]


def _err(p5: np.ndarray, ref: np.ndarray) -> float:
    e = np.linalg.norm(p5 - ref, axis=1)
    return float(e.max()) if np.isfinite(e).all() else math.inf


def _ms(t: float) -> str:
    return f"{t * 1e3:.1f}" if math.isfinite(t) else "failed"


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    banner, plan = Banner("bench_exudyn", quick), _plan(quick)
    T, (ne, h) = plan["t_end"], plan["ref"]
    try:
        import exudyn
    except ImportError:
        exudyn = None
    codes = CODES if exudyn else ("casflex",)
    # the same problem: each continuum's converged casflex motion and its own error against coarser settings ...
    refs, same, physics = {}, [], {}
    for c in ("casflex", "casflex-rot"):
        refs[c] = run(c, ne, h, T)[1]
        own = max(_err(run(c, n2, h2, T)[1], refs[c]) for n2, h2 in plan["checks"])
        same.append([f"{c} (reference)", f"{ne}, {h:g}", f"{own:.1e} (against "
                     + ", ".join(f"{n2} el. at {h2:g} s" for n2, h2 in plan["checks"]) + ")", "-"])
    ref_of = {c: refs["casflex-rot" if c in ("ge", "casflex-rot") else "casflex"] for c in CODES}
    for kind, ((n2, h2), (n3, h3)) in plan["converged"].items() if exudyn else ():  # ... and each Exudyn beam's
        (_, fine), (_, coarse) = run(kind, n2, h2, T), run(kind, n3, h3, T)
        physics[kind] = _err(fine, ref_of[kind])
        same.append([f"Exudyn {kind}", f"{n2}, {h2:g}", f"{_err(fine, coarse):.1e} (against {n3} el.)",
                     f"**{physics[kind]:.2e}**"])
        if kind == "ge":  # its own continuum's converged motion (shear included) is ge's reference
            ref_of[kind] = fine

    def measured(c: str, n: int, hh: float) -> tuple[float, float]:  # (best time, error of node 5) of a setting
        t, p5 = run(c, n, hh, T, plan["repeat"])
        return t, _err(p5, ref_of[c])

    rows = [{"elements": n, **{c: measured(c, n, 1e-3) for c in codes}} for n in plan["meshes"]]  # h = 1e-3
    pts = {c: [(*measured(c, n, hh), n, hh) for n in plan["front_meshes"][c] for hh in plan["front_hs"]] for c in codes}
    # per accuracy level and code: the least time among the settings that reach it
    fronts = [{c: min((t for t, e, *_ in pts[c] if e <= lv), default=math.inf) for c in codes} for lv in LEVELS]
    pairs = [(x, c) for x, c in PAIRS if x in codes]

    def ratios(t: dict) -> list[str]:
        return [f"**{t[x] / t[c]:.1f}**" if math.isfinite(t[x]) and math.isfinite(t[c]) else "-" for x, c in pairs]

    worst = max(r["casflex"][1] for r in rows)  # casflex's largest error at h = 1e-3 s
    lines, failed = checks([("every casflex run at h = 1e-3 s finite", f"max error {worst:.1e} m",
                             math.isfinite(worst))]
                           + [(f"Exudyn {k} within {TOL_PHYSICS[k]:g} m of casflex's reference of its continuum",
                               f"{e:.2e} m", e <= TOL_PHYSICS[k]) for k, e in physics.items()])
    page = [
        "# casflex vs Exudyn: twobar", "", f"{banner.line(Exudyn=exudyn.__version__ if exudyn else 'not installed')} "
        f"Horizon {T:g} s. The models, the codes' names and the measurement: "
        "[studies/bench_exudyn.md](../studies/bench_exudyn.md).", "",
        f"![time against the mesh, error against time](../figures/bench_exudyn{'_quick' * quick}.png)", "",
        "## The same problem", "", *table(["motion of node 5", "el./bar, h (s)", "its own error (m)",
                                           "from casflex's reference of its continuum (m)"], same, "llll"),
        "", "## Same mesh, same step (h = 1e-3 s): time of the whole run", "", *table(
            ["el./bar", *(f"{c}{u}" for c in codes for u in (" (ms)", " error (m)")),
             *(f"{x} / {c}" for x, c in pairs)],
            [[r["elements"], *(v for c in codes for v in (_ms(r[c][0]), f"{r[c][1]:.1e}")),
              *ratios({c: r[c][0] for c in codes})] for r in rows], "r" * (1 + 2 * len(codes) + len(pairs))),
        "", "## Accuracy against time", "", *table(
            ["error of node 5 at most (m)", *(f"{c} (ms)" for c in codes), *(f"{x} / {c}" for x, c in pairs)],
            [[f"{lv:.0e}", *(_ms(t[c]) if math.isfinite(t[c]) else "-" for c in codes), *ratios(t)]
             for lv, t in zip(LEVELS, fronts, strict=True)], "r" * (1 + len(codes) + len(pairs))),
        "", "Every setting measured (time in ms, error in m):", "",
        *(f"- {c}: " + "; ".join(f"{n} el. h {hh:g}: {t * 1e3:.1f} ms, {e:.1e}" for t, e, n, hh in pts[c])
          for c in codes),
        "", *lines]
    write_outputs("bench_exudyn", out_dir, quick, "\n".join(page), figure(plan, rows, pts, codes))
    assert_checks(failed)
    return {"rows": rows, "points": pts, "fronts": fronts, "physics": physics}


def figure(plan, rows, pts, codes) -> bytes:
    """Time against the mesh at h = 1e-3; every setting's error against time, and each code's Pareto front."""
    from casflex.plotting._figure import _new_figure

    fig = _new_figure((11, 4.2))
    ax1, ax2 = fig.subplots(1, 2)
    for i, c in enumerate(codes):
        style = {"color": f"C{i}", "marker": "osD^"[i], "ls": "-" if c.startswith("casflex") else "--"}
        ax1.loglog([r["elements"] for r in rows], [r[c][0] for r in rows], label=c, **style)
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
