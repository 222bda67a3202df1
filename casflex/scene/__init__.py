"""The scene: pure data describing a planar flexible multibody system, and its reading and writing.

- :mod:`casflex.scene.items`: the items (nodes, beams, springs, bodies, joints, supports, loads, parameters,
  run settings), each validated on construction, and :class:`SceneError`;
- :mod:`casflex.scene.markers`: markers fixed on beams and bodies (``[[markers]]``);
- :mod:`casflex.scene.uncertain`: properties known within an uncertainty (``[[uncertain]]``);
- :mod:`casflex.scene.scene`: :class:`Scene`, the whole system, its cross-checks and look-ups;
- :mod:`casflex.scene.io`: TOML in and out (:func:`load_scene`, :func:`dumps_scene`, the built-in scenes in
  ``casflex/scene/builtin/``);
- :mod:`casflex.scene.files`: a support's motion and a load's table read from data files.

A scene holds numbers only (no CasADi); :func:`casflex.model.assemble` turns it into a symbolic model.
"""

from casflex.scene.io import builtin_scenes, dumps_scene, load_scene, loads_scene, save_scene, scene_from_dict
from casflex.scene.markers import Marker
from casflex.scene.scene import (
    SUPPORT_DOFS,
    Beam,
    Joint,
    Load,
    Node,
    Parameter,
    RigidBody,
    RunSettings,
    Scene,
    SceneError,
    Spring,
    Support,
    TorsionSpring,
)
from casflex.scene.uncertain import Uncertain

__all__ = ["SceneError", "Node", "Beam", "Spring", "TorsionSpring", "RigidBody", "Joint", "Support", "Load",
           "Parameter", "RunSettings", "Scene", "SUPPORT_DOFS", "Marker", "Uncertain", "load_scene", "loads_scene",
           "dumps_scene", "save_scene", "builtin_scenes", "scene_from_dict"]
