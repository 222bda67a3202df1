"""Identification at the extremes: does each method find twobar's parameters from far starts, what
does noise do to the estimates and their standard errors, and is any NaN ever reported?

Set-up and how to read the page: docs/studies/extremes.md. Run: ``python studies/extremes_identification.py`` (about 8
min on 2 cores; ``--quick``: 9 cheap runs).
"""

from __future__ import annotations

import math
from pathlib import Path

from _study import Banner, cli, sweep, table, write_outputs

STARTS = (0.1, 0.2, 0.5, 2.0, 5.0, 10.0)
NOISES = (0.0, 1e-6, 1e-5, 1e-4, 1e-3)
METHODS = ("direct", "adapted-direct", "indirect")
ADAPTED_INSTANTS = {False: (0.4, 1.1, 1.6, 1.9, 2.3), True: (0.4, 1.1)}
KT_FACTORS, KT_STARTS, KT_NOISES = (1e-3, 1e-6), (0.1, 0.5, 2.0, 10.0), (0.0, 1e-5)
TOL_P, TOL_ADAPTED = 1e-6, 1e-4  # noise-free convergence: max relative error of p (adapted direct: of k1, k3)
NOMINAL = {"k1": 700.0, "kt1": 0.5, "k3": 400.0, "kt3": 0.5}


def one_run(*, kt_factor: float | None = None, **kw) -> dict:
    """``identification_run``; with ``kt_factor`` on twobar with kt1 = kt3 = kt_factor x nominal, the scene
    written once per worker to a file named by the hash of its text (so that its model and data are cached
    like a built-in scene's)."""
    import dataclasses
    import hashlib
    import tempfile

    from casflex.scene_io import dumps_scene, load_scene, save_scene
    from casflex.sweep import identification_run

    if kt_factor is None:
        return identification_run(**kw)
    base = load_scene("twobar")
    kt0 = base.property_value("torsion1.kt")
    scene = dataclasses.replace(base.with_values(kt1=kt0 * kt_factor, kt3=kt0 * kt_factor),
                                name=f"twobar_kt{kt_factor:g}")
    text = dumps_scene(scene)
    path = Path(tempfile.gettempdir()) / f"casflex_extremes_{hashlib.sha256(text.encode()).hexdigest()[:16]}.toml"
    if not path.exists():
        save_scene(scene, path)
    return {**identification_run(scene=str(path), **kw), "nominal": {
        "k1": base.property_value("spring1.k"), "kt1": kt0 * kt_factor, "k3": base.property_value("spring3.k"),
        "kt3": kt0 * kt_factor}}


def plan(quick: bool) -> list[dict]:
    """Every run's keyword arguments."""
    t_end, horizon = (1.2, 0.05) if quick else (3.0, 0.3)
    if quick:  # CI: the pipeline, not the answers
        specs = [(None, "direct", s, nz) for nz in (0.0, 1e-4) for s in (0.1, 10.0)] + \
            [(None, "adapted-direct", 0.1, nz) for nz in (0.0, 1e-4)] + [(None, "indirect", 2.0, 0.0)] + \
            [(1e-6, m, 0.1, 0.0) for m in ("direct", "adapted-direct")]
    else:
        specs = [(None, m, s, nz) for m in METHODS for nz in NOISES for s in STARTS] + \
            [(f, m, s, nz) for f in KT_FACTORS for m in METHODS for nz in KT_NOISES for s in KT_STARTS]
    out = []
    for f, m, s, nz in specs:
        kw = {"method": m, "start": s, "noise": nz, "seed": 1 if nz > 0 else None, "t_end": t_end}
        kw.update({"direct": {"instants": (0.69,)}, "adapted-direct": {"instants": ADAPTED_INSTANTS[quick]},
                   "indirect": {"horizon": horizon}}[m])
        out.append({**kw, "kt_factor": f} if f is not None else kw)
    return out


def _key(r: dict) -> str:
    return ((f"kt{r['kt_factor']:g}_" if "kt_factor" in r else "") + f"{r['method']}_s{r['start']:g}_n{r['noise']:g}"
            f"_T{r['t_end']:g}" + (f"_h{r['horizon']:g}" if r["method"] == "indirect" else ""))


def _bad_numbers(x, path: str = "") -> list[str]:
    """Paths of NaN/inf values in a record (numbers, or the strings the sweep writes for them)."""
    if isinstance(x, dict):
        return [b for k, v in x.items() for b in _bad_numbers(v, f"{path}.{k}" if path else str(k))]
    if isinstance(x, (list, tuple)):
        return [b for i, v in enumerate(x) for b in _bad_numbers(v, f"{path}[{i}]")]
    bad = (isinstance(x, float) and not math.isfinite(x)) or (isinstance(x, str) and x.strip().lower() in
                                                                ("nan", "inf", "-inf", "+inf"))
    return [path] if bad else []


def summarise(run: dict, rec: dict) -> dict:
    """One run's errors against the truth, its standard errors' honesty, and any anomaly."""
    out = {"key": _key(run), "method": run["method"], "start": run["start"], "noise": run["noise"],
           "kt_factor": run.get("kt_factor")}
    if "error" in rec:
        return {**out, "error": rec["error"], "success": False, "converged": False, "bad": []}
    nominal, par, weak = rec.get("nominal") or NOMINAL, rec["parameters"], rec.get("weak", [])
    rel = {k: abs(float(par[k]) / nominal[k] - 1.0) for k in nominal}
    # the sweep writes non-finite numbers as strings; an infinite standard error is the library's answer for a
    # parameter the data do not determine (then in the weak list)
    se = {k: float(v) if isinstance(v, str) else v for k, v in (rec.get("std_errors") or {}).items()}
    num = {k for k in nominal if isinstance(se.get(k), (int, float)) and not math.isnan(se[k])}
    inf_se = [k for k in nominal if isinstance(se.get(k), float) and se[k] == math.inf]
    err_k, err = max(rel["k1"], rel["k3"]), max(rel.values())
    crit, tol = (err_k, TOL_ADAPTED) if run["method"] == "adapted-direct" else (err, TOL_P)
    return {**out, "success": bool(rec["success"]), "status": rec["status"], "wall_s": rec["wall_s"], "p": par,
            "err": err, "err_k": err_k, "err_kt": max(rel["kt1"], rel["kt3"]), "weak": weak, "nominal": nominal,
            "converged": bool(rec["success"] and crit <= tol), "inf_se": inf_se,
            "covered_4se": num == set(nominal) and all(abs(float(par[k]) - nominal[k]) <= 4 * se[k] for k in nominal),
            "bad": [b for b in _bad_numbers(rec) if not (b.startswith("std_errors.") and b[11:] in inf_se
                                                         and b[11:] in weak)],
            "below_lower": [k for k in nominal if float(par[k]) < 0.0],
            "zero_se": [k for k in nominal if k in num and se[k] == 0.0],
            # success, yet a parameter off by > 10 % and by > 4 reported SE, and not in the weak list
            "overconfident": [k for k in nominal if rec["success"] and rel[k] > 0.1 and k not in weak and k in num
                              and math.isfinite(se[k]) and abs(float(par[k]) - nominal[k]) > 4 * se[k]]}


def _mark(r: dict) -> str:
    """Noise 0: ✓ converged, ✗! success but p misses the criterion, ✗ solver failure. Noise > 0: ✓ success,
    truth within 4 SE and error <= 10 %; ~ within 4 SE, error > 10 %; ✗! success with the truth outside 4 SE."""
    if "error" in r:
        return "error"
    if not r["success"]:
        return "✗"
    if r["noise"] == 0:
        return "✓" if r["converged"] else "✗!"
    return "✗!" if not r["covered_4se"] else "✓" if _err(r) <= 0.1 else "~"


def _err(r: dict) -> float:
    return r["err_k"] if r["method"] == "adapted-direct" else r["err"]


def _method_table(rows: list[dict], method: str, starts: list, noises: list) -> list[str]:
    body = []
    for nz in noises:
        g = {r["start"]: r for r in rows if r["method"] == method and r["noise"] == nz}
        cells = ["" if s not in g else "error" if "error" in g[s] else f"{_mark(g[s])} {_err(g[s]):.0e}"
                 for s in starts]
        weak = sorted({k for r in g.values() if "error" not in r for k in r["weak"]})
        body.append([f"{nz:g}", *cells, ", ".join(weak) or "-"])
    return table(["noise (m)", *(f"{s:g} x p*" for s in starts), "weak (any start)"], body,
                 "r" + "c" * len(starts) + "l")


def _walls(rows: list[dict]) -> str:
    """Wall time per run of each method, and the runs stopped by the wall-time cap."""
    ok = [r for r in rows if "error" not in r]
    return "Wall time per run: " + "; ".join(f"{m} {min(w):.2g}-{max(w):.2g} s" for m in METHODS if (
        w := [r["wall_s"] for r in ok if r["method"] == m])) + "."


def _kt_table(rows: list[dict]) -> list[str]:
    starts, body = sorted({r["start"] for r in rows}), []
    for f in sorted({r["kt_factor"] for r in rows}, reverse=True):
        for m in METHODS:
            for nz in sorted({r["noise"] for r in rows}):
                g = {r["start"]: r for r in rows if r["kt_factor"] == f and r["method"] == m and r["noise"] == nz}
                if g:
                    body.append([f"{f:g}", m, f"{nz:g}", *("" if s not in g else "error" if "error" in g[s] else
                                                          f"{'ok' if g[s]['success'] else 'FAIL'} "
                                                          f"({g[s]['status'][:18]}): k {g[s]['err_k']:.0e}, kt "
                                                          f"{g[s]['err_kt']:.0e}" + (" NaN!" if g[s]["bad"] else "")
                                                          for s in starts),
                                 f"{sum('error' not in r and {'kt1', 'kt3'} <= set(r['weak']) for r in g.values())}"
                                 f"/{len(g)}"])
    return table(["kt / nominal", "method", "noise (m)", *(f"{s:g} x p*" for s in starts), "kt weak in"],
                 body, "rlr" + "l" * (len(starts) + 1))


def _anomalies(rows: list[dict]) -> list[str]:
    """Records with NaN/inf, a standard error of exactly 0, an infinite one outside the weak list, an
    overconfident success, or a stiffness below its lower bound 0: each listed with its parameters."""
    kinds = {"bad": "NaN/inf in the record", "zero_se": "standard error exactly 0", "overconfident":
             "success, off by > 10 % and > 4 SE, not weak", "below_lower": "below the lower bound 0"}
    out = [f"- {text}: " + "; ".join(f"{r['key']} ({', '.join(r[k])})" for r in hit) for k, text in kinds.items()
           if (hit := [r for r in rows if r.get(k)])]
    notweak = [r for r in rows if set(r.get("inf_se", [])) - set(r.get("weak", []))]
    out += [f"- infinite standard error, not weak: {', '.join(r['key'] for r in notweak)}"] if notweak else []
    return out or ["- none: no NaN/inf, no standard error of 0, no undetermined parameter outside the weak list, no "
                   "overconfident success, no stiffness below its bound."]


def page(rows: list[dict], quick: bool, banner: str, checks: list[tuple[bool, str]]) -> str:
    main_rows, kt = [r for r in rows if r["kt_factor"] is None], [r for r in rows if r["kt_factor"] is not None]
    starts, noises = sorted({r["start"] for r in main_rows}), sorted({r["noise"] for r in main_rows})
    ktr = [r for r in kt if "error" not in r]
    lines = ["# Identification at the extremes" + (" (quick mode)" if quick else ""), "", banner, "",
             "What is run, how to read it and what it shows: [docs/studies/extremes.md](../studies/extremes.md); the "
             "simulation at the extremes: [extremes.md](extremes.md).", "",
             f"Adapted direct at {ADAPTED_INSTANTS[quick]} s; indirect (single shooting) over "
             f"0..{0.05 if quick else 0.3:g} s, data over {1.2 if quick else 3.0:g} s. Cell: max relative error "
             "of p (adapted direct: of k1, k3); noise 0: ✓ converged, ✗! success missing the criterion; noise > 0: ✓ "
             "success, truth within 4 reported SE and error <= 10 %, ~ within 4 SE but error > 10 %, ✗! success with "
             "the truth outside 4 SE; ✗ solver failure.", ""]
    for m in METHODS:
        lines += [f"**{m}**", "", *_method_table(main_rows, m, starts, noises), ""]
    lines += [_walls(main_rows), "", "Anomalies in the records:", "", *_anomalies(rows), "",
              "## Torsional stiffness near zero", ""]
    lines += [*_kt_table(kt), "", f"{len(ktr)} runs; kt1 and kt3 flagged weak in "
              f"{sum({'kt1', 'kt3'} <= set(r['weak']) for r in ktr)} of {len(ktr)}; k1, k3 within 1e-4 in "
              f"{sum(r['err_k'] <= 1e-4 for r in ktr)} of {len(ktr)}.", "", "## Self-checks (asserted by the study)",
              "",
              *(f"- {t}" if passed else f"- **FAILED**: {t}" for passed, t in checks)]
    return "\n".join(lines) + "\n"


def main(quick: bool = False, out_dir: Path | None = None, record: Path | None = None,
         scheduler: str | None = None) -> list[dict]:
    banner = Banner("extremes_identification", quick)
    rows = [summarise(run, rec) for run, rec in sweep("extremes_identification", plan(quick), _key, one_run,
                                                      record=record, quick=quick, scheduler=scheduler)]
    errs = [(r["key"], r["error"]) for r in rows if "error" in r]
    loud = [(r["key"], r["bad"]) for r in rows if r["bad"] and r["success"]]
    direct0 = [r for r in rows if r["method"] == "direct" and r["noise"] == 0 and r["kt_factor"] is None]
    checks = [(not errs, f"no identification run raised{': ' + str(errs) if errs else ''}"),
              (not loud, f"no NaN/inf (other than the infinite standard error of a parameter in the weak list) in a "
               f"record that reports success; NaN/inf in {sum(bool(r['bad']) for r in rows)} of the {len(rows)} "
               "records"),
              (all(r["converged"] for r in direct0), f"direct identification on noise-free data converges from every "
               f"start ({len(direct0)} runs)")]
    write_outputs("extremes_identification", out_dir, quick, page(rows, quick, banner.line(), checks))
    failed = [t for ok, t in checks if not ok]
    assert not failed, "self-checks failed: " + "; ".join(failed)
    return rows


if __name__ == "__main__":
    cli(__doc__, main)
