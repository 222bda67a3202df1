"""The muscles of a trial end to end (casflex.muscles.analysis) on Hamner's subject 02 running (the planar model
with its 92 Thelen muscles, the trial's markers and both plates): static optimization balances every joint, the
root goes to the residuals, the reactions are the cut's net loads less the muscles', the files carry OpenSim's
labels. Against OpenSim 4.6's own StaticOptimization and JointReaction on the same files:
tests/test_peers_opensim_muscle_trials.py (the peers extra)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from casflex.inverse import Filter, Trial, prepare, solve
from casflex.lab.tables import read_sto
from casflex.muscles.analysis import TrialMuscles, muscle_result, reserve_actuators
from casflex.muscles.cut import joint_loads
from casflex.muscles.reaction import JointReaction
from casflex.scene.from_osim import scene_from_osim

LAB = Path(__file__).parent / "data" / "lab"
MODEL = Path(__file__).parent / "data" / "muscles" / "hamner_subject02_planar_muscles.osim"
JOINTS = ("hip_r", "knee_r", "ankle_r")


@pytest.fixture(scope="module")
def run():
    inputs = prepare(MODEL, Trial(LAB / "hamner_running_whole.trc", grf=LAB / "hamner_running_whole_grf.mot",
                                  plates={"calcn_r": "ground_", "calcn_l": "1_ground_"},
                                  tasks=LAB / "hamner_tasks_ik.xml"), filter=Filter(10.0))
    res = solve(inputs)
    osim = scene_from_osim(MODEL, muscles=True)
    trial = TrialMuscles(osim, inputs.tree, res.t, res.plates, reserve_actuators(osim.scene, inputs.tree.root, 1.0),
                         reaction=JointReaction(on="child", frame="ground"), joints=JOINTS)
    return osim, res, trial, trial.solve(res.z, res.zd, res.zdd)


def test_static_optimization_balances_every_joint_and_the_residuals_the_root(run):
    """The joints' moments carried by muscles and reserves to the QP's tolerance (1e-6 N m on moments of
    hundreds); the root's three loads by FX, FY, MZ exactly (three actuators, three coordinates)."""
    _, res, trial, out = run
    assert out.so.success and np.abs(out.so.violation).max() < 1e-6
    assert [a.name for a in trial.residuals] == ["FX", "FY", "MZ"]
    from casflex.muscles.actuators import actuator_columns

    root = np.column_stack([res.loads[f"{c.name}_{'force' if c.translational else 'moment'}"]
                            for c in trial.root_coordinates])
    rows = [list(trial.scene.coordinates).index(c) for c in trial.root_coordinates]
    A = actuator_columns(trial.tree, trial.scene, tuple(trial.residuals), trial.osim.frames, res.z)[:, rows, :]
    assert np.abs(np.einsum("kca,ka->kc", A, out.residuals) - root).max() < 1e-6


def test_the_reactions_are_the_cuts_net_loads_less_the_muscles(run):
    """An independent route for the force: Newton-Euler of the part beyond each joint (casflex.muscles.cut) less
    each muscle's tension along its path's segments that cross the joint (1e-6 N: round-off on kN)."""
    osim, res, trial, out = run
    net = joint_loads(trial.scene, res.dof_names, res.q, res.qd, res.qdd, res.t, res.plates)
    k, n_m = res.t.size, len(trial.muscles)
    unit = np.array(trial.paths.unit_loads.map(k)(res.z.T)).reshape(-1, n_m, k, order="F").transpose(2, 0, 1)
    for joint in JOINTS:
        i = trial.tree.hinges.index(joint)
        muscles = np.einsum("krm,km->kr", unit[:, 3 * i:3 * i + 2, :], out.so.forces)
        want = net[joint][:, :2] - muscles
        assert np.abs(out.reactions[joint].loads[:, 0, :2] - want).max() < 1e-6, joint


def test_the_files_are_named_and_labelled_as_opensims(run, tmp_path):
    from casflex.muscles.result import file_names

    _, res, trial, out = run
    result = muscle_result(trial, out, res.z)
    written = result.save(tmp_path, "run")
    assert [p.name for p in written] == list(file_names("run"))
    jr = read_sto(tmp_path / "run_JointReaction_ReactionLoads.sto")
    assert jr.names[:9] == tuple(f"hip_r_on_femur_r_in_ground_{c}" for c in
                                 ("fx", "fy", "fz", "mx", "my", "mz", "px", "py", "pz"))
    so = read_sto(tmp_path / "run_StaticOptimization_force.sto")
    assert so.names[:len(trial.muscles)] == tuple(m.name for m in trial.muscles) and "FX" in so.names
    text = result.summary()
    assert text.splitlines()[1].startswith("  hip_r: ") and "BW" in text


def test_the_figures_are_written(run, tmp_path):
    from casflex.plotting.muscles import FIGURES, save_muscle_figures

    _, res, trial, out = run
    paths = save_muscle_figures(muscle_result(trial, out, res.z), tmp_path)
    assert [p.name for p in paths] == list(FIGURES) and all(p.stat().st_size > 10_000 for p in paths)


@pytest.mark.parametrize(("change", "said"), [
    # the tendon longer than the path: each gave exit 0, the soleus carrying nothing and the reserves 31 % of the
    # ankle's moment in its place
    ({"tendon_slack_length": 2.0}, r"at full activation it pulls at most 0 % of its max isometric force over the "
                                   r"trial \(its path 0.3\d\d-0.3\d\d m long, shorter than its tendon slack length 2 m "
                                   r"at every frame\)"),
    ({"optimal_fiber_length": 5.0}, r"at full activation it pulls at most 0 % .* its fibre 0.425-0.425 optimal "
                                    r"fibre lengths \(5 m\)\)"),
    # a fibre of 1 um stretched to 6e4 optimal lengths: refused as "passive: not finite at (0, 33)", naming nothing
    ({"optimal_fiber_length": 1e-6}, r"its passive force is not finite at t = 0.2 s .* its fibre 2.64e\+04-6.8e\+04 "
                                     r"optimal fibre lengths \(1e-06 m\)\)"),
])
def test_a_muscle_that_cannot_pull_in_the_trial_is_refused_naming_it(run, change, said):
    import dataclasses

    osim, res, trial, _ = run
    muscles = tuple(dataclasses.replace(m, **change) if m.name == "soleus_r" else m for m in osim.muscles)
    weak = TrialMuscles(dataclasses.replace(osim, muscles=muscles), trial.tree, res.t, res.plates,
                        reserve_actuators(osim.scene, trial.tree.root, 1.0), joints=JOINTS)
    with pytest.raises(ValueError, match=rf"^{MODEL}: ForceSet: Thelen2003Muscle 'soleus_r': {said}: check its "
                                         "tendon_slack_length, optimal_fiber_length and path points$"):
        weak.solve(res.z, res.zd, res.zdd)


def test_a_residual_whose_bounds_the_roots_balance_exceeds_is_refused(run):
    """The residuals carry the root's loads whole (no muscle reaches it): FX bounded to +-10 N wrote -71.6 N and
    more at 56 of the 61 frames, outside its bounds, with exit 0; wide bounds change nothing."""
    import dataclasses

    osim, res, trial, out = run
    acts = reserve_actuators(osim.scene, trial.tree.root, 1.0)
    for bound, refused in ((10.0, True), (1e4, False)):
        bounded = tuple(dataclasses.replace(a, min_control=-bound, max_control=bound) if a.name == "FX" else a
                        for a in acts)
        tm = TrialMuscles(osim, trial.tree, res.t, res.plates, bounded, joints=JOINTS, source="reserves.xml")
        if refused:
            said = (r"^reserves.xml: PointActuator 'FX': the root's balance \(the inverse dynamics' residual\) "
                    r"needs a control of -?\d+\.?\d* at t = [\d.]+ s, outside its bounds \[-10, 10\] "
                    r"\(\d+ of 61 frames\)")
            with pytest.raises(ValueError, match=said):
                tm.solve(res.z, res.zd, res.zdd)
        else:
            assert np.array_equal(tm.solve(res.z, res.zd, res.zdd).residuals, out.residuals)


def test_a_bad_curve_property_is_refused_naming_the_model_before_the_work(run):
    """Thelen's FmaxTendonStrain of 0: refused once static optimization had begun, after the marker fit and the
    inverse dynamics, without the file's name; now when the trial's muscles are made."""
    import dataclasses

    osim, res, trial, _ = run
    muscles = tuple(dataclasses.replace(m, properties=(("FmaxTendonStrain", 0.0), *m.properties))
                    if m.name == "soleus_r" else m for m in osim.muscles)
    with pytest.raises(ValueError, match=rf"^{MODEL}: muscle 'soleus_r'.FmaxTendonStrain: must be > 0, got 0$"):
        TrialMuscles(dataclasses.replace(osim, muscles=muscles), trial.tree, res.t, res.plates)


def _own(osim, props: dict, kind=None):
    """``osim`` with soleus_r's and med_gas_r's properties ``props`` added (and their kind ``kind``)."""
    import dataclasses

    muscles = tuple(dataclasses.replace(m, properties=(*props.get(m.name, ()), *m.properties), kind=kind or m.kind)
                    if m.name in props else m for m in osim.muscles)
    return dataclasses.replace(osim, muscles=muscles)


def test_a_muscles_own_activation_bounds_bound_it_as_opensims_static_optimization(run):
    """OpenSim's SO bounds each muscle by its own min_control / max_control (StaticOptimization.cpp, record: each
    actuator's getMinControl, getMaxControl): a max_control of 0.5 was refused (before: ignored, exit 0); now the
    soleus stops at 0.5 where it reached 1, the gastrocnemius stays at or above its min_control 0.05, the others
    keep [0.01, 1] (the activation bounds), and the report says which muscles have their own."""
    osim, res, trial, out = run
    i, j = ([m.name for m in trial.muscles].index(n) for n in ("soleus_r", "med_gas_r"))
    assert out.so.activations[:, i].max() > 0.9 and out.so.activations[:, j].min() < 0.02  # the bounds will act
    own = _own(osim, {"soleus_r": (("max_control", 0.5),), "med_gas_r": (("min_control", 0.05),)})
    tm = TrialMuscles(own, trial.tree, res.t, res.plates, reserve_actuators(osim.scene, trial.tree.root, 1.0),
                      joints=JOINTS)
    bounded = tm.solve(res.z, res.zd, res.zdd)
    a = bounded.so.activations
    assert bounded.so.success and np.abs(bounded.so.violation).max() < 1e-6
    assert a[:, i].max() == pytest.approx(0.5, abs=1e-8) and a[:, j].min() == pytest.approx(0.05, abs=1e-8)
    others = np.ones(a.shape[1], dtype=bool)
    others[[i, j]] = False
    assert a[:, others].min() >= 0.01 - 1e-9 and a[:, others].max() > 0.9
    assert "muscles med_gas_r [0.05, 1], soleus_r [0.01, 0.5] bounded by their own min_control / max_control" in \
        " ".join(tm.notes)
    assert not any("their own" in line for line in trial.notes)


@pytest.mark.parametrize(("props", "kind", "said"), [
    # OpenSim refuses a Millard muscle's minimum_activation below 0; casflex ignored it
    ((("minimum_activation", -0.5),), "Millard2012EquilibriumMuscle",
     r"Millard2012EquilibriumMuscle 'soleus_r'.minimum_activation: must be in \[0, 1\)"),
    # OpenSim refuses a min_control below the muscle's minimum_activation
    ((("min_control", 0.02), ("minimum_activation", 0.05)), None,
     r"'soleus_r'.min_control: 0.02 is below its minimum_activation 0.05 \(OpenSim refuses the model\)"),
    # an activation above 1 is a force above the muscle's (--activation-bounds' refusal, per muscle)
    ((("max_control", 2.0),), None, r"'soleus_r'.max_control: its activation bounds would be \[0.01, 2\]"),
    ((("min_control", 0.6), ("max_control", 0.5)), None, r"'soleus_r'.max_control: its activation bounds would be "
                                                          r"\[0.6, 0.5\]"),
])
def test_a_muscles_own_activation_bounds_no_activation_can_take_are_refused(run, props, kind, said):
    osim, res, trial, _ = run
    with pytest.raises(ValueError, match=rf"^{MODEL}: ForceSet: .*{said}"):
        TrialMuscles(_own(osim, {"soleus_r": props}, kind), trial.tree, res.t, res.plates)
    # a minimum_activation above the activation bounds' lower raises the muscle's: its activation cannot go below
    tm = TrialMuscles(_own(osim, {"soleus_r": (("minimum_activation", 0.05),)}), trial.tree, res.t, res.plates)
    assert tm.optimization.bounds(len(tm.muscles))[0][[m.name for m in tm.muscles].index("soleus_r")] == 0.05


def test_residuals_that_carry_the_body_are_said(run):
    """The run without its plates: the residual FY carries the body's weight (1.4 BW RMS) and the hip's contact
    force peaks at half its value with them, exit 0 without a word; with the plates, FY carries 0.19 BW (RMS)."""
    from casflex.muscles.analysis import residual_warnings

    osim, res, trial, out = run
    assert residual_warnings(trial, out) == []
    bare = TrialMuscles(osim, trial.tree, res.t, (), reserve_actuators(osim.scene, trial.tree.root, 1.0),
                        joints=JOINTS)
    (line,) = residual_warnings(bare, bare.solve(res.z, res.zd, res.zdd))
    assert line.startswith("residual 'FY' carries 1.") and "the ground reactions are missing" in line, line


def test_a_muscle_that_crosses_no_coordinate_of_the_plane_is_said(run):
    """Both its ends on one segment (or only on coordinates the plane holds still): it carries nothing and its
    activation stays at the lower bound; exit 0 without a word before. The run's own muscles all cross one."""
    import dataclasses

    _, res, trial, out = run
    assert not any("cross no coordinate" in line for line in muscle_result(trial, out, res.z).report)
    i = [m.name for m in trial.muscles].index("soleus_r")
    arms = out.arms.copy()
    arms[:, i, :] = 0.0
    report = muscle_result(trial, dataclasses.replace(out, arms=arms), res.z).report
    assert "muscles soleus_r cross no coordinate of the plane (moment arms 0 at every frame)" in report[-1]


def test_coordinates_nothing_acts_on_are_known_from_the_model_and_refused_at_the_solve(run):
    """Without reserves the arms' coordinates have nothing to carry their moments: known at the model's default pose
    (what a study checks before any run) and refused when the trial is solved."""
    osim, res, trial, _ = run
    bare = TrialMuscles(osim, trial.tree, res.t, res.plates, joints=JOINTS)
    names = [c.name for c, b in zip(bare.joint_coordinates, bare.bare_coordinates(), strict=True) if b]
    assert names == ["arm_flex_r", "arm_flex_l", "elbow_flex_r", "elbow_flex_l"]
    assert not any(trial.bare_coordinates())  # the reserves act on every coordinate
    with pytest.raises(ValueError, match=r"^arm_flex_r, arm_flex_l, elbow_flex_r, elbow_flex_l: no muscle crosses it "
                                         r"and no reserve acts on it"):
        bare.solve(res.z, res.zd, res.zdd)


def test_a_degroote_muscle_s_default_lower_bound_is_0_as_opensim_s(run):
    """OpenSim 4.6 gives a DeGrooteFregly2016Muscle without its own min_control 0 (a new muscle's
    finalizeFromProperties(); getMinControl()), a Millard's or Thelen's 0.01: casflex gave every muscle the
    activation bounds' 0.01, a DeGroote model's SO differing from OpenSim's. Now each kind's default, said; given
    activation bounds (--activation-bounds 0.02:1) still bound every muscle without its own; a Thelen model's bounds
    unchanged (none set per muscle)."""
    import dataclasses

    from casflex.muscles.static_optimization import StaticOptimization

    osim, res, trial, _ = run
    assert not trial.optimization.muscle_bounds and trial.optimization.bounds(3)[0].tolist() == [0.01] * 3  # Thelen
    dg = dataclasses.replace(osim, muscles=tuple(dataclasses.replace(m, kind="DeGrooteFregly2016Muscle")
                                                 if m.name in ("soleus_r", "med_gas_r") else m for m in osim.muscles))
    names = [m.name for m in dg.muscles]
    i, j, k = (names.index(n) for n in ("soleus_r", "med_gas_r", "tib_ant_r"))
    tm = TrialMuscles(dg, trial.tree, res.t, res.plates)
    lo, hi = tm.optimization.bounds(len(names))
    assert (lo[i], lo[j], lo[k]) == (0.0, 0.0, 0.01) and hi.min() == 1.0
    assert "muscles med_gas_r [0, 1], soleus_r [0, 1] bounded by their kind's OpenSim default" in " ".join(tm.notes)
    tm = TrialMuscles(dg, trial.tree, res.t, res.plates, optimization=StaticOptimization(activation_bounds=(0.02, 1)))
    lo, hi = tm.optimization.bounds(len(names))
    assert lo.tolist() == [0.02] * len(names) and hi.tolist() == [1.0] * len(names)
    own = _own(dg, {"soleus_r": (("min_control", 0.05),)})  # a muscle's own still wins
    assert TrialMuscles(own, trial.tree, res.t, res.plates).optimization.bounds(len(names))[0][i] == 0.05
