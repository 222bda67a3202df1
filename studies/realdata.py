"""Identification on data casflex did not generate (Exudyn's recordings): how close, how honest, how fast?

Prose: docs/studies/realdata.md. Run: ``python studies/realdata.py`` (about an hour on 2 cores; ``--quick``: twobar
at rest, 0.5 mm, one seed).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from _shared import exudyn_recording, fit_errors, honesty
from _study import Banner, assert_checks, checks, cli, sweep, table, write_outputs

NOISES = (0.0, 1e-4, 5e-4, 1e-3)
SEEDS = 10
INSTANTS = np.linspace(0.3, 2.7, 9)
SCENES = {  # markers for the indirect method, windows (start, end, initial state)
    "twobar": {"markers": ("x3", "y3", "x5", "y5"), "rest": (0.0, 3.0, "scene"), "mid": (0.5, 2.5, "estimate")},
    "threelink": {"markers": ("x3", "y3", "x5", "y5", "x7", "y7"), "rest": (0.0, 3.0, "scene"),
                  "mid": (1.0, 3.0, "estimate")},
}
MS_WALL = 300.0  # s: twobar converges in 40 s; threelink in 190-280 s, or not before it (Known limits)
#: (method, window) of the full runs; multiple shooting on threelink with one seed only (it takes its wall-time cap)
METHODS = (("indirect", "rest"), ("indirect", "mid"), ("adapted", "rest"), ("direct", "rest"), ("indirect-ms", "rest"))


def one_run(*, scene: str, method: str, window: str, noise: float, seed: int, quick: bool) -> dict:
    import casflex
    from casflex.identification import (
        Experiment,
        ModelRun,
        Shooting,
        Solver,
        Uncertainty,
        identify_adapted_direct,
        identify_direct,
        identify_indirect,
    )

    model = casflex.assemble(casflex.load_scene(scene))
    a, b, state = SCENES[scene][window]
    b = a + 1.0 if quick else b
    t0 = time.perf_counter()
    if method.startswith("indirect"):  # every method starts 20 % below the truth
        data = exudyn_recording(f"{scene}_exudyn", SCENES[scene]["markers"], a, b, noise, seed)
        # multiple shooting: IPOPT capped at MS_WALL s (a capped run counts as not converged)
        kw = ({"shooting": Shooting("multiple-shooting"),
               "solver": Solver("ipopt", options={"ipopt": {"max_wall_time": MS_WALL}})}
              if method == "indirect-ms" else {})
        r = identify_indirect(model, Experiment(data, initial_state=state), start=0.8, run=ModelRun(dt=1e-3),
                              uncertainty=Uncertainty(model_error="none" if quick else "refine"), **kw)
    else:
        names = tuple(d for d in model.dof_names if method == "direct" or not d.startswith("theta"))
        data = exudyn_recording(f"{scene}_exudyn", names, a, b, noise, seed)
        instants = [float(data.t[np.argmin(np.abs(data.t - (a + t)))]) for t in INSTANTS if a + t < b - 0.05]
        r = (identify_adapted_direct if method == "adapted" else identify_direct)(model, data, instants, start=0.8)
    return fit_errors(model, r) | {"message": r.message[:300], "wall_s": time.perf_counter() - t0}


def summarise(records: list[tuple[dict, dict]]) -> list[dict]:
    """One row per (scene, window, method, noise): the numbers the checks and the figure use, the table's cells."""
    groups: dict[tuple, list[dict]] = {}
    for run, rec in records:
        groups.setdefault((run["scene"], run["window"], run["method"], run["noise"]), []).append(rec)
    rows = []
    for (scene, window, method, noise), recs in sorted(groups.items()):
        ok = [r for r in recs if "error" not in r]
        row = {"scene": scene, "window": window, "method": method, "noise": noise, "runs": len(recs),
               "cells": ["all runs raised", *[""] * 6]}
        if ok:
            err = np.abs(np.array([r["rel_error"] for r in ok]))
            is_k = np.array([not n.startswith("kt") for n in ok[0]["names"]])
            k, kt = err[:, is_k], err[:, ~is_k]
            h = honesty(ok, np.array([r["se_finite"] for r in ok]))  # an infinite SE claims nothing: it covers
            row |= {"kt_err": float(np.median(kt)), "k_err_max": float(k.max()), "kt_err_max": float(kt.max()),
                    "cover3": float(h["cover3"].mean()), "dishonest": h["dishonest"], "cells": [
                        *(f"{100 * np.median(e):.3g} % / {100 * e.max():.3g} %" for e in (k, kt)),
                        *(f"{100 * h[c].mean():.0f} %" for c in ("cover2", "cover3", "success")), h["dishonest"],
                        f"{np.median([r['wall_s'] for r in ok]):.1f}"]}
        rows.append(row)
    return rows


def figure(rows: list[dict], path: Path) -> None:
    """kt's median error and the 3-SE coverage against the noise, window at rest."""
    from casflex.plotting._figure import _new_figure, _save

    fig = _new_figure((9.0, 3.8))
    ax1, ax2 = fig.subplots(1, 2)
    for key, style in (("indirect", "-o"), ("adapted", "-s"), ("direct", "-^")):
        for scene, color in (("twobar", "C0"), ("threelink", "C1")):
            sel = [r for r in rows if (r["method"], r["scene"], r["window"]) == (key, scene, "rest") and "kt_err" in r]
            nz = [max(1e3 * r["noise"], 0.01) for r in sel]  # noise-free runs drawn at 0.01 mm on the log axis
            if sel:
                ax1.loglog(nz, [max(r["kt_err"], 1e-6) for r in sel], style, color=color, label=f"{scene}, {key}")
                ax2.semilogx(nz, [100 * r["cover3"] for r in sel], style, color=color)
    ax1.set(xlabel="noise (mm; 0 drawn at 0.01)", ylabel="median relative error of kt")
    ax2.set(xlabel="noise (mm; 0 drawn at 0.01)", ylabel="3-SE coverage (%)", ylim=(0, 105))
    ax2.axhline(90, color="black", lw=0.6, ls="--", label="90 %: the default method's bar")
    ax1.legend(fontsize="x-small", frameon=False)
    ax2.legend(fontsize="x-small", frameon=False, loc="lower left")
    for ax in (ax1, ax2):
        ax.grid(True, alpha=0.3)
    fig.suptitle("identification on Exudyn's recordings, window at rest")
    _save(fig, path)


def main(quick: bool = False, out_dir: Path | None = None, record: Path | None = None) -> list[dict]:
    banner = Banner("realdata", quick)
    runs = [("twobar", m, "rest", 5e-4, 0) for m in ("indirect", "adapted")] if quick else [
        (scene, m, w, noise, seed) for scene in SCENES for noise in NOISES
        for seed in range(SEEDS if noise > 0 else 1)  # without noise every seed is the same run
        for m, w in METHODS if m != "indirect-ms" or scene == "twobar" or seed == 0]
    plan = [dict(zip(("scene", "method", "window", "noise", "seed"), r, strict=True), quick=quick) for r in runs]
    rows = summarise(sweep("realdata", plan, "{scene}_{method}_{window}_{noise:g}_{seed}".format_map, one_run,
                           record=record, quick=quick))
    ind = [r for r in rows if r["method"] == "indirect" and "kt_err" in r]  # the checks are on the default method
    bar = [r for r in ind if r["scene"] == "twobar" and r["noise"] <= 5e-4]  # the accuracy the docs claim
    check_lines, failed = checks([
        ("default method: dishonest successes, at most 1 in 10 runs (most per row)", max(r["dishonest"] for r in ind),
         all(r["dishonest"] <= max(1, round(0.1 * r["runs"])) for r in ind)),
        *([] if quick else [  # the quick mode's 1 s window pins kt down to ~12 % only
            ("default method: 3-SE coverage >= 90 % (lowest)", f"{100 * min(r['cover3'] for r in ind):.0f} %",
             all(r["cover3"] >= 0.9 for r in ind)),
            ("twobar, default method, up to 0.5 mm: k within 1 %, kt within 10 % (largest)",
             f"{100 * max(r['k_err_max'] for r in bar):.3g} %, {100 * max(r['kt_err_max'] for r in bar):.3g} %",
             all(r["k_err_max"] < 0.01 and r["kt_err_max"] < 0.1 for r in bar))])])
    page = ["# Identification on data casflex did not generate", "", f"{banner.line()} The data, the methods and the "
            "measures: [studies/realdata.md](../studies/realdata.md).", "",
            f"![kt's error, 3-SE coverage](../figures/realdata{'_quick' * quick}.png)", "",
            *table(["scene", "window", "method", "noise (mm)", "runs", "k error (median / max)",
                    "kt error (median / max)", "2 SE", "3 SE", "success", "dishonest", "wall (s)"],
                   [[r["scene"], r["window"], r["method"], f"{1e3 * r['noise']:g}", r["runs"], *r["cells"]]
                    for r in rows]), "", *check_lines]
    write_outputs("realdata", out_dir, quick, "\n".join(page), lambda f: figure(rows, f))
    assert_checks(failed)
    return rows


if __name__ == "__main__":
    cli(__doc__, main)
