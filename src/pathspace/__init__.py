"""pathspace: light-transport research in Python.

    import pathspace as ps
    scene = ps.load_scene("scenes/cornell-box/scene.toml")
    result = ps.render(scene, estimator="pt", spp=64, seed=1)
    result.image, result.variance, result.stats
    ref = ps.reference(scene, spp=4096)                      # cached
    ps.metrics.relmse(result.image, ref.image)
    ps.experiment.converge(scene, ["pt", "bdpt"], ref, time=10).plot()
    client = ps.cluster.start_client(workers=2)              # Dask (the dask extra)
    ps.render(scene, "bdpt", spp=1024, client=client)
"""
__version__ = "0.1.0"

# integrators: the old name, pointing to the new; cluster: Dask, imported only when a client is used
from . import cluster, estimators, experiment, integrators, metrics, plot
from ._native import default_thread_count
from .accel import Accel, Hits
from .driver import RenderResult, render
from .film import Film
from .reference import Reference, reference
from .scene import Scene, SceneError, load_scene, scene_from_dict

__all__ = [
    "Accel",
    "Film",
    "Hits",
    "Reference",
    "RenderResult",
    "Scene",
    "SceneError",
    "cluster",
    "default_thread_count",
    "estimators",
    "experiment",
    "load_scene",
    "metrics",
    "plot",
    "reference",
    "render",
    "scene_from_dict",
]
