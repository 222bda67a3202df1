"""casflex.scene.osim, casflex.scene.from_osim, casflex.scene.functions: OpenSim models read into planar
scenes (OpenSim's own kinematics of them: tests/test_peers_opensim.py), coupled hinges through the model."""

from __future__ import annotations

from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from casflex.elements.joints import spline_of
from casflex.inverse.inputs import inverse_model
from casflex.inverse.tree import kinematic_tree
from casflex.scene import dumps_scene, load_scene, loads_scene
from casflex.scene.from_osim import scene_from_osim
from casflex.scene.functions import SimmSpline

LEG = Path(__file__).parent / "data" / "lab" / "hamner_subject02_leg.osim"


def test_simm_spline_reproduces_a_cubic_and_continues_linearly():
    # FMM's end conditions match the third derivative of the cubics through the end knots: exact for a cubic
    x = np.array([-2.0, -1.3, -0.4, 0.0, 0.5, 1.1, 2.0])
    cubic = lambda v: 0.3 * v**3 - 0.2 * v**2 + v - 0.7  # noqa: E731
    f = SimmSpline(tuple(x), tuple(cubic(x)))
    v = np.linspace(-2, 2, 101)
    assert np.max(np.abs(f(v) - cubic(v))) < 1e-12  # rounding of O(1) values
    b = f.coefficients()[0]
    assert f(3.0) == pytest.approx(cubic(2.0) + b[-1] * 1.0, abs=1e-12)
    sym = ca.SX.sym("v")
    g = ca.Function("g", [sym], [spline_of(f, sym)])  # the symbolic model's evaluation (casflex.elements.joints)
    w = np.linspace(-3, 3, 61)
    assert np.array_equal(np.array(g(w[None, :])).ravel(), f(w))


def test_the_leg_model_becomes_a_tree_with_a_coupled_knee_and_a_report():
    r = scene_from_osim(LEG)
    sc = r.scene
    assert [(j.name, j.kind, j.coupled) for j in sc.joints] == [
        ("hip_r", "hinge", False), ("knee_r", "hinge", True), ("ankle_r", "hinge", False),
        ("subtalar_r", "weld", False), ("mtp_r", "weld", False)]
    assert {c.name: c.of for c in sc.coordinates} == {
        "pelvis_tilt": "pelvis.theta", "pelvis_tx": "pelvis.x", "pelvis_ty": "pelvis.y", "hip_flexion_r": "hip_r",
        "knee_angle_r": "knee_r", "ankle_angle_r": "ankle_r"}
    assert len(sc.markers) == 13 and all(m.label for m in sc.markers)
    text = "\n".join(r.report)
    for said in ("'hip_adduction_r' (rotation about [1.0, 0.0, 0.0]) locked", "'pelvis_tz'",
                 "11.7 deg from the plane's normal; projected", "a coupled hinge (its centre moves along x and y)"):
        assert said in text
    assert loads_scene(dumps_scene(sc)) == sc  # written out for the user to edit, read back the same
    assert load_scene(LEG) == sc


def test_a_coupled_hinge_s_constraints_hold_along_the_tree_and_its_tangent_is_exact():
    model = inverse_model(scene_from_osim(LEG).scene)
    tree = kinematic_tree(model)
    rng = np.random.default_rng(4)
    z = np.array([0.1, 0.2, 0.9, 0.3, -1.4, 0.2]) + 0.1 * rng.standard_normal(tree.n)
    q = np.array(tree.forward(z)).ravel()
    phi, B = (np.array(v) for v in model.constraint(q)[:2])
    assert np.max(np.abs(phi)) < 1e-14  # the tree places the tibia where the knee's rows put it
    h = 1e-6
    fd = np.column_stack([(np.array(model.constraint(q + h * e)[0]).ravel() - np.array(
        model.constraint(q - h * e)[0]).ravel()) / (2 * h) for e in np.eye(q.size)])
    assert np.max(np.abs(fd - B)) < 1e-8  # central differences: O(h^2) truncation, O(eps/h) rounding


def test_a_coordinate_the_file_locks_is_held_as_opensim_holds_it(tmp_path):
    text = LEG.read_text()
    knee = text.index('<Coordinate name="knee_angle_r">')
    end = text.index("</Coordinate>", knee)
    block = text[knee:end]
    locked = block.replace("<locked>false</locked>", "<locked>true</locked>") if "<locked>" in block \
        else block + "<locked>true</locked>"
    path = tmp_path / "locked.osim"
    path.write_text(text[:knee] + locked + text[end:])
    r = scene_from_osim(path)
    assert [(j.name, j.kind) for j in r.scene.joints][:3] == [("hip_r", "hinge"), ("knee_r", "weld"),
                                                              ("ankle_r", "hinge")]
    assert "knee_angle_r" not in {c.name for c in r.scene.coordinates}
    assert any("'knee_angle_r' (rotation about [0.0, 0.0, 1.0]) locked in the model file" in line for line in r.report)


def test_bad_model_files_are_refused_in_one_line(tmp_path):
    bad = tmp_path / "bad.osim"
    bad.write_text("<OpenSimDocument Version='30000'><Model name='m'/></OpenSimDocument>")
    with pytest.raises(ValueError, match=r"format 30000; casflex reads format 4.x"):
        scene_from_osim(bad)
    bad.write_text("not xml")
    with pytest.raises(ValueError, match=r"bad.osim: not an OpenSim model \(XML"):
        scene_from_osim(bad)
    ankle = '<CustomJoint name="ankle_r">'
    ellipsoid = LEG.read_text().replace('<CustomJoint name="knee_r">', '<EllipsoidJoint name="knee_r">').replace(
        f"</CustomJoint>\n\t\t\t\t{ankle}", f"</EllipsoidJoint>\n\t\t\t\t{ankle}")
    bad.write_text(ellipsoid)
    with pytest.raises(ValueError, match=r"joint 'knee_r': a EllipsoidJoint is not read by casflex \(PinJoint"):
        scene_from_osim(bad)


def test_a_clamped_coordinate_s_range_is_its_limits_through_the_scene_file():
    from casflex.scene.coordinates import Coordinate
    from casflex.scene.items import SceneError

    sc = scene_from_osim(LEG).scene
    knee = next(c for c in sc.coordinates if c.name == "knee_angle_r")
    assert knee.limits == (-2.0943950999999998, 0.17453293)  # the file's clamped range, rad
    assert loads_scene(dumps_scene(sc)) == sc
    with pytest.raises(SceneError, match=r"coordinate 'q'\.limits: the lower limit must be below the upper"):
        Coordinate("q", "hip", limits=(0.5, 0.5))
    with pytest.raises(SceneError, match=r"limits: expected \[lower, upper\]"):
        Coordinate("q", "hip", limits=(0.5,))


def test_a_marker_on_a_massless_body_welded_to_a_massive_one_is_carried_by_it(tmp_path):
    # Hamner's calcaneus of mass 0 (welded to the talus: the subtalar joint locked): its four markers were left out
    # ("massless; left out"), the foot then had none and every trial was refused ("the markers do not decide
    # ['ankle_angle_r']"); OpenSim keeps them. Now on the talus's body where OpenSim puts them (at every pose: the
    # same rigid segment), said in the report
    import re

    text = re.sub(r'(<Body name="calcn_r">\s*<mass>)[^<]*', r"\g<1>0", LEG.read_text())
    path = tmp_path / "massless_calcn.osim"
    path.write_text(text)
    made, ref = scene_from_osim(path), scene_from_osim(LEG)
    assert [(m.label, m.x, m.y) for m in made.scene.markers] == [(m.label, m.x, m.y) for m in ref.scene.markers]
    assert {m.on for m in made.scene.markers if m.label in ("R.Heel", "R.Toe.Tip")} == {"talus_r"}
    assert "marker 'R.Heel': on 'calcn_r', massless, welded to 'talus_r': carried by it" in made.report
    model, model_ref = (inverse_model(s.scene) for s in (made, ref))
    from casflex.model.markers import marker_positions

    assert np.allclose(marker_positions(model, model.q0), marker_positions(model_ref, model_ref.q0), rtol=0, atol=1e-15)
