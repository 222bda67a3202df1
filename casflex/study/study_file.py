"""A lab's study as a file (``casflex study STUDY.toml``, issue 38): its subjects, their trials, the options,
read and checked before any work. Paths are relative to the study file.

Checked before any work, besides every field's type and range (:class:`StudyError` naming the field): each file
exists; the IK task file and an ExternalLoads grf are read (one that names itself refused); from each trial's
files' headers and first and last rows (not their data): its window within the markers' and the plates' times,
the cut-offs below the Nyquist frequency of the markers' and the plates' rates, its plates' prefixes among the
plates' columns (a .mot / .sto; a C3D's plates are known only once read).

```toml
name = "running speeds"

[options]                      # every key optional; these are the defaults
plane = "X,Y"                  # the lab axes that become the model's x and y, or "auto": each trial's own
vertical = "Y"                 # the lab's vertical axis (for plane = "auto": casflex.study.direction)
cutoff = 6.0                   # Hz, the kinematics' (and the plates') zero-lag Butterworth; "none": unfiltered
cutoff_plates = "same"         # Hz, "none" or "same"
filter = "butterworth"         # or "opensim" (as OpenSim's ID tool)
root = ""                      # the node the data drive (default: the scene's first)
tasks = ""                     # an OpenSim IK task or setup file: the markers' weights
calibrate = true               # place the model's markers from each subject's static trial (when given)
scale = false                  # scale the segments too (casflex.inverse.calibrate)
bands = false                  # each load's band (anthropometry and marker noise, casflex.inverse.bands)
normalise = "none"             # or "mass": the table and figures per kg of each subject's mass (N m/kg, N/kg)
cycles = "clean"               # the means and figures from the cycles whose stance is wholly on the foot's plate
                               # (loads.csv flags each cycle: clean, t0, t1); "all": every cycle
passive = []                   # hinges whose net moment a spring-damper is fitted to, per trial ("knee_r") or
                               # per swing phase ("knee_r:swing"): casflex.inverse.passive; passive.csv
max_misfit = 0.1               # m, a marker farther than this from the fitted pose stops the trial (as casflex
                               # inverse --max-misfit; at most 1 m)

[options.muscles]              # optional: each trial's muscles and joint reactions too (casflex.study.muscles:
exponent = 2.0                 # its keys); the subjects' models .osim with their muscles; muscles.csv

[[subjects]]
name = "s02"
model = "subject02.osim"       # an OpenSim model, a scene TOML or a built-in scene (the marker sets' pig,
                               # pig_psis, cast: docs/lab.md)
mass = 72.8                    # kg (optional: the model's masses scaled to it; where not given, the
                               # C3D's own, PROCESSING:Bodymass as Vicon writes it: casflex.lab.c3d.BODY_MASS)
static = "s02_static.trc"      # optional: the calibration trial
static_window = [0.5, 1.5]     # s, optional: the static trial's frames averaged (default: all)
tasks = "s02_tasks.xml"        # optional: this subject's IK task file (default: options.tasks)
uncertain = ["pelvis.mass=10%"]   # optional: the anthropometry's uncertainty (TARGET=SD|P%|LO:HI)

[[subjects.trials]]
name = "run3"
markers = "s02_run3.trc"       # .trc or .c3d
grf = "s02_run3_grf.mot"       # .mot/.sto, the .c3d's plates, or an ExternalLoads .xml (optional)
plates = { calcn_r = "ground_force_", calcn_l = ["1_ground_force_", "2_ground_force_"] }   # optional: else
                               # each plate's contacts go to the foot over each, from the data (plates="auto")
window = [0.5, 2.0]            # s, optional
```
"""

from __future__ import annotations

import math
import os
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from casflex.inverse.options import Filter, Fit, OptionRefused

__all__ = ["Study", "Subject", "Trial", "Options", "TrialOptions", "load_study"]

_OPTIONS = {"plane": str, "vertical": str, "cutoff": (int, float, str), "cutoff_plates": (int, float, str),
            "filter": str,
            "root": str, "tasks": str, "normalise": str, "cycles": str, "passive": list, "calibrate": bool,
            "scale": bool, "bands": bool, "max_misfit": (int, float)}
_NORMALISE = ("none", "mass")
_CYCLES = ("clean", "all")


@dataclass(frozen=True)
class TrialOptions:
    """What each trial's inverse dynamics is asked (module docstring; every run's fingerprint: a change redoes the
    trials): ``plane`` (or "auto": each trial's own), ``vertical``, the ``filter`` (:class:`casflex.inverse.Filter`),
    ``root``, ``tasks`` (a resolved path or None), ``bands`` (each load's band, or none even where the subject
    declares uncertainty), ``passive`` ((hinge, "trial" or "swing") each) and ``max_misfit`` (m, the marker fit's
    limit, :class:`casflex.inverse.Fit`; None: its default, and left out of the runs' fingerprints,
    :data:`FINGERPRINT_OMITS_NONE`)."""

    plane: str = "X,Y"
    vertical: str = "Y"
    filter: Filter = Filter()
    root: str | None = None
    tasks: str | None = None
    bands: bool = False
    passive: tuple[tuple[str, str], ...] = ()
    max_misfit: float | None = None

    @property
    def fit(self) -> Fit:
        """The marker fit's limits (:class:`casflex.inverse.Fit`) each trial's inverse dynamics takes."""
        return Fit(max_misfit=self.max_misfit)


#: TrialOptions' fields added after studies had records: left out of a run's fingerprint where None (their
#: default), so that a study not giving them keeps its records (casflex.study.runner._run).
FINGERPRINT_OMITS_NONE = ("max_misfit",)


@dataclass(frozen=True)
class Options:
    """The study's options (module docstring): what each trial is asked (``trials``), each subject's calibration
    (``calibrate``, ``scale``) and the table's and figures' (``normalise``, ``cycles``)."""

    trials: TrialOptions = TrialOptions()
    calibrate: bool = True
    scale: bool = False
    normalise: str = "none"
    cycles: str = "clean"
    #: ``[options.muscles]`` (:class:`casflex.study.muscle_options.MuscleOptions`), None: no muscles computed
    muscles: Any = None


@dataclass(frozen=True)
class Trial:
    name: str
    markers: str
    grf: str | None = None
    plates: dict[str, str | list[str]] | None = None
    window: tuple[float, float] | None = None


@dataclass(frozen=True)
class Subject:
    name: str
    model: str
    trials: tuple[Trial, ...]
    mass: float | None = None
    static: str | None = None
    uncertain: tuple[str, ...] = ()
    #: where ``mass`` came from: None (the study file) or the C3D file and its parameter (``mass`` not given)
    mass_from: str | None = None
    static_window: tuple[float, float] | None = None
    #: this subject's IK task file (a resolved path), None: the study's ``options.tasks``
    tasks: str | None = None


@dataclass(frozen=True)
class Study:
    name: str
    path: str
    options: Options
    subjects: tuple[Subject, ...] = field(default_factory=tuple)

    def trials(self) -> list[tuple[Subject, Trial]]:
        """Every (subject, trial) in the file's order."""
        return [(s, t) for s in self.subjects for t in s.trials]


class StudyError(ValueError):
    """A study file that cannot be run: the message names the field (``subjects[1].trials[0].markers``)."""


def _check_keys(where: str, table: Any, known: set[str], required: set[str]) -> dict:
    if not isinstance(table, dict):
        raise StudyError(f"{where}: expected a table, got {type(table).__name__}")
    for k in table:
        if k not in known:
            raise StudyError(f"{where}.{k}: unknown field; expected some of {sorted(known)}")
    for k in sorted(required - set(table)):
        raise StudyError(f"{where}: missing required field {k!r}")
    return table


def _name(where: str, value: Any) -> str:
    if not isinstance(value, str) or not value.strip() or any(c in value for c in "/\\ \t\n:*?\"<>|"):
        raise StudyError(f"{where}: expected a name without spaces or path characters, got {value!r}")
    return value


def _file(base: Path, where: str, value: Any, suffixes: tuple[str, ...], builtin: bool = False) -> str:
    """The path (resolved against the study file's folder) of an existing input file, or a built-in scene."""
    if not isinstance(value, str) or not value:
        raise StudyError(f"{where}: expected a file name, got {value!r}")
    if builtin:
        from casflex.scene import builtin_scenes

        if value in builtin_scenes():
            return value
    path = Path(value) if Path(value).is_absolute() else base / value
    if not path.is_file():
        raise StudyError(f"{where}: {value}: no such file (relative to {base})")
    if not str(path).lower().endswith(suffixes):
        raise StudyError(f"{where}: {value}: expected {' or '.join(suffixes)}")
    return str(path)


def _frequency(value: Any) -> Any:
    """A cut-off as TOML writes it: "none" (unfiltered) and "same" are words (:class:`casflex.inverse.Filter` says
    what a cut-off may be)."""
    return (None if value.lower() == "none" else value.lower()) if isinstance(value, str) else value


def _filter(t: dict) -> Filter:
    """The [options] table's filter (its fields ``cutoff``, ``cutoff_plates``, ``filter``), checked by
    :class:`casflex.inverse.Filter`; StudyError naming the field."""
    try:
        return Filter(_frequency(t.get("cutoff", 6.0)), _frequency(t.get("cutoff_plates", "same")),
                      t.get("filter", "butterworth"))
    except OptionRefused as exc:
        raise StudyError(exc.said(lambda o: f"options.{o}")) from None


def _options(base: Path, table: Any) -> Options:
    t = _check_keys("options", table, set(_OPTIONS) | {"muscles"}, set())
    for k, typ in _OPTIONS.items():
        if k in t and not isinstance(t[k], typ) or (k in t and typ is not bool and isinstance(t[k], bool)):
            want = {bool: "true or false", str: "a text", list: "a list", (int, float): "a distance in m"}.get(
                typ, "a frequency in Hz or a word")
            raise StudyError(f"options.{k}: expected {want}, got {t[k]!r}")
    from casflex.lab import Plane

    if t.get("normalise", "none") not in _NORMALISE:
        raise StudyError(f"options.normalise: expected one of {list(_NORMALISE)}, got {t['normalise']!r}")
    if t.get("cycles", "clean") not in _CYCLES:
        raise StudyError(f"options.cycles: expected one of {list(_CYCLES)}, got {t['cycles']!r}")
    passive = t.get("passive", [])
    if not all(isinstance(p, str) and re.fullmatch(r"[^:\s]+(:(swing|trial))?", p) for p in passive):
        raise StudyError(f"options.passive: expected hinge names, each alone or with :swing or :trial, got {passive!r}")
    vertical = t.get("vertical", "Y")
    if vertical.upper() not in ("X", "Y", "Z"):
        raise StudyError(f"options.vertical: expected the lab's vertical axis X, Y or Z, got {vertical!r}")
    try:
        if t.get("plane", "X,Y") != "auto":
            Plane.parse(t.get("plane", "X,Y"))
    except ValueError as exc:
        raise StudyError(f"options.plane: {exc} (or \"auto\")") from None
    tasks = _tasks(base, "options.tasks", t["tasks"]) if t.get("tasks") else None
    trials = TrialOptions(plane=t.get("plane", "X,Y"), vertical=vertical.upper(), filter=_filter(t),
                          root=t.get("root") or None, tasks=tasks, bands=t.get("bands", False),
                          passive=tuple((p.partition(":")[0], p.partition(":")[2] or "trial") for p in passive),
                          max_misfit=_max_misfit(t))
    muscles = _muscles(base, t["muscles"]) if "muscles" in t else None
    return Options(trials, calibrate=t.get("calibrate", True), scale=t.get("scale", False),
                   normalise=t.get("normalise", "none"), cycles=t.get("cycles", "clean"), muscles=muscles)


def _max_misfit(t: dict) -> float | None:
    """The [options] table's ``max_misfit`` (m), checked by :class:`casflex.inverse.Fit`; StudyError naming the
    field."""
    value = t.get("max_misfit")
    try:
        Fit(max_misfit=value)
    except OptionRefused as exc:
        raise StudyError(exc.said(lambda o: f"options.{o}")) from None
    return None if value is None else float(value)


def _muscles(base: Path, table: Any):
    """``[options.muscles]`` (:class:`casflex.study.muscle_options.MuscleOptions`; its actuator file read);
    StudyError naming the field."""
    from casflex.scene.osim_actuators import read_actuators
    from casflex.study.muscle_options import KEYS, muscle_options

    t = _check_keys("options.muscles", table, KEYS, set())
    actuators = _file(base, "options.muscles.actuators", t["actuators"], (".xml", ".osim")) if "actuators" in t \
        else None
    try:
        if actuators is not None:
            read_actuators(actuators)
        return muscle_options(t, actuators)
    except ValueError as exc:
        field = "actuators: " if actuators is not None and str(exc).startswith(actuators) else ""
        raise StudyError(f"options.muscles.{field}{exc}") from None


def _tasks(base: Path, where: str, value: Any) -> str:
    """An IK task (or setup) file's resolved path, the file read (:func:`casflex.lab.setups.read_tasks`);
    StudyError naming ``where``."""
    from casflex.lab.setups import read_tasks

    tasks = _file(base, where, value, (".xml",))
    try:
        read_tasks(tasks)
    except ValueError as exc:
        raise StudyError(f"{where}: {exc}") from None
    return tasks


def _trial(base: Path, where: str, table: Any) -> Trial:
    t = _check_keys(where, table, {"name", "markers", "grf", "plates", "window"}, {"name", "markers"})
    plates = t.get("plates")
    if plates is not None and (not isinstance(plates, dict) or not plates or not all(
            isinstance(v, str) and v or isinstance(v, list) and v and all(isinstance(p, str) and p for p in v)
            for v in plates.values())):
        raise StudyError(f"{where}.plates: expected a table node = \"column prefix\" (or a list of them: a foot on "
                         f"several plates), got {plates!r}")
    window = _window(f"{where}.window", t.get("window"))
    given = [(n, p) for n, v in (plates or {}).items() for p in ([v] if isinstance(v, str) else v)]
    twice = sorted({p for _, p in given if [q for _, q in given].count(p) > 1})
    if twice:
        raise StudyError(f"{where}.plates: the plate {twice[0]!r} is given to " + " and ".join(
            dict.fromkeys(n for n, p in given if p == twice[0])) + ": a plate's force acts on one foot at a time "
            "(give it once, or leave plates out: each contact then goes to the foot over it)")
    trial = Trial(_name(f"{where}.name", t["name"]), _file(base, f"{where}.markers", t["markers"], (".trc", ".c3d")),
                  _file(base, f"{where}.grf", t["grf"], (".mot", ".sto", ".c3d", ".xml")) if "grf" in t else None,
                  dict(plates) if plates else None, window)
    _as_inverse(where, trial)
    return trial


def _window(where: str, window: Any, ordered: bool = False) -> tuple[float, float] | None:
    """A window [start, end] s as the study file gives it (None where not); StudyError naming ``where``
    (``ordered``: here also where not 0 <= start < end; a trial's is checked as inverse dynamics checks it)."""
    if window is None:
        return None
    ok = (isinstance(window, list) and len(window) == 2 and all(isinstance(w, (int, float)) and not isinstance(w, bool)
                                                                for w in window))
    if not ok or ordered and not 0 <= window[0] < window[1]:
        raise StudyError(f"{where}: expected [start, end] in s, 0 <= start < end, got {window!r}")
    return float(window[0]), float(window[1])


#: The study trial's field of each option of :class:`casflex.inverse.Trial` it sets, and how a refusal mentions it.
_TRIAL_FIELDS = {"t_start": "window", "t_end": "window"}
_TRIAL_MENTIONS = {"t_start": "the window's start"}


def _as_inverse(where: str, trial: Trial) -> None:
    """What :class:`casflex.inverse.Trial` refuses in a study's trial (its window, its plates without grf, plates
    with an ExternalLoads file); StudyError naming the field."""
    from casflex.inverse import Trial as Inverse

    try:
        Inverse(trial.markers, grf=trial.grf, plates=trial.plates, t_start=trial.window and trial.window[0],
                t_end=trial.window and trial.window[1])
    except OptionRefused as exc:
        raise StudyError(exc.said(lambda o: f"{where}.{_TRIAL_FIELDS.get(o, o)}", _TRIAL_MENTIONS)) from None


def _subject(base: Path, i: int, table: Any) -> Subject:
    where = f"subjects[{i}]"
    s = _check_keys(where, table, {"name", "model", "mass", "static", "static_window", "tasks", "uncertain", "trials"},
                    {"name", "model", "trials"})
    name = _name(f"{where}.name", s["name"])
    mass = s.get("mass")
    if mass is not None and (isinstance(mass, bool) or not isinstance(mass, (int, float)) or not 0 < mass < 1000):
        raise StudyError(f"{where}.mass: expected the subject's mass in kg, got {mass!r}")
    unc = s.get("uncertain", [])
    if not isinstance(unc, list) or not all(isinstance(u, str) for u in unc):
        raise StudyError(f"{where}.uncertain: expected a list of \"TARGET=SD|P%|LO:HI\", got {unc!r}")
    for u in unc:
        _uncertain(f"{where}.uncertain", u)
    trials = s["trials"]
    if not isinstance(trials, list) or not trials:
        raise StudyError(f"{where}.trials: expected one or more [[subjects.trials]] tables")
    out = tuple(_trial(base, f"{where}.trials[{k}]", t) for k, t in enumerate(trials))
    names = [t.name for t in out]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise StudyError(f"{where}.trials: trial {dup[0]!r} is named twice")
    static = _file(base, f"{where}.static", s["static"], (".trc", ".c3d")) if "static" in s else None
    static_window = _window(f"{where}.static_window", s.get("static_window"), ordered=True)
    if static_window is not None and static is None:
        raise StudyError(f"{where}.static_window: the subject has no static trial (give static, or leave the "
                         "window out)")
    mass_from = None
    if mass is None:  # the lab's own record of it, where its C3D files hold one (said in the report)
        mass, mass_from = _c3d_mass(f"{where}.mass", [static, *(t.markers for t in out)])
    return Subject(name, _file(base, f"{where}.model", s["model"], (".osim", ".toml"), builtin=True), out,
                   float(mass) if mass is not None else None, static, tuple(unc), mass_from, static_window,
                   _tasks(base, f"{where}.tasks", s["tasks"]) if "tasks" in s else None)


def _c3d_mass(where: str, files: list[str | None]) -> tuple[float | None, str | None]:
    """(kg, where from: the file's name and its parameter) of the first of ``files`` (the static trial, then the
    trials) that is a C3D holding the subject's mass (:func:`casflex.lab.c3d.c3d_body_mass`); (None, None) where
    none does. StudyError naming ``where`` where two files disagree by more than 1 %: the lab's record of the
    subject is not one."""
    from casflex.lab.c3d import c3d_body_mass

    found = []
    for f in files:
        if f is not None and f.lower().endswith(".c3d"):
            try:
                m = c3d_body_mass(f)
            except ValueError:  # a file its own check refuses, naming the field
                m = None
            if m is not None:
                found.append((m[0], f"{Path(f).name} ({m[1]})"))
    if not found:
        return None, None
    far = [(m, w) for m, w in found if abs(m - found[0][0]) > 0.01 * found[0][0]]
    if far:
        raise StudyError(f"{where}: not given, and the subject's C3D files disagree: {found[0][0]:g} kg in "
                         f"{found[0][1]}, {far[0][0]:g} kg in {far[0][1]}; give the subject's mass")
    return found[0]


#: the figure of the group (the subjects' means) in --out: no subject's figure may take its name
GROUP = "group"


def _subject_names(subs: tuple[Subject, ...]) -> None:
    """Each subject's name names its figure (``<name>.png`` in --out): unique, also where case is ignored (macOS,
    Windows), and not the group's figure's."""
    names = [s.name for s in subs]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise StudyError(f"subjects: subject {dup[0]!r} is named twice")
    for i, n in enumerate(names):
        if n.lower() in (GROUP, f"{GROUP}_contact"):  # the group's figures (group_contact.png: the muscles')
            raise StudyError(f"subjects[{i}].name: {n!r} names the group's figure ({n.lower()}.png): give the subject "
                             "another name")
        same = [m for m in names[:i] if m.lower() == n.lower()]
        if same:
            raise StudyError(f"subjects[{i}].name: {n!r} and {same[0]!r} differ only in case: their figures would be "
                             "one file where case is ignored (macOS, Windows); give other names")


def _uncertain(where: str, text: str):
    """The casflex.scene.Uncertain of ``TARGET=SD|P%|LO:HI``; StudyError naming ``where`` otherwise."""
    from casflex.scene.uncertain import parse

    try:
        return parse(text)
    except ValueError as exc:
        raise StudyError(f"{where}: {exc}") from None


def load_study(path: str) -> Study:
    """The study file at ``path``, every field and file checked (StudyError naming the field otherwise)."""
    p = Path(path)
    if not p.is_file():
        raise StudyError(f"{path}: no such study file")
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise StudyError(f"{path}: not valid TOML: {exc}") from None
    data = _check_keys("study", data, {"name", "options", "subjects"}, {"name", "subjects"})
    base = p.resolve().parent
    subjects = data["subjects"]
    if not isinstance(subjects, list) or not subjects:
        raise StudyError("subjects: expected one or more [[subjects]] tables")
    subs = tuple(_subject(base, i, s) for i, s in enumerate(subjects))
    _subject_names(subs)
    if not isinstance(data["name"], str) or not data["name"].strip():
        raise StudyError(f"name: expected the study's name, got {data['name']!r}")
    options = _options(base, data.get("options", {}))
    if options.normalise == "mass":
        for i, s in enumerate(subs):
            if s.mass is None:
                raise StudyError(f"subjects[{i}].mass: needed by options.normalise = \"mass\" (kg), and none of "
                                 "the subject's C3D files holds it (PROCESSING:Bodymass): give the subject's mass")
    for i, s in enumerate(subs):
        _check_static_window(f"subjects[{i}].static_window", s)
        for k, t in enumerate(s.trials):
            _check_trial_files(f"subjects[{i}].trials[{k}]", t, options)
    return Study(data["name"], str(p.resolve()), options, subs)


#: (path, size, modification time ns) -> what :func:`_spans` read from that file's header and first and last rows
_SPANS: dict[tuple[str, int, int], Any] = {}


def _spans(where: str, trial: Trial):
    """(the markers' FileSpan, the plates' FileSpan or None, the plates' rate Hz or NaN) from the trial files'
    headers and first and last rows (:func:`casflex.lab.tables.trc_span`, :func:`casflex.lab.c3d.c3d_span`); an
    ExternalLoads file read for its data file (a setup naming itself refused). StudyError naming the field."""
    from casflex.lab.c3d import c3d_span
    from casflex.lab.setups import read_external_loads
    from casflex.lab.tables import sto_span, trc_span

    def read(path: str):
        if path.lower().endswith(".c3d"):
            return c3d_span(path)
        return (trc_span(path) if path.lower().endswith(".trc") else sto_span(path)), math.nan

    def span(field_: str, path: str):
        try:
            st = os.stat(path)
            key = (os.path.abspath(path), st.st_size, st.st_mtime_ns)
            if key not in _SPANS:  # a file that many trials name (or a study checked again) read once
                _SPANS[key] = read(path)
            return _SPANS[key]
        except ValueError as exc:
            raise StudyError(f"{where}.{field_}: {exc}") from None

    markers, analog = span("markers", trial.markers)
    if trial.grf is None:
        return markers, (markers if trial.markers.lower().endswith(".c3d") else None), analog
    grf = trial.grf
    if grf.lower().endswith(".xml"):
        try:
            grf = read_external_loads(grf).datafile
        except ValueError as exc:
            raise StudyError(f"{where}.grf: {exc}") from None
        if not Path(grf).is_file():
            raise StudyError(f"{where}.grf: its datafile {grf}: no such file")
    plates, analog = span("grf", grf)
    return markers, plates, analog if grf.lower().endswith(".c3d") else plates.rate


def _check_static_window(where: str, subject: Subject) -> None:
    """The static trial's window within its file's times (its header and first and last rows); StudyError
    naming ``where``."""
    if subject.static_window is None:
        return
    markers = _spans(where.rpartition(".")[0] + ".static", Trial("static", subject.static))[0]
    lo, hi = subject.static_window
    slack = 0.5 / markers.rate if math.isfinite(markers.rate) else 1e-9  # half a sample: a frame's own time
    if lo < markers.t0 - slack or hi > markers.t1 + slack:
        raise StudyError(f"{where}: {lo:g}..{hi:g} s is not within the static trial's times {markers.t0:g}.."
                         f"{markers.t1:g} s ({Path(subject.static).name}): give a window within them")


def _check_trial_files(where: str, trial: Trial, options: Options) -> None:
    """What a trial's files' headers tell before any work (:func:`_spans`): its window within the markers' and the
    plates' times, the cut-offs below the Nyquist frequency of the markers' and the plates' rates, its plates'
    prefixes among the plates' columns. StudyError naming the field."""
    from casflex.lab.filtering import _plate_columns

    markers, plates, plate_rate = _spans(where, trial)
    lo, hi = trial.window or (markers.t0, markers.t1)
    for what, sp in (("markers", markers), ("grf", plates)):
        if sp is None or trial.window is None and what == "markers":
            continue
        slack = 0.5 / sp.rate if math.isfinite(sp.rate) else 1e-9  # half a sample: a frame's own time
        if lo < sp.t0 - slack or hi > sp.t1 + slack:
            field_ = "window" if trial.window else "grf"
            name = Path(trial.markers if what == "markers" else trial.grf or trial.markers).name
            span = "the window" if trial.window else "the markers' times"
            raise StudyError(f"{where}.{field_}: {span} {lo:g}..{hi:g} s is not within the {what}' times "
                             f"{sp.t0:g}..{sp.t1:g} s ({name}): give a window within both")
    f = options.trials.filter
    cutoffs = (("options.cutoff", f.cutoff, markers.rate, "markers"), ("options.cutoff_plates", f.plates, plate_rate,
                                                                       "plates"))
    for field_, cut, rate, what in cutoffs:
        if cut is not None and math.isfinite(rate) and not cut < rate / 2:
            raise StudyError(f"{field_}: {cut:g} Hz is not below the Nyquist frequency {rate / 2:g} Hz of "
                             f"{where}'s {what} ({rate:g} Hz): give a lower cut-off")
    for node, prefix in ((n, p) for n, v in (trial.plates or {}).items() for p in ([v] if isinstance(v, str) else v)):
        if plates is not None and plates.names:
            try:
                _plate_columns(SimpleNamespace(names=plates.names, source=Path(trial.grf or "").name), prefix)
            except ValueError as exc:
                raise StudyError(f"{where}.plates.{node}: {exc}") from None
