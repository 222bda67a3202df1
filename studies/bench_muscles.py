"""What ``casflex muscles`` costs against OpenSim's tools: a walk from its markers to muscle forces and joint
reactions, the whole command as a user runs it, side by side with OpenSim 4.6's IK + ID + StaticOptimization +
JointReaction on the same files.

The trial: Hamner's subject 02 running (tests/data: the planar model with its 92 Thelen muscles, 61 frames of 41
markers at 60 Hz, both plates, the lab's IK weights; a reserve of 1 N m on each joint and FX, FY, MZ on the pelvis).
casflex: ``casflex muscles MODEL --data run.trc --tasks tasks.xml --loads grf.mot --plate calcn_r=ground_ --plate
calcn_l=1_ground_ --cutoff 10 --actuators reserves.xml --joints hip_r,knee_r,ankle_r --out DIR`` (a new process
each time: interpreter start, imports, files, the marker fit, the inverse dynamics, the muscles, static optimization,
the reactions, the files written). OpenSim: one Python process
that imports OpenSim and runs its InverseKinematicsTool, InverseDynamicsTool and AnalyzeTool (StaticOptimization,
then JointReaction with its forces) on the same files and options (the peers extra: skipped where OpenSim is not
installed). Both best of several runs after a first one, taken in turn, with Python's bytecode cache on as in a
user's installation; the ratio is the pair's. Wall times are this machine's at its load (reported, never
asserted).
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _study import Banner, assert_checks, checks, cli, table, write_outputs

DATA = Path(__file__).resolve().parents[1] / "tests" / "data"
FILES = {"model": DATA / "muscles" / "hamner_subject02_planar_muscles.osim",
         "trc": DATA / "lab" / "hamner_running_whole.trc",
         "tasks": DATA / "lab" / "hamner_tasks_ik.xml", "grf": DATA / "lab" / "hamner_running_whole_grf.mot",
         "reserves": DATA / "muscles" / "hamner_reserve_actuators.xml"}
PLATES = {"calcn_r": "ground_", "calcn_l": "1_ground_"}
JOINTS = ("hip_r", "knee_r", "ankle_r")

#: The OpenSim side, one process (argv: model trc tasks grf reserves out t_end).
OPENSIM = """
import sys
import opensim  # noqa: F401 - first, as a user's script imports it
from casflex.peers.opensim_analyses import Trial, static_optimization
from casflex.peers.opensim_tools import inverse_dynamics, inverse_kinematics
model, trc, tasks, grf, reserves, out, t_end = sys.argv[1:]
ik = inverse_kinematics(model, trc, tasks, out + "/ik.mot", t_end=float(t_end), worker=False)
inverse_dynamics(model, ik["path"], out + "/id.sto", loads=grf, cutoff=10.0, t_end=float(t_end), worker=False)
static_optimization(Trial(model, ik["path"], grf, forces=(reserves,), cutoff=10.0, t_end=float(t_end)), out,
                    joints=["hip_r", "knee_r", "ankle_r"], worker=False)
"""


def _casflex(out: Path, t_end: float) -> list[str]:
    f = FILES
    return [sys.executable, "-m", "casflex", "muscles", str(f["model"]), "--data", str(f["trc"]), "--tasks",
            str(f["tasks"]), "--loads", str(f["grf"]), *(a for n, p in PLATES.items() for a in ("--plate", f"{n}={p}")),
            "--cutoff", "10",
            "--actuators", str(f["reserves"]), "--joints", ",".join(JOINTS), "--t-end", f"{t_end:g}", "--quiet",
            "--out", str(out)]


def _opensim(out: Path, t_end: float) -> list[str]:
    """OpenSim's side; its ExternalLoads file (the plates on the calcanei, as the lab's) written beside ``out``."""
    from casflex.peers.opensim_tools import external_loads

    f = FILES
    loads = external_loads(out.parent / "external_loads.xml", f["grf"], PLATES)
    return [sys.executable, "-c", OPENSIM, *(str(f[k]) for k in ("model", "trc", "tasks")), loads,
            str(f["reserves"]), str(out), f"{t_end:g}"]


#: Both commands' environment: Python's bytecode cache on, as in a user's installation (a sandbox that sets
#: PYTHONDONTWRITEBYTECODE recompiles every module at every start: 0.3-0.4 s of casflex's own).
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def _timed(cmd: list[str], out: Path) -> float:
    out.mkdir(exist_ok=True)
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True, env=ENV)
    return time.perf_counter() - t0


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    banner = Banner("bench_muscles", quick)
    t_end = 0.6 if quick else 1.2
    rounds = 2 if quick else 5
    have_opensim = importlib.util.find_spec("opensim") is not None
    walls: dict[str, list[float]] = {"casflex": [], "opensim": []}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        _timed(_casflex(folder / "c0", t_end), folder / "c0")  # the first run: a user's later ones follow
        if have_opensim:
            _timed(_opensim(folder / "o0", t_end), folder / "o0")
        for r in range(rounds):  # in turn, so that a drift of the machine's speed meets both
            walls["casflex"].append(_timed(_casflex(folder / f"c{r + 1}", t_end), folder / f"c{r + 1}"))
            if have_opensim:
                walls["opensim"].append(_timed(_opensim(folder / f"o{r + 1}", t_end), folder / f"o{r + 1}"))
    c = min(walls["casflex"])
    rows = [["`casflex muscles` (markers to reactions), best", f"{c:.2f}", "1"]]
    ratio = None
    if have_opensim:
        o = min(walls["opensim"])
        ratio = sorted(b / a for a, b in zip(walls["casflex"], walls["opensim"], strict=True))[rounds // 2]
        rows.append(["OpenSim 4.6 IK + ID + SO + JR in one process, best", f"{o:.2f}", f"{o / c:.1f}"])
    frames = int(round((t_end - 0.2) * 60)) + 1
    page = ["# What `casflex muscles` costs against OpenSim's tools", "", banner.line(), "",
            f"The trial: Hamner's subject 02 running, {frames} frames at 60 Hz, 41 markers, two plates, the planar "
            "model's 92 Thelen muscles, 11 reserves and 3 residual actuators; reactions at the right hip, knee and "
            "ankle. Each command a new process (best of "
            f"{rounds} after a first run), taken in turn.", "",
            *table(["what", "s", "x casflex"], rows, "lrr"), ""]
    if ratio is not None:
        page.append(f"The median of the {rounds} pairs' ratios (OpenSim / casflex): {ratio:.1f}.")
    else:
        page.append("OpenSim is not installed here (the peers extra): its side was not run.")
    rows_c = [("the OpenSim side ran (the peers extra installed)", str(have_opensim), have_opensim, False)]
    if ratio is not None:  # a wall-time ratio is this machine's at its load: reported, never asserted
        rows_c.append(("casflex at least 5 x faster than OpenSim's four tools (the issue's bar)", f"{ratio:.1f}",
                       ratio >= 5.0, False))
    lines, failed = checks(rows_c)
    write_outputs("bench_muscles", out_dir, quick, "\n".join(page + [""] + lines), None)
    assert_checks(failed)
    return {"walls": walls, "ratio": ratio}


if __name__ == "__main__":
    cli(__doc__, main)
