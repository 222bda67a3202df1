"""``casflex study STUDY.toml``: a lab's whole study (subjects, static and walking or running trials) in one
command, on dask (:mod:`casflex.study.runner`): one tidy table and the figures, resumable."""

from __future__ import annotations

import argparse
import csv
import io
import sys
from pathlib import Path

import numpy as np

from casflex.cli._base import OptionError, Outputs, integer, need_extra, output_path


def _table(rows: list[tuple]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["subject", "trial", "load", "foot", "cycle", "percent", "value", "band", "unit", "clean", "t0", "t1"])
    w.writerows([(*r[:5], f"{r[5]:g}", repr(r[6]), "" if r[7] is None else repr(r[7]), r[8],
                  "" if r[9] is None else str(r[9]).lower(), repr(r[10]), repr(r[11])) for r in rows])
    return buf.getvalue()


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

    per: dict[str, dict[str, list]] = {}
    for (subject, _), rec in out["trials"].items():
        for name, ld in getattr(rec, kind).items():
            keep = ld.clean or [False] * len(ld.value)
            offs = rec.toe_off.get(ld.foot) or [None] * len(ld.value)
            if split_side(name)[1] != split_side(ld.foot or "")[1]:  # an arm or the trunk on a foot's cycles
                offs = [None] * len(ld.value)  # its toe-off is no event of its own side: not drawn
            per.setdefault(name, {}).setdefault(subject, []).extend(
                (v, off) for v, ok, off in zip(ld.value, keep, offs, strict=True) if ok or all_cycles)
    per = {n: {s: c for s, c in subs.items() if c} for n, subs in per.items()}
    return {n: subs for n, subs in per.items() if subs}


def _coordinate_signs(out: dict) -> dict[str, float]:
    """The subjects' scene coordinates' signs by name (the clinical signs turn a coordinate of sign -1 again)."""
    from casflex.scene.io import loads_scene

    signs: dict[str, float] = {}
    for rec in out["subjects"].values():
        signs |= {c.name: c.sign for c in getattr(loads_scene(rec.scene), "coordinates", ())}
    return signs


def _figures(out: dict, directory: Path, title: str, per_kg: bool = False, all_cycles: bool = False,
             clinical: bool = False, normative: dict | None = None) -> tuple[list[str], list[str]]:
    """Per subject and for the group (the subjects' means): each joint's angle and moment over the gait cycle as
    gait reports show them (:func:`casflex.plotting.gait.gait_figure`); (the files written, warnings)."""
    from casflex.plotting._figure import _close
    from casflex.plotting.gait import gait_figure, split_side
    from casflex.study.runner import PERCENT, unit_of
    from casflex.study.study_file import GROUP  # a subject of this name is refused (its figure would be this)

    loads = _kept(out, all_cycles, "loads")
    kept = loads | _kept(out, all_cycles, "angles")
    if not kept:
        return [], []
    units = {n: unit_of(n, per_kg) if n in loads else "deg" for n in kept}
    options = {"units": units, "clinical": clinical, "normative": normative,
               "coordinate_signs": _coordinate_signs(out) if clinical else None}
    written = []
    for subject in sorted({s for subs in kept.values() for s in subs}):
        mine = {n: subs[subject] for n, subs in kept.items() if subject in subs}
        _close(gait_figure(PERCENT, {n: np.array([c for c, _ in cs]) for n, cs in mine.items()},
                           {n: [off for _, off in cs] for n, cs in mine.items()}, f"{title}: {subject}",
                           directory / f"{subject}.png", what="cycles", **options))
        written.append(f"{subject}.png")
    means = {n: {s: (np.array([c for c, _ in cs]).mean(axis=0),
                     float(np.mean(offs)) if (offs := [o for _, o in cs if o is not None]) else None)
                 for s, cs in subs.items()} for n, subs in kept.items()}
    _close(gait_figure(PERCENT, {n: np.array([m for m, _ in subs.values()]) for n, subs in means.items()},
                       {n: [o for _, o in subs.values()] for n, subs in means.items()},
                       f"{title}: the subjects' means", directory / f"{GROUP}.png", what="subjects", **options))
    drawn = {split_side(n)[0] for n in kept}
    unused = sorted(set(normative or {}) - drawn)
    notes = [f"--normative: no curve {k!r} in the figures (theirs: {', '.join(sorted(drawn))}): its band is not "
             "drawn" for k in unused]
    return [*written, f"{GROUP}.png"], notes


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
    """--normative's bands, checked before any work (:func:`casflex.plotting.gait.read_normative`)."""
    from casflex.plotting.gait import read_normative

    if path is None:
        return None
    try:
        return read_normative(path, {"angle": "deg", "moment": "N m/kg" if per_kg else "N m"})
    except ValueError as exc:
        raise OptionError(f"--normative: {exc}") from None


def cmd_study(args: argparse.Namespace, outputs: Outputs) -> int:
    need_extra("distributed", "casflex study")  # before the study file is read: one line, not a traceback at the end
    from casflex.study.runner import check_against_models, per_kg, run_study, tidy_rows
    from casflex.study.study_file import StudyError, load_study

    try:
        study = load_study(args.study)
        check_against_models(study)
    except StudyError as exc:
        raise OptionError(f"{args.study}: {exc}") from None
    files = [f for s, t in study.trials() for f in (t.markers, t.grf)] + [s.static for s in study.subjects]
    if c3d := next((f for f in files if f and f.lower().endswith(".c3d")), None):  # the workers would fail each trial
        need_extra("ezc3d", f"{args.study}: its C3D file {Path(c3d).name!r}")
    _check_cluster(args)
    normative = _normative(args.normative, study.options.normalise == "mass")
    staging = outputs.directory("--out", args.out)
    record = outputs.folder("--record", args.record) if args.record else Path(args.out) / "record"
    n = len(study.trials())
    print(f"study {study.name!r}: {len(study.subjects)} subject(s), {n} trial(s); records in {record}", flush=True)
    out = run_study(study, record, scheduler=args.scheduler, n_workers=args.workers,
                    progress=not args.quiet, retry_failed=args.retry_failed)
    if out["interrupted"]:
        kept = len(list(record.glob("*.json")))
        print(f"casflex: {kept} finished run(s) kept in {record}: the same command again resumes", file=sys.stderr)
        raise KeyboardInterrupt
    kg = study.options.normalise == "mass"
    rows = tidy_rows(per_kg(out, study), per_kg=kg)
    (staging / "loads.csv").write_text(_table(rows))
    passive = _passive_table(out)
    if passive is not None:
        (staging / "passive.csv").write_text(passive)
    figures, notes = _figures(per_kg(out, study), staging, study.name, per_kg=kg,
                              all_cycles=study.options.cycles == "all", clinical=args.signs == "clinical",
                              normative=normative)
    for note in notes:
        print(f"casflex: warning: {note}", file=sys.stderr)
    figures += _muscles(out, staging, study)
    lines = [f"{len(out['trials'])} of {n} trial(s) done, {len(rows)} rows in loads.csv"
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
