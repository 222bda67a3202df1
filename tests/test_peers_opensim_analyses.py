"""casflex.peers.opensim_analyses: OpenSim 4.6's static optimization, joint reactions and the muscles' SO inputs
on the reference's files: Hamner's run (tests/data/muscles/README_opensim_runs.md)."""

from __future__ import annotations

import importlib.util
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from casflex.lab import read_sto
from casflex.peers.opensim_analyses import Trial, rigid_tendon_model

needs_opensim = pytest.mark.skipif(importlib.util.find_spec("opensim") is None, reason="OpenSim is not installed")
DATA = Path(__file__).parent / "data" / "muscles"
LAB = Path(__file__).parent / "data" / "lab"
PLATES = {"calcn_r": "ground_", "calcn_l": "1_ground_"}


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Hamner's run as the reference's script gave it to OpenSim: its IK (stored), the plates at the frames' exact
    times and their ExternalLoads file."""
    from casflex.peers.opensim_tools import exact_times, external_loads

    tmp = tmp_path_factory.mktemp("hamner_run")
    grf = exact_times(LAB / "hamner_running_whole_grf.mot", tmp / "grf.mot", 0.2, 60.0)
    return {"loads": external_loads(tmp / "loads.xml", grf, PLATES)}


@pytest.mark.parametrize("change, message", [
    (dict(cutoff=0.0), "cutoff: expected a positive frequency"),
    (dict(t_start=2.0, t_end=1.0), "t_start, t_end: expected t_start < t_end"),
])
def test_trial_refuses_bad_values(change, message):
    with pytest.raises(ValueError, match=message):
        Trial("m.osim", "ik.mot", **change)


def test_rigid_tendon_model_sets_every_muscle(tmp_path):
    out = rigid_tendon_model(DATA / "gait10dof18musc.osim", tmp_path / "rigid.osim")
    muscles = list(ET.parse(out).getroot().iter("Millard2012EquilibriumMuscle"))
    assert len(muscles) == 18
    assert all(m.find("ignore_tendon_compliance").text == "true" for m in muscles)


@needs_opensim
def test_the_frames_opensims_so_logged_as_failed_are_read_from_its_log(tmp_path):
    """OpenSim's SO records a frame it could not solve anyway; static_optimization's "failed" lists those times
    from its log (the lines as OpenSim 4.6 writes them)."""
    from casflex.peers.opensim_analyses import _failed_times

    log = tmp_path / "so.log"
    log.write_text("  Optimizer failed: Ipopt: Maximum iterations exceeded (status -1)\n"
                   "[2026-11-29 05:50:58.029] [warning] OPTIMIZATION FAILED...\n"
                   "[2026-11-29 05:50:58.029] [warning] StaticOptimization.record: The optimizer could not find a "
                   "solution at time = 0.233333331199998.\n"
                   "[2026-11-29 05:50:58.030] [warning] The model appears too weak for static optimization.\n"
                   "[...] [warning] StaticOptimization.record: The optimizer could not find a solution at "
                   "time = 1.2.\n")
    assert _failed_times(str(log)) == [0.233333331199998, 1.2]
    log.write_text("")
    assert _failed_times(str(log)) == []


@needs_opensim
def test_the_peer_reproduces_the_reference(files, tmp_path):
    """SO over 0.2-0.24 s (later starts fail its muscles' equilibration) gives the stored
    rows (the filter sees the whole file either way), JR runs on its forces, and muscle_inputs gives the stored
    active forces and moment arms."""
    from casflex.peers.opensim_analyses import Trial, muscle_inputs, static_optimization

    trial = Trial(str(DATA / "hamner_subject02_planar_muscles.osim"), str(DATA / "hamner_run_ik.mot"),
                  loads=str(files["loads"]), forces=(str(DATA / "hamner_reserve_actuators.xml"),), cutoff=10.0,
                  t_start=0.2, t_end=0.24)
    out = static_optimization(trial, tmp_path / "out", joints=("knee_r",))
    mine, ref = read_sto(out["activation"]), read_sto(DATA / "hamner_run_so_activation.sto")
    rows = np.searchsorted(ref.t, mine.t - 1e-6)
    assert np.allclose(mine.t, ref.t[rows], atol=1e-6)
    for name in ("soleus_r", "vas_lat_r", "bifemlh_l"):
        # same states, same optimizer, stopped at its convergence criterion 1e-4 (measured 4e-6 apart: on Thelen's
        # muscles the first frame's start differs with the window)
        assert np.allclose(mine.column(name), ref.column(name)[rows], rtol=0.0, atol=1e-4), name
    jr = read_sto(out["reactions"])
    assert "knee_r_on_tibia_r_in_tibia_r_fy" in jr.names and out["so_seconds"] > 0.0
    # OpenSim logs as failed 2 of these 3 frames (none of them in the whole trial's run: its IPOPT's start differs
    # with the window), its values there as above
    assert Path(out["log"]).exists() and all(0.2 - 1e-6 <= t <= 0.24 for t in out["failed"])
    ins = muscle_inputs(trial, joints=("knee_r",))
    d = np.load(DATA / "hamner_run_inputs.npz")
    free = [ins["coordinates"].index(c) for c in d["coordinates"]]
    # the force-velocity's speeds: OpenSim's spline of the window's coordinates, not the whole trial's (5e-7 apart)
    assert np.allclose(ins["active"], d["active"][rows], rtol=1e-5)
    assert np.allclose(ins["arms"][:, :, free], d["arms"][rows], atol=1e-12)
    assert np.allclose(ins["units"], d["units"][rows][:, 3:6], atol=1e-12)
