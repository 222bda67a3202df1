"""A planar whole-body OpenSim model with Plug-in Gait's markers, for studies on Vicon data (studies/zoo_study.py).

Plug-in Gait (Vicon's conventional gait model) names its markers RASI, LASI, SACR, RTHI, RKNE, RTIB, RANK, RHEE,
RTOE, CLAV, RSHO (and the left side's; the arms' are left out, below). Hamner's subject 02 (tests/data/lab,
``hamner_subject02_planar.osim``: OpenSim's gait2392 bodies and joints made planar) carries a marker set of its own
on the same landmarks; this takes each Plug-in Gait marker from the landmark it sits on (below), on the same body,
and drops the others. The positions need only be near: a study calibrates each subject on its static trial, which
scales the segments by the markers' distances and then places every marker where the subject's is.

Landmarks: ASIS (R.ASIS), sacrum (V.Sacral), lateral thigh (R.Thigh.Upper), lateral femoral epicondyle
(R.Knee.Lat), lateral shank (R.Shank.Rear), lateral malleolus (R.Ankle.Lat), calcaneus (R.Heel), second
metatarsal head (midway between R.Toe.Lat and R.Toe.Med, on the first and fifth heads), jugular notch
(Sternum), acromion (R.Acromium). Plug-in Gait's C7, T10, STRN and head markers have no landmark in Hamner's set
and are left out (the torso is placed by CLAV and the shoulders; the head rides on the torso).

Plug-in Gait also writes its joint centres as virtual markers (RHJC, the knee's as the femur's origin RFEO, RAJC):
they are added at the model's hips, knees and ankles. Between them, unlike the skin markers, they measure the
segments' lengths; the study weighs them in the calibration only (its IK task file leaves them out).

The arms are locked to the torso (shoulders and elbows at their default: the trunk, head and arms one segment,
as lower-limb gait models take them) and their markers left out: a planar arm follows a child's arm swing badly
(across the body it appears hyperextended; the sample study's wrists were 0.1-0.2 m off the best planar pose), and
the arms move the hip's moment little.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

#: Plug-in Gait marker (right side; the left's with L) -> the Hamner markers whose mean it is
LANDMARKS = {"ASI": ("{s}.ASIS",), "THI": ("{s}.Thigh.Upper",), "KNE": ("{s}.Knee.Lat",), "TIB": ("{s}.Shank.Rear",),
             "ANK": ("{s}.Ankle.Lat",), "HEE": ("{s}.Heel",), "TOE": ("{s}.Toe.Lat", "{s}.Toe.Med"),
             "SHO": ("{s}.Acromium",)}
CENTRAL = {"SACR": ("V.Sacral",), "CLAV": ("Sternum",)}
#: Plug-in Gait's joint centres (its trials' virtual markers: hip from Davis's regression, the knee as the femur's
#: origin FEO, the ankle) -> (the joint, the body whose frame of the joint they sit at)
CENTRES = {"HJC": ("hip_{s}", "femur_{s}"), "FEO": ("knee_{s}", "tibia_{s}"), "AJC": ("ankle_{s}", "tibia_{s}")}
#: the arms' coordinates, locked (module docstring)
ARMS = ("arm_flex", "elbow_flex")


def pig_markers() -> dict[str, tuple[str, ...]]:
    """Every Plug-in Gait marker of the model -> its Hamner landmarks."""
    out = dict(CENTRAL)
    for side in "RL":
        out |= {f"{side}{k}": tuple(h.format(s=side) for h in v) for k, v in LANDMARKS.items()}
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


def pig_osim(source: str | Path, target: str | Path) -> list[str]:
    """Write ``target``: ``source`` (a Hamner-marker model) with Plug-in Gait's markers instead; returns their
    names."""
    tree = ET.parse(source)
    mset = tree.find(".//MarkerSet/objects")
    old = {m.get("name"): m for m in mset.findall("Marker")}
    where = {}
    for name, marks in pig_markers().items():
        body = {old[h].find("socket_parent_frame").text for h in marks}
        if len(body) != 1:
            raise ValueError(f"{name}: its landmarks {marks} lie on different bodies {sorted(body)}")
        where[name] = (body.pop(), np.mean([[float(v) for v in old[h].find("location").text.split()] for h in marks],
                                           axis=0))
    new = []
    for name, (body, loc) in (where | _joint_centres(tree)).items():
        m = ET.Element("Marker", name=name)
        ET.SubElement(m, "socket_parent_frame").text = body
        ET.SubElement(m, "location").text = " ".join(repr(float(v)) for v in loc)
        ET.SubElement(m, "fixed").text = "false"
        new.append(m)
    for m in old.values():
        mset.remove(m)
    mset.extend(new)
    for c in tree.iter("Coordinate"):  # module docstring: the arms locked to the torso
        if c.get("name", "").startswith(ARMS):
            (c.find("locked") if c.find("locked") is not None else ET.SubElement(c, "locked")).text = "true"
    ET.indent(tree)
    tree.write(target, encoding="utf-8", xml_declaration=True)
    return [m.get("name") for m in new]
