"""The built-in scene ``slidercrank`` (casflex/scene/builtin/slidercrank.toml), written from these numbers
(``python tests/slidercrank.py`` rewrites it; tests/test_joints.py checks the file equals this scene).

A crank (a balanced rigid body, radius R) turns at constant speed OMEGA about the origin, driven by a
support moving along theta = PHI0 + OMEGA t; a rigid connecting rod (length ELL) joins the crank pin A
to the piston's wrist pin B; the piston slides along the x axis. Ideal hinges at A and B, a slider
(rotation locked) from the ground to the piston, gravity -y.
"""

from __future__ import annotations

import math
from pathlib import Path

R, ELL, OMEGA, PHI0, T_END = 0.1, 0.35, 4.0 * math.pi, math.pi / 6, 1.0  # m, m, rad/s (2 rev/s), rad, s
M_CRANK, J_CRANK = 0.5, 2.5e-3  # kg, kg m^2 about its centre (at the origin)
M_ROD, M_PISTON, J_PISTON = 0.3, 0.4, 1e-3
J_ROD = M_ROD * ELL**2 / 12


def pins(phi: float) -> tuple[tuple[float, float], tuple[float, float]]:
    """The crank pin A and the wrist pin B (m) at crank angle phi (closed form)."""
    a = (R * math.cos(phi), R * math.sin(phi))
    return a, (a[0] + math.sqrt(ELL**2 - a[1] ** 2), 0.0)


def scene():
    from casflex import Joint, Node, RigidBody, RunSettings, Scene, Support

    (ax, ay), (bx, by) = pins(PHI0)
    rows = [(t, 0.0, 0.0, OMEGA * t) for t in (0.0, T_END / 3, 2 * T_END / 3, T_END)]
    return Scene(
        name="slidercrank",
        nodes=(Node("o", 0.0, 0.0, theta=PHI0), Node("a", ax, ay), Node("b", bx, by)),
        bodies=(RigidBody("crank", "o", M_CRANK, J_CRANK),
                RigidBody("rod", "a", M_ROD, J_ROD, com_x=(ax + bx) / 2, com_y=(ay + by) / 2),
                RigidBody("piston", "b", M_PISTON, J_PISTON)),
        supports=(Support("drive", "o", "clamp", motion=tuple(rows)),),
        joints=(Joint("crankpin", "hinge", ("o", "a")), Joint("wristpin", "hinge", ("a", "b")),
                Joint("cylinder", "slider", ("b",), axis=(1.0, 0.0))),
        run=RunSettings(t_end=T_END, dt=1e-3, alpha=-0.1),
    )


HEADER = """# A slider-crank on ideal joints (issue 25): a balanced crank (R = 0.1 m) driven at 2 rev/s by a
# support moving along theta = pi/6 + 4 pi t, a rigid connecting rod (0.35 m) on hinges at the crank
# pin and the wrist pin, a piston on a slider along x, gravity -y. Written by tests/slidercrank.py,
# which tests/test_joints.py checks; the piston's travel and the pins' forces have closed forms there.
"""

if __name__ == "__main__":
    import casflex

    path = Path(__file__).resolve().parents[1] / "casflex" / "scene" / "builtin" / "slidercrank.toml"
    path.write_text(HEADER + casflex.dumps_scene(scene()))
    print(f"wrote {path}")
