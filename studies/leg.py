"""The hip joint force of a swinging leg, from markers: the joint parameters identified, the force with its band.

Prose: docs/studies/leg.md. Run: ``python studies/leg.py`` (about 10 min on 2 cores; ``--quick``: one stride, one
seed per model, 10 draws).
"""

from __future__ import annotations

import dataclasses
import functools
import time
from pathlib import Path

import numpy as np
from _shared import fit_errors, honesty
from _study import Banner, assert_checks, checks, cli, sweep, table, write_outputs

from casflex.identification import ModelRun, Uncertainty

MARKERS = ("THI", "KNE", "TIB", "ANK", "TOE")
SCENES = ("leg", "leg_rigid")  # the fitted models: flexible bones, rigid links
NOISE = 1e-3
SEEDS = 10
DRAWS = 40


def _force(model, t_end: float, dt: float = 1e-3, alpha: float | None = None, **kw):
    """A simulation, and its |hip joint force| (N): the bushing's elastic and damper parts."""
    from casflex.simulate import Stepping, simulate

    tr = simulate(model, t_end, stepping=Stepping(dt=dt, alpha=alpha), **kw)
    o, i = np.asarray(tr.outputs), {n: k for k, n in enumerate(model.output_names)}
    return tr, np.hypot(*(o[:, i[f"hip_joint.{c}"]] + o[:, i[f"hip_joint.damper_{c}"]] for c in ("fx", "fy")))


@functools.lru_cache(maxsize=2)
def _truth(t_end: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The finer model's markers at 100 Hz (times, (k, 10)) and |hip force| at 4 kHz: once per worker process."""
    import casflex

    leg = casflex.load_scene("leg")
    fine = dataclasses.replace(leg, beams=tuple(dataclasses.replace(b, elements=4) for b in leg.beams))
    tr, f_true = _force(casflex.assemble(fine), t_end, dt=2.5e-4, alpha=leg.run.alpha)
    rows = np.arange(0, tr.t.size, 40)  # 100 Hz from the 4 kHz truth
    return tr.t[rows], np.column_stack([tr.output(f"{m}.{c}")[rows] for m in MARKERS for c in "xy"]), f_true


def one_run(*, seed: int, quick: bool, scene: str) -> dict:
    from scipy.ndimage import maximum_filter1d

    import casflex
    from casflex.data import MeasurementSet
    from casflex.identification import identify_indirect
    from casflex.identification.estimate import RICHARDSON, refined

    t_end = 1.1 if quick else 2.2
    t, q, f_true = _truth(t_end)
    data = MeasurementSet(t, tuple(f"{c}{m}" for m in MARKERS for c in "xy"),
                          q + np.random.default_rng(seed).normal(0, NOISE, q.shape), None, None)
    model = casflex.assemble(casflex.load_scene(scene))
    t0 = time.perf_counter()
    # each model's alternative form is the other (rigid links for flexible bones, and back): compared by AIC
    other = next(sc for sc in SCENES if sc != scene)
    r = identify_indirect(model, data, start=0.7, run=ModelRun(dt=1e-3),
                          uncertainty=Uncertainty(model_error="none" if quick else "refine", alternatives=[other]))
    wall = time.perf_counter() - t0
    fit = fit_errors(model, r)
    se = np.array(fit.pop("se"))
    est, f_est = _force(model, t_end, p=r.p)
    draws = np.random.default_rng(1000 + seed).multivariate_normal(r.p, np.asarray(r.correlation) * np.outer(se, se),
                                                                   size=10 if quick else DRAWS)
    lo, hi = np.percentile([_force(model, t_end, p=np.maximum(d, 0.0))[1] for d in draws], [2.5, 97.5], axis=0)
    # the model's own error (Richardson's estimate from the refined model, as the identification's for p), enveloped
    # over 49 ms, the bushings' 21 Hz ring: the pointwise difference crosses zero twice a period, the error does not
    f_model = maximum_filter1d(RICHARDSON * np.abs(_force(refined(model), t_end, dt=5e-4, p=r.p)[1][::2] - f_est),
                               size=49, mode="nearest")
    f_true = f_true[::4]  # the truth at the model's 1 ms steps
    residual = np.concatenate([np.asarray(smp["measured"]) - np.asarray(smp["model"]) for smp in r.samples])
    # refused for the model's form alone (another form fits as well and moves the parameters beyond their noise)
    form_only = not r.success and not r.extra["refusal"]["other"]
    return fit | {"wall_s": wall, "form_only": form_only, "residual_rms": float(np.sqrt(np.mean(residual**2))),
            "t": est.t.tolist(),
            "seed": seed, "f_true": f_true.tolist(), "f_est": f_est.tolist(), "lo": lo.tolist(), "hi": hi.tolist(),
            "model_error": f_model.tolist(), "force_rms": float(np.sqrt(np.mean((f_est - f_true) ** 2))),
            "band_width": float(np.median(hi - lo)), "inside": float(np.mean((f_true >= lo) & (f_true <= hi))),
            "inside_all": float(np.mean((f_true >= lo - f_model) & (f_true <= hi + f_model)))}


def figure(rec: dict, rigid: dict, path: Path) -> None:
    """The identified force, its band and the truth (top); the bands, the truth and the rigid links' force about
    the identified force (bottom: the band is narrow against the force)."""
    from casflex.plotting._figure import _new_figure, _save

    fig = _new_figure((8.0, 5.6))
    ax, dev = fig.subplots(2, 1, sharex=True, height_ratios=(3, 2))
    t, f, lo, hi, me = (np.array(rec[k]) for k in ("t", "f_est", "lo", "hi", "model_error"))
    ax.fill_between(t, lo, hi, color="C0", alpha=0.3, lw=0, label="95 % band (parameter draws)")
    ax.plot(t, f, color="C0", lw=1.0, label="identified model")
    ax.plot(t, rec["f_true"], color="black", lw=0.8, ls="--", label="truth (finer model)")
    ax.set_ylabel("|hip joint force| (N)")
    ax.legend(fontsize="small", frameon=False, loc="lower right")
    dev.fill_between(t, lo - f - me, hi - f + me, color="C1", alpha=0.25, lw=0, label="with the model's own error")
    dev.fill_between(t, lo - f, hi - f, color="C0", alpha=0.3, lw=0, label="parameters only")
    dev.plot(t, rec["f_true"] - f, color="black", lw=0.8, ls="--")
    dev.plot(t, rigid["f_est"] - f, color="C3", lw=0.8, label="identified rigid links")
    dev.legend(fontsize="small", frameon=False, loc="lower right", ncol=3)
    dev.set(ylabel="minus identified (N)", xlabel="t (s)")
    for a in (ax, dev):
        a.grid(True, alpha=0.3)
    fig.suptitle("leg swinging from a walking pelvis: hip joint force from five markers at 1 mm")
    _save(fig, path)


def main(quick: bool = False, out_dir: Path | None = None, record: Path | None = None) -> dict[str, list[dict]]:
    banner = Banner("leg", quick)
    plan = [{"seed": s, "quick": quick, "scene": sc} for sc in SCENES for s in range(1 if quick else SEEDS)]
    done = sweep("leg", plan, "{scene}-seed{seed}".format_map, one_run, record=record, quick=quick)
    runs = {sc: [rec for run, rec in done if run["scene"] == sc and "error" not in rec] for sc in SCENES}
    assert all(runs.values()), {sc: len(v) for sc, v in runs.items()}
    params, seeds = [], []  # the tables' rows: per model and parameter, per model and seed
    for sc, recs in runs.items():
        err, h = np.abs(np.array([r["rel_error"] for r in recs])), honesty(recs)
        params += [[sc, n, f"{truth:g}", f"{100 * np.median(e):.3g} % / {100 * e.max():.3g} %",
                    f"{100 * c2.mean():.0f} %", f"{100 * c3.mean():.0f} %"]
                   for n, truth, e, c2, c3 in zip(recs[0]["names"], recs[0]["truth"], err.T, h["cover2"].T,
                                                  h["cover3"].T, strict=True)]
        seeds += [[sc, r["seed"], "yes" if r["success"] else "no: " + r["message"], f"{max(map(abs, r['z'])):.1f}",
                   *(f"{r[k]:.3g}" for k in ("force_rms", "band_width")), f"{100 * r['inside']:.0f} %",
                   f"{np.median(r['model_error']):.3g}", f"{100 * r['inside_all']:.0f} %",
                   f"{r['residual_rms'] / NOISE:.2f}", f"{r['wall_s']:.1f}"] for r in recs]
    # the checks: honesty on the flexible model (the truth's form); residuals and force with either model
    flex, rigid, every = honesty(runs["leg"]), honesty(runs["leg_rigid"]), [r for recs in runs.values() for r in recs]
    limit = round(0.1 * len(runs["leg"]))
    failures = sum(not r["success"] and not r["form_only"] for r in runs["leg"])
    form_only = sum(r["form_only"] for r in runs["leg"])
    residual = max(abs(r["residual_rms"] / NOISE - 1) for r in every)
    force, peak = max(r["force_rms"] / max(r["f_true"]) for r in every), max(max(r["f_true"]) for r in every)
    check_lines, failed = checks([
        ("flexible bones: fits refused for anything but the model's form, at most 1 in 10", failures,
         failures <= limit),
        ("flexible bones: fits refused for the model's form alone (another form fits as well)", form_only, True,
         False),
        ("flexible bones: dishonest successes, at most 1 in 10", flex["dishonest"], flex["dishonest"] <= max(1, limit)),
        ("flexible bones: largest abs(z) < 5 (a 5-SE miss: 6e-7)", f"{flex['z'].max():.1f}", flex["z"].max() < 5),
        ("rigid links: successes with the truth beyond 3 total SE, at most 1 in 10", rigid["dishonest"],
         rigid["dishonest"] <= max(1, limit)),
        ("either model: residual RMS within 10 % of the noise (furthest)", f"{100 * residual:.1f} %", residual < 0.1),
        ("either model: hip force RMS error < 5 % of its peak (largest)", f"{100 * force:.2g} % of {peak:.0f} N",
         force < 0.05)])
    page = ["# The hip joint force of a swinging leg, from markers", "", f"{banner.line()} The set-up, how the band "
            "is built and read, and what the rigid links show: [studies/leg.md](../studies/leg.md).", "",
            *table(["model", "parameter", "truth", "error (median / max)", "2 SE", "3 SE"], params), "",
            *table(["model", "seed", "success", "largest abs(z)", "hip force RMS error (N)",
                    "parameter band, median width (N)", "truth inside it", "model error, median (N)",
                    "truth inside both", "residual RMS / noise", "wall (s)"], seeds), "", *check_lines]
    write_outputs("leg", out_dir, quick, "\n".join(page), lambda f: figure(runs["leg"][0], runs["leg_rigid"][0], f))
    assert_checks(failed)
    return runs


if __name__ == "__main__":
    cli(__doc__, main)
