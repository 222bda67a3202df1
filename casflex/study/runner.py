"""A lab's whole study in one call (``casflex study STUDY.toml``, issue 38): each subject calibrated on its
static trial, every trial's inverse dynamics, on dask.distributed (:mod:`casflex.study.sweep`: a local cluster,
or a scheduler's address), resumable, a trial that fails reported with its reason while the others go on;
then one tidy table and the figures.

The runs: ``calibrate-<subject>-<inputs>`` (the subject's scene placed on its static trial, :func:`casflex.inverse.
calibrate.calibrate`, the masses scaled to its mass) and ``trial-<subject>-<trial>-<inputs>`` (``<inputs>``: a
fingerprint of the run's inputs, :func:`_run`; :func:`trial_run`: each plate's contacts applied to the foot over
each where the study file does not say which plate acts on which node (``plates="auto"``,
:mod:`casflex.inverse.contacts`);
inverse dynamics; each load cut into gait cycles, foot strike to foot strike of the foot below the load's joint,
and resampled on 0-100 % of the cycle, :func:`.events.normalise`). Each run's record is a JSON file in the
record directory: a run with a record is not done again.

The table (``loads.csv``): one row per subject, trial, load, cycle and percent of the cycle, with the load's
value and its band (one standard deviation, where the study asks for bands; else empty). Loads are the lab's
(``<coordinate>_moment``) where the scene names its coordinates, else ``<hinge>.moment``, in N m (forces N).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from pathlib import Path

import numpy as np

from casflex.study.records import Calibration, CycleLoad, PassiveFit, TrialRecord
from casflex.study.study_file import Study, Trial, TrialOptions

__all__ = ["run_study", "trial_run", "calibrate_run", "check_against_models", "tidy_rows", "per_kg", "unit_of",
           "PERCENT"]

#: the points of a gait cycle in the table: 0, 1, ..., 100 % (as labs report it)
PERCENT = np.linspace(0.0, 100.0, 101)
#: what a run's record holds, in its fingerprint (:func:`_run`): 2, each cycle's "clean" flag (a record without
#: it, from before, is done again rather than read as clean or not); 3, a trial run's options given as values
#: (:class:`~casflex.study.study_file.TrialOptions`, the study file's trial): the fingerprint's text changed, the
#: records' content did not; 4, each trial's joint angles over its cycles and their toe-offs (the figures': a
#: record from before is done again rather than drawn without them), and the plates applied per contact where the
#: study file names none (a plate on either foot in turn, a foot on two plates), a stance straddling two plates clean
RECORD_FORMAT = 4


def calibrate_run(*, model: str, static: str | None, plane: str, root: str | None, calibrate: bool, scale: bool,
                  mass: float | None, vertical: str = "Y", static_window: tuple[float, float] | None = None,
                  mass_from: str | None = None) -> dict:
    """The subject's scene (TOML text) on its static trial (``calibrate``; its frames in ``static_window`` s, all
    where None) or as given, its masses scaled to ``mass`` (with the segments where ``scale``; ``mass_from``: where
    the mass was read, said in the report), and the report; ``plane`` "auto": the static trial's own
    (:mod:`.direction`)."""
    from casflex import load_scene
    from casflex.inverse.calibrate import calibrate as place
    from casflex.inverse.calibrate import mass_lines, scene_mass, with_mass
    from casflex.inverse.inputs import read_markers
    from casflex.scene import dumps_scene

    if str(model).lower().endswith(".osim"):  # and what the planar scene leaves out of the model (its constraints)
        scene, warnings = _osim(str(model), _digest(model))
        report = [f"warning: {w}" for w in warnings]
    else:
        scene, report = load_scene(model), []
    placed_mass = static is not None and calibrate and scale
    if mass_from is not None:
        report.append(f"the subject's mass {mass:g} kg read from {mass_from} (the study file gives none)")
    if static is not None and calibrate:
        lab = _frames(read_markers(static)[0], static_window)
        plane, lines = _trial_plane(scene, lab, plane, vertical, static=True, root=root)
        report += lines
        scene, placed = place(scene, lab, plane, root=root, scale=scale, mass=mass if scale else None)
        report += placed
    if mass is not None and not placed_mass:  # weighed, not measured: the masses to it, the sizes as they are
        total = scene_mass(scene)
        report += mass_lines(scene, mass)
        scene = with_mass(scene, mass)
        report.append(f"the model's masses scaled from {total:.1f} kg to the subject's {mass:g} kg (inertias with "
                      "them; the segments' sizes as they are)")
    return Calibration(dumps_scene(scene), tuple(report)).to_json()


@functools.lru_cache(maxsize=8)
def _osim(path: str, digest: str | None) -> tuple:
    """(the planar scene, its warnings) of the OpenSim model at ``path`` (:func:`casflex.scene.io.load_osim`, the
    reader of :func:`casflex.scene.load_scene`), read once per process and content (``digest``, :func:`_digest`): a
    study's subjects often share a model, and a worker calibrates one after the other (50 ms a read of Hamner's
    model). A scene is immutable: sharing it is safe."""
    from casflex.scene.io import load_osim

    return load_osim(path)


def _frames(lab, window: tuple[float, float] | None):
    """The static trial's frames within ``window`` (s; all where None); ValueError naming it where it holds none."""
    if window is None:
        return lab
    inside = (lab.t >= window[0] - 1e-9) & (lab.t <= window[1] + 1e-9)
    if not inside.any():  # within the trial's times (the study file's check) but between two frames
        raise ValueError(f"{lab.source}: static_window {window[0]:g}..{window[1]:g} s holds none of its frames (at "
                         f"{lab.rate:g} Hz): give a window of one frame or more")
    return dataclasses.replace(lab, t=lab.t[inside], xyz=lab.xyz[inside])


def _trial_plane(sc, lab, plane: str, vertical: str, static: bool = False, root: str | None = None
                 ) -> tuple[str, list[str]]:
    """(the trial's plane, report lines): ``plane``, or where "auto" the one the subject travels or faces in
    (:mod:`.direction`: a static trial by its markers, another by the scene's fit), its travel read from the root
    segment's markers (:func:`casflex.inverse.heading.travel_labels`: ValueError where the trial has none of them).
    The heading is checked against the plane by the trial's inverse dynamics (:mod:`casflex.inverse.heading`)."""
    from casflex.inverse.heading import facing_plane, travel_labels
    from casflex.study.direction import fitted_plane, walking_plane

    labels = travel_labels(sc, lab, root)
    if plane != "auto":
        return plane, []
    plane, line = walking_plane(lab, labels, vertical) or (facing_plane if static else fitted_plane)(
        sc, lab, vertical, *([root] if not static else []))
    return plane, [line]


def _load_feet(scene, names: list[str], feet: list[str]) -> dict[str, str | None]:
    """For each load, the foot (a node bearing a plate) below its joint: that foot's strikes cut it into cycles;
    None where no foot is (a root load, the trunk, the arms: the first foot's cycles that has any are used)."""
    from casflex.scene import SceneError
    from casflex.study.events import below

    hinge_of = {f"{c.name}_moment": c.of for c in scene.coordinates} | {f"{c.name}_force": c.of
                                                                          for c in scene.coordinates}
    out = {}
    for name in names:
        hinge = hinge_of.get(name, name.rpartition(".")[0])
        try:
            carried = below(scene, scene.item(hinge).nodes[-1])
        except SceneError:  # a root load ("root.fx", "<node>.x"): the whole body's
            carried = set()
        out[name] = next((f for f in feet if f in carried), None)
    return out


def _read(trial: Trial):
    """(markers, plates' table or None): the trial's files, read once (a C3D's own plates where no grf is named;
    none with an ExternalLoads file, which inverse dynamics reads itself)."""
    from casflex.study.events import read_trial

    grf = trial.grf
    if grf is not None and grf.lower().endswith(".xml"):
        return read_trial(trial.markers, None, plates=False)
    return read_trial(trial.markers, grf, required=False)


def _events(sc, lab, table, plates, plane: str) -> tuple[dict | str | None, dict, list[str], list]:
    """The trial's plates (the study file's, else "auto": each plate's contacts applied to the foot over each,
    :func:`casflex.inverse.contacts.plate_shares`), each foot's gait cycles (:func:`.events.gait_cycles`: the strikes
    the lab marked in the file, else the plates', else the heel marker's), report lines and the contacts, from one
    pass over its plates' contacts."""
    from casflex.study.events import AUTO, gait_cycles, plate_contacts, plate_prefixes

    if table is None:
        return plates, {}, ["no plates read for the gait cycles (the trial names none, or an ExternalLoads "
                            "file): loads over time only"], []
    found = plate_contacts(sc, lab, table, plane, plate_prefixes(table))
    feet, cycle_report = gait_cycles(found, sc, lab, plane)
    return plates if plates is not None else AUTO, feet, cycle_report, found


def _loads_of(res) -> list[str]:
    """The loads the table holds: the lab's moments where the scene names them, else every hinge's moment."""
    names = list(res.settings.get("moments", ()))
    return names or sorted(k for k in res.loads if k.endswith(".moment") and not k.startswith("root."))


#: s: the marked gait events' span widened by this on each side is a trial's window where the study file gives none
EVENTS_MARGIN = 0.1


def _window(trial: Trial, lab) -> tuple[float | None, float | None, list[str]]:
    """(t0, t1, report): the study file's window, else (a C3D trial with marked gait events) the events' span widened
    by :data:`EVENTS_MARGIN` within the trial, as a lab processes a trial (the frames beyond the marked events, the
    subject walking in and out of the volume, carry no cycle and are often half tracked), else the whole trial."""
    if trial.window is not None:
        return (*trial.window, [])
    times = [e[2] for e in lab.events]
    if not times:
        return None, None, []
    t0, t1 = max(float(lab.t[0]), min(times) - EVENTS_MARGIN), min(float(lab.t[-1]), max(times) + EVENTS_MARGIN)
    return t0, t1, [f"window: {t0:.3f}-{t1:.3f} s, the marked gait events' span +- {EVENTS_MARGIN:g} s (the trial "
                    f"{lab.t[0]:.3f}-{lab.t[-1]:.3f} s; `window` in the study file sets another)"]


@functools.lru_cache(maxsize=8)
def _scene(text: str):
    """The scene of a calibrated scene's TOML text, read once per process (a worker runs a subject's trials one
    after the other: the same text each time). A scene is immutable (frozen dataclasses): sharing it is safe."""
    from casflex.scene import loads_scene

    return loads_scene(text)


def trial_run(*, scene: str, trial: Trial, options: TrialOptions, uncertain: tuple[str, ...]) -> dict:
    """One trial's inverse dynamics and its loads over gait cycles (module docstring): its record
    (:class:`~casflex.study.records.TrialRecord`) as JSON, which the sweep writes."""
    from casflex.inverse import Bands, inverse_dynamics
    from casflex.inverse import Trial as Inverse
    from casflex.scene.uncertain import parse
    from casflex.study.kinematics import cycle_angles, toe_offs

    sc = _scene(scene)
    lab, table = _read(trial)
    t0, t1, window_report = _window(trial, lab)
    inside = (lab.t >= (t0 or -np.inf)) & (lab.t <= (t1 or np.inf))
    plane, plane_report = _trial_plane(sc, dataclasses.replace(lab, t=lab.t[inside], xyz=lab.xyz[inside]),
                                       options.plane, options.vertical, root=options.root)
    plates, feet, event_report, found = _events(sc, lab, table, trial.plates, plane)
    grf = trial.grf if trial.grf is not None and trial.grf.lower().endswith(".xml") else table
    res = inverse_dynamics(sc, Inverse(lab, grf=grf, plates=plates, plane=plane, root=options.root, t_start=t0,
                                       t_end=t1, tasks=options.tasks), filter=options.filter, fit=options.fit,
                           bands=Bands([parse(u) for u in uncertain] or None,  # false: none, even where the subject
                                       asked=bool(options.bands)))             # declares uncertainty
    feet = {f: [c for c in cs if res.t[0] <= c[0] and c[1] <= res.t[-1]] for f, cs in feet.items()}  # the window's
    loads, notes = _cycle_loads(sc, res, lab, found, plates or {}, feet, plane)
    return TrialRecord(res.settings.get("plates") or plates, plane,
                       (*window_report, *plane_report, *event_report, *notes, *res.report),
                       (*res.warnings, *notes),
                       loads, (float(res.t[0]), float(res.t[-1])),
                       tuple(_passive(res, sc, lab, found, feet, options.passive)),
                       cycle_angles(sc, res, loads), toe_offs(found, sc, lab, feet)).to_json()


def _cycle_loads(sc, res, lab, found, plates: dict | str, feet: dict, plane: str
                 ) -> tuple[dict[str, CycleLoad], list[str]]:
    """({load: its foot, cycles [t0, t1] s, whether each is clean, values and bands on 0-100 %}, notes): each load
    cut into the gait cycles of the foot below its joint (:func:`_load_feet`), each cycle's stance checked
    (:func:`.events.clean_cycles`: wholly on the foot's plate); a load whose foot walks but has no cycle (it
    touches no plate) gets none, said in the notes, where it took another foot's; a load above the feet (trunk,
    arms, root) the first foot's cycles that has any."""
    from casflex.study.events import clean_cycles, ground_feet, normalise

    names = _loads_of(res)
    walking = ground_feet(sc, lab, plane) if found else []  # no plates read: said in the report already
    first = next((f for f, cs in feet.items() if cs), next(iter(feet), None))  # a foot with cycles
    from casflex.lab.plate_checks import scene_mass

    weight = scene_mass(sc) * float(np.hypot(*sc.gravity))
    clean = {f: clean_cycles(found, f, cs, plates if isinstance(plates, str) else plates.get(f), weight=weight)
             for f, cs in feet.items()}
    loads, notes, bare = {}, [], {}
    for name, foot in _load_feet(sc, names, [*feet, *(f for f in walking if f not in feet)]).items():
        if foot is not None and foot not in feet:
            bare.setdefault(foot, []).append(name)
        foot = foot if foot is not None else first
        spans, flags = feet.get(foot, []), clean.get(foot, [])
        band = res.bands.get(name, {}).get("total") if res.bands else None
        loads[name] = CycleLoad(foot, tuple(tuple(c) for c in spans), tuple(ok for ok, _ in flags),
                                tuple(tuple(normalise(res.t, res.loads[name], *c).tolist()) for c in spans),
                                tuple(tuple(normalise(res.t, band, *c).tolist()) for c in spans)
                                if band is not None else None)
    for foot, names_ in bare.items():
        notes.append(f"{foot} touches no plate: no kinetic cycle for {', '.join(names_)}")
    for foot, flags in clean.items():
        notes += [f"{foot} cycle {k + 1} ({feet[foot][k][0]:.3f}-{feet[foot][k][1]:.3f} s) not clean: {why}: left "
                  "out of the means and figures" for k, (ok, why) in enumerate(flags) if not ok]
    return loads, notes


def _passive(res, sc, lab, found, feet: dict, specs) -> list[PassiveFit]:
    """Each (hinge, "trial" or "swing") of the study's ``passive``: the spring-damper fitted to the hinge's net
    moment (:func:`casflex.inverse.passive.fit_passive`) over the trial, or over each swing phase of the foot
    below the hinge (:func:`.events.swing_phases`); a window it cannot fit recorded with the reason."""
    from casflex.inverse.passive import fit_passive
    from casflex.study.events import below, swing_phases

    out = []
    for hinge, phase in specs:
        windows = [(float(res.t[0]), float(res.t[-1]))]
        if phase == "swing":
            foot = next((f for f in feet if f in below(sc, sc.item(hinge).nodes[-1])), None)
            windows = swing_phases(found, sc, lab, foot, feet[foot]) if foot else []
            if not windows:
                out.append(PassiveFit(hinge, phase, None,
                                      error="no swing phase in the trial (no foot below the hinge with a cycle)"))
        for t0, t1 in windows:
            try:
                f = fit_passive(res, hinge, t0, t1)
            except ValueError as exc:
                out.append(PassiveFit(hinge, phase, (t0, t1), error=str(exc)))
                continue
            out.append(PassiveFit(hinge, phase, tuple(f.window), kt=f.kt, ct=f.ct, rest_angle=f.rest_angle, se=f.se,
                                  r2=f.r2, n_effective=f.n_effective, passive=f.passive, why=tuple(f.why)))
    return out


def _digest(path: str | None) -> str | None:
    """sha1 of a file's bytes (None for no file, or a built-in scene's name)."""
    import hashlib

    if path is None or not Path(path).is_file():
        return None
    return hashlib.sha1(Path(path).read_bytes()).hexdigest()


#: the fields of a run's record (a record without one is not taken as done: casflex.study.sweep.Run.fields)
_FIELDS = {"calibrate_run": ("scene", "report"),
           "trial_run": ("plates", "plane", "report", "warnings", "loads", "t", "passive"),
           "muscle_run": ("report", "warnings", "outputs", "units", "body_weight")}


def _jsonable(value: object) -> object:
    """A value in a run's fingerprint: an option value by its fields (those added later left out where None:
    :data:`~casflex.study.study_file.FINGERPRINT_OMITS_NONE`), anything else as text."""
    from casflex.study.study_file import FINGERPRINT_OMITS_NONE

    if not dataclasses.is_dataclass(value):
        return str(value)
    return {k: v for k, v in dataclasses.asdict(value).items() if not (k in FINGERPRINT_OMITS_NONE and v is None)}


def _run(name: str, fn: Callable[..., dict], kwargs: dict, files: tuple[str | None, ...]):
    """The sweep's run ``name-<fingerprint>``: the fingerprint (8 hex digits) of its inputs (every option, the
    calibrated scene's text, the ``files``' contents) and casflex's version, so that a record is reused only for
    the same inputs: a study run again after a changed option, window, model or data file redoes what it changes
    (a failed trial too), and nothing else. The record holds its key (casflex.study.sweep.IDENTITY): a record
    copied by hand under another run's name is not taken."""
    import hashlib
    import json

    from casflex import __version__
    from casflex.study.sweep import Run

    text = json.dumps({"fn": fn.__name__, "kwargs": kwargs, "files": [_digest(f) for f in files],
                       "casflex": __version__, "record": RECORD_FORMAT}, sort_keys=True, default=_jsonable)
    return Run(f"{name}-{hashlib.sha1(text.encode()).hexdigest()[:8]}", fn, kwargs, _FIELDS.get(fn.__name__, ()))


def _plan(study: Study, calibrated: dict[str, Calibration]) -> dict:
    """(subject, trial) -> its run."""
    def options(s):  # the subject's own task file, where it gives one
        return study.options.trials if s.tasks is None else dataclasses.replace(study.options.trials, tasks=s.tasks)

    return {(s.name, t.name): _run(f"trial-{s.name}-{t.name}", trial_run,
                                   {"scene": calibrated[s.name].scene, "trial": t, "options": options(s),
                                    "uncertain": tuple(s.uncertain)}, (t.markers, t.grf, options(s).tasks))
            for s, t in study.trials() if s.name in calibrated}


def check_against_models(study: Study) -> None:
    """Every subject's model read, and the study's names checked against it before any run: its uncertain
    properties' targets, the plates' nodes, the root. StudyError naming the field otherwise."""
    import dataclasses as dc

    from casflex import load_scene
    from casflex.scene import SceneError
    from casflex.scene.uncertain import parse
    from casflex.study.study_file import StudyError

    scenes: dict[str, object] = {}  # a model that several subjects share read once
    for i, s in enumerate(study.subjects):
        try:
            scene = scenes[s.model] if s.model in scenes else scenes.setdefault(s.model, load_scene(s.model))
        except (SceneError, ValueError, OSError) as exc:
            raise StudyError(f"subjects[{i}].model: {exc}") from None
        try:
            dc.replace(scene, uncertain=tuple(parse(u) for u in s.uncertain))
        except (SceneError, ValueError) as exc:
            raise StudyError(f"subjects[{i}].uncertain: {exc}") from None
        nodes = {n.name for n in scene.nodes}
        hinges = {j.name for j in scene.joints}
        for hinge, _ in study.options.trials.passive:
            if hinge not in hinges:
                raise StudyError(f"options.passive: {hinge!r} is not a joint of subject {s.name}'s model (joints: "
                                 f"{sorted(hinges)[:12]}...)")
        root = study.options.trials.root
        if root is not None and root not in nodes:
            raise StudyError(f"options.root: {root!r} is not a node of subject {s.name}'s model")
        if study.options.muscles is not None:  # the muscles' options against the model (casflex.study.muscles)
            from casflex.study.muscles import check_muscles

            check_muscles(i, s.model, scene, study.options.muscles, root)
        for k, t in enumerate(s.trials):
            bad = sorted(set(t.plates or {}) - nodes)
            if bad:
                raise StudyError(f"subjects[{i}].trials[{k}].plates: {bad[0]!r} is not a node of the model "
                                 f"(nodes: {sorted(nodes)[:12]}...)")


def _calibration_kwargs(study: Study, s) -> dict:
    """A subject's calibration run's arguments (:func:`calibrate_run`); its static window and where its mass was
    read only where there are some (a study that gives neither keeps its records' fingerprints)."""
    o, to = study.options, study.options.trials
    kwargs = {"model": s.model, "static": s.static, "plane": to.plane, "root": to.root, "calibrate": o.calibrate,
              "scale": o.scale, "mass": s.mass, "vertical": to.vertical}
    extra = {"static_window": s.static_window, "mass_from": s.mass_from}
    return kwargs | {k: v for k, v in extra.items() if v is not None}


def _subject_hook(study: Study, plan: dict, calibrated: dict, on_subject: Callable[[str, dict], None],
                  converted: dict[str, TrialRecord]) -> Callable[[str, dict, bool], None]:
    """The sweep's ``on_record`` that calls ``on_subject`` (:func:`run_study`) once a subject's trials are all
    recorded, one of them in this sweep; the TrialRecords it makes kept in ``converted`` (run key -> record) for
    :func:`run_study`'s output (1.5 ms a trial's, made once)."""
    of = {r.key: subject for (subject, _), r in plan.items()}
    of_trial = {r.key: trial for (_, trial), r in plan.items()}
    left = {subject: {r.key for (s, _), r in plan.items() if s == subject} for subject in {s for s, _ in plan}}
    got: dict[str, dict] = {}
    ran: set[str] = set()

    def on_record(key: str, rec: dict, executed: bool) -> None:
        subject = of.get(key)
        if subject is None:
            return
        got[key] = rec
        left[subject].discard(key)
        if executed:
            ran.add(subject)
        if left[subject] or subject not in ran:
            return
        keys = [plan[(s, t)].key for s, t in ((s.name, t.name) for s, t in study.trials())
                if s == subject and (s, t) in plan]
        converted.update({k: TrialRecord.from_json(got[k]) for k in keys if "error" not in got[k]})
        trials = {(subject, of_trial[k]): converted[k] for k in keys if "error" not in got[k]}
        on_subject(subject, {"subjects": calibrated, "trials": trials})

    return on_record


def run_study(study: Study, record: str | Path, *, scheduler: str | None = None, n_workers: int | None = None,
              progress: Callable[[int, int, str], None] | bool = True, retry_failed: bool = False,
              session=None, on_subject: Callable[[str, dict], None] | None = None) -> dict:
    """Calibrate every subject and run every trial (module docstring), resuming from ``record``; returns
    {"subjects": {name: its Calibration}, "trials": {(subject, trial): its TrialRecord}, "failed": [(what, why)],
    "interrupted": bool, "records": {(subject, trial): its record's path}}. A failed calibration fails its
    subject's trials, reported; the others go on. ``retry_failed``: a run recorded as failed is run again (a
    worker lost, a file since mended), where by default its record stands until its inputs change. ``session``:
    the :class:`casflex.study.sweep.Session` to run on (kept open for the caller: the figures'), else one of its
    own (``scheduler``, ``n_workers``): one cluster for the calibrations, the trials and the muscles, started only
    where a run is to be done. ``on_subject(name, {"subjects": every Calibration, "trials": its trials' records})``:
    called as soon as the last of a subject's trials run in this call is recorded, while the others run (the
    figures': :mod:`casflex.cli.study`); its trials' records as :func:`run_study` returns them (in the study's
    order, the failed left out); not called for a subject none of whose trials is run."""
    from casflex.study.sweep import Session, run_sweep

    if session is None:
        with Session(scheduler, n_workers) as own:
            return run_study(study, record, progress=progress, retry_failed=retry_failed, session=own)
    sweep = {"progress": progress, "retry_failed": retry_failed, "session": session}
    cal_runs = {s.name: _run(f"calibrate-{s.name}", calibrate_run, _calibration_kwargs(study, s), (s.model, s.static))
                for s in study.subjects}
    cal = run_sweep(list(cal_runs.values()), record, **sweep)
    recs = {s.name: cal.results.get(cal_runs[s.name].key, {}) for s in study.subjects}
    failed = [(f"subject {s.name} (calibration)", recs[s.name].get("error", "not run"))
              for s in study.subjects if "scene" not in recs[s.name]]
    calibrated = {name: Calibration.from_json(rec) for name, rec in recs.items() if "scene" in rec}
    trials: dict = {}
    plan: dict = {}
    interrupted = cal.interrupted
    if not interrupted:
        plan = _plan(study, calibrated)
        converted: dict[str, TrialRecord] = {}  # the hook's TrialRecords, not made twice
        hook = _subject_hook(study, plan, calibrated, on_subject, converted) if on_subject is not None else None
        done = run_sweep(list(plan.values()), record, **sweep, on_record=hook)
        interrupted = done.interrupted
        for s, t in study.trials():
            rec = done.results.get(plan[(s.name, t.name)].key) if (s.name, t.name) in plan else None
            if rec is None:
                why = "its subject's calibration failed" if s.name not in calibrated else "not run"
                failed.append((f"{s.name} {t.name}", why))
            elif "error" in rec:
                failed.append((f"{s.name} {t.name}", rec["error"]))
            else:
                key = plan[(s.name, t.name)].key
                trials[(s.name, t.name)] = converted[key] if key in converted else TrialRecord.from_json(rec)
    muscles: dict = {}
    if study.options.muscles is not None and not interrupted:  # after the trials: their plates and cycles
        from casflex.study.muscles import run_muscles

        muscles, more, interrupted = run_muscles(study, calibrated, trials, record, _run, **sweep)
        failed += more
    return {"subjects": calibrated, "trials": trials, "failed": failed, "interrupted": interrupted,
            "records": {k: str(Path(record) / f"{r.key}.json") for k, r in plan.items()}, "muscles": muscles}


def unit_of(load: str, per_kg: bool = False) -> str:
    """A load's unit (:func:`casflex.inverse.lab_names.load_unit`: N for a force, else N m); per kg where asked."""
    from casflex.inverse.lab_names import load_unit

    return load_unit(load) + ("/kg" if per_kg else "")


def per_kg(out: dict, study: Study) -> dict:
    """:func:`run_study`'s output with every value and band divided by its subject's mass where the study says
    ``normalise = "mass"`` (as labs report gait), else as it is."""
    if study.options.normalise != "mass":
        return out
    mass = {s.name: s.mass for s in study.subjects}
    trials = {key: dataclasses.replace(rec, loads={name: ld.per(mass[key[0]]) for name, ld in rec.loads.items()})
              for key, rec in out["trials"].items()}
    return out | {"trials": trials}


def tidy_rows(out: dict, per_kg: bool = False) -> list[tuple]:
    """(subject, trial, load, foot, cycle, percent, value, band, unit, clean, t0, t1) rows of :func:`run_study`'s
    trials (``per_kg``: their values are per kg, :func:`per_kg`); ``clean``: the cycle's stance wholly on the
    foot's plate (:func:`.events.clean_cycles`), None where the record does not say; t0, t1: the cycle's start
    and end (s)."""
    rows = []
    for (subject, trial), rec in out["trials"].items():
        for name, ld in rec.loads.items():
            unit = unit_of(name, per_kg)
            clean = ld.clean or [None] * len(ld.value)
            for k, values in enumerate(ld.value):
                band = ld.band[k] if ld.band is not None else [None] * len(values)
                t0, t1 = ld.cycles[k]
                rows += [(subject, trial, name, ld.foot, k + 1, float(p), v, b, unit, clean[k], t0, t1)
                         for p, v, b in zip(PERCENT, values, band, strict=True)]
    return rows
