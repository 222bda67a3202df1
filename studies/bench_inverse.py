"""What ``casflex inverse`` costs: 1 s of a trial at 100 Hz, the whole command in a later process.

The trial: the Hamner stride's markers (tests/data/lab, 60 Hz) resampled to 100 Hz by a cubic spline
and stretched to 1.0 s (a slower stride: the cost depends on the frames, not on the speed), with its
plate resampled alike, written as TRC and .mot files. Timed: the command ``casflex inverse hamner_leg
... --out loads.csv`` as a user runs it (a new process each time: interpreter start, imports, files,
fit, filter, loads, output), best of several runs after a first one; inside one process, each stage;
and OpenSim 4.6's InverseDynamicsSolver on the same frames (the peers extra; its worker process's
start excluded), side by side. What is measured and what the numbers mean: docs/studies/bench_inverse.md.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _study import Banner, assert_checks, best_of, checks, cli, table, write_outputs

LAB = Path(__file__).resolve().parents[1] / "tests" / "data" / "lab"
RATE, SPAN = 100.0, 1.0


def write_trial(folder: Path) -> tuple[Path, Path]:
    """The 1 s, 100 Hz trial (module docstring) as ``trial.trc`` and ``grf.mot`` in ``folder``."""
    from scipy.interpolate import CubicSpline

    from casflex.lab import read_sto, read_trc
    from casflex.lab.lowpass import even_times

    lab, grf = read_trc(LAB / "hamner_running_stride.trc"), read_sto(LAB / "hamner_running_stride_grf.mot")
    t_old = even_times(lab.t, lab.rate)
    t_new = np.arange(0.0, SPAN + 1e-9, 1.0 / RATE)
    stretch = lambda tt: t_old[0] + (t_old[-1] - t_old[0]) * tt / SPAN  # noqa: E731
    xyz = CubicSpline(t_old, lab.xyz, axis=0)(stretch(t_new)) * 1e3  # mm
    lines = ["PathFileType\t4\t(X/Y/Z)\ttrial.trc",
             "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
             f"{RATE:g}\t{RATE:g}\t{t_new.size}\t{len(lab.labels)}\tmm\t{RATE:g}\t1\t{t_new.size}",
             "Frame#\tTime\t" + "\t\t\t".join(lab.labels),
             "\t\t" + "\t".join(f"{c}{i + 1}" for i in range(len(lab.labels)) for c in "XYZ"), ""]
    lines += [f"{k + 1}\t{tt:.4f}\t" + "\t".join(f"{v:.5f}" for v in xyz[k].ravel()) for k, tt in enumerate(t_new)]
    trc = folder / "trial.trc"
    trc.write_text("\n".join(lines) + "\n")
    vals = CubicSpline(even_times(grf.t), grf.values, axis=0)(stretch(t_new))
    head = ["name grf.mot", f"datacolumns {1 + len(grf.names)}", f"datarows {t_new.size}",
            f"range {t_new[0]:g} {t_new[-1]:g}", "endheader", "time\t" + "\t".join(grf.names)]
    mot = folder / "grf.mot"
    mot.write_text("\n".join(head + [f"{tt:.4f}\t" + "\t".join(f"{v:.8g}" for v in row)
                                     for tt, row in zip(t_new, vals, strict=True)]) + "\n")
    return trc, mot


def _command(trc: Path, mot: Path, out: Path) -> list[str]:
    return [sys.executable, "-m", "casflex", "inverse", "hamner_leg", "--data", str(trc), "--loads", str(mot),
            "--plate", "ankle=ground_", "--root", "pelvis", "--cutoff", "10", "--quiet", "--out", str(out)]


def _stages(trc: Path, mot: Path) -> dict:
    """Each stage's time in this process (s), the imports already paid."""
    from casflex.inverse import Filter, Trial, inverse_dynamics, inverse_model, kinematic_tree
    from casflex.inverse.fit import fit_markers
    from casflex.lab import Plane, markers_in_plane, read_trc

    t0 = time.perf_counter()
    model = inverse_model("hamner_leg")
    tree = kinematic_tree(model, "pelvis")
    t1 = time.perf_counter()
    lab = read_trc(trc)
    ms = markers_in_plane(lab, {m.name: m.label for m in model.scene.markers}, Plane.parse("X,Y"))
    t2 = time.perf_counter()
    fit_markers(tree, ms.t, ms.q)
    t3 = time.perf_counter()
    res = inverse_dynamics("hamner_leg", Trial(trc, grf=mot, plates={"ankle": "ground_"}, root="pelvis"),
                           filter=Filter(cutoff=10.0))
    t4 = time.perf_counter()
    return {"model": t1 - t0, "read": t2 - t1, "fit": t3 - t2, "all": t4 - t3, "res": res}


def _opensim(res) -> float | None:
    import importlib.util

    if importlib.util.find_spec("opensim") is None:
        return None
    from casflex.inverse import inverse_model
    from casflex.peers import opensim as osp

    F, Mo = res.plates[0].at(res.t)  # the plate as the inverse applied it
    scene = inverse_model("hamner_leg").scene
    k = 20  # frames repeated so that the worker's start is measured apart
    args = (res.t, res.q, res.qd, res.qdd)
    t0 = time.perf_counter()
    osp.inverse_dynamics(scene, "pelvis", *(a[:2] for a in args), plates=[("ankle", F[:2], 0 * F[:2], Mo[:2])])
    start = time.perf_counter() - t0
    reps = [np.tile(a, (k,) + (1,) * (a.ndim - 1)) for a in args]
    reps[0] = np.arange(reps[0].size) * 1e-2
    t0 = time.perf_counter()
    osp.inverse_dynamics(scene, "pelvis", *reps, plates=[("ankle", np.tile(F, (k, 1)), 0 * np.tile(F, (k, 1)),
                                                           np.tile(Mo, k))])
    return (time.perf_counter() - t0 - start) / (k * res.t.size)


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    banner = Banner("bench_inverse", quick)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        trc, mot = write_trial(folder)
        cmd = _command(trc, mot, folder / "loads.csv")
        env = {**os.environ}
        subprocess.run(cmd, check=True, env=env, capture_output=True)  # the first run: a user's later ones follow
        wall, _ = best_of(lambda: subprocess.run(cmd, check=True, env=env, capture_output=True), 3 if quick else 7,
                          float("inf"))
        bare, _ = best_of(lambda: subprocess.run([sys.executable, "-c", "pass"], check=True), 3, float("inf"))
        st = _stages(trc, mot)
        os_frame = _opensim(st["res"])
    n = st["res"].t.size
    per_frame = st["all"] / n
    rows = [["`casflex inverse` command, a later process (best)", f"{1e3 * wall:.0f}", f"{1e3 * wall / n:.2f}"],
            ["of which a bare Python start", f"{1e3 * bare:.0f}", "-"],
            ["in one process: model and tree", f"{1e3 * st['model']:.0f}", "-"],
            ["in one process: read the TRC", f"{1e3 * st['read']:.0f}", "-"],
            ["in one process: marker fit", f"{1e3 * st['fit']:.0f}", f"{1e3 * st['fit'] / n:.2f}"],
            ["in one process: the whole inverse_dynamics()", f"{1e3 * st['all']:.0f}", f"{1e3 * per_frame:.2f}"]]
    if os_frame is not None:
        rows.append(["OpenSim 4.6 InverseDynamicsSolver (dynamics only, same frames)", f"{1e3 * os_frame * n:.1f}",
                     f"{1e3 * os_frame:.3f}"])
    page = ["# What `casflex inverse` costs", "", f"{banner.line()} What is measured and what the numbers mean: "
            "[studies/bench_inverse.md](../studies/bench_inverse.md).", "",
            f"The trial: {n} frames at {RATE:g} Hz ({SPAN:g} s), 13 markers, one plate, the rigid hamner_leg "
            "(12 dofs).",
            "", *table(["what", "ms", "ms per frame"], rows, "lrr"), ""]
    # a wall time is this machine's, at this load: reported, never asserted
    lines, failed = checks([("`casflex inverse` on 1 s at 100 Hz takes under 1 s in a later process",
                             f"{wall:.2f} s", wall < 1.0, False)])
    write_outputs("bench_inverse", out_dir, quick, "\n".join(page + lines), None)
    assert_checks(failed)
    return {"wall": wall, "stages": {k: v for k, v in st.items() if k != "res"}, "opensim_frame": os_frame}


if __name__ == "__main__":
    cli(__doc__, main)
