"""casflex's muscle path against OpenSim 4.6's StaticOptimization and JointReaction on public trials.

Trials of opensim-org/opensim-models (commit 20a888b; the files in tests/data, their provenance in the READMEs
there), each run by both tools on the same model file, coordinates, plates and reserves:
- run: Hamner's subject 02 running (tests/data/lab's excerpt: 61 frames at 60 Hz, both stances), the subject's model
  made planar with its 92 Thelen2003Muscle muscles (tests/data/muscles/hamner_subject02_planar_muscles.osim), OpenSim's
  IK of the excerpt on that model with the lab's Tasks_IK.xml, the plates as the pipeline's External_Loads.xml
  assigns them (the excerpt's times, sixtieths of a second rounded to the ms, set to the frames' exact times, as
  they are for the IK's coordinates), reserves written here: a CoordinateActuator of optimal force 1 N m on each
  free coordinate but the pelvis's, and the residuals FX, FY (1 N) and MZ (1 N m) on the pelvis; 10 Hz.
OpenSim runs SO at its defaults (activation exponent 2, convergence 1e-4, 100 iterations: as a lab runs it) and, not
in --quick, again with 1000 iterations; then JR of hip_r, knee_r, ankle_r on the child in the child's frame with SO's
forces. casflex runs ``prepare``/``solve`` (filter "opensim", plates unfiltered) and
``casflex.muscles.analysis.TrialMuscles`` on the same files. Measured per trial: each muscle's force (RMS of casflex
minus OpenSim over the trial, % of that muscle's peak), the reactions' in-plane force (RMS, % of its peak) and moment
(RMS, N m), each SO's cost and OpenSim's balance where its optimizer reported failure, the right hip's contact force
in body weights beside the instrumented implants' (docs/muscles.md), and the wall time of both paths.
``--quick``: the first trial at hand, OpenSim at its defaults. What the numbers mean: docs/studies/opensim_muscles.md.
"""

from __future__ import annotations

import importlib.util
import tempfile
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from _study import Banner, assert_checks, checks, cli, png, table, write_outputs

ROOT = Path(__file__).resolve().parents[1]
MUSCLES, LAB = ROOT / "tests" / "data" / "muscles", ROOT / "tests" / "data" / "lab"
JOINTS = (("hip_r", "femur_r"), ("knee_r", "tibia_r"), ("ankle_r", "talus_r"))
STANCE_N = 20.0  # N: a plate's vertical force above this is contact
#: In-vivo hip contact force, instrumented implants: (BW, what, source) per trial.
IN_VIVO = {"walk": (2.38, "average peak, 4 patients walking at about 4 km/h",
                    "Bergmann et al. 2001, J Biomech 34:859-871"),
           "run": (5.5, "jogging, one patient",
                   "Bergmann, Graichen, Rohlmann 1993, J Biomech 26:969-990")}


@dataclass(frozen=True)
class Trial:
    """A trial: its model, (coordinates or markers and IK tasks), plates, reserves (None: written here), cut-off
    (Hz), span (s), frame rate (Hz) and the muscles its figure shows."""

    name: str
    stem: str
    model: Path
    grf: Path
    cutoff: float
    window: tuple[float, float]
    rate: float
    shown: tuple[str, ...]
    coordinates: Path | None = None
    loads: Path | None = None
    markers: Path | None = None
    tasks: Path | None = None
    reserves: Path | None = None
    vertical: str = "ground_force_vy"  # the right plate's vertical force's column
    joints: tuple[tuple[str, str], ...] = JOINTS
    gait: str = ""  # IN_VIVO's key (else the stem)


TRIALS = (Trial("Hamner subject 02, running (planar, 92 Thelen muscles)", "run",
                MUSCLES / "hamner_subject02_planar_muscles.osim", LAB / "hamner_running_whole_grf.mot", 10.0,
                (0.2, 1.2), 60.0, ("glut_max2_r", "glut_med1_r", "vas_lat_r", "soleus_r"),
                markers=LAB / "hamner_running_whole.trc", tasks=LAB / "hamner_tasks_ik.xml"),
          Trial("Rajagopal pipeline's walk (planar, 80 Millard muscles, no wraps)", "rajagopal_walk",
                MUSCLES / "rajagopal_walk_planar_muscles.osim", MUSCLES / "rajagopal_walk_grf.mot", 6.0, (0.1, 1.75),
                100.0, ("glmax2_r", "glmed1_r", "vaslat_r", "soleus_r"), loads=MUSCLES / "rajagopal_walk_grf.xml",
                markers=MUSCLES / "rajagopal_walk.trc", tasks=MUSCLES / "rajagopal_walk_ik_tasks.xml",
                vertical="ground_force_r_vy", joints=(("hip_r", "femur_r"), ("walker_knee_r", "tibia_r"),
                                                      ("ankle_r", "talus_r")), gait="walk"))


def reserves(path: Path, model: Path) -> Path:
    """The run's reserves: a CoordinateActuator of 1 N m on each free coordinate but the pelvis's, FX and FY
    (1 N, in the ground's axes, at the pelvis's origin) and MZ (1 N m) on the pelvis."""
    from casflex.muscles.analysis import reserve_actuators
    from casflex.scene.from_osim import scene_from_osim
    from casflex.scene.osim_actuators import write_actuators

    return Path(write_actuators(path, reserve_actuators(scene_from_osim(model).scene, "pelvis", 1.0), "reserves"))


def files(trial: Trial, tmp: Path) -> dict:
    """The trial's model, coordinates, loads and reserves as both tools read them (the run's IK by OpenSim)."""
    from casflex.peers.opensim_tools import exact_times, external_loads, inverse_kinematics

    if trial.coordinates is not None:
        return {"model": trial.model, "coordinates": trial.coordinates, "loads": trial.loads,
                "reserves": trial.reserves, "grf": trial.grf, "ik_seconds": 0.0}
    t0, t1 = trial.window
    ik = inverse_kinematics(trial.model, trial.markers, trial.tasks, tmp / "ik.mot", t_start=t0, t_end=t1)
    if trial.loads is not None:  # the pipeline's ExternalLoads, its plates' rows on the frames' times already
        tree = ET.parse(trial.loads)
        tree.getroot().find(".//datafile").text = str(trial.grf)
        tree.write(tmp / "loads.xml", encoding="UTF-8", xml_declaration=True)
        grf, loads = trial.grf, tmp / "loads.xml"
    else:
        grf = exact_times(trial.grf, tmp / "grf.mot", t0, trial.rate)
        loads = Path(external_loads(tmp / "loads.xml", grf, {"calcn_r": "ground_", "calcn_l": "1_ground_"}))
    return {"model": trial.model, "coordinates": Path(exact_times(ik["path"], tmp / "ik_even.mot", t0, trial.rate)),
            "loads": loads, "reserves": reserves(tmp / "reserves.xml", trial.model), "grf": Path(grf),
            "ik_seconds": ik["seconds"]}


def opensim(trial: Trial, f: dict, tmp: Path, iterations: int) -> dict:
    """OpenSim's SO (``iterations`` per frame) then JR; the output tables read back."""
    from casflex.lab.tables import read_sto
    from casflex.peers.opensim_analyses import Trial as OsimTrial
    from casflex.peers.opensim_analyses import static_optimization

    t0, t1 = trial.window
    run = OsimTrial(f["model"], f["coordinates"], loads=f["loads"], forces=(f["reserves"],), cutoff=trial.cutoff,
                    t_start=t0, t_end=t1)
    so = static_optimization(run, tmp / f"so{iterations}", max_iterations=iterations,
                             joints=[j for j, _ in trial.joints], on="child", frame="child")
    return {"force": read_sto(so["force"]), "activation": read_sto(so["activation"]), "jr": read_sto(so["reactions"]),
            "failed": so["failed"], "seconds": so["so_seconds"] + so["jr_seconds"], "so_seconds": so["so_seconds"],
            "jr_seconds": so["jr_seconds"]}


def casflex(trial: Trial, f: dict) -> dict:
    """casflex's whole muscle path from the files: inverse dynamics, paths, SO, residuals, reactions (timed)."""
    from casflex.inverse import Filter, prepare, solve
    from casflex.inverse import Trial as InverseTrial
    from casflex.muscles.analysis import TrialMuscles
    from casflex.muscles.reaction import JointReaction
    from casflex.scene.from_osim import scene_from_osim
    from casflex.scene.osim_actuators import read_actuators

    start = time.perf_counter()
    inputs = prepare(f["model"], InverseTrial(coordinates=f["coordinates"], grf=f["loads"]),
                     filter=Filter(trial.cutoff, None, "opensim"))
    res = solve(inputs)
    osim = scene_from_osim(f["model"], muscles=True)
    tm = TrialMuscles(osim, inputs.tree, res.t, res.plates, read_actuators(f["reserves"]),
                      reaction=JointReaction(on="child", frame="child"), joints=tuple(j for j, _ in trial.joints))
    out = tm.solve(res.z, res.zd, res.zdd)
    return {"t": res.t, "out": out, "trial": tm, "names": [m.name for m in osim.muscles],
            "seconds": time.perf_counter() - start}


def _at(table_, t, names) -> np.ndarray:
    return np.column_stack([np.interp(t, table_.t, table_.column(n)) for n in names])


def body_weight(model: Path) -> float:
    """N: the model's mass times its gravity."""
    from casflex.scene.osim import read_osim

    m = read_osim(model)
    return float(sum(b.mass for b in m.bodies.values()) * np.linalg.norm(m.gravity))


def compare(mine: dict, ref: dict, joints_: tuple = JOINTS) -> dict:
    """The measures of one OpenSim run against casflex's (module docstring)."""
    t, out, names = mine["t"], mine["out"], mine["names"]
    failed = np.array([any(abs(x - f) < 1e-6 for f in ref["failed"]) for x in t])
    theirs = _at(ref["force"], t, names)
    rms = np.sqrt(np.mean((out.so.forces - theirs) ** 2, axis=0))
    peak = np.abs(theirs).max(axis=0)
    ok = ~failed  # the frames OpenSim solved: at the others its answer depends on the actuators' order
    rms_ok = np.sqrt(np.mean((out.so.forces[ok] - theirs[ok]) ** 2, axis=0))
    peak_ok = np.abs(theirs[ok]).max(axis=0)
    coords = [c.name for c in mine["trial"].joint_coordinates]
    acts = _at(ref["activation"], t, names)
    controls = _at(ref["activation"], t, [f"{c}_reserve" for c in coords])
    cost_os = (acts ** 2).sum(1) + (controls ** 2).sum(1)
    cost_cf = (out.so.activations ** 2).sum(1) + (out.so.reserve_controls ** 2).sum(1)
    balance = np.einsum("kmc,km->kc", out.arms, acts * out.active) + controls - out.moments
    joints = {}
    for joint, body in joints_:
        th = _at(ref["jr"], t, [f"{joint}_on_{body}_in_{body}_{c}" for c in ("fx", "fy", "fz", "mz")])
        ours = out.reactions[joint].loads[:, 0, :]
        f_cf, f_os = np.hypot(ours[:, 0], ours[:, 1]), np.hypot(th[:, 0], th[:, 1])
        joints[joint] = {"force_pct": 100 * float(np.sqrt(np.mean((f_cf - f_os) ** 2))) / f_os.max(),
                         "xy_pct": 100 * float(np.sqrt(np.mean((ours[:, :2] - th[:, :2]) ** 2, axis=0)).max())
                         / f_os.max(),
                         "mz_rms": float(np.sqrt(np.mean((ours[:, 2] - th[:, 3]) ** 2))), "peak": float(f_os.max()),
                         "cf": f_cf, "os": f_os, "os3d": np.sqrt(f_os ** 2 + th[:, 2] ** 2)}
    return {"pct": 100 * rms / peak, "rms": rms, "peak": peak, "pct_ok": 100 * rms_ok / peak_ok, "rms_ok": rms_ok,
            "peak_ok": peak_ok, "failed": failed,
            "theirs": theirs, "cost_os": cost_os, "cost_cf": cost_cf, "balance": np.abs(balance).max(axis=1),
            "joints": joints, "seconds": ref["seconds"], "so_seconds": ref["so_seconds"],
            "jr_seconds": ref["jr_seconds"]}


def stance(grf_path: Path, t: np.ndarray, column: str = "ground_force_vy") -> tuple[np.ndarray, np.ndarray]:
    """(contact, complete) (k,) bool: the right plate's vertical force above STANCE_N, and the frames of the
    stances begun and ended inside the trial (a peak at the trial's edge is the filter's)."""
    from casflex.lab.tables import read_sto

    grf = read_sto(grf_path)
    on = np.interp(t, grf.t, grf.column(column)) > STANCE_N
    whole = np.zeros_like(on)
    for a, b in _spans(on):
        if a > 0 and b < len(on) - 1:
            whole[a:b + 1] = True
    return on, whole


def run_trial(trial: Trial, tmp: Path, quick: bool) -> dict:
    f = files(trial, tmp)
    refs = {100: opensim(trial, f, tmp, 100)}
    mine = casflex(trial, f)
    if not quick:
        refs[1000] = opensim(trial, f, tmp, 1000)
    bw = body_weight(trial.model)
    res = {"trial": trial, "mine": mine, "bw": bw, "cmp": {k: compare(mine, r, trial.joints) for k, r in refs.items()},
           "ik_seconds": f["ik_seconds"]}
    res["stance"], on = stance(f["grf"], mine["t"], trial.vertical)
    hip = res["cmp"][100]["joints"]["hip_r"]
    res["hip_bw"] = {k: float(hip[k][on].max() / bw) for k in ("cf", "os", "os3d")}
    return res


def figure(r: dict) -> bytes:
    from casflex.plotting._figure import _new_figure

    trial, mine, c = r["trial"], r["mine"], r["cmp"][100]
    t, bw = mine["t"], r["bw"]
    fig = _new_figure((12, 7.5))
    grid = fig.add_gridspec(2, 4, height_ratios=(1.3, 1.0))
    ax = fig.add_subplot(grid[0, :])
    hip = c["joints"]["hip_r"]
    for a, b in _spans(r["stance"]):
        ax.axvspan(t[a], t[b], color="0.92", lw=0)
    value, what, source = IN_VIVO[trial.gait or trial.stem]
    ax.axhline(value, color="C2", ls=":", lw=1.5, label=f"in vivo {value:g} BW: {what} ({source})")
    ax.plot(t, hip["os3d"] / bw, color="0.5", lw=1.0, ls="--", label="OpenSim 4.6 JR, with its out-of-plane force")
    ax.plot(t, hip["os"] / bw, color="k", lw=2.4, alpha=0.45, label="OpenSim 4.6 SO + JR, in the plane")
    ax.plot(t, hip["cf"] / bw, color="C0", lw=1.1, label="casflex TrialMuscles, in the plane")
    if c["failed"].any():
        ax.plot(t[c["failed"]], hip["os"][c["failed"]] / bw, "x", color="C3", ms=6, label="OpenSim SO failed there")
    ax.set(title=f"{trial.name}: right hip contact force (right stance shaded)", ylabel="body weights", xlabel="t (s)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7.5, loc="upper left", framealpha=0.9)
    names = mine["names"]
    for k, m in enumerate(trial.shown):
        ax = fig.add_subplot(grid[1, k])
        i = names.index(m)
        ax.plot(t, c["theirs"][:, i], color="k", lw=2.4, alpha=0.45, label="OpenSim SO")
        ax.plot(t, mine["out"].so.forces[:, i], color="C0", lw=1.1, label="casflex")
        if c["failed"].any():
            ax.plot(t[c["failed"]], c["theirs"][c["failed"], i], "x", color="C3", ms=5)
        ax.set(title=m, xlabel="t (s)", ylabel="N" if k == 0 else None)
        ax.grid(alpha=0.3)
    fig.axes[1].legend(fontsize=7.5)
    return png(fig)


def _spans(mask: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) index of each run of True in ``mask``."""
    edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(int), 0]))
    return [(a, b - 1) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def _section(r: dict, quick: bool) -> list[str]:
    trial, mine = r["trial"], r["mine"]
    rows, names = [], mine["names"]
    for key, c in r["cmp"].items():
        i = int(np.argmax(c["pct"]))
        big = c["peak"] >= 50.0
        j = int(np.argmax(np.where(big, c["pct"], -1)))
        big_ok = c["peak_ok"] >= 50.0
        k = int(np.argmax(np.where(big_ok, c["pct_ok"], -1)))
        rows.append([f"OpenSim at {key} iterations", f"{int(c['failed'].sum())} of {len(c['failed'])}",
                     f"{c['pct'][i]:.2f} ({names[i]}, peak {c['peak'][i]:.0f} N)",
                     f"{c['pct'][j]:.2f} ({names[j]})", f"{np.median(c['pct']):.2f}", f"{c['rms'].max():.2f}",
                     f"{c['pct_ok'][k]:.2f} ({names[k]}) / {c['rms_ok'][~big_ok].max(initial=0.0):.2f}",
                     *(f"{c['joints'][j_]['force_pct']:.3f} / {c['joints'][j_]['mz_rms']:.3f}"
                       for j_, _ in trial.joints)])
    c = r["cmp"][100]
    fail = c["failed"]
    gap, viol = c["cost_os"] - c["cost_cf"], np.abs(mine["out"].so.violation).max()
    if fail.any():
        cost = (f"At the {int(fail.sum())} frames OpenSim's SO reported as failed, its cost (the sum of squared "
                f"activations and reserve controls) minus casflex's: median {np.median(gap[fail]):.3g}, from "
                f"{gap[fail].min():.3g} to {gap[fail].max():.3g}; at the others from {gap[~fail].min():.3g} to "
                f"{gap[~fail].max():.3g}. casflex balances every coordinate to {viol:.1e} N m; OpenSim's balance (its "
                f"activations and reserves on casflex's moment arms, forces at full activation and moments) misses by "
                f"up to {c['balance'][fail].max():.3f} N m at the failed frames and {c['balance'][~fail].max():.3f} "
                "N m at the others: with reserves of 1 N m carrying up to some 20 N m, each 0.01 N m of that slack "
                "buys up to 0.4 of cost.")
    else:
        cost = (f"OpenSim's SO converged at every frame; its balance is within {c['balance'].max():.3f} N m of "
                "casflex's moments (casflex's inverse dynamics, moment arms and forces at full activation).")
    hip = r["hip_bw"]
    value, what, source = IN_VIVO[trial.gait or trial.stem]
    stem = f"opensim_muscles_{trial.stem}"
    times = r["cmp"][100]
    return [f"## {trial.name}", "", f"![hip contact force and muscles](../figures/{stem}{'_quick' * quick}.png)", "",
            f"{len(mine['t'])} frames, t = {trial.window[0]:g}..{trial.window[1]:g} s, {len(names)} muscles, "
            f"coordinates filtered at {trial.cutoff:g} Hz; body weight {r['bw']:.0f} N.", "",
            *table(["OpenSim's SO", "frames it reported failed", "worst muscle: RMS % of its peak",
                    "worst muscle of peak >= 50 N (%)", "median muscle (%)", "largest RMS (N)",
                    "OpenSim's solved frames: worst of peak >= 50 N (%) / largest RMS of the others (N)",
                    *(f"{j} force % / mz N m" for j, _ in trial.joints)], rows, "lrrrrrr" + "r" * 3),
            "", cost, "",
            f"Right hip contact force, peak over the complete right stances: casflex {hip['cf']:.2f} BW, OpenSim "
            f"{hip['os']:.2f} BW in the plane ({hip['os3d']:.2f} BW with its out-of-plane component); in vivo "
            f"{value:g} BW ({what}; {source}).", "",
            *table(["time (s)", "casflex (inverse dynamics + TrialMuscles, from the files)", "OpenSim SO + JR run()",
                    "ratio"], [[f"one run each{', OpenSim at 100 iterations' * (len(r['cmp']) > 1)}",
                                f"{mine['seconds']:.2f}", f"{times['so_seconds']:.2f} + {times['jr_seconds']:.2f}",
                                f"{times['seconds'] / mine['seconds']:.1f}x"]], "lrrr"), ""]


def main(quick: bool = False, out_dir: Path | None = None) -> dict:
    banner = Banner("opensim_muscles", quick)
    if importlib.util.find_spec("opensim") is None:
        write_outputs("opensim_muscles", out_dir, quick, "# casflex's muscles against OpenSim's SO and JR\n\n"
                      f"{banner.line()} Skipped: OpenSim is not installed (the peers extra).\n")
        return {}
    results = []
    for trial in TRIALS[:1] if quick else TRIALS:
        with tempfile.TemporaryDirectory(prefix="casflex-opensim-muscles-") as tmp:
            results.append(run_trial(trial, Path(tmp), quick))
    from importlib.metadata import version

    page = ["# casflex's muscle forces and joint reactions against OpenSim's StaticOptimization and JointReaction",
            "", f"{banner.line(OpenSim=version('opensim'))} What is compared and what the numbers mean: "
            "[studies/opensim_muscles.md](../studies/opensim_muscles.md).", "",
            "Muscles: RMS over the trial of casflex's force minus OpenSim's, % of OpenSim's peak of that muscle. "
            "Reactions (hip_r, knee_r, ankle_r on the child, in the child's axes): RMS of the difference of the "
            "in-plane force's magnitude, % of its peak; RMS of the moment's difference (N m: the reserves').", ""]
    for r in results:
        page += _section(r, quick)
    lab = {r["trial"].stem: r["cmp"][100] for r in results}
    big = {s: float(np.max(np.where(c["peak_ok"] >= 50.0, c["pct_ok"], 0.0))) for s, c in lab.items()}
    small = {s: float(c["rms_ok"][c["peak_ok"] < 50.0].max(initial=0.0)) for s, c in lab.items()}
    react = max(c["joints"][j]["force_pct"] for c in lab.values() for j in c["joints"])
    lines, failed = checks([
        ("every muscle whose peak is 50 N or more within 2 % of its peak over the frames OpenSim's SO solved (at its "
         "defaults), every trial", ", ".join(f"{s} {v:.2f} %" for s, v in big.items()), max(big.values()) < 2.0),
        ("the muscles of smaller peak (at the 0.01 activation floor most of the trial, where OpenSim's interior point "
         "stops above it) within 1 N RMS, the same frames", ", ".join(f"{s} {v:.2f} N" for s, v in small.items()),
         max(small.values()) < 1.0),
        ("hip, knee and ankle reaction forces within 2 % of peak (RMS over every frame), OpenSim at its defaults, "
         "every trial", f"largest {react:.3f} %",
         react < 2.0),
        ("casflex's muscle path faster than OpenSim's SO + JR, every trial",
         ", ".join(f"{r['mine']['seconds']:.1f} s against {r['cmp'][100]['seconds']:.1f} s" for r in results),
         all(r["mine"]["seconds"] < r["cmp"][100]["seconds"] for r in results), False)])
    write_outputs("opensim_muscles", out_dir, quick, "\n".join(page + lines),
                  {f"opensim_muscles_{r['trial'].stem}": figure(r) for r in results})
    assert_checks(failed)
    return {"results": results}


if __name__ == "__main__":
    cli(__doc__, main)
