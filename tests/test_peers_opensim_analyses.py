"""casflex.peers.opensim_analyses: OpenSim 4.6's static optimization, joint reactions and the muscles' SO inputs
on the reference's files (tests/data/muscles/README_opensim_runs.md)."""

from __future__ import annotations

import importlib.util
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from casflex.lab import read_sto
from casflex.peers.opensim_analyses import Trial, rigid_tendon_model

needs_opensim = pytest.mark.skipif(importlib.util.find_spec("opensim") is None, reason="OpenSim is not installed")
DATA = Path(__file__).parent / "data" / "muscles"
MODELS = Path("/work/.mirror/opensim-org+opensim-models/repo")
PIPE = "Pipelines/Gait10dof18musc"
FILES = {"m.osim": "OutputReference/subject01.osim", "ik.mot": "OutputReference/IK/subject01_walk_IK.mot",
         "subject01_walk_grf.xml": "ExperimentalData/subject01_walk_grf.xml",
         "subject01_walk_grf.mot": "ExperimentalData/subject01_walk_grf.mot",
         "reserves.xml": "gait10dof_Reserve_Actuators.xml"}


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    if not MODELS.exists():
        pytest.skip("opensim-models is not at hand")
    tmp = tmp_path_factory.mktemp("gait10dof18musc")
    for name, path in FILES.items():
        (tmp / name).write_bytes(subprocess.run(["git", "-C", str(MODELS), "show", f"HEAD:{PIPE}/{path}"],
                                                capture_output=True, check=True).stdout)
    return tmp


@pytest.mark.parametrize("change, message", [
    (dict(cutoff=0.0), "cutoff: expected a positive frequency"),
    (dict(t_start=2.0, t_end=1.0), "t_start, t_end: expected t_start < t_end"),
])
def test_trial_refuses_bad_values(change, message):
    with pytest.raises(ValueError, match=message):
        Trial("m.osim", "ik.mot", **change)


def test_rigid_tendon_model_sets_every_muscle(files, tmp_path):
    out = rigid_tendon_model(files / "m.osim", tmp_path / "rigid.osim")
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
    """SO over 0.5-0.6 s gives the stored rows (the filter sees the whole file either way), JR runs on its forces,
    and muscle_inputs gives the stored active forces and moment arms."""
    from casflex.peers.opensim_analyses import Trial, muscle_inputs, static_optimization

    trial = Trial(str(files / "m.osim"), str(files / "ik.mot"), loads=str(files / "subject01_walk_grf.xml"),
                  forces=(str(files / "reserves.xml"),), cutoff=6.0, t_start=0.5, t_end=0.6)
    out = static_optimization(trial, tmp_path / "out", joints=("knee_r",))
    mine, ref = read_sto(out["activation"]), read_sto(DATA / "gait10dof18musc_so_activation.sto")
    rows = np.searchsorted(ref.t, mine.t - 1e-6)
    assert np.allclose(mine.t, ref.t[rows], atol=1e-6)
    for name in ("soleus_r", "vasti_r", "hamstrings_l"):
        assert np.allclose(mine.column(name), ref.column(name)[rows], atol=1e-6)  # same states, same optimizer
    jr = read_sto(out["reactions"])
    assert "knee_r_on_tibia_r_in_tibia_r_fy" in jr.names and out["so_seconds"] > 0.0
    assert out["failed"] == [] and Path(out["log"]).exists()  # the walk's frames all solved
    ins = muscle_inputs(trial, joints=("knee_r",))
    d = np.load(DATA / "gait10dof18musc_inputs.npz")
    assert np.allclose(ins["active"], d["active"][rows], rtol=1e-9)
    assert np.allclose(ins["arms"], d["arms"][rows], atol=1e-12)
    assert np.allclose(ins["units"], d["units"][rows][:, 3:6], atol=1e-12)
