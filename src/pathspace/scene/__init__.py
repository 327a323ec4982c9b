"""Scenes: the format-independent scene model and its TOML front end."""
from ..fields import SceneError
from .mesh import TriangleMesh
from .model import Scene
from .toml_loader import load_scene, scene_from_dict

__all__ = ["Scene", "SceneError", "TriangleMesh", "load_scene", "scene_from_dict"]
