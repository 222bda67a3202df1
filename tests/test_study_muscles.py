"""A study's muscles (``[options.muscles]``, issue 47): the .osim's muscles carried onto each subject's calibrated
scene as OpenSim's ScaleTool carries them (:mod:`casflex.muscles.scaling`), the options refused in one line naming
the field before any work, and a two-subject study on Hamner's subject 02 run (tests/data/lab, its muscle model
tests/data/muscles/hamner_subject02_planar_muscles.osim; the same data twice: the mechanics of a study)."""

from __future__ import annotations

import csv
import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pytest

from casflex.cli import main
from casflex.inverse.calibrate import _scaled_scene
from casflex.inverse.inputs import inverse_model
from casflex.inverse.tree import kinematic_tree
from casflex.muscles.path import MusclePaths
from casflex.muscles.scaling import scaled_muscles
from casflex.scene.from_osim import scene_from_osim
from casflex.study.runner import check_against_models
from casflex.study.study_file import StudyError, load_study

LAB = Path(__file__).resolve().parent / "data" / "lab"
DATA = Path(__file__).resolve().parent / "data" / "muscles"
MODEL = DATA / "hamner_subject02_planar_muscles.osim"


@pytest.fixture(scope="module")
def osim():
    return scene_from_osim(MODEL, muscles=True)


def _default_lengths(scene, muscles) -> np.ndarray:
    tree = kinematic_tree(inverse_model(scene, None))
    z0 = tree.coordinates(np.asarray(tree.model.q0, dtype=float).ravel())
    return np.asarray(MusclePaths(tree, muscles).length(z0), dtype=float).ravel()


def test_muscles_follow_a_uniform_scaling_exactly(osim):
    """Every segment scaled by 1.1 about its joint is the whole model scaled by 1.1 about the root's joint frame:
    every muscle-tendon length at the default pose, and so every optimal fibre and tendon slack length, 1.1 times
    the model's."""
    tree = kinematic_tree(inverse_model(osim.scene, None))
    after = _scaled_scene(tree, {c: 1.1 for c in set(tree.cluster)})
    moved, report = scaled_muscles(osim, after)
    ratio = _default_lengths(after, moved.muscles) / _default_lengths(osim.scene, osim.muscles)
    assert np.abs(ratio - 1.1).max() < 1e-12  # the scene's numbers to 1e-16: a metre-sized path to 1e-15 m
    for m, m0 in zip(moved.muscles, osim.muscles, strict=True):
        assert m.optimal_fiber_length == pytest.approx(1.1 * m0.optimal_fiber_length, rel=1e-12)
        assert m.tendon_slack_length == pytest.approx(1.1 * m0.tendon_slack_length, rel=1e-12)
        assert m.max_isometric_force == m0.max_isometric_force
    assert "1.1000" in report[0] and "ScaleTool" in report[0]


def test_one_scaled_segment_changes_only_its_muscles(osim):
    """The right femur 5 % longer: muscles with no point on it or below it keep their lengths; those crossing the
    right hip or knee change theirs, with their fibre and tendon lengths in proportion."""
    tree = kinematic_tree(inverse_model(osim.scene, None))
    femur = tree.cluster[tree.model.node_names.index("femur_r")]
    after = _scaled_scene(tree, {c: 1.05 if c == femur else 1.0 for c in set(tree.cluster)})
    moved, _ = scaled_muscles(osim, after)
    ratio = _default_lengths(after, moved.muscles) / _default_lengths(osim.scene, osim.muscles)
    left = [i for i, m in enumerate(osim.muscles) if m.name.endswith("_l")]
    right = [i for i, m in enumerate(osim.muscles) if m.name.endswith("_r")]
    assert np.abs(ratio[left] - 1.0).max() < 1e-12
    assert ratio[[i for i in right if osim.muscles[i].name.startswith("vas")]].min() > 1.01  # vasti: on the femur
    for i in right:
        m, m0 = moved.muscles[i], osim.muscles[i]
        assert m.tendon_slack_length / m0.tendon_slack_length == pytest.approx(ratio[i], rel=1e-12)


def test_an_unscaled_subject_keeps_the_models_muscles_and_another_scene_is_refused(osim):
    moved, report = scaled_muscles(osim, osim.scene)
    assert moved.muscles == osim.muscles and "as the model gives them" in report[0]
    nodes = list(osim.scene.nodes)
    k = next(i for i, n in enumerate(nodes) if n.name == "tibia_r")
    nodes[k] = dataclasses.replace(nodes[k], x=nodes[k].x + 0.01)
    with pytest.raises(ValueError, match="'tibia_r' lies 10 mm from where scaling its segment"):
        scaled_muscles(osim, dataclasses.replace(osim.scene, nodes=tuple(nodes)))


STUDY = """name = "hamner muscles"

[options]
cutoff = 10.0
tasks = "hamner_tasks_ik.xml"
scale = true

[options.muscles]
actuators = "hamner_reserve_actuators.xml"
joints = ["hip_r", "hip_l"]
{muscles}

[[subjects]]
name = "s02"
model = "hamner_subject02_planar_muscles.osim"
static = "static.trc"

[[subjects.trials]]
name = "run"
markers = "hamner_running_whole.trc"
grf = "hamner_running_whole_grf.mot"
plates = {{ calcn_r = "ground_", calcn_l = "1_ground_" }}

[[subjects]]
name = "s02_heavy"
model = "hamner_subject02_planar_muscles.osim"
mass = 80.0

[[subjects.trials]]
name = "run"
markers = "hamner_running_whole.trc"
grf = "hamner_running_whole_grf.mot"
plates = {{ calcn_r = "ground_", calcn_l = "1_ground_" }}
"""


def _static(folder: Path) -> None:
    """A one-frame "static" trial cut from the run (t = 0.45 s; its acromion markers left out: the running trunk's
    twist would place them 10 cm off): a subject scaled by it, for the mechanics."""
    lines = (LAB / "hamner_running_whole.trc").read_text().splitlines()
    names, head, row = lines[3].split("\t"), lines[2].split("\t"), lines[21].split("\t")
    head[2] = "1"
    for label in ("R.Acromium", "L.Acromium"):
        i = names.index(label)
        row[i:i + 3] = ["", "", ""]
    (folder / "static.trc").write_text("\n".join([*lines[:2], "\t".join(head), *lines[3:6], "\t".join(row)]) + "\n")


@pytest.fixture()
def folder(tmp_path: Path) -> Path:
    for f in ("hamner_running_whole.trc", "hamner_running_whole_grf.mot", "hamner_tasks_ik.xml"):
        shutil.copy(LAB / f, tmp_path / f)
    for f in ("hamner_subject02_planar_muscles.osim", "hamner_reserve_actuators.xml"):
        shutil.copy(DATA / f, tmp_path / f)
    _static(tmp_path)
    return tmp_path


def write(folder: Path, muscles: str = "", old: str = "", new: str = "") -> Path:
    path = folder / "study.toml"
    path.write_text(STUDY.format(muscles=muscles).replace(old, new, 1))
    return path


@pytest.mark.parametrize("muscles, old, new, message", [
    ("exponent = 0.5", "", "", "options.muscles.exponent: expected a number >= 1"),
    ("activation_bounds = [1.0, 0.5]", "", "", "options.muscles.activation_bounds: expected 0 <= lower < upper"),
    ("on = \"side\"", "", "", "options.muscles.on: expected 'child' or 'parent'"),
    ("frame = 3", "", "", "options.muscles.frame: expected 'child', 'parent' or 'ground'"),
    ("reserves = 10.0", "", "", "options.muscles.reserves: actuators gives the reserves; give one of them"),
    ("uncertainty = { max_force = \"10%\" }", "", "", "options.muscles.uncertainty.max_force: unknown property"),
    ("uncertainty = { tendon_slack_length = \"80%\" }", "", "",
     "options.muscles.uncertainty.tendon_slack_length: expected a relative standard deviation in [0, 0.5)"),
    ("criteria = [2.0]", "", "", "options.muscles.criteria: expected exponents >= 1 other than exponent (2)"),
    ("speed = 1", "", "", "options.muscles.speed: unknown field"),
    ("criteria = [20.0]", "", "", "options.muscles.criteria: expected exponents >= 1 other than exponent (2) and at "
                                  "most 10, got [20.0]"),
    ("activation_bounds = [0.01, 5.0]", "", "", "options.muscles.activation_bounds: expected 0 <= lower < upper <= 1"),
    ("", 'joints = ["hip_r", "hip_l"]', "joints = []", "options.muscles.joints: expected a list of joint names (leave "
                                                       "the key out for every hinge), got []"),
    ("", 'joints = ["hip_r", "hip_l"]', 'joints = ["hip_r", "hip_r"]', "options.muscles.joints: 'hip_r' given twice"),
    ("", 'actuators = "hamner_reserve_actuators.xml"', 'actuators = "none.xml"',
     "options.muscles.actuators: none.xml: no such file"),
])
def test_bad_muscle_options_are_refused_naming_the_field(folder, muscles, old, new, message):
    with pytest.raises(StudyError) as exc:
        load_study(str(write(folder, muscles, old, new)))
    assert str(exc.value).startswith(message) and "\n" not in str(exc.value), str(exc.value)


@pytest.mark.parametrize("old, new, message", [
    ('joints = ["hip_r", "hip_l"]', 'joints = ["hip_x"]', "options.muscles.joints: 'hip_x' is not a hinge of"),
    ('model = "hamner_subject02_planar_muscles.osim"\nmass', 'model = "hamner_leg"\nmass',
     "subjects[1].model: options.muscles needs an OpenSim model (.osim) with its muscles, got 'hamner_leg'"),
    # neither actuators nor reserves: the study passed its checks and each muscle run failed on the arms ("no muscle
    # crosses it and no reserve acts on it"), after the calibrations and the trials' runs
    ('actuators = "hamner_reserve_actuators.xml"', '', "options.muscles: neither actuators nor reserves given, and "
     "nothing acts on arm_flex_r, arm_flex_l, elbow_flex_r, elbow_flex_l, which no muscle of subjects[0]'s model "
     "(hamner_subject02_planar_muscles.osim) crosses: static optimization has nothing to carry their moments; give "
     "reserves = N"),
])
def test_muscle_options_are_checked_against_the_models_before_any_run(folder, old, new, message):
    study = load_study(str(write(folder, "", old, new)))
    with pytest.raises(StudyError) as exc:
        check_against_models(study)
    assert str(exc.value).startswith(message), str(exc.value)


def test_an_actuator_on_a_missing_coordinate_is_refused_before_any_run(folder, tmp_path, capsys):
    xml = (folder / "hamner_reserve_actuators.xml").read_text()
    assert "<coordinate>hip_flexion_r</coordinate>" in xml
    (folder / "hamner_reserve_actuators.xml").write_text(xml.replace("<coordinate>hip_flexion_r</coordinate>",
                                                                     "<coordinate>hip_nowhere</coordinate>", 1))
    out = tmp_path / "out"
    code = main(["study", str(write(folder)), "--out", str(out), "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "options.muscles.actuators: " in err[0] and "hip_nowhere" in err[0], err
    assert not out.exists()


def _hip(path: Path) -> dict[str, np.ndarray]:
    rows = [r for r in csv.DictReader(path.open()) if r["output"] == "hip_r_resultant"]
    return {s: np.array([float(r["value"]) for r in rows if r["subject"] == s]) for s in {r["subject"] for r in rows}}


def test_a_two_subject_study_writes_the_muscles_and_redoes_only_them_when_their_options_change(folder, capsys):
    out = folder / "out"
    assert main(["study", str(write(folder)), "--out", str(out), "--workers", "1", "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "group_contact.png" in text and (out / "group_contact.png").is_file()
    hip = _hip(out / "muscles.csv")
    assert sorted(hip) == ["s02", "s02_heavy"] and all(v.size == 101 for v in hip.values())  # one right cycle each
    # running: the planar model's hip contact force peaks at 8.5 BW (in-vivo running 4-5 BW; docs/muscles.md)
    assert all(6.0 < v.max() < 11.0 for v in hip.values()), {s: v.max() for s, v in hip.items()}
    assert not np.allclose(hip["s02"], hip["s02_heavy"], atol=0.01)  # the scaled subject's muscles differ
    with (out / "muscles.csv").open() as f:
        units = {r["output"]: r["unit"] for r in csv.DictReader(f)}
    assert units["hip_r_resultant"] == "BW" and units["soleus_r.activation"] == "1"
    assert units["hip_r_on_femur_r_in_ground_mz"] == "BW m"
    before = {p.name: p.stat().st_mtime_ns for p in (out / "record").glob("*.json")}
    assert sum(n.startswith("muscles-") for n in before) == 2
    assert main(["study", str(write(folder, "exponent = 3.0", "", "")), "--out", str(out), "--workers", "1",
                 "--quiet"]) == 0
    after = {p.name: p.stat().st_mtime_ns for p in (out / "record").glob("*.json")}
    assert {n for n in after if n not in before and n.startswith("muscles-")} and \
        all(after[n] == t for n, t in before.items())  # the calibrations and trials kept, two muscle runs added
    assert len(after) == len(before) + 2
    hip3 = _hip(out / "muscles.csv")
    assert not np.allclose(hip3["s02"], hip["s02"], atol=0.01)  # p = 3 shares the load otherwise


def test_a_subject_named_as_the_contact_figure_is_refused(folder):
    with pytest.raises(StudyError, match=r"subjects\[1\]\.name: 'Group_Contact' names the group's figure "
                                         r"\(group_contact\.png\)"):
        load_study(str(write(folder, "", 'name = "s02_heavy"', 'name = "Group_Contact"')))


def test_the_criteria_default_to_the_other_of_2_and_3(folder):
    """The bands' spread is to p = 3 beside p = 2, and to p = 2 beside p = 3 (the issue's two criteria)."""
    assert load_study(str(write(folder))).options.muscles.criteria == (3.0,)
    assert load_study(str(write(folder, "exponent = 3.0"))).options.muscles.criteria == (2.0,)


def test_a_muscle_runs_record_says_what_casflex_muscles_says(folder, tmp_path):
    """The residual warning (the run without its plates: FY carries 1.4 BW RMS) and the muscles crossing no
    coordinate of the plane (soleus_r's ends both on the tibia) reached `casflex muscles`' output only: a study's
    muscle run built its own record without them. Now its warnings (the summary's lines) hold the same text."""
    from casflex.scene import dumps_scene
    from casflex.study.muscles import muscle_run

    text = (folder / "hamner_subject02_planar_muscles.osim").read_text()
    old = "<PathPoint name=\"soleus_r-P2\">"
    at = text.index(old)
    end = text.index("</PathPoint>", at)
    text = text[:at] + text[at:end].replace("/bodyset/calcn_r", "/bodyset/tibia_r") + text[end:]
    # its path now 0.205 m: the tendon shortened so that the fibre sits near its optimal length (else refused as a
    # muscle that cannot pull)
    text = text.replace("<tendon_slack_length>0.27766217612689298</tendon_slack_length>",
                        "<tendon_slack_length>0.155</tendon_slack_length>", 1)
    (folder / "hamner_subject02_planar_muscles.osim").write_text(text)
    study = load_study(str(write(folder)))
    s = study.subjects[0]
    scene = dumps_scene(scene_from_osim(s.model, muscles=True).scene)  # the subject unscaled: the model's scene
    rec = muscle_run(model=s.model, scene=scene, trial=s.trials[0], options=study.options.trials, plane="X,Y",
                     plates=None, cycles={}, muscles=study.options.muscles, uncertain=())
    warnings = rec["warnings"]
    assert any(w.startswith("residual 'FY' carries 1.") and "the ground reactions are missing" in w
               for w in warnings), warnings
    assert "muscles soleus_r cross no coordinate of the plane (moment arms 0 at every frame): they carry no moment, " \
           "their activations stay at the lower bound" in warnings, warnings


def test_muscles_follow_a_subject_scaled_on_a_static_trial_without_some_segments_markers():
    # the static excerpt records the pelvis and the right leg only: the calibration wrote the other segments welded,
    # and the muscles refused the subject ("its nodes or coordinates differ"); now those keep their joints and size
    from casflex.inverse.calibrate import calibrate

    osim = scene_from_osim(DATA / "hamner_subject02_planar_muscles.osim", muscles=True)
    after, _ = calibrate(osim.scene, str(LAB / "hamner_static_excerpt.trc"), root="pelvis", scale=True)
    moved, report = scaled_muscles(osim, after, "pelvis")
    assert report[0].startswith("muscles: their path points scaled with their segments")
    left = [(a, b) for a, b in zip(osim.muscles, moved.muscles, strict=True) if a.name.endswith("_l")]
    assert left and all(abs(b.optimal_fiber_length / a.optimal_fiber_length - 1) < 0.01 for a, b in left)
