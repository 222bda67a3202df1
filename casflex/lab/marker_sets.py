"""The marker sets labs use, by their usual names: what casflex's built-in models (``pig``, ``pig_psis``, ``cast``:
``casflex/scene/builtin``, docs/lab.md) expect of a trial, and the other names a lab's software writes for the
same point.

Plug-in Gait (Vicon's conventional gait model) writes its joint centres as virtual points: Nexus 2 and pyCGM2 as
``RHJC``, ``RKJC``, ``RAJC`` (and ``L...``), older Plug-in Gait only as its segments' origins, the femur's at the
knee's centre (``RFEO``) and the tibia's at the ankle's (``RTIO``), each segment's axes as points at the
segment's length from its origin: the femur's proximal one (``RFEP``) at the hip's centre (BTKData's Plug-in Gait
statics: the tibia's proximal point 20-21 mm from the femur's origin, the two centres of one knee; the same
within that for the hip). The built-in models carry the joint centres
under the first names, with weight 0: where the static trial has them, the calibration fits the static pose to them
(weight 1 there) and scales the segments on them (between them they measure the thigh and shank, which skin
markers do not); the marker fit leaves them out (it follows the skin markers, as OpenSim's IK task files of these
sets do).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from casflex.lab.tables import LabMarkers

__all__ = ["JOINT_CENTRES", "JOINT_CENTRE_ALIASES", "joint_centres"]

#: the joint centres' usual names (module docstring): a model's markers of these names and weight 0 are the
#: calibration's (casflex.inverse.calibrate fits the static pose to them, weighed as the skin markers)
JOINT_CENTRES = tuple(f"{s}{k}" for s in "RL" for k in ("HJC", "KJC", "AJC"))

#: a joint centre's usual name -> the other names Plug-in Gait writes it under (module docstring)
JOINT_CENTRE_ALIASES = {f"{s}{k}": tuple(f"{s}{a}" for a in v) for s in "RL"
                        for k, v in {"HJC": ("FEP",), "KJC": ("FEO",), "AJC": ("TIO",)}.items()}


def joint_centres(lab: LabMarkers, wanted: list[str] | tuple[str, ...]) -> tuple[LabMarkers, list[str]]:
    """(the trial with each ``wanted`` joint centre it lacks taken from the first of its other names the trial has
    (:data:`JOINT_CENTRE_ALIASES`), a report line per one taken); the trial as it is where none is."""
    add, lines = {}, []
    for name in wanted:
        if name in lab.labels or name in add:
            continue
        alias = next((a for a in JOINT_CENTRE_ALIASES.get(name, ()) if a in lab.labels), None)
        if alias is not None:
            add[name] = lab.marker(alias)
            lines.append(f"{lab.source}: joint centre {name} taken from {alias} (Plug-in Gait's segment point there)")
    if not add:
        return lab, []
    xyz = np.concatenate([lab.xyz, np.stack(list(add.values()), axis=1)], axis=1)
    return dataclasses.replace(lab, labels=lab.labels + tuple(add), xyz=xyz), lines
