"""casflex against OpenSim's own tools on a lab's model, markers and task weights: joint angles and moments.

The public running trial of OpenSim's Hamner pipeline (opensim-org/opensim-models at COMMIT: subject 02, 10 s
at 60 Hz, 41 markers, two plates), the subject's own registered model made planar in OpenSim's terms
(studies/_planar_osim.py: 14 coordinates free, the others locked; the ankles' and elbows' axes set to the
normal), the lab's IK task file (Tasks_IK.xml: 37 weighted markers). OpenSim 4.6 (the peers extra) runs its
InverseKinematicsTool and InverseDynamicsTool (coordinates filtered at CUTOFF Hz, plates unfiltered, both feet
loaded); casflex runs ``inverse`` on the same .osim, trial, task file and cut-off. Compared, per joint:
- the joint angles (OpenSim's IK against casflex's unfiltered fit), RMS over the trial;
- the moments, RMS over the complete stances of that side's foot (lumbar: of either foot), as % of OpenSim's
  peak there: casflex's default filter and ``--filter opensim``, against OpenSim's pipeline as a lab runs it
  (its IK file keeps the trial's times rounded to the ms, and its ID tool resamples them at the smallest
  step, 16 ms) and against its ID on the frames' exact times (the same times as casflex's);
- the wall time of the whole ``casflex inverse`` command and of OpenSim's two tools in one script.
The model repository: the environment's OPENSIM_MODELS (a clone, or a bare git directory, of
opensim-org/opensim-models); ``--quick`` takes the 1 s excerpt of tests/data/lab instead. What the numbers
mean: docs/studies/opensim_gait.md.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from _planar_osim import planar_osim
from _study import Banner, assert_checks, checks, cli, png, table, write_outputs

COMMIT = "20a888b"
LAB = Path(__file__).resolve().parents[1] / "tests" / "data" / "lab"
CUTOFF = 10.0  # Hz: a running trial's coordinates (Hamner et al. 2010 filtered at 12 Hz; 6 Hz is walking's)
STANCE_N = 20.0  # N: a plate's vertical force above this is contact
KEEP = ("pelvis_tilt", "pelvis_tx", "pelvis_ty", "hip_flexion_r", "hip_flexion_l", "knee_angle_r", "knee_angle_l",
        "ankle_angle_r", "ankle_angle_l", "lumbar_extension", "arm_flex_r", "arm_flex_l", "elbow_flex_r",
        "elbow_flex_l")
JOINTS = ("hip_flexion_r", "knee_angle_r", "ankle_angle_r", "hip_flexion_l", "knee_angle_l", "ankle_angle_l",
          "lumbar_extension")
MAX_MISFIT = 0.3  # m: a planar torso leaves the running trunk's rotation out: shoulder markers 0.1 m off


@dataclass(frozen=True)
class Trial:
    name: str
    model: str
    markers: str
    grf: str
    tasks: str
    plates: dict = field(default_factory=dict)
    window: tuple[float, float] = (0.0, 9.983)


TRIALS = (Trial("Hamner subject 02, running", "Pipelines/Hamner/outputReference/subject02_registered.osim",
                "Pipelines/Hamner/subject02_running.trc", "Pipelines/Hamner/subject02_running_grf.mot",
                "Pipelines/Hamner/Tasks_IK.xml", {"calcn_r": "ground_", "calcn_l": "1_ground_"}),)


def _models() -> Path:
    path = os.environ.get("OPENSIM_MODELS")
    if not path or not Path(path).exists():
        raise SystemExit("OPENSIM_MODELS: the path of a clone (or bare git directory) of opensim-org/opensim-models")
    return Path(path)


def _copy(repo: Path, name: str, dest: Path) -> Path:
    """The repository's file ``name`` at COMMIT, written to ``dest``."""
    out = dest / Path(name).name
    out.write_bytes(subprocess.run(["git", f"--git-dir={repo / '.git' if (repo / '.git').exists() else repo}",
                                    "show", f"{COMMIT}:{name}"], check=True, capture_output=True).stdout)
    return out


def _opensim(files: dict, trial: Trial, tmp: Path) -> dict:
    from casflex.peers.opensim_tools import exact_times, external_loads, inverse_dynamics, inverse_kinematics

    t0, t1 = trial.window
    ik = inverse_kinematics(files["model"], files["markers"], files["tasks"], tmp / "ik.mot", t_start=t0, t_end=t1)
    loads = external_loads(tmp / "loads.xml", files["grf"], trial.plates)
    idv = inverse_dynamics(files["model"], ik["path"], tmp / "id.sto", loads=loads, cutoff=CUTOFF, t_start=t0,
                           t_end=t1)
    even = exact_times(ik["path"], tmp / "ik_even.mot", t0, 60.0)
    ide = inverse_dynamics(files["model"], even, tmp / "id_even.sto", loads=loads, cutoff=CUTOFF, t_start=t0,
                           t_end=t1)
    ik8 = inverse_kinematics(files["model"], files["markers"], files["tasks"], tmp / "ik8.mot", t_start=t0, t_end=t1,
                             accuracy=1e-8)
    return {"ik": ik, "ik8": ik8, "id": idv, "id_even": ide}


def _casflex(files: dict, trial: Trial) -> dict:
    from casflex.inverse import inverse_dynamics
    from casflex.scene.from_osim import scene_from_osim

    scene = scene_from_osim(files["model"]).scene
    common = dict(grf=files["grf"], plates=trial.plates, tasks=files["tasks"], t_start=trial.window[0],
                  t_end=trial.window[1], max_misfit=MAX_MISFIT, cutoff_plates=None)
    raw = inverse_dynamics(scene, files["markers"], cutoff=None, **common)
    start = time.perf_counter()
    runs = {f: inverse_dynamics(scene, files["markers"], cutoff=CUTOFF, filter=f, **common)
            for f in ("butterworth", "opensim")}
    return {"scene": scene, "raw": raw, "runs": runs, "seconds": (time.perf_counter() - start) / 2}


def _angles(scene, raw, ik_path: Path) -> dict:
    """RMS (deg, or mm for the pelvis's translations) of casflex's unfiltered fit minus OpenSim's IK."""
    from casflex.lab import read_sto
    from casflex.scene.coordinates import to_lab

    ik = read_sto(ik_path)
    out = {}
    for c in scene.coordinates:
        mine = to_lab(scene, c, raw.z[:, raw.coordinate_names.index(c.scene_coordinate())])
        ref = ik.column(c.name) if c.translational else np.radians(ik.column(c.name))
        scale = 1e3 if c.translational else 180 / np.pi
        out[c.name] = float(scale * np.sqrt(np.mean((mine - ref) ** 2)))
    return out


def _stances(grf, prefix: str, t: np.ndarray) -> np.ndarray:
    """The times t (k,) within complete stances on plate ``prefix`` (contact begun and ended inside t)."""
    on = np.interp(t, grf.t, grf.column(f"{prefix}force_vy")) > STANCE_N
    starts = np.flatnonzero(~on[:-1] & on[1:]) + 1
    ends = np.flatnonzero(on[:-1] & ~on[1:])  # each stance's last loaded time
    mask = np.zeros_like(on)
    for a in starts:
        b = ends[ends >= a]
        if b.size:
            mask[a:b[0] + 1] = True
    return mask


def _moments(res, ref, grf, plates: dict) -> dict:
    """{joint: (RMS of casflex - OpenSim over the joint's stances, OpenSim's peak there)} (N m), casflex's
    loads taken at OpenSim's times by a cubic spline (OpenSim's pipeline resamples the frames)."""
    from scipy.interpolate import CubicSpline

    feet = {side: next(p for b, p in plates.items() if b.endswith(f"_{side}")) for side in "rl"}
    stance = {s: _stances(grf, p, ref.t) for s, p in feet.items()}
    out = {}
    for joint in JOINTS:
        name = f"{joint}_moment"
        side = joint[-1] if joint[-2] == "_" else None
        mask = stance[side] if side else stance["r"] | stance["l"]
        inside = (ref.t >= res.t[0]) & (ref.t <= res.t[-1]) & mask
        mine = CubicSpline(res.t, res.loads[name])(ref.t[inside])
        theirs = ref.column(name)[inside]
        out[joint] = (float(np.sqrt(np.mean((mine - theirs) ** 2))), float(np.abs(theirs).max()))
    return out


def _command_times(files: dict, trial: Trial, tmp: Path, repeat: int) -> dict:
    """Wall time (s, best of ``repeat``) of the whole ``casflex inverse`` command and of a Python script running
    OpenSim's IK and ID tools, each a fresh process, side by side."""
    t0, t1 = trial.window
    plates = [a for b, p in trial.plates.items() for a in ("--plate", f"{b}={p}")]
    cf = [sys.executable, "-m", "casflex", "inverse", str(files["model"]), "--data", str(files["markers"]),
          "--loads", str(files["grf"]), *plates, "--tasks", str(files["tasks"]), "--cutoff", f"{CUTOFF:g}",
          "--cutoff-plates", "none", "--t-start", f"{t0:g}", "--t-end", f"{t1:g}", "--max-misfit",
          f"{MAX_MISFIT:g}", "--out", str(tmp / "cf.sto"), "--quiet"]
    script = (f"import opensim as o\no.Logger.removeFileSink()\nm=o.Model({str(files['model'])!r})\n"
              "ik=o.InverseKinematicsTool()\n"
              f"ik.setModel(m)\nik.setMarkerDataFileName({str(files['markers'])!r})\n"
              f"ik.set_IKTaskSet(o.IKTaskSet({str(files['tasks'])!r}))\nik.setStartTime({t0})\nik.setEndTime({t1})\n"
              f"ik.setResultsDir({str(tmp)!r})\nik.setOutputMotionFileName({str(tmp / 'os_ik.mot')!r})\n"
              "ik.set_report_marker_locations(False)\nik.set_report_errors(False)\nik.run()\n"
              "i=o.InverseDynamicsTool()\nm2=o.Model(m)\ni.setModel(m2)\n"
              f"i.setCoordinatesFileName({str(tmp / 'os_ik.mot')!r})\ni.setLowpassCutoffFrequency({CUTOFF})\n"
              f"i.setExternalLoadsFileName({str(tmp / 'loads.xml')!r})\ni.setStartTime({t0})\ni.setEndTime({t1})\n"
              f"i.setResultsDir({str(tmp)!r})\ni.setOutputGenForceFileName('os_id.sto')\ni.run()\n")
    best = {}
    for name, cmd in (("casflex", cf), ("opensim", [sys.executable, "-c", script])):
        walls = []
        for _ in range(repeat):
            start = time.perf_counter()
            subprocess.run(cmd, check=True, capture_output=True, cwd=tmp)  # OpenSim's log file goes there
            walls.append(time.perf_counter() - start)
        best[name] = min(walls)
    return best


def _files(trial: Trial, tmp: Path, quick: bool) -> tuple[dict, list[str], Trial]:
    """The trial's model (made planar), markers, plates and tasks: from OPENSIM_MODELS, or (``quick``) the
    excerpt in tests/data/lab that tests/hamner_whole.py cut from them (1 s, the model already planar)."""
    if quick:
        files = {"model": LAB / "hamner_subject02_planar.osim", "markers": LAB / "hamner_running_whole.trc",
                 "grf": LAB / "hamner_running_whole_grf.mot", "tasks": LAB / "hamner_tasks_ik.xml"}
        return files, [], Trial(**{**trial.__dict__, "window": (0.2, 1.2)})
    repo = _models()
    files = {k: _copy(repo, getattr(trial, k), tmp) for k in ("model", "markers", "grf", "tasks")}
    planar = tmp / "planar.osim"
    changes = planar_osim(str(files["model"]), str(planar), KEEP, "planar")
    return {**files, "model": planar}, changes, trial


def run_trial(trial: Trial, tmp: Path, quick: bool) -> dict:
    from casflex.lab import read_sto

    files, changes, trial = _files(trial, tmp, quick)
    ref = _opensim(files, trial, tmp)
    mine = _casflex(files, trial)
    grf = read_sto(files["grf"])
    out = {"trial": trial.name, "window": trial.window, "changes": changes,
           "angles": _angles(mine["scene"], mine["raw"], Path(ref["ik"]["path"])),
           "angles8": _angles(mine["scene"], mine["raw"], Path(ref["ik8"]["path"])),
           "opensim_seconds": ref["ik"]["seconds"] + ref["id"]["seconds"], "casflex_seconds": mine["seconds"],
           "misfit_mm": 1e3 * float(np.nanmedian(mine["raw"].marker_rms)), "moments": {}, "series": {}}
    for f, res in mine["runs"].items():
        for ref_name in ("id", "id_even"):
            out["moments"][(f, ref_name)] = _moments(res, read_sto(ref[ref_name]["path"]), grf, trial.plates)
    even = read_sto(ref["id_even"]["path"])
    out["series"] = {"t": even.t, **{f"os:{j}": even.column(f"{j}_moment") for j in JOINTS},
                     **{f"cf:{j}": mine["runs"]["butterworth"].loads[f"{j}_moment"] for j in JOINTS},
                     **{f"cfo:{j}": mine["runs"]["opensim"].loads[f"{j}_moment"] for j in JOINTS},
                     "t_cf": mine["runs"]["butterworth"].t}
    out["commands"] = _command_times(files, trial, tmp, 1 if quick else 3)
    return out


def figure(result: dict) -> bytes:
    from casflex.plotting._figure import _new_figure

    s = result["series"]
    fig = _new_figure((12, 6.5))
    axes = fig.subplots(2, 3, sharex=True).ravel()
    span = (s["t"] >= s["t"][0] + 0.3) & (s["t"] <= s["t"][0] + 1.8)
    span_cf = (s["t_cf"] >= s["t"][0] + 0.3) & (s["t_cf"] <= s["t"][0] + 1.8)
    for ax, joint in zip(axes, JOINTS[:6], strict=True):
        ax.plot(s["t"][span], s[f"os:{joint}"][span], color="k", lw=2.2, alpha=0.5, label="OpenSim 4.6 ID tool")
        ax.plot(s["t_cf"][span_cf], s[f"cf:{joint}"][span_cf], color="C0", lw=1.1, label="casflex (default filter)")
        ax.plot(s["t_cf"][span_cf], s[f"cfo:{joint}"][span_cf], color="C3", lw=1.0, ls="--",
                label="casflex --filter opensim")
        ax.set(title=f"{joint}_moment", ylabel="N m")
        ax.axhline(0.0, color="0.6", lw=0.6)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    for ax in axes[3:]:
        ax.set_xlabel("t (s)")
    return png(fig)


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    banner = Banner("opensim_gait", quick)
    if importlib.util.find_spec("opensim") is None:
        write_outputs("opensim_gait", out_dir, quick, "# casflex against OpenSim's IK and ID tools\n\n"
                      f"{banner.line()} Skipped: OpenSim is not installed (the peers extra).\n")
        return {}
    with tempfile.TemporaryDirectory(prefix="casflex-opensim-gait-") as tmp:
        result = run_trial(TRIALS[0], Path(tmp), quick)
    page, worst = _page(banner, result, quick)
    lines, failed = checks([
        ("joint angles within 1 deg RMS of OpenSim's IK (the pelvis's translations within 5 mm)",
         f"largest {max(v for k, v in result['angles'].items() if not k.endswith(('_tx', '_ty'))):.2f} deg",
         all(v < (5.0 if k.endswith(("_tx", "_ty")) else 1.0) for k, v in result["angles"].items())),
        ("the same least squares: within 0.01 deg (0.01 mm) of OpenSim's IK run at accuracy 1e-8",
         f"largest {max(result['angles8'].values()):.4f}", max(result["angles8"].values()) < 0.01),
        ("hip, knee and ankle moments within 2 % of OpenSim's peak (RMS over stance), --filter opensim, OpenSim on "
         "the frames' times", f"largest {worst['opensim', 'id_even']:.2f} %", worst["opensim", "id_even"] < 2.0),
        ("the same with casflex's default filter", f"largest {worst['butterworth', 'id_even']:.2f} %",
         worst["butterworth", "id_even"] < 2.0),
        ("the same against OpenSim's pipeline as a lab runs it, default filter",
         f"largest {worst['butterworth', 'id']:.2f} %", worst["butterworth", "id"] < 2.0),
        ("the whole casflex command faster than OpenSim's IK + ID script",
         f"{result['commands']['casflex']:.2f} s against {result['commands']['opensim']:.2f} s",
         result["commands"]["casflex"] < result["commands"]["opensim"], False)])
    write_outputs("opensim_gait", out_dir, quick, "\n".join(page + lines), figure(result))
    assert_checks(failed)
    return result


def _page(banner: Banner, r: dict, quick: bool) -> tuple[list[str], dict]:
    from importlib.metadata import version

    t0, t1 = r["window"]
    worst, rows = {}, []
    for joint in JOINTS:
        cells = [joint, f"{r['angles'][joint]:.2f}", f"{r['angles8'][joint]:.4f}"]
        for key in (("butterworth", "id"), ("opensim", "id"), ("butterworth", "id_even"), ("opensim", "id_even")):
            rms, peak = r["moments"][key][joint]
            if joint != "lumbar_extension":  # the targets: hip, knee, ankle (the lumbar is reported)
                worst[key] = max(worst.get(key, 0.0), 100 * rms / peak)
            cells.append(f"{100 * rms / peak:.2f}")
        rows.append([*cells[:3], f"{r['moments']['opensim', 'id_even'][joint][1]:.0f}", *cells[3:]])
    pelvis = [[c, f"{v:.2f} {'mm' if c.endswith(('_tx', '_ty')) else 'deg'} ({r['angles8'][c]:.4f})"]
              for c, v in r["angles"].items() if c not in JOINTS]
    cmd = r["commands"]
    page = ["# casflex against OpenSim's IK and ID tools on the lab's own model and task weights", "",
            f"{banner.line(OpenSim=version('opensim'))} What is compared and what the numbers mean: "
            "[studies/opensim_gait.md](../studies/opensim_gait.md).", "",
            f"![moments over a stride](../figures/opensim_gait{'_quick' * quick}.png)", "",
            f"{r['trial']}, t = {t0:g}..{t1:g} s; the model made planar ({sum('locked' in c for c in r['changes'])} "
            f"coordinates locked, {sum('set to the normal' in c for c in r['changes'])} axes set to the normal"
            f"{'; tests/data/lab' * quick}); coordinates filtered at "
            f"{CUTOFF:g} Hz, plates not filtered (OpenSim's ID tool). casflex's marker fit: median misfit "
            f"{r['misfit_mm']:.1f} mm RMS over the markers (a planar torso on a running trunk).", "",
            "## Joint angles and moments", "",
            "Angle: RMS of casflex's unfiltered fit minus OpenSim's IK over the trial (deg), OpenSim at its default "
            "accuracy (1e-5, the lab's setup) and at 1e-8. Moments: RMS of casflex "
            "minus OpenSim over the complete stances of the joint's side (lumbar: either foot), % of OpenSim's peak "
            "there; against OpenSim as a lab runs it (its ID tool resamples the IK file's rounded times at 16 ms) "
            "and on the frames' exact times.", "",
            *table(["joint", "angle (deg)", "angle, OpenSim at 1e-8 (deg)", "OpenSim's peak moment (N m)",
                    "default filter, lab's pipeline (%)",
                    "--filter opensim, lab's pipeline (%)", "default filter, exact times (%)",
                    "--filter opensim, exact times (%)"], rows, "lrrrrrrr"), "",
            "The other coordinates (against OpenSim at 1e-8 in brackets): "
            + ", ".join(f"{c} {v}" for c, v in pelvis) + ".", "",
            "## Time", "",
            *table(["", "casflex inverse (whole command)", "OpenSim IK + ID tools (a Python script)", "ratio"],
                   [["wall time, s (best of 3, fresh processes)", f"{cmd['casflex']:.2f}", f"{cmd['opensim']:.2f}",
                     f"{cmd['opensim'] / cmd['casflex']:.1f}x"],
                    ["in-process: casflex's inverse_dynamics, OpenSim's two tools' run()",
                     f"{r['casflex_seconds']:.2f}", f"{r['opensim_seconds']:.2f}",
                     f"{r['opensim_seconds'] / r['casflex_seconds']:.1f}x"]], "lrrr"), ""]
    return page, worst


if __name__ == "__main__":
    cli(__doc__, main)
