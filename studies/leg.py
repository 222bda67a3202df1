"""The hip joint force of a swinging leg, from markers: the joint parameters identified, the force
reported with its uncertainty band.

Fitted by two models: the scene's flexible bones (``leg``) and rigid links (``leg_rigid``).
Set-up and how to read the page: docs/studies/leg.md. Run: ``python studies/leg.py`` (about 10 min on 2
cores; ``--quick``: one stride, one seed per model, 10 draws).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
from _shared import honesty
from _study import Banner, cli, sweep, table, write_outputs

MARKERS = ("THI", "KNE", "TIB", "ANK", "TOE")
SCENES = {"leg": "flexible bones (`leg`)", "leg_rigid": "rigid links (`leg_rigid`)"}  # the fitted models
NOISE = 1e-3
SEEDS = 10
DRAWS = 40


def _force(model, tr) -> np.ndarray:
    """|hip joint force| (N) along a trajectory: the bushing's elastic and damper parts."""
    i = {n: k for k, n in enumerate(model.output_names)}
    o = np.asarray(tr.outputs)
    fx = o[:, i["hip_joint.fx"]] + o[:, i["hip_joint.damper_fx"]]
    fy = o[:, i["hip_joint.fy"]] + o[:, i["hip_joint.damper_fy"]]
    return np.hypot(fx, fy)


def _truth(t_end: float):
    """The fine model's motion: (model, trajectory, hip force)."""
    import dataclasses

    import casflex
    from casflex.simulate import simulate

    scene = casflex.load_scene("leg")
    fine = casflex.assemble(dataclasses.replace(scene, beams=tuple(dataclasses.replace(b, elements=4)
                                                                   for b in scene.beams)))
    tr = simulate(fine, t_end, dt=2.5e-4, alpha=scene.run.alpha)
    return fine, tr, _force(fine, tr)


def one_run(*, seed: int, quick: bool, scene: str = "leg") -> dict:
    """One seed (a sweep run): the fit, and the hip force at the estimate and at the draws."""
    from scipy.ndimage import maximum_filter1d

    import casflex
    from casflex.data import MeasurementSet
    from casflex.identification import identify_indirect
    from casflex.identification.estimate import RICHARDSON, refined
    from casflex.simulate import simulate

    t_end = 1.1 if quick else 2.2
    fine, tr, f_true = _truth(t_end)
    rows = np.arange(0, tr.t.size, 40)  # 100 Hz from the 4 kHz truth
    names = tuple(f"{c}{m}" for m in MARKERS for c in "xy")
    q = np.column_stack([tr.output(f"{m}.{c}")[rows] for m in MARKERS for c in "xy"])
    data = MeasurementSet(tr.t[rows], names, q + np.random.default_rng(seed).normal(0, NOISE, q.shape), None, None)
    model = casflex.assemble(casflex.load_scene(scene))
    t0 = time.perf_counter()
    r = identify_indirect(model, data, dt=1e-3, start=0.7, model_error="none" if quick else "refine")
    wall = time.perf_counter() - t0
    names = list(model.parameter_names)
    se = np.array([r.std_errors[k] for k in names])
    cov = np.asarray(r.correlation) * np.outer(se, se)
    est = simulate(model, t_end, dt=1e-3, p=r.p)
    f_est = _force(model, est)
    draws = np.random.default_rng(1000 + seed).multivariate_normal(r.p, cov, size=10 if quick else DRAWS)
    forces = [_force(model, simulate(model, t_end, dt=1e-3, p=np.maximum(d, 0.0))) for d in draws]
    lo, hi = np.percentile(np.array(forces), [2.5, 97.5], axis=0)
    # the model's own error in the force: Richardson's estimate from the refined model (twice the
    # elements, half the step) at the same parameters, as the identification estimates it for p
    finer = refined(model)
    f_model = RICHARDSON * np.abs(_force(finer, simulate(finer, t_end, dt=5e-4, p=r.p))[::2] - f_est)
    # its envelope over 49 ms, a period of the fastest oscillation in the force (the bushings' 21 Hz
    # ring): the pointwise difference crosses zero twice a period, the error does not vanish there
    f_model = maximum_filter1d(f_model, size=49, mode="nearest")
    f_true_c = f_true[::4]  # the truth at the model's 1 ms steps
    inside = (f_true_c >= lo) & (f_true_c <= hi)
    inside_all = (f_true_c >= lo - f_model) & (f_true_c <= hi + f_model)
    err = r.p - model.p_nominal
    residual = np.concatenate([np.asarray(smp["measured"]) - np.asarray(smp["model"]) for smp in r.samples])
    return {"seed": seed, "scene": scene, "residual_rms": float(np.sqrt(np.mean(residual**2))),
            "names": names, "truth": model.p_nominal.tolist(), "estimate": r.p.tolist(), "se": se.tolist(),
            "z": (err / se).tolist(), "rel_error": (err / model.p_nominal).tolist(), "success": bool(r.success),
            "message": r.message, "wall_s": wall, "t": est.t.tolist(), "f_true": f_true_c.tolist(),
            "f_est": f_est.tolist(), "lo": lo.tolist(), "hi": hi.tolist(),
            "force_rms": float(np.sqrt(np.mean((f_est - f_true_c) ** 2))), "band_width": float(np.median(hi - lo)),
            "inside": float(inside.mean()), "model_error": f_model.tolist(),
            "model_error_median": float(np.median(f_model)), "inside_all": float(inside_all.mean())}


def _tables(recs: list[dict]) -> list[str]:
    """One model's fits: errors and coverage per parameter; per seed the force's error and band."""
    names, h = recs[0]["names"], honesty(recs)
    err = np.abs(np.array([r["rel_error"] for r in recs]))
    return [f"Runs: {len(recs)}; success {100 * h['success'].mean():.0f} %; dishonest (success with a parameter "
            f"more than 3 SE from the truth): {h['dishonest']}; largest |z| {h['z'].max():.1f}; an identification "
            f"takes {np.median([r['wall_s'] for r in recs]):.0f} s (median, 2 runs at a time on 2 cores).", "",
            *table(["parameter", "truth", "error (median / max)", "2 SE", "3 SE"],
                   [[n, f"{recs[0]['truth'][j]:g}",
                     f"{100 * np.median(err[:, j]):.3g} % / {100 * err[:, j].max():.3g} %",
                     f"{100 * h['cover2'][:, j].mean():.0f} %", f"{100 * h['cover3'][:, j].mean():.0f} %"]
                    for j, n in enumerate(names)]), "",
            *table(["seed", "success", "hip force RMS error (N)", "parameter band, median width (N)", "truth inside it",
                    "model error, median (N)", "truth inside both", "residual RMS / noise", "wall (s)"],
                   [[r["seed"], "yes" if r["success"] else "no: " + r["message"], f"{r['force_rms']:.3g}",
                     f"{r['band_width']:.3g}", f"{100 * r['inside']:.0f} %", f"{r['model_error_median']:.3g}",
                     f"{100 * r['inside_all']:.0f} %", f"{r['residual_rms'] / NOISE:.2f}", f"{r['wall_s']:.1f}"]
                    for r in recs])]


def page(runs: dict[str, list[dict]], banner: str) -> str:
    """The two models' tables, and the hip force's peak against the leg's weight."""
    import casflex

    lines = ["# The hip joint force of a swinging leg, from markers", "",
             f"{banner} The set-up, how the band is built and read, and what the rigid links show: "
             "[studies/leg.md](../studies/leg.md).", ""]
    for scene, recs in runs.items():
        lines += [f"## Fitted with {SCENES[scene]}", "", *_tables(recs), ""]
    scene = casflex.load_scene("leg")
    mass = sum(b.rho * b.A * scene.distance(*b.nodes) for b in scene.beams) + sum(b.mass for b in scene.bodies)
    peak = max(max(r["f_true"]) for recs in runs.values() for r in recs)
    lines += [f"The hip force peaks at {peak:.0f} N (the leg weighs {9.81 * mass:.0f} N)."]
    return "\n".join(lines) + "\n"


def figure(rec: dict, rigid: dict, path: Path) -> None:
    """The identified force, its band and the truth (top); the band, the truth and the rigid links' force
    about the identified force."""
    from casflex.plotting._figure import _new_figure, _save

    fig = _new_figure((8.0, 5.6))
    ax, dev = fig.subplots(2, 1, sharex=True, height_ratios=(3, 2))
    t, f = np.array(rec["t"]), np.array(rec["f_est"])
    ax.fill_between(t, rec["lo"], rec["hi"], color="C0", alpha=0.3, lw=0, label="95 % band (parameter draws)")
    ax.plot(t, f, color="C0", lw=1.0, label="identified model")
    ax.plot(t, rec["f_true"], color="black", lw=0.8, ls="--", label="truth (finer model)")
    ax.set_ylabel("|hip joint force| (N)")
    ax.legend(fontsize="small", frameon=False, loc="lower right")
    # the band is narrow against the force: the lower panel shows both about the identified force
    me = np.array(rec["model_error"])
    dev.fill_between(t, np.array(rec["lo"]) - f - me, np.array(rec["hi"]) - f + me, color="C1", alpha=0.25, lw=0,
                     label="with the model's own error")
    dev.fill_between(t, np.array(rec["lo"]) - f, np.array(rec["hi"]) - f, color="C0", alpha=0.3, lw=0,
                     label="parameters only")
    dev.plot(t, np.array(rec["f_true"]) - f, color="black", lw=0.8, ls="--")
    dev.plot(t, np.array(rigid["f_est"]) - f, color="C3", lw=0.8, label="identified rigid links")
    dev.legend(fontsize="small", frameon=False, loc="lower right", ncol=3)
    dev.set_ylabel("minus identified (N)")
    dev.set_xlabel("t (s)")
    for a in (ax, dev):
        a.grid(True, alpha=0.3)
    fig.suptitle("leg swinging from a walking pelvis: hip joint force from five markers at 1 mm")
    _save(fig, path)


def main(quick: bool = False, out_dir: Path | None = None, record: Path | None = None) -> dict[str, list[dict]]:
    banner = Banner("leg", quick)
    plan = [{"seed": s, "quick": quick, "scene": sc} for sc in SCENES for s in range(1 if quick else SEEDS)]
    done = sweep("leg", plan, lambda r: f"{r['scene']}-seed{r['seed']}", one_run, record=record, quick=quick)
    runs = {sc: [rec for run, rec in done if run["scene"] == sc and "error" not in rec] for sc in SCENES}
    assert all(runs.values()), {sc: len(v) for sc, v in runs.items()}
    write_outputs("leg", out_dir, quick, page(runs, banner.line()),
                  lambda f: figure(runs["leg"][0], runs["leg_rigid"][0], f))
    for r in (r for recs in runs.values() for r in recs):
        print(json.dumps({k: r[k] for k in ("scene", "seed", "estimate", "se", "z", "success", "force_rms",
                                            "band_width", "inside", "residual_rms", "wall_s")}))
    # the study's checks on the flexible model (the truth's form): at most one fit in ten
    # unsuccessful (the plausibility checks may flag the model's own error on a marker that hardly
    # moves: seed 7, yTHI fitted to 95 %), a success with a parameter beyond 3 SE of the truth at
    # most once in ten, and the hip force within 5 % of its peak
    recs = runs["leg"]
    h = honesty(recs)
    assert (~h["success"]).sum() <= round(0.1 * len(recs)), [r["message"] for r in recs]
    assert h["dishonest"] <= max(1, round(0.1 * len(recs))), h["z"]
    assert h["z"].max() < 5, h["z"]  # one that a single run can fail: a 5-SE miss, 6e-7 with honest SE
    # with either model the fit leaves residuals at the noise level (within 10 %: the RMS of 1100
    # noise samples scatters by 2 %) and the hip force within 5 % of its peak
    for r in (r for recs in runs.values() for r in recs):
        assert abs(r["residual_rms"] / NOISE - 1) < 0.1, (r["scene"], r["residual_rms"])
        assert r["force_rms"] < 0.05 * max(r["f_true"]), r["force_rms"]
    return runs


if __name__ == "__main__":
    cli(__doc__, main)
