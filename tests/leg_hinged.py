"""The built-in scene ``leg_hinged`` derived from ``leg_rigid`` and ``leg``: how
casflex/scene/builtin/leg_hinged.toml is written (``python tests/leg_hinged.py``) and what
tests/test_joints.py checks it against."""

from __future__ import annotations

import dataclasses
from pathlib import Path

HEADER = """\
# The built-in rigid leg (casflex/scene/builtin/leg_rigid.toml, from leg.toml: subject, sources, pelvis path,
# markers) on ideal hinges instead of stiff bushings (issue 25). Written by tests/leg_hinged.py, which
# tests/test_joints.py checks:
# - hip_pin (pelvis-thigh, at the hip) and knee_pin (thigh-shank, at the knee, a point of the rigid
#   thigh) replace the 2e5 N/m bushings and their dampers; the hip's and the knee's torsion
#   spring-dampers (and their four parameters) stay: ideal in translation, compliant in rotation.
# - The foot is a rigid body of its own on node ankle, on the hinge ankle_pin at the shank's end, with
#   a torsion spring-damper 'ankle' of 10 N m/rad and 0.1 N m s/rad: example values of the order of a
#   relaxed ankle's passive stiffness in swing, not measured on this subject (leg.toml's sources give
#   none), and not parameters.
# Nine dofs (three bodies), six hinge rows: three dofs of motion, no bushing mode.
"""
KT_ANKLE, CT_ANKLE = 10.0, 0.1  # N m/rad, N m s/rad


def hinged_leg(rigid, leg, *, ankle: bool = True):
    """``rigid`` (leg_rigid) with hinges for its bushings; ``ankle``: the foot on a hinged ankle (the
    node ``ankle`` of ``leg``) instead of fixed to the shank."""
    from casflex import Joint, Scene, TorsionSpring

    joints = [Joint("hip_pin", "hinge", ("pelvis", "hip")),
              Joint("knee_pin", "hinge", ("hip", "knee_s"))]
    nodes, bodies, torsion = list(rigid.nodes), list(rigid.bodies), list(rigid.torsion_springs)
    if ankle:
        nodes.append(next(n for n in leg.nodes if n.name == "ankle"))
        bodies = [dataclasses.replace(b, node="ankle") if b.name == "foot" else b for b in bodies]
        joints.append(Joint("ankle_pin", "hinge", ("knee_s", "ankle")))
        torsion.append(TorsionSpring("ankle", ("knee_s", "ankle"), KT_ANKLE, ct=CT_ANKLE))
    return Scene(name="leg_hinged" if ankle else "leg_hinged_fixed_foot", nodes=tuple(nodes),
                 torsion_springs=tuple(torsion), bodies=tuple(bodies), supports=rigid.supports,
                 joints=tuple(joints), loads=rigid.loads, parameters=rigid.parameters, gravity=rigid.gravity,
                 run=rigid.run, markers=rigid.markers)


if __name__ == "__main__":
    import casflex
    from casflex.results import atomic_write_text
    from casflex.scene.io import dumps_scene

    path = Path(casflex.__file__).parent / "scene" / "builtin" / "leg_hinged.toml"
    scene = hinged_leg(casflex.load_scene("leg_rigid"), casflex.load_scene("leg"))
    atomic_write_text(path, HEADER + dumps_scene(scene))
    print(f"wrote {path}")
