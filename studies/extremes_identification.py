"""Identification at the extremes: does each method find twobar's parameters from far starts, what
does noise do to the estimates and their standard errors, and is any NaN ever reported? Set-up and how to
read the page: docs/studies/extremes.md. Run: ``python studies/extremes_identification.py [--quick]
[--record DIR] [--scheduler ADDRESS]`` (about 8 min on 2 cores; ``--quick``: 9 cheap runs).
"""

from __future__ import annotations

import math
from itertools import product
from pathlib import Path

from _study import Banner, assert_checks, checks, cli, sweep, table, write_outputs

STARTS = (0.1, 0.2, 0.5, 2.0, 5.0, 10.0)
NOISES = (0.0, 1e-6, 1e-5, 1e-4, 1e-3)
METHODS = ("direct", "adapted-direct", "indirect")
ADAPTED_INSTANTS = {False: (0.4, 1.1, 1.6, 1.9, 2.3), True: (0.4, 1.1)}
KT_FACTORS, KT_STARTS, KT_NOISES = (1e-3, 1e-6), (0.1, 0.5, 2.0, 10.0), (0.0, 1e-5)
TOL_P, TOL_ADAPTED = 1e-6, 1e-4  # noise-free convergence: max relative error of p (adapted direct: of k1, k3)
NOMINAL = {"k1": 700.0, "kt1": 0.5, "k3": 400.0, "kt3": 0.5}


def one_run(*, kt_factor: float | None = None, **kw) -> dict:
    """``identification_run``; with ``kt_factor``, on twobar with kt1 = kt3 = kt_factor x nominal, its scene written
    once per worker to a file named by its text's hash (its model and data cached like a built-in scene's)."""
    import dataclasses
    import hashlib
    import tempfile

    from casflex.scene.io import dumps_scene, load_scene, save_scene
    from casflex.study.sweep import identification_run

    if kt_factor is not None:
        kt = NOMINAL["kt1"] * kt_factor
        scene = dataclasses.replace(load_scene("twobar").with_values(kt1=kt, kt3=kt), name=f"twobar_kt{kt_factor:g}")
        text = dumps_scene(scene)
        path = Path(tempfile.gettempdir()) / f"casflex_extremes_{hashlib.sha256(text.encode()).hexdigest()[:16]}.toml"
        if not path.exists():
            save_scene(scene, path)
        kw["scene"] = str(path)
    return identification_run(**kw)


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
    by_method = {"direct": {"instants": (0.69,)}, "adapted-direct": {"instants": ADAPTED_INSTANTS[quick]},
                 "indirect": {"horizon": horizon}}
    return [{"method": m, "start": s, "noise": nz, "seed": 1 if nz > 0 else None, "t_end": t_end, **by_method[m],
             **({} if f is None else {"kt_factor": f})} for f, m, s, nz in specs]


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
    f = run.get("kt_factor")
    out = {"key": _key(run), "method": run["method"], "start": run["start"], "noise": run["noise"], "kt_factor": f}
    if "error" in rec:
        return {**out, "error": rec["error"], "success": False, "converged": False, "bad": [], "cell": "error",
                "kt_cell": "error"}
    nominal = {**NOMINAL, **({"kt1": NOMINAL["kt1"] * f, "kt3": NOMINAL["kt3"] * f} if f is not None else {})}
    par, weak = {k: float(v) for k, v in rec["parameters"].items()}, rec.get("weak", [])
    rel = {k: abs(par[k] / nominal[k] - 1.0) for k in nominal}
    # the sweep writes non-finite numbers as strings; an infinite standard error is the library's answer for a
    # parameter the data do not determine (then in the weak list)
    se = {k: float(v) if isinstance(v, str) else v for k, v in (rec.get("std_errors") or {}).items()}
    num = {k for k in nominal if isinstance(se.get(k), (int, float)) and not math.isnan(se[k])}
    inf_se = [k for k in nominal if isinstance(se.get(k), float) and se[k] == math.inf]
    err_k = max(rel["k1"], rel["k3"])
    err = err_k if run["method"] == "adapted-direct" else max(rel.values())  # the cells' error
    converged = bool(rec["success"] and err <= (TOL_ADAPTED if run["method"] == "adapted-direct" else TOL_P))
    covered = num == set(nominal) and all(abs(par[k] - nominal[k]) <= 4 * se[k] for k in nominal)
    bad = [b for b in _bad_numbers(rec) if not (b.startswith("std_errors.") and b[11:] in inf_se and b[11:] in weak)]
    mark = ("✗" if not rec["success"] else ("✓" if converged else "✗!") if run["noise"] == 0 else  # docs: Cells
            "✗!" if not covered else "✓" if err <= 0.1 else "~")
    return {**out, "success": bool(rec["success"]), "wall_s": rec["wall_s"], "weak": weak, "err_k": err_k,
            "converged": converged, "bad": bad, "inf_se_not_weak": [k for k in inf_se if k not in weak],
            "cell": f"{mark} {err:.0e}", "kt_cell": f"{'ok' if rec['success'] else 'FAIL'} ({rec['status'][:18]}): "
            f"k {err_k:.0e}, kt {max(rel['kt1'], rel['kt3']):.0e}" + (" NaN!" if bad else ""),
            "below_lower": [k for k in nominal if par[k] < 0.0],
            "zero_se": [k for k in nominal if k in num and se[k] == 0.0],
            # success, yet a parameter off by > 10 % and by > 4 reported SE, and not in the weak list
            "overconfident": [k for k in nominal if rec["success"] and rel[k] > 0.1 and k not in weak and k in num
                              and math.isfinite(se[k]) and abs(par[k] - nominal[k]) > 4 * se[k]]}


def page(rows: list[dict], quick: bool, banner: str, check_lines: list[str]) -> str:
    main_rows, kt = [r for r in rows if r["kt_factor"] is None], [r for r in rows if r["kt_factor"] is not None]
    lines = ["# Identification at the extremes" + (" (quick mode)" if quick else ""), "", banner, "",
             "What is run, how to read it and what it shows: [docs/studies/extremes.md](../studies/extremes.md).", "",
             "Wall time per run: " + "; ".join(f"{m} {min(w):.2g}-{max(w):.2g} s" for m in METHODS if (w := [
                 r["wall_s"] for r in main_rows if r["method"] == m and "error" not in r])) + ".", ""]
    starts = sorted({r["start"] for r in main_rows})
    for m in METHODS:
        g = {(r["noise"], r["start"]): r for r in main_rows if r["method"] == m}
        body = [[f"{nz:g}", *(g[(nz, s)]["cell"] if (nz, s) in g else "" for s in starts), ", ".join(sorted(
            {k for (n, _), r in g.items() if n == nz and "error" not in r for k in r["weak"]})) or "-"]
            for nz in sorted({r["noise"] for r in main_rows})]
        lines += [f"**{m}**", "", *table(["noise (m)", *(f"{s:g} x p*" for s in starts), "weak (any start)"], body,
                                         "r" + "c" * len(starts) + "l"), ""]
    starts, factors, body = sorted({r["start"] for r in kt}), sorted({r["kt_factor"] for r in kt}, reverse=True), []
    for f, m, nz in product(factors, METHODS, sorted({r["noise"] for r in kt})):
        if g := {r["start"]: r for r in kt if (r["kt_factor"], r["method"], r["noise"]) == (f, m, nz)}:
            weak = sum("error" not in r and {"kt1", "kt3"} <= set(r["weak"]) for r in g.values())
            body.append([f"{f:g}", m, f"{nz:g}", *(g[s]["kt_cell"] if s in g else "" for s in starts),
                         f"{weak}/{len(g)}"])
    lines += ["## Torsional stiffness near zero", "", *table(
        ["kt / nominal", "method", "noise (m)", *(f"{s:g} x p*" for s in starts), "kt weak in"], body,
        "rlr" + "l" * (len(starts) + 1)), ""]
    return "\n".join(lines + check_lines)


def self_checks(rows: list[dict]) -> list[tuple]:
    """(check, value, passed[, asserted]): the study's assertions, then the anomalies looked for in every record."""
    errs = [f"{r['key']}: {r['error']}" for r in rows if "error" in r]
    direct0 = [r for r in rows if r["method"] == "direct" and r["noise"] == 0 and r["kt_factor"] is None]
    ktr = [r for r in rows if r["kt_factor"] is not None and "error" not in r]
    hits = {k: "; ".join(f"{r['key']} ({', '.join(r[k])})" for r in rows if r.get(k)) for k in
            ("bad", "zero_se", "inf_se_not_weak", "overconfident", "below_lower")}
    return [("no identification run raised", "; ".join(errs) or f"none of {len(rows)}", not errs),
            ("no NaN/inf (but the infinite standard error of a weak parameter) in a record that reports success; "
             "records with NaN/inf", hits.pop("bad") or "none", not any(r["bad"] and r["success"] for r in rows)),
            ("direct identification on noise-free data converges from every start",
             f"{sum(r['converged'] for r in direct0)} of {len(direct0)}", all(r["converged"] for r in direct0)),
            ("no standard error exactly 0 or infinite outside the weak list, no overconfident success (off by > 10 % "
             "and > 4 SE, not weak), no stiffness below its lower bound 0",
             "; ".join(f"{k}: {v}" for k, v in hits.items() if v) or "none", not any(hits.values()), False),
            ("kt near zero: kt1 and kt3 reported weak (and k1, k3 within 1e-4 in)",
             f"{sum({'kt1', 'kt3'} <= set(r['weak']) for r in ktr)} of {len(ktr)} "
             f"({sum(r['err_k'] <= 1e-4 for r in ktr)} of {len(ktr)})",
             all({"kt1", "kt3"} <= set(r["weak"]) for r in ktr), False)]


def main(quick: bool = False, out_dir: Path | None = None, record: Path | None = None,
         scheduler: str | None = None) -> list[dict]:
    banner = Banner("extremes_identification", quick)
    rows = [summarise(run, rec) for run, rec in sweep("extremes_identification", plan(quick), _key, one_run,
                                                      record=record, quick=quick, scheduler=scheduler)]
    check_lines, failed = checks(self_checks(rows))
    write_outputs("extremes_identification", out_dir, quick, page(rows, quick, banner.line(), check_lines))
    assert_checks(failed)
    return rows


if __name__ == "__main__":
    cli(__doc__, main)
