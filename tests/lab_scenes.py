"""A rigid right leg for OpenSim's walking2.c3d excerpt (tests/data/lab): the lab tests' C3D trial through
``casflex inverse``.

The segments are placed where the trial's first frame has them, in the plane "X,Z" (walking along +X, Z
up, seen from -Y: the subject's right): the root at the right hip joint centre point the file carries
(RHJC), the knee and ankle at RKJC and RAJC, each segment's markers where that frame has them. The
masses and inertias are Winter's (2009, table 4.1) fractions for a 70 kg subject: plausible, not this
subject's (the tests check what the command does with the data, not the subject's loads).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

C3D = Path(__file__).resolve().parent / "data" / "lab" / "walking2_excerpt.c3d"
PLANE = "X,Z"
#: segment -> (node's joint-centre point, distal joint-centre point or None, mass kg, radius of gyration
#: about the centre of mass / length, centre of mass from proximal / length, the trial's markers on it)
SEGMENTS = {
    "pelvis": ("RHJC", None, 10.0, 0.0, 0.0, ("RASI", "LASI", "RPSI", "LPSI")),
    "thigh": ("RHJC", "RKJC", 7.0, 0.323, 0.433, ("RTH1", "RTH2", "RTH3")),
    "shank": ("RKJC", "RAJC", 3.26, 0.302, 0.433, ("RTB1", "RTB2", "RTB3")),
    "foot": ("RAJC", None, 1.02, 0.0, 0.0, ("RCAL", "RMT1", "RMT2")),
}


def walking2_leg() -> str:
    """The scene's TOML text (module docstring)."""
    from casflex.lab import Plane, read_c3d

    lab, _ = read_c3d(C3D, plates=False)
    P = Plane.parse(PLANE).matrix

    def at(label: str) -> np.ndarray:
        return lab.marker(label)[0] @ P.T

    lines = ['name = "walking2_leg"', "gravity = [0.0, -9.81]"]
    nodes = {"pelvis": at("RHJC") + [0.0, 0.1], "hip": at("RHJC"), "knee": at("RKJC"), "ankle": at("RAJC")}
    for name, xy in nodes.items():
        lines += ["[[nodes]]", f'name = "{name}"', f"x = {float(xy[0])!r}", f"y = {float(xy[1])!r}"]
    on = {"pelvis": "pelvis", "thigh": "hip", "shank": "knee", "foot": "ankle"}
    for seg, (a, b, mass, gyration, com, _) in SEGMENTS.items():
        pa = at(a)
        pb = at(b) if b else pa + [0.06, -0.04]  # the foot's centre forward of the ankle, the pelvis' above
        length = float(np.linalg.norm(pb - pa)) if b else 0.1
        c = pa + com * (pb - pa) if b else (nodes["pelvis"] if seg == "pelvis" else pb)
        inertia = mass * (gyration * length) ** 2 if b else 0.01 * mass
        lines += ["[[bodies]]", f'name = "{seg}"', f'node = "{on[seg]}"', f"mass = {mass}",
                  f"inertia = {float(inertia)!r}", f"com_x = {float(c[0])!r}", f"com_y = {float(c[1])!r}"]
    for hinge, (a, b) in {"hip": ("pelvis", "hip"), "knee": ("hip", "knee"), "ankle": ("knee", "ankle")}.items():
        p = nodes[b]
        lines += ["[[joints]]", f'name = "{hinge}"', 'kind = "hinge"', f'nodes = ["{a}", "{b}"]',
                  f"point = [{float(p[0])!r}, {float(p[1])!r}]"]
    for seg, (*_, markers) in SEGMENTS.items():
        for label in markers:
            xy = at(label)
            lines += ["[[markers]]", f'name = "{label}"', f'on = "{seg}"', f"x = {float(xy[0])!r}",
                      f"y = {float(xy[1])!r}", f'label = "{label}"']
    return "\n".join(lines) + "\n"
