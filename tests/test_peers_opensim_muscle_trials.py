"""casflex's muscle path (casflex.muscles.analysis.TrialMuscles) against OpenSim 4.6's StaticOptimization and
JointReaction on a second public trial: Hamner's subject 02 running (tests/data/lab's excerpt, 61 frames at 60 Hz,
both stances), the subject's model made planar with its 92 Thelen2003Muscle muscles
(tests/data/muscles/hamner_subject02_planar_muscles.osim), OpenSim's IK of the excerpt on that model, the plates as
the pipeline's External_Loads.xml assigns them, a CoordinateActuator reserve of 1 N m on each free coordinate but
the pelvis's and FX, FY, MZ residuals on the pelvis. Both tools read the same files (studies/opensim_muscles.py runs
the same comparison and says what the numbers mean: docs/studies/opensim_muscles.md).

OpenSim's SO at its defaults (100 iterations) stops short at some frames (its log: "OPTIMIZATION FAILED ... could
not find a solution", 9 of the 61 frames here; recorded anyway, and what it records there depends on the
actuators' order in the force set): the comparison is over the frames it solved."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

needs_opensim = pytest.mark.skipif(importlib.util.find_spec("opensim") is None, reason="OpenSim is not installed")

DATA = Path(__file__).parent / "data"
MODEL = DATA / "muscles" / "hamner_subject02_planar_muscles.osim"
LAB = DATA / "lab"
JOINTS = (("hip_r", "femur_r"), ("knee_r", "tibia_r"), ("ankle_r", "talus_r"))
T0, T1, RATE, CUTOFF = 0.2, 1.2, 60.0, 10.0


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    from casflex.inverse import Filter, prepare, solve
    from casflex.inverse import Trial as InverseTrial
    from casflex.lab.tables import read_sto
    from casflex.muscles.analysis import TrialMuscles, reserve_actuators
    from casflex.muscles.reaction import JointReaction
    from casflex.peers.opensim_analyses import Trial, static_optimization
    from casflex.peers.opensim_tools import exact_times, external_loads, inverse_kinematics
    from casflex.scene.from_osim import scene_from_osim
    from casflex.scene.osim_actuators import read_actuators, write_actuators

    tmp = tmp_path_factory.mktemp("hamner_muscles")
    ik = inverse_kinematics(MODEL, LAB / "hamner_running_whole.trc", LAB / "hamner_tasks_ik.xml", tmp / "ik.mot",
                            t_start=T0, t_end=T1)
    # the IK's and the plates' times are the frames' rounded to the ms: both set to the exact sixtieths, else the
    # plates are splined through times 0.3 ms off (1-2 N m of difference in the moments at two frames in three)
    coords = exact_times(ik["path"], tmp / "ik_even.mot", T0, RATE)
    grf = exact_times(LAB / "hamner_running_whole_grf.mot", tmp / "grf.mot", T0, RATE)
    loads = external_loads(tmp / "loads.xml", grf, {"calcn_r": "ground_", "calcn_l": "1_ground_"})
    osim = scene_from_osim(MODEL, muscles=True)
    reserves = Path(write_actuators(tmp / "reserves.xml", reserve_actuators(osim.scene, "pelvis", 1.0)))
    so = static_optimization(Trial(MODEL, coords, loads=loads, forces=(str(reserves),), cutoff=CUTOFF, t_start=T0,
                                   t_end=T1), tmp / "so", joints=[j for j, _ in JOINTS], on="child", frame="child")
    inputs = prepare(MODEL, InverseTrial(coordinates=coords, grf=loads), filter=Filter(CUTOFF, None, "opensim"))
    res = solve(inputs)
    trial = TrialMuscles(osim, inputs.tree, res.t, res.plates, read_actuators(reserves),
                         reaction=JointReaction(on="child", frame="child"), joints=tuple(j for j, _ in JOINTS))
    out = trial.solve(res.z, res.zd, res.zdd)
    solved = np.array([not any(abs(t - f) < 1e-6 for f in so["failed"]) for t in res.t])
    return {"t": res.t, "out": out, "names": [m.name for m in osim.muscles], "solved": solved,
            "force": read_sto(so["force"]), "jr": read_sto(so["reactions"]), "failed": so["failed"]}


def _at(table, t, names):
    return np.column_stack([np.interp(t, table.t, table.column(n)) for n in names])


@needs_opensim
def test_casflex_solves_every_frame_and_opensim_most(run):
    """casflex balances every coordinate at every frame (its QP, to 1e-10); OpenSim 4.6 logged 9 of the 61 frames
    as failed (its IPOPT at 100 iterations): the comparison below needs most of them (at least 45)."""
    out = run["out"]
    assert out.so.success and np.abs(out.so.violation).max() < 1e-6
    assert run["solved"].sum() >= 45, run["failed"]
    assert len(run["names"]) == 92


@needs_opensim
def test_muscle_forces_are_opensims_within_2_percent_of_each_peak_where_it_solved(run):
    """Every muscle whose peak reaches 50 N within 2 % of that peak (RMS over OpenSim's solved frames; measured
    0.45 %, peri_r); the 10 of smaller peak, at the 0.01 activation floor most of the trial where OpenSim's interior
    point stops above the bound at its 1e-4 criterion, within 1 N RMS (measured 0.33 N: up to 4 % of such a peak)."""
    ok, names = run["solved"], run["names"]
    theirs = _at(run["force"], run["t"], names)[ok]
    ours = run["out"].so.forces[ok]
    rms = np.sqrt(np.mean((ours - theirs) ** 2, axis=0))
    peak = np.abs(theirs).max(axis=0)
    big = peak >= 50.0
    assert big.sum() >= 80
    assert (rms[big] < 0.02 * peak[big]).all(), {n: r / p for n, r, p, b in zip(names, rms, peak, big, strict=True)
                                                  if b and r >= 0.02 * p}
    assert rms[~big].max() < 1.0, dict(zip(np.array(names)[~big], rms[~big], strict=True))


@needs_opensim
def test_hip_knee_and_ankle_reactions_are_opensims_within_2_percent_of_peak(run):
    """On the child, in the child's axes, over OpenSim's solved frames: fx and fy within 2 % of the in-plane force's
    peak (RMS; measured 0.07 % hip, 0.01 % knee, 0.04 % ankle) and mz within 0.5 N m (measured 0.004)."""
    ok, out = run["solved"], run["out"]
    for joint, body in JOINTS:
        theirs = _at(run["jr"], run["t"], [f"{joint}_on_{body}_in_{body}_{c}" for c in ("fx", "fy", "mz")])[ok]
        ours = out.reactions[joint].loads[ok, 0, :]
        rms = np.sqrt(np.mean((ours - theirs) ** 2, axis=0))
        peak = np.hypot(theirs[:, 0], theirs[:, 1]).max()
        assert peak > 3000.0  # running: several body weights (some 650 N) at each joint
        assert (rms[:2] < 0.02 * peak).all() and rms[2] < 0.5, (joint, rms, peak)
