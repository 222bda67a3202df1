"""A lab's 3D OpenSim model made planar in OpenSim's own terms, so that OpenSim's tools and casflex work on
one and the same planar model (studies/opensim_gait.py).

What changes, by XML alone (no OpenSim needed), and nothing else:
- every coordinate not in ``keep`` is locked (``<locked>true</locked>``) at its default value: OpenSim's IK
  and ID then hold it there, and casflex's reader welds it there; the constraints (a patella's coordinate
  coupled to the knee's) are removed, their coordinates being locked;
- a joint with kept coordinates whose two offset frames share one orientation R (Rajagopal's knee, a PinJoint's
  tilted ankle) gets frames without it and its transform's axes turned by R (the same joint: X_F J X_M^-1
  with R J R^T), so that its axes are seen in the bodies' frames; a PinJoint then turns about the bodies' z;
- each kept rotation whose axis lies within 30 degrees of the plane's normal gets the normal (0, 0, 1) as its
  axis, and the joint's other two rotation axes become x and y;
- a rotation that follows a kept coordinate about another axis (the knee's ab-/adduction and rotation coupled
  to its flexion) is held at its value at the coordinate's default (a Constant);
- translations that follow a kept coordinate (the knee's rolling) become their sums along x and y (SIMM splines
  on shared knots add exactly), the part along the normal held at its value at the coordinate's default: else
  OpenSim's IK, fitting the markers' distance along the normal too (some 0.3 m for a subject walking off the
  model's plane), trades the fit in the plane for it (0.1-0.6 deg at Rajagopal's knee);
- the forces (muscles), the geometry (frames' included) and the controllers are removed: inverse dynamics
  excludes muscles anyway, and the file shrinks from some 700 kB to some 80 kB.
Bodies (mass, centre of mass, inertia), joint frames' origins and markers are the source's.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Iterable

import numpy as np

__all__ = ["planar_osim"]

_NORMAL_TOLERANCE_DEG = 30.0  # as casflex.scene.from_osim.PROJECTED: the largest tilt projected, not refused
_ROTATIONS = ("rotation1", "rotation2", "rotation3")
_TRANSLATIONS = ("translation1", "translation2", "translation3")


def _vec(text: str | None) -> np.ndarray:
    return np.array([float(v) for v in (text or "0 0 0").split()])


def _text(v) -> str:
    return " ".join(f"{float(x):.17g}" for x in v)


def _orientation(xyz: np.ndarray) -> np.ndarray:
    """OpenSim's frame orientation: X-Y-Z body-fixed angles (rad) -> rotation (3, 3)."""
    (ca, cb, cc), (sa, sb, sc) = np.cos(xyz), np.sin(xyz)
    rx = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
    ry = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    rz = np.array([[cc, -sc, 0], [sc, cc, 0], [0, 0, 1]])
    return rx @ ry @ rz


def _tilt(a: np.ndarray) -> float:
    """Degrees between ``a`` and the plane's normal (either way)."""
    return math.degrees(math.acos(min(1.0, abs(a[2]) / np.linalg.norm(a))))


def _offset_frames(joint: ET.Element) -> list[ET.Element]:
    """The joint's own parent and child offset frames (those its sockets name)."""
    frames = {f.get("name"): f for f in joint.iter("PhysicalOffsetFrame")}
    names = [(joint.findtext(s) or "").strip() for s in ("socket_parent_frame", "socket_child_frame")]
    return [frames[n] for n in names if n in frames]


def _unrotate(joint: ET.Element, keep: set[str], report: list[str]) -> None:
    """Move a shared orientation R of the joint's offset frames into its transform's axes (module docstring)."""
    frames = _offset_frames(joint)
    coords = {c.get("name") for c in joint.iter("Coordinate")}
    if len(frames) != 2 or not coords & keep:
        return
    angles = [_vec(f.findtext("orientation")) for f in frames]
    if not np.any(angles[0]) and not np.any(angles[1]):
        return
    if not np.allclose(angles[0], angles[1], rtol=0.0, atol=1e-12):
        raise ValueError(f"joint {joint.get('name')!r}: its offset frames differ in orientation; not made planar")
    R = _orientation(angles[0])
    for f in frames:
        f.find("orientation").text = "0 0 0"
    if joint.tag == "PinJoint":
        report.append(f"joint {joint.get('name')!r}: its axis {_text(np.round(R[:, 2], 6))} "
                      f"({_tilt(R[:, 2]):.1f} deg off) set to the normal")
        if _tilt(R[:, 2]) > _NORMAL_TOLERANCE_DEG:
            raise ValueError(f"joint {joint.get('name')!r}: its axis is {_tilt(R[:, 2]):.1f} deg from the normal")
        return
    for ta in joint.iter("TransformAxis"):
        ta.find("axis").text = _text(R @ _vec(ta.findtext("axis")))


def _function(ta: ET.Element) -> ET.Element:
    return next(c for c in ta if c.tag not in ("coordinates", "axis"))


def _knots(fn: ET.Element) -> tuple[np.ndarray | None, np.ndarray]:
    """(x knots, y values) of a SIMM spline (a multiplier's scale applied), (None, value) of a constant."""
    if fn.tag == "MultiplierFunction":
        x, y = _knots(next(iter(fn.find("function"))))
        return x, float(fn.findtext("scale")) * y
    if fn.tag == "Constant":
        return None, np.array(float(fn.findtext("value")))
    if fn.tag == "LinearFunction" and float(_vec(fn.findtext("coefficients"))[0]) == 0.0:
        return None, np.array(_vec(fn.findtext("coefficients"))[1])
    if fn.tag == "SimmSpline":
        return _vec(fn.findtext("x")), _vec(fn.findtext("y"))
    raise ValueError(f"a {fn.tag} in a coupled transform: not made planar")


def _set_function(ta: ET.Element, coordinate: str, x: np.ndarray | None, y: np.ndarray) -> None:
    ta.remove(_function(ta))
    ta.find("coordinates").text = coordinate if x is not None else None
    if x is None:
        ET.SubElement(ET.SubElement(ta, "Constant", name="function"), "value").text = f"{float(y):.17g}"
    else:
        spline = ET.SubElement(ta, "SimmSpline", name="function")
        ET.SubElement(spline, "x").text = _text(x)
        ET.SubElement(spline, "y").text = _text(y)


def _hold_coupled_rotations(joint: ET.Element, keep: set[str], default: dict, report: list[str]) -> None:
    """A rotation following a kept coordinate through a spline about an axis off the normal: held at its value
    at the coordinate's default (a knot of the spline)."""
    for ta in joint.iter("TransformAxis"):
        coord = (ta.findtext("coordinates") or "").strip()
        if ta.get("name") not in _ROTATIONS or coord not in keep or _function(ta).tag == "LinearFunction":
            continue
        if _tilt(_vec(ta.findtext("axis"))) <= _NORMAL_TOLERANCE_DEG:
            continue
        x, y = _knots(_function(ta))
        at = np.flatnonzero(np.isclose(x, default[coord], rtol=0, atol=1e-12)) if x is not None else []
        if x is not None and not len(at):
            raise ValueError(f"joint {joint.get('name')!r}: {coord!r}'s default is not a knot of its coupled rotation")
        value = float(y[at[0]]) if x is not None else float(y)
        _set_function(ta, "", None, np.array(value))
        report.append(f"joint {joint.get('name')!r}: {ta.get('name')} (following {coord!r} about "
                      f"{_text(np.round(_vec(ta.findtext('axis')), 4))}) held at {value:g} rad")


def _planar_translations(joint: ET.Element, keep: set[str], default: dict, report: list[str]) -> None:
    """Translations following a kept coordinate: summed along x and y on their shared knots (module docstring)."""
    axes = {ta.get("name"): ta for ta in joint.iter("TransformAxis") if ta.get("name") in _TRANSLATIONS}
    coords = {(ta.findtext("coordinates") or "").strip() for ta in axes.values()} - {""}
    if not coords & keep or all(np.allclose(_vec(ta.findtext("axis")), e) for ta, e in
                                zip(axes.values(), np.eye(3), strict=True)):
        return
    if len(coords) > 1:
        raise ValueError(f"joint {joint.get('name')!r}: translations follow {sorted(coords)}; not made planar")
    parts = [(_vec(ta.findtext("axis")), *_knots(_function(ta))) for ta in axes.values()]
    knots = [x for _, x, _ in parts if x is not None]
    if any(len(x) != len(knots[0]) or not np.array_equal(x, knots[0]) for x in knots):
        raise ValueError(f"joint {joint.get('name')!r}: its translations' splines have different knots")
    total = sum(np.outer(y * np.ones_like(knots[0]), a / np.linalg.norm(a)) for a, _, y in parts)  # (knots, 3)
    coord = coords.pop()
    at = np.flatnonzero(np.isclose(knots[0], default[coord], rtol=0, atol=1e-12))
    if not len(at):
        raise ValueError(f"joint {joint.get('name')!r}: {coord!r}'s default is not a knot of its translations")
    for k, ta in enumerate(axes.values()):  # x and y in the plane; the normal's part held (as casflex holds it)
        ta.find("axis").text = _text(np.eye(3)[k])
        _set_function(ta, coord, knots[0], total[:, k]) if k < 2 else _set_function(ta, "", None, total[at[0], 2])
    report.append(f"joint {joint.get('name')!r}: translations following {coord!r} summed along x and y; along the "
                  f"normal held at {1e3 * total[at[0], 2]:.2f} mm (its reach {1e3 * np.ptp(total[:, 2]):.2f} mm)")


def _planar_rotations(joint: ET.Element, keep: set[str], report: list[str]) -> None:
    axes = {ta.get("name"): ta for ta in joint.iter("TransformAxis")}
    for name in ("rotation1", "rotation2", "rotation3"):
        ta = axes.get(name)
        coord = (ta.findtext("coordinates") or "").strip() if ta is not None else ""
        if not coord or coord not in keep:
            continue
        a = _vec(ta.findtext("axis"))
        tilt = _tilt(a)
        if tilt > _NORMAL_TOLERANCE_DEG:
            raise ValueError(f"joint {joint.get('name')!r}: coordinate {coord!r} turns about {a}, "
                             f"{tilt:.1f} deg from the normal: lock it instead")
        others = [n for n in ("rotation1", "rotation2", "rotation3") if n != name]
        sign = 1.0 if a[2] > 0 else -1.0
        for ta_name, vec in zip([name, *others], ([0, 0, sign], [1, 0, 0], [0, 1, 0]), strict=True):
            axes[ta_name].find("axis").text = " ".join(f"{v:g}" for v in vec)
        if tilt > 1e-9:
            report.append(f"joint {joint.get('name')!r}: {coord!r}'s axis {_text(np.round(a, 6))} ({tilt:.1f} deg off) "
                          "set to the normal")


#: The muscle classes ``planar_osim(..., muscles=True)`` keeps.
_MUSCLES = ("Millard2012EquilibriumMuscle", "Thelen2003Muscle", "DeGrooteFregly2016Muscle")


def _keep_muscles(forces: ET.Element, report: list[str]) -> None:
    """The ForceSet's muscles kept, its other forces removed (named in the report)."""
    holder = forces.find("objects")
    gone = [el for el in (holder if holder is not None else []) if el.tag not in _MUSCLES]
    for el in gone:
        holder.remove(el)
    if gone:
        names = ", ".join(f"{el.tag} {el.get('name')}" for el in gone)
        report.append(f"forces removed (muscles kept): {names}")


def planar_osim(source: str, dest: str, keep: Iterable[str], name: str | None = None, *, muscles: bool = False
                ) -> list[str]:
    """Write ``dest``: the model file ``source`` with only the coordinates ``keep`` free, their rotations about
    the plane's normal (module docstring). ``muscles``: the ForceSet's muscles (and the bodies' wrap objects)
    kept, its other forces removed (the muscle analyses compare casflex and OpenSim on the same planar model).
    Returns what was changed, one line each."""
    tree = ET.parse(source)
    root = tree.getroot()
    model = root.find("Model")
    if name:
        model.set("name", name)
    keep = set(keep)
    report: list[str] = []
    found = set()
    default = {c.get("name"): float(c.findtext("default_value", "0")) for c in model.iter("Coordinate")}
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
    for joint in [j for j in model.iter() if j.tag in ("CustomJoint", "PinJoint")]:
        _unrotate(joint, keep, report)
        if joint.tag == "CustomJoint":
            _hold_coupled_rotations(joint, keep, default, report)
            _planar_rotations(joint, keep, report)
            _planar_translations(joint, keep, default, report)
    for parent in list(model.iter()):
        for child in list(parent):
            if child.tag == "ConstraintSet" and len(child.find("objects") or []):  # on locked coordinates
                report.append(f"constraints removed: {', '.join(c.get('name') for c in child.find('objects'))}")
                child.remove(child.find("objects"))
                ET.SubElement(child, "objects")
            elif child.tag == "ForceSet" and muscles:
                _keep_muscles(child, report)
            elif child.tag in ("ForceSet", "ControllerSet", "ProbeSet"):
                parent.remove(child)
                report.append(f"{child.tag} removed")
            elif child.tag == "WrapObjectSet" and muscles:
                continue
            elif child.tag in ("attached_geometry", "VisibleObject", "WrapObjectSet", "FrameGeometry"):
                parent.remove(child)
    for e in root.iter():  # the source's blank lines (where its comments were) out
        e.text = e.text.strip() if e.text and e.text.strip() else None
        e.tail = None
    ET.indent(tree, space=" ")
    tree.write(dest, encoding="UTF-8", xml_declaration=True)
    return report
