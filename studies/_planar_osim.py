"""A lab's 3D OpenSim model made planar in OpenSim's own terms, so that OpenSim's tools and casflex work on
one and the same planar model (studies/opensim_gait.py).

What changes, by XML alone (no OpenSim needed), and nothing else:
- every coordinate not in ``keep`` is locked (``<locked>true</locked>``) at its default value: OpenSim's IK
  and ID then hold it there, and casflex's reader welds it there;
- each kept rotation whose axis lies within 30 degrees of the plane's normal gets the normal (0, 0, 1) as its
  axis, and the joint's other two rotation axes become x and y (they carry no coordinate, only constants);
- the forces (muscles), the geometry (frames' included) and the controllers are removed: inverse dynamics
  excludes muscles anyway, and the file shrinks from some 700 kB to some 80 kB.
Bodies (mass, centre of mass, inertia), joint frames, coupled translations and markers are the source's.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Iterable

__all__ = ["planar_osim"]

_NORMAL_TOLERANCE_DEG = 30.0  # as casflex.scene.from_osim.PROJECTED: the largest tilt projected, not refused


def _axis(ta: ET.Element) -> list[float]:
    return [float(v) for v in (ta.findtext("axis") or "0 0 0").split()]


def _planar_rotations(joint: ET.Element, keep: set[str], report: list[str]) -> None:
    axes = {ta.get("name"): ta for ta in joint.iter("TransformAxis")}
    for name in ("rotation1", "rotation2", "rotation3"):
        ta = axes.get(name)
        coord = (ta.findtext("coordinates") or "").strip() if ta is not None else ""
        if not coord or coord not in keep:
            continue
        a = _axis(ta)
        tilt = math.degrees(math.acos(min(1.0, abs(a[2]) / math.sqrt(sum(v * v for v in a)))))
        if tilt > _NORMAL_TOLERANCE_DEG:
            raise ValueError(f"joint {joint.get('name')!r}: coordinate {coord!r} turns about {a}, "
                             f"{tilt:.1f} deg from the normal: lock it instead")
        others = [n for n in ("rotation1", "rotation2", "rotation3") if n != name]
        sign = 1.0 if a[2] > 0 else -1.0
        for ta_name, vec in zip([name, *others], ([0, 0, sign], [1, 0, 0], [0, 1, 0]), strict=True):
            axes[ta_name].find("axis").text = " ".join(f"{v:g}" for v in vec)
        if tilt > 1e-9:
            report.append(f"joint {joint.get('name')!r}: {coord!r}'s axis {a} ({tilt:.1f} deg off) set to the normal")


def planar_osim(source: str, dest: str, keep: Iterable[str], name: str | None = None) -> list[str]:
    """Write ``dest``: the model file ``source`` with only the coordinates ``keep`` free, their rotations about
    the plane's normal (module docstring). Returns what was changed, one line each."""
    tree = ET.parse(source)
    root = tree.getroot()
    model = root.find("Model")
    if name:
        model.set("name", name)
    keep = set(keep)
    report: list[str] = []
    found = set()
    for coord in model.iter("Coordinate"):
        found.add(coord.get("name"))
        if coord.get("name") not in keep:
            locked = coord.find("locked")
            if locked is None:
                locked = ET.SubElement(coord, "locked")
            locked.text = "true"
            report.append(f"coordinate {coord.get('name')!r} locked at {coord.findtext('default_value', '0').strip()}")
    if missing := sorted(keep - found):
        raise ValueError(f"keep: no coordinate {', '.join(missing)} in {source}")
    for joint in model.iter("CustomJoint"):
        _planar_rotations(joint, keep, report)
    for parent in list(model.iter()):
        for child in list(parent):
            if child.tag in ("ForceSet", "ControllerSet", "ProbeSet"):
                parent.remove(child)
                report.append(f"{child.tag} removed")
            elif child.tag in ("attached_geometry", "VisibleObject", "WrapObjectSet", "FrameGeometry"):
                parent.remove(child)
    for e in root.iter():  # the source's blank lines (where its comments were) out
        e.text = e.text.strip() if e.text and e.text.strip() else None
        e.tail = None
    ET.indent(tree, space=" ")
    tree.write(dest, encoding="UTF-8", xml_declaration=True)
    return report
