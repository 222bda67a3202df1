"""Speed-accuracy trade-off on twobar: which dt, HHT alpha, mesh and inertia form reach a stated accuracy fastest?

Run: ``python studies/tradeoff.py`` (10-15 min) or ``--quick``. Set-up and reading: docs/studies/tradeoff.md.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np
from _shared import twobar
from _study import Banner, assert_checks, best_of, checks, cli, fnum, paths_check, png, table, write_outputs
from matplotlib.lines import Line2D

from casflex.plotting._figure import _new_figure
from casflex.simulate import Stepping, compiled_library, integrator_for, simulate

ALPHAS = (0.0, -0.05, -0.1, -0.3, -1.0 / 3.0)
NODES, FORCES = ("3", "5"), ("spring1.force", "spring3.force", "torsion1.moment", "torsion3.moment")
GRID_STEP = 1e-2  # the common time grid of the errors: every multiple of the coarsest step
LEVELS = ((1e-3, 5.0), (1e-4, 1.0), (1e-5, 0.1))  # stated accuracies: (node positions, m; joint forces, %)
HEADLINE, MARGIN = (1e-4, 1.0), (8e-5, 0.8)  # MARGIN: the headline with a 20 % margin
TIE = 0.15  # recommended: among settings within 15 % of the cheapest (timing noise), lagrange first
NAN = {"pos": np.nan, "force_rel": np.nan}
PATHS = (("compiled_s", "compiled"), ("interp_s", "interpreted"))


class Config(NamedTuple):  # one setting
    elements: int  # per bar
    inertia: str
    alpha: float

    @property
    def label(self) -> str:
        return f"{self.elements} el., {self.inertia}, alpha {fmt_alpha(self.alpha)}"


CENTRE = Config(1, "lagrange", 0.0)


def fmt_alpha(alpha: float) -> str:
    return "-1/3" if abs(alpha + 1.0 / 3.0) < 1e-12 else f"{alpha:g}"


def ms(s: float | None) -> str:
    return "" if s is None or not np.isfinite(s) else (f"{s * 1e3:.1f} ms" if s < 10 else f"{s:.1f} s")


def plan_for(quick: bool) -> dict:
    if quick:
        return {"t_end": 0.5, "dts": [1e-2, 5e-3, 2e-3, 1e-3, 5e-4], "dt_fine": 5e-5, "alphas": (0.0, -1.0 / 3.0),
                "meshes": (1, 2), "mesh_dts": [1e-2, 1e-3], "alt_alphas": (), "seed_alphas": (0.0,),
                "seed_meshes": (1,), "window": 300, "fit": (5e-4, 2e-3), "validate_dt": 5e-4}
    return {"t_end": 3.0, "dts": [1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4, 5e-5, 2e-5], "dt_fine": 1e-5,
            "alphas": ALPHAS, "meshes": (1, 2, 4, 8), "mesh_dts": [1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4],
            "alt_alphas": (-0.05,), "seed_alphas": ALPHAS, "seed_meshes": (1, 2, 4, 8), "window": 3000,
            "fit": (1e-4, 2e-3), "validate_dt": 1e-4}


def tasks_for(plan: dict) -> list[tuple[Config, float, bool]]:
    """(config, dt, time the interpreted path too) in run order; the reference first."""
    fine, ref = plan["dt_fine"], Config(plan["meshes"][-1], "lagrange", 0.0)
    tasks = [(ref, fine, True), (ref, 2 * fine, True)]
    for form, alphas in (("lagrange", plan["alphas"]), ("seed", plan["seed_alphas"])):
        tasks += [(Config(1, form, a), dt, form == "lagrange" or a == 0.0) for a in alphas
                  for dt in [*plan["dts"], fine]]
    for ne in plan["meshes"][1:]:  # (the reference at its dt is already the first)
        tasks += [(Config(ne, "lagrange", 0.0), dt, True) for dt in plan["mesh_dts"] + [fine] * (ne != ref.elements)]
        tasks += [(Config(ne, "lagrange", a), dt, False) for a in plan["alt_alphas"] for dt in plan["mesh_dts"]]
        if ne in plan["seed_meshes"]:
            tasks.append((Config(ne, "seed", 0.0), fine, False))
    return tasks


def diff(s: dict, ref: dict) -> dict:
    """Max over the grid: position distance (m), force errors (% of the reference's peak)."""
    rel = 100.0 * np.abs(s["forces"] - ref["forces"]).max(axis=0) / np.abs(ref["forces"]).max(axis=0)
    return {"pos": float(np.linalg.norm(s["pos"] - ref["pos"], axis=2).max()), "force_rel": float(rel.max())}


def run(cfg: Config, dt: float, interp: bool, plan: dict, m, samples: dict) -> dict:
    """One setting's row (its samples on the error grid into ``samples``): compiled, then interpreted on a window."""
    t_end, steps = plan["t_end"], int(round(plan["t_end"] / dt))
    w = min(steps, plan["window"])  # the interpreted window
    t_c, tr = best_of(lambda: simulate(m, t_end, stepping=Stepping(dt=dt, alpha=cfg.alpha, compiled=True),
                                       raise_on_failure=False), 3)
    row = {"cfg": cfg, "dt": dt, "ok": tr.success, "message": tr.message, "compiled_s": t_c if tr.success else None,
           "interp_s": None, "interp_projected": False, "newton_per_step": None,
           "paths_diff": None, "is_ref": cfg == Config(plan["meshes"][-1], "lagrange", 0.0) and dt == plan["dt_fine"]}
    if not tr.success:
        return row
    idx = np.round(np.arange(0.0, t_end + 1e-12, GRID_STEP) / tr.meta["dt"]).astype(int)
    energy, q, y = tr.energies["total"][idx], tr.q[:w + 1].copy(), tr.outputs[:w + 1].copy()
    samples[(cfg, dt)] = {  # node positions (k, 2, 2), joint forces (k, 4), energy drift
        "pos": np.stack([np.stack([tr.dof(f"x{n}")[idx], tr.dof(f"y{n}")[idx]], axis=1) for n in NODES], axis=1),
        "forces": np.stack([tr.output(k)[idx] for k in FORCES], axis=1),
        "drift": float(np.abs(energy - energy[0]).max())}
    del tr  # a fine-dt trajectory is large
    if interp:
        t_i, ti = best_of(lambda: simulate(m, w * dt, stepping=Stepping(dt=dt, alpha=cfg.alpha),
                                           raise_on_failure=False), 3)
        if ti.success:
            dy = (np.abs(ti.outputs - y).max(axis=0) / np.maximum(np.abs(y).max(axis=0), 1e-300)).max()
            row.update(interp_s=t_i / w * steps, interp_projected=w < steps,
                       newton_per_step=ti.stats["newton_iterations"] / max(ti.stats["steps"], 1),
                       paths_diff=max(float(np.abs(ti.q - q).max()), float(dy)))
    print(f"  {cfg.label:34s} dt {dt:7.0e}: compiled {ms(t_c)}, interpreted {ms(row['interp_s'])}", flush=True)
    return row


def fit_order(dts, errs, lo: float, hi: float) -> float:
    """Least-squares slope of log(error) vs log(dt) over lo <= dt <= hi."""
    d, e = np.asarray(dts), np.asarray(errs)
    m = (d >= lo * (1 - 1e-9)) & (d <= hi * (1 + 1e-9)) & np.isfinite(e) & (e > 0)
    return float(np.polyfit(np.log(d[m]), np.log(e[m]), 1)[0]) if m.sum() >= 2 else float("nan")


def cost_groups(rows: list[dict], key: str) -> dict[tuple[int, float], list[float]]:
    """The times ``key`` by (mesh, dt): alpha and the inertia form do not change the work per step."""
    groups: dict[tuple[int, float], list[float]] = {}
    for r in rows:
        if r[key] is not None and np.isfinite(r[key]):
            groups.setdefault((r["cfg"].elements, r["dt"]), []).append(r[key])
    return groups


def pick(rows: list[dict], key: str, pos_tol: float, force_tol: float) -> tuple[dict, float, int] | None:
    """The recommended row within both tolerances, its cost (median over its mesh and dt) and that median's n."""
    groups = cost_groups(rows, key)
    cost = {k: float(np.median(v)) for k, v in groups.items()}
    ok = [r for r in rows if r[key] is not None and np.isfinite(r[key]) and r["err"]["pos"] <= pos_tol
          and r["err"]["force_rel"] <= force_tol]
    if not ok:
        return None
    c_min = min(cost[(r["cfg"].elements, r["dt"])] for r in ok)
    near = [r for r in ok if cost[(r["cfg"].elements, r["dt"])] <= (1 + TIE) * c_min]
    best = min(near, key=lambda r: (r["cfg"].inertia != "lagrange", r["err"]["pos"], r[key]))
    k = (best["cfg"].elements, best["dt"])
    return best, cost[k], len(groups[k])


def analyse(plan: dict, rows: list[dict], samples: dict) -> dict:
    """Errors (set in the rows), orders in dt, the reference's own error, recommended settings, Pareto fronts."""
    fine, meshes, (lo, hi) = plan["dt_fine"], plan["meshes"], plan["fit"]
    lag_fine = {ne: samples.get((Config(ne, "lagrange", 0.0), fine)) for ne in meshes}
    ref = lag_fine[meshes[-1]]
    for r in rows:
        s, base = samples.get((r["cfg"], r["dt"])), samples.get((r["cfg"]._replace(alpha=0.0), fine))
        r["err"] = diff(s, ref) if s is not None else NAN
        r["err_dt"] = diff(s, base) if s is not None and base is not None else NAN  # time discretisation alone
        r["drift"] = s["drift"] if s is not None else np.nan
    orders = {}
    for cfg in dict.fromkeys(r["cfg"] for r in rows):
        rs = [r for r in rows if r["cfg"] == cfg and r["dt"] != fine]
        dts, ep, ef = [r["dt"] for r in rs], [r["err_dt"]["pos"] for r in rs], [r["err_dt"]["force_rel"] for r in rs]
        orders[cfg] = {"pos": fit_order(dts, ep, lo, hi), "force": fit_order(dts, ef, lo, hi),
                       "n": sum(lo * (1 - 1e-9) <= d <= hi * (1 + 1e-9) for d in dts)}
    # the reference's own error: time (same mesh at 2 dt, order 2: e = d / (2^2 - 1)) and mesh (geometric)
    d_time = diff(samples[(Config(meshes[-1], "lagrange", 0.0), 2 * fine)], ref)
    ref_time = {k: d_time[k] / 3.0 for k in NAN}
    mesh_d = {ne: diff(lag_fine[ne], ref) for ne in meshes[:-1]}
    mesh_ratio, ref_mesh = {}, dict(NAN)
    if len(meshes) >= 3:
        d_ab = diff(lag_fine[meshes[-3]], lag_fine[meshes[-2]])
        for k in NAN:
            mesh_ratio[k] = d_ab[k] / mesh_d[meshes[-2]][k]
            ref_mesh[k] = mesh_d[meshes[-2]][k] / (mesh_ratio[k] - 1.0) if mesh_ratio[k] > 1.0 else np.inf
    ref_err = {k: ref_time[k] + (ref_mesh[k] if np.isfinite(ref_mesh[k]) else 0.0) for k in NAN}
    seed_cmp = [{"ne": ne, "diff": diff(s, lag_fine[ne]), "seed_err": diff(s, ref)}
                for ne in meshes if (s := samples.get((Config(ne, "seed", 0.0), fine))) is not None]
    cand = [r for r in rows if r["ok"] and not r["is_ref"]]
    recs = []  # a `seed` pick (not energy consistent) is followed by the `lagrange` one
    for tol in (*LEVELS, MARGIN):
        resolved = ("yes" if np.isfinite(ref_mesh["pos"]) else "mesh part not estimated") if (
            ref_err["pos"] <= 0.1 * tol[0] and ref_err["force_rel"] <= 0.1 * tol[1]) else "**no**"
        for key, path in PATHS:
            recs.append({"tol": tol, "resolved": resolved, "key": key, "path": path, "pick": pick(cand, key, *tol)})
            if recs[-1]["pick"] is not None and recs[-1]["pick"][0]["cfg"].inertia == "seed":
                recs.append(dict(recs[-1], path=f"{path}, `lagrange` only", pick=pick(
                    [r for r in cand if r["cfg"].inertia == "lagrange"], key, *tol)))
    fronts = {}  # the non-dominated (time, error) points, both smaller is better, by time
    for key, _ in PATHS:
        for ek in ("pos", "force_rel"):
            pts = [(r[key], r["err"][ek], r) for r in cand if r[key] is not None]
            fronts[(key, ek)] = [r for t, e, r in sorted(pts, key=lambda p: p[0]) if not any(
                t2 <= t and e2 <= e and (t2 < t or e2 < e) for t2, e2, _ in pts)]
    return {"orders": orders, "d_time": d_time, "ref_time": ref_time, "ref_mesh": ref_mesh, "ref_err": ref_err,
            "mesh_d": mesh_d, "mesh_ratio": mesh_ratio, "seed_cmp": seed_cmp, "cand": cand, "recs": recs,
            "fronts": fronts}


def self_checks(rows: list[dict], an: dict) -> list[tuple]:
    """(check, value, passed, asserted); the orders for alpha < 0 are the theory's: reported, not asserted."""
    ref_err, ratio, tight = an["ref_err"], an["mesh_ratio"], min(LEVELS)
    out = [(f"order in dt of the node positions, {cfg.label}, is 2 (1.5 .. 2.5)", f"{o['pos']:.3f}",
            bool(1.5 <= o["pos"] <= 2.5), cfg.alpha == 0.0)
           for cfg, o in sorted(an["orders"].items(), key=lambda co: co[0] != CENTRE) if cfg == CENTRE or o["n"] >= 2]
    diffs = [r["paths_diff"] for r in rows if r["paths_diff"] is not None]
    worst, centre = max(diffs, default=np.nan), [r["ok"] for r in rows if r["cfg"] == CENTRE]
    out += [paths_check(worst, f"max abs on q, relative on the joint outputs, over every interpreted window "
                               f"({len(diffs)} runs)"),
            ("every run of the centre setting converges", f"{sum(centre)} / {len(centre)}", all(centre))]
    if np.isfinite(an["ref_mesh"]["pos"]):
        out += [(f"the reference's estimated error is below 1/10 of the tightest stated accuracy ({tight[0]:g} m, "
                 f"{tight[1]:g} %)", f"{ref_err['pos']:.1e} m, {ref_err['force_rel']:.1e} %",
                 ref_err["pos"] <= 0.1 * tight[0] and ref_err["force_rel"] <= 0.1 * tight[1]),
                ("the mesh converges: differences shrink by more than 2x per halving of the element size",
                 ", ".join(f"{k} {v:.1f}" for k, v in ratio.items()), all(v > 2.0 for v in ratio.values()))]
    speed = [r["interp_s"] / r["compiled_s"] for r in an["cand"] if r["interp_s"] is not None and r["dt"] <= 1e-3]
    head = next(rc["pick"] for rc in an["recs"] if rc["tol"] == HEADLINE and rc["key"] == "compiled_s")
    return out + [("compiled is faster than interpreted at every dt <= 1e-3", f"speed-up {min(speed):.1f} .. "
                   f"{max(speed):.1f}" if speed else "no data", bool(speed) and min(speed) > 1.0),
                  (f"a measured setting meets the headline accuracy ({HEADLINE[0]:g} m, {HEADLINE[1]:g} %)",
                   head[0]["cfg"].label if head else "none", head is not None)]


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    """Run every setting, write the page and the Pareto plot, assert the self-checks."""
    banner, plan = Banner("tradeoff", quick), plan_for(quick)
    models, rows, samples = {}, [], {}
    for cfg, dt, interp in tasks_for(plan):
        if cfg[:2] not in models:
            models[cfg[:2]] = twobar(cfg.elements, inertia=cfg.inertia)
        compiled_library(integrator_for(models[cfg[:2]], alpha=cfg.alpha))  # the one-off build: cached, untimed
        rows.append(run(cfg, dt, interp, plan, models[cfg[:2]], samples))
    vrow = next(r for r in rows if r["cfg"] == CENTRE and r["dt"] == plan["validate_dt"])  # checks the projection
    v_full, _ = best_of(lambda: simulate(models[CENTRE[:2]], plan["t_end"],
                                         stepping=Stepping(dt=plan["validate_dt"], alpha=0.0)), 3)
    an = dict(analyse(plan, rows, samples), vcheck=(v_full, vrow))
    check_lines, failed = checks(self_checks(rows, an))
    write_outputs("tradeoff", out_dir, quick, "\n".join(_page(quick, plan, rows, an, banner) + check_lines),
                  png(_figure(an, plan)))
    assert_checks(failed)
    return dict(an, rows=rows)


def star(r: dict, key: str) -> str:  # an interpreted time projected from the first steps
    return "*" if key == "interp_s" and r["interp_projected"] else ""


GRIDS = (("Position error against the reference (m)", lambda r: f"{r['err']['pos']:.2e}"),
         ("Joint force error against the reference (% of peak)", lambda r: f"{r['err']['force_rel']:.2e}"),
         ("Time-discretisation error of the positions: against the same model at the last row's dt, alpha = 0 (m)",
          lambda r: fnum(r["err_dt"]["pos"], ".2e", "")),
         ("Compiled wall time", lambda r: ms(r["compiled_s"])),
         ("Newton iterations per step (interpreted)", lambda r: fnum(r["newton_per_step"], ".2f", "")),
         ("Energy drift, max |E(t) - E(0)| over the grid (J)", lambda r: fnum(r["drift"], ".2e", "")))


def _page(quick: bool, plan: dict, rows: list[dict], an: dict, banner: Banner) -> list[str]:
    t_end, fine, meshes = plan["t_end"], plan["dt_fine"], plan["meshes"]
    v_full, vrow = an["vcheck"]
    spread = [max(v) / min(v) for v in cost_groups(an["cand"], "compiled_s").values() if len(v) >= 3]
    L = ["# Speed-accuracy trade-off: twobar", "", banner.line(), "", "## Setup", "", *table(["", "value"], [
        ["horizon", f"{t_end:g} s"], ["reference", f"{meshes[-1]} el., lagrange, alpha 0, dt = {fine:g} s"],
        ["interpreted runs: time measured over the first (steps; longer runs projected, marked `*`)", plan["window"]],
        [f"projection check: centre setting, dt = {plan['validate_dt']:g} s, interpreted over the horizon, measured / "
         "projected (ratio)", f"{v_full:.2f} s / {vrow['interp_s']:.2f} s (**{v_full / vrow['interp_s']:.2f}**)"],
        ["timing noise: compiled time max / min among settings with the same mesh and dt, median (max; groups)",
         f"{np.median(spread):.2f} ({max(spread):.2f}; {len(spread)})" if spread else "-"]], "lr"), ""]
    recs, note = [], {HEADLINE: " (**headline**)", MARGIN: " (headline with a 20 % margin)"}
    for rc in an["recs"]:
        (r, cost, n), key = rc["pick"] or (None, None, None), rc["key"]
        recs.append([f"{rc['tol'][0]:g} m / {rc['tol'][1]:g} %{note.get(rc['tol'], '')}", rc["resolved"], rc["path"],
                     *(["none measured", *[""] * 7] if r is None else [
                         f"{r['dt']:g}", fmt_alpha(r["cfg"].alpha), r["cfg"].elements, r["cfg"].inertia,
                         f"{ms(cost)}{star(r, key)} ({n})", f"{ms(r[key])}{star(r, key)}",
                         *(f"{r['err'][k]:.2e}" for k in NAN)])])
    L += ["## Recommended settings for a stated accuracy", "", *table(
        ["accuracy: positions / forces", "resolved by the reference", "path", "dt (s)", "alpha", "elements/bar",
         "inertia", "cost (median of n)", "this setting's time", "position error (m)", "force error (%)"], recs,
        "lclrrrlrrrr"), ""]
    ref_rows = [(f"reference vs {meshes[-1]} el., dt = {2 * fine:g} s", an["d_time"]),
                *((f"reference vs {ne} el., dt = {fine:g} s (mesh error of {ne} el.)", d)
                  for ne, d in an["mesh_d"].items()),
                ("estimated error of the reference: time (first row / (2^2 - 1))", an["ref_time"]),
                ("estimated error of the reference: mesh (geometric extrapolation)", an["ref_mesh"]),
                ("estimated error of the reference: total", an["ref_err"])]
    L += ["## The reference and its self-convergence", "", *table(
        ["comparison", "position diff. (m)", "force diff. (%)"],
        [[name, *(fnum(d[k], ".2e", "not estimated") for k in NAN)] for name, d in ref_rows], "lrr"), ""]
    rowmap = {(r["cfg"], r["dt"]): r for r in rows}
    for title, cols in (("dt x alpha x inertia form (1 element per bar)", [Config(1, form, a) for form, k in (
            ("lagrange", "alphas"), ("seed", "seed_alphas")) for a in plan[k]]), ("elements per bar (`lagrange`)", [
            Config(ne, "lagrange", a) for a in (0.0, *plan["alt_alphas"]) for ne in meshes])):
        dts = sorted({r["dt"] for r in rows if r["cfg"] in cols}, reverse=True)
        L += [f"## Factor: {title}", ""]
        for grid_title, fmt in GRIDS:
            L += [f"**{grid_title}**", "", *table(["dt (s)", "steps", *(c.label for c in cols)], [
                [f"{dt:g}", int(round(t_end / dt)), *("" if (r := rowmap.get((c, dt))) is None else "failed"
                                                      if not r["ok"] else "reference" if r["is_ref"] else fmt(r)
                                                      for c in cols)] for dt in dts], "r" * (2 + len(cols))), ""]
    L += ["## Convergence order in dt", "", "**Fitted over {:g} <= dt <= {:g} s**".format(*plan["fit"]), "",
          *table(["setting", "points", "order, node positions", "order, joint forces"],
                 [[cfg.label, o["n"], *(fnum(o[k], ".3f", "") for k in ("pos", "force"))]
                  for cfg, o in an["orders"].items() if o["n"] >= 2], "lrrr"), "",
          "## Factor: inertia form (`seed` vs `lagrange`)", "", f"**Both forms at dt = {fine:g} s, alpha = 0**", "",
          *table(["elements/bar", "seed - lagrange, positions (m)", "seed - lagrange, forces (%)",
                  "seed vs reference (m)"], [[c["ne"], *(f"{c['diff'][k]:.2e}" for k in NAN),
                                              f"{c['seed_err']['pos']:.2e}"] for c in an["seed_cmp"]], "rrrr"),
          "", "## Pareto fronts", "", f"![Pareto plot](../figures/tradeoff{'_quick' * quick}.png)", ""]
    if failed := [r for r in rows if not r["ok"]]:
        L += ["Runs that failed: " + "; ".join(f"{r['cfg'].label} dt {r['dt']:g}: {r['message']}" for r in failed), ""]
    return L


def _figure(an: dict, plan: dict):
    """Error against wall time, compiled and interpreted, positions and forces, with the Pareto fronts."""
    cand, fig, handles = an["cand"], _new_figure((13, 10.5)), {}
    axes, meshes = fig.subplots(2, 2), sorted({r["cfg"].elements for r in cand})
    alphas = list(dict.fromkeys(r["cfg"].alpha for r in cand if r["cfg"].elements == 1))
    cfgs = sorted({r["cfg"] for r in cand}, key=lambda c: (c.elements, c.inertia, -c.alpha))
    for col, (key, path) in enumerate(PATHS):
        for row, ek in enumerate(("pos", "force_rel")):
            ax = axes[row, col]
            for c in cfgs:
                pts = sorted((r for r in cand if r["cfg"] == c and r[key] is not None), key=lambda r: r["dt"])
                ls = "-" if c.inertia == "lagrange" else ":"
                color, marker = ((f"C{alphas.index(c.alpha)}", "o" if ls == "-" else "s") if c.elements == 1 else
                                 (f"C{5 + meshes.index(c.elements)}", ("^" if c.alpha == 0 else "v") if ls == "-"
                                  else "D"))
                ax.plot([r[key] for r in pts], [r["err"][ek] for r in pts], ls=ls, color=color, lw=0.8, alpha=0.7)
                for r in pts:  # hollow: interpreted time projected from the first steps
                    ax.plot(r[key], r["err"][ek], marker=marker, color=color, ms=5, ls="none",
                            mfc="none" if key == "interp_s" and r["interp_projected"] else color)
                handles[c] = Line2D([], [], color=color, marker=marker, ls=ls, label=c.label)
            fr = an["fronts"][(key, ek)]
            ax.step([r[key] for r in fr], [r["err"][ek] for r in fr], where="post", color="k", lw=1.2, alpha=0.8)
            ax.plot([r[key] for r in fr], [r["err"][ek] for r in fr], "o", ms=11, mfc="none", mec="k", mew=1.3)
            for lv in sorted({lv[row] for lv in LEVELS}):
                ax.axhline(lv, color="0.5", ls="--", lw=0.8)
            ax.set(xscale="log", yscale="log", xlabel=f"wall time of simulate() over {plan['t_end']:g} s, "
                   f"{'compiled C' if col == 0 else 'interpreted'} (s)",
                   ylabel="max error, nodes 3 and 5 (m)" if ek == "pos" else "max joint force error (% of peak)")
            ax.grid(True, which="both", alpha=0.25)
            ax.tick_params(which="minor", labelsize="x-small")  # a narrow log range labels its minor ticks
            ax.set_title(f"{'node positions' if ek == 'pos' else 'joint forces'}, "
                         f"{path + ' (hollow: projected from the first steps)' * col}", fontsize="medium")
    handles["front"] = Line2D([], [], color="k", marker="o", mfc="none", ms=9, label="Pareto front (non-dominated)")
    fig.legend(handles=list(handles.values()), loc="outside lower center", ncol=4, fontsize="small")
    fig.suptitle(f"twobar, {plan['t_end']:g} s: error against a converged reference vs wall time "
                 f"(dt {max(plan['dts']):g} .. {plan['dt_fine']:g} s; dashed: stated accuracies)")
    return fig


if __name__ == "__main__":
    cli(__doc__, main)
