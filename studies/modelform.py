"""Identification when the model's form is wrong: recordings of other forms, fitted by the built-in scenes.

Prose: docs/studies/modelform.md. Run: ``python studies/modelform.py`` (about 15 min on 2 cores; ``--quick``: 1 s of
the correct form and of rotary inertia, one seed).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from _shared import DATA, exudyn_recording, fit_errors, honesty
from _study import Banner, assert_checks, checks, cli, sweep, table, write_outputs

from casflex.identification import ModelRun, Uncertainty

NOISE = 5e-4
SEEDS = 10
#: case -> (fitted scene, recording: a file of tests/data and its key in forms_exudyn.npz (None: the file's own
#: channels), what differs from the fitted scene). Every recording is Exudyn's, 8 elements per beam.
CASES = {
    "twobar, correct form": ("twobar", "twobar_exudyn", None, "nothing (ANCF beams as the scene's)"),
    "twobar, rotary inertia": ("twobar", "forms_exudyn", "twobar_rotary",
                               "geometrically exact beams: shear and the section's rotary inertia"),
    "twobar, rotary inertia, 10 x E": ("twobar", "forms_exudyn", "twobar_rotary_stiff",
                                       "the same with beams 10 x stiffer"),
    "twobar, 100 x softer beams": ("twobar", "forms_exudyn", "twobar_soft", "ANCF beams with E / 100"),
    "twobar, rigid links": ("twobar", "forms_exudyn", "twobar_rigid", "ANCF beams with 1000 x E"),
    "twobar, dampers missing": ("twobar", "twobar_damped_exudyn", None,
                                "dampers in the joints (twobar_damped.toml)"),
    "threelink, correct form": ("threelink", "threelink_exudyn", None, "nothing"),
    "threelink, rotary inertia": ("threelink", "forms_exudyn", "threelink_rotary",
                                  "geometrically exact beams: shear and rotary inertia"),
}
QUICK_CASES = ("twobar, correct form", "twobar, rotary inertia")
NODES = {"twobar": ("3", "5"), "threelink": ("3", "5", "7")}


def _recording(case: str, t_end: float, seed: int):
    from casflex.data import MeasurementSet

    scene, file, key, _ = CASES[case]
    names = tuple(f"{c}{n}" for n in NODES[scene] for c in "xy")
    if key is None:
        return exudyn_recording(file, names, 0.0, t_end, NOISE, seed)
    z = np.load(DATA / f"{file}.npz")
    rows = z["t"] <= t_end + 1e-9
    cols = [list(z[f"{key}_channels"]).index(c) for c in names]
    q = z[key][np.ix_(rows, cols)]
    return MeasurementSet(z["t"][rows], names, q + np.random.default_rng(seed).normal(0, NOISE, q.shape), None, None)


def one_run(*, case: str, seed: int, quick: bool) -> dict:
    import casflex
    from casflex.identification import identify_indirect

    model = casflex.assemble(casflex.load_scene(CASES[case][0]))
    data = _recording(case, 1.0 if quick else 3.0, seed)
    t0 = time.perf_counter()
    r = identify_indirect(model, data, start=0.8, run=ModelRun(dt=1e-3),
                          uncertainty=Uncertainty(model_error="none" if quick else "refine"))
    unc = r.extra["uncertainty"]
    se_noise = np.array([unc["noise"][k] for k in model.parameter_names])
    err = r.p - model.p_nominal
    return fit_errors(model, r) | {
        "wall_s": time.perf_counter() - t0, "z_noise": (err / se_noise).tolist(),
        "forms": [(f["name"], f["verdict"], f.get("delta_aic")) for f in r.extra["forms"]]}


def summarise(done: list[tuple[dict, dict]]) -> list[dict]:
    rows = []
    for case in CASES:
        recs = [rec for run, rec in done if run["case"] == case and "error" not in rec]
        if not recs:
            continue
        h = honesty(recs)
        z_noise = np.abs(np.array([r["z_noise"] for r in recs]))
        verdicts = [v for r in recs for _, v, _ in r["forms"]]
        aic = [d for r in recs for _, _, d in r["forms"] if d is not None]
        rows.append({"case": case, "runs": len(recs), "successes": int(h["success"].sum()),
                     "dishonest": h["dishonest"], "cover3": float(h["cover3"].mean()),
                     "cover3_noise": float((z_noise <= 3).mean()),
                     "err_max": float(np.abs(np.array([r["rel_error"] for r in recs])).max()),
                     "z_max": float(h["z"].max()), "z_noise_max": float(z_noise.max()),
                     "verdicts": ", ".join(f"{v} {verdicts.count(v)}" for v in dict.fromkeys(verdicts)) or "-",
                     "aic": f"{np.median(aic):+.0f}" if aic else "-",
                     "wall": float(np.median([r["wall_s"] for r in recs]))})
    return rows


def main(quick: bool = False, out_dir: Path | None = None, record: Path | None = None) -> list[dict]:
    banner = Banner("modelform", quick)
    plan = [{"case": c, "seed": s, "quick": quick} for c in (QUICK_CASES if quick else CASES)
            for s in range(1 if quick else SEEDS)]
    done = sweep("modelform", plan, lambda r: f"{r['case']}-{r['seed']}".replace(" ", "_").replace(",", ""),
                 one_run, record=record, quick=quick)
    rows = summarise(done)
    wrong = [r for r in rows if "correct" not in r["case"]]
    right = [r for r in rows if "correct" in r["case"]]
    check_lines, failed = checks([
        ("wrong forms: successes with the truth beyond 3 total SE, at most 1 in 10 per case (most)",
         max((r["dishonest"] for r in wrong), default=0),
         all(r["dishonest"] <= max(1, round(0.1 * r["runs"])) for r in wrong)),
        *([] if quick else [
            ("correct forms: success in at least 9 of 10 fits (fewest)", min(r["successes"] for r in right),
             all(r["successes"] >= 0.9 * r["runs"] for r in right)),
            ("correct forms: the total 3-SE interval covers the truth in at least 97 % (least)",
             f"{100 * min(r['cover3'] for r in right):.0f} %", all(r["cover3"] >= 0.97 for r in right))])])
    page = ["# Identification when the model's form is wrong", "",
            f"{banner.line()} Exudyn's recordings of nodes {'/'.join('+'.join(n) for n in NODES.values())} at "
            f"100 Hz, {1e3 * NOISE:g} mm noise, {'1' if quick else '3'} s from rest, fitted by the built-in scene "
            "(one element per beam) from 0.8 x the truth with the default options. The forms and the measures: "
            "[studies/modelform.md](../studies/modelform.md).", "",
            *table(["case", "the recording's form", "runs", "success", "truth beyond 3 total SE, successes",
                    "3 total SE cover", "3 noise SE cover", "largest error", "largest abs(z), total / noise",
                    "alternatives' verdicts", "median delta AIC", "wall (s)"],
                   [[r["case"], CASES[r["case"]][3], r["runs"], f"{r['successes']} / {r['runs']}", r["dishonest"],
                     f"{100 * r['cover3']:.0f} %", f"{100 * r['cover3_noise']:.0f} %", f"{100 * r['err_max']:.3g} %",
                     f"{r['z_max']:.1f} / {r['z_noise_max']:.1f}", r["verdicts"], r["aic"], f"{r['wall']:.1f}"]
                    for r in rows]), "", *check_lines]
    write_outputs("modelform", out_dir, quick, "\n".join(page))
    assert_checks(failed)
    return rows


if __name__ == "__main__":
    cli(__doc__, main)
