"""casflex's muscle path (casflex.muscles.analysis.TrialMuscles) against OpenSim 4.6's StaticOptimization and
JointReaction on a public walk: the Rajagopal pipeline's (opensim-models, Pipelines/Rajagopal; tests/data/muscles'
cut, 0.1-1.75 s at 100 Hz, one right gait cycle inside), on Rajagopal 2016 scaled by the pipeline, made planar with
its 80 Millard2012EquilibriumMuscle muscles, the patella's path points made MovingPathPoints of the knee and every
wrap object removed (an edited model, not Rajagopal's: tests/data/muscles/README.md, studies/_rajagopal_walk.py).
OpenSim's IK of the cut on that model with the pipeline's task weights, the pipeline's ExternalLoads, a
CoordinateActuator reserve of 1 N m on each free coordinate but the pelvis's and FX, FY, MZ residuals on the pelvis;
both tools read the same files, filter at 6 Hz (OpenSim's filter) and run SO at OpenSim's defaults, then JR of the
right hip, knee and ankle on the child in the child's frame (docs/studies/opensim_muscles.md says what the numbers
mean). OpenSim's SO at 100 iterations logs some frames as failed: the muscles are compared over the others."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

needs_opensim = pytest.mark.skipif(importlib.util.find_spec("opensim") is None, reason="OpenSim is not installed")

DATA = Path(__file__).parent / "data" / "muscles"
MODEL = DATA / "rajagopal_walk_planar_muscles.osim"
JOINTS = (("hip_r", "femur_r"), ("walker_knee_r", "tibia_r"), ("ankle_r", "talus_r"))
T0, T1, RATE, CUTOFF = 0.1, 1.75, 100.0, 6.0


def test_the_edited_model_has_its_muscles_without_wraps_and_the_patella_points_moving():
    """The data's edits (studies/_rajagopal_walk.py) as the README says: 80 muscles, no wrap object left, every
    point that was on a patella a MovingPathPoint of the knee on the held patella, the patella's coupler gone."""
    import xml.etree.ElementTree as ET

    model = ET.parse(MODEL).getroot().find("Model")
    muscles = model.find("ForceSet/objects").findall("Millard2012EquilibriumMuscle")
    assert len(muscles) == 80
    assert not [w for s in model.iter("WrapObjectSet") for w in s.find("objects")]
    assert not [w for s in model.iter("PathWrapSet") for w in s.find("objects")]
    on_patella = [p for p in model.iter() if (p.findtext("socket_parent_frame") or "").strip().startswith(
        "/bodyset/patella_")]
    assert len(on_patella) == 18 and {p.tag for p in on_patella} == {"MovingPathPoint"}
    assert {p.findtext("socket_x_coordinate").rsplit("/", 1)[1] for p in on_patella} == {"knee_angle_r",
                                                                                         "knee_angle_l"}
    assert not list(model.iter("CoordinateCouplerConstraint"))


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    import xml.etree.ElementTree as ET

    from casflex.inverse import Filter, prepare, solve
    from casflex.inverse import Trial as Recorded
    from casflex.lab.tables import read_sto
    from casflex.muscles.analysis import TrialMuscles, reserve_actuators
    from casflex.muscles.reaction import JointReaction
    from casflex.peers.opensim_analyses import Trial, static_optimization
    from casflex.peers.opensim_tools import exact_times, inverse_kinematics
    from casflex.scene.from_osim import scene_from_osim
    from casflex.scene.osim_actuators import read_actuators, write_actuators

    tmp = tmp_path_factory.mktemp("rajagopal_muscles")
    ik = inverse_kinematics(MODEL, DATA / "rajagopal_walk.trc", DATA / "rajagopal_walk_ik_tasks.xml",
                            tmp / "ik.mot", t_start=T0, t_end=T1)
    coords = exact_times(ik["path"], tmp / "ik_even.mot", T0, RATE)  # the IK's times are rounded to the ms
    tree = ET.parse(DATA / "rajagopal_walk_grf.xml")  # the plates' rows (400 Hz) hold the frames' times
    tree.getroot().find(".//datafile").text = str(DATA / "rajagopal_walk_grf.mot")
    tree.write(tmp / "loads.xml", encoding="UTF-8", xml_declaration=True)
    loads = tmp / "loads.xml"
    osim = scene_from_osim(MODEL, muscles=True)
    reserves = Path(write_actuators(tmp / "reserves.xml", reserve_actuators(osim.scene, "pelvis", 1.0)))
    so = static_optimization(Trial(MODEL, coords, loads=loads, forces=(str(reserves),), cutoff=CUTOFF, t_start=T0,
                                   t_end=T1), tmp / "so", joints=[j for j, _ in JOINTS], on="child", frame="child")
    inputs = prepare(MODEL, Recorded(coordinates=coords, grf=loads), filter=Filter(CUTOFF, None, "opensim"))
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
    """casflex balances every coordinate at every frame (its QP, to 1e-10); OpenSim 4.6 logged 22 of the 166
    frames as failed (its IPOPT at 100 iterations): the comparison below needs most of them (at least 120)."""
    out = run["out"]
    assert out.so.success and np.abs(out.so.violation).max() < 1e-6
    assert run["solved"].sum() >= 120, run["failed"]
    assert len(run["names"]) == 80


@needs_opensim
def test_muscle_forces_are_opensims_within_2_percent_of_each_peak_but_four_of_the_foot(run):
    """Over OpenSim's solved frames, RMS: the muscles whose peak reaches 50 N within 2 % of that peak but 4 small
    muscles of the foot, within 3 % (measured fhl_l 2.55 %, fhl_r 2.36 %, tibpost_l 2.18 %, perlong_r 2.06 %:
    a few N at activations of a few per cent, where OpenSim's interior point stops at its 1e-4 criterion: at 1e-6,
    one 15-minute run, they came within 0.37 % and every muscle within 1.25 %, docs/studies/opensim_muscles.md);
    those of smaller peak, at the 0.01 activation floor most of the trial, within
    1.5 N RMS (measured 1.36 N, glmed1_r)."""
    ok, names = run["solved"], run["names"]
    theirs = _at(run["force"], run["t"], names)[ok]
    ours = run["out"].so.forces[ok]
    rms = np.sqrt(np.mean((ours - theirs) ** 2, axis=0))
    peak = np.abs(theirs).max(axis=0)
    big = peak >= 50.0
    assert big.sum() >= 40
    past = {n: r / p for n, r, p, b in zip(names, rms, peak, big, strict=True) if b and r >= 0.02 * p}
    assert len(past) <= 4 and all(v < 0.03 for v in past.values()), past
    assert rms[~big].max() < 1.5, dict(zip(np.array(names)[~big], rms[~big], strict=True))


@needs_opensim
def test_hip_knee_and_ankle_reactions_are_opensims_within_2_percent_of_peak(run):
    """On the child, in the child's axes, every frame: fx and fy within 2 % of the in-plane force's peak (RMS;
    the study measures the magnitude's: 0.32 % hip, 0.19 % knee, 0.14 % ankle) and mz within 0.1 N m (0.02 at
    the knee)."""
    out = run["out"]
    for joint, body in JOINTS:
        theirs = _at(run["jr"], run["t"], [f"{joint}_on_{body}_in_{body}_{c}" for c in ("fx", "fy", "mz")])
        ours = out.reactions[joint].loads[:, 0, :]
        rms = np.sqrt(np.mean((ours - theirs) ** 2, axis=0))
        peak = np.hypot(theirs[:, 0], theirs[:, 1]).max()
        assert peak > 2000.0  # walking: several body weights (834 N) at each joint
        assert (rms[:2] < 0.02 * peak).all() and rms[2] < 0.1, (joint, rms, peak)
