"""The built-in scene ``leg_rigid`` derived from ``leg``: how casflex/scene/builtin/leg_rigid.toml is written
(``python tests/leg_rigid.py``) and what tests/test_leg_scene.py checks it against."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

HEADER = """\
# The built-in leg (casflex/scene/builtin/leg.toml: subject, sources, pelvis path, joints, markers) with
# thigh and shank as rigid links instead of flexible beams (issue 13). Written by
# tests/leg_rigid.py from leg.toml, which tests/test_leg_scene.py checks:
# - Each segment is a rigid body at the node of its proximal joint (thigh at the hip, shank at the
#   knee): the beam's mass rho A L, its centre of mass at the beam's middle and its moment of
#   inertia about it m L^2 / 12, the uniform beam's (what the beam's consistent mass gives a rigid
#   motion). The foot is the same body, now on the shank's node.
# - The knee bushing and torsion spring-damper join the thigh's node (at the hip) to the shank's:
#   the bushing at the knee, a point on the rigid thigh (a spring's point_a), the torsion spring
#   on the two segments' rotations. Same stiffness and damping, same parameters.
# - The markers sit where they sit on leg, now on the rigid thigh and shank.
# Three dofs per segment (6 in all, against leg's 12): no axial or bending modes.
"""


def rigid_leg(leg):
    """``leg`` (the flexible scene) with its thigh and shank as rigid bodies."""
    from casflex import RigidBody, Scene

    nodes = {n.name: n for n in leg.nodes}
    beams = {b.name: b for b in leg.beams}

    def body(beam: str, at: str) -> RigidBody:
        b = beams[beam]
        na, nb = (nodes[n] for n in b.nodes)
        L = math.hypot(nb.x - na.x, nb.y - na.y)
        m = b.rho * b.A * L
        return RigidBody(beam, at, mass=m, inertia=m * L * L / 12, com_x=(na.x + nb.x) / 2, com_y=(na.y + nb.y) / 2)

    knee = nodes["knee"]
    springs = tuple(dataclasses.replace(s, nodes=("hip", "knee_s"), point_a=(knee.x, knee.y)) if s.name == "knee_joint"
                    else s for s in leg.springs)
    torsion = tuple(dataclasses.replace(s, nodes=("hip", "knee_s")) if s.name == "knee" else s
                    for s in leg.torsion_springs)
    foot = next(b for b in leg.bodies if b.name == "foot")
    return Scene(name="leg_rigid", nodes=tuple(n for n in leg.nodes if n.name not in ("knee", "ankle")),
                 springs=springs, torsion_springs=torsion,
                 bodies=(body("thigh", "hip"), body("shank", "knee_s"), dataclasses.replace(foot, node="knee_s")),
                 supports=leg.supports, loads=leg.loads, parameters=leg.parameters, gravity=leg.gravity,
                 run=leg.run, markers=leg.markers)


if __name__ == "__main__":
    import casflex
    from casflex.results import atomic_write_text
    from casflex.scene.io import dumps_scene

    path = Path(casflex.__file__).parent / "scene" / "builtin" / "leg_rigid.toml"
    atomic_write_text(path, HEADER + dumps_scene(rigid_leg(casflex.load_scene("leg"))))
    print(f"wrote {path}")
