"""The Rajagopal pipeline's walk as a muscle trial: the planar, edited Rajagopal 2016 model and the cut trial in
tests/data/muscles (their provenance: tests/data/muscles/README.md). Run once, with OpenSim (the peers extra)
and a copy of opensim-org/opensim-models (OPENSIM_MODELS: a clone or bare git directory):

    OPENSIM_MODELS=... .venv/bin/python studies/_rajagopal_walk.py

What it does, in order (nothing else):
1. Rajagopal2016.osim scaled by OpenSim's ScaleTool with the pipeline's two setups (as studies/opensim_gait.py);
2. made planar with its 80 Millard2012EquilibriumMuscle muscles (``planar_osim(..., muscles=True)``, the 14
   coordinates of studies/opensim_gait.py); the patella's coordinate is then locked and its coupler removed;
3. the patella's path points (the quadriceps' points over the patella) moved onto the femur as MovingPathPoints
   whose x, y, z follow the knee's angle (SimmSplines, natural cubic, through the point's place in the femur's frame,
   sampled by OpenSim every 2 degrees over the knee's range with the patella's coordinate at the knee's angle,
   as the model's coupler sets it): the patella's motion seen by the muscles kept, casflex's refusal of the
   coupler avoided (the patella's 0.09 kg body stays welded to the femur at the knee's default);
4. every wrap object removed (from the bodies and from the paths): Rajagopal's wrap cylinders turn about axes
   off the plane's normal, which no planar path holds; both tools then run this edited model (its moment arms
   differ from the real model's where a wrap was active: docs/studies/opensim_muscles.md);
5. the trial cut to 0.1-1.75 s (the right foot's strikes at 0.268 and 1.412 s and the left toe-off at 1.59 s
   inside, with room for the 6 Hz filter's edges): the .trc's frames, and the plates' rows at 2000 Hz kept every
   5th (400 Hz: the frames' times at 100 Hz are rows of it, where both tools take the plates); the pipeline's IK
   tasks and ExternalLoads (its data file named as the cut, its model kinematics file cleared: the plates are in
   the ground).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _planar_osim import planar_osim  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "tests" / "data" / "muscles"
COMMIT = "20a888b9655e73fb84963d6e03eee3752cf6074b"
PIPE = "Pipelines/Rajagopal"
KEEP = ("pelvis_tilt", "pelvis_tx", "pelvis_ty", "hip_flexion_r", "hip_flexion_l", "knee_angle_r", "knee_angle_l",
        "ankle_angle_r", "ankle_angle_l", "lumbar_extension", "arm_flex_r", "arm_flex_l", "elbow_flex_r",
        "elbow_flex_l")
SETUPS = ("Scale/scale_setup_walk_scaleOnly.xml", "Scale/scale_setup_walk.xml")
INPUTS = ("Scale/markerset_walk_preScale.xml", "ExpData/static_walk_1.trc", "ExpData/static_walk_2.trc")
WINDOW = (0.1, 1.75)  # s
GRF_EVERY = 5  # rows of the plates' 2000 Hz kept
STEP_DEG = 2.0  # the patella's samples over the knee's range
MODEL, TRC, GRF = "rajagopal_walk_planar_muscles.osim", "rajagopal_walk.trc", "rajagopal_walk_grf.mot"
LOADS, TASKS = "rajagopal_walk_grf.xml", "rajagopal_walk_ik_tasks.xml"


def _copy(name: str, out: Path) -> Path:
    repo = Path(os.environ["OPENSIM_MODELS"])
    git = repo / ".git" if (repo / ".git").exists() else repo
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_bytes(subprocess.run(["git", f"--git-dir={git}", "show", f"{COMMIT}:{name}"], check=True,
                                   capture_output=True).stdout)
    return out


def scaled(tmp: Path) -> Path:
    """The pipeline's subject: Rajagopal2016.osim scaled by OpenSim's ScaleTool with its two setups."""
    from casflex.peers.opensim_tools import scale

    folder = tmp / "pipeline"
    _copy("Models/Rajagopal/Rajagopal2016.osim", folder / "generic_unscaled.osim")
    for name in (*INPUTS, *SETUPS):
        _copy(f"{PIPE}/{name}", folder / name)
    scale(*(folder / s for s in SETUPS))
    return folder / "Scale" / "subject_scaled_walk.osim"


def patella_samples(model: Path, side: str, points: list[tuple[str, np.ndarray]]) -> tuple[np.ndarray, dict]:
    """(knee angles (rad), {point: (n, 3) its place (m) in the frame of patella_<side> held at the patella's
    default}) with the patella's coordinate at each angle (the coupler's identity), by OpenSim on the scaled 3D
    model."""
    import opensim as osim

    m = osim.Model(str(model))
    state = m.initSystem()
    knee = m.getCoordinateSet().get(f"knee_angle_{side}")
    beta = m.getCoordinateSet().get(f"knee_angle_{side}_beta")
    q = np.radians(np.arange(0.0, np.degrees(knee.getRangeMax()) + 1e-9, STEP_DEG))
    patella, femur = m.getBodySet().get(f"patella_{side}"), m.getBodySet().get(f"femur_{side}")
    out = {name: np.zeros((len(q), 3)) for name, _ in points}
    on_femur = {name: [] for name, _ in points}
    for v in q:
        knee.setValue(state, float(v), False)
        beta.setValue(state, float(v), False)
        m.realizePosition(state)
        for name, p in points:
            on_femur[name].append(patella.findStationLocationInAnotherFrame(state, osim.Vec3(*p), femur))
    beta.setValue(state, beta.getDefaultValue(), False)  # where the planar model holds the patella
    m.realizePosition(state)
    for name, _ in points:
        for k, r in enumerate(on_femur[name]):
            r = femur.findStationLocationInAnotherFrame(state, r, patella)
            out[name][k] = [r.get(i) for i in range(3)]
    return q, out


def _moving(point: ET.Element, side: str, q: np.ndarray, xyz: np.ndarray) -> ET.Element:
    """A MovingPathPoint on patella_<side> at ``xyz`` (n, 3) over knee angles ``q``, named as ``point``."""
    mp = ET.Element("MovingPathPoint", name=point.get("name"))
    ET.SubElement(mp, "socket_parent_frame").text = f"/bodyset/patella_{side}"
    for axis in "xyz":
        ET.SubElement(mp, f"socket_{axis}_coordinate").text = f"/jointset/walker_knee_{side}/knee_angle_{side}"
    for k, axis in enumerate("xyz"):
        spline = ET.SubElement(ET.SubElement(mp, f"{axis}_location"), "SimmSpline", name="function")
        ET.SubElement(spline, "x").text = " ".join(f"{v:.12g}" for v in q)
        ET.SubElement(spline, "y").text = " ".join(f"{v:.12g}" for v in xyz[:, k])
    return mp


def edit(planar: Path, source3d: Path, dest: Path, wraps: bool = False) -> list[str]:
    """The planar model's patella points made moving and its wraps removed (module docstring, 3-4); ``wraps``:
    kept (the wraps' effect, :func:`wrap_effect`)."""
    tree = ET.parse(planar)
    model = tree.getroot().find("Model")
    report, wrapped = [], []
    for side in "rl":
        holders = [(pps, p) for pps in model.iter("PathPointSet") for p in pps.find("objects")
                   if (p.findtext("socket_parent_frame") or "").strip() == f"/bodyset/patella_{side}"]
        if not holders:
            continue
        if any(p.tag != "PathPoint" for _, p in holders):
            raise ValueError(f"patella_{side}: a path point other than a PathPoint")
        q, xyz = patella_samples(source3d, side, [(p.get("name"), np.array(p.findtext("location").split(), float))
                                                  for _, p in holders])
        for pps, p in holders:
            objects = pps.find("objects")
            objects.insert(list(objects).index(p), _moving(p, side, q, xyz[p.get("name")]))
            objects.remove(p)
        report.append(f"patella_{side}: its {len(holders)} path points made MovingPathPoints of "
                      f"knee_angle_{side} ({len(q)} samples, {STEP_DEG:g} deg apart)")
    for muscle in [el for el in model.iter() if el.find("GeometryPath") is not None and not wraps]:
        objects = muscle.find("GeometryPath").find("PathWrapSet/objects")
        if objects is not None and len(objects):
            wrapped.append(muscle.get("name"))
            for w in list(objects):
                objects.remove(w)
    gone = []
    for wos in model.iter("WrapObjectSet") if not wraps else ():
        objects = wos.find("objects")
        if objects is not None:
            gone += [w.get("name") for w in objects]
            for w in list(objects):
                objects.remove(w)
    report.append(f"{len(gone)} wrap objects removed; {len(wrapped)} muscles had wraps: {', '.join(wrapped)}")
    ET.indent(tree, space=" ")
    tree.write(dest, encoding="UTF-8", xml_declaration=True)
    return report


def _cut_table(src: Path, dest: Path, t0: float, t1: float, every: int, trc: bool) -> int:
    """Rows of ``src`` (.trc or .mot) with t0 <= t <= t1 (every ``every``-th from the first), the header's counts
    set; returns the rows kept."""
    lines = src.read_text().splitlines()
    head = 5 if trc else next(i for i, ln in enumerate(lines) if ln.strip().lower() == "endheader") + 2
    col = 1 if trc else 0
    rows = [ln for ln in lines[head:] if ln.strip() and t0 - 1e-9 <= float(ln.split("\t")[col]) <= t1 + 1e-9]
    rows = rows[::every]
    header = lines[:head]
    if trc:
        vals = header[2].split()  # DataRate CameraRate NumFrames NumMarkers Units OrigDataRate OrigDataStartFrame ...
        vals[2] = vals[7] = str(len(rows))
        vals[6] = rows[0].split("\t")[0]  # the source's frame number of the first kept
        header[2] = "\t".join(vals)
        rows = ["\t".join([str(k + 1), *r.split("\t")[1:]]) for k, r in enumerate(rows)]
    else:
        header = [f"nRows={len(rows)}" if h.startswith("nRows=") else h for h in header]
    dest.write_text("\n".join(header + rows) + "\n")
    return len(rows)


def trial(tmp: Path) -> list[str]:
    """The cut trial, IK tasks and ExternalLoads in OUT (module docstring, 5)."""
    trc = _cut_table(_copy(f"{PIPE}/ExpData/motion_capture_walk.trc", tmp / "walk.trc"), OUT / TRC, *WINDOW, 1, True)
    grf = _cut_table(_copy(f"{PIPE}/ExpData/grf_walk.mot", tmp / "grf.mot"), OUT / GRF, *WINDOW, GRF_EVERY, False)
    setup = ET.parse(_copy(f"{PIPE}/IK/ik_setup_walk.xml", tmp / "ik.xml")).getroot()
    ET.ElementTree(setup.find(".//IKTaskSet")).write(OUT / TASKS, encoding="UTF-8", xml_declaration=True)
    loads = ET.parse(_copy(f"{PIPE}/ID/grf_walk.xml", tmp / "loads.xml"))
    loads.getroot().find(".//datafile").text = GRF
    loads.getroot().find(".//external_loads_model_kinematics_file").text = None
    loads.write(OUT / LOADS, encoding="UTF-8", xml_declaration=True)
    return [f"{TRC}: {trc} frames", f"{GRF}: {grf} rows"]


#: (muscle, coordinate) pairs whose moment arms :func:`wrap_effect` reports
WRAP_ARMS = (("vaslat_r", "knee_angle_r"), ("vasint_r", "knee_angle_r"), ("recfem_r", "knee_angle_r"),
             ("gasmed_r", "knee_angle_r"), ("semimem_r", "knee_angle_r"), ("bfsh_r", "knee_angle_r"),
             ("glmax2_r", "hip_flexion_r"), ("psoas_r", "hip_flexion_r"), ("iliacus_r", "hip_flexion_r"),
             ("addlong_r", "hip_flexion_r"), ("gasmed_r", "ankle_angle_r"))


def wrap_effect(with_wraps: Path, without: Path) -> list[str]:
    """OpenSim's moment arms (``computeMomentArm``) of WRAP_ARMS with the wraps and without, over the walk's
    range (hip -20..40 deg, knee 0..70 deg, ankle -20..20 deg, 5 deg apart, one coordinate moved at a time):
    one line per pair, the arms in mm at the coordinate's 0, middle and end, and the largest difference."""
    import opensim as osim

    lines = []
    spans = {"hip_flexion_r": (-20, 40), "knee_angle_r": (0, 70), "ankle_angle_r": (-20, 20)}
    arms = {}
    for tag, path in (("with", with_wraps), ("without", without)):
        m = osim.Model(str(path))
        state = m.initSystem()
        for muscle, coord in WRAP_ARMS:
            c = m.getCoordinateSet().get(coord)
            values = np.radians(np.arange(spans[coord][0], spans[coord][1] + 1e-9, 5.0))
            r = []
            for v in values:
                c.setValue(state, float(v), False)
                m.realizePosition(state)
                r.append(m.getMuscles().get(muscle).computeMomentArm(state, c))
            c.setValue(state, 0.0, False)
            arms[tag, muscle, coord] = (np.degrees(values), 1e3 * np.array(r))
    for muscle, coord in WRAP_ARMS:
        deg, a = arms["with", muscle, coord]
        _, b = arms["without", muscle, coord]
        at = [0, len(deg) // 2, len(deg) - 1]
        lines.append(f"{muscle} about {coord}: with wraps " + ", ".join(f"{a[i]:.1f}" for i in at) + " mm, without "
                     + ", ".join(f"{b[i]:.1f}" for i in at) + f" mm at {', '.join(f'{deg[i]:g}' for i in at)} deg; "
                     f"largest difference {np.abs(a - b).max():.1f} mm")
    return lines


def main() -> None:
    import opensim  # noqa: F401  (first: the ScaleTool then runs here, not in a worker)

    with tempfile.TemporaryDirectory(prefix="casflex-rajagopal-") as tmp:
        tmp = Path(tmp)
        source = scaled(tmp)
        report = planar_osim(str(source), str(tmp / "planar.osim"), KEEP, "rajagopal_walk_planar", muscles=True)
        report += edit(tmp / "planar.osim", source, OUT / MODEL)
        edit(tmp / "planar.osim", source, tmp / "wrapped.osim", wraps=True)
        report += wrap_effect(tmp / "wrapped.osim", OUT / MODEL)
        report += trial(tmp)
        if len(sys.argv) > 1:  # the scaled 3D model kept where asked (the wraps' effect: the study's page)
            Path(sys.argv[1]).write_bytes(source.read_bytes())
    print("\n".join(report))


if __name__ == "__main__":
    main()
