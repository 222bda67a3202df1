"""Identification on data casflex did not generate (Exudyn's recordings): how close, how honest, how fast?

Set-up and how to read the page: docs/studies/realdata.md. Run: ``python studies/realdata.py`` (about an hour on 2
cores; ``--quick``: twobar at rest, 0.5 mm, one seed; ``--record DIR`` resumes).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
from _shared import exudyn_recording, honesty
from _study import Banner, cli, sweep, table, write_outputs

NOISES = (0.0, 1e-4, 5e-4, 1e-3)
SEEDS = 10
INSTANTS = np.linspace(0.3, 2.7, 9)
SCENES = {  # markers for the indirect method, windows (start, end, initial state)
    "twobar": {"markers": ("x3", "y3", "x5", "y5"), "rest": (0.0, 3.0, "scene"), "mid": (0.5, 2.5, "estimate")},
    "threelink": {"markers": ("x3", "y3", "x5", "y5", "x7", "y7"), "rest": (0.0, 3.0, "scene"),
                  "mid": (1.0, 3.0, "estimate")},
}
MS_WALL = 300.0  # s: twobar converges within half of it; threelink cycles until it (Known limits)


def one_run(*, scene: str, method: str, window: str, noise: float, seed: int, quick: bool) -> dict:
    """One identification (a sweep run): errors, z-scores against the truth, success, wall time."""
    import casflex
    from casflex.identification import identify_adapted_direct, identify_direct, identify_indirect

    model = casflex.assemble(casflex.load_scene(scene))
    a, b, state = SCENES[scene][window]
    b = a + 1.0 if quick else b
    start = 0.8  # every method starts 20 % below the truth
    t0 = time.perf_counter()
    if method.startswith("indirect"):
        data = exudyn_recording(f"{scene}_exudyn", SCENES[scene]["markers"], a, b, noise, seed)
        # multiple shooting: IPOPT capped at MS_WALL s (a capped run counts as not converged)
        kw = ({"transcription": "multiple-shooting", "solver": "ipopt",
               "solver_options": {"ipopt": {"max_wall_time": MS_WALL}}} if method == "indirect-ms" else {})
        r = identify_indirect(model, data, dt=1e-3, initial_state=state, start=start,
                              model_error="none" if quick else "refine", **kw)
    else:
        names = tuple(d for d in model.dof_names if not d.startswith("theta")) if method == "adapted" \
            else model.dof_names
        data = exudyn_recording(f"{scene}_exudyn", names, a, b, noise, seed)
        instants = [float(data.t[np.argmin(np.abs(data.t - (a + t)))]) for t in INSTANTS if a + t < b - 0.05]
        r = (identify_adapted_direct if method == "adapted" else identify_direct)(model, data, instants, start=start)
    se = np.array([r.std_errors[k] for k in model.parameter_names])
    with np.errstate(divide="ignore", invalid="ignore"):
        z = (r.p - model.p_nominal) / se
    return {"success": bool(r.success), "status": r.status, "message": r.message[:300],
            "rel_error": (r.p / model.p_nominal - 1).tolist(), "z": np.where(np.isfinite(z), z, 0.0).tolist(),
            "se_finite": np.isfinite(se).tolist(), "names": list(model.parameter_names),
            "wall_s": time.perf_counter() - t0}


def plan(quick: bool) -> list[dict]:
    """Every run of the study (quick: the default and the adapted direct method, once)."""
    if quick:
        return [{"scene": "twobar", "method": m, "window": "rest", "noise": 5e-4, "seed": 0, "quick": True}
                for m in ("indirect", "adapted")]
    runs = []
    for scene in SCENES:
        for noise in NOISES:
            for seed in range(SEEDS if noise > 0 else 1):  # without noise every seed is the same run
                runs += [{"scene": scene, "method": "indirect", "window": w, "noise": noise, "seed": seed}
                         for w in ("rest", "mid")]
                runs += [{"scene": scene, "method": m, "window": "rest", "noise": noise, "seed": seed}
                         for m in ("adapted", "direct")]
            # multiple shooting: every seed on twobar; one on threelink, where it does not converge and
            # each run takes its wall-time cap (docs/identification.md, Known limits)
            runs += [{"scene": scene, "method": "indirect-ms", "window": "rest", "noise": noise, "seed": seed}
                     for seed in range(SEEDS if noise > 0 and scene == "twobar" else 1)]
    return [{**r, "quick": False} for r in runs]


def summarise(records: list[tuple[dict, dict]]) -> list[dict]:
    """One row per (scene, window, method, noise)."""
    groups: dict[tuple, list[dict]] = {}
    for run, rec in records:
        groups.setdefault((run["scene"], run["window"], run["method"], run["noise"]), []).append(rec)
    rows = []
    for (scene, window, method, noise), recs in sorted(groups.items()):
        ok = [r for r in recs if "error" not in r]
        row = {"scene": scene, "window": window, "method": method, "noise": noise, "runs": len(recs),
               "failed": len(recs) - len(ok)}
        if ok:
            err = np.abs(np.array([r["rel_error"] for r in ok]))
            is_k = np.array([not n.startswith("kt") for n in ok[0]["names"]])
            h = honesty(ok, np.array([r["se_finite"] for r in ok]))  # an infinite SE claims nothing: it covers
            row |= {"k_err": float(np.median(err[:, is_k])), "kt_err": float(np.median(err[:, ~is_k])),
                    "k_err_max": float(err[:, is_k].max()), "kt_err_max": float(err[:, ~is_k].max()),
                    "cover2": float(h["cover2"].mean()), "cover3": float(h["cover3"].mean()),
                    "success": float(h["success"].mean()), "dishonest": h["dishonest"],
                    "wall_s": float(np.median([r["wall_s"] for r in ok]))}
        rows.append(row)
    return rows


def page(rows: list[dict], banner: str, quick: bool) -> str:
    """One table: errors, coverage, honesty and time per (scene, window, method, noise)."""
    def cells(r: dict) -> list:
        return ["all runs raised", *[""] * 6] if "k_err" not in r else [
            f"{100 * r['k_err']:.3g} % / {100 * r['k_err_max']:.3g} %",
            f"{100 * r['kt_err']:.3g} % / {100 * r['kt_err_max']:.3g} %", f"{100 * r['cover2']:.0f} %",
            f"{100 * r['cover3']:.0f} %", f"{100 * r['success']:.0f} %", r["dishonest"], f"{r['wall_s']:.1f}"]

    return "\n".join(["# Identification on data casflex did not generate", "", f"{banner} The data, the methods and "
                      "the measures: [studies/realdata.md](../studies/realdata.md).", "",
                      f"![kt's error, 3-SE coverage](../figures/realdata{'_quick' * quick}.png)",
                      "", *table(
                          ["scene", "window", "method", "noise (mm)", "runs", "k error (median / max)",
                           "kt error (median / max)", "2 SE", "3 SE", "success", "dishonest", "wall (s)"],
                          [[r["scene"], r["window"], r["method"], f"{1e3 * r['noise']:g}", r["runs"], *cells(r)]
                           for r in rows]), ""])


def figure(rows: list[dict], path: Path) -> None:
    """kt's median error and the 3-SE coverage against the noise, window at rest."""
    from casflex.plotting._figure import _new_figure, _save

    fig = _new_figure((9.0, 3.8))
    ax1, ax2 = fig.subplots(1, 2)
    for key, style in (("indirect", "-o"), ("adapted", "-s"), ("direct", "-^")):
        for scene, color in (("twobar", "C0"), ("threelink", "C1")):
            sel = [r for r in rows if r["method"] == key and r["scene"] == scene and r["window"] == "rest"
                   and "k_err" in r]
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


def _key(r: dict) -> str:
    return f"{r['scene']}_{r['method']}_{r['window']}_{r['noise']:g}_{r['seed']}"


def main(quick: bool = False, out_dir: Path | None = None, record: Path | None = None) -> list[dict]:
    banner = Banner("realdata", quick)
    rows = summarise(sweep("realdata", plan(quick), _key, one_run, record=record, quick=quick))
    write_outputs("realdata", out_dir, quick, page(rows, banner.line(), quick), lambda f: figure(rows, f))
    for r in rows:
        print(json.dumps(r))
    # the study's own checks, on the default method: honest on both scenes (a success more than 3 SE
    # from the truth at most once in ten runs, and the 3-SE intervals holding the truth at least 90 %
    # of the time); twobar's accuracy bar (k within 1 %, kt within 10 % at up to 0.5 mm) is the one the
    # docs claim, on the full windows (the quick mode's 1 s window pins kt down to ~12 % only).
    # threelink's own accuracy is reported, not asserted: its last joint's k3 comes out within 1.2 %
    # (2.2 SE) mid-motion at 0.5 mm.
    for r in rows:
        if r["method"] == "indirect" and "k_err" in r:
            assert r["dishonest"] <= max(1, round(0.1 * r["runs"])), r
            if not quick:
                assert r["cover3"] >= 0.9, r
                if r["scene"] == "twobar" and r["noise"] <= 5e-4:
                    assert r["k_err_max"] < 0.01 and r["kt_err_max"] < 0.1, r
    return rows


if __name__ == "__main__":
    cli(__doc__, main)
