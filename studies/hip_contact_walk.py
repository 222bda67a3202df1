"""The right hip's contact force over the gait cycle of a public walk, with its band, beside the instrumented
implants' (Bergmann et al. 2001).

The Rajagopal pipeline's walk (tests/data/muscles: the cut trial and the planar, edited Rajagopal 2016 model;
provenance in the README there) through what ``casflex muscles`` does from the markers:

    casflex muscles tests/data/muscles/rajagopal_walk_planar_muscles.osim --data .../rajagopal_walk.trc \\
        --tasks .../rajagopal_walk_ik_tasks.xml --loads .../rajagopal_walk_grf.xml --filter opensim --cutoff 6 \\
        --cutoff-plates none --reserves 1 --joints hip_r,walker_knee_r,ankle_r \\
        --muscle-uncertainty max_isometric_force=10% --muscle-uncertainty optimal_fiber_length=10% \\
        --muscle-uncertainty tendon_slack_length=10% --uncertain femur_r.mass=10% --uncertain tibia_r.mass=10% \\
        --uncertain pelvis.mass=10% --uncertain torso.mass=10% --marker-noise 0 --out ...

(casflex's marker fit with the pipeline's weights; OpenSim's filter at 6 Hz; a reserve of 1 N m on each coordinate
and the residuals on the pelvis; the bands one SD from every muscle's max isometric force, optimal fibre and tendon
slack lengths at 10 % each, independent, by a Monte Carlo (``--draws``, here DRAWS), and from the masses of the
pelvis, torso, right thigh and shank at 10 %; the markers taken as exact (``--marker-noise 0``: the planar fit's
residuals, some 14 mm, are the model's missing out-of-plane motion, not noise); static optimization's exponent 3
beside its 2). The gait cycle: from
the right plate's strike (vertical force above 20 N) to its next. Figure and table: docs/figures/hip_contact_walk.png,
docs/tables/hip_contact_walk.md; what they mean: docs/muscles.md, "The hip over a gait cycle".
``--quick``: 10 draws, max isometric force only (first order).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from _study import Banner, assert_checks, checks, cli, png, table, write_outputs

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data" / "muscles"
MODEL = DATA / "rajagopal_walk_planar_muscles.osim"
DRAWS = 100
STANCE_N = 20.0  # N: the right plate's vertical force above this is contact
UNCERTAIN_MASSES = ("femur_r.mass=10%", "tibia_r.mass=10%", "pelvis.mass=10%", "torso.mass=10%")
#: Bergmann et al. 2001 (J Biomech 34:859-871), normal walking at about 4 km/h: the four patients' average peak
#: (238 % BW) and the typical patient's (about 250 % BW, their Fig. / Table: "about 2.5 BW")
IN_VIVO = (2.38, 2.50)


def run(quick: bool) -> dict:
    """casflex's muscle path with the bands (module docstring); the result and the seconds."""
    from casflex.cli._base import uncertain_option
    from casflex.inverse import Bands, Filter, Fit, Trial, prepare, solve
    from casflex.muscles.analysis import TrialMuscles, muscle_result, reserve_actuators
    from casflex.muscles.bands import muscle_bands
    from casflex.muscles.options import MuscleUncertainty
    from casflex.muscles.reaction import JointReaction
    from casflex.scene.from_osim import scene_from_osim
    from casflex.scene.osim_actuators import read_actuators

    start = time.perf_counter()
    osim = scene_from_osim(str(MODEL), muscles=True)
    trial = Trial(str(DATA / "rajagopal_walk.trc"), grf=str(DATA / "rajagopal_walk_grf.xml"),
                  tasks=str(DATA / "rajagopal_walk_ik_tasks.xml"), t_start=0.1, t_end=1.75)
    inputs = prepare(str(MODEL), trial, filter=Filter(6.0, None, "opensim"), fit=Fit(),
                     bands=Bands([uncertain_option(u) for u in UNCERTAIN_MASSES], 0.0, True))
    acts = read_actuators(str(MODEL)) + reserve_actuators(osim.scene, inputs.tree.root, 1.0)
    tm = TrialMuscles(osim, inputs.tree, inputs.t, inputs.plates, acts, reaction=JointReaction(on="child",
                      frame="child"), joints=("hip_r", "walker_knee_r", "ankle_r"), source=str(MODEL))
    res = solve(inputs)
    out = tm.solve(res.z, res.zd, res.zdd)
    result = muscle_result(tm, out, res.z)
    unc = MuscleUncertainty(max_isometric_force=0.1) if quick else MuscleUncertainty(0.1, 0.1, 0.1)
    mb = muscle_bands(tm, inputs, None, res.z, res.zd, res.zdd, uncertainty=unc, criteria=(3.0,),
                      draws=10 if quick else DRAWS)
    return {"t": result.t, "result": result, "bands": mb, "seconds": time.perf_counter() - start,
            "grf": inputs.plates}


def cycle(t: np.ndarray) -> tuple[float, float, float]:
    """(strike, next strike, toe-off between) of the right foot (s): the right plate's vertical force crossing
    STANCE_N up, and down."""
    from casflex.lab.tables import read_sto

    grf = read_sto(DATA / "rajagopal_walk_grf.mot")
    on = grf.column("ground_force_r_vy") > STANCE_N
    ups = grf.t[1:][np.diff(on.astype(int)) == 1]
    ups = ups[(ups >= t[0]) & (ups <= t[-1])]
    if len(ups) < 2:
        raise ValueError(f"rajagopal_walk_grf.mot: {len(ups)} right strikes inside the trial; a cycle needs two")
    off = grf.t[1:][(np.diff(on.astype(int)) == -1) & (grf.t[1:] > ups[0])][0]
    return float(ups[0]), float(ups[1]), float(off)


def figure(r: dict, strike: float, end: float, off: float) -> bytes:
    from casflex.plotting._figure import _new_figure

    t, res, mb = r["t"], r["result"], r["bands"]
    bw = res.body_weight
    inside = (t >= strike - 1e-9) & (t <= end + 1e-9)
    pct = 100 * (t[inside] - strike) / (end - strike)
    hip = res.resultants["hip_r"][inside] / bw
    sd = mb.bands["hip_r_resultant"]["total"][inside] / bw
    p3 = (res.resultants["hip_r"] + mb.spread["hip_r_resultant"]["p3"])[inside] / bw
    fig = _new_figure((9, 5))
    ax = fig.add_subplot(1, 1, 1)
    ax.axvspan(0, 100 * (off - strike) / (end - strike), color="0.93", lw=0, label="right stance")
    ax.fill_between(pct, hip - sd, hip + sd, color="C0", alpha=0.25, lw=0,
                    label="+-1 SD: muscle properties 10 % and segment masses 10 %")
    ax.plot(pct, hip, color="C0", lw=1.8, label="casflex, planar Rajagopal 2016 (edited), static optimization p = 2")
    ax.plot(pct, p3, color="C1", lw=1.0, ls="--", label="the same, p = 3 (beside the band, not in it)")
    ax.axhspan(*IN_VIVO, color="C2", alpha=0.35, lw=0,
               label="in vivo peak, walking: 2.38-2.5 BW (Bergmann et al. 2001)")
    ax.set(xlabel="% of the right gait cycle (from the right plate's strike)", ylabel="body weights",
           title="Right hip contact force over the Rajagopal pipeline's walk")
    ax.set_xlim(0, 100)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", framealpha=0.9)
    return png(fig)


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    banner = Banner("hip_contact_walk", quick)
    r = run(quick)
    t, res, mb = r["t"], r["result"], r["bands"]
    strike, end, off = cycle(t)
    bw = res.body_weight
    inside = (t >= strike - 1e-9) & (t <= off + 1e-9)
    hip = res.resultants["hip_r"]
    b = mb.bands["hip_r_resultant"]
    peaks = []
    pct = 100 * (t - strike) / (end - strike)
    for what, sel in (("weight acceptance (5-30 % of the cycle)", inside & (pct >= 5) & (pct <= 30)),
                      ("push-off (30 % to toe-off)", inside & (pct > 30))):
        k = int(np.flatnonzero(sel)[np.argmax(hip[sel])])
        p3 = hip[k] + mb.spread["hip_r_resultant"]["p3"][k]
        peaks.append([what, f"{100 * (t[k] - strike) / (end - strike):.0f} %", f"{hip[k] / bw:.2f}",
                      f"{b['total'][k] / bw:.2f}", f"{b['muscles'][k] / bw:.2f}", f"{b['anthropometry'][k] / bw:.2f}",
                      f"{p3 / bw:.2f}", f"{hip[k] / bw / IN_VIVO[0]:.2f}"])
    page = ["# The right hip's contact force over a gait cycle, with its band", "",
            f"{banner.line()} What it is: [muscles.md](../muscles.md#the-hip-over-a-gait-cycle).", "",
            f"![hip contact force over the gait cycle](../figures/hip_contact_walk{'_quick' * quick}.png)", "",
            f"The Rajagopal pipeline's walk, {len(t)} frames; right strike at {strike:.3f} s, toe-off at {off:.3f} s, "
            f"next strike at {end:.3f} s; body weight {bw:.0f} N. Bands: "
            + ("max isometric force 10 % (first order)" if quick else
               f"max isometric force, optimal fibre and tendon slack lengths 10 % each ({DRAWS} draws)")
            + ", masses of pelvis, torso, right thigh and shank 10 %.", "",
            *table(["peak", "at (% cycle)", "casflex (BW)", "1 SD (BW)", "muscles' part", "anthropometry's part",
                    "p = 3 (BW)", "over 2.38 BW"], peaks, "lrrrrrrr"), "",
            *(f"    {line}" for line in mb.summary()[:3]), "", *(f"- {line}" for line in mb.report), "",
            f"casflex's muscle path with its bands took {r['seconds']:.0f} s."]
    lines, failed = checks([("the band is finite and positive over the stance", f"{b['total'][inside].min() / bw:.3f}"
                             f"-{b['total'][inside].max() / bw:.3f} BW",
                             bool(np.isfinite(b["total"][inside]).all() and (b["total"][inside] > 0).all())),
                            ("static optimization satisfied every frame", f"{res.report or 'no frame refused'}",
                             not any("refused" in line for line in res.report))])
    write_outputs("hip_contact_walk", out_dir, quick, "\n".join(page + ["", *lines]),
                  figure(r, strike, end, off))
    assert_checks(failed)
    return r


if __name__ == "__main__":
    cli(__doc__, main)
