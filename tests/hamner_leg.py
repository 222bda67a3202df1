"""The built-in scenes ``hamner_leg`` (rigid) and ``hamner_leg_flexible``: the right leg of subject 02 of
OpenSim's Hamner running pipeline in the sagittal plane, scaled to that subject, and the lab files
they are tested against. ``python tests/hamner_leg.py [MODELS]`` writes

- casflex/scene/builtin/hamner_leg.toml and casflex/scene/builtin/hamner_leg_flexible.toml,
- tests/data/lab/hamner_subject02_leg.osim: the scaled model's pelvis and right-leg bodies, joints and the
  markers the scenes use, as placed on the subject (subject02_registered.osim: HEADER_RIGID), what
  tests/test_hamner_leg.py recomputes the masses, centres and markers from,
- tests/data/lab/hamner_running_stride.trc, hamner_running_stride_grf.mot, hamner_running_stride_ik.mot:
  one right stride of the running trial (tests/data/lab/README.md),

from opensim-org/opensim-models at commit 20a888b (Apache License 2.0; MODELS: a git directory or
clone of it, default /work/.mirror/opensim-org+opensim-models/repo). It needs the ``opensim`` Python
package (4.x), which places the bodies, joint centres and markers in the default pose; the test
recomputes them from the XML alone. It prints the numbers and a check of the markers' fit.
``python tests/hamner_leg.py --flexible`` rewrites hamner_leg_flexible.toml alone, from the built-in
hamner_leg (no opensim needed): the scene main() writes too.
"""

from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

COMMIT = "20a888b"
MODELS = "/work/.mirror/opensim-org+opensim-models/repo"
OSIM = "Pipelines/Hamner/outputReference/subject02_scaled.osim"
# the scaled model with its markers placed on the subject's static trial (Setup_Scale.xml's MarkerPlacer);
# its bodies and joints are the scaled model's, checked below
OSIM_PLACED = "Pipelines/Hamner/outputReference/subject02_registered.osim"
TRIAL_TRC = "Pipelines/Hamner/subject02_running.trc"
TRIAL_GRF = "Pipelines/Hamner/subject02_running_grf.mot"
TRIAL_IK = "Pipelines/Hamner/outputReference/ResultsIK/subject02_running_ik.mot"

HERE = Path(__file__).resolve().parent
LAB = HERE / "data" / "lab"
LEG_OSIM = LAB / "hamner_subject02_leg.osim"
STRIDE_TRC = LAB / "hamner_running_stride.trc"
STRIDE_GRF = LAB / "hamner_running_stride_grf.mot"
STRIDE_IK = LAB / "hamner_running_stride_ik.mot"

#: OpenSim bodies of each scene segment (the subtalar and mtp joints locked: talus, calcaneus and toes
#: are one rigid foot; the model has no patella body).
SEGMENTS = {"pelvis": ("pelvis",), "thigh": ("femur_r",), "shank": ("tibia_r",),
            "foot": ("talus_r", "calcn_r", "toes_r")}
JOINTS = ("ground_pelvis", "hip_r", "knee_r", "ankle_r", "subtalar_r", "mtp_r")
#: Scene marker name -> (TRC label, segment): the trial's markers on the right leg and the pelvis.
MARKERS = {
    "R_ASIS": ("R.ASIS", "pelvis"), "L_ASIS": ("L.ASIS", "pelvis"), "V_Sacral": ("V.Sacral", "pelvis"),
    "R_Thigh_Upper": ("R.Thigh.Upper", "thigh"), "R_Thigh_Front": ("R.Thigh.Front", "thigh"),
    "R_Thigh_Rear": ("R.Thigh.Rear", "thigh"),
    "R_Shank_Upper": ("R.Shank.Upper", "shank"), "R_Shank_Front": ("R.Shank.Front", "shank"),
    "R_Shank_Rear": ("R.Shank.Rear", "shank"),
    "R_Heel": ("R.Heel", "foot"), "R_Midfoot_Sup": ("R.Midfoot.Sup", "foot"),
    "R_Midfoot_Lat": ("R.Midfoot.Lat", "foot"), "R_Toe_Tip": ("R.Toe.Tip", "foot"),
}
IK_COLUMNS = ("pelvis_tilt", "hip_flexion_r", "knee_angle_r", "ankle_angle_r")
GRF_COLUMNS = ("ground_force_vx", "ground_force_vy", "ground_force_vz", "ground_force_px", "ground_force_py",
               "ground_force_pz", "ground_torque_x", "ground_torque_y", "ground_torque_z")
STANCE_N = 20.0  # N: the first plate's vertical force above this is the right foot's stance

G = 9.80665  # m/s^2, the model's gravity
# Flexible bones: cortical bone E (Reilly and Burstein 1975, longitudinal, human femur: 17 GPa), density
# 1900 kg/m^3, hollow circular midshaft sections (outer, inner radius, m).
E_BONE, RHO_BONE = 17e9, 1900.0
SECTIONS = {"thigh": (0.0135, 0.007), "shank": (0.012, 0.006)}
BEAMS = 4  # beams per bone, end to end, joined at user nodes that carry the segment's other mass
ELEMENTS = 1  # elements per beam (HEADER_FLEXIBLE: 2 move the held modes by < 0.1 %)
ZETA_TISSUE = 0.3  # the damping ratio of the lowest held bending mode (HEADER_FLEXIBLE)
#: The bones: (segment, proximal node, distal joint's node on the other side, distal node of the bone).
BONES = {"thigh": ("hip", "knee", "knee_t"), "shank": ("knee", "ankle", "ankle_s")}

HEADER_RIGID = """\
# Subject 02 of OpenSim's Hamner running pipeline (Hamner, Seth and Delp 2010, J. Biomech.
# 43(14):2709-2716): the pelvis and right leg in the sagittal plane, as rigid segments on ideal hinges.
# Written by tests/hamner_leg.py (tested by tests/test_hamner_leg.py) from the scaled model
# Pipelines/Hamner/outputReference/subject02_scaled.osim of opensim-org/opensim-models at commit 20a888b
# (Apache License 2.0) and, for the markers, subject02_registered.osim beside it: the same model (bodies
# and joints identical) with its markers placed on the subject's static trial by the scale tool's
# MarkerPlacer; subject02_scaled.osim's own markers are the generic model's, scaled: in the plane 6 mm
# to 24 cm from the placed ones (R.Shank.Front), and a rigid fit to the trial leaves 8-10 cm RMS on thigh
# and shank with them. The pelvis and right-leg part of it is tests/data/lab/hamner_subject02_leg.osim.
# - Lab axes X forward, Y up, Z to the subject's right; the scene's plane is (X, Y), seen from +Z. The
#   initial configuration is the model's default pose (every coordinate 0: the pelvis origin at the
#   lab's origin, the leg straight down), each 3-D position projected on (X, Y); node rotations 0 are
#   the bodies' frames there, so a node's rotation is its OpenSim body's rotation about Z.
# - Bodies, with the OpenSim mass, centre of mass and Izz (about the centre of mass): pelvis (the pelvis
#   body alone: no torso, no left leg), thigh (femur_r), shank (tibia_r; the model has no patella body:
#   its notes say Seth removed it), foot (talus_r + calcn_r + toes_r merged: the subtalar and mtp joints
#   locked, total mass, combined centre of mass, Izz about it by the parallel-axis theorem in the plane).
# - Nodes at the pelvis origin and the joint centres: hip (hip_r), knee, ankle (ankle_r). OpenSim's knee
#   (knee_r) is a CustomJoint whose tibia origin slides along a spline of the knee angle (Yamaguchi and
#   Zajac's planar knee); here it is a fixed hinge at its position at knee angle 0 (the tibia origin in
#   the default pose). The ankle is a hinge about Z at the ankle_r centre (OpenSim's ankle axis is
#   oblique: its projection).
# - Hinges hip [pelvis, hip], knee [hip, knee] at the knee centre (a point of the thigh, whose node is
#   the hip), ankle [knee, ankle] at the ankle centre. No supports: the pelvis floats (its own body makes
#   its dofs massive) and whatever drives it (an inverse dynamics' pelvis path) adds them. 12 dofs, 6
#   hinge rows: 6 dofs of motion (the pelvis' 3, hip, knee, ankle).
# - Markers: the trial's pelvis and right-leg markers (labels as in subject02_running.trc), where the
#   placed MarkerSet puts them in the default pose, projected; three or four per segment, none missing in
#   the trial. A rigid fit of each segment's markers to the running stride
#   (tests/data/lab/hamner_running_stride.trc) leaves 3 mm RMS on thigh and shank, 8 mm on pelvis and
#   foot (skin motion, and the pelvis' and foot's turning out of the plane).
# - gravity: the model's, 9.80665 m/s^2.
"""

HEADER_FLEXIBLE = """\
# Subject 02's pelvis and right leg (built-in hamner_leg: sources, axes, default pose, joint centres,
# markers) with flexible thigh and shank. Written by tests/hamner_leg.py (tested by
# tests/test_hamner_leg.py) from hamner_leg alone:
# - Each bone runs along the straight line between its joint centres, from the hip to node knee_t (at
#   the knee centre) and from the knee to node ankle_s (at the ankle centre), as 4 beams end to end,
#   <segment>_bone_1 .. _4, joined at the user nodes <segment>_1 .. _3 at its quarter points (user nodes,
#   so that bodies can sit there), one element each: two elements per beam move the held modes below by
#   less than 0.001 %. Cortical bone, E = 17 GPa (Reilly and Burstein 1975, J. Biomech. 8:393-405,
#   longitudinal modulus of human femoral cortical bone), density 1900 kg/m^3 (cortical bone, about 1.9
#   g/cm^3), hollow circular midshaft sections of outer and inner radius 13.5 and 7 mm (femur) and 12 and
#   6 mm (tibia): round numbers of the order of the adult midshaft sections measured by Ruff and Hayes
#   (1983), Am. J. Phys. Anthropol. 60:359-381 (total and medullary areas of 573 and 154 mm^2 for the
#   femur, 452 and 113 mm^2 for the tibia). A = pi (ro^2 - ri^2), I = pi (ro^4 - ri^4) / 4.
# - Mass along the bone: each segment keeps the rigid scene's mass, centre of mass and Izz exactly in the
#   undeformed state (the flexible inverse starts from the rigid pose). The bone's own mass is the beams'
#   (rho A, uniform along it); the rest of the segment (soft tissue, marrow, the bone's ends beyond the
#   tube) is a linear density f(xi) = f0 + f1 xi + f2 xi^2 (kg/m, xi = s / L from the proximal joint)
#   lumped on the bone's 5 nodes by the trapezoid rule (node k carries w_k f(xi_k), w = L/4 (1/2, 1, 1, 1,
#   1/2)), as point masses (<segment>_mass_0 .. _4, no inertia of their own) beside their nodes on the line
#   through the remainder's centre of mass parallel to the bone. f's three coefficients solve three
#   linear equations: the remainder's mass, its centre along the bone and its Izz, so the sum (beams and
#   bodies) is the segment's exactly, no fit; every mass comes out positive (checked). The densities
#   (below) fall from the hip towards the knee and peak in the upper quarter of the shank: not imposed,
#   they follow from OpenSim's centres of mass and Izz.
# - Damping: the bones' beams carry stiffness-proportional (Rayleigh) damping beta (docs/scene-format.md:
#   mode i decays with the damping ratio beta omega_i / 2), beta = 2 zeta / omega_1, omega_1 the lowest
#   mode of the leg held as the flexible inverse holds it (the pelvis clamped, every hinge locked: its
#   drives; the default pose), zeta = 0.3, rounded to 3 digits. It stands for the soft tissue around the
#   bones, which the beams leave out and which damps what moves the bone: the soft-tissue vibrations of
#   the leg in running are heavily damped (Boyer and Nigg 2006, J. Biomech. Eng. 128:815), more so
#   with muscle activity (Wakeling and Nigg 2001, J. Appl. Physiol. 90:412-420), and soft tissue does
#   about -19 J of net work per stance at 3 m/s, over 25 % of the stance's negative work (Riddick and Kuo
#   2016, J. Biomech. 49:436-441). 0.3 is the middle of the 0.2-0.5 quoted for soft-tissue (wobbling
#   mass) damping ratios in running (Gruber et al. 1998, J. Biomech. 31:439-444; Schmitt and Guenther
#   2011, Arch. Appl. Mech. 81:887-897; the review of Nikooyan and Zadpoor 2011, Proc. IMechE H
#   225:1121-1135; that range as cited for this model, not re-read from those papers' tables). The higher
#   held modes are then overdamped (their ratios below); their slow roots relax at 1 / beta.
# - Hinges hip [pelvis, hip], knee [knee_t, knee] at the knee centre, ankle [ankle_s, ankle] at the
#   ankle centre; no supports (as hamner_leg). The thigh's and shank's markers are on the beam of the 4
#   that holds their projection on the bone (off the axis, as on the subject), at their rigid positions
#   in the default pose; the pelvis' and the foot's on their bodies.
# - Limits: the beams are the whole load path, so each bone carries the net joint moments in bending;
#   in vivo the muscles pull along the bones and take most of it. In the stride's stance the rigid
#   inverse's moments (knee up to 219 N m) would bend these sections to surface strains of 7000-10000
#   microstrain (M r / E I), about ten times the 850 microstrain measured on a running man's tibial
#   midshaft (Lanyon et al. 1975, Acta Orthop. Scand. 46:256-268): this model's deflections under
#   running loads are centimetres, an overestimate of the bones'.
"""


def flexible_numbers(scene) -> str:
    """Header lines: each bone's length and mass, the masses on its nodes and the linear density they
    stand for; the held modes' frequencies and damping ratios."""
    import textwrap

    nodes = {n.name: np.array([n.x, n.y]) for n in scene.nodes}
    lines = []
    for seg in BONES:
        names = bone_nodes(seg)
        beams = [bm for bm in scene.beams if bm.name.startswith(f"{seg}_bone_")]
        L = float(np.linalg.norm(nodes[names[-1]] - nodes[names[0]]))
        masses = np.array([x.mass for x in scene.bodies if x.name.startswith(f"{seg}_mass_")])
        w = np.full(BEAMS + 1, L / BEAMS)
        w[[0, -1]] /= 2
        lines.append(f"{seg}: bone {L:.4f} m, {sum(bm.rho * bm.A for bm in beams) / len(beams) * L:.4f} kg; on "
                     f"{', '.join(names)}: {', '.join(f'{m:.4f}' for m in masses)} kg, a linear density of "
                     f"{', '.join(f'{f:.1f}' for f in masses / w)} kg/m there")
    md = held_modes(scene)
    beta = scene.beams[0].beta
    hz, zeta = ", ".join(f"{f:.2f}" for f in md["hz"]), ", ".join(f"{z:.3g}" for z in md["zeta"])
    lines.append(f"held (pelvis clamped, hinges locked, default pose; casflex.statics.modes), the lowest modes "
                 f"{hz} Hz, damping ratios {zeta} (beta = {beta:g} s); the linearised damped leg: the lowest "
                 f"pair zeta {md['zeta_1']:.3f} at {md['hz_1'] * math.sqrt(1 - md['zeta_1']**2):.2f} Hz, the "
                 f"overdamped modes' slow roots decaying at {1 / beta:.0f} 1/s; run.dt = 1 ms")
    return "".join(textwrap.fill(ln + ".", 110, initial_indent="# - ", subsequent_indent="#   ") + "\n"
                   for ln in lines)


def write_flexible(rigid) -> Path:
    """hamner_leg_flexible.toml from the rigid scene ``rigid``."""
    import casflex
    from casflex.results import atomic_write_text
    from casflex.scene.io import dumps_scene

    flexible = flexible_scene(rigid)
    path = Path(casflex.__file__).parent / "scene" / "builtin" / "hamner_leg_flexible.toml"
    atomic_write_text(path, HEADER_FLEXIBLE + flexible_numbers(flexible) + dumps_scene(flexible))
    return path


# -- sources -------------------------------------------------------------------------------------------

def source_text(models: str | Path, path: str) -> str:
    """A file of opensim-models at COMMIT, from a git directory or clone ``models``."""
    out = subprocess.run(["git", "-C", str(models), "show", f"{COMMIT}:{path}"], capture_output=True, check=True)
    return out.stdout.decode("utf-8")


def write_leg_osim(text: str, path: Path = LEG_OSIM) -> None:
    """The scaled model cut to the pelvis and the right leg: those bodies (mass, centre of mass, inertia;
    no geometry), their joints, the markers of MARKERS; no forces. Comments and display properties
    dropped, numbers as in the source."""
    root = ET.fromstring(text)
    model = root.find("Model")
    keep_bodies = {b for bs in SEGMENTS.values() for b in bs}
    keep_markers = {label for label, _ in MARKERS.values()}
    for child in list(model):
        if child.tag in ("BodySet", "JointSet", "MarkerSet"):
            objects = child.find("objects")
            for obj in list(objects):
                name = obj.get("name")
                keep = {"BodySet": keep_bodies, "JointSet": set(JOINTS), "MarkerSet": keep_markers}[child.tag]
                if name not in keep:
                    objects.remove(obj)
        elif child.tag not in ("gravity", "credits", "publications", "length_units", "force_units"):
            model.remove(child)
    for parent in model.iter():
        for child in list(parent):
            if child.tag in ("FrameGeometry", "attached_geometry", "WrapObjectSet"):
                parent.remove(child)
    model.insert(0, ET.Comment(
        f" Cut from opensim-org/opensim-models {OSIM_PLACED} at commit {COMMIT} (Apache License 2.0; "
        f"{Path(OSIM).name} with its markers placed on the static trial) by tests/hamner_leg.py: the pelvis and "
        "right-leg bodies, their joints and the markers of the built-in scenes hamner_leg and "
        "hamner_leg_flexible; geometry, forces and the other bodies removed, numbers as in the source. "))
    ET.indent(root, space="\t")
    path.write_text('<?xml version="1.0" encoding="UTF-8" ?>\n' + ET.tostring(root, encoding="unicode") + "\n",
                    encoding="utf-8")


def stride_rows(grf_text: str) -> tuple[int, int]:
    """(first, last) data-row index of the first right stride in the GRF file: from the first right heel
    strike (the first plate's vertical force rising above STANCE_N) to the next one, both included."""
    lines = grf_text.splitlines()
    end = next(i for i, ln in enumerate(lines) if ln.strip().lower() == "endheader")
    names = [n.strip() for n in lines[end + 1].split("\t")]
    rows = [ln.split("\t") for ln in lines[end + 2:] if ln.strip()]
    fy = np.array([float(r[names.index("ground_force_vy")]) for r in rows])
    on = fy > STANCE_N
    strikes = np.flatnonzero(on[1:] & ~on[:-1]) + 1
    return int(strikes[0]), int(strikes[1])


def write_stride(trc_text: str, grf_text: str, ik_text: str) -> dict:
    """The stride excerpts (module docstring); returns their spans."""
    first, last = stride_rows(grf_text)
    # markers: the header as the source's (counts adjusted), the rows' cells as written
    lines = trc_text.splitlines()
    head = [ln.rstrip("\t\r ").split("\t") for ln in lines[:5]]
    labels = [c.strip() for c in head[3][2::3]]
    cols = [labels.index(label) for label, _ in MARKERS.values()]
    rows = [ln.rstrip("\r").split("\t") for ln in lines[5:] if ln.strip()]
    rows = [r for r in rows if r[0].strip()]
    take = rows[first:last + 1]
    keys, vals = head[1], head[2]
    vals = [str(len(take)) if k == "NumFrames" else str(len(cols)) if k == "NumMarkers" else v
            for k, v in zip(keys, vals, strict=False)]
    out = ["\t".join(["PathFileType", "4", "(X/Y/Z)", STRIDE_TRC.name]), "\t".join(keys), "\t".join(vals),
           "\t".join(["Frame#", "Time"] + [f"{labels[c]}\t\t" for c in cols]),
           "\t".join(["", ""] + [f"{a}{i + 1}" for i in range(len(cols)) for a in "XYZ"]), ""]
    for r in take:
        out.append("\t".join(r[:2] + [x for c in cols for x in r[2 + 3 * c:5 + 3 * c]]))
    STRIDE_TRC.write_text("\n".join(out) + "\n", encoding="utf-8")
    t_trc = (float(take[0][1]), float(take[-1][1]))
    frames = (int(take[0][0]), int(take[-1][0]))

    def table(text: str, columns: tuple[str, ...], path: Path, select) -> tuple[float, float, int]:
        lines = text.splitlines()
        end = next(i for i, ln in enumerate(lines) if ln.strip().lower() == "endheader")
        names = [n.strip() for n in lines[end + 1].split("\t")]
        data = [ln.rstrip("\r").split("\t") for ln in lines[end + 2:] if ln.strip()]
        keep = [names.index("time")] + [names.index(c) for c in columns]
        chosen = select(data)
        t0, t1 = float(chosen[0][keep[0]]), float(chosen[-1][keep[0]])
        header = [f"name {path.name}", f"datacolumns {len(keep)}", f"datarows {len(chosen)}",
                  f"range {t0:.6f} {t1:.6f}"]
        extra = [ln.rstrip("\t\r ") for ln in lines[:end] if ln.split("=")[0].strip() in ("inDegrees",)]
        out = header + extra + ["endheader", "\t".join(["time", *columns])]
        out += ["\t".join(r[k].strip() for k in keep) for r in chosen]
        path.write_text("\n".join(out) + "\n", encoding="utf-8")
        return t0, t1, len(chosen)

    grf = table(grf_text, GRF_COLUMNS, STRIDE_GRF, lambda d: d[first:last + 1])
    assert abs(grf[0] - t_trc[0]) < 1e-9 and abs(grf[1] - t_trc[1]) < 1e-9, (grf, t_trc)  # the same rows
    # IK: the rows whose time (exact sixtieths) rounds to the markers' (ms) times
    ik = table(ik_text, IK_COLUMNS, STRIDE_IK,
               lambda d: [r for r in d if t_trc[0] - 1e-3 <= float(r[0]) <= t_trc[1] + 1e-3])
    return {"frames": frames, "trc": t_trc, "rows": (first, last), "grf": grf, "ik": ik}


# -- the model in its default pose (OpenSim API) ----------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class Segment:
    """A planar rigid segment: mass (kg), centre of mass (x, y) (m), Izz about it (kg m^2)."""

    mass: float
    com: tuple[float, float]
    izz: float


def merged(parts: list[Segment]) -> Segment:
    """One rigid segment of ``parts``: total mass, combined centre, Izz by the parallel-axis theorem."""
    m = sum(p.mass for p in parts)
    c = np.sum([p.mass * np.array(p.com) for p in parts], axis=0) / m
    izz = sum(p.izz + p.mass * float(np.sum((np.array(p.com) - c) ** 2)) for p in parts)
    return Segment(m, (float(c[0]), float(c[1])), izz)


def default_pose(osim: Path) -> dict:
    """Segments, joint centres and marker positions (x, y) of the model ``osim`` in its default pose, from
    the OpenSim API in a process of its own (opensim's Moco library carries a casadi of its own, which
    clashes with casflex's in one process)."""
    out = subprocess.run([sys.executable, __file__, "--pose", str(osim)], capture_output=True, text=True, check=True)
    raw = json.loads(out.stdout)
    pose = {k: {n: np.array(v) for n, v in raw[k].items()} for k in ("centres", "markers")}
    pose |= {k: {n: Segment(v[0], tuple(v[1]), v[2]) for n, v in raw[k].items()} for k in ("segments", "parts")}
    return pose | {"pelvis": np.array(raw["pelvis"]), "model_mass": raw["model_mass"]}


def _pose_json(osim: str) -> str:
    """default_pose's work, in the child process (JSON)."""
    import opensim

    opensim.Logger.setLevelString("error")
    model = opensim.Model(osim)
    state = model.initSystem()

    def vec(v) -> np.ndarray:
        return np.array([v.get(i) for i in range(3)])

    for c in range(model.getCoordinateSet().getSize()):
        assert model.getCoordinateSet().get(c).getValue(state) == 0.0
    parts = {}
    for bs in SEGMENTS.values():
        for name in bs:
            body = model.getBodySet().get(name)
            rot = body.getTransformInGround(state).R()
            assert all(rot.get(i, j) == float(i == j) for i in range(3) for j in range(3)), name  # axes aligned
            inertia = body.getInertia()
            assert np.allclose(vec(inertia.getProducts()), 0.0), name
            com = vec(body.findStationLocationInGround(state, body.getMassCenter()))
            parts[name] = Segment(body.getMass(), (float(com[0]), float(com[1])), float(vec(inertia.getMoments())[2]))
    segments = {seg: merged([parts[b] for b in bs]) for seg, bs in SEGMENTS.items()}
    centres = {j: vec(model.getJointSet().get(j).getChildFrame().getPositionInGround(state))[:2]
               for j in JOINTS}
    origin = vec(model.getBodySet().get("pelvis").getPositionInGround(state))[:2]
    markers = {}
    for name, (label, _) in MARKERS.items():
        markers[name] = vec(model.getMarkerSet().get(label).getLocationInGround(state))[:2]
    def seg(g: Segment) -> list:
        return [g.mass, list(g.com), g.izz]

    return json.dumps({"segments": {k: seg(g) for k, g in segments.items()},
                       "parts": {k: seg(g) for k, g in parts.items()},
                       "centres": {k: v.tolist() for k, v in centres.items()}, "pelvis": origin.tolist(),
                       "markers": {k: v.tolist() for k, v in markers.items()}, "model_mass": model.getTotalMass(state)})


# -- the scenes ------------------------------------------------------------------------------------------

RUN_RIGID = dict(t_end=0.5, dt=0.01, alpha=-0.05)
RUN_FLEXIBLE = dict(t_end=0.5, dt=0.001, alpha=-0.05)  # the held bending modes: 3.8 Hz, then overdamped


def rigid_scene(pose: dict):
    from casflex import Joint, Marker, Node, RigidBody, RunSettings, Scene

    seg, cen = pose["segments"], pose["centres"]
    at = {"pelvis": pose["pelvis"], "hip": cen["hip_r"], "knee": cen["knee_r"], "ankle": cen["ankle_r"]}
    node_of = {"pelvis": "pelvis", "thigh": "hip", "shank": "knee", "foot": "ankle"}
    nodes = tuple(Node(n, float(p[0]), float(p[1])) for n, p in at.items())
    bodies = tuple(RigidBody(s, node_of[s], mass=g.mass, inertia=g.izz, com_x=g.com[0], com_y=g.com[1])
                   for s, g in seg.items())
    joints = (Joint("hip", "hinge", ("pelvis", "hip"), point=tuple(map(float, at["hip"]))),
              Joint("knee", "hinge", ("hip", "knee"), point=tuple(map(float, at["knee"]))),
              Joint("ankle", "hinge", ("knee", "ankle"), point=tuple(map(float, at["ankle"]))))
    markers = tuple(Marker(name, MARKERS[name][1], float(p[0]), float(p[1]), label=MARKERS[name][0])
                    for name, p in pose["markers"].items())
    return Scene(name="hamner_leg", nodes=nodes, bodies=bodies, joints=joints, gravity=(0.0, -G),
                 run=RunSettings(**RUN_RIGID), markers=markers)


def tissue_masses(segment: Segment, a: np.ndarray, b: np.ndarray, m_bone: float) -> list[Segment]:
    """The point masses on the BEAMS + 1 equally spaced nodes of the bone a-b that, with the uniform bone of
    mass m_bone, make up ``segment`` exactly (HEADER_FLEXIBLE): node k (at s_k along the bone) carries
    w_k f(s_k / L), w the trapezoid rule's weights and f(xi) = f0 + f1 xi + f2 xi^2 (kg/m) the linear
    density whose three coefficients give the remainder's mass, centre and Izz; each mass sits beside its
    node on the line through the remainder's centre parallel to the bone."""
    L = float(np.linalg.norm(b - a))
    e = (b - a) / L
    n = np.array([-e[1], e[0]])
    c, cb = np.array(segment.com), (a + b) / 2
    m_r = segment.mass - m_bone
    assert m_r > 0, "the bone outweighs its segment"
    c_r = (segment.mass * c - m_bone * cb) / m_r
    i_r = (segment.izz - m_bone * L * L / 12 - m_bone * float(np.sum((cb - c) ** 2))
           - m_r * float(np.sum((c_r - c) ** 2)))  # the remainder's, about c_r
    assert i_r >= 0, f"the remainder's inertia is negative ({i_r} kg m^2)"
    t_r, d_r = float((c_r - a) @ e), float((c_r - a) @ n)
    xi = np.linspace(0.0, 1.0, BEAMS + 1)
    s = xi * L
    w = np.full(BEAMS + 1, L / BEAMS)
    w[[0, -1]] /= 2
    V = np.array([[w @ xi**j for j in range(3)], [w @ (s * xi**j) for j in range(3)],
                  [w @ ((s - t_r) ** 2 * xi**j) for j in range(3)]])
    f = np.linalg.solve(V, [m_r, m_r * t_r, i_r])
    m = w * (f[0] + f[1] * xi + f[2] * xi**2)
    assert (m > 0).all(), f"a negative point mass: {m}"
    return [Segment(float(mk), tuple(float(v) for v in a + sk * e + d_r * n), 0.0) for mk, sk in zip(m, s, strict=True)]


def section(r_out: float, r_in: float) -> tuple[float, float]:
    """Area (m^2) and second moment of area (m^4) of a circular tube."""
    return math.pi * (r_out**2 - r_in**2), math.pi * (r_out**4 - r_in**4) / 4


def bone_nodes(seg: str) -> list[str]:
    """The names of a bone's BEAMS + 1 nodes, proximal to distal."""
    a, _, bb = BONES[seg]
    return [a] + [f"{seg}_{k}" for k in range(1, BEAMS)] + [bb]


def held_modes(scene, count: int = 4) -> dict:
    """The vibration modes of ``scene`` about its initial configuration with the pelvis clamped and every
    hinge locked (a weld at its point): what the flexible inverse's drives hold while they turn the joints
    (casflex.inverse.flexible). Undamped frequencies (Hz, casflex.statics.modes), the modal damping
    ratios of the beams' dampers, C_ii / (2 omega_i) with C = d f_int / dq' projected on the mass-normalised
    shapes, and the damping ratio and frequency (Hz) of the slowest oscillating pair of the damped
    linearised system M x'' + C x' + K x = 0 on the joints' null space."""
    import warnings

    import casadi as ca

    from casflex import Joint, Support
    from casflex.model import assemble
    from casflex.statics.modes import modes

    held = dataclasses.replace(
        scene, supports=(Support("pelvis_clamp", "pelvis", "clamp"),),
        joints=tuple(Joint(j.name, "weld", j.nodes, point=j.point) for j in scene.joints))
    model = assemble(held)
    with warnings.catch_warnings():  # the default pose is no equilibrium under gravity: K lacks its preload
        warnings.simplefilter("ignore")
        md = modes(model)
    q, qd = ca.SX.sym("q", model.n_dof), ca.SX.sym("qd", model.n_dof)
    h, f_int, _ = model.forces(q, qd, model.p_nominal)  # the dampers' forces are in h (casflex.model)
    C = np.array(ca.Function("C", [q, qd], [ca.jacobian(h + f_int, qd)])(model.q0, np.zeros(model.n_dof)))
    V, w = md.shapes, md.omega
    Cm = V.T @ C @ V
    n = w.size
    lam = np.linalg.eigvals(np.block([[np.zeros((n, n)), np.eye(n)], [-np.diag(np.sign(w) * w**2), -Cm]]))
    pair = min((x for x in lam if x.imag > 1e-6 * abs(x)), key=abs)
    return {"hz": md.freq_hz[:count], "zeta": np.diag(Cm)[:count] / (2 * w[:count]),
            "zeta_1": float(-pair.real / abs(pair)), "hz_1": float(abs(pair) / (2 * math.pi))}


def flexible_scene(rigid):
    """hamner_leg_flexible from the rigid scene (HEADER_FLEXIBLE)."""
    from casflex import Beam, Joint, Marker, Node, RigidBody, RunSettings, Scene

    nodes = {n.name: n for n in rigid.nodes}
    seg = {b.name: Segment(b.mass, (b.com_x, b.com_y), b.inertia) for b in rigid.bodies}
    xy = {n: np.array([nodes[n].x, nodes[n].y]) for n in nodes}
    new_nodes, beams, bodies = [nodes["pelvis"]], [], [next(b for b in rigid.bodies if b.name == "pelvis")]
    on = {"pelvis": lambda m: "pelvis", "foot": lambda m: "foot"}
    for s, (a, b, _) in BONES.items():
        A, I = section(*SECTIONS[s])
        L = float(np.linalg.norm(xy[b] - xy[a]))
        names = bone_nodes(s)
        at = [xy[a] + k / BEAMS * (xy[b] - xy[a]) for k in range(BEAMS + 1)]
        at[0], at[-1] = xy[a], xy[b]
        new_nodes += [nodes[a] if k == 0 else Node(nm, float(p[0]), float(p[1])) for k, (nm, p) in
                      enumerate(zip(names, at, strict=True))]
        beams += [Beam(f"{s}_bone_{k + 1}", (names[k], names[k + 1]), E=E_BONE, A=A, I=I, rho=RHO_BONE,
                       elements=ELEMENTS) for k in range(BEAMS)]
        for k, g in enumerate(tissue_masses(seg[s], xy[a], xy[b], RHO_BONE * A * L)):
            bodies.append(RigidBody(f"{s}_mass_{k}", names[k], mass=g.mass, inertia=0.0, com_x=g.com[0],
                                    com_y=g.com[1]))

        def beam_of(m, s=s, a=xy[a], b=xy[b], L=L) -> str:  # the beam that holds the marker's projection
            along = float((np.array([m.x, m.y]) - a) @ (b - a)) / L
            return f"{s}_bone_{min(BEAMS, int(along / L * BEAMS) + 1)}"

        on[s] = beam_of
    new_nodes.append(nodes["ankle"])
    bodies.append(next(b for b in rigid.bodies if b.name == "foot"))
    joints = (Joint("hip", "hinge", ("pelvis", "hip"), point=(nodes["hip"].x, nodes["hip"].y)),
              Joint("knee", "hinge", ("knee_t", "knee"), point=(nodes["knee"].x, nodes["knee"].y)),
              Joint("ankle", "hinge", ("ankle_s", "ankle"), point=(nodes["ankle"].x, nodes["ankle"].y)))
    markers = tuple(Marker(m.name, on[m.on](m), m.x, m.y, label=m.label) for m in rigid.markers)
    scene = Scene(name="hamner_leg_flexible", nodes=tuple(new_nodes), beams=tuple(beams), bodies=tuple(bodies),
                  joints=joints, gravity=rigid.gravity, run=RunSettings(**RUN_FLEXIBLE), markers=markers)
    beta = float(f"{2 * ZETA_TISSUE / (2 * math.pi * held_modes(scene)['hz'][0]):.3g}")  # beta omega_1 / 2 = zeta
    return dataclasses.replace(scene, beams=tuple(dataclasses.replace(bm, beta=beta) for bm in beams))


# -- the check: a rigid fit of each segment's markers to the trial ------------------------------------------

def kabsch(model_xy: np.ndarray, lab_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Rotation R (2x2), translation t and RMS residual of the best rigid fit R model + t ~ lab."""
    cm, cl = model_xy.mean(axis=0), lab_xy.mean(axis=0)
    u, _, vt = np.linalg.svd((model_xy - cm).T @ (lab_xy - cl))
    d = np.sign(np.linalg.det(u @ vt))
    R = (u @ np.diag([1.0, d]) @ vt).T
    t = cl - R @ cm
    res = lab_xy - (model_xy @ R.T + t)
    return R, t, float(np.sqrt(np.mean(np.sum(res**2, axis=1))))


def fit_check(scene, trc: Path) -> dict:
    from casflex.lab import Plane, markers_in_plane, read_trc

    data = markers_in_plane(read_trc(trc), {m.name: m.label for m in scene.markers}, Plane.parse("X,Y"))
    out = {}
    for seg in SEGMENTS:
        ms = [m for m in scene.markers if m.on == seg]
        model_xy = np.array([[m.x, m.y] for m in ms])
        cols = [(data.channels.index(f"x{m.name}"), data.channels.index(f"y{m.name}")) for m in ms]
        rms = [kabsch(model_xy, np.array([[row[i], row[j]] for i, j in cols]))[2] for row in data.q]
        out[seg] = (float(np.sqrt(np.mean(np.square(rms)))), float(np.max(rms)))
    return out


def main(models: str) -> None:
    import casflex
    from casflex.results import atomic_write_text
    from casflex.scene.io import dumps_scene

    write_leg_osim(source_text(models, OSIM_PLACED))
    spans = write_stride(source_text(models, TRIAL_TRC), source_text(models, TRIAL_GRF),
                         source_text(models, TRIAL_IK))
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        poses = {}
        for path in (OSIM, OSIM_PLACED):
            full = Path(tmp) / Path(path).name
            full.write_text(source_text(models, path), encoding="utf-8")
            poses[path] = default_pose(full)
    pose, scaled = poses[OSIM_PLACED], poses[OSIM]
    cut = default_pose(LEG_OSIM)  # the cut model places everything where the full one does
    for other in (scaled, cut):  # the scaled model: the same bodies and joints, the generic markers
        assert np.array_equal(other["pelvis"], pose["pelvis"]) and other["segments"] == pose["segments"]
        assert all(np.array_equal(other["centres"][j], pose["centres"][j]) for j in JOINTS)
    assert all(np.array_equal(cut["markers"][m], pose["markers"][m]) for m in MARKERS)

    rigid = rigid_scene(pose)
    scenes = Path(casflex.__file__).parent / "scene" / "builtin"
    atomic_write_text(scenes / "hamner_leg.toml", HEADER_RIGID + dumps_scene(rigid))
    write_flexible(casflex.load_scene("hamner_leg"))  # from the file, as the test rebuilds it
    flexible = casflex.load_scene("hamner_leg_flexible")
    for s in (rigid, flexible):
        casflex.assemble(casflex.load_scene(s.name))

    print(f"model mass {pose['model_mass']:.6f} kg; scene {sum(g.mass for g in pose['segments'].values()):.6f} kg")
    for name, g in pose["segments"].items():
        print(f"  {name:7s} m = {g.mass:.6f} kg, com = ({g.com[0]:+.6f}, {g.com[1]:+.6f}) m, Izz = {g.izz:.6f} kg m^2")
    for j in JOINTS:
        print(f"  {j:13s} centre ({pose['centres'][j][0]:+.6f}, {pose['centres'][j][1]:+.6f}) m")
    c = pose["centres"]
    print(f"  thigh {np.linalg.norm(c['knee_r'] - c['hip_r']):.4f} m, "
          f"shank {np.linalg.norm(c['ankle_r'] - c['knee_r']):.4f} m")
    for b in flexible.beams:
        print(f"  {b.name}: A = {b.A:.4e} m^2, I = {b.I:.4e} m^4")
    for b in flexible.bodies:
        print(f"  body {b.name}: m = {b.mass:.6f} at ({b.com_x:+.6f}, {b.com_y:+.6f})")
    print(f"stride: {spans}")
    for seg, (rms, worst) in fit_check(rigid, STRIDE_TRC).items():
        print(f"  markers on {seg}: RMS residual {1e3 * rms:.1f} mm (worst frame {1e3 * worst:.1f} mm)")
    for path in (LEG_OSIM, STRIDE_TRC, STRIDE_GRF, STRIDE_IK, scenes / "hamner_leg.toml",
                 scenes / "hamner_leg_flexible.toml"):
        print(f"wrote {path} ({path.stat().st_size} bytes)")


if __name__ == "__main__":
    if sys.argv[1:2] == ["--pose"]:
        print(_pose_json(sys.argv[2]))
    elif sys.argv[1:2] == ["--flexible"]:  # hamner_leg_flexible.toml alone, from the built-in hamner_leg
        import casflex

        print(f"wrote {write_flexible(casflex.load_scene('hamner_leg'))}")
    else:
        main(sys.argv[1] if len(sys.argv) > 1 else MODELS)
