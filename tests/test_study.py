"""``casflex study`` (issue 38): a study file read and checked before any work, its subjects calibrated and its
trials run on dask, one tidy table, a failing trial reported while the others go on, a resumed run redoing
nothing. The data: Hamner's subject 02 running (tests/data/lab, 1 s, both plates) on the planar whole-body
model, as two "subjects" (the same model and data twice: the mechanics of a study, not a second subject's answer)."""

from __future__ import annotations

import csv
import dataclasses
import shutil
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from casflex.cli import main
from casflex.study.runner import check_against_models
from casflex.study.study_file import StudyError, load_study

LAB = Path(__file__).resolve().parent / "data" / "lab"
FILES = ("hamner_subject02_planar.osim", "hamner_running_whole.trc", "hamner_running_whole_grf.mot",
         "hamner_tasks_ik.xml")

STUDY = """name = "hamner running"

[options]
plane = "X,Y"
cutoff = 6.0
tasks = "hamner_tasks_ik.xml"

[[subjects]]
name = "s02"
model = "hamner_subject02_planar.osim"

[[subjects.trials]]
name = "run"
markers = "hamner_running_whole.trc"
grf = "hamner_running_whole_grf.mot"

[[subjects.trials]]
name = "run_late"
markers = "hamner_running_whole.trc"
grf = "hamner_running_whole_grf.mot"
window = [0.25, 1.15]

[[subjects]]
name = "s02_again"
model = "hamner_subject02_planar.osim"
mass = 80.0

[[subjects.trials]]
name = "run"
markers = "hamner_running_whole.trc"
grf = "hamner_running_whole_grf.mot"
{extra}
"""


@pytest.fixture()
def folder(tmp_path: Path) -> Path:
    for f in FILES:
        shutil.copy(LAB / f, tmp_path / f)
    return tmp_path


def write(folder: Path, extra: str = "") -> Path:
    path = folder / "study.toml"
    path.write_text(STUDY.replace("{extra}", extra))
    return path


@pytest.mark.parametrize("edit, said", [
    (('model = "hamner_subject02_planar.osim"', 'model = "nowhere.osim"', 1),
     "subjects[0].model: nowhere.osim: no such file"),
    (('name = "run_late"', 'name = "run"', 1), "subjects[0].trials: trial 'run' is named twice"),
    (("window = [0.25, 1.15]", "window = [1.15, 0.25]", 1), "subjects[0].trials[1].window"),
    (("cutoff = 6.0", "cutoff = -1", 1), "options.cutoff"),
    (("mass = 80.0", 'mass = "heavy"', 1), "subjects[1].mass"),
    (("mass = 80.0", 'mass = 80.0\nuncertain = ["pelvis.mass=-3%"]', 1), "subjects[1].uncertain"),
    (('plane = "X,Y"', 'plane = "X,Q"', 1), "options.plane"),
    (('plane = "X,Y"', 'plane = "auto"\nvertical = "W"', 1), "options.vertical"),
    (('plane = "X,Y"', 'plane = "X,Y"\nnormalise = "height"', 1), "options.normalise"),
    (('plane = "X,Y"', 'plane = "X,Y"\npassive = ["knee_r:stance"]', 1), "options.passive"),
    (('plane = "X,Y"', 'plane = "X,Y"\npassive = ["knee_q"]', 1), "options.passive: 'knee_q' is not a joint"),
    (('plane = "X,Y"', 'plane = "X,Y"\nnormalise = "mass"', 1), "subjects[0].mass: needed by options.normalise"),
    (('plane = "X,Y"', 'plane = "X,Y"\nspeed = 3', 1), "options.speed: unknown field"),
    (('plane = "X,Y"', 'plane = "X,Y"\ncycles = "some"', 1), "options.cycles"),
    (("cutoff = 6.0", "cutoff = 6.0\nmax_misfit = 0", 1), "options.max_misfit: must be a distance > 0 m, got 0"),
    (("cutoff = 6.0", "cutoff = 6.0\nmax_misfit = 150", 1), "options.max_misfit: must be at most 1 m"),
    (("cutoff = 6.0", 'cutoff = 6.0\nmax_misfit = "0.15"', 1), "options.max_misfit: expected a distance in m"),
    (("cutoff = 6.0", "cutoff = 6.0\nmax_misfit = true", 1), "options.max_misfit: expected a distance in m"),
    # knowable from the files' headers, refused before any work (they failed each trial at run time)
    (("window = [0.25, 1.15]", "window = [0.25, 3.0]", 1),
     "subjects[0].trials[1].window: the window 0.25..3 s is not within the markers' times 0.2..1.2 s"),
    (("cutoff = 6.0", "cutoff = 45.0", 1), "options.cutoff: 45 Hz is not below the Nyquist frequency 30 Hz"),
    (("cutoff = 6.0", "cutoff = 6.0\ncutoff_plates = 31", 1), "options.cutoff_plates: 31 Hz is not below the Nyquist"),
    (('window = [0.25, 1.15]', 'window = [0.25, 1.15]\nplates = { calcn_r = "ground_", calcn_l = "ground_" }', 1),
     "subjects[0].trials[1].plates: the plate 'ground_' is given to calcn_r and calcn_l"),
    (('window = [0.25, 1.15]', 'window = [0.25, 1.15]\nplates = { calcn_r = "2_ground_" }', 1),
     "subjects[0].trials[1].plates.calcn_r: hamner_running_whole_grf.mot: no plate '2_ground_'"),
    (("mass = 80.0", 'mass = 80.0\nuncertain = ["pelvis.massx=3%"]', 1), "subjects[1].uncertain"),
    # an ExternalLoads file says which body each plate acts on (casflex.inverse.Trial's rule): the run failed on it
    (('grf = "hamner_running_whole_grf.mot"', 'grf = "hamner_tasks_ik.xml"\nplates = { calcn_r = "ground_" }', 1),
     "subjects[0].trials[0].plates: .*hamner_tasks_ik.xml says which body each plate acts on; give plates or that"),
    (('window = [0.25, 1.15]', 'window = [0.25, 1.15]\nplates = { calcn_x = "ground_force_" }', 1),
     "subjects[0].trials[1].plates"),
    # a subject's figure is <name>.png: "group" would be the group's figure, "S02" s02's where case is ignored
    (('name = "s02_again"', 'name = "Group"', 1), "subjects[1].name: 'Group' names the group's figure"),
    (('name = "s02_again"', 'name = "S02"', 1), "subjects[1].name: 'S02' and 's02' differ only in case"),
])
def test_a_bad_study_file_is_refused_in_one_line_before_any_work(folder, capsys, edit, said):
    path = write(folder)
    path.write_text(path.read_text().replace(*edit))
    with pytest.raises(StudyError, match=said.replace("[", r"\[").replace("]", r"\]")):
        check_against_models(load_study(str(path)))
    assert main(["study", str(path), "--out", str(folder / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and said.split(":")[0] in err[0], err
    assert not (folder / "out").exists()


@pytest.mark.parametrize("field", ["tasks", "grf"])
def test_a_setup_file_that_names_itself_is_refused_before_any_work(folder, capsys, field):
    # an IK setup whose IKTaskSet file is itself, an ID setup whose external_loads_file is itself: read forever
    # (RecursionError, a traceback) where the trial ran
    tag = {"tasks": ("InverseKinematicsTool", '<IKTaskSet file="self.xml"/>'),
           "grf": ("InverseDynamicsTool", "<external_loads_file>self.xml</external_loads_file>")}[field]
    (folder / "self.xml").write_text(f"<OpenSimDocument><{tag[0]}>{tag[1]}</{tag[0]}></OpenSimDocument>\n")
    path = write(folder)
    old = 'tasks = "hamner_tasks_ik.xml"' if field == "tasks" else 'grf = "hamner_running_whole_grf.mot"'
    path.write_text(path.read_text().replace(old, old.split("=")[0] + '= "self.xml"', 1))
    said = "options.tasks" if field == "tasks" else "subjects[0].trials[0].grf"
    pattern = said.replace("[", r"\[").replace("]", r"\]") + ": .*self.xml.* names .self.xml., a file already on"
    with pytest.raises(StudyError, match=pattern):
        load_study(str(path))
    assert main(["study", str(path), "--out", str(folder / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and said in err[0], err
    assert not (folder / "out").exists()


def _refusing_port():
    """A socket bound to a local port and not listening: a connection to it is refused (kept open: the port stays
    this test's)."""
    import socket

    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    return sock


@pytest.mark.parametrize("options, said", [
    (["--workers", "{many}"], "--workers: {many} is more local workers than this machine runs at once (at most"),
    (["--scheduler", "tcp://127.0.0.1:{port}"], "--scheduler: nothing answers at 'tcp://127.0.0.1:{port}'"),
    (["--record", "no/such/dir"], "--record: directory 'no/such' does not exist (casflex does not create it)"),
    (["--record", "study.toml"], "--record: 'study.toml' is an input of the command (the study)"),
    (["--record", "out"], "--record: 'out' is also the --out folder"),
], ids=["workers", "scheduler", "record-parent", "record-input", "record-out"])
def test_the_cluster_and_record_options_are_refused_in_one_line_before_anything_is_made(folder, capsys, monkeypatch,
                                                                                       options, said):
    # --workers 10000 started no worker and printed 700k lines; --scheduler with nothing there left an empty record
    # folder after dask's 30 s; --record no/such/dir made the folders; an input or --out as --record: no word
    import os

    monkeypatch.chdir(folder)
    sock = _refusing_port()
    fill = {"many": str((os.cpu_count() or 1) + 1), "port": str(sock.getsockname()[1])}  # beyond a core a worker
    write(folder)
    before = sorted(p.name for p in folder.iterdir())
    try:
        code = main(["study", "study.toml", "--out", "out", "--quiet", *[o.format(**fill) for o in options]])
    finally:
        sock.close()
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and said.format(**fill) in err[0], err
    assert sorted(p.name for p in folder.iterdir()) == before  # no out, no record, no no/


def test_a_record_is_taken_only_under_its_own_name_and_a_broken_one_is_redone(folder, capsys):
    # another trial's record copied by hand under a trial's name was reused (its loads in that trial's rows, exit 0);
    # a record holding [] gave a traceback and one holding {} "casflex: error: loads". Each is now redone, and said.
    path = write(folder)
    record = folder / "record"
    assert main(["study", str(path), "--out", str(folder / "first"), "--record", str(record), "--quiet"]) == 0
    first = (folder / "first" / "loads.csv").read_text()
    rec = {p.name.rsplit("-", 1)[0]: p for p in record.glob("*.json")}
    rec["trial-s02-run"].write_bytes(rec["trial-s02-run_late"].read_bytes())
    rec["trial-s02_again-run"].write_text("[]")
    rec["calibrate-s02_again"].write_text("{}")
    capsys.readouterr()
    assert main(["study", str(path), "--out", str(folder / "again"), "--record", str(record), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert f"{rec['trial-s02-run']} is the record of 'trial-s02-run_late-" in err, err
    assert f"{rec['trial-s02_again-run']} holds a JSON list, not a run's record" in err, err
    assert f"{rec['calibrate-s02_again']} does not name its run" in err, err
    assert (folder / "again" / "loads.csv").read_text() == first  # each run done again: the same table


def _table(path: Path) -> list[dict]:
    with path.open() as f:
        return list(csv.DictReader(f))


def test_a_study_runs_resumes_and_reports_a_failed_trial(folder, capsys):
    # a third subject whose trial's markers file is the plates' (no marker the model has): it fails, reported,
    # while the others run; the run again from the records redoes nothing and writes the same table
    broken = '\n[[subjects]]\nname = "broken"\nmodel = "hamner_subject02_planar.osim"\n\n[[subjects.trials]]\n' \
             'name = "run"\nmarkers = "bad.trc"\ngrf = "hamner_running_whole_grf.mot"\n'
    (folder / "bad.trc").write_text((folder / "hamner_running_whole.trc").read_text().replace("R.ASIS", "Q.ASIS")
                                    .replace("L.ASIS", "Q2.ASIS").replace("V.Sacral", "Q3"))
    path = write(folder, broken)
    out = folder / "out"
    assert main(["study", str(path), "--out", str(out), "--quiet"]) == 1
    printed = capsys.readouterr().out
    assert "1 failed" in printed and "broken run" in printed
    rows = _table(out / "loads.csv")
    assert {r["subject"] for r in rows} == {"s02", "s02_again"}
    assert {r["trial"] for r in rows if r["subject"] == "s02"} == {"run", "run_late"}
    assert "hip_flexion_r_moment" in {r["load"] for r in rows}
    assert all(0.0 <= float(r["percent"]) <= 100.0 for r in rows)
    # each cycle flagged, with its span: Hamner's right cycle (0.390-1.101 s) stands wholly on its plate
    right = {(r["clean"], r["t0"][:5], r["t1"][:5]) for r in rows if r["load"] == "ankle_angle_r_moment"}
    assert right == {("true", "0.389", "1.101")}, right
    assert (out / "group.png").is_file() and (out / "s02.png").is_file()
    summary = (out / "summary.txt").read_text()
    assert "broken run:" in summary
    # plates assigned from the data: the right foot's plate to calcn_r
    assert "'calcn_r'" in summary and "'calcn_l'" in summary
    first = (out / "loads.csv").read_text()
    records = sorted(p.name for p in (out / "record").glob("*.json"))
    assert main(["study", str(path), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "sweep:" not in err  # nothing run again: every record reused (the sweep reports each run it does)
    assert (out / "loads.csv").read_text() == first
    assert sorted(p.name for p in (out / "record").glob("*.json")) == records
    # --retry-failed runs the failed trial again, and it alone
    assert main(["study", str(path), "--out", str(out), "--retry-failed"]) == 1
    err = capsys.readouterr().err
    assert err.count("sweep:") == 1 and "(last: trial-broken-run-" in err


def test_plane_auto_finds_the_plane_opensim_s_lab_sets(folder):
    # Hamner's lab: X forward, Y up (OpenSim's); "auto" with Y vertical finds X,Y from the subject's travel or
    # facing, the same table as the plane given
    path = folder / "auto.toml"
    one = 'name = "auto"\n[options]\nplane = "{plane}"\nvertical = "Y"\ntasks = "hamner_tasks_ik.xml"\n' \
          '[[subjects]]\nname = "s02"\nmodel = "hamner_subject02_planar.osim"\n[[subjects.trials]]\nname = "run"\n' \
          'markers = "hamner_running_whole.trc"\ngrf = "hamner_running_whole_grf.mot"\n'
    tables = {}
    for plane in ("auto", "X,Y"):
        path.write_text(one.replace("{plane}", plane))
        assert main(["study", str(path), "--out", str(folder / plane.replace(",", "")), "--quiet"]) == 0
        tables[plane] = (folder / plane.replace(",", "") / "loads.csv").read_text()
        record, = (folder / plane.replace(",", "") / "record").glob("trial-s02-run-*.json")
        record = record.read_text()
        assert '"plane": "X,Y"' in record
    assert tables["auto"] == tables["X,Y"]


def test_normalise_mass_gives_the_table_per_kg_from_the_same_records(folder):
    # the records hold N m; normalise = "mass" divides at the table (a rerun from the same records computes nothing)
    one = 'name = "kg"\n[options]\nplane = "X,Y"\ntasks = "hamner_tasks_ik.xml"\n{norm}\n[[subjects]]\n' \
          'name = "s02"\nmass = 80.0\nmodel = "hamner_subject02_planar.osim"\n[[subjects.trials]]\nname = "run"\n' \
          'markers = "hamner_running_whole.trc"\ngrf = "hamner_running_whole_grf.mot"\n'
    path, record = folder / "kg.toml", folder / "record"
    tables = {}
    for norm in ("", 'normalise = "mass"'):
        path.write_text(one.replace("{norm}", norm))
        assert main(["study", str(path), "--out", str(folder / f"out{len(norm)}"), "--record", str(record),
                     "--quiet"]) == 0
        tables[norm] = _table(folder / f"out{len(norm)}" / "loads.csv")
    plain, kg = tables[""], tables['normalise = "mass"']
    assert len(plain) == len(kg) > 0
    assert {r["unit"] for r in plain if r["load"].endswith("_moment")} == {"N m"}
    assert {r["unit"] for r in kg if r["load"].endswith("_moment")} == {"N m/kg"}
    worst = max(abs(float(a["value"]) / 80.0 - float(b["value"])) for a, b in zip(plain, kg, strict=True))
    assert worst <= 1e-12 * max(abs(float(a["value"])) for a in plain)  # one division: to the last digits


def _stamps(out: Path) -> dict[str, int]:
    return {p.name: p.stat().st_mtime_ns for p in out.iterdir() if p.is_file()}


def test_a_changed_option_redoes_the_runs_it_changes_and_only_those(folder, capsys, monkeypatch):
    # records are keyed by their inputs' fingerprint: a new window redoes that trial (a failed one too), the
    # others and the calibration are reused. One local cluster per command (calibrations, trials, figures: two
    # before, 0.8-0.9 s each), none where nothing is to run; the same command again on up-to-date outputs runs
    # nothing and writes nothing (3.5 s before: imports, table, figures); a figure whose data did not change is
    # not drawn again
    from casflex.cli import study as command
    from casflex.study import sweep

    clusters = []
    monkeypatch.setattr(sweep, "_local_cluster", lambda n, started, f=sweep._local_cluster: clusters.append(n) or
                        f(n, started))
    monkeypatch.setattr(command, "FIGURES_ON_CLUSTER", 1)  # the figures drawn on the workers (a study's 4 and more)
    path = write(folder)
    out, record = folder / "out", folder / "record"
    assert main(["study", str(path), "--out", str(out), "--record", str(record)]) == 0
    assert len(clusters) == 1
    first, stamps = {p.name for p in record.glob("*.json")}, _stamps(out)
    capsys.readouterr()
    assert main(["study", str(path), "--out", str(out), "--record", str(record)]) == 0
    said = capsys.readouterr()
    assert f"up to date: the outputs in {out} are those of these inputs and records" in said.out, said.out
    assert "sweep:" not in said.err and _stamps(out) == stamps and len(clusters) == 1
    path.write_text(path.read_text().replace("window = [0.25, 1.15]", "window = [0.3, 1.15]"))
    assert main(["study", str(path), "--out", str(out), "--record", str(record)]) == 0
    said = capsys.readouterr()
    assert "up to date" not in said.out and len(clusters) == 2
    new = {p.name for p in record.glob("*.json")} - first
    assert len(new) == 1 and next(iter(new)).startswith("trial-s02-run_late-"), new
    assert said.err.count("sweep:") == 1 and "(last: trial-s02-run_late-" in said.err  # one run: one progress line
    again = _stamps(out)
    assert again["s02_again.png"] == stamps["s02_again.png"]  # its trial unchanged: not drawn again
    assert again["s02.png"] != stamps["s02.png"] and again["loads.csv"] != stamps["loads.csv"]
    (out / "s02_again.png").unlink()  # an output gone: not up to date; nothing to run, the figure drawn again
    assert main(["study", str(path), "--out", str(out), "--record", str(record)]) == 0
    said = capsys.readouterr()
    assert "up to date" not in said.out and "sweep:" not in said.err and (out / "s02_again.png").is_file()
    last = _stamps(out)
    assert [last[f] == again[f] for f in ("s02.png", "group.png", "loads.csv")] == [True, True, False]


def test_the_table_is_made_from_each_subject_s_lines_as_its_trials_finish_the_same_bytes(folder, monkeypatch):
    # a subject's lines of loads.csv are made as soon as its trials are recorded (while the others run), not all
    # after the last record: the same table, bit for bit, as the one a resumed study (nothing run) makes after
    import casflex.cli.study as command

    made = []
    table = command._loads_csv
    monkeypatch.setattr(command, "_loads_csv", lambda out, kg: made.append(table(out, kg)[1]) or table(out, kg))
    path = write(folder)
    record = folder / "record"
    assert main(["study", str(path), "--out", str(folder / "first"), "--record", str(record), "--quiet"]) == 0
    assert made == []  # every subject's lines made as its trials finished
    assert main(["study", str(path), "--out", str(folder / "again"), "--record", str(record), "--quiet"]) == 0
    assert len(made) == 1 and made[0] > 0  # nothing run: the table made after, from the records
    assert (folder / "again" / "loads.csv").read_bytes() == (folder / "first" / "loads.csv").read_bytes()


def test_the_table_quotes_a_name_only_where_csv_must():
    # loads.csv is written by the csv module where a name holds a comma, a quote or a line break (elsewhere formatted
    # directly, twice as fast, to the same text: the test below); a plain name unquoted
    from casflex.cli.study import _table

    row = ("s02", "run", "knee_angle_r_moment", "calcn_r", 1, 0.0, 0.1 + 0.2, None, "N m", True, 0.39, 1.1)
    plain = _table([row])
    assert plain.splitlines()[1] == "s02,run,knee_angle_r_moment,calcn_r,1,0,0.30000000000000004,,N m,true,0.39,1.1"
    odd = _table([("s,02", *row[1:7], 2.5, *row[8:])])
    assert odd.splitlines()[1] == '"s,02",run,knee_angle_r_moment,calcn_r,1,0,0.30000000000000004,2.5,N m,true,0.39,1.1'


def test_a_subject_s_lines_made_from_its_records_are_the_rows_lines():
    # a subject's lines of loads.csv are made from its records' cycles directly (a cycle's names and times
    # formatted once, its values by repr): the text of its rows, with and without bands, a foot or its clean flags
    # (made-up values of every magnitude, and a nan); a name that CSV quotes leaves them to the csv module
    from casflex.cli.study import _HEAD, _loads_text, _table
    from casflex.study.records import CycleLoad, TrialRecord
    from casflex.study.runner import tidy_rows

    rng = np.random.default_rng(5)

    def cycles(n):
        return tuple(tuple(float(v) for v in rng.normal(0.0, 10.0 ** rng.integers(-9, 9), 101)) for _ in range(n))

    value = cycles(2)
    value = (value[0][:7] + (float("nan"),) + value[0][8:], value[1])
    loads = {"knee_angle_r_moment": CycleLoad("calcn_r", ((0.1, 0.8), (0.8, 1.5000000000000002)), (True, False),
                                              value, cycles(2)),
             "pelvis_tx_force": CycleLoad(None, ((0.3, 1.1),), (), cycles(1)),
             "ankle_angle_l_moment": CycleLoad("calcn_l", (), (), ())}
    rec = TrialRecord(None, "X,Y", (), (), loads, (0.0, 2.0))
    out = {"trials": {("s02", "run"): rec, ("s03", "run 2"): rec}}
    for per_kg in (False, True):
        text = _loads_text(out, per_kg)
        assert ",".join(_HEAD) + "\n" + text == _table(tidy_rows(out, per_kg=per_kg))  # the csv module's text
        assert text.count("\n") == 2 * 3 * 101
    assert _loads_text({"trials": {("s,02", "run"): rec}}) is None


def test_a_changed_data_file_at_the_same_path_is_run_again(folder, capsys):
    # the fingerprint holds the files' contents, not only their paths: a trial re-exported in place is redone
    path = write(folder)
    out, record = folder / "out", folder / "record"
    assert main(["study", str(path), "--out", str(out), "--record", str(record), "--quiet"]) == 0
    first = {p.name for p in record.glob("*.json")}
    trc = folder / "hamner_running_whole.trc"
    trc.write_text(trc.read_text().replace("\t", " \t", 1))  # the same numbers, other bytes
    assert main(["study", str(path), "--out", str(out), "--record", str(record), "--quiet"]) == 0
    new = sorted(p.name.rsplit("-", 1)[0] for p in record.glob("*.json") if p.name not in first)
    assert new == ["trial-s02-run", "trial-s02-run_late", "trial-s02_again-run"], new  # every trial reads it


@pytest.mark.parametrize("static", [True, False])
def test_a_subject_s_mass_is_applied_with_or_without_a_static_trial_or_scaling(static):
    # mass with scale = false (the default) refused the calibration before; now the masses are scaled to it, the
    # segments as they are
    from casflex.scene import loads_scene
    from casflex.study.runner import calibrate_run

    out = calibrate_run(model="hamner_leg", static=str(LAB / "hamner_static_excerpt.trc") if static else None,
                        plane="X,Y", root="pelvis", calibrate=True, scale=False, mass=50.0)
    assert abs(sum(b.mass for b in loads_scene(out["scene"]).bodies) - 50.0) < 1e-9
    assert "scaled from" in out["report"][-1]


def test_passive_fits_per_trial_and_per_swing_phase(folder):
    # the right knee over the trial and over the right foot's swing (its plate's off to its next strike)
    one = 'name = "passive"\n[options]\nplane = "X,Y"\ntasks = "hamner_tasks_ik.xml"\n' \
          'passive = ["knee_r", "knee_r:swing"]\n[[subjects]]\nname = "s02"\n' \
          'model = "hamner_subject02_planar.osim"\n[[subjects.trials]]\nname = "run"\n' \
          'markers = "hamner_running_whole.trc"\ngrf = "hamner_running_whole_grf.mot"\n'
    path = folder / "passive.toml"
    path.write_text(one)
    assert main(["study", str(path), "--out", str(folder / "out"), "--quiet"]) == 0
    rows = _table(folder / "out" / "passive.csv")
    assert [(r["hinge"], r["phase"]) for r in rows] == [("knee_r", "trial"), ("knee_r", "swing")]
    trial, swing = rows
    assert float(trial["t0"]) == pytest.approx(0.2) and float(trial["t1"]) == pytest.approx(1.2)
    # the right stance's plate off (0.65-0.667 s, tests/data/lab/README.md) to the next strike (1.10 s)
    assert 0.64 <= float(swing["t0"]) <= 0.68 and 1.08 <= float(swing["t1"]) <= 1.12
    assert all(r["passive"] in ("yes", "no") and float(r["kt_se"]) > 0 for r in rows)


def _zeroed_grf(folder: Path, name: str, prefix: str, before: float = float("inf")) -> str:
    """A copy of the trial's plates with the plate ``prefix``'s columns 0 at the times before ``before`` s: a foot
    that never touches a plate (``1_ground_``: the left), or whose first stance is off the plates (``ground_``
    before 0.8 s: the right's 0.39-0.665 s stance)."""
    lines = (LAB / "hamner_running_whole_grf.mot").read_text().splitlines()
    head = lines.index("endheader") + 1
    names = lines[head].split("\t")
    cols = [k for k, n in enumerate(names) if n.startswith(prefix) and (prefix != "ground_" or n[0] == "g")]
    for i in range(head + 1, len(lines)):
        row = lines[i].split("\t")
        if float(row[0]) < before:
            for k in cols:
                row[k] = "0"
        lines[i] = "\t".join(row)
    (folder / name).write_text("\n".join(lines) + "\n")
    return str(folder / name)


def _trial_run(folder: Path, grf: str) -> dict:
    from casflex import load_scene
    from casflex.scene import dumps_scene
    from casflex.study.runner import trial_run
    from casflex.study.study_file import Trial, TrialOptions

    options = TrialOptions(tasks=str(LAB / "hamner_tasks_ik.xml"))
    trial = Trial("run", str(LAB / "hamner_running_whole.trc"), grf)
    return trial_run(scene=dumps_scene(load_scene(str(LAB / "hamner_subject02_planar.osim"))), trial=trial,
                     options=options, uncertain=())


def test_a_foot_that_touches_no_plate_gets_no_kinetic_cycles(tmp_path):
    # the left plate zeroed: the left leg's loads took the right foot's cycle (and its name, calcn_r) before
    rec = _trial_run(tmp_path, _zeroed_grf(tmp_path, "left_never.mot", "1_ground_"))
    assert rec["plates"] == {"calcn_r": "ground_"}
    for side, cycles in (("l", 0), ("r", 1)):
        for joint in ("hip_flexion", "knee_angle", "ankle_angle"):
            ld = rec["loads"][f"{joint}_{side}_moment"]
            assert ld["foot"] == f"calcn_{side}" and len(ld["cycles"]) == len(ld["value"]) == cycles
    note, = [w for w in rec["warnings"] if "touches no plate" in w]
    assert note.startswith("calcn_l touches no plate: no kinetic cycle for hip_flexion_l_moment")
    assert rec["loads"]["lumbar_extension_moment"]["foot"] == "calcn_r"  # the trunk: the first foot's cycles


def test_a_cycle_off_the_plates_is_flagged_and_left_out_of_the_means(tmp_path):
    # the right foot's first stance (0.39-0.665 s) zeroed: its cycle comes from the heel marker's strikes, with no
    # ground reaction under the stance; averaged with the clean cycle of the same trial it halved the ankle's peak
    from casflex.cli.study import cycle_curves

    clean = _trial_run(tmp_path, str(LAB / "hamner_running_whole_grf.mot"))
    off = _trial_run(tmp_path, _zeroed_grf(tmp_path, "right_off.mot", "ground_", before=0.8))
    assert clean["loads"]["ankle_angle_r_moment"]["clean"] == [True]
    ld = off["loads"]["ankle_angle_r_moment"]
    assert len(ld["cycles"]) == 1 and ld["clean"] == [False]
    assert any("not clean: no strike on a plate" in w and "off every plate" in w for w in off["warnings"])
    from casflex.study.records import TrialRecord

    out = {"trials": {("s02", "run"): TrialRecord.from_json(clean), ("s02", "right_off"): TrialRecord.from_json(off)}}
    peak = {k: float(cycle_curves(out, all_cycles=k)["ankle_angle_r_moment"]["s02"].mean(axis=0).min())
            for k in (False, True)}
    alone = float(np.min(clean["loads"]["ankle_angle_r_moment"]["value"][0]))
    assert peak[False] == alone  # the clean cycle alone: the same numbers
    assert peak[True] > 0.75 * alone  # with the cycle off the plates: some half the peak (the bug's answer)


def test_a_plate_both_feet_step_on_in_turn_gives_each_foot_its_contacts(tmp_path):
    # the two plates written as one both feet step on in turn: refused before ("one node per plate"); each contact
    # applied to its foot now, the record's loads and cycles those of the two plates
    from casflex.lab import read_sto
    from casflex.lab.tables import write_sto

    grf = read_sto(LAB / "hamner_running_whole_grf.mot")
    right = grf.column("ground_force_vy") > 0
    kinds = [n[len("ground_"):] for n in grf.names if n.startswith("ground_")]
    one = {f"ground_{k}": np.where(right, grf.column(f"ground_{k}"), grf.column(f"1_ground_{k}")) for k in kinds}
    path = write_sto(tmp_path / "one.mot", grf.t, one, title="one", units=dict.fromkeys(one, "-"))
    two, merged = _trial_run(tmp_path, str(LAB / "hamner_running_whole_grf.mot")), _trial_run(tmp_path, str(path))
    assert two["plates"] == {"calcn_r": "ground_", "calcn_l": "1_ground_"}
    assert merged["plates"] == {"calcn_l": "ground_", "calcn_r": "ground_"}
    assert merged["loads"].keys() == two["loads"].keys()
    for name, ld in two["loads"].items():
        got = merged["loads"][name]
        assert (got["foot"], got["cycles"], got["clean"]) == (ld["foot"], ld["cycles"], ld["clean"]), name
        assert np.allclose(got["value"], ld["value"], rtol=0, atol=1e-6), name  # round-off of the shares' sums
    assert two["loads"]["ankle_angle_r_moment"]["clean"] == [True]


def test_a_marker_the_trial_lacks_is_left_out_with_a_warning(tmp_path):
    # before: the trial failed ("no marker labelled 'R.Toe.Lat'"); OpenSim's IK leaves such a marker out
    from casflex import load_scene
    from casflex.scene import dumps_scene
    from casflex.study.runner import trial_run
    from casflex.study.study_file import Trial, TrialOptions

    trc = tmp_path / "run.trc"
    trc.write_text((LAB / "hamner_running_whole.trc").read_text().replace("R.Toe.Lat", "R.Toe.Lost"))
    rec = trial_run(scene=dumps_scene(load_scene(str(LAB / "hamner_subject02_planar.osim"))),
                    trial=Trial("run", str(trc), str(LAB / "hamner_running_whole_grf.mot")),
                    options=TrialOptions(tasks=str(LAB / "hamner_tasks_ik.xml")), uncertain=())
    assert f"{trc}: the scene's markers ['R.Toe.Lat'] are not in the trial: left out of the fit (as OpenSim's IK " \
           "leaves out a marker the trial lacks)" in rec["warnings"]
    assert rec["loads"]["ankle_angle_r_moment"]["clean"] == [True]


def test_calibration_s_warnings_are_in_the_summary(folder, monkeypatch, capsys):
    # issue 48: a marker the static trial puts 10 cm from the model's was said in the record only (as a median)
    import casflex.study.runner as runner
    from casflex.study.records import Calibration

    lines = (LAB / "hamner_static_excerpt.trc").read_text().splitlines()
    k = lines[3].split("\t").index("R.Toe.Tip")  # its X column (each label over its X, Y, Z)
    for i in range(6, len(lines)):
        row = lines[i].split("\t")
        row[k] = f"{float(row[k]) + 120.0:.6f}"  # mm, along the foot
        lines[i] = "\t".join(row)
    (folder / "static.trc").write_text("\n".join(lines) + "\n")
    rec = runner.calibrate_run(model="hamner_leg", static=str(folder / "static.trc"), plane="X,Y", root="pelvis",
                               calibrate=True, scale=False, mass=None)
    said = [r for r in rec["report"] if r.startswith("warning: markers moved more than 50 mm")]
    assert len(said) == 1 and "(R.Toe.Tip)" in said[0]
    monkeypatch.setattr(runner, "run_study", lambda *a, **k: {
        "subjects": {"s02": Calibration.from_json(rec)}, "trials": {}, "failed": [], "interrupted": False,
        "records": {}})
    main(["study", str(write(folder)), "--out", str(folder / "out")])
    assert f"  s02: {said[0]}" in (folder / "out" / "summary.txt").read_text().splitlines()
    assert f"casflex: warning: subject s02: {said[0].removeprefix('warning: ')}" in capsys.readouterr().err


def test_a_subject_model_s_constraint_the_scene_leaves_out_is_in_the_subject_s_report(tmp_path):
    # before: the study read an .osim through load_scene, and an ignored constraint went without a word
    from casflex.study.runner import calibrate_run

    text = (LAB / "hamner_subject02_leg.osim").read_text()
    weld = ('<ConstraintSet><objects><WeldConstraint name="w"><socket_frame1>/bodyset/calcn_r</socket_frame1>'
            "<socket_frame2>/bodyset/toes_r</socket_frame2></WeldConstraint></objects></ConstraintSet>")
    model = tmp_path / "leg.osim"
    model.write_text(text.replace("\t\t<MarkerSet", weld + "\n\t\t<MarkerSet", 1))
    out = calibrate_run(model=str(model), static=None, plane="X,Y", root="pelvis", calibrate=False, scale=False,
                        mass=None)
    assert out["report"] == [f"warning: {model}: constraint WeldConstraint 'w' ignored: the planar scene holds "
                             "'calcn_r' and 'toes_r' fixed relative to each other already"]


def test_a_c3d_trial_s_plate_prefix_is_checked_before_any_work(tmp_path, capsys):
    # a C3D's plates are in its parameter section, read before any work as a .mot's columns are (it failed the trial
    # at run time)
    for f in ("walking2_excerpt.c3d", "hamner_subject02_planar.osim"):
        shutil.copy(LAB / f, tmp_path / f)
    path = tmp_path / "study.toml"
    path.write_text('name = "c3d"\n[options]\nplane = "X,Y"\n\n[[subjects]]\nname = "s"\n'
                    'model = "hamner_subject02_planar.osim"\n\n[[subjects.trials]]\nname = "walk"\n'
                    'markers = "walking2_excerpt.c3d"\ngrf = "walking2_excerpt.c3d"\n'
                    'plates = { calcn_r = "2_ground_" }\n')
    with pytest.raises(StudyError, match=r"subjects\[0\]\.trials\[0\]\.plates\.calcn_r: walking2_excerpt.c3d: no "
                                         r"plate '2_ground_'.*the plates there are \['1_ground_', 'ground_'\]"):
        load_study(str(path))


def _c3d_with_mass(folder: Path, name: str, mass: float | None) -> Path:
    """walking2_excerpt.c3d (tests/data/lab) with the subject's mass as Vicon's Nexus writes it
    (PROCESSING:Bodymass), or as it is (None)."""
    import ezc3d

    c = ezc3d.c3d(str(LAB / "walking2_excerpt.c3d"))
    if mass is not None:
        c.add_parameter("PROCESSING", "Bodymass", [mass])
    c.write(str(folder / name))
    return folder / name


C3D_STUDY = """name = "mass from the C3D"
[options]
plane = "X,Y"
normalise = "mass"
[[subjects]]
name = "s"
model = "hamner_subject02_planar.osim"
{subject}
[[subjects.trials]]
name = "walk"
markers = "walk.c3d"
"""


def test_a_subject_s_mass_is_read_from_its_c3d_where_the_study_file_gives_none(tmp_path):
    # normalise = "mass" without a mass refused the study; the lab's C3D holds it (Nexus: PROCESSING:Bodymass)
    shutil.copy(LAB / "hamner_subject02_planar.osim", tmp_path)
    _c3d_with_mass(tmp_path, "walk.c3d", 61.5)
    path = tmp_path / "study.toml"
    path.write_text(C3D_STUDY.replace("{subject}", ""))
    s = load_study(str(path)).subjects[0]
    assert (s.mass, s.mass_from) == (61.5, "walk.c3d (PROCESSING:BODYMASS)")
    path.write_text(C3D_STUDY.replace("{subject}", "mass = 70.0"))  # the study file's own wins, and says so
    assert (load_study(str(path)).subjects[0].mass, load_study(str(path)).subjects[0].mass_from) == (70.0, None)
    _c3d_with_mass(tmp_path, "static.c3d", 66.0)  # two files of one subject that disagree: refused, both named
    path.write_text(C3D_STUDY.replace("{subject}", 'static = "static.c3d"'))
    with pytest.raises(StudyError, match=r"subjects\[0\]\.mass: not given, and the subject's C3D files disagree: "
                                         r"66 kg in static.c3d \(PROCESSING:BODYMASS\), 61.5 kg in walk.c3d"):
        load_study(str(path))
    _c3d_with_mass(tmp_path, "walk.c3d", None)  # none anywhere: the refusal says where it looked
    path.write_text(C3D_STUDY.replace("{subject}", ""))
    with pytest.raises(StudyError, match=r"subjects\[0\]\.mass: needed by options.normalise = \"mass\" \(kg\), and "
                                         "none of the subject's C3D files holds it"):
        load_study(str(path))


def test_the_calibration_says_where_the_mass_came_from():
    from casflex.study.runner import calibrate_run

    out = calibrate_run(model="hamner_leg", static=None, plane="X,Y", root="pelvis", calibrate=True, scale=False,
                        mass=61.5, mass_from="walk.c3d (PROCESSING:BODYMASS)")
    assert "the subject's mass 61.5 kg read from walk.c3d (PROCESSING:BODYMASS)" in out["report"][0]


def test_a_static_trial_s_window_averages_only_its_frames(tmp_path):
    from casflex.study.runner import calibrate_run

    static = str(LAB / "hamner_static_excerpt.trc")  # 30 frames at 60 Hz from t = 0
    kw = dict(model="hamner_leg", static=static, plane="X,Y", root="pelvis", calibrate=True, scale=False, mass=None)
    assert "30 frames averaged" in "\n".join(calibrate_run(**kw)["report"])
    assert "11 frames averaged" in "\n".join(calibrate_run(**kw, static_window=(0.1, 0.27))["report"])
    shutil.copy(LAB / "hamner_subject02_planar.osim", tmp_path)
    shutil.copy(LAB / "hamner_static_excerpt.trc", tmp_path)
    _c3d_with_mass(tmp_path, "walk.c3d", 61.5)
    path = tmp_path / "study.toml"
    for window, said in (("[0.1, 0.27]", None), ("[0.27, 0.1]", r"subjects\[0\]\.static_window: expected \[start, "),
                         ("[0.1, 9.0]", r"subjects\[0\]\.static_window: 0.1..9 s is not within the static trial's "
                                        r"times 0..0.483")):
        path.write_text(C3D_STUDY.replace("{subject}", f'static = "hamner_static_excerpt.trc"\n'
                                                       f"static_window = {window}"))
        if said is None:
            assert load_study(str(path)).subjects[0].static_window == (0.1, 0.27)
        else:
            with pytest.raises(StudyError, match=said):
                load_study(str(path))


def test_a_subject_s_own_task_file_weighs_its_trials(folder):
    from casflex.study.runner import _plan

    (folder / "other_tasks.xml").write_text((folder / "hamner_tasks_ik.xml").read_text())
    path = write(folder)
    path.write_text(path.read_text().replace('mass = 80.0', 'mass = 80.0\ntasks = "other_tasks.xml"'))
    study = load_study(str(path))
    assert study.subjects[1].tasks == str(folder / "other_tasks.xml")
    plan = _plan(study, {"s02": SimpleNamespace(scene=""), "s02_again": SimpleNamespace(scene="")})
    assert plan[("s02", "run")].kwargs["options"].tasks == str(folder / "hamner_tasks_ik.xml")
    assert plan[("s02_again", "run")].kwargs["options"].tasks == str(folder / "other_tasks.xml")
    path.write_text(path.read_text().replace('tasks = "other_tasks.xml"', 'tasks = "none.xml"'))
    with pytest.raises(StudyError, match=r"subjects\[1\]\.tasks: none.xml: no such file"):
        load_study(str(path))


def test_a_c3d_study_on_a_built_in_marker_set_model_says_where_its_mass_came_from(tmp_path, capsys):
    # walking2.c3d's excerpt (a CAST-type set with its joint centres) on the built-in cast model, no mass in the
    # study file: the C3D's PROCESSING:Bodymass, said in summary.txt
    _c3d_with_mass(tmp_path, "walk.c3d", 61.5)
    path = tmp_path / "study.toml"
    path.write_text('name = "cast"\n[options]\nplane = "X,Z"\nvertical = "Z"\nnormalise = "mass"\n'
                    '[[subjects]]\nname = "s"\nmodel = "cast"\nstatic = "walk.c3d"\nstatic_window = [2.56, 2.58]\n'
                    '[[subjects.trials]]\nname = "walk"\nmarkers = "walk.c3d"\n')
    code = main(["study", str(path), "--out", str(tmp_path / "out"), "--workers", "1", "--quiet"])
    summary = (tmp_path / "out" / "summary.txt").read_text()
    assert code == 0, summary
    assert "  s: mass 61.5 kg read from walk.c3d (PROCESSING:BODYMASS)" in summary.splitlines()
    assert "1 of 1 trial(s) done" in summary


def test_a_trial_with_marked_events_and_no_window_is_cut_to_their_span():
    """A C3D walk's frames beyond its marked gait events (walking in and out of the volume, often half tracked)
    carry no cycle: without a study file's window the trial is cut to the events' span +- 0.1 s within the trial,
    and the report says so; a window given, or no events, keeps what it was (before: the whole trial, where a
    lab's half-tracked ends were refused)."""
    import dataclasses

    from casflex.lab import read_c3d
    from casflex.study.runner import EVENTS_MARGIN, _window
    from casflex.study.study_file import Trial

    lab = read_c3d(str(LAB / "walking2_excerpt.c3d"), plates=False)[0]
    trial = Trial("walk", "walk.c3d")
    assert _window(trial, lab) == (None, None, [])  # no events: the whole trial
    marked = dataclasses.replace(lab, events=(("Right", "Foot Strike", 2.7), ("Left", "Foot Off", 2.95),
                                              ("Right", "Foot Strike", 3.35)))
    t0, t1, report = _window(trial, marked)
    assert (t0, t1) == (pytest.approx(2.7 - EVENTS_MARGIN), pytest.approx(lab.t[-1]))  # clipped to the trial
    assert report[0].startswith("window: 2.600-3.396 s, the marked gait events' span +- 0.1 s")
    assert _window(dataclasses.replace(trial, window=(2.6, 3.0)), marked) == (2.6, 3.0, [])


def test_a_subject_s_figure_is_drawn_while_the_other_subjects_trials_run(folder, monkeypatch):
    # the 11 figures of a 200-trial study were drawn after its last record (34 s of 127 on one worker): each
    # subject's is drawn here as soon as its trials are recorded, the same PNG as drawn from the whole study's plan
    from casflex.cli import study as command
    from casflex.study import runner

    calls, returned = [], []
    run_study, draw_figure = runner.run_study, command.draw_figure

    def run(*args, **kwargs):
        out = run_study(*args, **kwargs)
        returned.append(True)
        return out

    monkeypatch.setattr(command, "draw_figure", lambda plan: calls.append((plan["title"], bool(returned))) or
                        draw_figure(plan))
    monkeypatch.setattr(runner, "run_study", run)
    out = folder / "out"
    assert main(["study", str(write(folder)), "--out", str(out), "--quiet"]) == 0
    # each figure drawn once, the subjects' before the runs ended, the group's after
    assert sorted(calls) == [("hamner running: s02", False), ("hamner running: s02_again", False),
                             ("hamner running: the subjects' means", True)], calls
    study = load_study(str(folder / "study.toml"))
    whole = run_study(study, out / "record", progress=False)  # every record reused: the whole study's plans
    plans, _ = command._figure_plans(runner.per_kg(whole, study), study.name)
    again = folder / "again"
    again.mkdir()
    command._draw_figures(plans, again, {})
    assert all((again / name).read_bytes() == (out / name).read_bytes() for name in plans)


def _shoulder_off(folder: Path, dx_mm: float = 170.0, after: float = 1.0) -> str:
    """The running trial with R.Acromium moved dx_mm forward from ``after`` s: the planar trunk's fit leaves it about
    120 mm off (as Hamner's whole running trial leaves that shoulder marker 102 mm off past 1.7 s)."""
    lines = (LAB / "hamner_running_whole.trc").read_text().splitlines()
    col = 2 + 3 * [n for n in lines[3].split("\t")[2:] if n].index("R.Acromium")  # its X column
    for i in range(5, len(lines)):
        row = lines[i].split("\t")
        if len(row) > col and row[1] and float(row[1]) >= after:
            row[col] = f"{float(row[col]) + dx_mm:.6f}"
            lines[i] = "\t".join(row)
    (folder / "shoulder_off.trc").write_text("\n".join(lines) + "\n")
    return str(folder / "shoulder_off.trc")


def test_the_study_file_s_max_misfit_reaches_each_trial_s_marker_fit(folder):
    """options.max_misfit (m) is the marker fit's limit in each trial's inverse dynamics: a shoulder marker ~120 mm
    off is refused at the default 0.1 m, naming the option, and taken at 0.2 m; a study without it keeps its runs'
    fingerprints (its records are not redone), one with it gets others."""
    from casflex import load_scene
    from casflex.scene import dumps_scene
    from casflex.study.runner import _run, trial_run

    trc = _shoulder_off(folder)
    path = write(folder)
    plain = load_study(str(path))
    path.write_text(path.read_text().replace("cutoff = 6.0", "cutoff = 6.0\nmax_misfit = 0.2"))
    study = load_study(str(path))
    assert plain.options.trials.max_misfit is None and study.options.trials.max_misfit == 0.2
    assert study.options.trials.fit.misfit == 0.2 and plain.options.trials.fit.misfit == 0.1
    scene = dumps_scene(load_scene(str(folder / "hamner_subject02_planar.osim")))
    trial = dataclasses.replace(plain.subjects[0].trials[0], markers=trc)
    with pytest.raises(ValueError, match=r"marker 'R.Acromium' lies 1\d\d mm .*max_misfit 100 mm.*options.max_misfit"):
        trial_run(scene=scene, trial=trial, options=plain.options.trials, uncertain=())
    rec = trial_run(scene=scene, trial=trial, options=study.options.trials, uncertain=())
    assert rec["loads"] and any("R.Acromium" in line for line in rec["report"])
    legacy = dataclasses.asdict(plain.options.trials)  # the options' fingerprint before max_misfit existed
    legacy.pop("max_misfit")
    key = {name: _run("trial", trial_run, {"scene": scene, "trial": trial, "options": o}, ()).key
           for name, o in (("plain", plain.options.trials), ("legacy", legacy), ("given", study.options.trials))}
    assert key["plain"] == key["legacy"] != key["given"]


def test_a_model_is_read_once_per_worker_and_content_for_its_subjects_calibrations(tmp_path, monkeypatch):
    # each calibration read the .osim twice (its scene, then its warnings): 2 x 50 ms a subject of Hamner's model
    import functools

    import casflex.scene.from_osim as from_osim
    from casflex.study import runner

    reads = []
    real = from_osim.scene_from_osim
    monkeypatch.setattr(from_osim, "scene_from_osim", lambda *a, **k: reads.append(a[0]) or real(*a, **k))
    getattr(runner, "_osim", functools.lru_cache()(print)).cache_clear()  # a worker that read none yet
    model = tmp_path / "leg.osim"
    shutil.copy(LAB / "hamner_subject02_leg.osim", model)
    kw = dict(model=str(model), static=None, plane="X,Y", root="pelvis", calibrate=True, scale=False)
    first, second = runner.calibrate_run(**kw, mass=50.0), runner.calibrate_run(**kw, mass=60.0)
    assert len(reads) == 1, reads
    same = [[r for r in rec["report"] if " kg" not in r] for rec in (first, second)]  # the lines of its mass aside
    assert same[0] == same[1] and first["scene"] != second["scene"]  # their own masses
    model.write_text(model.read_text().replace("<OpenSimDocument", "<!-- edited -->\n<OpenSimDocument", 1))
    runner.calibrate_run(**kw, mass=50.0)
    assert len(reads) == 2  # a changed file is read again


def test_the_figures_and_the_output_share_each_trial_s_record_made_once(folder, monkeypatch):
    # the trials' TrialRecords were made from their JSON twice: for each subject's figure, and after the last trial
    # for the output (1.5 ms each: 0.3 s after the last record of a 200-trial study)
    from casflex.study import runner
    from casflex.study.records import TrialRecord
    from casflex.study.sweep import SweepResult

    made, seen = [], {}
    monkeypatch.setattr(TrialRecord, "from_json", classmethod(lambda cls, d: made.append(d) or object()))

    def sweep(runs, record, on_record=None, **_):  # every run done at once, as the sweep reports a finished one
        out = {r.key: {"scene": "s", "report": []} if r.key.startswith("calibrate") else {"t": [0, 1]} for r in runs}
        for key, rec in out.items():
            if on_record is not None:
                on_record(key, rec, True)
        return SweepResult(out, tuple(out), (), False, 0.0)

    monkeypatch.setattr("casflex.study.sweep.run_sweep", sweep)
    monkeypatch.setattr(runner.Calibration, "from_json", classmethod(lambda cls, d: SimpleNamespace(**d)))
    out = runner.run_study(load_study(str(write(folder))), folder / "rec", session=object(),
                           on_subject=lambda subject, got: seen.update(got["trials"]))
    assert len(made) == 3 and seen == out["trials"] and len(out["trials"]) == 3


def test_the_command_imports_no_plotting_before_its_cluster_without_a_normative_band():
    # --normative's check imported casflex.plotting.gait (matplotlib, 0.9 s of CPU) before the cluster's start
    import subprocess
    import sys

    code = ("import sys\nfrom casflex.cli.study import _normative\nassert _normative(None, False) is None\n"
            "print(sorted(m for m in sys.modules if m.startswith(('matplotlib', 'casflex.plotting'))))")
    got = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert got.strip() == "[]", got


def test_a_static_window_between_two_frames_is_one_line_naming_it():
    # within the static trial's times (the study file's check passes) but between its frames at 0.1 and 0.117 s: the
    # calibration failed with "data.t: expected a 1-d array of finite times (s)", naming neither the file nor the field
    from casflex.study.runner import calibrate_run

    static = str(LAB / "hamner_static_excerpt.trc")
    with pytest.raises(ValueError, match=r"hamner_static_excerpt.trc: static_window 0.101..0.11 s holds none of its "
                                         r"frames \(at 60 Hz\)"):
        calibrate_run(model="hamner_leg", static=static, plane="X,Y", root="pelvis", calibrate=True, scale=False,
                      mass=None, static_window=(0.101, 0.11))
    out = calibrate_run(model="hamner_leg", static=static, plane="X,Y", root="pelvis", calibrate=True, scale=False,
                        mass=None, static_window=(0.1, 0.1))  # one frame: averaged alone
    assert "static trial: 1 frames averaged, 13 of 13 markers seen" in out["report"]
