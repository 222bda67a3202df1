"""Reserve and residual actuators: OpenSim's actuator files read, refused where they cannot be honoured, and their
generalised forces along the scene's coordinates checked against the virtual work done by finite displacement."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from casflex.inverse import inverse_model, kinematic_tree
from casflex.muscles.actuators import actuator_columns, check_actuators
from casflex.scene.from_osim import scene_from_osim
from casflex.scene.osim_actuators import Actuator, read_actuators

DATA = Path(__file__).parent / "data" / "muscles"
MODEL = DATA / "gait10dof18musc.osim"
RESERVES = DATA / "gait10dof_Reserve_Actuators.xml"


@pytest.fixture(scope="module")
def leg():
    osim = scene_from_osim(MODEL)
    return osim, kinematic_tree(inverse_model(osim.scene))


def test_the_pipelines_reserve_file_is_read_as_opensim_writes_it():
    acts = read_actuators(RESERVES)
    kinds = {a.name: a.kind for a in acts}
    assert kinds["FX"] == "PointActuator" and kinds["MZ"] == "TorqueActuator"
    assert sum(k == "CoordinateActuator" for k in kinds.values()) == 7
    fy = next(a for a in acts if a.name == "FY")
    assert (fy.optimal_force, fy.body, fy.point, fy.force_is_global) == (2.0, "pelvis", (-0.034, 0.0, 0.0), True)
    assert math.isinf(fy.min_control) and fy.min_control < 0


def _pelvis_point(tree, osim, z, point):
    """Ground position (x, y) of the pelvis station at ``point`` (its frame) in the pose z, by the tree's forward
    kinematics (independent of the module under test: numbers only)."""
    q = np.array(tree.forward(z)).ravel()
    dofs = tree.model.dof_names
    x, y, th = (q[dofs.index(f"{k}pelvis")] for k in ("x", "y", "theta"))
    R, p = osim.frames["pelvis"]
    node = osim.scene.nodes[0]
    rel = (p + R @ np.asarray(point))[:2] - np.array([node.x, node.y])
    d = th - node.theta
    return np.array([x, y]) + np.array([[math.cos(d), -math.sin(d)], [math.sin(d), math.cos(d)]]) @ rel


def test_a_point_actuator_does_the_virtual_work_of_its_force(leg):
    """Q_c = F . dP/dc: the columns equal central differences of the point's position (1e-7 step: error ~1e-10)."""
    osim, tree = leg
    act = Actuator("push", "PointActuator", 3.0, body="pelvis", point=(-0.034, 0.02, 0.0), direction=(1.0, 2.0, 0.0),
                   force_is_global=True)
    rng = np.random.default_rng(4)
    z = rng.uniform(-0.5, 0.5, tree.n)
    cols = actuator_columns(tree, osim.scene, (act,), osim.frames, z[None])[0, :, 0]
    F = 3.0 * np.array([1.0, 2.0]) / math.sqrt(5.0)
    for i, c in enumerate(osim.scene.coordinates):
        k = tree.names.index(c.of if "." in c.of else f"{c.of}.angle")
        dz = np.zeros(tree.n)
        dz[k] = 1e-7 * c.sign
        dP = (_pelvis_point(tree, osim, z + dz, act.point) - _pelvis_point(tree, osim, z - dz, act.point)) / 2e-7
        assert cols[i] == pytest.approx(F @ dP, abs=1e-7), c.name


def test_coordinate_and_torque_actuators_act_on_their_coordinates_only(leg):
    osim, tree = leg
    acts = read_actuators(RESERVES)
    cols = actuator_columns(tree, osim.scene, acts, osim.frames, np.zeros((1, tree.n)))[0]
    names = [c.name for c in osim.scene.coordinates]
    hip = [a.name for a in acts].index("hip_flexion_r_reserve")
    assert cols[:, hip] == pytest.approx(np.eye(len(names))[names.index("hip_flexion_r")])
    mz = [a.name for a in acts].index("MZ")  # a torque on the pelvis against the ground turns the pelvis only
    assert cols[:, mz] == pytest.approx(np.eye(len(names))[names.index("pelvis_tilt")])


def _write(tmp_path, body: str) -> Path:
    p = tmp_path / "acts.xml"
    p.write_text(f'<?xml version="1.0"?><OpenSimDocument Version="40000"><ForceSet name="a"><objects>{body}'
                 "</objects></ForceSet></OpenSimDocument>")
    return p


@pytest.mark.parametrize(("body", "message"), [
    ("<CoordinateActuator name='r'><coordinate>hip_flexion_r</coordinate><optimal_force>0</optimal_force>"
     "</CoordinateActuator>", "CoordinateActuator 'r': optimal_force: must be > 0"),
    ("<CoordinateActuator name='r'><coordinate>hip_flexion_r</coordinate><optimal_force>nan</optimal_force>"
     "</CoordinateActuator>", "optimal_force: expected 1 number, got 'nan'"),
    ("<CoordinateActuator name='r'><coordinate>hip_flexion_r</coordinate><min_control>2</min_control>"
     "<max_control>1</max_control></CoordinateActuator>", "min_control: 2 is above max_control 1"),
    ("<PathActuator name='p'/>", "PathActuator 'p': not read by casflex"),
    ("<CoordinateActuator name='r'><coordinate>hip_flexion_r</coordinate></CoordinateActuator>"
     "<CoordinateActuator name='r'><coordinate>knee_angle_r</coordinate></CoordinateActuator>",
     "two actuators named 'r'"),
    ("<PointActuator name='p'><body>pelvis</body><direction>0 0 0</direction></PointActuator>",
     "PointActuator 'p': direction: is zero"),
    # read first-wins without a word before (OpenSim too): which one counts would be a guess
    ("<CoordinateActuator name='r'><coordinate>hip_flexion_r</coordinate><optimal_force>1</optimal_force>"
     "<optimal_force>100</optimal_force></CoordinateActuator>", "CoordinateActuator 'r': optimal_force: given 2 "
     "times; give it once"),
])
def test_an_actuator_file_that_cannot_be_honoured_is_refused_by_name(tmp_path, body, message):
    with pytest.raises(ValueError, match=re.escape(message)) as err:
        read_actuators(_write(tmp_path, body))
    assert str(err.value).startswith(str(tmp_path / "acts.xml") + ": ") and "\n" not in str(err.value)


def test_an_actuator_on_a_missing_coordinate_or_body_is_refused(leg, tmp_path):
    osim, _ = leg
    acts = read_actuators(_write(tmp_path, "<CoordinateActuator name='r'><coordinate>hip_flexion_x</coordinate>"
                                           "</CoordinateActuator>"))
    with pytest.raises(ValueError, match="CoordinateActuator 'r': coordinate: no coordinate 'hip_flexion_x'"):
        check_actuators(acts, osim.scene, "acts.xml")
    acts = read_actuators(_write(tmp_path, "<PointActuator name='p'><body>thorax</body></PointActuator>"))
    with pytest.raises(ValueError, match="PointActuator 'p': body: no body 'thorax'"):
        check_actuators(acts, osim.scene, "acts.xml")
    acts = read_actuators(_write(tmp_path, "<CoordinateActuator name='r'><coordinate>subtalar_angle_r</coordinate>"
                                           "</CoordinateActuator>"))
    assert "holds still" in check_actuators(acts, osim.scene, "acts.xml", model_coordinates={"subtalar_angle_r"})[0]


def test_an_actuator_named_as_a_muscle_or_another_actuator_is_refused(leg, tmp_path):
    """The results hold one column per name: a reserve named as a muscle wrote its control (up to 21.8) in the
    muscle's activation column, with exit 0; two actuators of one name (the model's and the file's) lost one."""
    osim, _ = leg
    acts = read_actuators(_write(tmp_path, "<CoordinateActuator name='soleus_r'><coordinate>hip_flexion_r"
                                           "</coordinate></CoordinateActuator>"))
    check_actuators(acts, osim.scene, "acts.xml")  # the muscles' names not given: nothing to compare
    with pytest.raises(ValueError, match=r"^acts.xml: CoordinateActuator 'soleus_r': a muscle of the model has that "
                                         r"name; give the actuator its own"):
        check_actuators(acts, osim.scene, "acts.xml", muscles=["hamstrings_r", "soleus_r"])
    with pytest.raises(ValueError, match=r"^acts.xml: two actuators named 'soleus_r' \(the model's and the file's"):
        check_actuators(acts + acts, osim.scene, "acts.xml")

def test_written_actuators_read_back_as_they_were(tmp_path):
    """write_actuators (a study's reserves) writes what read_actuators reads back field for field: the pipeline's
    file through both, and infinite control bounds."""
    from casflex.scene.osim_actuators import write_actuators

    acts = read_actuators(RESERVES)
    assert {a.kind for a in acts} == {"PointActuator", "TorqueActuator", "CoordinateActuator"}
    assert read_actuators(write_actuators(tmp_path / "a.xml", acts)) == acts
    with pytest.raises(ValueError, match="'m': kind 'Thelen2003Muscle'"):
        write_actuators(tmp_path / "b.xml", [Actuator("m", "Thelen2003Muscle", 1.0)])
