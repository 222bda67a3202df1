"""``casflex study STUDY.toml``: a lab's whole study (subjects, static and walking or running trials) in one
command, on dask (:mod:`casflex.study.runner`): one tidy table and the figures, resumable."""

from __future__ import annotations

import argparse
import csv
import functools
import io
import os
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

from casflex.cli._base import OptionError, Outputs, integer, need_extra, output_path

_HEAD = ["subject", "trial", "load", "foot", "cycle", "percent", "value", "band", "unit", "clean", "t0", "t1"]


def _table(rows: list[tuple]) -> str:
    """loads.csv's text of ``rows`` (:func:`casflex.study.runner.tidy_rows`) by the csv module, each value and band
    by repr (the shortest text that reads back to the same double): where a name needs CSV's quoting (a comma, a
    quote, a line break), else :func:`_loads_text` makes the same text twice as fast (:func:`_loads_csv`)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(_HEAD)
    w.writerows([(*r[:5], f"{r[5]:g}", repr(r[6]), "" if r[7] is None else repr(r[7]), r[8],
                  "" if r[9] is None else str(r[9]).lower(), repr(r[10]), repr(r[11])) for r in rows])
    return buf.getvalue()


def _loads_csv(out: dict, per_kg: bool = False) -> tuple[str, int]:
    """loads.csv's text of ``out``'s trials and its rows' count: from the records' cycles (:func:`_loads_text`), or
    by the csv module (:func:`_table`) where a name needs quoting."""
    from casflex.study.runner import tidy_rows

    body = _loads_text(out, per_kg)
    if body is not None:
        return ",".join(_HEAD) + "\n" + body, body.count("\n")
    rows = tidy_rows(out, per_kg=per_kg)
    return _table(rows), len(rows)


def _quoted(name) -> bool:
    """Whether CSV quotes ``name`` (a comma, a quote, a line break in it)."""
    return isinstance(name, str) and any(c in name for c in ',"\r\n')


def _loads_text(out: dict, per_kg: bool = False) -> str | None:
    """loads.csv's lines of ``out``'s trials, without its header, as the csv module writes the rows of
    :func:`casflex.study.runner.tidy_rows` (:func:`_table`), made from the records' cycles without the rows: each
    cycle's names, times and unit formatted once, its values (and bands) by repr, joined with the percents (16 000
    lines a subject of 20 trials: 94-104 -> 24-29 ms of CPU); None where a name needs CSV's quoting."""
    from casflex.study.runner import PERCENT, unit_of

    percents = [f"{float(p):g}" for p in PERCENT]
    parts: list[str] = []
    for (subject, trial), rec in out["trials"].items():
        for name, ld in rec.loads.items():
            unit = unit_of(name, per_kg)
            if any(_quoted(n) for n in (subject, trial, name, ld.foot, unit)):
                return None
            foot = "" if ld.foot is None else ld.foot
            clean = ld.clean or [None] * len(ld.value)
            for k, values in enumerate(ld.value):
                head = f"{subject},{trial},{name},{foot},{k + 1},"
                t0, t1 = ld.cycles[k]
                tail = f",{unit},{'' if clean[k] is None else str(clean[k]).lower()},{t0!r},{t1!r}\n"
                cells = (zip(percents, map(repr, values), [""] * len(values), strict=True) if ld.band is None else
                         zip(percents, map(repr, values), map(repr, ld.band[k]), strict=True))
                parts += [head, (tail + head).join(map(",".join, cells)), tail]
    return "".join(parts)


def _passive_table(out: dict) -> str | None:
    """passive.csv: one row per subject, trial, hinge and window of the study's passive fits (None: none asked)."""
    rows = [(subject, trial, f) for (subject, trial), rec in out["trials"].items() for f in rec.passive]
    if not rows:
        return None
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["subject", "trial", "hinge", "phase", "t0", "t1", "kt", "kt_se", "ct", "ct_se", "rest_angle",
                "rest_angle_se", "r2", "passive", "why"])
    for subject, trial, f in rows:
        window = f.window or ["", ""]
        if f.error is not None:
            w.writerow([subject, trial, f.hinge, f.phase, *window, *[""] * 8, f.error])
            continue
        w.writerow([subject, trial, f.hinge, f.phase, *window, repr(f.kt), repr(f.se["kt"]), repr(f.ct),
                    repr(f.se["ct"]), repr(f.rest_angle), repr(f.se["rest_angle"]), repr(f.r2),
                    "yes" if f.passive else "no", "; ".join(f.why)])
    return buf.getvalue()


def cycle_curves(out: dict, all_cycles: bool = False, kind: str = "loads") -> dict[str, dict[str, np.ndarray]]:
    """load (or joint angle, ``kind`` "angles") -> subject -> its cycles (m, 101) over the subject's trials: the
    clean ones (their stance wholly on the foot's plate, :func:`casflex.study.events.clean_cycles`), every one
    where ``all_cycles`` (the study's ``cycles = "all"``); a subject without any left out, a load without any
    subject too."""
    return {n: {s: np.array([c for c, _ in cs]) for s, cs in subs.items()}
            for n, subs in _kept(out, all_cycles, kind).items()}


def _kept(out: dict, all_cycles: bool, kind: str) -> dict[str, dict[str, list[tuple[tuple, float | None]]]]:
    """name -> subject -> [(cycle's values, its toe-off %)] of the cycles kept (:func:`cycle_curves`)."""
    from casflex.plotting.gait import split_side

    side = functools.lru_cache(maxsize=None)(lambda name: split_side(name)[1])  # a few names, 200 trials' worth
    per: dict[str, dict[str, list]] = {}
    for (subject, _), rec in out["trials"].items():
        for name, ld in getattr(rec, kind).items():
            keep = ld.clean or [False] * len(ld.value)
            offs = rec.toe_off.get(ld.foot) or [None] * len(ld.value)
            if side(name) != side(ld.foot or ""):  # an arm or the trunk on a foot's cycles
                offs = [None] * len(ld.value)  # its toe-off is no event of its own side: not drawn
            per.setdefault(name, {}).setdefault(subject, []).extend(
                (v, off) for v, ok, off in zip(ld.value, keep, offs, strict=True) if ok or all_cycles)
    per = {n: {s: c for s, c in subs.items() if c} for n, subs in per.items()}
    return {n: subs for n, subs in per.items() if subs}


def _coordinate_signs(out: dict) -> dict[str, float]:
    """The subjects' scene coordinates' signs by name (the clinical signs turn a coordinate of sign -1 again)."""
    signs: dict[str, float] = {}
    for rec in out["subjects"].values():
        signs |= dict(_scene_signs(rec.scene))
    return signs


@functools.lru_cache(maxsize=256)
def _scene_signs(scene: str) -> tuple[tuple[str, float], ...]:
    """(name, sign) of the scene's coordinates, each scene read once in the process: each subject's figure plan
    asks for every subject's (30 ms a whole-body scene: 3 s of a 10-subject study's command with clinical signs)."""
    from casflex.scene.io import loads_scene

    return tuple((c.name, c.sign) for c in getattr(loads_scene(scene), "coordinates", ()))


def _figure_plans(out: dict, title: str, per_kg: bool = False, all_cycles: bool = False, clinical: bool = False,
                  normative: dict | None = None) -> tuple[dict[str, dict], list[str]]:
    """Per subject and for the group (the subjects' means): each joint's angle and moment over the gait cycle as
    gait reports show them (:func:`casflex.plotting.gait.gait_figure`): ({file name: gait_figure's arguments but
    its path}, warnings)."""
    from casflex.plotting.gait import split_side
    from casflex.study.runner import PERCENT, unit_of
    from casflex.study.study_file import GROUP  # a subject of this name is refused (its figure would be this)

    loads = _kept(out, all_cycles, "loads")
    kept = loads | _kept(out, all_cycles, "angles")
    if not kept:
        return {}, []
    units = {n: unit_of(n, per_kg) if n in loads else "deg" for n in kept}
    options = {"units": units, "clinical": clinical, "normative": normative,
               "coordinate_signs": _coordinate_signs(out) if clinical else None}
    plans = {}
    for subject in sorted({s for subs in kept.values() for s in subs}):
        mine = {n: subs[subject] for n, subs in kept.items() if subject in subs}
        plans[f"{subject}.png"] = {"percent": PERCENT, "curves": {n: np.array([c for c, _ in cs])
                                                                  for n, cs in mine.items()},
                                   "toe_off": {n: [off for _, off in cs] for n, cs in mine.items()},
                                   "title": f"{title}: {subject}", "what": "cycles", **options}
    means = {n: {s: (np.array([c for c, _ in cs]).mean(axis=0),
                     float(np.mean(offs)) if (offs := [o for _, o in cs if o is not None]) else None)
                 for s, cs in subs.items()} for n, subs in kept.items()}
    plans[f"{GROUP}.png"] = {"percent": PERCENT,
                             "curves": {n: np.array([m for m, _ in subs.values()]) for n, subs in means.items()},
                             "toe_off": {n: [o for _, o in subs.values()] for n, subs in means.items()},
                             "title": f"{title}: the subjects' means", "what": "subjects", **options}
    drawn = {split_side(n)[0] for n in kept}
    unused = sorted(set(normative or {}) - drawn)
    notes = [f"--normative: no curve {k!r} in the figures (theirs: {', '.join(sorted(drawn))}): its band is not "
             "drawn" for k in unused]
    return plans, notes


def draw_figure(plan: dict) -> bytes:
    """The PNG of one figure of :func:`_figure_plans` (in a dask worker, or here), rendered into memory as
    :func:`casflex.plotting._figure._save` renders it (the same bytes), and returned (a worker on another machine
    returns it). Neither written to a temporary file and read back (an fsync) nor cleared (the figure's artists
    dropped one by one: 13 % of its time): drawn over the thread's previous figure where it has the same panels
    (:class:`casflex.plotting.gait.GaitFigures`, the same pixels), else freed with its last reference."""
    from casflex.plotting.gait import GaitFigures

    return GaitFigures.of_thread().png(**plan)


def _fingerprint(plan: dict) -> str:
    """What a figure is drawn from (its data, title and options) and casflex's version, as 16 hex digits: a figure
    whose fingerprint is the one recorded beside it is not drawn again."""
    import hashlib
    import pickle

    from casflex import __version__

    return hashlib.sha1(pickle.dumps((__version__, sorted(plan.items(), key=lambda kv: kv[0])))).hexdigest()[:16]


#: figures to draw from which they are drawn on the study's cluster (started for them where every run is recorded);
#: fewer are drawn here: a worker's first figure pays matplotlib's import (about a second), this process's not
FIGURES_ON_CLUSTER = 4


def _draw_figures(plans: dict[str, dict], directory: Path, kept: dict[str, str], session=None,
                  meanwhile: Callable[[], None] | None = None, drawn: dict[str, tuple[str, bytes]] | None = None
                  ) -> dict[str, str]:
    """Each figure of ``plans`` written into ``directory`` but those whose fingerprint is in ``kept`` (up to date
    in the target folder): taken from ``drawn`` ({name: (fingerprint, PNG)}, drawn while the trials ran) where
    drawn from the same plan, else drawn on ``session``'s workers in parallel where there are
    :data:`FIGURES_ON_CLUSTER` or more, else here; ``meanwhile()`` (the table's writing) called while the workers
    draw. Returns {file name: fingerprint} of every figure."""
    prints = {name: _fingerprint(plan) for name, plan in plans.items()}
    todo = [name for name in plans if kept.get(name) != prints[name]]
    for name in [name for name in todo if (drawn or {}).get(name, ("",))[0] == prints[name]]:
        (directory / name).write_bytes(drawn[name][1])
        todo.remove(name)
    futures = {}
    if session is not None and len(todo) >= FIGURES_ON_CLUSTER:
        client = session.client()
        futures = {name: client.submit(draw_figure, plans[name], pure=False) for name in todo}
    if meanwhile is not None:
        meanwhile()
    for name in todo:
        (directory / name).write_bytes(futures[name].result() if futures else draw_figure(plans[name]))
    return prints


class _EarlyFigures:
    """:func:`casflex.study.runner.run_study`'s ``on_subject``: a subject's figure drawn here as soon as its trials
    are recorded, while the workers run the other subjects' (this process is idle meanwhile: the figures, 11 of
    them 34 s after the last record of a 200-trial study on one worker, overlap the trials). Kept with its
    fingerprint in :attr:`drawn`: :func:`_draw_figures` takes it where the whole study's plan for the figure is
    the same (the same records, units and options), else draws it anew; a figure that fails here is left to it."""

    def __init__(self, study, options: dict, kept: dict[str, str]) -> None:
        self.study, self.options, self.kept = study, options, kept
        self.drawn: dict[str, tuple[str, bytes]] = {}
        self.rows: dict[str, tuple[tuple, str | None]] = {}  # subject -> (its trials, its loads.csv lines)

    def __call__(self, subject: str, out: dict) -> None:
        from casflex.study.runner import per_kg

        try:  # its lines of loads.csv too (0.7 s of CPU for 200 trials, else all after the last record)
            self.rows[subject] = (tuple(out["trials"]), _loads_text(per_kg(out, self.study), self.options["per_kg"]))
        except Exception:  # noqa: BLE001 - the table is then made after the trials, where its error is reported
            pass
        name = f"{subject}.png"
        try:
            plan = _figure_plans(per_kg(out, self.study), self.study.name, **self.options)[0].get(name)
            if plan is not None and self.kept.get(name) != (fp := _fingerprint(plan)):
                self.drawn[name] = (fp, draw_figure(plan))
        except Exception:  # noqa: BLE001 - drawn again after the trials, where its error is reported
            pass

    def table(self, out: dict) -> str | None:
        """loads.csv's text of ``out``'s trials from the subjects' lines made as their trials finished, where each
        subject's were made from the same trials (in the table's order), else None (:func:`_loads_csv` makes it)."""
        order = list(out["trials"])
        subjects = list(dict.fromkeys(s for s, _ in order))
        parts = [self.rows.get(s, ((), None)) for s in subjects]
        if any(text is None for _, text in parts) or [k for keys, _ in parts for k in keys] != order:
            return None
        return ",".join(_HEAD) + "\n" + "".join(text for _, text in parts)


def _muscles(out: dict, directory: Path, study) -> list[str]:
    """muscles.csv (one row per subject, trial, output, cycle and percent: the joints' reactions in body weights,
    the muscles' activations) and the group's contact force figure; the figures written."""
    from casflex.plotting.study_muscles import plot_contact
    from casflex.study.muscles import contact_curves, muscle_rows
    from casflex.study.runner import PERCENT
    from casflex.study.study_file import GROUP

    if study.options.muscles is None:
        return []
    rows = muscle_rows(out["muscles"], PERCENT)
    (directory / "muscles.csv").write_text(_table(rows).replace("subject,trial,load,", "subject,trial,output,", 1))
    curves = contact_curves(out["muscles"], study.options.cycles == "all")
    if not curves:
        return []
    plot_contact(PERCENT, curves, f"{study.name}: joint contact forces", directory / f"{GROUP}_contact.png")
    return [f"{GROUP}_contact.png"]


def _check_cluster(args: argparse.Namespace) -> None:
    """--workers within what the machine runs at once, --scheduler answering: one line before any work."""
    from casflex.study.sweep import max_workers, unreachable

    if args.scheduler is None and args.workers is not None:
        limit, why = max_workers()
        if args.workers > limit:
            raise OptionError(f"--workers: {args.workers} is more local workers than this machine runs at once "
                              f"(at most {limit}: {why}); give at most {limit}, or --scheduler with its own workers")
    if args.scheduler is not None and (why := unreachable(args.scheduler)) is not None:
        raise OptionError(f"--scheduler: nothing answers at {args.scheduler!r} ({why}): start the scheduler "
                          "(dask scheduler) and its workers, or leave --scheduler out for a local cluster")


def _normative(path: str | None, per_kg: bool) -> dict | None:
    """--normative's bands, checked before any work (:func:`casflex.plotting.gait.read_normative`). Without one,
    matplotlib is not imported here (0.9 s of CPU before the cluster's start): the figures import it while the
    trials run."""
    if path is None:
        return None
    from casflex.plotting.gait import read_normative

    try:
        return read_normative(path, {"angle": "deg", "moment": "N m/kg" if per_kg else "N m"})
    except ValueError as exc:
        raise OptionError(f"--normative: {exc}") from None


#: the file beside the outputs that says what they were made from (:func:`_inputs_key`) and each one's size and
#: time: the same command again with nothing changed reads it and the summary, and does nothing else
MANIFEST = ".casflex-study.json"


def _paths(value, out: set[str]) -> set[str]:
    """Every text in ``value`` (the study's dataclasses, lists, dicts) that may name a file."""
    import dataclasses

    if dataclasses.is_dataclass(value):
        for f in dataclasses.fields(value):
            _paths(getattr(value, f.name), out)
    elif isinstance(value, (list, tuple)):
        for v in value:
            _paths(v, out)
    elif isinstance(value, dict):
        for v in value.values():
            _paths(v, out)
    elif isinstance(value, str) and value:
        out.add(value)
    return out


def _stat(path: str | Path) -> list[int] | None:
    try:
        st = os.stat(path)
    except (OSError, ValueError):  # no such file (a built-in scene's name, an option's value)
        return None
    return [st.st_size, st.st_mtime_ns]


def _inputs_key(args: argparse.Namespace, study, record: Path) -> str:
    """What the outputs are made from, as 40 hex digits: casflex's version, the options that change them, the
    study file's text, the size and modification time (ns) of every file the study names and of every record in
    ``record``. Sizes and times, not contents: as make and rsync tell a changed file (a file rewritten with its old
    size and time, to the nanosecond, is taken as unchanged; --retry-failed or a new --out redoes everything)."""
    import hashlib
    import json

    from casflex import __version__

    files = sorted(_paths(study, set()) | {args.normative or ""})
    try:
        recs = sorted((e.name, e.stat().st_size, e.stat().st_mtime_ns) for e in os.scandir(record)
                      if e.name.endswith(".json"))
    except OSError:
        recs = []
    text = json.dumps({"casflex": __version__, "study": Path(args.study).read_text(), "signs": args.signs,
                       "normative": args.normative, "record": str(Path(record).resolve()),
                       "files": [(f, _stat(f)) for f in files], "records": recs})
    return hashlib.sha1(text.encode()).hexdigest()


def _manifest(out: str) -> dict:
    """The manifest beside the outputs in ``out`` (:data:`MANIFEST`), {} where there is none or it is unreadable."""
    import json

    try:
        d = json.loads((Path(out) / MANIFEST).read_text())
    except (OSError, ValueError):
        return {}
    return d if isinstance(d, dict) else {}


def _up_to_date(args: argparse.Namespace, old: dict, key: str) -> int | None:
    """The exit status of the run that made the outputs in --out where they are up to date (the same inputs'
    :func:`_inputs_key`, each output file as it wrote it), else None: the study is run."""
    files = old.get("files")
    if old.get("inputs") != key or not isinstance(files, dict) or not files or (args.retry_failed and old.get("code")):
        return None
    if any(_stat(Path(args.out) / name) != stat for name, stat in files.items()):
        return None
    return int(old.get("code", 0))


def _write_manifest(staging: Path, old: dict, key: str, figures: dict[str, str], code: int) -> None:
    """The manifest of the outputs staged in ``staging`` (their sizes and times, kept by the moves into --out) and
    of the figures kept from before (``old``'s)."""
    import json

    files = {f.name: _stat(f) for f in staging.iterdir() if f.name != MANIFEST}
    files |= {name: old.get("files", {}).get(name) for name in figures if name not in files}
    (staging / MANIFEST).write_text(json.dumps({"inputs": key, "code": code, "files": files, "figures": figures}))


def _kept_figures(old: dict, out: str, key_figures: dict) -> dict[str, str]:
    """{figure: fingerprint} of the figures in --out as the manifest says they were written (not changed since)."""
    files = old.get("files", {})
    return {name: fp for name, fp in key_figures.items()
            if name in files and _stat(Path(out) / name) == files[name]}


def _need_distributed() -> None:
    """need_extra's check without importing dask (a second of a command that may have nothing to do)."""
    import importlib.util

    from casflex.cli._base import _extra_line

    if importlib.util.find_spec("distributed") is None:
        raise OptionError(_extra_line("distributed", "casflex study"))


def cmd_study(args: argparse.Namespace, outputs: Outputs) -> int:
    _need_distributed()  # before the study file is read: one line, not a traceback at the end
    from casflex.study.study_file import StudyError, load_study

    try:
        study = load_study(args.study)
    except StudyError as exc:
        raise OptionError(f"{args.study}: {exc}") from None
    _check_cluster(args)
    staging = outputs.directory("--out", args.out)
    record = outputs.folder("--record", args.record) if args.record else Path(args.out) / "record"
    n = len(study.trials())
    print(f"study {study.name!r}: {len(study.subjects)} subject(s), {n} trial(s); records in {record}", flush=True)
    old, key = _manifest(args.out), _inputs_key(args, study, record)
    if (code := _up_to_date(args, old, key)) is not None:
        print((Path(args.out) / "summary.txt").read_text(), end="")
        print(f"up to date: the outputs in {args.out} are those of these inputs and records (nothing run, nothing "
              "written)")
        return code
    return _run(args, study, staging, record, old)


def _run(args: argparse.Namespace, study, staging: Path, record: Path, old: dict) -> int:
    """The study run (what is not recorded yet), its table, figures and summary staged in ``staging``."""
    from casflex.study.runner import check_against_models, per_kg, run_study
    from casflex.study.study_file import StudyError
    from casflex.study.sweep import Session

    try:
        check_against_models(study)
    except StudyError as exc:
        raise OptionError(f"{args.study}: {exc}") from None
    files = [f for s, t in study.trials() for f in (t.markers, t.grf)] + [s.static for s in study.subjects]
    if c3d := next((f for f in files if f and f.lower().endswith(".c3d")), None):  # the workers would fail each trial
        need_extra("ezc3d", f"{args.study}: its C3D file {Path(c3d).name!r}")
    normative = _normative(args.normative, study.options.normalise == "mass")
    n = len(study.trials())
    kg = study.options.normalise == "mass"
    options = {"per_kg": kg, "all_cycles": study.options.cycles == "all", "clinical": args.signs == "clinical",
               "normative": normative}
    kept = _kept_figures(old, args.out, old.get("figures", {}))
    early = _EarlyFigures(study, options, kept)
    with Session(args.scheduler, args.workers) as session:
        out = run_study(study, record, progress=not args.quiet, retry_failed=args.retry_failed, session=session,
                        on_subject=early)
        if out["interrupted"]:
            kept = len(list(record.glob("*.json")))
            print(f"casflex: {kept} finished run(s) kept in {record}: the same command again resumes",
                  file=sys.stderr)
            raise KeyboardInterrupt
        plans, notes = _figure_plans(per_kg(out, study), study.name, **options)
        passive, counted = _passive_table(out), []  # loads.csv's rows, counted while the workers draw

        def tables() -> None:  # while the workers draw the figures
            text = early.table(out)
            if text is None:  # a subject's lines not made as its trials finished: the table of all now
                text, rows = _loads_csv(per_kg(out, study), kg)
                counted.append(rows)
            else:  # a line a row (no name in the subjects' lines needs quoting)
                counted.append(text.count("\n") - 1)
            (staging / "loads.csv").write_text(text)
            if passive is not None:
                (staging / "passive.csv").write_text(passive)

        prints = _draw_figures(plans, staging, kept, session, tables, early.drawn)
    for note in notes:
        print(f"casflex: warning: {note}", file=sys.stderr)
    figures = [*plans, *_muscles(out, staging, study)]
    code = _summary(study, out, counted[0], passive, figures, n, staging)
    _write_manifest(staging, old, _inputs_key(args, study, record), prints, code)
    return code


def _summary(study, out: dict, rows: int, passive: str | None, figures: list[str], n: int, staging: Path) -> int:
    """summary.txt, printed too: the trials done, each trial's plates and cycles, the failures; the exit status."""
    lines = [f"{len(out['trials'])} of {n} trial(s) done, {rows} rows in loads.csv"
             + (f", {passive.count(chr(10)) - 1} passive fit(s) in passive.csv" if passive else "")
             + f"; figures: {', '.join(figures) or 'none'}"]
    lines += [f"  {s.name}: mass {s.mass:g} kg read from {s.mass_from}" for s in study.subjects if s.mass_from]
    for subject, rec in out["subjects"].items():  # what a subject's model holds that its scene leaves out
        for line in (ln for ln in rec.report if ln.startswith("warning: ")):
            lines.append(f"  {subject}: {line}")
            print(f"casflex: warning: subject {subject}: {line.removeprefix('warning: ')}", file=sys.stderr)
    for (subject, trial), rec in out["trials"].items():
        cycles = {ld.foot: f"{sum(ld.clean)} clean of {len(ld.cycles)}" for ld in rec.loads.values()}
        lines.append(f"  {subject} {trial}: plates {rec.plates}; cycles per foot {cycles}")
        lines += [f"    {note}" for note in rec.warnings
                  if "no kinetic cycle" in note or "not clean" in note or "are not in the trial" in note]
    for (subject, trial), rec in out.get("muscles", {}).items():
        lines += [f"  {subject} {trial} muscles: {note}" for note in (*rec.warnings, *(  # the bands' peaks, p = 3
            ln for ln in rec.report if " resultant: peak " in ln))]
    if out["failed"]:
        lines.append(f"{len(out['failed'])} failed:")
        lines += [f"  {what}: {why}" for what, why in out["failed"]]
    (staging / "summary.txt").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 1 if out["failed"] else 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("study", help="a lab's whole study (subjects and trials in a study file), on dask")
    s.add_argument("study", help="the study file (TOML: subjects, their trials, the options; docs/lab.md)")
    s.add_argument("--out", type=output_path, required=True, metavar="DIR",
                   help="the results: loads.csv (one row per subject, trial, load, cycle and percent), "
                        "passive.csv (the passive fits asked), summary.txt and the figures (per subject, group.png)")
    s.add_argument("--record", type=output_path, metavar="DIR",
                   help="the runs' records (default DIR/record): a run recorded there is not done again")
    s.add_argument("--scheduler", metavar="ADDRESS", help="an existing dask scheduler (tcp://host:8786); default "
                                                          "a local cluster")
    s.add_argument("--workers", type=integer(1, "a number of workers"),
                   help="the local cluster's worker processes (default 2; at most one per core, and 1 GiB of the "
                        "machine's memory each)")
    s.add_argument("--retry-failed", action="store_true",
                   help="run again the runs recorded as failed (a lost worker, a mended file); by default a failed "
                        "run's record stands until its inputs change")
    s.add_argument("--signs", choices=("model", "clinical"), default="model",
                   help="the figures' signs: the model's (default: as loads.csv, OpenSim's coordinates) or clinical "
                        "(hip and knee flexion and ankle dorsiflexion +; hip and knee extensor and ankle "
                        "plantarflexor moments +; docs/lab.md)")
    s.add_argument("--normative", metavar="CSV",
                   help="a normative band (grey, mean +- 1 SD) in each figure's panels, from a CSV file: "
                        "load,percent,mean,sd,unit (docs/lab.md)")
    s.add_argument("--quiet", action="store_true", help="no progress messages")
    s.set_defaults(func=cmd_study)
