"""casflex.inverse.given: coordinates given instead of markers (a .mot of joint angles, e.g. OpenSim's IK)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from casflex.inverse import Filter, Trial, inverse_dynamics
from casflex.scene.coordinates import to_lab
from casflex.scene.from_osim import scene_from_osim

DATA = Path(__file__).parent / "data" / "lab"
LEG, TRC = DATA / "hamner_subject02_leg.osim", DATA / "hamner_running_stride.trc"
GRF = DATA / "hamner_running_stride_grf.mot"
PLATES = {"calcn_r": "ground_"}


def _mot(path: Path, t, columns: dict, degrees: bool | None = True) -> Path:
    head = [] if degrees is None else [f"inDegrees={'yes' if degrees else 'no'}"]
    rows = ["\t".join(f"{v:.15g}" for v in row) for row in np.column_stack([t, *columns.values()])]
    path.write_text("\n".join(["Coordinates", *head, "endheader", "\t".join(["time", *columns]), *rows]) + "\n")
    return path


@pytest.fixture(scope="module")
def fitted():
    """The markers' unfiltered fit and its loads: what a table of the same coordinates must give again."""
    return inverse_dynamics(LEG, Trial(TRC, grf=GRF, plates=PLATES), filter=Filter(cutoff=None))


def _table(fitted, tmp_path, degrees=True) -> Path:
    scene = scene_from_osim(LEG).scene
    cols = {}
    for c in scene.coordinates:
        v = to_lab(scene, c, fitted.z[:, fitted.coordinate_names.index(c.scene_coordinate())])
        cols[c.name] = np.degrees(v) if degrees and not c.translational else v
    return _mot(tmp_path / "ik.mot", np.round(fitted.t, 3), cols, degrees)  # times rounded as OpenSim writes them


@pytest.mark.parametrize("degrees", [True, False])
def test_a_table_of_the_fitted_coordinates_gives_the_same_loads(fitted, tmp_path, degrees):
    res = inverse_dynamics(LEG, Trial(coordinates=_table(fitted, tmp_path, degrees), grf=GRF, plates=PLATES),
                           filter=Filter(cutoff=None))
    assert res.report[0].startswith("coordinates given: 6 columns") and res.marker_labels == ()
    assert np.allclose(res.t, fitted.t, rtol=0, atol=1e-12)  # the rounded times put back on their sixtieths
    # the same coordinates (printed to 15 digits) through the same rates and dynamics
    assert np.max(np.abs(res.z - fitted.z)) < 1e-12
    for name in ("hip_flexion_r_moment", "knee_angle_r_moment", "ankle_angle_r_moment", "pelvis_ty_force"):
        assert np.allclose(res.loads[name], fitted.loads[name], rtol=1e-9, atol=1e-8), name


def test_the_tree_s_own_names_serve_a_scene_without_lab_coordinates(fitted, tmp_path):
    import dataclasses

    scene = dataclasses.replace(scene_from_osim(LEG).scene, coordinates=())
    cols = {name: fitted.z[:, k] for k, name in enumerate(fitted.coordinate_names)}
    res = inverse_dynamics(scene, Trial(coordinates=_mot(tmp_path / "own.mot", fitted.t, cols, False), grf=GRF,
                                        plates=PLATES), filter=Filter(cutoff=None))
    assert np.allclose(res.loads["knee_r.moment"], fitted.loads["knee_r.moment"], rtol=1e-9, atol=1e-8)


def test_bad_coordinate_tables_are_refused_in_one_line(fitted, tmp_path):
    good = _table(fitted, tmp_path)
    text = good.read_text()
    cases = {
        "no column 'knee_angle_r' or 'knee_r.angle'": text.replace("knee_angle_r", "knee_r"),
        "does not say inDegrees=yes or no": text.replace("inDegrees=yes\n", ""),
        "column 'hip_flexion_r' has no number at t = ": None,
    }
    for match, body in cases.items():
        path = tmp_path / "bad.mot"
        if body is None:
            lines = text.splitlines()
            head = lines.index("endheader") + 1
            cells = lines[head + 5].split("\t")
            cells[lines[head].split("\t").index("hip_flexion_r")] = "nan"
            lines[head + 5] = "\t".join(cells)
            body = "\n".join(lines) + "\n"
        path.write_text(body)
        with pytest.raises(ValueError, match=match):
            inverse_dynamics(LEG, Trial(coordinates=path, grf=GRF, plates=PLATES))
    with pytest.raises(ValueError, match="give the trial's markers or its coordinates"):
        inverse_dynamics(LEG, Trial(TRC, coordinates=good))
    with pytest.raises(ValueError, match="give the trial's markers or its coordinates"):
        inverse_dynamics(LEG, Trial())
    with pytest.raises(ValueError, match="tasks: they weight the marker fit"):
        inverse_dynamics(LEG, Trial(coordinates=good, tasks={"R.Heel": 1.0}))


@pytest.mark.parametrize("no_rate", [False, True])
def test_times_in_milliseconds_are_refused_naming_the_file(fitted, tmp_path, no_rate):
    """Times in ms (OpenSim writes s): the rate the frames' slope gives rounds to 0 Hz, which raised
    ZeroDivisionError (a traceback); that division mended, the trial ran unfiltered as 1000 s of motion and gave
    exit 0 with accelerations a million times too small. ``no_rate``: DataRate=0 in the header, the same division."""
    good = _table(fitted, tmp_path)
    lines = good.read_text().splitlines()
    head = lines.index("endheader") + 2
    lines[head:] = ["\t".join([f"{float(row.split(chr(9))[0]) * 1e3:.6g}", *row.split("\t")[1:]])
                    for row in lines[head:]]
    if no_rate:
        lines.insert(1, "DataRate=0")
    bad = tmp_path / "ms.mot"
    bad.write_text("\n".join(lines) + "\n")
    for cutoff in (None, 6.0):
        with pytest.raises(ValueError, match=r"the frames are 16.67 s apart \(0.06 Hz; the trial runs \d+ s\): "
                                             r"times in ms, not s\?") as err:
            inverse_dynamics(LEG, Trial(coordinates=bad, grf=GRF, plates=PLATES), filter=Filter(cutoff=cutoff))
        assert str(err.value).startswith(f"{bad}: ") and "\n" not in str(err.value)

def test_the_command_takes_coordinates_and_refuses_both_or_neither(fitted, tmp_path):
    import subprocess
    import sys

    table = _table(fitted, tmp_path)
    base = [sys.executable, "-m", "casflex", "inverse", str(LEG), "--loads", str(GRF), "--plate", "calcn_r=ground_"]
    run = subprocess.run([*base, "--coordinates", str(table), "--out", str(tmp_path / "id.sto")],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert "coordinates given: 6 columns" in run.stdout and (tmp_path / "id.sto").exists()
    for extra, said in (([], "--data, --coordinates: give"), (["--data", str(TRC), "--coordinates", str(table)],
                                                              "--data, --coordinates: give"),
                        (["--coordinates", str(table), "--tasks", str(table)], "--tasks: they weight the marker fit")):
        run = subprocess.run([*base, *extra], capture_output=True, text=True)
        assert run.returncode == 2 and run.stderr.strip().splitlines() == [run.stderr.strip()] and said in run.stderr


def _rewritten(table: Path, path: Path, degrees: str, scale) -> Path:
    """The table with its header's inDegrees set to ``degrees`` and each column scaled by ``scale(name)``."""
    lines = table.read_text().splitlines()
    head = lines.index("endheader") + 1
    names = lines[head].split("\t")
    rows = ["\t".join(f"{float(v) * scale(n):.15g}" for n, v in zip(names, row.split("\t"), strict=True))
            for row in lines[head + 1:]]
    text = "\n".join(lines[:head + 1] + rows).replace("inDegrees=yes", f"inDegrees={degrees}")
    path.write_text(text + "\n")
    return path


@pytest.mark.parametrize(("degrees", "scale", "match"), [
    # degrees under inDegrees=no: the pelvis's -3.4 degrees read as -3.4 rad, 197 degrees past its +-90
    ("no", lambda n: 1.0, r"column 'pelvis_tilt' reaches -440.4 degrees at t = 0.683 s, more than 30 degrees beyond "
                          r"the model's range -90..90 degrees; the header says inDegrees=no"),
    # radians under inDegrees=yes: the knee's 106 degrees of swing read as 1.85 degrees
    ("yes", lambda n: np.pi / 180 if n not in ("time", "pelvis_tx", "pelvis_ty") else 1.0,
     r"header inDegrees=yes, yet every angle stays within 1.85 degrees over the trial \(knee_angle_r the largest\)"),
    # millimetres read as metres: the pelvis 849 m along the lab
    ("yes", lambda n: 1e3 if n in ("pelvis_tx", "pelvis_ty") else 1.0,
     r"column 'pelvis_tx' is 848.8 m at t = 1.067 s, beyond any lab \(100 m\): positions are in m; millimetres"),
    # centimetres: the treadmill's pelvis 80 m along the lab and 101 m up
    ("yes", lambda n: 1e2 if n in ("pelvis_tx", "pelvis_ty") else 1.0,
     r"column 'pelvis_ty' is 101.1 m at t = 1.033 s, beyond any lab \(100 m\)"),
    # a hinge past a full turn where the model gives no range (the hip's 2377 degrees read as radians)
    ("no", lambda n: 1.0, None),
])
def test_coordinates_in_units_the_header_does_not_say_are_refused_naming_the_column(fitted, tmp_path, degrees, scale,
                                                                                   match):
    """Each gave loads of 1e6 N m (or, radians as degrees, plausible-looking wrong ones) with exit 0."""
    import dataclasses

    bad = _rewritten(_table(fitted, tmp_path), tmp_path / "bad.mot", degrees, scale)
    scene = scene_from_osim(LEG).scene
    if match is None:  # without the coordinates' ranges only the full turn is left to tell
        scene = dataclasses.replace(scene, coordinates=tuple(dataclasses.replace(c, limits=None)
                                                             for c in scene.coordinates))
        match = (r"column 'hip_flexion_r' reaches 41.49 rad \(2377 degrees\) at t = 0.967 s: no joint turns beyond a "
                 r"full turn; the header says inDegrees=no: are the angles in the other unit\?")
    with pytest.raises(ValueError, match=match) as err:
        inverse_dynamics(scene, Trial(coordinates=bad, grf=GRF, plates=PLATES))
    assert str(err.value).startswith(f"{bad}: ") and "\n" not in str(err.value)


def test_joint_moments_no_body_carries_are_refused_with_their_size(fitted, tmp_path, monkeypatch):
    """The backstop after the inverse dynamics: with the coordinates' checks taken away, millimetres read as metres
    give a hip moment of 1.2e6 N m: 8000 N m/kg of the 146 kg whose weight the plate's peak of 1432 N is."""
    import casflex.inverse
    import casflex.lab.checks as checks

    monkeypatch.setattr(checks, "check_coordinates", lambda *args: None)
    # and the plates' line of action, which the positions in mm put 790 m from the foot (lab.plate_checks)
    monkeypatch.setattr(casflex.inverse, "plates_under_feet", lambda *args: None)
    mm = lambda n: 1e3 if n in ("pelvis_tx", "pelvis_ty") else 1.0  # noqa: E731
    bad = _rewritten(_table(fitted, tmp_path), tmp_path / "mm.mot", "yes", mm)
    with pytest.raises(ValueError, match=r"hip_flexion_r_moment reaches 1.204e\+06 N m at t = 0.516667 s, 8.26e\+03 "
                                         r"N m per kg of a body of 146 kg; no human joint carries 20 N m/kg"):
        inverse_dynamics(LEG, Trial(coordinates=bad, grf=GRF, plates=PLATES))
    res = inverse_dynamics(LEG, Trial(coordinates=_table(fitted, tmp_path), grf=GRF, plates=PLATES))
    # the real stride: the knee's 203 N m is 1.4 N m/kg of that weight, far inside the limit
    assert 150 < np.abs(res.loads["knee_angle_r_moment"]).max() < 250
