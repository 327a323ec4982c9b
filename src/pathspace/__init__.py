"""pathspace: light-transport research in Python.

    import pathspace as ps
    scene = ps.load_scene("scenes/cornell-box/scene.toml")
    result = ps.render(scene, estimator="pt", spp=64, seed=1)
    result.image, result.variance, result.stats
"""
from . import estimators, integrators  # integrators: the old name of estimators, pointing to the new names
from ._native import default_thread_count
from .accel import Accel, Hits
from .film import Film
from .driver import RenderResult, render
from .scene import Scene, SceneError, load_scene, scene_from_dict

__all__ = [
    "Accel",
    "Film",
    "Hits",
    "RenderResult",
    "Scene",
    "SceneError",
    "default_thread_count",
    "load_scene",
    "render",
    "scene_from_dict",
]
__version__ = "0.1.0"
