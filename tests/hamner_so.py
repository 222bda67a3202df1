"""OpenSim 4.6's StaticOptimization (and JointReaction) and casflex's muscle path side by side on Hamner's subject 02
run (tests/data/muscles: the planar model or an edited copy, OpenSim's IK of the run, the reserve file;
README_opensim_runs.md), 0.2-0.4 s: what the peers' tests of the activation bounds compare (OpenSim in its own
process: casflex.peers.opensim_analyses)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

DATA = Path(__file__).parent / "data" / "muscles"
LAB = Path(__file__).parent / "data" / "lab"
T0, T1 = 0.2, 0.4


def both_static_optimizations(model: Path, tmp: Path, joints: tuple[tuple[str, str], ...]) -> dict:
    """OpenSim's SO + JR (of ``joints``' (joint, child) on the child, in the child's axes) and casflex's
    TrialMuscles on ``model`` over the window: {"names": the muscles, "trial", "out" (casflex's), "rows" (casflex's
    frames at OpenSim's solved ones), "keep" (those), "failed" (OpenSim's failed times), "act", "force" (OpenSim's,
    solved frames x muscles), "jr" (OpenSim's reactions' table)}."""
    from casflex.inverse import Filter, prepare, solve
    from casflex.inverse import Trial as InverseTrial
    from casflex.lab.tables import read_sto
    from casflex.muscles.analysis import TrialMuscles
    from casflex.muscles.reaction import JointReaction
    from casflex.peers.opensim_analyses import Trial, static_optimization
    from casflex.peers.opensim_tools import exact_times, external_loads
    from casflex.scene.from_osim import scene_from_osim
    from casflex.scene.osim_actuators import read_actuators

    coords = DATA / "hamner_run_ik.mot"  # OpenSim's IK, its times the frames' exact sixtieths
    grf = exact_times(LAB / "hamner_running_whole_grf.mot", tmp / "grf.mot", T0, 60.0)
    loads = external_loads(tmp / "loads.xml", grf, {"calcn_r": "ground_", "calcn_l": "1_ground_"})
    reserves = DATA / "hamner_reserve_actuators.xml"
    so = static_optimization(Trial(str(model), str(coords), loads=loads, forces=(str(reserves),), cutoff=10.0,
                                   t_start=T0, t_end=T1), tmp / "so", joints=[j for j, _ in joints], on="child",
                             frame="child")
    osim = scene_from_osim(model, muscles=True)
    inputs = prepare(model, InverseTrial(coordinates=coords, grf=loads), filter=Filter(10.0, None, "opensim"))
    res = solve(inputs)
    trial = TrialMuscles(osim, inputs.tree, res.t, res.plates, read_actuators(reserves),
                         reaction=JointReaction(on="child", frame="child"), joints=tuple(j for j, _ in joints))
    out = trial.solve(res.z, res.zd, res.zdd)
    act, force = read_sto(so["activation"]), read_sto(so["force"])
    keep = [i for i, t in enumerate(act.t) if not any(abs(t - f) < 1e-6 for f in so["failed"])]
    rows = [int(np.argmin(np.abs(res.t - t))) for t in act.t[keep]]
    assert np.abs(res.t[rows] - act.t[keep]).max() < 1e-6
    names = [m.name for m in osim.muscles]
    return {"names": names, "trial": trial, "out": out, "rows": rows, "keep": keep, "failed": so["failed"],
            "act": np.column_stack([act.column(n) for n in names])[keep],
            "force": np.column_stack([force.column(n) for n in names])[keep], "jr": read_sto(so["reactions"])}
