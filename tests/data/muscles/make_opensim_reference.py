"""Writes this folder's OpenSim reference (README_opensim_runs.md): OpenSim 4.6's static optimization and joint
reactions on opensim-models' Gait10dof18musc walk, with what its SO saw of the muscles.

    python tests/data/muscles/make_opensim_reference.py [opensim-models git dir]    # needs OpenSim: '.[peers]'

The models' repository defaults to /work/.mirror/opensim-org+opensim-models/repo (a bare snapshot: its files
are read with ``git show``). Writes gait10dof18musc_so_activation.sto, gait10dof18musc_so_force.sto,
gait10dof18musc_jr.sto, gait10dof18musc_jr_parent.sto (OpenSim's own output files, their header and columns
kept, the numbers at 9 significant digits) and gait10dof18musc_inputs.npz.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
PIPE = "Pipelines/Gait10dof18musc"
FILES = {"model": f"{PIPE}/OutputReference/subject01.osim", "ik": f"{PIPE}/OutputReference/IK/subject01_walk_IK.mot",
         "grf_xml": f"{PIPE}/ExperimentalData/subject01_walk_grf.xml",
         "grf": f"{PIPE}/ExperimentalData/subject01_walk_grf.mot",
         "reserves": f"{PIPE}/gait10dof_Reserve_Actuators.xml"}
NAMES = {"grf_xml": "subject01_walk_grf.xml", "grf": "subject01_walk_grf.mot"}  # the .xml names the .mot
JOINTS = ("hip_r", "knee_r", "ankle_r")
CUTOFF, T0, T1 = 6.0, 0.0, 2.5


def _compact(src: Path, dest: Path) -> None:
    """``src`` with its header as OpenSim wrote it and its numbers at 9 significant digits (OpenSim pads 12
    decimals: twice the size)."""
    lines = src.read_text().splitlines()
    head = next(i for i, ln in enumerate(lines) if ln.strip().lower() == "endheader") + 2
    rows = ["\t".join(f"{float(v):.9g}" for v in ln.split()) for ln in lines[head:] if ln.strip()]
    dest.write_text("\n".join(lines[:head] + rows) + "\n")


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
    for c, name in enumerate(inputs["coordinates"]):
        if f"{name}_reserve" in cols:
            cols[f"{name}_reserve"] += moved[:, c]
        elif np.abs(moved[:, c]).max() > 1e-6:  # the root's coordinates: muscles are internal forces there
            raise RuntimeError(f"{name}: the muscles' generalized force is {np.abs(moved[:, c]).max():g}, no reserve")
    for m in inputs["muscles"]:
        cols[m][:] = 0.0
    write_sto(dest, so.t, cols, title="net", units={n: "N" for n in cols})


def _casflex_net(paths: dict, t: np.ndarray) -> np.ndarray:
    """(k, 3, 3): casflex's rigid inverse dynamics of the same trial (the model's planar scene, OpenSim's IK as
    the coordinates, OpenSim's filter at 6 Hz, the plates unfiltered as OpenSim applies them): each joint's
    ``.fx``, ``.fy`` (N, in the ground, on the child) and ``.moment`` (N m: the generalized force), at ``t``."""
    from casflex.inverse import Filter, Trial, inverse_dynamics
    from casflex.scene.from_osim import scene_from_osim

    r = inverse_dynamics(scene_from_osim(paths["model"]).scene,
                         Trial(coordinates=paths["ik"], grf=paths["grf"],
                               plates={"calcn_r": "ground_", "calcn_l": "1_ground_"}),
                         filter=Filter(CUTOFF, None, "opensim"))
    return np.stack([np.column_stack([np.interp(t, r.t, r.loads[f"{j}.{w}"]) for w in ("fx", "fy", "moment")])
                     for j in JOINTS], axis=1)


def main(repo: str = "/work/.mirror/opensim-org+opensim-models/repo") -> None:
    from casflex.lab import read_sto
    from casflex.peers.opensim_analyses import Trial, joint_reaction, muscle_inputs, static_optimization
    from casflex.peers.opensim_tools import inverse_dynamics

    commit = subprocess.run(["git", "-C", repo, "rev-parse", "HEAD"], capture_output=True, text=True,
                            check=True).stdout.strip()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        paths = {}
        for key, path in FILES.items():
            paths[key] = tmp / NAMES.get(key, Path(path).name)
            paths[key].write_bytes(subprocess.run(["git", "-C", repo, "show", f"HEAD:{path}"], capture_output=True,
                                                  check=True).stdout)
        trial = Trial(paths["model"], paths["ik"], loads=paths["grf_xml"], forces=(paths["reserves"],), cutoff=CUTOFF,
                      t_start=T0, t_end=T1)
        so = static_optimization(trial, tmp / "out", joints=JOINTS, on="child", frame="child")
        inputs = muscle_inputs(trial, joints=JOINTS)
        ide = inverse_dynamics(paths["model"], paths["ik"], tmp / "id.sto", loads=paths["grf_xml"], cutoff=CUTOFF,
                               t_start=T0, t_end=T1)
        _net_forces(Path(so["force"]), tmp / "net_forces.sto", inputs)
        net = joint_reaction(trial, tmp / "net_forces.sto", tmp / "out", name="net", joints=JOINTS, on="child",
                             frame="ground")
        parent = joint_reaction(trial, so["force"], tmp / "out", name="parent", joints=JOINTS, on="parent",
                                frame="parent")
        for src, name in ((so["activation"], "so_activation"), (so["force"], "so_force"), (so["reactions"], "jr"),
                          (parent["path"], "jr_parent")):
            _compact(Path(src), HERE / f"gait10dof18musc_{name}.sto")
        idt, nt = read_sto(ide["path"]), read_sto(net["path"])
        mine = _casflex_net(paths, inputs["t"])
        moments = np.column_stack([idt.column(f"{c}_{'force' if c in ('pelvis_tx', 'pelvis_ty') else 'moment'}")
                                   for c in inputs["coordinates"]])
        net_loads = np.stack([np.column_stack([nt.column(f"{j}_on_{b}_in_ground_{w}") for w in ("fx", "fy", "mz")])
                              for j, b in zip(JOINTS, ("femur_r", "tibia_r", "talus_r"), strict=True)], axis=1)
        np.savez_compressed(HERE / "gait10dof18musc_inputs.npz", t=inputs["t"], muscles=inputs["muscles"],
                            coordinates=inputs["coordinates"], joints=list(JOINTS), active=inputs["active"],
                            passive=inputs["passive"], length=inputs["length"], arms=inputs["arms"],
                            units=inputs["units"], child=inputs["child"], parent=inputs["parent"],
                            lever=inputs["lever"], offset=inputs["offset"], id_moments=moments, id_t=idt.t,
                            net=net_loads, casflex_net=mine, commit=commit,
                            so_seconds=so["so_seconds"], jr_seconds=so["jr_seconds"])
        print(f"opensim-models {commit}: SO {so['so_seconds']:.2f} s, JR {so['jr_seconds']:.2f} s")


if __name__ == "__main__":
    main(*sys.argv[1:])
