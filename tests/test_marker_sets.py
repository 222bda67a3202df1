"""The built-in models of the marker sets labs use (issue 48, item 4: casflex/scene/builtin/pig.toml, pig_psis.toml,
cast.toml; tests/marker_set_scenes.py writes them), the joint centres' other names (casflex.lab.marker_sets), and a
whole-body model on lower-body markers: its trunk locked, said (casflex.inverse.locking)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from casflex import load_scene
from casflex.lab import LabMarkers

TESTS = Path(__file__).resolve().parent
sys.path.insert(0, str(TESTS))
LAB = TESTS / "data" / "lab"
TRUNK = ("CLAV", "RSHO", "LSHO")


@pytest.mark.parametrize("name", ["pig", "pig_psis", "cast"])
def test_the_shipped_marker_set_models_are_what_their_script_writes(name, tmp_path):
    from marker_set_scenes import set_scene_text

    shipped = (TESTS.parent / "casflex" / "scene" / "builtin" / f"{name}.toml").read_text()
    assert shipped == set_scene_text(name, tmp_path)  # no hand edit: the script and its source say all
    sc = load_scene(name)  # by name, as a study file's model or casflex inverse's scene
    centres = {m.name for m in sc.markers if m.weight == 0}
    assert centres == {f"{s}{k}" for s in "RL" for k in ("HJC", "KJC", "AJC")}
    assert {"hip_flexion_r", "knee_angle_l", "ankle_angle_r", "lumbar_extension"} <= {c.name for c in sc.coordinates}


def _static(sc, labels, extra: dict | None = None, n: int = 20) -> LabMarkers:
    """A static trial (m, lab X forward, Y up) of the scene's markers ``labels`` where the scene puts them, 0.1 mm
    of noise (a standing subject's markers are not still to the bit)."""
    pos = {m.name: (m.x, m.y, 0.0) for m in sc.markers} | (extra or {})
    xyz = np.array([pos[lb] for lb in labels])
    noise = 1e-4 * np.random.default_rng(0).normal(size=(n, len(labels), 3))
    return LabMarkers(np.arange(n) / 100.0, tuple(labels), xyz[None] + noise, 100.0, "m", "static.trc")


def test_a_whole_body_model_on_lower_body_markers_locks_its_trunk_and_says_so():
    # refused before: "the markers do not decide ['lumbar_extension'] in any frame: segment 'torso' ..."
    from casflex.inverse.calibrate import calibrate

    sc = load_scene("pig")
    lower = [m.name for m in sc.markers if m.name not in TRUNK and m.weight > 0]
    out, report = calibrate(sc, _static(sc, lower), "X,Y")
    assert report[0] == ("segment 'torso': the static trial static.trc has none of its markers ['CLAV', 'RSHO', "
                         "'LSHO']: its joint 'back' (lumbar_extension) locked at the model's default pose (the "
                         "segment rides on 'pelvis', its mass with it)")
    # locked for the static fit only: the scene written keeps the back's hinge and the trunk's markers (where they
    # were), for the trials that record them (a trial without them locks it again)
    assert next(j for j in out.joints if j.name == "back").kind == "hinge"
    assert "lumbar_extension" in {c.name for c in out.coordinates}
    assert {(m.name, m.x, m.y) for m in out.markers if m.name in TRUNK} == {(m.name, m.x, m.y) for m in sc.markers
                                                                            if m.name in TRUNK}
    assert abs(sum(b.mass for b in out.bodies) - sum(b.mass for b in sc.bodies)) < 1e-9  # the trunk's mass stays
    full, report = calibrate(sc, _static(sc, [m.name for m in sc.markers if m.weight > 0]), "X,Y")
    assert next(j for j in full.joints if j.name == "back").kind == "hinge"  # its markers recorded: kept
    assert not any("locked" in line for line in report)


def test_a_trial_without_the_trunk_s_markers_runs_with_the_trunk_locked():
    from casflex.inverse import Trial, prepare

    sc = load_scene("pig")
    lower = [m.name for m in sc.markers if m.name not in TRUNK and m.weight > 0]  # no joint centres either
    inputs = prepare(sc, Trial(_static(sc, lower), plane="X,Y"))
    assert any(w.startswith("segment 'torso': static.trc has none of its markers") for w in inputs.warnings)
    assert "lumbar_extension" not in {c.name for c in inputs.model.scene.coordinates}


def test_plug_in_gait_s_segment_origins_stand_for_the_joint_centres_in_the_calibration():
    from casflex.inverse.calibrate import calibrate
    from casflex.lab.marker_sets import JOINT_CENTRE_ALIASES, joint_centres

    sc = load_scene("pig")
    knee = next(m for m in sc.markers if m.name == "RKJC")
    shifted = (knee.x + 0.01, knee.y, 0.0)  # the subject's knee centre 10 mm off the model's
    lab = _static(sc, [*(m.name for m in sc.markers if m.weight > 0), "RFEO"], {"RFEO": shifted})
    taken, lines = joint_centres(lab, [m.name for m in sc.markers])
    assert lines == ["static.trc: joint centre RKJC taken from RFEO (Plug-in Gait's segment point there)"]
    assert JOINT_CENTRE_ALIASES["LHJC"] == ("LFEP",) and JOINT_CENTRE_ALIASES["RAJC"] == ("RTIO",)
    np.testing.assert_array_equal(taken.marker("RKJC"), lab.marker("RFEO"))
    out, report = calibrate(sc, lab, "X,Y")
    placed = next(m for m in out.markers if m.name == "RKJC")
    moved = np.hypot(placed.x - knee.x, placed.y - knee.y)
    assert 0.005 < moved < 0.015, moved  # placed on the subject's (the static pose fitted to it too: not all 10 mm)
    assert "marker 'RKJC' (RKJC): not in the static trial" not in report
    assert placed.weight == 0.0  # the marker fit's weight again after the calibration's


def test_the_cast_model_calibrates_on_walking2_s_cluster_markers():
    from casflex.study.runner import calibrate_run

    # walking2.c3d (tests/data/lab): a CAST-type set and the joint centres; its first 20 ms as a static trial (no
    # standing frames in the excerpt: the markers move less than the static check's 50 mm in them)
    out = calibrate_run(model="cast", static=str(LAB / "walking2_excerpt.c3d"), plane="X,Z", root=None,
                        calibrate=True, scale=True, mass=None, vertical="Z", static_window=(2.56, 2.58))
    assert "static trial: 6 frames averaged, 37 of 37 markers seen" in out["report"]


def test_the_joint_centres_place_the_static_pose_in_the_calibration():
    # the right shank's and foot's skin markers missing from the static trial, its joint centres there: they decide
    # the shank's pose
    # in the calibration (weight 0 left them out: "the markers do not decide ['knee_angle_r'] ... of weight 0")
    from casflex.inverse.calibrate import calibrate

    sc = load_scene("pig")
    labels = [m.name for m in sc.markers if m.name not in ("RTIB", "RANK", "RHEE", "RTOE")]
    out, report = calibrate(sc, _static(sc, labels), "X,Y")
    assert report[0].startswith("segment 'talus_r': the static trial static.trc has none of its markers ['RHEE', "
                                "'RTOE']: its joint 'ankle_r' (ankle_angle_r) locked")  # the foot's alone
    assert "static trial: 20 frames averaged, 20 of 22 markers seen" in report  # the foot's left out with it
    assert next(j for j in out.joints if j.name == "knee_r").kind == "hinge"
    assert {m.name: m.weight for m in out.markers}["RAJC"] == 0.0
