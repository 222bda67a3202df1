"""Speed-accuracy trade-off: which step dt, HHT alpha, mesh and inertia form reach a stated accuracy at
the least wall time, compiled or interpreted?

Set-up and how to read the page: docs/studies/tradeoff.md. Run: ``python studies/tradeoff.py`` (10-15 min;
``--quick``: 0.5 s, a reduced grid).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from _study import Banner, best_of, cli, png, table, write_outputs
from _tradeoff import CENTRE, GRID_STEP, Config, Models, fmt_alpha, fmt_e, grid, measure, ms, plan_for, run, tasks_for

from casflex.simulate import simulate

LEVELS = ((1e-3, 5.0), (1e-4, 1.0), (1e-5, 0.1))  # stated accuracies: (node positions, m; joint forces, %)
HEADLINE = (1e-4, 1.0)
TIE = 0.15  # recommended: among settings within 15 % of the cheapest (timing noise), lagrange first


def _pareto(points: list[tuple[float, float]]) -> list[int]:
    """Indices of the non-dominated (time, error) points (both smaller is better), by time."""
    out = [i for i, (ti, ei) in enumerate(points) if not any(
        tj <= ti and ej <= ei and (tj < ti or ej < ei) for j, (tj, ej) in enumerate(points) if j != i)]
    return sorted(out, key=lambda i: points[i][0])


def _pick(rows: list[dict], key: str, pos_tol: float, force_tol: float) -> tuple[dict, float, int] | None:
    """The recommended row within both tolerances, the cost of its (mesh, dt) and how many runs that
    median is of. Cost: alpha and the inertia form do not change the work per step, so a setting's cost is
    the median time over the settings with the same mesh and dt (robust to timing noise). Among the
    qualifying settings within TIE of the cheapest: ``lagrange`` first, then the most accurate."""
    groups: dict[tuple[int, float], list[float]] = {}
    for r in rows:
        if r.get(key) is not None and np.isfinite(r[key]):
            groups.setdefault((r["cfg"].elements, r["dt"]), []).append(r[key])
    cost = {k: float(np.median(v)) for k, v in groups.items()}
    ok = [r for r in rows if r.get(key) is not None and np.isfinite(r[key]) and r["err"]["pos"] <= pos_tol
          and r["err"]["force_rel"] <= force_tol]
    if not ok:
        return None
    c_min = min(cost[(r["cfg"].elements, r["dt"])] for r in ok)
    near = [r for r in ok if cost[(r["cfg"].elements, r["dt"])] <= (1 + TIE) * c_min]
    best = min(near, key=lambda r: (r["cfg"].inertia != "lagrange", r["err"]["pos"], r[key]))
    k = (best["cfg"].elements, best["dt"])
    return best, cost[k], len(groups[k])


def _analyse(plan: dict, rows: list[dict], samples: dict) -> dict:
    """The errors (see _tradeoff.measure), then the recommended settings and the Pareto fronts."""
    an = measure(plan, rows, samples)
    ref_err, ref_mesh = an["ref_err"], an["ref_mesh"]
    cand = [r for r in rows if r["ok"] and not r["is_ref"]]
    recs = []
    for pos_tol, f_tol in LEVELS:
        resolved = bool(ref_err["pos"] <= 0.1 * pos_tol and ref_err["force_rel"] <= 0.1 * f_tol)
        recs.append({"pos": pos_tol, "force": f_tol,
                     "resolved": None if resolved and not np.isfinite(ref_mesh["pos"]) else resolved,
                     "compiled": _pick(cand, "compiled_s", pos_tol, f_tol), "interp": _pick(cand, "interp_s", pos_tol,
                                                                                             f_tol)})
    fronts = {}
    for key in ("compiled_s", "interp_s"):
        pts = [r for r in cand if r[key] is not None]
        for ek in ("pos", "force_rel"):
            fronts[(key, ek)] = [pts[i] for i in _pareto([(r[key], r["err"][ek]) for r in pts])]
    return dict(an, cand=cand, recs=recs, fronts=fronts)


def _checks(rows: list[dict], an: dict) -> list[tuple[str, bool, str, bool]]:
    """(name, passed, value, asserted). The orders for alpha < 0 are the theory's expectation (HHT-alpha is
    second order for every alpha): reported, not asserted (a failure would be a finding about the integrator)."""
    orders, ref_err, ratio = an["orders"], an["ref_err"], an["mesh_ratio"]
    out = [(f"order in dt of the node positions, {CENTRE.label}, is 2 (1.5 .. 2.5)",
            1.5 <= orders[CENTRE]["pos"] <= 2.5, f"{orders[CENTRE]['pos']:.3f}", True)]
    out += [(f"order in dt of the node positions, {cfg.label}, is 2 (1.5 .. 2.5)"
             + ("" if cfg.alpha == 0.0 else " [theory; reported, not asserted]"), bool(1.5 <= o["pos"] <= 2.5),
             f"{o['pos']:.3f}", cfg.alpha == 0.0) for cfg, o in orders.items() if cfg != CENTRE and o["n"] >= 2]
    diffs = [r["paths_diff"] for r in rows if r["paths_diff"] is not None]
    worst = max(diffs) if diffs else np.nan
    out.append(("compiled and interpreted runs agree to 1e-8 (max abs on q, relative on the joint outputs) over "
                f"every interpreted window ({len(diffs)} runs)", bool(worst <= 1e-8), f"{worst:.1e}", True))
    centre = [r["ok"] for r in rows if r["cfg"] == CENTRE]
    out.append(("every run of the centre setting converges", all(centre), f"{sum(centre)} / {len(centre)}", True))
    tight = min(LEVELS)
    if np.isfinite(an["ref_mesh"]["pos"]):
        out.append((f"the reference's estimated error is below 1/10 of the tightest stated accuracy ({tight[0]:g} m, "
                    f"{tight[1]:g} %)", ref_err["pos"] <= 0.1 * tight[0] and ref_err["force_rel"] <= 0.1 * tight[1],
                    f"{ref_err['pos']:.1e} m, {ref_err['force_rel']:.1e} %", True))
        out.append(("the mesh converges: differences shrink by more than 2x per halving of the element size",
                    all(v > 2.0 for v in ratio.values()), ", ".join(f"{k} {v:.1f}" for k, v in ratio.items()), True))
    speed = [r["interp_s"] / r["compiled_s"] for r in an["cand"] if r["interp_s"] is not None and r["dt"] <= 1e-3]
    out.append(("compiled is faster than interpreted at every dt <= 1e-3", bool(speed) and min(speed) > 1.0,
                f"speed-up {min(speed):.1f} .. {max(speed):.1f}" if speed else "no data", True))
    head = next(r for r in an["recs"] if (r["pos"], r["force"]) == HEADLINE)["compiled"]
    out.append((f"a measured setting meets the headline accuracy ({HEADLINE[0]:g} m, {HEADLINE[1]:g} %)",
                head is not None, head[0]["cfg"].label if head else "none", True))
    return out


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    """Run every setting, write the page and the Pareto plot, assert the self-checks."""
    banner = Banner("tradeoff", quick)
    plan = plan_for(quick)
    models, rows, samples = Models(), [], {}
    tasks = tasks_for(plan)
    print(f"{len(tasks)} settings, horizon {plan['t_end']} s, reference dt {plan['dt_fine']:g} s")
    for cfg, dt, interp in tasks:
        row, s = run(cfg, dt, interp, plan, models(cfg))
        rows.append(row)
        if s is not None:
            samples[(cfg, dt)] = s
    # projection check: the interpreted centre run over the whole horizon at one dt
    vrow = next(r for r in rows if r["cfg"] == CENTRE and r["dt"] == plan["validate_dt"])
    v_full, _ = best_of(lambda: simulate(models(CENTRE), plan["t_end"], dt=plan["validate_dt"], alpha=0.0), 3)
    an = _analyse(plan, rows, samples)
    an.update(vcheck=(v_full, vrow, v_full / vrow["interp_s"]), builds=models.builds)
    checks = _checks(rows, an)
    page = _page(quick, plan, rows, an, checks, banner)
    write_outputs("tradeoff", out_dir, quick, "\n".join(page) + "\n", png(_figure(an, plan)))
    failed = [c for c in checks if c[3] and not c[1]]
    assert not failed, "self-checks failed: " + "; ".join(f"{n} ({v})" for n, _, v, _ in failed)
    return {"rows": rows, "orders": an["orders"], "recommendations": an["recs"], "reference_error": an["ref_err"],
            "seed_vs_lagrange": an["seed_cmp"], "checks": checks}


# -- page and figure ----------------------------------------------------------------------------

def _noise(rows: list[dict]) -> str:
    """Timing noise of this run: spread of compiled times between settings with the same work."""
    groups: dict[tuple[int, float], list[float]] = {}
    for r in rows:
        if r["ok"] and r["compiled_s"] and not r["is_ref"]:
            groups.setdefault((r["cfg"].elements, r["dt"]), []).append(r["compiled_s"])
    spread = [max(v) / min(v) for v in groups.values() if len(v) >= 3]
    return (f" Timing noise of this run: settings with the same mesh and dt (same work per step, measured at "
            f"different moments of the run) differ in compiled time by a factor {np.median(spread):.2f} (median "
            f"over {len(spread)} groups, at most {max(spread):.2f}).") if spread else ""


def _setting(r: dict, cost: float, inertia: bool = True) -> str:
    return (f"dt = {r['dt']:g} s, alpha = {fmt_alpha(r['cfg'].alpha)}, {r['cfg'].elements} el./bar"
            + (f", {r['cfg'].inertia}" if inertia else "") + f", compiled {ms(cost)} (error {r['err']['pos']:.2e} m, "
            f"{r['err']['force_rel']:.2e} %)")


def _recommendations(plan: dict, rows: list[dict], recs: list[dict]) -> list[str]:
    L = ["## Recommended settings for a stated accuracy", "",
         "Chosen by the script from the measured tables, by the rule in [studies/tradeoff.md](../studies/tradeoff.md"
         "#recommended-settings)." + _noise(rows), ""]

    def cells(rc: dict, key: str) -> list:
        if rc[key] is None:
            return ["none measured", *[""] * 7]
        r, cost, n = rc[key]
        star = "*" if key == "interp" and r["interp_projected"] else ""
        return [f"{r['dt']:g}", fmt_alpha(r["cfg"].alpha), r["cfg"].elements, r["cfg"].inertia,
                f"{ms(cost)}{star} ({n})", f"{ms(r[key + '_s'])}{star}", f"{r['err']['pos']:.2e}",
                f"{r['err']['force_rel']:.2e}"]

    L += [*table(["accuracy: positions / forces", "resolved by the reference", "path", "dt (s)", "alpha",
                  "elements/bar", "inertia", "cost (median of n)", "this setting's time", "position error (m)",
                  "force error (%)"],
                 [[f"{rc['pos']:g} m / {rc['force']:g} %", {True: "yes", False: "**no**", None: "mesh part not "
                                                              "estimated"}[rc["resolved"]], path, *cells(rc, key)]
                  for rc in recs for key, path in (("compiled", "compiled"), ("interp", "interpreted"))],
                 "lclrrrlrrrr"), ""]
    head = next(rc for rc in recs if (rc["pos"], rc["force"]) == HEADLINE)["compiled"]
    if head is not None:
        r, cost, n = head
        pool = [x for x in rows if x["ok"] and not x["is_ref"]]
        tol = (0.8 * HEADLINE[0], 0.8 * HEADLINE[1])
        margin = _pick(pool, "compiled_s", *tol)
        margin_lag = _pick([x for x in pool if x["cfg"].inertia == "lagrange"], "compiled_s", *tol)
        s = (f"**For node positions within {HEADLINE[0]:g} m and joint forces within {HEADLINE[1]:g} % over "
             f"{plan['t_end']:g} s: dt = {r['dt']:g} s, alpha = {fmt_alpha(r['cfg'].alpha)}, "
             f"elements = {r['cfg'].elements} "
             f"per bar, inertia = {r['cfg'].inertia}, compiled: {ms(cost)}** (median over the {n} measured settings "
             f"with this mesh and dt; this setting {ms(r['compiled_s'])}; measured error {r['err']['pos']:.2e} m, "
             f"{r['err']['force_rel']:.2e} %" + (f"; interpreted, same setting: {ms(r['interp_s'])}"
                                                 f"{'*' if r['interp_projected'] else ''}" if r["interp_s"] else "")
             + ").")
        if r["err"]["pos"] > tol[0] or r["err"]["force_rel"] > tol[1]:
            s += (f" The position error is {r['err']['pos'] / HEADLINE[0]:.0%} of the tolerance; with a 20 % margin "
                  f"(errors below {tol[0]:g} m and {tol[1]:g} %): "
                  + (_setting(margin[0], margin[1]) if margin is not None else "none measured")
                  + (f"; with `lagrange`: {_setting(margin_lag[0], margin_lag[1], inertia=False)}" if margin is not None
                     and margin[0]["cfg"].inertia != "lagrange" and margin_lag is not None else "") + ".")
        L.append(s)
    if any(rc[k] is not None and rc[k][0]["cfg"].inertia == "seed" for rc in recs for k in ("compiled", "interp")):
        L += ["", "A `seed` setting is picked for some accuracy: no `lagrange` setting within the tie margin meets "
              "it (on a coarse mesh `seed` happens to land closer to the converged solution, see 'Inertia form'), "
              "but it is not energy consistent; the `lagrange` alternatives are in the tables."]
    return L + [""]


def _page(quick: bool, plan: dict, rows: list[dict], an: dict, checks: list, banner: Banner) -> list[str]:
    t_end, fine, window, meshes = plan["t_end"], plan["dt_fine"], plan["window"], plan["meshes"]
    rowmap = {(r["cfg"], r["dt"]): r for r in rows}
    v_full, vrow, v_ratio = an["vcheck"]
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else 0.0
    L = ["# Speed-accuracy trade-off: twobar", "", banner.line() + (
        " **All absolute times were measured under load** (shared machine, other jobs running); the ratios "
        "compiled/interpreted, measured side by side, are more reliable." if max(banner.load0, load) > 0.5 * (
            os.cpu_count() or 1) else ""), "", "## Setup", "",
         f"Horizon **{t_end:g} s**; reference **{meshes[-1]} elements per bar, alpha = 0, dt = {fine:g} s, "
         f"`lagrange`**; errors on the grid t = 0, {GRID_STEP:g}, ..., {t_end:g} s. Interpreted time: over the whole "
         f"horizon up to {window} steps, else over the **first {window} steps**, projected (marked `*`). Projection "
         "check: centre setting at dt = "
         f"{plan['validate_dt']:g} s, interpreted over the whole {t_end:g} s measured {v_full:.2f} s against "
         f"{vrow['interp_s']:.2f} s projected from {vrow['interp_steps']} steps (ratio measured/projected "
         f"**{v_ratio:.2f}**" + ("; the projected interpreted times are probably optimistic by about this factor)."
                                 if v_ratio > 1.15 else "; the projected interpreted times are probably pessimistic "
                                 "by about this factor)." if v_ratio < 0.87 else ").")
         + " The scene, the error measures, the timing and the reading of the results: "
         "[studies/tradeoff.md](../studies/tradeoff.md).", ""]
    L += _recommendations(plan, rows, an["recs"])
    d_time, rt, rm, re_, ratio = an["d_time"], an["ref_time"], an["ref_mesh"], an["ref_err"], an["mesh_ratio"]
    L += ["## The reference and its self-convergence", "", *table(
        ["comparison", "position diff. (m)", "force diff. (%)"],
        [[f"reference vs {meshes[-1]} el., dt = {2 * fine:g} s", f"{d_time['pos']:.2e}", f"{d_time['force_rel']:.2e}"]]
        + [[f"reference vs {ne} el., dt = {fine:g} s (mesh error of {ne} el.)", f"{d['pos']:.2e}",
            f"{d['force_rel']:.2e}"] for ne, d in an["mesh_d"].items()], "lrr")]
    L += ["", f"Estimated error of the reference: time discretisation {rt['pos']:.1e} m / {rt['force_rel']:.1e} % "
          "(difference to 2 dt divided by 2^2 - 1, order 2 as measured below); "
          + (f"mesh {rm['pos']:.1e} m / {rm['force_rel']:.1e} % (geometric extrapolation: the difference between "
             f"{meshes[-3]} and {meshes[-2]} el. is {ratio['pos']:.1f}x (positions) and {ratio['force_rel']:.1f}x "
             f"(forces) that between {meshes[-2]} and {meshes[-1]} el.)" if np.isfinite(rm["pos"]) else
             "mesh: not estimated (needs three meshes; quick mode has two)")
          + f". Total {re_['pos']:.1e} m / {re_['force_rel']:.1e} %.", ""]

    def interp_cell(r):
        return "" if r["interp_s"] is None else (f"{ms(r['interp_s'])}{'*' if r['interp_projected'] else ''} "
                                                 f"(x{r['interp_s'] / r['compiled_s']:.0f})")

    pos, force = (lambda r: f"{r['err']['pos']:.2e}"), (lambda r: f"{r['err']['force_rel']:.2e}")
    dts = [*plan["dts"], fine]
    lag = [Config(1, "lagrange", a) for a in plan["alphas"]]
    alphas = [f"alpha {fmt_alpha(a)}" for a in plan["alphas"]]
    L += ["## Factor: dt x alpha (1 element per bar, `lagrange`)", ""]
    for title, fmt in (("Position error against the reference (m)", pos),
                       ("Joint force error against the reference (% of peak)", force),
                       (f"Time-discretisation error of the positions: against the same model at dt = {fine:g} s, "
                        "alpha = 0 (m)", lambda r: fmt_e(r["err_dt"]["pos"])),
                       ("Compiled wall time", lambda r: ms(r["compiled_s"])),
                       ("Interpreted wall time (* projected from the first steps; in brackets the ratio to compiled)",
                        interp_cell)):
        L += grid(title, lag, alphas, dts, rowmap, fmt, t_end)
    nwt = [f"{r['newton_per_step']:.2f} (dt {r['dt']:g})" for r in rows
           if r["cfg"] == CENTRE and r["newton_per_step"] is not None and r["newton_per_step"] > 1.005]
    L += [f"Newton iterations per step (interpreted runs of the centre setting): 1.00 at every dt except "
          f"{', '.join(nwt) if nwt else 'none'}.", ""]
    L += _orders(plan, an["orders"], rowmap)
    mesh = [Config(ne, "lagrange", 0.0) for ne in meshes]
    heads = [f"{ne} el." for ne in meshes]
    mesh_dts = sorted({r["dt"] for r in rows if r["cfg"] in mesh}, reverse=True)
    L += ["## Factor: elements per bar (alpha = 0, `lagrange`)", ""]
    for title, fmt in (("Position error against the reference (m)", pos), ("Joint force error (% of peak)", force),
                       ("Compiled wall time", lambda r: ms(r["compiled_s"])),
                       ("Interpreted wall time (* projected; ratio to compiled)", interp_cell)):
        L += grid(title, mesh, heads, mesh_dts, rowmap, fmt)
    if plan["alt_alpha"] is not None:
        L += grid(f"alpha = {fmt_alpha(plan['alt_alpha'])}: position error (m) / force error (%) / compiled wall time",
                   [c._replace(alpha=plan["alt_alpha"]) for c in mesh], heads, plan["mesh_dts"], rowmap,
                   lambda r: f"{pos(r)} / {force(r)} / {ms(r['compiled_s'])}")
    L += _inertia(plan, rows, an["seed_cmp"])
    seed = [Config(1, "seed", a) for a in plan["seed_alphas"]]
    L += grid("`seed`, 1 element per bar: position error against the reference (m)", seed,
               [f"alpha {fmt_alpha(a)}" for a in plan["seed_alphas"]], dts, rowmap, pos, t_end)
    L += grid("`seed`, 1 element per bar: joint force error (% of peak)", seed,
               [f"alpha {fmt_alpha(a)}" for a in plan["seed_alphas"]], dts, rowmap, force, t_end)
    L += ["## Pareto fronts", "", f"![Pareto plot](../figures/tradeoff{'_quick' * quick}.png)", "",
          "Non-dominated settings (no other measured setting is both faster and more accurate), node positions:", "",
          *table(["path", "setting", "dt (s)", "wall time", "position error (m)", "force error (%)"],
                 [[path, r["cfg"].label, f"{r['dt']:g}",
                   ms(r[key]) + ("*" if key == "interp_s" and r["interp_projected"] else ""), pos(r), force(r)]
                  for key, path in (("compiled_s", "compiled"), ("interp_s", "interpreted"))
                  for r in an["fronts"][(key, "pos")]], "llrrrr"),
          "", "## One-off builds (not in the times above)", "",
          *table(["setting", "dofs", "integrator build (s)", "C library (s)"],
                 [[cfg.label, b["n_dof"], f"{b['integrator_s']:.2f}",
                   f"{b['library_s']:.2f} ({'cached' if b['cached'] else 'compiled'})"]
                  for cfg, b in an["builds"].items()], "lrrr"), ""]
    if failed := [r for r in rows if not r["ok"]]:
        L += ["Runs that failed: " + "; ".join(f"{r['cfg'].label} dt {r['dt']:g}: {r['message']}" for r in failed), ""]
    return L + ["## Self-checks", "", "Asserted checks stop the script when they fail (after this page is written).",
                "",
                *table(["check", "value", "asserted", "result"],
                       [[name, val, "yes" if asserted else "no", "pass" if ok else "**FAIL**"]
                        for name, ok, val, asserted in checks], "llcc")]


def _orders(plan: dict, orders: dict, rowmap: dict) -> list[str]:
    small, fine = plan["fit_small"], plan["dt_fine"]
    L = ["## Convergence order in dt", "",
         f"Least-squares slope of log(error) vs log(dt) over {plan['fit'][0]:g} <= dt <= {plan['fit'][1]:g} s, the "
         f"error measured against the same model (mesh, inertia form) at dt = {fine:g} s, alpha = 0."
         + (f" The last two columns fit the small steps only, {small[0]:g} <= dt <= {small[1]:g} s." if small else ""),
         "", *table(["setting", "points", "order, node positions", "order, joint forces",
                     *(["order, positions, small dt", "order, forces, small dt"] if small else [])],
                    [[cfg.label, o["n"], f"{o['pos']:.3f}", f"{o['force']:.3f}",
                      *([fmt_e(o["pos_small"], ".3f"), fmt_e(o["force_small"], ".3f")] if small else [])]
                     for cfg, o in orders.items() if o["n"] >= 2], "lrrr" + "rr" * bool(small))]
    lin = [(a, r["err_dt"]["pos"]) for a in plan["alphas"] if a != 0.0
           and (r := rowmap.get((Config(1, "lagrange", a), fine))) is not None]
    return L + ([""] + ([f"Difference between alpha < 0 and alpha = 0 at the same dt = {fine:g} s (1 el., `lagrange`), "
                         "divided by |alpha|: "
                         + ", ".join(f"{v / abs(a):.3e} m (alpha {fmt_alpha(a)})" for a, v in lin)
                         + ": proportional to alpha.", ""] if lin else []))


def _inertia(plan: dict, rows: list[dict], seed_cmp: list[dict]) -> list[str]:
    fine = plan["dt_fine"]
    L = ["## Factor: inertia form (`seed` vs `lagrange`)", "",
         f"Both forms on every mesh at dt = {fine:g} s, alpha = 0 (how to read it: "
         "[studies/tradeoff.md](../studies/tradeoff.md#inertia-form)):", "",
         *table(["elements/bar", "seed - lagrange, positions (m)", "seed - lagrange, forces (%)",
                 "seed vs reference (m)", "lagrange vs reference (m)"],
                [[c["ne"], f"{c['diff']['pos']:.2e}", f"{c['diff']['force_rel']:.2e}", f"{c['seed_err']['pos']:.2e}",
                  "0 (reference)" if c["lag_err"] is None else f"{c['lag_err']['pos']:.2e}"] for c in seed_cmp],
                "rrrrr"), ""]
    dr = [(r["cfg"].inertia, r["dt"], r["drift"]) for r in rows
          if r["cfg"].elements == 1 and r["cfg"].alpha == 0.0 and r["dt"] in (1e-3, fine) and r["ok"]]
    return L + (["Energy drift, max |E(t) - E(0)| over the grid (1 el., alpha = 0; gravity and strain energy "
                 "included): " + ", ".join(f"{i} dt {d:g}: {v:.2e} J" for i, d, v in dr) + ".", ""] if dr else [])


def _figure(an: dict, plan: dict):
    """Error against wall time, compiled and interpreted, positions and forces, with the Pareto fronts."""
    from matplotlib.lines import Line2D

    from casflex.plotting._figure import _new_figure

    cand = an["cand"]
    fig = _new_figure((13, 10.5))
    axes = fig.subplots(2, 2)
    alphas = list(dict.fromkeys(r["cfg"].alpha for r in cand if r["cfg"].elements == 1))
    meshes = sorted({r["cfg"].elements for r in cand})

    def series(c: Config) -> str:
        return (f"alpha {fmt_alpha(c.alpha)}, 1 el., {c.inertia}" if c.elements == 1 else
                f"{c.elements} el., alpha {fmt_alpha(c.alpha)}, {c.inertia}")

    def style(c: Config) -> tuple[str, str, str]:
        ls = "-" if c.inertia == "lagrange" else ":"
        if c.elements == 1:
            return f"C{alphas.index(c.alpha)}", "o" if c.inertia == "lagrange" else "s", ls
        return f"C{5 + meshes.index(c.elements)}", ("^" if c.alpha == 0.0 else "v") if ls == "-" else "D", ls

    cfgs = list(dict.fromkeys(r["cfg"] for r in sorted(cand, key=lambda r: (r["cfg"].elements, r["cfg"].inertia,
                                                                            -r["cfg"].alpha))))
    names = list(dict.fromkeys(series(c) for c in cfgs))
    handles = {}
    for col, key in enumerate(("compiled_s", "interp_s")):
        for row, ek in enumerate(("pos", "force_rel")):
            ax = axes[row, col]
            for name in names:
                pts = sorted((r for r in cand if series(r["cfg"]) == name and r[key] is not None),
                             key=lambda r: r["dt"])
                if not pts:
                    continue
                color, marker, ls = style(pts[0]["cfg"])
                ax.plot([r[key] for r in pts], [r["err"][ek] for r in pts], ls=ls, color=color, lw=0.8, alpha=0.7)
                for r in pts:  # hollow: interpreted time projected from the first steps
                    hollow = key == "interp_s" and r["interp_projected"]
                    ax.plot(r[key], r["err"][ek], marker=marker, color=color, ms=5, ls="none",
                            mfc="none" if hollow else color)
                handles[name] = Line2D([], [], color=color, marker=marker, ls=ls, label=name)
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
                         f"{'compiled' if col == 0 else 'interpreted (hollow: projected from the first steps)'}",
                         fontsize="medium")
    handles["front"] = Line2D([], [], color="k", marker="o", mfc="none", ms=9, label="Pareto front (non-dominated)")
    fig.legend(handles=list(handles.values()), loc="outside lower center", ncol=4, fontsize="small")
    fig.suptitle(f"twobar, {plan['t_end']:g} s: error against a converged reference vs wall time "
                 f"(dt {max(plan['dts']):g} .. {plan['dt_fine']:g} s; dashed: stated accuracies)")
    return fig


if __name__ == "__main__":
    cli(__doc__, main)
