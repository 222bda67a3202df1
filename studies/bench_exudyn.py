"""Benchmark against Exudyn: do the two codes solve the same twobar problem, which is faster at the same mesh and
step, and which is cheaper for a required accuracy of node 5? Run: ``python studies/bench_exudyn.py [--quick]``
(about 15 min; without Exudyn the casflex side only). The models and the measurement: docs/studies/bench_exudyn.md.
"""

from __future__ import annotations

import importlib.util
import math
import time
from pathlib import Path

import numpy as np
from _shared import twobar
from _study import Banner, assert_checks, best_of, checks, cli, fnum, png, table, write_outputs

import casflex
from casflex.simulate import Stepping, compiled_library, integrator_for, simulate

GRID = 1e-2  # errors on t = 0, 0.01, ...
TOL_PHYSICS = {"ancf": 2e-6, "ge": 5e-6}  # converged Exudyn from casflex's converged reference, node 5 (m; why: docs)
CODES = ("casflex", "ancf", "casflex-rot", "ge")
PAIRS = (("ancf", "casflex"), ("ge", "casflex-rot"))  # each Exudyn beam against casflex on its continuum
LEVELS = (1e-3, 3e-4, 1e-4, 3e-5, 1e-5, 3e-6, 1e-6)  # accuracy levels of the fronts (m)
PLAN = {"t_end": 3.0, "meshes": (1, 2, 4, 8, 16, 32), "ref": (16, 2.5e-5), "converged": {"ancf": (8, 5e-5),
        "ge": (64, 2.5e-5)}, "front_meshes": {c: (1, 2, 4, 8) for c in CODES} | {"ge": (4, 8, 16, 32)},
        "front_hs": (2e-3, 1e-3, 5e-4, 2.5e-4, 1e-4), "repeat": 5}
QUICK_PLAN = {"t_end": 0.3, "meshes": (1, 2), "ref": (4, 1e-4), "converged": {"ancf": (4, 1e-4), "ge": (16, 1e-4)},
              "front_meshes": {c: (1, 2) for c in CODES}, "front_hs": (1e-3, 5e-4), "repeat": 2}


def run(code: str, elements: int, h: float, t_end: float, repeat: int = 1) -> tuple[float, np.ndarray]:
    """(best time of ``repeat`` runs, node 5 on the error grid) of casflex's whole simulate() calls (``casflex-rot``:
    rotary inertia) or of Exudyn's SolveDynamic (beam ``code``; inf if Exudyn stops; one run is enough past 2 s)."""
    n = int(round(t_end / h))
    if code.startswith("casflex"):
        model = twobar(elements, code == "casflex-rot")
        compiled_library(integrator_for(model, alpha=0.0))  # built (or loaded) once, not timed
        t, tr = best_of(lambda: simulate(model, t_end, stepping=Stepping(dt=h, alpha=0.0, compiled=True)), repeat)
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


def _err(p5: np.ndarray, ref: np.ndarray) -> float:  # the largest distance of node 5; inf where a run failed
    return float(np.nan_to_num(np.linalg.norm(p5 - ref, axis=1).max(), nan=math.inf))


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    from casflex.plotting._figure import _new_figure

    banner, plan = Banner("bench_exudyn", quick), QUICK_PLAN if quick else PLAN
    T, (ne, h) = plan["t_end"], plan["ref"]
    exudyn = importlib.import_module("exudyn") if importlib.util.find_spec("exudyn") else None
    codes = CODES if exudyn else ("casflex",)
    # the same problem: each continuum's converged casflex motion, and each Exudyn beam's converged run from it
    refs = {c: run(c, ne, h, T)[1] for c in ("casflex", "casflex-rot")}
    ref_of, physics = {c: refs["casflex-rot" if c in ("ge", "casflex-rot") else "casflex"] for c in CODES}, {}
    for kind, (n2, h2) in plan["converged"].items() if exudyn else ():
        physics[kind] = (n2, h2, _err(fine := run(kind, n2, h2, T)[1], ref_of[kind]))
        if kind == "ge":  # its own continuum's converged motion (shear included) is ge's reference
            ref_of[kind] = fine

    def measured(c: str, n: int, hh: float) -> tuple[float, float]:  # (best time, error of node 5) of a setting
        t, p5 = run(c, n, hh, T, plan["repeat"])
        return t, _err(p5, ref_of[c])

    rows = [{"elements": n, **{c: measured(c, n, 1e-3) for c in codes}} for n in plan["meshes"]]  # h = 1e-3
    pts = {c: [measured(c, n, hh) for n in plan["front_meshes"][c] for hh in plan["front_hs"]] for c in codes}
    # per accuracy level and code: the least time among the settings that reach it
    fronts = [{c: min((t for t, e in pts[c] if e <= lv), default=math.inf) for c in codes} for lv in LEVELS]
    pairs = [(x, c) for x, c in PAIRS if x in codes]

    def ratios(t: dict) -> list[str]:
        return [f"**{t[x] / t[c]:.1f}**" if math.isfinite(t[x]) and math.isfinite(t[c]) else "-" for x, c in pairs]

    worst = max(r["casflex"][1] for r in rows)  # casflex's largest error at h = 1e-3 s
    lines, failed = checks([("every casflex run at h = 1e-3 s finite", f"max error {worst:.1e} m", worst < math.inf)]
                           + [(f"Exudyn {k} ({n2} el., h {h2:g} s) within {TOL_PHYSICS[k]:g} m of casflex's reference "
                               f"of its continuum ({ne} el., h {h:g} s)", f"{e:.2e} m", e <= TOL_PHYSICS[k])
                              for k, (n2, h2, e) in physics.items()])
    page = [
        "# casflex vs Exudyn: twobar", "", f"{banner.line(Exudyn=exudyn.__version__ if exudyn else 'not installed')} "
        f"Horizon {T:g} s. The models, the codes' names and the measurement: "
        "[studies/bench_exudyn.md](../studies/bench_exudyn.md).", "",
        f"![every setting's error against time, each code's front](../figures/bench_exudyn{'_quick' * quick}.png)", "",
        "## Same mesh, same step (h = 1e-3 s): time of the whole run", "", *table(
            ["el./bar", *(f"{c}{u}" for c in codes for u in (" (ms)", " error (m)")),
             *(f"{x} / {c}" for x, c in pairs)],
            [[r["elements"], *(v for c in codes for v in (fnum(r[c][0] * 1e3, ".1f", "failed"), f"{r[c][1]:.1e}")),
              *ratios({c: r[c][0] for c in codes})] for r in rows], "r" * (1 + 2 * len(codes) + len(pairs))),
        "", "## Accuracy against time", "", *table(
            ["error of node 5 at most (m)", *(f"{c} (ms)" for c in codes), *(f"{x} / {c}" for x, c in pairs)],
            [[f"{lv:.0e}", *(fnum(t[c] * 1e3, ".1f") for c in codes), *ratios(t)]
             for lv, t in zip(LEVELS, fronts, strict=True)], "r" * (1 + len(codes) + len(pairs))),
        "", *lines]
    ax = _new_figure((6.5, 4.2)).subplots()  # every setting's error against its time (faint), each code's front
    for i, c in enumerate(codes):
        style = {"color": f"C{i}", "marker": "osD^"[i], "ls": "-" if c.startswith("casflex") else "--"}
        p = sorted((t, e) for t, e in pts[c] if math.isfinite(t) and math.isfinite(e))
        ax.loglog([t for t, _ in p], [e for _, e in p], style["marker"], color=style["color"], alpha=0.35)
        fr = [(t, e) for j, (t, e) in enumerate(p) if all(e < e2 for _, e2 in p[:j])]  # faster ones are less accurate
        ax.loglog([t for t, _ in fr], [e for _, e in fr], label=f"{c}: front", **style)
    ax.set(xlabel=f"wall time of {T:g} s (s)", ylabel="max error of node 5 (m)", title="faint: every setting")
    ax.tick_params(which="minor", labelsize="x-small")  # a narrow log range labels its minor ticks
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize="small")
    write_outputs("bench_exudyn", out_dir, quick, "\n".join(page), png(ax.figure))
    assert_checks(failed)
    return {"rows": rows, "points": pts, "fronts": fronts, "physics": physics}


if __name__ == "__main__":
    cli(__doc__, main)
