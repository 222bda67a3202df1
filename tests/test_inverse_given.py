"""casflex.inverse.given: coordinates given instead of markers (a .mot of joint angles, e.g. OpenSim's IK)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from casflex.inverse import inverse_dynamics
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
    return inverse_dynamics(LEG, TRC, grf=GRF, plates=PLATES, cutoff=None)


def _table(fitted, tmp_path, degrees=True) -> Path:
    scene = scene_from_osim(LEG).scene
    cols = {}
    for c in scene.coordinates:
        v = to_lab(scene, c, fitted.z[:, fitted.coordinate_names.index(c.scene_coordinate())])
        cols[c.name] = np.degrees(v) if degrees and not c.translational else v
    return _mot(tmp_path / "ik.mot", np.round(fitted.t, 3), cols, degrees)  # times rounded as OpenSim writes them


@pytest.mark.parametrize("degrees", [True, False])
def test_a_table_of_the_fitted_coordinates_gives_the_same_loads(fitted, tmp_path, degrees):
    res = inverse_dynamics(LEG, coordinates=_table(fitted, tmp_path, degrees), grf=GRF, plates=PLATES, cutoff=None)
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
    res = inverse_dynamics(scene, coordinates=_mot(tmp_path / "own.mot", fitted.t, cols, False), grf=GRF,
                           plates=PLATES, cutoff=None)
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
            inverse_dynamics(LEG, coordinates=path, grf=GRF, plates=PLATES)
    with pytest.raises(ValueError, match="give the trial's markers or its coordinates"):
        inverse_dynamics(LEG, TRC, coordinates=good)
    with pytest.raises(ValueError, match="give the trial's markers or its coordinates"):
        inverse_dynamics(LEG)
    with pytest.raises(ValueError, match="tasks: they weight the marker fit"):
        inverse_dynamics(LEG, coordinates=good, tasks={"R.Heel": 1.0})


def test_the_command_takes_coordinates_and_refuses_both_or_neither(fitted, tmp_path):
    import subprocess
    import sys

    table = _table(fitted, tmp_path)
    base = [sys.executable, "-m", "casflex", "inverse", str(LEG), "--loads", str(GRF), "--plate", "calcn_r=ground_"]
    run = subprocess.run([*base, "--coordinates", str(table), "--out", str(tmp_path / "id.sto"), "--quiet"],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert "coordinates given: 6 columns" in run.stdout and (tmp_path / "id.sto").exists()
    for extra, said in (([], "--data, --coordinates: give"), (["--data", str(TRC), "--coordinates", str(table)],
                                                              "--data, --coordinates: give"),
                        (["--coordinates", str(table), "--tasks", str(table)], "--tasks: weights the marker fit")):
        run = subprocess.run([*base, *extra], capture_output=True, text=True)
        assert run.returncode == 2 and run.stderr.strip().splitlines() == [run.stderr.strip()] and said in run.stderr
