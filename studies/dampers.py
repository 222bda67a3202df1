"""Can the joints' dampers be identified from a few noisy markers, with honest standard errors?

Set-up and how to read the page: docs/studies/dampers.md. Run: ``python studies/dampers.py`` (about 5 min on 2 cores;
``--quick``: 1 s at rest, one seed).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
from _shared import DATA, exudyn_recording, honesty
from _study import Banner, cli, sweep, table, write_outputs

MARKERS = ("x3", "y3", "x5", "y5")
NOISE = 1e-3
SEEDS = 10
WINDOWS = {"rest": (0.0, 3.0, "scene"), "mid": (0.5, 2.5, "estimate")}


def one_run(*, window: str, seed: int, quick: bool) -> dict:
    """One identification (a sweep run): relative errors, z-scores against the truth, success, wall time."""
    import casflex
    from casflex.identification import identify_indirect

    model = casflex.assemble(casflex.load_scene(DATA / "twobar_damped.toml"))
    a, b, state = WINDOWS[window]
    data = exudyn_recording("twobar_damped_exudyn", MARKERS, a, a + 1.0 if quick else b, NOISE, seed)
    t0 = time.perf_counter()
    r = identify_indirect(model, data, dt=1e-3, initial_state=state, start=0.8)
    se = np.array([r.std_errors[k] for k in model.parameter_names])
    err = r.p - model.p_nominal
    return {"names": list(model.parameter_names), "rel_error": (err / model.p_nominal).tolist(),
            "z": (err / se).tolist(), "success": bool(r.success), "message": r.message,
            "wall_s": time.perf_counter() - t0}


def summarise(records: list[tuple[dict, dict]]) -> list[dict]:
    """One row per (window, parameter), and the window's success and dishonest counts."""
    rows = []
    for window in WINDOWS:
        recs = [rec for run, rec in records if run["window"] == window and "error" not in rec]
        if not recs:
            continue
        err, h = np.abs(np.array([r["rel_error"] for r in recs])), honesty(recs)
        rows += [{"window": window, "parameter": name, "runs": len(recs), "err_median": float(np.median(err[:, j])),
                  "err_max": float(err[:, j].max()), "cover2": float(h["cover2"][:, j].mean()),
                  "cover3": float(h["cover3"][:, j].mean()), "success": float(h["success"].mean()),
                  "dishonest": h["dishonest"], "wall_s": float(np.median([r["wall_s"] for r in recs])),
                  "z": [r["z"][j] for r in recs]} for j, name in enumerate(recs[0]["names"])]
    return rows


def page(rows: list[dict], banner: str) -> str:
    """The table of errors, coverage and honesty per window and parameter."""
    return "\n".join(["# Identifying joint dampers from markers", "", f"{banner} The set-up and the measures: "
                      "[studies/dampers.md](../studies/dampers.md).", "", *table(
                          ["window", "parameter", "runs", "error (median / max)", "2 SE", "3 SE", "success",
                           "dishonest", "wall (s)"],
                          [[r["window"], r["parameter"], r["runs"],
                            f"{100 * r['err_median']:.3g} % / {100 * r['err_max']:.3g} %", f"{100 * r['cover2']:.0f} %",
                            f"{100 * r['cover3']:.0f} %", f"{100 * r['success']:.0f} %", r["dishonest"],
                            f"{r['wall_s']:.1f}"] for r in rows]), ""])


def figure(rows: list[dict], path: Path) -> None:
    """z-scores of every run, per parameter and window, against the 2- and 3-SE lines."""
    from casflex.plotting._figure import _new_figure, _save

    fig = _new_figure((8.0, 3.4))
    ax = fig.subplots()
    names = list(dict.fromkeys(r["parameter"] for r in rows))
    for k, (window, color) in enumerate((("rest", "C0"), ("mid", "C1"))):
        for r in (r for r in rows if r["window"] == window):
            ax.plot(np.full(len(r["z"]), names.index(r["parameter"]) + (k - 0.5) * 0.25), r["z"], "o", ms=3,
                    color=color, alpha=0.7, label=window if r["parameter"] == names[0] else None)
    for level in (-3, -2, 2, 3):
        ax.axhline(level, color="black", lw=0.5, ls="--" if abs(level) == 2 else "-")
    ax.set_xticks(range(len(names)), names)
    ax.set_ylabel("(estimate - truth) / reported SE")
    ax.set_ylim(-4.5, 4.5)
    ax.legend(fontsize="small", frameon=False, loc="upper left", ncol=2)
    ax.grid(True, axis="y", alpha=0.3)
    fig.suptitle("twobar with dampers, Exudyn's markers at 1 mm: z-scores of the eight joint parameters")
    _save(fig, path)


def main(quick: bool = False, out_dir: Path | None = None, record: Path | None = None) -> list[dict]:
    banner = Banner("dampers", quick)
    plan = [{"window": w, "seed": s, "quick": quick} for w in (("rest",) if quick else WINDOWS)
            for s in range(1 if quick else SEEDS)]
    rows = summarise(sweep("dampers", plan, lambda r: f"{r['window']}_{r['seed']}", one_run, record=record,
                           quick=quick))
    write_outputs("dampers", out_dir, quick, page(rows, banner.line()), lambda f: figure(rows, f))
    for r in rows:
        print(json.dumps({k: v for k, v in r.items() if k != "z"}))
    # the study's checks (issue 13's bar): from the recording at rest, every damper within 5 % of the
    # truth at 1 mm in every run; in both windows honest: a success more than 3 SE from the truth at
    # most once in ten runs. Mid-motion (2 s, initial state estimated) the accuracy is reported only.
    # The quick mode's 1 s window is checked for honesty only.
    assert rows, "no run finished"
    for r in rows:
        assert r["dishonest"] <= max(1, round(0.1 * r["runs"])), r
        # one that a single run can fail: with honest SE a 5-SE miss has probability 6e-7
        assert max(abs(z) for z in r["z"]) < 5, r
        if not quick and r["window"] == "rest" and r["parameter"].startswith("c"):
            assert r["err_max"] < 0.05, r
    return rows


if __name__ == "__main__":
    cli(__doc__, main)
