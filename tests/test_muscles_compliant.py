"""casflex.muscles.compliant: static optimization with each muscle's fibre and tendon in static equilibrium, on
Hamner's subject 02 running (the planar model's 92 Thelen muscles, tests/data/lab's trial to 0.6 s). OpenSim's own
equilibrium beside casflex's: tests/test_peers_opensim_muscles.py."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from casflex.cli import main
from casflex.inverse import Filter, Trial, prepare, solve
from casflex.muscles.analysis import TrialMuscles, reserve_actuators
from casflex.muscles.compliant import solve_compliant, tendon_equilibrium
from casflex.muscles.curves import rigid_tendon
from casflex.muscles.static_optimization import StaticOptimization, solve_static_optimization
from casflex.scene.from_osim import scene_from_osim

LAB = Path(__file__).parent / "data" / "lab"
MODEL = Path(__file__).parent / "data" / "muscles" / "hamner_subject02_planar_muscles.osim"


@pytest.fixture(scope="module")
def run():
    inputs = prepare(MODEL, Trial(LAB / "hamner_running_whole.trc", grf=LAB / "hamner_running_whole_grf.mot",
                                  plates={"calcn_r": "ground_", "calcn_l": "1_ground_"},
                                  tasks=LAB / "hamner_tasks_ik.xml", t_end=0.6), filter=Filter(10.0))
    res = solve(inputs)
    osim = scene_from_osim(MODEL, muscles=True)
    trial = TrialMuscles(osim, inputs.tree, res.t, res.plates, reserve_actuators(osim.scene, inputs.tree.root, 1.0),
                         joints=("hip_r", "knee_r", "ankle_r"))
    rigid = trial.solve(res.z, res.zd, res.zdd)
    compliant = trial.solve(res.z, res.zd, res.zdd, optimization=StaticOptimization(tendon="compliant"))
    return trial, rigid, compliant


def test_the_options_refuse_an_unknown_tendon_and_a_compliant_one_without_the_curves():
    with pytest.raises(ValueError, match="tendon: expected 'rigid' or 'compliant', got 'elastic'"):
        StaticOptimization(tendon="elastic")
    with pytest.raises(ValueError, match="tendon: 'compliant' needs force_length_velocity"):
        StaticOptimization(tendon="compliant", force_length_velocity=False)


def test_compliant_tendons_balance_every_joint_and_each_muscle_is_in_equilibrium(run):
    trial, _, out = run
    assert out.so.success and np.abs(out.so.violation).max() < 1e-6  # N m, IPOPT's tolerance on moments of 100s
    names = [m.name for m in trial.muscles]
    for name in ("soleus_r", "med_gas_r", "vas_int_r"):
        i = names.index(name)
        for k in (0, len(out.lengths) // 2, len(out.lengths) - 1):
            T, ln = tendon_equilibrium(trial.muscles[i], out.lengths[k, i], out.so.activations[k, i], passive=False)
            # the solved tendon force is the equilibrium's at its activation (1e-6 N: the tolerances on kN)
            assert abs(T - out.so.forces[k, i]) < 1e-6 * trial.muscles[i].max_isometric_force
            assert abs(ln - out.so.stats["norm_fiber_length"][k, i]) < 1e-6


def test_a_stiff_tendon_gives_the_rigid_tendons_forces(run):
    """With every tendon 1000 times stiffer (Thelen's FmaxTendonStrain 0.033 -> 3.3e-5) the compliant problem is the
    rigid one at the fibre velocity 0 (f_V = 1): forces within 0.5 % of each muscle's peak (measured 0.25 %: the
    tendons still stretch 3.3e-5 of their slack length at F_iso, 2e-4 of a 5 cm fibre's optimal length)."""
    trial, rigid, _ = run
    stiff = [dataclasses.replace(m, properties=(*(p for p in m.properties if p[0] != "FmaxTendonStrain"),
                                                ("FmaxTendonStrain", 3.3e-5))) for m in trial.muscles]
    reserves = np.array([trial.reserves[c.name].optimal_force if c.name in trial.reserves else 0.0
                         for c in trial.joint_coordinates])
    names = [c.name for c in trial.joint_coordinates]
    comp = solve_compliant(rigid.moments, rigid.arms, rigid.lengths, stiff, reserves,
                           StaticOptimization(tendon="compliant"), coordinates=names)
    active = np.column_stack([rigid_tendon(m, rigid.lengths[:, i], 0.0).active for i, m in enumerate(stiff)])
    rig = solve_static_optimization(rigid.moments, rigid.arms, active, None, reserves, trial.optimization,
                                    coordinates=names)
    peak = np.maximum(np.abs(rig.forces).max(axis=0), 1.0)
    assert (np.abs(comp.forces - rig.forces) / peak).max() < 5e-3


def test_compliant_tendons_change_the_calf_muscles_forces(run):
    """The long tendons stretch: the gastrocnemii's fibres work shorter (down to Thelen's active range's foot) and
    carry less, the soleus's more (measured on the run's first 0.6 s: docs/muscles.md)."""
    trial, rigid, comp = run
    names = [m.name for m in trial.muscles]
    ln = comp.so.stats["norm_fiber_length"]
    i = names.index("med_gas_r")
    stance = rigid.so.forces[:, i] > 0.5 * rigid.so.forces[:, i].max()
    rigid_fibre = np.column_stack([rigid_tendon(m, rigid.lengths[:, j], rigid.speeds[:, j]).norm_fiber_length
                                   for j, m in enumerate(trial.muscles)])
    assert (ln[stance, i] < rigid_fibre[stance, i]).all()  # the tendon stretched, the fibre shorter
    assert comp.so.forces[:, i].max() < rigid.so.forces[:, i].max()


def test_the_command_takes_tendon_compliant(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    trial = ["--data", str(LAB / "hamner_running_whole.trc"), "--loads", str(LAB / "hamner_running_whole_grf.mot"),
             "--plate", "calcn_r=ground_", "--plate", "calcn_l=1_ground_", "--tasks", str(LAB / "hamner_tasks_ik.xml"),
             "--cutoff", "10", "--t-end", "0.4"]
    assert main(["muscles", str(MODEL), *trial, "--reserves", "1", "--tendon", "compliant", "--joints", "hip_r",
                 "--out", str(out), "--quiet"]) == 0
    assert (out / "hamner_running_whole_StaticOptimization_force.sto").exists()
    code = main(["muscles", str(MODEL), *trial, "--tendon", "compliant", "--no-force-length-velocity",
                 "--out", str(tmp_path / "o2"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "--tendon: 'compliant' needs force_length_velocity" in err


def _soleus():
    return next(m for m in scene_from_osim(MODEL, muscles=True).muscles if m.name == "soleus_r")


def test_a_muscle_shorter_than_its_tendon_carries_nothing_and_a_moment_out_of_reach_is_refused():
    m = _soleus()
    lmt = np.array([[0.9 * m.tendon_slack_length], [m.tendon_slack_length + m.optimal_fiber_length]])
    arms = np.full((2, 1, 1), -0.05)
    out = solve_compliant(np.array([[0.0], [-20.0]]), arms, lmt, [m], np.array([1.0]),
                          StaticOptimization(tendon="compliant"), coordinates=["ankle_angle_r"])
    assert out.forces[0, 0] == 0.0 and out.stats["slack"][0, 0] and not out.stats["slack"][1, 0]
    assert out.forces[1, 0] > 0 and np.abs(out.violation).max() < 1e-6
    with pytest.raises(ValueError, match=r"static optimization \(compliant tendons\): IPOPT stopped \("):
        solve_compliant(np.array([[-1e5]]), arms[:1], lmt[1:], [m], None, StaticOptimization(tendon="compliant"),
                        coordinates=["ankle_angle_r"])


def test_the_command_refuses_bands_with_compliant_tendons(tmp_path, capsys):
    code = main(["muscles", str(MODEL), "--data", str(LAB / "hamner_running_whole.trc"), "--loads",
                 str(LAB / "hamner_running_whole_grf.mot"), "--plate", "calcn_r=ground_", "--plate",
                 "calcn_l=1_ground_", "--tasks", str(LAB / "hamner_tasks_ik.xml"), "--tendon", "compliant",
                 "--muscle-uncertainty", "max_isometric_force=10%", "--out", str(tmp_path / "o"), "--quiet"])
    err = [ln for ln in capsys.readouterr().err.splitlines() if not ln.startswith("casflex: warning: ")]
    assert code == 2 and len(err) == 1 and "--tendon: 'compliant' takes no bands yet" in err[0], err
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_the_equilibrium_of_a_muscle_too_short_for_one_is_its_slack_tendon():
    # just above its tendon slack length, at half activation, the fibre cannot shorten enough to be in equilibrium:
    # the tendon is slack (force 0, the fibre at its shortest), as well below it; IPOPT's infeasible iterate was
    # returned (15.5 N, no equilibrium)
    m = _soleus()
    below = tendon_equilibrium(m, 0.9 * m.tendon_slack_length, 0.5)
    assert below[0] == 0.0 and tendon_equilibrium(m, 1.01 * m.tendon_slack_length, 0.5) == below
    T, ln = tendon_equilibrium(m, m.tendon_slack_length + m.optimal_fiber_length, 0.5)
    assert T > 0.0 and ln > below[1]  # stretched: an equilibrium, its fibre longer


def test_an_equilibrium_ipopt_stops_on_with_a_search_direction_too_small_is_taken():
    # Hamner's add_brev_l at 0.13872976421448543 m and activation 0.3 (a pose of the peers' comparison with OpenSim's
    # equilibrateMuscles): IPOPT, asked for 1e-14, stops with Search_Direction_Becomes_Too_Small on the root (the
    # forces 1.2e-14 F_iso apart), which was refused as "no equilibrium" (21 of the comparison's 330 on this machine)
    import casadi as ca

    from casflex.muscles.compliant import _frame_terms

    model = Path(__file__).parent / "data" / "muscles" / "hamner_subject02_planar_muscles.osim"
    (m,) = [m for m in scene_from_osim(model, muscles=True).muscles if m.name == "add_brev_l"]
    lmt = 0.13872976421448543
    T, ln = tendon_equilibrium(m, lmt, 0.3)
    tendon, fibre = (float(ca.evalf(e)) for e in _frame_terms(m, lmt, 0.3, ln, True))
    assert T > 0.0 and T == pytest.approx(tendon, abs=1e-9) and abs(fibre - tendon) <= 1e-9 * m.max_isometric_force
