"""Writes this folder's OpenSim reference (README_opensim_runs.md): OpenSim 4.6's inverse kinematics, static
optimization and joint reactions on Hamner's subject 02 run (tests/data/lab's whole trial, 0.2-1.2 s, on the planar
model with its 92 muscles), with what its SO saw of the muscles.

    python tests/data/muscles/make_opensim_reference.py    # needs OpenSim: '.[peers]'

Writes hamner_run_ik.mot (OpenSim's IK, the times set to the exact sixtieths, as written),
hamner_run_so_activation.sto, hamner_run_so_force.sto, hamner_run_jr.sto, hamner_run_jr_parent.sto (OpenSim's own
output files, their header and columns kept, the numbers at 9 significant digits) and hamner_run_inputs.npz.
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
LAB = HERE.parent / "lab"
MODEL, RESERVES = HERE / "hamner_subject02_planar_muscles.osim", HERE / "hamner_reserve_actuators.xml"
PLATES = {"calcn_r": "ground_", "calcn_l": "1_ground_"}
JOINTS, CHILDREN = ("hip_r", "knee_r", "ankle_r"), ("femur_r", "tibia_r", "talus_r")
#: the peer test's trial (tests/test_peers_opensim_muscle_trials.py): both stances of the run at 60 Hz
CUTOFF, T0, T1, RATE = 10.0, 0.2, 1.2, 60.0


def _compact(src: Path, dest: Path) -> None:
    """``src`` with its header as OpenSim wrote it and its numbers at 9 significant digits (OpenSim pads 12
    decimals: twice the size)."""
    lines = src.read_text().splitlines()
    head = next(i for i, ln in enumerate(lines) if ln.strip().lower() == "endheader") + 2
    rows = ["\t".join(f"{float(v):.9g}" for v in ln.split()) for ln in lines[head:] if ln.strip()]
    dest.write_text("\n".join(lines[:head] + rows) + "\n")


def _locked() -> set[str]:
    """The planar model's locked (out-of-plane) coordinates."""
    from casflex.scene.osim import read_osim

    return {c.name for j in read_osim(MODEL).joints for c in j.coordinates if c.locked}


def _net_forces(src: Path, dest: Path, inputs: dict) -> None:
    """SO's forces with the muscles' generalized forces moved into the reserves: the muscles at 0 and each
    ``<coordinate>_reserve`` plus sum_m r_mc F_m. The model's accelerations stay SO's, so that JointReaction gives
    the net load across each joint (what casflex's rigid inverse dynamics gives)."""
    from casflex.lab import read_sto
    from casflex.lab.tables import write_sto

    so = read_sto(src)
    cols = {n: so.column(n).copy() for n in so.names}
    f = np.column_stack([cols[m] for m in inputs["muscles"]])
    moved = np.einsum("kmc,km->kc", inputs["arms"], f)
    locked = _locked()
    for c, name in enumerate(inputs["coordinates"]):
        if name in locked:  # the planar model's out-of-plane coordinates: no motion, no work, nothing to carry
            continue
        if f"{name}_reserve" in cols:
            cols[f"{name}_reserve"] += moved[:, c]
        elif np.abs(moved[:, c]).max() > 1e-6:  # the root's coordinates: muscles are internal forces there
            raise RuntimeError(f"{name}: the muscles' generalized force is {np.abs(moved[:, c]).max():g}, no reserve")
    for m in inputs["muscles"]:
        cols[m][:] = 0.0
    write_sto(dest, so.t, cols, title="net", units={n: "N" for n in cols})


def _casflex_net(model: Path, coords: Path, loads: Path, t: np.ndarray) -> np.ndarray:
    """(k, 3, 3): casflex's rigid inverse dynamics of the same trial (the model's planar scene, OpenSim's IK as
    the coordinates, OpenSim's filter at the cut-off, the plates unfiltered as OpenSim applies them): each joint's
    ``.fx``, ``.fy`` (N, in the ground, on the child) and ``.moment`` (N m: the generalized force), at ``t``."""
    from casflex.inverse import Filter, Trial, inverse_dynamics
    from casflex.scene.from_osim import scene_from_osim

    r = inverse_dynamics(scene_from_osim(model).scene, Trial(coordinates=coords, grf=loads),
                         filter=Filter(CUTOFF, None, "opensim"))
    return np.stack([np.column_stack([np.interp(t, r.t, r.loads[f"{j}.{w}"]) for w in ("fx", "fy", "moment")])
                     for j in JOINTS], axis=1)


def _opensim_runs(tmp: Path) -> dict:
    """OpenSim's IK of the run (its times set to the exact sixtieths, as the plates'), then SO + JR (on the child,
    in the child), the inputs SO saw, ID, the net loads' JR and JR on the parent."""
    from casflex.peers.opensim_analyses import Trial, joint_reaction, muscle_inputs, static_optimization
    from casflex.peers.opensim_tools import exact_times, external_loads, inverse_dynamics, inverse_kinematics

    ik = inverse_kinematics(MODEL, LAB / "hamner_running_whole.trc", LAB / "hamner_tasks_ik.xml", tmp / "ik.mot",
                            t_start=T0, t_end=T1)
    coords = Path(exact_times(ik["path"], tmp / "ik_even.mot", T0, RATE))
    grf = exact_times(LAB / "hamner_running_whole_grf.mot", tmp / "grf.mot", T0, RATE)
    loads = Path(external_loads(tmp / "loads.xml", grf, PLATES))
    trial = Trial(str(MODEL), str(coords), loads=str(loads), forces=(str(RESERVES),), cutoff=CUTOFF, t_start=T0,
                  t_end=T1)
    so = static_optimization(trial, tmp / "out", joints=JOINTS, on="child", frame="child")
    inputs = muscle_inputs(trial, joints=JOINTS)
    ide = inverse_dynamics(MODEL, coords, tmp / "id.sto", loads=loads, cutoff=CUTOFF, t_start=T0, t_end=T1)
    _net_forces(Path(so["force"]), tmp / "net_forces.sto", inputs)
    net = joint_reaction(trial, tmp / "net_forces.sto", tmp / "out", name="net", joints=JOINTS, on="child",
                         frame="ground")
    parent = joint_reaction(trial, so["force"], tmp / "out", name="parent", joints=JOINTS, on="parent",
                            frame="parent")
    return {"so": so, "inputs": inputs, "id": ide, "net": net, "parent": parent, "coords": coords, "loads": loads}


def main() -> None:
    from casflex.lab import read_sto

    with tempfile.TemporaryDirectory() as tmp:
        r = _opensim_runs(Path(tmp))
        so, inputs = r["so"], r["inputs"]
        for src, name in ((so["activation"], "so_activation.sto"), (so["force"], "so_force.sto"),
                          (so["reactions"], "jr.sto"), (r["parent"]["path"], "jr_parent.sto")):
            _compact(Path(src), HERE / f"hamner_run_{name}")
        shutil.copyfile(r["coords"], HERE / "hamner_run_ik.mot")  # as OpenSim read it: its states to the last digit
        idt, nt = read_sto(r["id"]["path"]), read_sto(r["net"]["path"])
        mine = _casflex_net(MODEL, r["coords"], r["loads"], inputs["t"])
        nan = np.full(len(idt.t), np.nan)  # a coordinate OpenSim's ID leaves out (locked)
        moments = np.column_stack([idt.column(f"{c}_force") if f"{c}_force" in idt.names else
                                   idt.column(f"{c}_moment") if f"{c}_moment" in idt.names else nan
                                   for c in inputs["coordinates"]])
        net_loads = np.stack([np.column_stack([nt.column(f"{j}_on_{b}_in_ground_{w}") for w in ("fx", "fy", "mz")])
                              for j, b in zip(JOINTS, CHILDREN, strict=True)], axis=1)
        locked = _locked()  # kept: the coordinates the planar model moves
        free = [i for i, c in enumerate(inputs["coordinates"]) if c not in locked]
        np.savez_compressed(HERE / "hamner_run_inputs.npz", t=inputs["t"], muscles=inputs["muscles"],
                            coordinates=[inputs["coordinates"][i] for i in free], joints=list(JOINTS),
                            active=inputs["active"], passive=inputs["passive"], length=inputs["length"],
                            arms=inputs["arms"][:, :, free],
                            units=inputs["units"], child=inputs["child"], parent=inputs["parent"],
                            lever=inputs["lever"], offset=inputs["offset"], id_moments=moments[:, free], id_t=idt.t,
                            net=net_loads, casflex_net=mine, failed=np.asarray(so["failed"], float),
                            so_seconds=so["so_seconds"], jr_seconds=so["jr_seconds"])
        print(f"SO {so['so_seconds']:.2f} s, JR {so['jr_seconds']:.2f} s, failed frames {so['failed']}")


if __name__ == "__main__":
    main()
