"""The built-in models of the marker sets labs use (casflex/scene/builtin/pig.toml, pig_psis.toml, cast.toml):
``python tests/marker_set_scenes.py`` writes them, tests/test_marker_sets.py checks the shipped files are what
this writes.

Each is the planar whole-body model of tests/data/lab (``hamner_subject02_planar.osim``: OpenSim's gait2392
bodies and joints made planar, Hamner's subject 02) with a lab marker set instead of Hamner's own, each marker
taken from the Hamner landmark it sits on (below), on the same body; the arms locked to the torso (the trunk,
head and arms one segment, as lower-limb gait models take them: a planar arm follows an arm swing badly and
moves the hip's moment little). The positions need only be near: a study calibrates each subject on its static
trial, which scales the segments by the markers' distances and places every marker where the subject's is.

- ``pig``: Plug-in Gait (Vicon's conventional gait model): RASI, LASI, SACR, RTHI, RKNE, RTIB, RANK, RHEE, RTOE
  (and the left's), CLAV, RSHO, LSHO. Landmarks: ASIS (R.ASIS), sacrum (V.Sacral), lateral thigh
  (R.Thigh.Upper), lateral femoral epicondyle (R.Knee.Lat), lateral shank (R.Shank.Rear), lateral malleolus
  (R.Ankle.Lat), calcaneus (R.Heel), second metatarsal head (midway between R.Toe.Lat and R.Toe.Med), jugular
  notch (Sternum), acromion (R.Acromium). C7, T10, STRN, the head's and the arms' markers are left out.
- ``pig_psis``: the same with the two posterior superior iliac spines (RPSI, LPSI, at the sacrum's landmark:
  in the sagittal plane they project on it) instead of SACR.
- ``cast``: a CAST-type cluster set (Cappozzo's calibrated anatomical systems, as in OpenSim's walking2.c3d):
  RASI, LASI, RPSI, LPSI; thigh cluster RTH1-3 (R.Thigh.Upper, .Front, .Rear); femoral condyles RLFC, RMFC
  (R.Knee.Lat, .Med); shank cluster RTB1-3 (R.Shank.Upper, .Front, .Rear); malleoli RLMAL, RMMAL; calcaneus
  RCAL; first and second metatarsal heads RMT1 (R.Toe.Med), RMT2 (midway); CLAV.

Each also carries the joint centres a lab's software writes (:mod:`casflex.lab.marker_sets`: RHJC, RKJC, RAJC and
the left's) at the model's hips, knees and ankles, with weight 0: the calibration places and scales the
segments on them where the static trial has them, the marker fit leaves them out. A trial without the trunk's
markers (Plug-in Gait's lower body) has its trunk locked to the pelvis, said (:mod:`casflex.inverse.locking`).
"""

from __future__ import annotations

import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SOURCE = ROOT / "tests" / "data" / "lab" / "hamner_subject02_planar.osim"
BUILTIN = ROOT / "casflex" / "scene" / "builtin"
#: per set: marker (right side, {s}: R or L) -> the Hamner landmarks whose mean it is
SIDES = {
    "pig": {"{s}ASI": ("ASIS",), "{s}THI": ("Thigh.Upper",), "{s}KNE": ("Knee.Lat",), "{s}TIB": ("Shank.Rear",),
            "{s}ANK": ("Ankle.Lat",), "{s}HEE": ("Heel",), "{s}TOE": ("Toe.Lat", "Toe.Med"), "{s}SHO": ("Acromium",)},
    "cast": {"{s}ASI": ("ASIS",), "{s}TH1": ("Thigh.Upper",), "{s}TH2": ("Thigh.Front",), "{s}TH3": ("Thigh.Rear",),
             "{s}LFC": ("Knee.Lat",), "{s}MFC": ("Knee.Med",), "{s}TB1": ("Shank.Upper",), "{s}TB2": ("Shank.Front",),
             "{s}TB3": ("Shank.Rear",), "{s}LMAL": ("Ankle.Lat",), "{s}MMAL": ("Ankle.Med",), "{s}CAL": ("Heel",),
             "{s}MT1": ("Toe.Med",), "{s}MT2": ("Toe.Lat", "Toe.Med")}}
SIDES["pig_psis"] = SIDES["pig"]
CENTRAL = {"pig": {"SACR": ("V.Sacral",), "CLAV": ("Sternum",)},
           "pig_psis": {"CLAV": ("Sternum",)}, "cast": {"CLAV": ("Sternum",)}}
#: sets with the two posterior superior iliac spines, at the sacrum's landmark (module docstring)
PSIS = ("pig_psis", "cast")
#: the joint centres (casflex.lab.marker_sets) -> (the joint, the body whose frame of the joint they sit at)
CENTRES = {"HJC": ("hip_{s}", "femur_{s}"), "KJC": ("knee_{s}", "tibia_{s}"), "AJC": ("ankle_{s}", "tibia_{s}")}
#: the arms' coordinates, locked (module docstring)
ARMS = ("arm_flex", "elbow_flex")
TITLE = {"pig": "Plug-in Gait (SACR)", "pig_psis": "Plug-in Gait (RPSI, LPSI)", "cast": "a CAST-type cluster set"}


def set_markers(name: str) -> dict[str, tuple[str, ...]]:
    """Every marker of the set ``name`` -> its Hamner landmarks."""
    out = dict(CENTRAL[name])
    for side in "RL":
        out |= {k.format(s=side): tuple(f"{side}.{h}" for h in v) for k, v in SIDES[name].items()}
    return out


def _joint_centres(tree: ET.ElementTree) -> dict[str, tuple[str, np.ndarray]]:
    """Each joint centre marker -> (its body's path, its location in the body): the joint's frame on that body."""
    out = {}
    for side in "rl":
        for name, (joint, body) in CENTRES.items():
            j = next(e for e in tree.iter() if e.get("name") == joint.format(s=side))
            frame = next(f for f in j.iter("PhysicalOffsetFrame")
                         if f.find("socket_parent").text.endswith("/" + body.format(s=side)))
            out[f"{side.upper()}{name}"] = (f"/bodyset/{body.format(s=side)}",
                                            np.array([float(v) for v in frame.find("translation").text.split()]))
    return out


def _marker(name: str, body: str, loc) -> ET.Element:
    m = ET.Element("Marker", name=name)
    ET.SubElement(m, "socket_parent_frame").text = body
    ET.SubElement(m, "location").text = " ".join(repr(float(v)) for v in loc)
    ET.SubElement(m, "fixed").text = "false"
    return m


def set_osim(name: str, target: Path) -> None:
    """Write ``target``: the source model with the set ``name``'s markers instead of Hamner's, the arms locked."""
    tree = ET.parse(SOURCE)
    mset = tree.find(".//MarkerSet/objects")
    old = {m.get("name"): m for m in mset.findall("Marker")}
    where = {}
    for marker, marks in set_markers(name).items():
        body = {old[h].find("socket_parent_frame").text for h in marks}
        if len(body) != 1:
            raise ValueError(f"{marker}: its landmarks {marks} lie on different bodies {sorted(body)}")
        where[marker] = (body.pop(), np.mean([[float(v) for v in old[h].find("location").text.split()]
                                              for h in marks], axis=0))
    if name in PSIS:
        body, loc = old["V.Sacral"].find("socket_parent_frame").text, [float(v) for v in old["V.Sacral"].find(
            "location").text.split()]
        where |= {f"{s}PSI": (body, np.array(loc) + [0.0, 0.0, 0.05 * sign]) for s, sign in (("R", 1), ("L", -1))}
    for m in old.values():
        mset.remove(m)
    mset.extend(_marker(n, b, loc) for n, (b, loc) in (where | _joint_centres(tree)).items())
    for c in tree.iter("Coordinate"):  # module docstring: the arms locked to the torso
        if c.get("name", "").startswith(ARMS):
            (c.find("locked") if c.find("locked") is not None else ET.SubElement(c, "locked")).text = "true"
    tree.write(target, encoding="utf-8", xml_declaration=True)


def set_scene_text(name: str, work: Path) -> str:
    """The built-in scene's TOML text of the set ``name`` (its header says what it is)."""
    import dataclasses

    from casflex.scene import dumps_scene
    from casflex.scene.from_osim import scene_from_osim

    set_osim(name, work / f"{name}.osim")
    scene = scene_from_osim(work / f"{name}.osim").scene
    centres = {f"{s}{k}" for s in "RL" for k in CENTRES}
    scene = dataclasses.replace(scene, name=name, markers=tuple(
        dataclasses.replace(m, weight=0.0) if m.name in centres else m for m in scene.markers))
    head = [f"# {name}: the planar whole-body model with {TITLE[name]}'s markers, for gait labs' trials.",
            "# Written by tests/marker_set_scenes.py (do not edit: it says how, and from what) from",
            "# tests/data/lab/hamner_subject02_planar.osim (OpenSim's gait2392 made planar, Hamner's subject 02,",
            "# opensim-org/opensim-models, Apache License 2.0). Markers: " + ", ".join(set_markers(name)) + ";",
            "# " + ("RPSI, LPSI; " if name in PSIS else "") + "joint centres RHJC, RKJC, RAJC, LHJC, LKJC, LAJC "
            "(weight 0: the calibration's only).",
            "# Lab axes of the model: X forward, Y up; calibrate each subject on a static trial (casflex study's",
            "# static, or casflex inverse --static): the markers here are near, not the subject's."]
    return "\n".join(head) + "\n" + dumps_scene(scene)


def main() -> None:
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        for name in TITLE:
            (BUILTIN / f"{name}.toml").write_text(set_scene_text(name, Path(tmp)))
            print(f"wrote {BUILTIN / f'{name}.toml'}")


if __name__ == "__main__":
    sys.exit(main())
