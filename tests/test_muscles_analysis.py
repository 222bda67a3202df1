"""The muscles of a trial end to end (casflex.muscles.analysis): casflex's inverse dynamics of OpenSim's own
Gait10dof18musc walk, its muscles' paths and curves, static optimization and joint reactions, against OpenSim 4.6's
StaticOptimization and JointReaction on the same model, coordinates, ground reactions and reserves (the reference
files: tests/data/muscles/README_opensim_runs.md)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from casflex.inverse import Filter, Trial, prepare, solve
from casflex.lab.tables import read_sto
from casflex.muscles.analysis import TrialMuscles
from casflex.muscles.reaction import JointReaction
from casflex.scene.from_osim import scene_from_osim
from casflex.scene.osim_actuators import read_actuators

DATA = Path(__file__).parent / "data" / "muscles"
MODEL = DATA / "gait10dof18musc_subject01.osim"
JOINTS = (("hip_r", "femur_r"), ("knee_r", "tibia_r"), ("ankle_r", "talus_r"))


@pytest.fixture(scope="module")
def walk():
    inputs = prepare(MODEL, Trial(coordinates=DATA / "subject01_walk_IK.mot", grf=DATA / "subject01_walk_grf.xml"),
                     filter=Filter(6.0, None, "opensim"))
    res = solve(inputs)
    osim = scene_from_osim(MODEL, muscles=True)
    trial = TrialMuscles(osim, inputs.tree, res.t, res.plates, read_actuators(DATA / "gait10dof_Reserve_Actuators.xml"),
                         reaction=JointReaction(on="child", frame="child"), joints=tuple(j for j, _ in JOINTS))
    return osim, res, trial, trial.solve(res.z, res.zd, res.zdd)


def _at(table, t, names):
    return np.column_stack([np.interp(t, table.t, table.column(n)) for n in names])


def test_muscle_forces_are_opensims_within_2_percent_of_each_peak(walk):
    """The issue's bar, 2 % of each muscle's peak force (RMS over the trial); measured 0.4 % (rect_fem_r): two
    inverse dynamics (casflex's and OpenSim's splines of the same coordinates) and OpenSim's SO tolerance 1e-4."""
    osim, res, _, out = walk
    names = [m.name for m in osim.muscles]
    theirs = _at(read_sto(DATA / "gait10dof18musc_so_force.sto"), res.t, names)
    rms = np.sqrt(np.mean((out.so.forces - theirs) ** 2, axis=0))
    assert out.so.success and (rms < 0.02 * np.abs(theirs).max(axis=0)).all(), dict(zip(names, rms, strict=True))


def test_hip_knee_and_ankle_reactions_are_opensims_within_2_percent_of_peak(walk):
    """On the child, in the child's frame: the force within 2 % of its peak (RMS; measured 0.07 %) and the moment
    about the plane's normal (the reserves': a few N m) within 0.5 N m (measured 0.01)."""
    _, res, _, out = walk
    jr = read_sto(DATA / "gait10dof18musc_jr.sto")
    for joint, body in JOINTS:
        theirs = _at(jr, res.t, [f"{joint}_on_{body}_in_{body}_{c}" for c in ("fx", "fy", "mz")])
        ours = out.reactions[joint].loads[:, 0, :]
        rms = np.sqrt(np.mean((ours - theirs) ** 2, axis=0))
        assert (rms[:2] < 0.02 * np.abs(theirs[:, :2]).max()).all() and rms[2] < 0.5, (joint, rms)


def test_the_root_is_the_residual_actuators_and_the_muscles_reach_no_root_coordinate(walk):
    _, res, trial, out = walk
    assert [a.name for a in trial.residuals] == ["FX", "FY", "MZ"]
    so = read_sto(DATA / "gait10dof18musc_so_force.sto")
    theirs = _at(so, res.t, ["FX", "FY", "MZ"])
    forces = out.residuals * np.array([a.optimal_force for a in trial.residuals])
    assert np.sqrt(np.mean((forces - theirs) ** 2, axis=0)).max() < 0.02 * np.abs(theirs).max()
    assert [c.name for c in trial.joint_coordinates][0] == "hip_flexion_r"


def test_the_files_are_named_and_labelled_as_opensims_and_say_what_opensims_say(walk, tmp_path):
    from casflex.muscles.analysis import muscle_result
    from casflex.muscles.result import file_names

    osim, res, trial, out = walk
    result = muscle_result(trial, out, res.z)
    written = result.save(tmp_path, "walk")
    assert [p.name for p in written] == list(file_names("walk"))
    for ours, theirs in (("walk_StaticOptimization_force.sto", "gait10dof18musc_so_force.sto"),
                         ("walk_JointReaction_ReactionLoads.sto", "gait10dof18musc_jr.sto")):
        a, b = read_sto(tmp_path / ours), read_sto(DATA / theirs)
        assert set(a.names) <= set(b.names)  # OpenSim's labels (its force file adds the plates' columns)
    jr = read_sto(tmp_path / "walk_JointReaction_ReactionLoads.sto")
    ref = read_sto(DATA / "gait10dof18musc_jr.sto")
    for c in ("knee_r_on_tibia_r_in_tibia_r_px", "knee_r_on_tibia_r_in_tibia_r_py"):  # m: exact geometry
        assert np.abs(jr.column(c) - _at(ref, res.t, [c])[:, 0]).max() < 1e-6
    text = result.summary()
    assert text.splitlines()[1].startswith("  hip_r: ") and "BW" in text
    assert "no muscle crosses lumbar_extension" in text


def test_the_figures_are_written(walk, tmp_path):
    from casflex.muscles.analysis import muscle_result
    from casflex.plotting.muscles import FIGURES, save_muscle_figures

    _, res, trial, out = walk
    paths = save_muscle_figures(muscle_result(trial, out, res.z), tmp_path)
    assert [p.name for p in paths] == list(FIGURES) and all(p.stat().st_size > 10_000 for p in paths)
