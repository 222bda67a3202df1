"""``casflex study STUDY.toml``: a lab's whole study (subjects, static and walking or running trials) in one
command, on dask (:mod:`casflex.study.runner`): one tidy table and the figures, resumable."""

from __future__ import annotations

import argparse
import csv
import io
import sys
from pathlib import Path

import numpy as np

from casflex.cli._base import OptionError, Outputs, integer, output_path


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


def cycle_curves(out: dict, all_cycles: bool = False) -> dict[str, dict[str, np.ndarray]]:
    """load -> subject -> its cycles (m, 101) over the subject's trials: the clean ones (their stance wholly on the
    foot's plate, :func:`casflex.study.events.clean_cycles`), every one where ``all_cycles`` (the study's
    ``cycles = "all"``); a subject without any left out, a load without any subject too."""
    per: dict[str, dict[str, list]] = {}
    for (subject, _), rec in out["trials"].items():
        for name, ld in rec.loads.items():
            keep = ld.clean or [False] * len(ld.value)
            per.setdefault(name, {}).setdefault(subject, []).extend(
                v for v, ok in zip(ld.value, keep, strict=True) if ok or all_cycles)
    per = {n: {s: np.array(c) for s, c in subs.items() if c} for n, subs in per.items()}
    return {n: subs for n, subs in per.items() if subs}


def _figures(out: dict, directory: Path, title: str, per_kg: bool = False, all_cycles: bool = False) -> list[str]:
    """Per subject and for the group (the subjects' means): each load over the gait cycle (:func:`cycle_curves`);
    the files written."""
    from casflex.plotting.study import plot_cycles
    from casflex.study.runner import PERCENT, unit_of
    from casflex.study.study_file import GROUP  # a subject of this name is refused (its figure would be this)

    per = cycle_curves(out, all_cycles)
    if not per:
        return []
    units = {n: unit_of(n, per_kg) for n in per}
    written = []
    for subject in sorted({s for subs in per.values() for s in subs}):
        curves = {n: {subject: subs[subject]} for n, subs in per.items() if subject in subs}
        plot_cycles(PERCENT, curves, f"{title}: {subject}", directory / f"{subject}.png", units=units)
        written.append(f"{subject}.png")
    group = {n: {GROUP: np.array([c.mean(axis=0) for c in subs.values()])} for n, subs in per.items()}
    plot_cycles(PERCENT, group, f"{title}: the subjects' means", directory / f"{GROUP}.png", units=units)
    return [*written, f"{GROUP}.png"]


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


def cmd_study(args: argparse.Namespace, outputs: Outputs) -> int:
    from casflex.study.runner import check_against_models, per_kg, run_study, tidy_rows
    from casflex.study.study_file import StudyError, load_study

    try:
        study = load_study(args.study)
        check_against_models(study)
    except StudyError as exc:
        raise OptionError(f"{args.study}: {exc}") from None
    _check_cluster(args)
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
    figures = _figures(per_kg(out, study), staging, study.name, per_kg=kg, all_cycles=study.options.cycles == "all")
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
        lines += [f"    {note}" for note in rec.warnings if "no kinetic cycle" in note or "not clean" in note]
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
    s.add_argument("--quiet", action="store_true", help="no progress messages")
    s.set_defaults(func=cmd_study)
