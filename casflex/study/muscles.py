"""A study's muscles (``[options.muscles]`` of a study file, issue 47): each trial's static optimization and joint
reactions (:mod:`casflex.muscles`) on its subject's calibrated scene, the .osim's muscles carried onto it
(:func:`casflex.muscles.scaling.scaled_muscles`: path points with their segments, optimal fibre and tendon slack
lengths by the muscle-tendon length's ratio, as OpenSim's ScaleTool), cut into the trial's gait cycles.

```toml
[options.muscles]              # the table present: the muscles are computed; every key optional
exponent = 2.0                 # static optimization's sum of activation^p (OpenSim's activation_exponent)
force_length_velocity = true   # false: a muscle's force per activation is its max isometric force
activation_bounds = [0.01, 1.0]  # of the muscles without min_control / max_control of their own (theirs win);
                               # default: each kind's OpenSim default (DeGroote's [0, 1], the others' [0.01, 1])
actuators = "reserves.xml"     # reserves and residuals (an OpenSim ForceSet file), added to the model's own
reserves = 100.0               # or: a reserve of this optimal force (N m) on every joint coordinate, FX FY MZ
joints = ["hip_r", "hip_l"]    # the joints whose reactions the table holds (default: every hinge)
on = "child"                   # the reaction on the joint's child or parent (OpenSim's apply_on_bodies)
frame = "ground"               # expressed in the child's, the parent's or the ground's axes
uncertainty = { max_isometric_force = "10%", tendon_slack_length = "2%" }   # with bands = true: 1 SD each
criteria = [3.0]               # with bands = true: the outputs' spread to these exponents, in the report
                               # (default: 3, or 2 where exponent is 3)
```

The run ``muscles-<subject>-<trial>-<inputs>`` follows the trial's run (its plane and plates, its feet's cycles) and
fingerprints its own inputs (the muscle options, the model, the actuator file): a change of ``[options.muscles]``
redoes the muscle runs only. Its record (:class:`~casflex.study.records.MuscleRecord`): each joint's reaction (fx,
fy, mz, in body weights, BW m) and resultant (the contact force, BW), each muscle's activation, per gait cycle on
0-100 % (``muscles.csv``), their bands where the study asks for bands.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from casflex.study.muscle_options import MuscleOptions
from casflex.study.records import CycleLoad, MuscleRecord
from casflex.study.study_file import StudyError, Trial, TrialOptions

__all__ = ["check_muscles", "muscle_run", "muscle_rows", "run_muscles", "contact_curves"]

def _actuators(model: str, opts: MuscleOptions, scene, root: str) -> tuple:
    from casflex.muscles.analysis import reserve_actuators
    from casflex.scene.osim_actuators import read_actuators

    acts = read_actuators(model)
    if opts.actuators:
        acts += read_actuators(opts.actuators)
    elif opts.reserves is not None:
        acts += reserve_actuators(scene, root, opts.reserves)
    return acts


def _trial_muscles(model: str, scene, opts: MuscleOptions, root: str | None, t=(0.0, 1.0), plates=(),
                   body_weight: float | None = None, osim=None):
    """(TrialMuscles of the subject's scene, report lines): the .osim's muscles carried onto ``scene``."""
    from casflex.inverse.inputs import inverse_model
    from casflex.inverse.tree import kinematic_tree
    from casflex.muscles.analysis import TrialMuscles
    from casflex.muscles.reaction import JointReaction
    from casflex.muscles.scaling import scaled_muscles
    from casflex.scene.from_osim import scene_from_osim

    osim, report = scaled_muscles(osim or scene_from_osim(model, muscles=True), scene, root)
    tree = kinematic_tree(inverse_model(scene, root), root)
    return TrialMuscles(osim, tree, t, plates, _actuators(model, opts, scene, tree.root),
                        optimization=opts.optimization(),
                        reaction=JointReaction(on=opts.on, frame=opts.frame, body_weight=body_weight),
                        joints=opts.joints, source=opts.actuators or model), report


def check_muscles(i: int, model: str, scene, opts: MuscleOptions, root: str | None) -> None:
    """Subject i's model read with its muscles and the muscle options checked against it before any run: an
    OpenSim model with muscles casflex computes, the joints among its hinges, the actuators on its coordinates and
    bodies. StudyError naming the field."""
    from casflex.scene.from_osim import scene_from_osim

    if not str(model).lower().endswith(".osim"):
        raise StudyError(f"subjects[{i}].model: options.muscles needs an OpenSim model (.osim) with its muscles, got "
                         f"{Path(model).name!r}")
    try:
        osim = scene_from_osim(model, muscles=True)
    except ValueError as exc:
        raise StudyError(f"subjects[{i}].model: {exc}") from None
    if not osim.muscles:
        raise StudyError(f"subjects[{i}].model: {Path(model).name} has no muscle casflex computes (Millard2012"
                         "EquilibriumMuscle, Thelen2003Muscle, DeGrooteFregly2016Muscle) for options.muscles")
    hinges = [j.name for j in scene.joints if len(j.nodes) == 2 and j.kind == "hinge"]
    bad = [j for j in opts.joints if j not in hinges]
    if bad:
        raise StudyError(f"options.muscles.joints: {bad[0]!r} is not a hinge of subjects[{i}]'s model (hinges: "
                         f"{hinges[:12]})")
    try:
        tm, _ = _trial_muscles(model, scene, opts, root, osim=osim)
    except ValueError as exc:
        field = "options.muscles.actuators" if opts.actuators else f"subjects[{i}].model"
        raise StudyError(f"{field}: {exc}") from None
    bare = [c.name for c, b in zip(tm.joint_coordinates, tm.bare_coordinates(), strict=True) if b]
    if bare:  # each muscle run would fail on them ("no muscle crosses it and no reserve acts on it")
        field, given = ("options.muscles.actuators", f"{Path(opts.actuators).name} has no reserve on") \
            if opts.actuators else ("options.muscles", "neither actuators nor reserves given, and nothing acts on")
        raise StudyError(f"{field}: {given} {', '.join(bare)}, which no muscle of subjects[{i}]'s model "
                         f"({Path(model).name}) crosses: static optimization has nothing to carry their moments; "
                         "give reserves = N (N m, on every joint coordinate) or an actuators file with reserves there")


def _feet_of(scene, trial_muscles, names: list[str], feet: list[str]) -> dict[str, str | None]:
    """Each output's foot (whose strikes cut it into cycles): a joint's, the foot below its child; a muscle's, the
    foot below its insertion's node; None where no foot is (the first foot's cycles are used)."""
    from casflex.study.events import below

    node = {f"{m.name}.activation": m.path[-1].node for m in trial_muscles.muscles}
    for h in trial_muscles.joints:
        node[h] = scene.item(h).nodes[-1]
    out = {}
    for name in names:
        stem = next((h for h in trial_muscles.joints if name.startswith(f"{h}_")), name)
        carried = below(scene, node[stem]) if stem in node else set()
        out[name] = next((f for f in feet if f in carried), None)
    return out


def muscle_run(*, model: str, scene: str, trial: Trial, options: TrialOptions, plane: str,
               plates: dict[str, str] | None, cycles: dict[str, list], muscles: MuscleOptions,
               uncertain: tuple[str, ...]) -> dict:
    """One trial's muscles (module docstring) on the trial run's ``plane``, ``plates`` and each foot's ``cycles``
    ([(t0, t1), clean] each): its record (:class:`~casflex.study.records.MuscleRecord`) as JSON."""
    from casflex.inverse import Bands, prepare, solve
    from casflex.inverse import Trial as Inverse
    from casflex.lab.plate_checks import scene_mass
    from casflex.muscles.bands import muscle_outputs
    from casflex.scene import loads_scene
    from casflex.scene.uncertain import parse
    from casflex.study.events import read_trial

    sc = loads_scene(scene)
    external = trial.grf is not None and trial.grf.lower().endswith(".xml")  # read by inverse dynamics itself
    lab, table = read_trial(trial.markers, None, plates=False) if external else \
        read_trial(trial.markers, trial.grf, required=False)
    grf = trial.grf if external else table
    t0, t1 = trial.window or (None, None)
    inputs = prepare(sc, Inverse(lab, grf=grf, plates=plates, plane=plane, root=options.root, t_start=t0, t_end=t1,
                                 tasks=options.tasks), filter=options.filter, fit=options.fit,
                     bands=Bands([parse(u) for u in uncertain] or None, asked=bool(options.bands)))
    weight = scene_mass(sc) * float(np.hypot(*sc.gravity))
    tm, report = _trial_muscles(model, sc, muscles, options.root, inputs.t, inputs.plates, body_weight=weight)
    res = solve(inputs)
    frames = tm.solve(res.z, res.zd, res.zdd)
    values = {n: v for n, v in muscle_outputs(tm, frames).items() if n in _kept(tm)}
    bands, lines = {}, []
    if options.bands:
        from casflex.muscles.bands import muscle_bands

        mb = muscle_bands(tm, inputs, None, res.z, res.zd, res.zdd, uncertainty=muscles.uncertainty,
                          criteria=muscles.criteria, draws="auto")
        bands = {n: b["total"] for n, b in mb.bands.items() if n in values}
        lines = [*mb.summary([n for n in values if n.endswith("_resultant")]), *mb.report]
    from casflex.muscles.analysis import residual_warnings, uncrossed_notes

    # what `casflex muscles` says of the trial, the same lines: the residuals' warning, the muscles crossing nothing
    notes = [*tm.notes, *([frames.so.report] if frames.so.report else []), *residual_warnings(tm, frames),
             *uncrossed_notes(tm, frames)]
    outputs = _cut(sc, tm, res.t, values, bands, cycles)
    return MuscleRecord((*report, *notes, *lines), tuple(notes), outputs,
                        {n: _unit(n) for n in outputs}, weight).to_json()


def _kept(tm) -> set[str]:
    """The outputs the table holds: each reported joint's reaction and resultant, each muscle's activation."""
    return {f"{m.name}.activation" for m in tm.muscles} | {f"{h}_resultant" for h in tm.joints} | _reaction_names(tm)


def _reaction_names(tm) -> set[str]:
    from casflex.muscles.bands import _reaction_names as names

    out = set()
    for h in tm.joints:
        body, frame = names(tm, h)
        out |= {f"{h}_on_{body}_in_{frame}_{c}" for c in ("fx", "fy", "mz")}
    return out


def _unit(name: str) -> str:
    return "1" if name.endswith(".activation") else "BW m" if name.endswith("_mz") else "BW"


def _cut(sc, tm, t: np.ndarray, values: dict, bands: dict, cycles: dict[str, list]) -> dict[str, CycleLoad]:
    """Each output cut into its foot's gait cycles (:func:`_feet_of`) and resampled on 0-100 %."""
    from casflex.study.events import normalise

    feet = _feet_of(sc, tm, list(values), list(cycles))
    first = next(iter(cycles), None)
    out = {}
    for name, v in values.items():
        foot = feet[name] if feet[name] is not None else first
        spans = [tuple(c) for c, _ in cycles.get(foot, [])]
        clean = tuple(bool(ok) for _, ok in cycles.get(foot, []))
        band = bands.get(name)
        out[name] = CycleLoad(foot, tuple(spans), clean, tuple(tuple(normalise(t, v, *c).tolist()) for c in spans),
                              None if band is None else tuple(tuple(normalise(t, band, *c).tolist()) for c in spans))
    return out


def foot_cycles(rec) -> dict[str, list]:
    """foot -> [((t0, t1), clean), ...] of a trial run's record (:class:`~casflex.study.records.TrialRecord`)."""
    out: dict[str, list] = {}
    for ld in rec.loads.values():
        if ld.foot is not None and ld.foot not in out:
            clean = ld.clean or (True,) * len(ld.cycles)
            out[ld.foot] = [(list(c), bool(ok)) for c, ok in zip(ld.cycles, clean, strict=True)]
    return out


def muscle_rows(records: dict, percent: np.ndarray) -> list[tuple]:
    """(subject, trial, output, foot, cycle, percent, value, band, unit, clean, t0, t1) rows of the muscle records
    ((subject, trial) -> :class:`~casflex.study.records.MuscleRecord`) on ``percent`` (the gait cycle's 101
    points), as :func:`casflex.study.runner.tidy_rows`."""
    rows = []
    for (subject, trial), rec in records.items():
        for name, ld in rec.outputs.items():
            clean = ld.clean or [None] * len(ld.value)
            for k, values in enumerate(ld.value):
                band = ld.band[k] if ld.band is not None else [None] * len(values)
                t0, t1 = ld.cycles[k]
                rows += [(subject, trial, name, ld.foot, k + 1, float(p), v, b, rec.units[name], clean[k], t0, t1)
                         for p, v, b in zip(percent, values, band, strict=True)]
    return rows



def run_muscles(study, calibrated: dict, trials: dict, record, make_run, **sweep) -> tuple[dict, list, bool]:
    """Every done trial's muscle run (module docstring) on the sweep, each made by ``make_run`` (name, function,
    kwargs, files) (:func:`casflex.study.runner._run`: fingerprinted): ({(subject, trial): MuscleRecord}, failed
    [(what, why)], interrupted)."""
    from casflex.study.sweep import run_sweep

    o = study.options
    plan = {}
    for s, t in study.trials():
        rec = trials.get((s.name, t.name))
        if rec is None:
            continue
        kwargs = {"model": s.model, "scene": calibrated[s.name].scene, "trial": t, "options": o.trials,
                  "plane": rec.plane, "plates": rec.plates, "cycles": foot_cycles(rec), "muscles": o.muscles,
                  "uncertain": tuple(s.uncertain)}
        plan[(s.name, t.name)] = make_run(f"muscles-{s.name}-{t.name}", muscle_run, kwargs,
                                      (s.model, t.markers, t.grf, o.trials.tasks, o.muscles.actuators))
    if not plan:
        return {}, [], False
    done = run_sweep(list(plan.values()), record, **sweep)
    out, failed = {}, []
    for key, run in plan.items():
        rec = done.results.get(run.key)
        if rec is None or "error" in rec:
            failed.append((f"{key[0]} {key[1]} (muscles)", "not run" if rec is None else rec["error"]))
        else:
            out[key] = MuscleRecord.from_json(rec)
    return out, failed, done.interrupted


def contact_curves(records: dict, all_cycles: bool = False) -> dict[str, dict[str, tuple]]:
    """joint resultant -> subject -> (values (m, 101), bands (m, 101) or None) over the subject's trials' clean
    cycles (every one where ``all_cycles``); a subject without any left out."""
    per: dict[str, dict[str, tuple[list, list]]] = {}
    for (subject, _), rec in records.items():
        for name, ld in rec.outputs.items():
            if not name.endswith("_resultant"):
                continue
            keep = ld.clean or (False,) * len(ld.value)
            v, b = per.setdefault(name, {}).setdefault(subject, ([], []))
            for k, ok in enumerate(keep):
                if ok or all_cycles:
                    v.append(ld.value[k])
                    b.append(ld.band[k] if ld.band is not None else None)
    return {n: {s: (np.array(v), None if any(x is None for x in b) else np.array(b)) for s, (v, b) in subs.items()
                if v} for n, subs in per.items() if any(v for v, _ in subs.values())}
