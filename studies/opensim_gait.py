"""casflex against OpenSim's own tools on a lab's model, markers and task weights: joint angles and moments.

Two public trials of OpenSim's pipelines (opensim-org/opensim-models at COMMIT), two subjects, two models:
- running: Hamner's subject 02 (10 s at 60 Hz, 41 markers, two plates), the subject's own registered model
  (Hamner 2010: gait2392's legs, a knee whose centre rolls along splines of its angle), the pipeline's
  Tasks_IK.xml (37 weighted markers), coordinates filtered at 10 Hz;
- walking: the Rajagopal pipeline's subject (2.4 s at 100 Hz, 41 markers, two plates), Rajagopal 2016 scaled by
  OpenSim's ScaleTool with the pipeline's two setups (scale, then place the markers on the second static
  trial), its walker knee (rotations and rolling coupled to the knee angle, a patella coupled by a
  constraint), the tasks of its ik_setup_walk.xml, its grf_walk.xml, coordinates filtered at 6 Hz.
Each model is made planar in OpenSim's terms (studies/_planar_osim.py: 14 coordinates free, the others
locked; the ankles', elbows' and knees' axes set to the normal, the knee's coupled rotations held). OpenSim 4.6
(the peers extra) runs its InverseKinematicsTool and InverseDynamicsTool (coordinates filtered, plates
unfiltered, both feet loaded); casflex runs ``inverse`` on the same .osim, trial, task file, loads and cut-off.
Compared, per trial and joint:
- the joint angles (OpenSim's IK against casflex's unfiltered fit), RMS over the trial;
- the moments, RMS over the complete stances of that side's foot (lumbar: of either foot), as % of OpenSim's
  peak there: casflex's default filter and ``--filter opensim``, against OpenSim's pipeline as a lab runs it
  (its IK file keeps the trial's times rounded to the ms, and its ID tool resamples them at the smallest
  step, 16 ms) and against its ID on the frames' exact times (the same times as casflex's);
- the wall time of the whole ``casflex inverse`` command and of OpenSim's two tools in one script.
The model repository: the environment's OPENSIM_MODELS (a clone, or a bare git directory, of
opensim-org/opensim-models); ``--quick`` takes the 1 s excerpt of the running trial in tests/data/lab
instead. What the numbers mean: docs/studies/opensim_gait.md.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from _planar_osim import planar_osim
from _study import Banner, assert_checks, checks, cli, png, table, write_outputs

COMMIT = "20a888b"
LAB = Path(__file__).resolve().parents[1] / "tests" / "data" / "lab"
STANCE_N = 20.0  # N: a plate's vertical force above this is contact
KEEP = ("pelvis_tilt", "pelvis_tx", "pelvis_ty", "hip_flexion_r", "hip_flexion_l", "knee_angle_r", "knee_angle_l",
        "ankle_angle_r", "ankle_angle_l", "lumbar_extension", "arm_flex_r", "arm_flex_l", "elbow_flex_r",
        "elbow_flex_l")
JOINTS = ("hip_flexion_r", "knee_angle_r", "ankle_angle_r", "hip_flexion_l", "knee_angle_l", "ankle_angle_l",
          "lumbar_extension")
MAX_MISFIT = 0.3  # m: a planar torso leaves the running trunk's rotation out: shoulder markers 0.1 m off


@dataclass(frozen=True)
class Scaling:
    """A pipeline's scale step: its folder's files ``inputs`` and ``setups`` copied as they lie, the generic
    model where the setups look for it (``generic_as``), the setups run in turn, the scaled model read."""

    folder: str
    generic: str
    generic_as: str
    setups: tuple[str, ...]
    inputs: tuple[str, ...]
    scaled: str


@dataclass(frozen=True)
class Trial:
    """A trial: repository paths; ``plates`` body -> column prefix, or ``loads`` the pipeline's ExternalLoads
    file; ``model`` the subject's model, or ``scaling`` makes it; ``tasks`` an IK task set or setup file."""

    name: str
    stem: str
    model: str
    markers: str
    grf: str
    tasks: str
    window: tuple[float, float]
    rate: float  # Hz, the markers'
    cutoff: float  # Hz, the coordinates' (both tools)
    plates: dict = field(default_factory=dict)
    loads: str | None = None
    scaling: Scaling | None = None


_RAJAGOPAL = "Pipelines/Rajagopal"
TRIALS = (Trial("Hamner subject 02, running", "run", "Pipelines/Hamner/outputReference/subject02_registered.osim",
                "Pipelines/Hamner/subject02_running.trc", "Pipelines/Hamner/subject02_running_grf.mot",
                "Pipelines/Hamner/Tasks_IK.xml", (0.0, 9.983), 60.0, 10.0,  # Hamner et al. 2010 filtered at 12 Hz
                plates={"calcn_r": "ground_", "calcn_l": "1_ground_"}),
          Trial("Rajagopal pipeline's subject, walking", "walk", "", f"{_RAJAGOPAL}/ExpData/motion_capture_walk.trc",
                f"{_RAJAGOPAL}/ExpData/grf_walk.mot", f"{_RAJAGOPAL}/IK/ik_setup_walk.xml", (0.0, 2.37), 100.0, 6.0,
                loads=f"{_RAJAGOPAL}/ID/grf_walk.xml",
                scaling=Scaling(_RAJAGOPAL, "Models/Rajagopal/Rajagopal2016.osim", "generic_unscaled.osim",
                                ("Scale/scale_setup_walk_scaleOnly.xml", "Scale/scale_setup_walk.xml"),
                                ("Scale/markerset_walk_preScale.xml", "ExpData/static_walk_1.trc",
                                 "ExpData/static_walk_2.trc"), "Scale/subject_scaled_walk.osim")))


def _models() -> Path:
    path = os.environ.get("OPENSIM_MODELS")
    if not path or not Path(path).exists():
        raise SystemExit("OPENSIM_MODELS: the path of a clone (or bare git directory) of opensim-org/opensim-models")
    return Path(path)


def _copy(repo: Path, name: str, out: Path) -> Path:
    """The repository's file ``name`` at COMMIT, written to ``out``."""
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_bytes(subprocess.run(["git", f"--git-dir={repo / '.git' if (repo / '.git').exists() else repo}",
                                    "show", f"{COMMIT}:{name}"], check=True, capture_output=True).stdout)
    return out


def _opensim(files: dict, trial: Trial, tmp: Path) -> dict:
    from casflex.peers.opensim_tools import exact_times, inverse_dynamics, inverse_kinematics

    t0, t1 = trial.window
    ik = inverse_kinematics(files["model"], files["markers"], files["tasks"], tmp / "ik.mot", t_start=t0, t_end=t1)
    loads, cutoff = files["loads"], trial.cutoff
    idv = inverse_dynamics(files["model"], ik["path"], tmp / "id.sto", loads=loads, cutoff=cutoff, t_start=t0,
                           t_end=t1)
    even = exact_times(ik["path"], tmp / "ik_even.mot", t0, trial.rate)
    ide = inverse_dynamics(files["model"], even, tmp / "id_even.sto", loads=loads, cutoff=cutoff, t_start=t0,
                           t_end=t1)
    ik8 = inverse_kinematics(files["model"], files["markers"], files["tasks"], tmp / "ik8.mot", t_start=t0, t_end=t1,
                             accuracy=1e-8)
    return {"ik": ik, "ik8": ik8, "id": idv, "id_even": ide}


def _casflex(files: dict, trial: Trial) -> dict:
    from casflex.inverse import Filter, Fit, inverse_dynamics
    from casflex.inverse import Trial as Recorded
    from casflex.scene.from_osim import scene_from_osim

    scene = scene_from_osim(files["model"]).scene
    recorded = Recorded(files["markers"], grf=files["loads"], tasks=files["tasks"], t_start=trial.window[0],
                        t_end=trial.window[1])
    fit = Fit(max_misfit=MAX_MISFIT)
    raw = inverse_dynamics(scene, recorded, filter=Filter(None, None), fit=fit)
    start = time.perf_counter()
    runs = {f: inverse_dynamics(scene, recorded, filter=Filter(trial.cutoff, None, f), fit=fit)
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


def _stances(grf, vertical: str, t: np.ndarray) -> np.ndarray:
    """The times t (k,) within complete stances on the plate whose vertical force is the column ``vertical``
    (contact begun and ended inside t)."""
    on = np.interp(t, grf.t, grf.column(vertical)) > STANCE_N
    starts = np.flatnonzero(~on[:-1] & on[1:]) + 1
    ends = np.flatnonzero(on[:-1] & ~on[1:])  # each stance's last loaded time
    mask = np.zeros_like(on)
    for a in starts:
        b = ends[ends >= a]
        if b.size:
            mask[a:b[0] + 1] = True
    return mask


def _moments(res, ref, grf, loads: Path) -> dict:
    """{joint: (RMS of casflex - OpenSim over the joint's stances, OpenSim's peak there)} (N m), casflex's
    loads taken at OpenSim's times by a cubic spline (OpenSim's pipeline resamples the frames); the feet's
    plates are the ExternalLoads file ``loads``'s."""
    from scipy.interpolate import CubicSpline

    from casflex.lab.setups import read_external_loads

    plates = read_external_loads(loads).plates
    feet = {side: next(f"{i[0]}y" for b, i in plates.items() if b.endswith(f"_{side}")) for side in "rl"}
    stance = {s: _stances(grf, column, ref.t) for s, column in feet.items()}
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


def commands(files: dict, trial: Trial, tmp: Path, casflex_python: str = sys.executable,
             opensim_python: str = sys.executable) -> dict[str, list[str]]:
    """{"casflex": the whole ``casflex inverse`` command, "opensim": a Python script running OpenSim's IK and ID
    tools} on the trial's files, each writing into ``tmp`` (also studies/bench_opensim_trials.py's)."""
    t0, t1 = trial.window
    cf = [casflex_python, "-m", "casflex", "inverse", str(files["model"]), "--data", str(files["markers"]),
          "--loads", str(files["loads"]), "--tasks", str(files["tasks"]), "--cutoff", f"{trial.cutoff:g}",
          "--cutoff-plates", "none", "--t-start", f"{t0:g}", "--t-end", f"{t1:g}", "--max-misfit",
          f"{MAX_MISFIT:g}", "--out", str(tmp / "cf.sto"), "--quiet"]
    script = (f"import opensim as o\no.Logger.removeFileSink()\nm=o.Model({str(files['model'])!r})\n"
              "ik=o.InverseKinematicsTool()\n"
              f"ik.setModel(m)\nik.setMarkerDataFileName({str(files['markers'])!r})\n"
              f"ik.set_IKTaskSet(o.IKTaskSet({str(files['tasks'])!r}))\nik.setStartTime({t0})\nik.setEndTime({t1})\n"
              f"ik.setResultsDir({str(tmp)!r})\nik.setOutputMotionFileName({str(tmp / 'os_ik.mot')!r})\n"
              "ik.set_report_marker_locations(False)\nik.set_report_errors(False)\nik.run()\n"
              "i=o.InverseDynamicsTool()\nm2=o.Model(m)\ni.setModel(m2)\n"
              f"i.setCoordinatesFileName({str(tmp / 'os_ik.mot')!r})\ni.setLowpassCutoffFrequency({trial.cutoff})\n"
              f"i.setExternalLoadsFileName({str(files['loads'])!r})\ni.setStartTime({t0})\ni.setEndTime({t1})\n"
              f"i.setResultsDir({str(tmp)!r})\ni.setOutputGenForceFileName('os_id.sto')\ni.run()\n")
    return {"casflex": cf, "opensim": [opensim_python, "-c", script]}


def _command_times(files: dict, trial: Trial, tmp: Path, repeat: int) -> dict:
    """Wall time (s, best of ``repeat``) of the whole ``casflex inverse`` command and of a Python script running
    OpenSim's IK and ID tools, each a fresh process, side by side."""
    best = {}
    for name, cmd in commands(files, trial, tmp).items():
        walls = []
        for _ in range(repeat):
            start = time.perf_counter()
            subprocess.run(cmd, check=True, capture_output=True, cwd=tmp)  # OpenSim's log file goes there
            walls.append(time.perf_counter() - start)
        best[name] = min(walls)
    return best


def _tasks(src: Path, out: Path) -> Path:
    """The IK task set of ``src`` (a task set file, or an IK setup holding one) alone in ``out``: OpenSim's
    IKTaskSet reads only the former (casflex's --tasks takes both)."""
    root = ET.parse(src).getroot()
    tasks = root if root.tag == "IKTaskSet" else root.find(".//IKTaskSet")
    ET.ElementTree(tasks).write(out, encoding="UTF-8", xml_declaration=True)
    return out


def _loads(repo: Path, trial: Trial, grf: Path, tmp: Path) -> Path:
    """The trial's ExternalLoads file: the pipeline's, its data file the copy ``grf`` (its model kinematics file
    not used: plates expressed in the ground), or one written for ``trial.plates``."""
    from casflex.peers.opensim_tools import external_loads

    if not trial.loads:
        return Path(external_loads(tmp / "loads.xml", grf, trial.plates))
    tree = ET.parse(_copy(repo, trial.loads, tmp / "loads.xml"))
    tree.getroot().find(".//datafile").text = str(grf)
    kin = tree.getroot().find(".//external_loads_model_kinematics_file")
    if kin is not None:
        kin.text = None
    tree.write(tmp / "loads.xml", encoding="UTF-8", xml_declaration=True)
    return tmp / "loads.xml"


def _scaled(repo: Path, scaling: Scaling, tmp: Path) -> tuple[Path, float]:
    """The subject's model scaled by OpenSim's ScaleTool with the pipeline's setups; the tool's seconds."""
    from casflex.peers.opensim_tools import scale

    folder = tmp / "pipeline"
    _copy(repo, scaling.generic, folder / scaling.generic_as)
    for name in (*scaling.inputs, *scaling.setups):
        _copy(repo, f"{scaling.folder}/{name}", folder / name)
    seconds = scale(*(folder / s for s in scaling.setups))["seconds"]
    return folder / scaling.scaled, seconds


def _files(trial: Trial, tmp: Path, quick: bool) -> tuple[dict, list[str], Trial]:
    """The trial's model (made planar), markers, plates, loads and tasks: from OPENSIM_MODELS, or (``quick``)
    the excerpt in tests/data/lab that tests/hamner_whole.py cut from them (1 s, the model already planar)."""
    from casflex.peers.opensim_tools import external_loads

    if quick:
        files = {"model": LAB / "hamner_subject02_planar.osim", "markers": LAB / "hamner_running_whole.trc",
                 "grf": LAB / "hamner_running_whole_grf.mot", "tasks": LAB / "hamner_tasks_ik.xml"}
        files["loads"] = Path(external_loads(tmp / "loads.xml", files["grf"], trial.plates))
        return files, [], Trial(**{**trial.__dict__, "window": (0.2, 1.2)})
    repo = _models()
    files = {k: _copy(repo, getattr(trial, k), tmp / Path(getattr(trial, k)).name) for k in ("markers", "grf")}
    files["tasks"] = _tasks(_copy(repo, trial.tasks, tmp / "setup_ik.xml"), tmp / "tasks.xml")
    files["loads"] = _loads(repo, trial, files["grf"], tmp)
    changes = []
    if trial.scaling:
        files["model"], seconds = _scaled(repo, trial.scaling, tmp)
        changes.append(f"scaled by OpenSim's ScaleTool ({len(trial.scaling.setups)} setups, {seconds:.1f} s)")
    else:
        files["model"] = _copy(repo, trial.model, tmp / "model.osim")
    changes += planar_osim(str(files["model"]), str(tmp / "planar.osim"), KEEP, "planar")
    return {**files, "model": tmp / "planar.osim"}, changes, trial


def run_trial(trial: Trial, tmp: Path, quick: bool) -> dict:
    from casflex.lab import read_sto

    files, changes, trial = _files(trial, tmp, quick)
    ref = _opensim(files, trial, tmp)
    mine = _casflex(files, trial)
    grf = read_sto(files["grf"])
    out = {"trial": trial.name, "stem": trial.stem, "window": trial.window, "cutoff": trial.cutoff, "changes": changes,
           "angles": _angles(mine["scene"], mine["raw"], Path(ref["ik"]["path"])),
           "angles8": _angles(mine["scene"], mine["raw"], Path(ref["ik8"]["path"])),
           "opensim_seconds": ref["ik"]["seconds"] + ref["id"]["seconds"], "casflex_seconds": mine["seconds"],
           "misfit_mm": 1e3 * float(np.nanmedian(mine["raw"].marker_rms)), "moments": {}, "series": {}}
    for f, res in mine["runs"].items():
        for ref_name in ("id", "id_even"):
            out["moments"][(f, ref_name)] = _moments(res, read_sto(ref[ref_name]["path"]), grf, files["loads"])
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


def _figure_stem(result: dict) -> str:
    return "opensim_gait" if result["stem"] == "run" else f"opensim_gait_{result['stem']}"


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    banner = Banner("opensim_gait", quick)
    if importlib.util.find_spec("opensim") is None:
        write_outputs("opensim_gait", out_dir, quick, "# casflex against OpenSim's IK and ID tools\n\n"
                      f"{banner.line()} Skipped: OpenSim is not installed (the peers extra).\n")
        return {}
    results = []
    for trial in TRIALS[:1] if quick else TRIALS:
        with tempfile.TemporaryDirectory(prefix="casflex-opensim-gait-") as tmp:
            results.append(run_trial(trial, Path(tmp), quick))
    page, worst = _page(banner, results, quick)
    gait = [j for j in JOINTS if j != "lumbar_extension"] + ["pelvis_tilt", "lumbar_extension"]
    angles = max(r["angles"][k] for r in results for k in gait)
    arms = max(v for r in results for k, v in r["angles"].items() if k.startswith(("arm_", "elbow_")))
    moves = max(v for r in results for k, v in r["angles"].items() if k.endswith(("_tx", "_ty")))
    angles8 = max(v for r in results for v in r["angles8"].values())
    cmd = [(r["commands"]["casflex"], r["commands"]["opensim"]) for r in results]
    lines, failed = checks([
        ("pelvis, hip, knee, ankle and lumbar angles within 1 deg RMS of OpenSim's IK at the lab's accuracy (the "
         "pelvis's translations within 5 mm), every trial", f"largest {angles:.2f} deg, {moves:.2f} mm",
         angles < 1.0 and moves < 5.0),
        ("the arms' angles, the same (their light markers leave OpenSim's IK short of its minimum at 1e-5; the next "
         "check is the fit's)", f"largest {arms:.2f} deg", arms < 1.0, False),
        ("the same least squares: every angle within 0.01 deg (0.01 mm) of OpenSim's IK run at accuracy 1e-8",
         f"largest {angles8:.4f}", angles8 < 0.01),
        ("hip, knee and ankle moments within 2 % of OpenSim's peak (RMS over stance), --filter opensim, OpenSim on "
         "the frames' times", f"largest {worst['opensim', 'id_even']:.2f} %", worst["opensim", "id_even"] < 2.0),
        ("the same against OpenSim's pipeline as a lab runs it, --filter opensim",
         f"largest {worst['opensim', 'id']:.2f} %", worst["opensim", "id"] < 2.0),
        ("the same with casflex's default filter (another filter: 4th-order Winter against OpenSim's padded 6th "
         "order; the difference is the filters')", f"largest {worst['butterworth', 'id_even']:.2f} %",
         worst["butterworth", "id_even"] < 2.0, False),
        ("the whole casflex command faster than OpenSim's IK + ID script, every trial",
         ", ".join(f"{a:.2f} s against {b:.2f} s" for a, b in cmd), all(a < b for a, b in cmd), False)])
    write_outputs("opensim_gait", out_dir, quick, "\n".join(page + lines),
                  {_figure_stem(r): figure(r) for r in results})
    assert_checks(failed)
    return {"results": results, "worst": worst}


def _section(r: dict, quick: bool, worst: dict) -> list[str]:
    """The page's part for the trial result ``r``; ``worst`` gets its hip, knee and ankle's largest % ."""
    t0, t1 = r["window"]
    rows = []
    for joint in JOINTS:
        cells = [joint, f"{r['angles'][joint]:.2f}", f"{r['angles8'][joint]:.4f}"]
        for key in (("butterworth", "id"), ("opensim", "id"), ("butterworth", "id_even"), ("opensim", "id_even")):
            rms, peak = r["moments"][key][joint]
            if joint != "lumbar_extension":  # the targets: hip, knee, ankle (the lumbar is reported)
                worst[key] = max(worst.get(key, 0.0), 100 * rms / peak)
            cells.append(f"{100 * rms / peak:.2f}")
        rows.append([*cells[:3], f"{r['moments']['opensim', 'id_even'][joint][1]:.0f}", *cells[3:]])
    others = [[c, f"{v:.2f} {'mm' if c.endswith(('_tx', '_ty')) else 'deg'} ({r['angles8'][c]:.4f})"]
              for c, v in r["angles"].items() if c not in JOINTS]
    cmd = r["commands"]
    made = [c for c in r["changes"] if "scaled" in c]
    return [f"## {r['trial']}", "",
            f"![moments over a stride](../figures/{_figure_stem(r)}{'_quick' * quick}.png)", "",
            f"t = {t0:g}..{t1:g} s; {''.join(m + '; ' for m in made)}the model made planar "
            f"({sum('locked' in c for c in r['changes'])} coordinates locked, "
            f"{sum('set to the normal' in c for c in r['changes'])} axes set to the normal, "
            f"{sum('(following' in c for c in r['changes'])} coupled rotations held"
            f"{'; tests/data/lab' * quick}); coordinates filtered at {r['cutoff']:g} Hz, plates not filtered "
            f"(OpenSim's ID tool). casflex's marker fit: median misfit {r['misfit_mm']:.1f} mm RMS over the "
            "markers (a planar torso on a 3D trunk).", "",
            *table(["joint", "angle (deg)", "angle, OpenSim at 1e-8 (deg)", "OpenSim's peak moment (N m)",
                    "default filter, lab's pipeline (%)", "--filter opensim, lab's pipeline (%)",
                    "default filter, exact times (%)", "--filter opensim, exact times (%)"], rows, "lrrrrrrr"), "",
            "The other coordinates (against OpenSim at 1e-8 in brackets): "
            + ", ".join(f"{c} {v}" for c, v in others) + ".", "",
            *table(["time", "casflex inverse (whole command)", "OpenSim IK + ID tools (a Python script)", "ratio"],
                   [[f"wall time, s (best of {1 if quick else 3}, fresh processes)", f"{cmd['casflex']:.2f}",
                     f"{cmd['opensim']:.2f}", f"{cmd['opensim'] / cmd['casflex']:.1f}x"],
                    ["in-process: casflex's inverse_dynamics, OpenSim's two tools' run()",
                     f"{r['casflex_seconds']:.2f}", f"{r['opensim_seconds']:.2f}",
                     f"{r['opensim_seconds'] / r['casflex_seconds']:.1f}x"]], "lrrr"), ""]


def _page(banner: Banner, results: list[dict], quick: bool) -> tuple[list[str], dict]:
    from importlib.metadata import version

    worst: dict = {}
    sections = [line for r in results for line in _section(r, quick, worst)]
    page = ["# casflex against OpenSim's IK and ID tools on the lab's own model and task weights", "",
            f"{banner.line(OpenSim=version('opensim'))} What is compared and what the numbers mean: "
            "[studies/opensim_gait.md](../studies/opensim_gait.md).", "",
            "Angle: RMS of casflex's unfiltered fit minus OpenSim's IK over the trial (deg), OpenSim at its default "
            "accuracy (1e-5, the lab's setup) and at 1e-8. Moments: RMS of casflex "
            "minus OpenSim over the complete stances of the joint's side (lumbar: either foot), % of OpenSim's peak "
            "there; against OpenSim as a lab runs it (its ID tool resamples the IK file's times, rounded to the ms, "
            "at their smallest step) and on the frames' exact times.", "", *sections]
    return page, worst


if __name__ == "__main__":
    cli(__doc__, main)
