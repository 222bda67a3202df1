"""casflex: planar flexible multibody dynamics and parameter identification on CasADi."""

from casflex.model import Model, assemble
from casflex.scene import Beam, Load, Node, Parameter, RunSettings, Scene, SceneError, Spring, Support, TorsionSpring
from casflex.scene_io import builtin_scenes, dumps_scene, load_scene, loads_scene, save_scene

__version__ = "0.1.0"

__all__ = [
    "Beam", "Load", "Model", "Node", "Parameter", "RunSettings", "Scene", "SceneError", "Spring",
    "Support", "TorsionSpring", "assemble", "builtin_scenes", "dumps_scene", "load_scene",
    "loads_scene", "save_scene", "__version__",
]
