"""Stability at the extremes: where does HHT-alpha on twobar stop converging, and is every failure
detected and reported with its time?

Set-up, how to read the page and what it shows: docs/studies/extremes.md.
Run: ``python studies/extremes.py [--quick] [--raw FILE | --render FILE]`` (about 4 min; ``--quick``: seconds).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from _extremes import ALPHAS, DRIFT_TOL, HORIZONS, STATUSES, detail, omega_max_of, run_case
from _shared import twobar
from _study import Banner, assert_checks, checks, cli, fnum, save_raw, table, write_outputs

from casflex.simulate import ENERGY_GROWTH

GRID = {False: {"dts": (1e-5, 1e-4, 1e-3, 3e-3, 1e-2, 2e-2, 5e-2), "k": (1e-3, 1.0, 1e3, 1e6),
                "E": (1.0, 1e-3, 1e-6), "long_min_dt": 1e-4},  # 30 s for dt >= 1e-4: 3e5 steps at most
        True: {"dts": (1e-3, 1e-2, 5e-2), "k": (1.0, 1e6), "E": (1.0,), "long_min_dt": 1e-2}}
NEWTON_SAMPLES = {3.0: 300, 30.0: 100}  # steps re-run interpreted per run to count Newton iterations
AN = dict(zip(ALPHAS, ("0", "-1/3"), strict=True))  # alpha as the page writes it
SUSPECT_DRIFT = 0.1  # a success at alpha = 0 with a larger drift is not a credible solution


def label(ks: float, es: float) -> str:
    return f"springs x{ks:g}, E x{es:g}"


def simulation_grid(quick: bool) -> dict:
    """The stability map: every (stiffness, alpha, dt, horizon) run."""
    g = GRID[quick]
    rows, omega, ref_scale = [], {}, {}  # ref_scale: per case, its finest converged alpha = 0, 3 s run's
    for es in g["E"]:
        model = twobar(1, e_scale=es)
        for ks in g["k"]:
            omega[label(ks, es)] = om = omega_max_of(model, model.p_nominal * ks)
            for a, dt, T in ((a, dt, T) for a in ALPHAS for dt in g["dts"] for T in HORIZONS
                             if T < 10 or dt >= g["long_min_dt"]):
                row, _ = run_case(model, k_scale=ks, e_scale=es, alpha=a, dt=dt, t_end=T, omega_max=om,
                                  n_samples=NEWTON_SAMPLES[T], interpreted_check=T < 10 and round(T / dt) <= 300,
                                  ref_scale=ref_scale.get((ks, es)))
                if (ks, es) not in ref_scale and a == 0.0 and T < 10 and row["success"]:
                    ref_scale[(ks, es)] = row["energy"]["own_scale_J"]
                rows.append(row)
    return {"rows": rows, "omega_max": omega}


def _sel(rows: list[dict], **match) -> list[dict]:
    return [r for r in rows if all(r[k] == v for k, v in match.items())]


def _suspect(r: dict) -> bool:
    return bool(r["success"] and r["alpha"] == 0.0 and r["energy"]["drift"] > SUSPECT_DRIFT)


def _message_ok(r: dict) -> bool:
    """The message names the status, the time the returned trajectory ends (6 digits) and the step after, and
    its details: iterations and a residual above tol, a jump of more than pi, energy above the threshold."""
    f = r["failure"]
    return bool(f and f["kind"] == r["status"]
                and all(abs(f[k] - (r["steps"] + i) * r["dt"]) <= 5e-6 * max(1, f[k]) + 1e-12
                        for i, k in enumerate(("t", "t1")))
                and {"newton_failed": lambda: f["iterations"] >= 1 and not f["residual"] <= f["tol"],
                     "element_range": lambda: abs(f["theta1"] - f["theta0"]) > math.pi - 1e-3,
                     "energy_growth": lambda: f["percent"] >= 100 * ENERGY_GROWTH - 0.5}[f["kind"]]())


def self_checks(rows: list[dict]) -> list[tuple]:
    """(check, value, passed[, asserted]) rows of the page's self-checks."""
    fails, rng = [r for r in rows if not r["success"]], _sel(rows, status="element_range")
    same = [r["interpreted_same"] for r in rows if "interpreted_same" in r]
    mism = max(r["newton"]["replay_mismatch"] for r in rows)
    unsound, flagged = [r for r in rows if r["wraps"] or _suspect(r)], [r for r in rows if "flagged" in r]
    named = sum(any(k == f"{r['failure']['element']}.{r['failure']['end']}" for k, *_ in r["flagged"]["wrap"])
                for r in rng)
    out = [("no NaN/inf in a returned trajectory", f"{len(rows)} runs", all(r["finite"] for r in rows)),
           ("each failure's message: its status, the time the returned trajectory ends, the iterations and "
            "residual, the element's jump or the energy created",
            ", ".join(f"{len(_sel(fails, status=s))} {s}" for s in STATUSES), all(map(_message_ok, fails))),
           ("runs of <= 300 steps repeated on the interpreted path: the same success, steps and message",
            f"{sum(same)} of {len(same)}", all(same)),
           ("re-run sampled steps reproduce the compiled states", f"max relative difference {mism:.1e}", mism <= 1e-12),
           (f"every failure detected: no success with a wrap (the study's atan2) or, at alpha = 0, a drift above "
            f"{SUSPECT_DRIFT:g}; no failed run returns a wrap", f"{len(unsound)} of {len(rows)} runs", not unsound),
           ("each element_range failure: the study's wrap check of the rejected step at the element end named",
            f"{named} of {len(rng)}", named == len(rng)),
           ("the rejected step of each element_range and energy_growth failure: Newton converged in it",
            f"{sum(r['flagged']['converged'] for r in flagged)} of {len(flagged)}",
            all(r["flagged"]["converged"] for r in flagged), False)]
    for T, tol in DRIFT_TOL.items():
        if small := [r["energy"]["drift"] for r in _sel(rows, alpha=0.0, success=True, wraps=0, t_end=T)
                     if r["dt"] <= 1e-3]:
            out.append((f"alpha = 0, {T:g} s, converged, dt <= 1e-3: energy drift < {tol:g}",
                        f"largest {max(small):.1e} of {len(small)}", max(small) < tol))
    nom = [r for r in _sel(rows, alpha=0.0, t_end=3.0, k_scale=1.0, e_scale=1.0, success=True) if r["dt"] <= 1e-3]
    if len(nom) >= 3:  # the trapezoidal rule's error on this nonlinear chain
        d, e = np.array([r["dt"] for r in nom]), np.array([r["energy"]["drift"] for r in nom])
        order = np.polyfit(np.log(d), np.log(e), 1)[0]
        out.append(("alpha = 0, nominal stiffness, 3 s: energy drift O(dt^2)", f"fitted order {order:.2f}; drift "
                    f"{e.max():.1e} at dt = {d.max():g} to {e.min():.1e} at {d.min():g}", abs(order - 2) < 0.2, False))
    return out


def _mark(r: dict | None) -> str:
    """Map cell: ✓ drift, ⚠ drift (a success the study does not believe), ✗ status and time; w: a wrap."""
    if r is None:
        return ""
    w = " w" if r["wraps"] else ""
    if r["success"]:
        return ("⚠ " if _suspect(r) else "✓ ") + f"{r['energy']['drift']:.0e}{w}"
    code = {"element_range": "range", "energy_growth": "energy", "newton_failed": "Newton"}.get(r["status"], "?")
    return f"✗ {code} " + (f"{r['failure']['t']:.3g} s" if r["failure"] else "?") + w


def _newton_class(r: dict) -> str:
    """The study's diagnosis of a Newton failure (docs/studies/extremes.md)."""
    tw, td = r["t_first_wrap"], r["t_drift_1pct"]
    return ("wrap" if tw is not None and (td is None or tw <= td) else "blow-up"
            if r["energy"]["max_gain"] > SUSPECT_DRIFT else "round-off"
            if r["failing_step"]["kind"] == "stalls at the round-off floor" else "newton")


def _cross(r: dict) -> str:
    """The study's own view of a failure."""
    fl = r.get("flagged") or {}
    if r["status"] == "element_range":
        return ("wrap in the rejected step: " + ", ".join(f"{k} {a:+.2f} -> {b:+.2f}" for k, a, b in fl["wrap"])
                if fl["wrap"] else "**no wrap in the rejected step**")
    if r["status"] == "energy_growth":
        g = fl["dE_J"] / r["energy"]["scale_J"]
        return (f"flagged state {g:.2g} x scale above E(0) ({fl['dE_J'] / fl['moving_max_J']:.0%} of max T + V_el)"
                + ("" if g > SUSPECT_DRIFT else f" **below {SUSPECT_DRIFT:g}**"))
    return _newton_class(r)


def _limit(cells: list[dict | None], om: float) -> str:
    """The largest dt up to which every run of a map row converges, and omega_max dt there."""
    rr = [r for r in cells if r]
    n_ok = next((i for i, r in enumerate(rr) if not r["success"]), len(rr))
    wr = " (range)" if _sel(rr, status="element_range") else ""
    d = rr[n_ok - 1]["dt"] if n_ok else math.nan
    return f"{'all, to ' if n_ok == len(rr) else ''}{d:g} (omega dt {om * d:.3g}){wr}" if n_ok else f"none{wr}"


def _map_tables(raw: dict, T: float, newton: bool = False) -> list[str]:
    """Per alpha, stiffness x dt: the map cells, f_max and the largest dt every run converges with; or
    (``newton``) Newton iterations mean (max) of the sampled steps."""
    out = []
    for a in ALPHAS:
        runs = {(r["k_scale"], r["e_scale"], r["dt"]): r for r in _sel(raw["sim"]["rows"], t_end=T, alpha=a)}
        dts, body = sorted({d for *_, d in runs}), []
        for c in dict.fromkeys(k[:2] for k in runs):
            cells, om = [runs.get((*c, d)) for d in dts], raw["sim"]["omega_max"][label(*c)]
            body.append([label(*c), *(f"{r['newton']['mean']:.2f} ({r['newton']['max']})" if r and
                                      r["newton"]["sampled"] else "-" for r in cells)] if newton else
                        [label(*c), f"{om / (2 * math.pi):.4g}", *map(_mark, cells), _limit(cells, om)])
        head = ["stiffness", *([] if newton else ["f_max (Hz)"]), *(f"{d:g}" for d in dts)]
        out += [f"**alpha = {AN[a]}**", "", *(table(head, body, "l" + "r" * len(dts)) if newton else
                                              table([*head, "every run converges up to dt"], body,
                                                    "lr" + "c" * len(dts) + "l")), ""]
    return out


def _fail_table(rows: list[dict]) -> list[str]:
    fails = sorted((r for r in rows if not r["success"]), key=lambda r: (
        r["alpha"], STATUSES.index(r["status"]), r["e_scale"], r["k_scale"], r["dt"], r["t_end"]))
    body = []
    for r in fails:
        f, fs, nw = r["failure"], r.get("failing_step"), r["newton"]
        body.append([label(r["k_scale"], r["e_scale"]), AN[r["alpha"]], f"{r['dt']:g}", f"{r['t_end']:g}",
                     r["status"], fnum(f and f["t"], ".4g"), detail(f) if f else "-", _cross(r), f"{r['omega_dt']:.3g}",
                     f"{r['energy']['max_gain']:.2g}", fnum(r["t_drift_1pct"], ".3g"),
                     f"{r['spring_rel'][0]:.2g}-{r['spring_rel'][1]:.3g}",
                     f"{nw['mean_last20']:.1f} ({nw['max_last20']})",
                     *([f"{fs['kind']}, min {fs['min_residual']:.1e}", f"{fs['cond_predictor']:.1e}",
                        "converge" if fs["half_steps_converge"] else "fail"] if fs else ["-"] * 3)])
    return table(["stiffness", "alpha", "dt (s)", "horizon (s)", "status", "failed at t (s)", "message",
                  "study's cross-check", "omega_max dt", "energy gain before (max)", "1 % drift from t (s)",
                  "spring length / rest (min-max)", "Newton last 20 steps: mean (max)", "failing step: plain Newton",
                  "cond at predictor", "two half steps"], body, "llrrlrllrrrlllrl")


def _lost(g: list[dict]) -> str:
    """The energy runs lost by the end, min to max, and the nominal stiffness's at dt = 1e-3."""
    e, nom = [-r["energy"]["end"] for r in g], [-r["energy"]["end"] for r in _sel(g, k_scale=1, e_scale=1, dt=1e-3)]
    return f"{min(e):.1e} to {max(e):.1e}" + (f"; nominal, dt = 1e-3: {nom[0]:.1e}" if nom else "") if e else "-"


def _why(rows: list[dict], hs: list[float]) -> list[str]:
    """Per alpha: the failures by status and the study's diagnosis of the Newton failures; the energy the converged
    runs lost by the end, in units of the energy scale (negative: a gain)."""
    body = []
    for a in ALPHAS:
        fails = [r for r in _sel(rows, alpha=a) if not r["success"]]
        nf = _sel(fails, status="newton_failed")
        cls = [_newton_class(r) for r in nf]
        body.append([AN[a], len(_sel(rows, alpha=a)), len(fails), *(len(_sel(fails, status=s)) for s in STATUSES),
                     ", ".join(f"{cls.count(c)} {c}" for c in dict.fromkeys(cls)) or "-",
                     f"{sum(r['failing_step']['half_steps_converge'] for r in nf)} of {len(nf)}" if nf else "-",
                     sum(r["newton"]["max_last20"] > 2 * max(r["newton"]["mean"], 1.0) for r in fails),
                     *(_lost(_sel(rows, alpha=a, t_end=T, success=True, wraps=0)) for T in hs)])
    return table(["alpha", "runs", "failed", *STATUSES, "Newton failures: diagnosis", "two half steps converge",
                  "Newton's count rose before the failure", *(f"energy lost by the end, {T:g} s" for T in hs)],
                 body, "lrrrrrllr" + "l" * len(hs))


def page(raw: dict, check_lines: list[str]) -> str:
    rows = raw["sim"]["rows"]
    hs = [T for T in HORIZONS if _sel(rows, t_end=T)]
    lines = ["# Stability at the extremes" + (" (quick mode)" if raw["quick"] else ""), "", raw["banner"], "",
             "What is run, how to read it and what it shows: [docs/studies/extremes.md](../studies/extremes.md).", "",
             f"Grid: alpha in {{0, -1/3}} x dt in {{{', '.join(f'{d:g}' for d in sorted({r['dt'] for r in rows}))}}} s "
             f"x {len({(r['k_scale'], r['e_scale']) for r in rows})} stiffness cases x horizon; {len(rows)} runs.", ""]
    for T in hs:
        lines += [f"## Stability map, {T:g} s", "", *_map_tables(raw, T)]
    return "\n".join([*lines, "## Where and why runs fail", "", *_why(rows, hs), "", "### Every failure", "",
                      *_fail_table(rows), "", "## Newton iterations per step (3 s runs)", "",
                      *_map_tables(raw, 3.0, newton=True), *check_lines])


def main(quick: bool = False, out_dir: Path | None = None, raw_path: Path | None = None) -> dict:
    banner = Banner("extremes", quick)
    raw = {"quick": quick, "sim": simulation_grid(quick)}
    raw["banner"] = banner.line()
    save_raw(raw, raw_path)
    return render(raw, out_dir)


def render(raw: dict, out_dir: Path | None = None) -> dict:
    """The page with its self-checks; then a failed check raises."""
    check_lines, failed = checks(self_checks(raw["sim"]["rows"]))
    write_outputs("extremes", out_dir, raw["quick"], page(raw, check_lines))
    assert_checks(failed)
    return raw


if __name__ == "__main__":
    cli(__doc__, main, render)
