"""casflex.scene.osim_muscles and the muscles of casflex.scene.from_osim: gait10dof18musc's muscles read (the five
properties, the other numbers, Millard's curves' numbers, conditional and moving points on the scene's lab
coordinates), the report, a coordinate the scene holds evaluated at its default value, and the refusals (one line
naming the file, the muscle and the element), each on the model with one fault."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from casflex.cli import main
from casflex.scene.from_osim import scene_from_osim
from casflex.scene.osim import read_osim

GAIT = Path(__file__).parent / "data" / "muscles" / "gait10dof18musc.osim"
TEXT = GAIT.read_text()


def _model(tmp_path: Path, *changes: str, within: str | None = None) -> Path:
    """The gait model with ``old, new, ...`` replaced (the first occurrence, after ``within`` if given)."""
    text = TEXT
    start = text.index(within) if within else 0
    for old, new in zip(changes[::2], changes[1::2], strict=True):
        at = text.index(old, start)
        text = text[:at] + new + text[at + len(old):]
    path = tmp_path / "model.osim"
    path.write_text(text)
    return path


def _refused(path: Path, pattern: str) -> None:
    with pytest.raises(ValueError) as exc:
        scene_from_osim(path, muscles=True)
    message = str(exc.value)
    assert "\n" not in message and message.startswith(f"{path}: ")
    assert re.search(pattern, message), message


def test_gait10dof18musc_muscles_are_read_with_their_numbers_and_points():
    m = read_osim(GAIT, muscles=True)
    assert len(m.muscles) == 18 and {mu.kind for mu in m.muscles} == {"Millard2012EquilibriumMuscle"}
    vasti = next(mu for mu in m.muscles if mu.name == "vasti_r")
    assert vasti.numbers == {"max_isometric_force": 5000.0, "optimal_fiber_length": 0.087, "tendon_slack_length":
                             0.136, "pennation_angle_at_optimal": 0.05235988, "max_contraction_velocity": 10.0}
    props = dict(vasti.properties)
    assert props["ActiveForceLengthCurve.minimum_value"] == 0.0 and props["deactivation_time_constant"] == 0.04
    assert props["ForceVelocityCurve.max_eccentric_velocity_force_multiplier"] == 1.4
    assert [p.kind for p in vasti.path] == ["PathPoint", "PathPoint", "ConditionalPathPoint", "MovingPathPoint"]
    assert vasti.path[2].condition == ("knee_angle_r", -2.61799, -1.42) and vasti.path[0].body == "femur_r"
    assert [(a, c) for a, c, _ in vasti.path[3].moving] == [(0, "knee_angle_r"), (1, "knee_angle_r"),
                                                             (2, "knee_angle_r")]


def test_the_scene_carries_the_muscles_on_its_lab_coordinates_and_reports_them():
    s = scene_from_osim(GAIT, muscles=True)
    assert len(s.muscles) == 18
    assert "muscles: 18 (18 Millard2012EquilibriumMuscle)" in s.report
    assert not any(line.startswith("ignored:") for line in s.report)  # the muscles kept are not "ignored"
    vasti = next(mu for mu in s.muscles if mu.name == "vasti_r")
    assert vasti.path[2].condition == ("knee_angle_r", -2.61799, -1.42)
    assert [(a, c) for a, c, _ in vasti.path[3].moving] == [(0, "knee_angle_r"), (1, "knee_angle_r")]  # z constant
    assert vasti.path[3].node == "tibia_r" and vasti.path[3].location[2] == 0.0018


def test_another_muscle_class_and_actuators_stay_ignored_and_listed(tmp_path):
    path = _model(tmp_path, '<Millard2012EquilibriumMuscle name="hamstrings_r">',
                  '<RigidTendonMuscle name="hamstrings_r">', "</Millard2012EquilibriumMuscle>", "</RigidTendonMuscle>")
    s = scene_from_osim(path, muscles=True)
    assert len(s.muscles) == 17 and "ignored: 1 ForceSet RigidTendonMuscle" in s.report


@pytest.mark.parametrize("kind", ["Thelen2003Muscle", "DeGrooteFregly2016Muscle"])
def test_thelen_and_degroote_muscles_are_read(tmp_path, kind):
    path = _model(tmp_path, '<Millard2012EquilibriumMuscle name="hamstrings_r">', f'<{kind} name="hamstrings_r">',
                  "</Millard2012EquilibriumMuscle>", f"</{kind}>")
    s = scene_from_osim(path, muscles=True)
    assert s.muscles[0].kind == kind and s.muscles[0].max_isometric_force == 2700.0
    counts = sorted(["17 Millard2012EquilibriumMuscle", f"1 {kind}"], key=lambda t: t.split()[1])
    assert f"muscles: 18 ({', '.join(counts)})" in s.report


def test_points_on_a_coordinate_the_scene_holds_are_evaluated_at_its_default_value(tmp_path):
    path = _model(tmp_path, "<locked>false</locked>", "<locked>true</locked>",
                  within='<Coordinate name="knee_angle_r">')
    s = scene_from_osim(path, muscles=True)
    vasti = next(mu for mu in s.muscles if mu.name == "vasti_r")
    assert [p.name for p in vasti.path] == ["vas_int_r-P1", "vas_int_r-P2", "vas_int_r-P4"]  # P3: knee in -2.6..-1.4
    assert vasti.path[-1].moving == () and vasti.path[-1].location == pytest.approx((0.0554632, 0.0252923, 0.0018))
    assert ("muscle 'vasti_r' path point 'vas_int_r-P3': its coordinate 'knee_angle_r' is held at 0 by the scene: "
            "never on the path; left out") in s.dropped
    assert any(d.startswith("muscle 'vasti_r' path point 'vas_int_r-P4': its x follows 'knee_angle_r', held at 0")
               for d in s.dropped)


HAM = '<Millard2012EquilibriumMuscle name="hamstrings_r">'


@pytest.mark.parametrize("old, new, pattern", [
    ("<max_isometric_force>2700", "<max_isometric_force>nan", r"\.max_isometric_force: expected 1 numbers, got 'nan'"),
    ("<max_isometric_force>2700", "<max_isometric_force>inf", r"max_isometric_force: expected 1 numbers, got 'inf'"),
    ("<optimal_fiber_length>0.109", "<optimal_fiber_length>-0.109", r"optimal_fiber_length: must be > 0, got -0\.109"),
    ("<tendon_slack_length>0.32600000000000001", "<tendon_slack_length>0", r"tendon_slack_length: must be > 0, got 0"),
    ("<pennation_angle_at_optimal>0", "<pennation_angle_at_optimal>1.6",
     r"pennation_angle_at_optimal: must be in \[0, pi/2\) rad, got 1\.6"),
    ("<max_contraction_velocity>10", "<max_contraction_velocity>0", r"max_contraction_velocity: must be > 0, got 0"),
    ("<minimum_activation>0.01", "<minimum_activation>nan", r"\.minimum_activation: 'nan' is no number"),
    ("<isometric_slope>5", "<isometric_slope>inf", r"ForceVelocityCurve\.isometric_slope: 'inf' is no number"),
    ("/bodyset/tibia_r", "/bodyset/tibia_x", r"path point 'bifemlh_r-P2': on 'tibia_x', no body of the model"),
    # an element given twice was read first-wins without a word (OpenSim too): which one counts would be a guess
    ("<max_isometric_force>2700", "<max_isometric_force>1000</max_isometric_force><max_isometric_force>2700",
     r"\.max_isometric_force: given 2 times; give it once"),
    ("<minimum_activation>0.01", "<max_control>0.5</max_control><max_control>1</max_control><minimum_activation>0.01",
     r"\.max_control: given 2 times; give it once"),
    ("<isometric_slope>5", "<isometric_slope>4</isometric_slope><isometric_slope>5",
     r"\.ForceVelocityCurve\.isometric_slope: given 2 times; give it once"),
])
def test_bad_muscle_numbers_and_bodies_are_refused(tmp_path, old, new, pattern):
    _refused(_model(tmp_path, old, new, within=HAM),
             r"ForceSet: Millard2012EquilibriumMuscle 'hamstrings_r'.*" + pattern)


def test_a_path_of_one_point_is_refused(tmp_path):
    a = TEXT.index('<PathPoint name="bifemlh_r-P2">')
    b = TEXT.index('<PathPoint name="bifemlh_r-P3">')
    c = TEXT.index("</PathPoint>", b) + len("</PathPoint>")
    path = tmp_path / "model.osim"
    path.write_text(TEXT[:a] + TEXT[c:])
    _refused(path, r"'hamstrings_r'\.GeometryPath: 1 path point\(s\); a muscle's path needs two or more")


def test_a_condition_or_a_moving_point_on_a_missing_coordinate_is_refused(tmp_path):
    _refused(_model(tmp_path, "/jointset/knee_r/knee_angle_r", "/jointset/knee_r/knee_bend_r",
                    within='<ConditionalPathPoint name="rect_fem_r-P2">'),
             r"'rect_fem_r' path point 'rect_fem_r-P2'\.socket_coordinate: 'knee_bend_r' is no coordinate")
    _refused(_model(tmp_path, "/jointset/knee_r/knee_angle_r", "/jointset/knee_r/knee_bend_r",
                    within='<MovingPathPoint name="rect_fem_r-P3">'),
             r"'rect_fem_r' path point 'rect_fem_r-P3'\.socket_x_coordinate: 'knee_bend_r' is no coordinate")


def _wrapped(tmp_path: Path, obj: str) -> Path:
    """bifemsh_r wrapping over ``obj`` (a wrap object's XML) on femur_r."""
    text = TEXT.replace('<Body name="femur_r">', f'<Body name="femur_r"><WrapObjectSet><objects>{obj}</objects>'
                        "</WrapObjectSet>", 1)
    a = text.index('<Millard2012EquilibriumMuscle name="bifemsh_r">')
    at = text.index("<PathWrapSet>", a) + len("<PathWrapSet>")
    text = text[:at] + ('<objects><PathWrap name="w"><wrap_object>knee_wrap</wrap_object><range>-1 -1</range>'
                        "</PathWrap></objects>") + text[text.index("</PathWrapSet>", at):]
    path = tmp_path / "wrapped.osim"
    path.write_text(text)
    return path


@pytest.mark.parametrize("obj, why", [
    ('<WrapSphere name="knee_wrap"><radius>0.03</radius></WrapSphere>', "a WrapSphere: its wrapping leaves the plane"),
    ('<WrapCylinder name="knee_wrap"><xyz_body_rotation>0.5 0 0</xyz_body_rotation><radius>0.03</radius>'
     "</WrapCylinder>", r"a WrapCylinder whose axis \[0.0, -0.479, 0.878\] is not the plane's normal: its wrapping "
     "leaves the plane"),
    ('<WrapSphere name="other"><radius>0.03</radius></WrapSphere>', "PathWrap: wrap object 'knee_wrap' is on no body"),
    ('<WrapEllipsoid name="knee_wrap"><dimensions>0.03 0.03 0.05</dimensions></WrapEllipsoid>',
     "a WrapEllipsoid: its wrapping leaves the plane"),
    ('<WrapTorus name="knee_wrap"><inner_radius>0.01</inner_radius><outer_radius>0.03</outer_radius></WrapTorus>',
     "a WrapTorus: its wrapping leaves the plane"),
])
def test_wraps_are_refused_naming_the_muscle_the_wrap_object_and_why(tmp_path, obj, why):
    _refused(_wrapped(tmp_path, obj), r"^\S+: ForceSet: Millard2012EquilibriumMuscle 'bifemsh_r': .*" + why)


def test_a_cylinder_about_the_planes_normal_is_kept_as_a_circle(tmp_path):
    s = scene_from_osim(_wrapped(tmp_path, '<WrapCylinder name="knee_wrap"><translation>0 -0.4 0</translation>'
                                           "<radius>0.03</radius><length>0.1</length><quadrant>-x</quadrant>"
                                           "</WrapCylinder>"), muscles=True)
    (w,) = next(m for m in s.muscles if m.name == "bifemsh_r").wraps
    assert (w.name, w.radius, w.length, w.quadrant, w.points) == ("knee_wrap", 0.03, 0.1, "-x", (-1, -1))
    R, p = s.frames["femur_r"]
    assert np.allclose(w.centre, p + R @ [0, -0.4, 0], atol=1e-15) and abs(w.frame[8]) == 1
    assert "muscle 'bifemsh_r': wraps over 'knee_wrap' (a circle in the plane, radius 0.03 m)" in s.report


@pytest.mark.parametrize("obj, why", [
    ('<WrapCylinder name="knee_wrap"><radius>0.03</radius><quadrant>+w</quadrant></WrapCylinder>',
     r"wrap object 'knee_wrap'\.quadrant: '\+w' is none of OpenSim's"),
    ('<WrapCylinder name="knee_wrap"><radius>-0.03</radius></WrapCylinder>',
     r"wrap object 'knee_wrap': radius -0.03 m, length 1 m: both must be > 0"),
])
def test_a_bad_cylinder_is_refused(tmp_path, obj, why):
    _refused(_wrapped(tmp_path, obj), why)


def test_two_wraps_on_one_path_are_refused(tmp_path):
    path = _wrapped(tmp_path, '<WrapCylinder name="knee_wrap"><radius>0.03</radius></WrapCylinder>'
                              '<WrapCylinder name="w2"><radius>0.02</radius></WrapCylinder>')
    text = path.read_text().replace("</PathWrap></objects>", "</PathWrap><PathWrap name=\"w2\"><wrap_object>w2"
                                    "</wrap_object></PathWrap></objects>", 1)
    path.write_text(text)
    _refused(path, r"'bifemsh_r': wrap objects \['knee_wrap', 'w2'\]: 2 wraps on one path; OpenSim iterates")


def test_an_inactive_wrap_object_is_reported_and_left_out(tmp_path):
    s = scene_from_osim(_wrapped(tmp_path, '<WrapSphere name="knee_wrap"><active>false</active><radius>0.03</radius>'
                                           "</WrapSphere>"), muscles=True)
    assert "muscle 'bifemsh_r': wrap object 'knee_wrap' is not active in the model; ignored" in s.report
    assert len(s.muscles) == 18


def test_a_bad_or_wrapping_muscle_does_not_stop_the_bones_being_read(tmp_path, capsys):
    """Inverse dynamics and import use the bones only: a muscle casflex cannot compute (NaN, or wrapping in 3D) is
    refused where the muscles are asked for, not where they are not (a 3D-wrapping model still gives its scene)."""
    path = _model(tmp_path, "<optimal_fiber_length>0.109", "<optimal_fiber_length>nan", within=HAM)
    out = tmp_path / "scene.toml"
    assert main(["import", str(path), "--out", str(out)]) == 0 and out.exists()
    assert "Millard2012EquilibriumMuscle" in capsys.readouterr().out  # listed as ignored
    _refused(path, "ForceSet: ")
    wrapped = _wrapped(tmp_path, '<WrapSphere name="knee_wrap"><radius>0.03</radius></WrapSphere>')
    assert scene_from_osim(wrapped).muscles == ()


def test_two_path_points_of_one_name_are_refused(tmp_path):
    a = TEXT.index('<PathPoint name="bifemlh_r-P2">')
    b = TEXT.index("</PathPoint>", a) + len("</PathPoint>")
    path = tmp_path / "model.osim"
    path.write_text(TEXT[:b] + TEXT[a:b] + TEXT[b:])
    _refused(path, r"'hamstrings_r'\.GeometryPath: two path points named 'bifemlh_r-P2'; give each its own name")


def test_a_path_point_on_the_ground_is_refused(tmp_path):
    """The planar scene has no node for the ground: such a point had no node to follow."""
    _refused(_model(tmp_path, "/bodyset/pelvis", "/ground", within=HAM),
             r"'hamstrings_r': path point 'bifemlh_r-P1': on 'ground', the ground \(casflex's scene has no node")
