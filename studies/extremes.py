"""Stability at the extremes: where does HHT-alpha on twobar stop converging, and is every failure
detected and reported with its time? Set-up and how to read the page: docs/studies/extremes.md.
Run: ``python studies/extremes.py [--quick] [--raw FILE | --render FILE]`` (about 2 min; ``--quick``: seconds).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from _extremes import ALPHAS, CAUSES, DRIFT_TOL, HORIZONS, omega_max_of, reason, run_case
from _shared import twobar
from _study import Banner, assert_checks, checks, cli, fnum, save_raw, table, write_outputs

GRID = {False: {"dts": (1e-5, 1e-4, 1e-3, 3e-3, 1e-2, 2e-2, 5e-2), "k": (1e-3, 1.0, 1e3, 1e6),
                "E": (1.0, 1e-3, 1e-6), "long_min_dt": 1e-4},  # 30 s for dt >= 1e-4: 3e5 steps at most
        True: {"dts": (1e-3, 1e-2, 5e-2), "k": (1.0, 1e6), "E": (1.0,), "long_min_dt": 1e-2}}
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
                                  interpreted_check=T < 10 and round(T / dt) <= 300,
                                  ref_scale=ref_scale.get((ks, es)))
                if (ks, es) not in ref_scale and a == 0.0 and T < 10 and row["success"]:
                    ref_scale[(ks, es)] = row["energy"]["own_scale_J"]
                rows.append(row)
    return {"rows": rows, "omega_max": omega}


def _sel(rows: list[dict], **match) -> list[dict]:
    return [r for r in rows if all(r[k] == v for k, v in match.items())]


def _suspect(r: dict) -> bool:
    return bool(r["success"] and r["alpha"] == 0.0 and r["energy"]["drift"] > SUSPECT_DRIFT)


def self_checks(rows: list[dict]) -> list[tuple]:
    """(check, value, passed[, asserted]) rows of the page's self-checks."""
    fails, rng = [r for r in rows if not r["success"]], _sel(rows, status="element_range")
    same = [r["interpreted_same"] for r in rows if "interpreted_same" in r]
    unsound, flagged = [r for r in rows if r["wraps"] or _suspect(r)], [r for r in rows if "flagged" in r]
    # a message names its cause and the time the returned trajectory ends (energy_growth: the flagged state's)
    told = [CAUSES[r["status"]][0] in r["message"]
            and f"t = {(r['steps'] + (r['status'] == 'energy_growth')) * r['dt']:.6g} s" in r["message"] for r in fails]
    named = sum(any(f"element {k.rsplit('.', 1)[0]}: " in r["message"] for k, *_ in r["flagged"]["wrap"])
                for r in rng)
    out = [("no NaN/inf in a returned trajectory", f"{len(rows)} runs", all(r["finite"] for r in rows)),
           ("each failure's message names its cause and the time the returned trajectory ends",
            ", ".join(f"{len(_sel(fails, status=s))} {s}" for s in CAUSES), all(told)),
           ("runs of <= 300 steps repeated on the interpreted path: the same success, steps and message",
            f"{sum(same)} of {len(same)}", all(same)),
           (f"every failure detected: no success with a wrap (the study's atan2) or, at alpha = 0, a drift above "
            f"{SUSPECT_DRIFT:g}; no failed run returns a wrap", f"{len(unsound)} of {len(rows)} runs", not unsound),
           ("each element_range failure: the study's wrap check of the rejected step at the element named",
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
    return f"✗ {CAUSES[r['status']][1]} {r['t_reached']:.3g} s{w}"


def _newton_class(r: dict) -> str:
    """The study's diagnosis of a Newton failure (docs/studies/extremes.md)."""
    tw, td = r["t_first_wrap"], r["t_drift_1pct"]
    return ("wrap" if tw is not None and (td is None or tw <= td) else "blow-up"
            if r["energy"]["max_gain"] > SUSPECT_DRIFT else "newton")


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


def _map_tables(raw: dict, T: float) -> list[str]:
    """Per alpha, stiffness x dt: the map cells, f_max and the largest dt every run converges with."""
    out = []
    for a in ALPHAS:
        runs = {(r["k_scale"], r["e_scale"], r["dt"]): r for r in _sel(raw["sim"]["rows"], t_end=T, alpha=a)}
        dts, body = sorted({d for *_, d in runs}), []
        for c in dict.fromkeys(k[:2] for k in runs):
            cells, om = [runs.get((*c, d)) for d in dts], raw["sim"]["omega_max"][label(*c)]
            body.append([label(*c), f"{om / (2 * math.pi):.4g}", *map(_mark, cells), _limit(cells, om)])
        out += [f"**alpha = {AN[a]}**", "", *table(["stiffness", "f_max (Hz)", *(f"{d:g}" for d in dts),
                                                    "every run converges up to dt"], body, "lr" + "c" * len(dts) + "l"),
                ""]
    return out


def _fail_table(rows: list[dict]) -> list[str]:
    fails = sorted((r for r in rows if not r["success"]), key=lambda r: (
        r["alpha"], list(CAUSES).index(r["status"]), r["e_scale"], r["k_scale"], r["dt"], r["t_end"]))
    return table(["stiffness", "alpha", "dt (s)", "horizon (s)", "status", "failed at t (s)", "message",
                  "study's cross-check", "omega_max dt", "energy gain before (max)", "1 % drift from t (s)"], [
        [label(r["k_scale"], r["e_scale"]), AN[r["alpha"]], f"{r['dt']:g}", f"{r['t_end']:g}", r["status"],
         f"{r['t_reached']:.4g}", reason(r["message"]), _cross(r), f"{r['omega_dt']:.3g}",
         f"{r['energy']['max_gain']:.2g}", fnum(r["t_drift_1pct"], ".3g")] for r in fails], "llrrlrllrrr")


def _lost(g: list[dict]) -> str:
    """The energy runs lost by the end, min to max, and the nominal stiffness's at dt = 1e-3."""
    e, nom = [-r["energy"]["end"] for r in g], [-r["energy"]["end"] for r in _sel(g, k_scale=1, e_scale=1, dt=1e-3)]
    return f"{min(e):.1e} to {max(e):.1e}" + (f"; nominal, dt = 1e-3: {nom[0]:.1e}" if nom else "") if e else "-"


def _why(rows: list[dict], hs: list[float]) -> list[str]:
    """Per alpha: the failures by status, the diagnosis of the Newton failures, the energy the converged runs lost."""
    body = []
    for a in ALPHAS:
        fails = [r for r in _sel(rows, alpha=a) if not r["success"]]
        cls = [_newton_class(r) for r in _sel(fails, status="newton_failed")]
        body.append([AN[a], len(_sel(rows, alpha=a)), len(fails), *(len(_sel(fails, status=s)) for s in CAUSES),
                     ", ".join(f"{cls.count(c)} {c}" for c in dict.fromkeys(cls)) or "-",
                     *(_lost(_sel(rows, alpha=a, t_end=T, success=True, wraps=0)) for T in hs)])
    return table(["alpha", "runs", "failed", *CAUSES, "Newton failures: diagnosis",
                  *(f"energy lost by the end, {T:g} s" for T in hs)], body, "lrrrrrl" + "l" * len(hs))


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
                      *_fail_table(rows), "", *check_lines])


def main(quick: bool = False, out_dir: Path | None = None, raw_path: Path | None = None) -> dict:
    banner = Banner("extremes", quick)
    raw = {"quick": quick, "sim": simulation_grid(quick), "banner": banner.line()}  # the banner after the runs
    save_raw(raw, raw_path)
    return render(raw, out_dir)


def render(raw: dict, out_dir: Path | None = None) -> dict:
    check_lines, failed = checks(self_checks(raw["sim"]["rows"]))
    write_outputs("extremes", out_dir, raw["quick"], page(raw, check_lines))
    assert_checks(failed)
    return raw


if __name__ == "__main__":
    cli(__doc__, main, render)
