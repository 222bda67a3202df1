"""``casflex study`` (issue 38): a study file read and checked before any work, its subjects calibrated and its
trials run on dask, one tidy table, a failing trial reported while the others go on, a resumed run redoing
nothing. The data: Hamner's subject 02 running (tests/data/lab, 1 s, both plates) on the planar whole-body
model, as two "subjects" (the same model and data twice: the mechanics of a study, not a second subject's answer)."""

from __future__ import annotations

import csv
import shutil
from pathlib import Path

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
    (("mass = 80.0", 'mass = 80.0\nuncertain = ["pelvis.massx=3%"]', 1), "subjects[1].uncertain"),
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


def test_a_changed_option_redoes_the_runs_it_changes_and_only_those(folder, capsys):
    # records are keyed by their inputs' fingerprint: a new window redoes that trial (a failed one too), the
    # others and the calibration are reused
    path = write(folder)
    out, record = folder / "out", folder / "record"
    assert main(["study", str(path), "--out", str(out), "--record", str(record)]) == 0
    first = {p.name for p in record.glob("*.json")}
    capsys.readouterr()
    path.write_text(path.read_text().replace("window = [0.25, 1.15]", "window = [0.3, 1.15]"))
    assert main(["study", str(path), "--out", str(out), "--record", str(record)]) == 0
    err = capsys.readouterr().err
    new = {p.name for p in record.glob("*.json")} - first
    assert len(new) == 1 and next(iter(new)).startswith("trial-s02-run_late-"), new
    assert err.count("sweep:") == 1 and "(last: trial-s02-run_late-" in err  # one run done: one progress line


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
