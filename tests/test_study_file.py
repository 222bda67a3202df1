"""casflex.study.study_file, fuzzed: mutated copies of a valid study file (fields deleted, wrong types, NaN and
infinities, negative numbers, unknown keys, paths to missing files and to folders, duplicated subjects and
trials, emptied lists) fed to ``casflex study --out``: each is refused in one line (exit 2, nothing written), or
is a study the checks accept (then not run: it would start a cluster); never a traceback, never a hang.

Seeded (the same cases every run) and bounded: the checks run before any cluster starts, in process, a few
hundredths of a second a case."""

from __future__ import annotations

import copy
import math
import random
import shutil
import signal
import tomllib
from pathlib import Path

import pytest

from casflex.cli import main
from casflex.study.runner import check_against_models
from casflex.study.study_file import StudyError, load_study

LAB = Path(__file__).resolve().parent / "data" / "lab"
FILES = ("hamner_subject02_planar.osim", "hamner_running_whole.trc", "hamner_running_whole_grf.mot",
         "hamner_tasks_ik.xml")
VALID = {
    "name": "fuzz",
    "options": {"plane": "X,Y", "cutoff": 6.0, "cutoff_plates": "same", "tasks": "hamner_tasks_ik.xml",
                "normalise": "none", "passive": ["knee_r"], "bands": False, "cycles": "clean",
                "max_misfit": 0.15},
    "subjects": [
        {"name": "s02", "model": "hamner_subject02_planar.osim", "mass": 70.0,
         "trials": [{"name": "run", "markers": "hamner_running_whole.trc", "grf": "hamner_running_whole_grf.mot",
                     "plates": {"calcn_r": "ground_", "calcn_l": "1_ground_"}, "window": [0.25, 1.15]},
                    {"name": "again", "markers": "hamner_running_whole.trc",
                     "grf": "hamner_running_whole_grf.mot"}]},
        {"name": "s03", "model": "hamner_subject02_planar.osim", "uncertain": ["pelvis.mass=10%"],
         "trials": [{"name": "run", "markers": "hamner_running_whole.trc"}]},
    ],
}
#: values of the wrong type or out of range, for any field
ODD = [math.nan, math.inf, -math.inf, -1, -0.5, 0, 1e308, "", " ", "x", "nowhere.trc", "sub/", ".", True, False,
       [], [1, 2], ["a"], {}, {"a": 1}, [math.nan, 1.0], [2.0, 1.0], [-1.0, 0.5], "../", "a b", "ground_"]
PATHS = ["missing.trc", "missing.osim", "nofolder/x.trc", "folder", "folder/", ".", "hamner_tasks_ik.xml",
         "hamner_running_whole_grf.mot", "hamner_running_whole.trc", "/", "study.toml"]
CASES = 160


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float) and not math.isfinite(v):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf")
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return "{ " + ", ".join(f'"{k}" = {_toml_value(x)}' for k, x in v.items()) + " }"


def _toml(study: dict) -> str:
    """The study as TOML: its scalars, [options], [[subjects]] with their [[subjects.trials]] (a field whose type
    the mutation changed to a table or a list of tables is written inline: TOML gives the reader the same)."""
    out = [f'"{k}" = {_toml_value(v)}' for k, v in study.items() if k not in ("options", "subjects")]
    if isinstance(study.get("options"), dict):
        out += ["[options]", *(f'"{k}" = {_toml_value(v)}' for k, v in study["options"].items())]
    elif "options" in study:
        out.insert(0, f'"options" = {_toml_value(study["options"])}')
    subjects = study.get("subjects")
    if not isinstance(subjects, list) or not all(isinstance(s, dict) for s in subjects):
        if "subjects" in study:
            out.insert(0, f'"subjects" = {_toml_value(subjects)}')
        return "\n".join(out) + "\n"
    for s in subjects:
        out.append("[[subjects]]")
        out += [f'"{k}" = {_toml_value(v)}' for k, v in s.items() if k != "trials"]
        trials = s.get("trials")
        if isinstance(trials, list) and trials and all(isinstance(t, dict) for t in trials):
            for t in trials:
                out += ["[[subjects.trials]]", *(f'"{k}" = {_toml_value(v)}' for k, v in t.items())]
        elif "trials" in s:
            out.append(f'"trials" = {_toml_value(trials)}')  # before any [[subjects.trials]]: the subject's own
    return "\n".join(out) + "\n"


def _tables(study: dict) -> list[dict]:
    """Every table of the study (itself, its options, each subject, each trial, each plates table)."""
    found = [study]
    for v in study.values():
        if isinstance(v, dict):
            found += _tables(v)
        elif isinstance(v, list):
            found += [x for y in v if isinstance(y, dict) for x in _tables(y)]
    return found


def _mutate(study: dict, rng: random.Random) -> str:
    """One mutation of the study in place; what it did."""
    tables = [t for t in _tables(study) if t]
    if not tables:
        study["subjects"] = rng.choice(ODD)
        return "subjects replaced"
    table = rng.choice(tables)
    key = rng.choice(sorted(table))
    kind = rng.choice(["delete", "odd", "odd", "number", "unknown", "path", "duplicate", "empty"])
    if kind == "delete":
        del table[key]
    elif kind == "odd":
        table[key] = copy.deepcopy(rng.choice(ODD))
    elif kind == "number":
        table[key] = rng.choice([math.nan, -1.0, -70.0, 0.0, 1e9, -math.inf, 3])
    elif kind == "unknown":
        key = rng.choice(["speed", "Name", "trial", "windows", "mass_kg", "static_trial"])
        table[key] = 1
    elif kind == "path":
        table[key] = rng.choice(PATHS)
    elif kind == "duplicate" and (lists := [v for t in tables for v in t.values()
                                            if isinstance(v, list) and v and isinstance(v[0], dict)]):
        target = rng.choice(lists)
        target.append(copy.deepcopy(rng.choice(target)))
        key = "a subject or trial"
    else:
        table[key] = [] if isinstance(table[key], list) else ""
        kind = "empty"
    return f"{kind} {key}"


class _Hang(Exception):
    pass


def _alarm(signum, frame):
    raise _Hang("a study file's checks took more than 10 s")


@pytest.fixture()
def folder(tmp_path: Path) -> Path:
    for f in FILES:
        shutil.copy(LAB / f, tmp_path / f)
    (tmp_path / "folder").mkdir()
    return tmp_path


def test_the_valid_study_file_is_accepted(folder):
    path = folder / "study.toml"
    path.write_text(_toml(VALID))
    study = load_study(str(path))
    check_against_models(study)
    assert [t.name for _, t in study.trials()] == ["run", "again", "run"]


def test_mutated_study_files_are_refused_in_one_line_or_accepted_never_a_traceback(folder, capsys):
    rng = random.Random(45)
    path, out = folder / "study.toml", folder / "out"
    refused, accepted = 0, 0
    old = signal.signal(signal.SIGALRM, _alarm)
    try:
        for case in range(CASES):
            study = copy.deepcopy(VALID)
            did = [_mutate(study, rng) for _ in range(rng.choice([1, 1, 2, 3]))]
            text = _toml(study)
            tomllib.loads(text)  # the test's own writer: valid TOML
            path.write_text(text)
            signal.alarm(10)
            try:
                check_against_models(load_study(str(path)))
            except StudyError:
                code = main(["study", str(path), "--out", str(out), "--quiet"])
                err = capsys.readouterr().err.strip().splitlines()
                where = f"case {case} ({', '.join(did)}):\n{text}"
                assert code == 2 and len(err) == 1 and err[0].startswith("casflex: error: "), f"{where}{err}"
                assert "Traceback" not in err[0] and not out.exists(), where
                refused += 1
            else:
                accepted += 1  # a study the checks take (a deleted optional field, a value still in range)
            finally:
                signal.alarm(0)
    finally:
        signal.signal(signal.SIGALRM, old)
    assert refused >= CASES // 2, (refused, accepted)  # most mutations break the file: the checks are exercised
