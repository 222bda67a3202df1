"""What a trial's bands cost (issue 49, goal 2): the marker-noise and anthropometry bands of an inverse run against
the same run without them, CPU time in one process; before (central differences) and now (exact derivatives).

Two trials: Hamner's subject 02 running on the planar whole-body model (tests/data/lab: 1 s at 60 Hz, 61 frames,
41 markers, both plates, OpenSim's IK weights, 6 Hz; six segment masses uncertain by 10 %, the cases of
studies/bench_study.py) and the Hamner stride on the leg (44 frames, one plate, 10 Hz; every segment's mass and
inertia uncertain by 15 %, tests/test_inverse_bands.py's case). Each trial's inverse run (``inverse_dynamics``:
reading, the marker fit, the filter, the loads) is timed without bands, with the markers' band alone and with both,
the bands taken two ways: **exact** (casflex.inverse.load_jacobian: the loads' derivatives along the coordinates,
their rates and the properties from one CasADi function mapped over the frames, as casflex computes them now) and
**central differences** (the route before it: the loads solved again with each coordinate, rate and property moved
both ways, 2 x (3 n_z + n_u) solves; still what the muscles' bands use, passed as ``function``). The cases are taken
in turn, ``ROUNDS`` times, the best CPU time (time.process_time) of each kept: the machine is shared, and CPU time
is what another process does not take. The two routes' bands are compared load by load.

Longer trials (not with ``--quick``): the leg's markers over a synthetic stride-like motion (each coordinate a sum of
two sines at 1.4 and 2.8 Hz, 2 mm of white noise on the markers, no plates) for 5 and 20 s at 100 Hz and 5 s at
1000 Hz (500, 2,000 and 5,000 frames), 6 Hz, the leg's eight properties: without bands against both bands, to show
how the ratio goes with the trial's length (the filter's memory, 150 frames at 100 Hz and 1,160 at 1000 Hz, sets
the markers' band's cost near the ends).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the study's dask workers run

import time  # noqa: E402
from contextlib import contextmanager  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from _study import Banner, assert_checks, checks, cli, png, table, write_outputs  # noqa: E402

LAB = Path(__file__).resolve().parents[1] / "tests" / "data" / "lab"
MASSES = ["pelvis.mass=10%", "torso.mass=10%", "femur_r.mass=10%", "femur_l.mass=10%", "tibia_r.mass=10%",
          "tibia_l.mass=10%"]
TABLE = [f"{b}.{p}=15%" for b in ("pelvis", "thigh", "shank", "foot") for p in ("mass", "inertia")]
#: the cases of a trial: (name, bands' route or None, uncertain properties asked)
CASES = (("none", None, False), ("markers", "exact", False), ("markers+props", "exact", True),
         ("markers, central diff.", "fd", False), ("markers+props, central diff.", "fd", True))


def trials() -> dict:
    """name -> (model, Trial keyword arguments, cutoff Hz, uncertain properties, what it is)."""
    run = ("hamner_subject02_planar.osim",
           {"markers": LAB / "hamner_running_whole.trc", "grf": LAB / "hamner_running_whole_grf.mot",
            "tasks": LAB / "hamner_tasks_ik.xml", "plane": "X,Y",
            "plates": {"calcn_r": "ground_", "calcn_l": "1_ground_"}}, 6.0, MASSES,
           "Hamner's run, whole body (61 frames, 14 coordinates, 2 plates; 6 masses)")
    leg = ("hamner_leg", {"markers": LAB / "hamner_running_stride.trc", "grf": LAB / "hamner_running_stride_grf.mot",
                          "plates": {"ankle": "ground_"}, "root": "pelvis"}, 10.0, TABLE,
           "Hamner's stride, leg (44 frames, 6 coordinates, 1 plate; 8 masses and inertias)")
    return {"run": run, "leg": leg}


#: the long synthetic trials: (rate Hz, duration s)
LONG = ((100.0, 5.0), (100.0, 20.0), (1000.0, 5.0))


def long_trial(rate: float, duration: float):
    """(scene, Trial keyword arguments): the leg's markers over a synthetic motion (module docstring)."""
    from casflex.inverse import inverse_model, kinematic_tree
    from casflex.lab import LabMarkers
    from casflex.model.markers import marker_positions
    from casflex.scene.io import load_scene

    scene = load_scene("hamner_leg")
    model = inverse_model(scene)
    tree = kinematic_tree(model, "pelvis")
    t = np.arange(0.0, duration, 1.0 / rate)
    w = 2 * np.pi * 1.4
    z = np.zeros((t.size, tree.n))
    z[:, 0], z[:, 1], z[:, 2] = 3.5 * t, 0.95 + 0.03 * np.sin(2 * w * t), 0.1 * np.sin(w * t)
    for k in range(3, tree.n):
        z[:, k] = 0.5 * np.sin(w * t + k) + 0.1 * np.sin(2 * w * t + 2 * k)
    y = marker_positions(model, np.array(tree.forward.map(t.size)(z.T)).T).reshape(t.size, -1, 2)
    y = y + 0.002 * np.random.default_rng(0).standard_normal(y.shape)
    lab = LabMarkers(t, tuple(m.lab_label for m in scene.markers), np.concatenate([y, np.zeros_like(y[..., :1])], 2),
                     rate, "m", "synthetic")
    return scene, {"markers": lab, "root": "pelvis", "plane": "X,Y"}


@contextmanager
def route(kind: str | None, seen: dict):
    """Within: the inverse's bands taken by ``kind`` ("exact": as casflex does; "fd": central differences through
    the rigid loads, the route before load_jacobian); the bands stage's CPU s and its bands kept in ``seen``."""
    import casflex.inverse as inverse
    from casflex.inverse.bands import inverse_bands, rigid_load_function

    def timed(spec, inputs, fit, z, zd, zdd, names):
        def solved(z, zd, zdd, p):  # the rigid loads solved again at moved coordinates or properties
            return rigid_load_function(spec.tree, inputs.t, inputs.plates, p)(z, zd, zdd)

        t0 = time.process_time()
        out = inverse_bands(spec, inputs, fit, z, zd, zdd, names, solved if kind == "fd" else None)
        seen["stage"] = time.process_time() - t0
        seen["bands"], seen["parts"] = out[0], out[1]
        return out

    inverse.inverse_bands = timed
    try:
        yield
    finally:
        inverse.inverse_bands = inverse_bands


def run_case(trial: tuple, route_kind: str | None, props: bool) -> tuple[float, dict]:
    """(CPU s, {"stage": s, "bands", "parts"}) of one inverse run of ``trial`` with the case's bands."""
    from casflex.inverse import Bands, Filter, Trial, inverse_dynamics
    from casflex.scene.uncertain import parse

    model, kw, cutoff, uncertain, _ = trial
    bands = Bands(asked=False) if route_kind is None else Bands([parse(u) for u in uncertain] if props else None,
                                                                  asked=True)
    seen: dict = {}
    scene = str(LAB / model) if isinstance(model, str) and model.endswith(".osim") else model
    with route(route_kind or "exact", seen):
        t0 = time.process_time()
        res = inverse_dynamics(scene, Trial(**kw), filter=Filter(cutoff), bands=bands)
        cpu = time.process_time() - t0
    seen["loads"] = res.loads
    return cpu, seen


def agreement(exact: dict, fd: dict) -> dict:
    """The largest difference of the two routes' bands over every load and frame: the markers' relative to that
    load's largest band (or 1e-6 of its largest value where the band is smaller), the anthropometry's and each
    property's part relative to the load's largest value (a load no uncertain property moves, an arm's moment, has
    a band of 0 exactly and of round-off by differences)."""
    peak = {k: float(np.max(np.abs(v))) for k, v in fd["loads"].items() if np.max(np.abs(v)) > 0}
    out = {"markers": max(float(np.max(np.abs(exact["bands"][k]["markers"] - fd["bands"][k]["markers"])))
                          / max(float(np.max(fd["bands"][k]["markers"])), 1e-6 * p) for k, p in peak.items()),
           "anthropometry": max(float(np.max(np.abs(exact["bands"][k]["anthropometry"]
                                                    - fd["bands"][k]["anthropometry"]))) / p
                                for k, p in peak.items())}
    out["parts"] = max((float(np.max(np.abs(exact["parts"][g][k] - fd["parts"][g][k]))) / peak[k]
                        for g in fd["parts"] for k in fd["parts"][g] if k in peak), default=0.0)
    return out


def figure(cpu: dict, names: dict, long: dict) -> bytes:
    """CPU s per trial and case, the ratio to no bands on each bar; the long trials' ratio by frames."""
    from casflex.plotting._figure import _new_figure

    fig = _new_figure((5.5 * (len(cpu) + bool(long)), 4))
    axes = np.atleast_1d(fig.subplots(1, len(cpu) + bool(long)))
    if long:
        frames = [v["frames"] for v in long.values()]
        ratio = [v["bands"] / v["none"] for v in long.values()]
        axes[-1].plot(frames, ratio, "o-")
        for f, r, key in zip(frames, ratio, long, strict=True):
            axes[-1].annotate(f"{key}\n{r:.2f}x", (f, r), fontsize="small", textcoords="offset points", xytext=(4, 4))
        axes[-1].axhline(2.0, color="0.5", ls="--", lw=1)
        axes[-1].set(xscale="log", xlabel="frames", ylabel="with bands / without (CPU, median)", ylim=(0.8, 2.5))
        axes[-1].set_title("the leg, synthetic trials: markers + 8 properties", fontsize="medium")
    for ax, (tr, by) in zip(axes, cpu.items(), strict=False):
        cases = list(by)
        best = [by[c] for c in cases]
        colours = ["0.6" if c == "none" else "tab:red" if "central" in c else "tab:blue" for c in cases]
        bars = ax.bar(np.arange(len(cases)), best, 0.6, color=colours)
        ax.bar_label(bars, labels=[f"{b:.2f} s\n{b / by['none']:.1f}x" for b in best], fontsize="small")
        ax.set_xticks(np.arange(len(cases)), [c.replace(", ", ",\n") for c in cases], fontsize="small")
        ax.set(ylabel="CPU s per trial (median of the rounds)")
        ax.set_title(names[tr].split(" (")[0], fontsize="medium")
        ax.set_ylim(0, 1.25 * max(best))
    return png(fig)


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    banner = Banner("bench_bands", quick)
    rounds = 2 if quick else 5
    specs = trials()
    if quick:
        specs = {"leg": specs["leg"]}
    cpu = {tr: {c[0]: [] for c in CASES} for tr in specs}
    stage = {tr: {c[0]: [] for c in CASES if c[1]} for tr in specs}
    last: dict = {}
    for tr, trial in specs.items():
        run_case(trial, "exact", True)  # imports and first calls apart
        for r in range(rounds):
            for name, kind, props in CASES:
                if kind == "fd" and r >= 2:  # 10x the others: two rounds are enough to know it
                    continue
                s, seen = run_case(trial, kind, props)
                cpu[tr][name].append(s)
                if kind:
                    stage[tr][name].append(seen["stage"])
                last[(tr, name)] = seen
    long = {}
    for rate, duration in ([] if quick else LONG):
        scene, kw = long_trial(rate, duration)
        trial = (scene, kw, 6.0, TABLE, "")
        times = {"none": [], "bands": []}
        for _ in range(3):
            times["none"].append(run_case(trial, None, False)[0])
            times["bands"].append(run_case(trial, "exact", True)[0])
        long[f"{duration:g} s at {rate:g} Hz"] = {"frames": int(round(rate * duration)),
                                                  **{k: float(np.median(v)) for k, v in times.items()}}
    best = {tr: {c: min(v) for c, v in by.items()} for tr, by in cpu.items()}
    med = {tr: {c: float(np.median(v)) for c, v in by.items()} for tr, by in cpu.items()}
    agree = {tr: agreement(last[(tr, "markers+props")], last[(tr, "markers+props, central diff.")]) for tr in specs}
    names = {tr: specs[tr][4] for tr in specs}
    rows = []
    for tr in specs:
        for name, _, _ in CASES:
            st = f"{min(stage[tr][name]):.3f}" if name in stage[tr] else "-"
            rows.append([names[tr] if name == "none" else "", name, " / ".join(f"{v:.2f}" for v in cpu[tr][name]),
                         f"{best[tr][name]:.3f}", f"{med[tr][name]:.3f}", st,
                         f"{best[tr][name] / best[tr]['none']:.2f} x / {med[tr][name] / med[tr]['none']:.2f} x"])
    page = ["# What a trial's bands cost", "",
            f"{banner.line()} What is measured: the docstring of studies/bench_bands.py.", "",
            f"**The machine's load.** The machine ({os.cpu_count()} cores) is shared with other work: load average "
            f"{banner.load0:.2f} at the start, {os.getloadavg()[0]:.2f} at the end. Times are CPU times "
            "(time.process_time) of this one process, the cases taken in turn and the best of "
            f"{rounds} rounds kept (2 for the central differences), and their median; ratios are of times measured "
            "side by side in this run. The CPU time of a case varies by up to 1.5x between rounds on this loaded "
            "machine (the other processes share the cores' caches): one lucky round of a case moves its best, so the "
            "ratios are given on both.", "",
            "![CPU time per trial without bands, with exact bands, with central differences](../figures/"
            "bench_bands.png)", "",
            "## One trial's inverse run in one process", "",
            "The whole `inverse_dynamics` call (reading the files, the marker fit, the filter, the loads and the "
            "bands); \"bands stage\" is casflex.inverse.bands.inverse_bands alone. \"props\": the trial's uncertain "
            "properties (anthropometry) with the markers' band.", "",
            *table(["trial", "bands", "CPU s (each round)", "best CPU s", "median CPU s", "bands stage s (best)",
                    "against no bands (best / median)"], rows, "llrrrrr"), "",
            "## The two routes' bands", "",
            "The largest difference between the exact bands and the central differences' over every load and frame: "
            "the markers' band relative to that load's largest band (at least 1e-6 of the load's largest value), the "
            "anthropometry's band and each property's part relative to the load's largest value (a load no uncertain "
            "property moves, an arm's moment, has an anthropometry band of 0 exactly and of round-off by "
            "differences). The central differences' error (a step of 1e-5 along z: ~1e-10 relative) and round-off.",
            "",
            *table(["trial", "markers' band", "anthropometry's band", "properties' parts"],
                   [[names[tr], f"{a['markers']:.1e}", f"{a['anthropometry']:.1e}", f"{a['parts']:.1e}"]
                    for tr, a in agree.items()], "lrrr"), ""]
    if long:
        page += ["## Longer trials", "",
                 "The leg over a synthetic motion (module docstring), no bands against the markers' band and the eight "
                 "properties' (exact), the median CPU s of 3 rounds each.", "",
                 *table(["trial", "frames", "no bands s", "bands s", "against no bands"],
                        [[k, str(v["frames"]), f"{v['none']:.2f}", f"{v['bands']:.2f}",
                          f"{v['bands'] / v['none']:.2f} x"] for k, v in long.items()], "lrrrr"), ""]
    main_tr = "run" if "run" in specs else "leg"
    ratio = med[main_tr]["markers+props"] / med[main_tr]["none"]
    ok = [("the exact and central differences' bands agree (markers' band, relative)",
           " / ".join(f"{a['markers']:.1e}" for a in agree.values()), all(a["markers"] < 1e-6 for a in agree.values())),
          ("the anthropometry's band agrees to round-off (relative to the load)",
           " / ".join(f"{a['anthropometry']:.1e}" for a in agree.values()),
           all(a["anthropometry"] < 1e-10 for a in agree.values())),
          ("the bands leave the loads as they are", "exact and central differences",
           all(np.array_equal(last[(tr, "markers+props")]["loads"][k], last[(tr, "none")]["loads"][k])
               for tr in specs for k in last[(tr, "none")]["loads"])),
          (f"{names[main_tr]}: markers + properties at most 2x the run without bands (issue 49; medians)",
           f"{ratio:.2f} x",
           ratio <= 2.0, False),
          *([("the longer trials: bands at most 2x the run without them",
              " / ".join(f"{v['bands'] / v['none']:.2f} x" for v in long.values()),
              all(v["bands"] <= 2.0 * v["none"] for v in long.values()), False)] if long else [])]
    lines, failed = checks(ok)
    write_outputs("bench_bands", out_dir, quick, "\n".join(page + lines), figure(med, names, long))
    assert_checks(failed)
    return {"cpu": cpu, "stage": stage, "agreement": agree, "long": long}


if __name__ == "__main__":
    cli(__doc__, main)
