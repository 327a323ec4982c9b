"""Renders, references, convergence runs and sweeps on a Dask cluster (the ``dask`` extra).

    from dask.distributed import Client, LocalCluster
    import pathspace as ps

    client = Client(LocalCluster(n_workers=2, threads_per_worker=1))   # or ps.cluster.start_client(workers=2)
    r = ps.render("scenes/cornell-box/scene.toml", "bdpt", spp=256, client=client)
    sw = ps.experiment.sweep(scene, "pt", {"rr": ["albedo", "off"]}, ref, spp=64, client=client)

* **One render** (:func:`pathspace.render` with ``client=``) becomes tasks of consecutive passes
  (:mod:`pathspace.cluster.render`).  Each task renders its passes with the render's seed and
  ``first_pass`` at its first pass -- the random streams of a pass depend only on the seed and the
  pass, so a task's passes are the same samples as in one process -- and returns its film; the client
  merges the films in pass order as they arrive.
* **Sweeps and convergence runs** make one task per cell and seed (per estimator and seed); each renders
  in one worker thread.  Finished sweep cells are cached, so a sweep run again renders only the cells
  it is missing (:mod:`pathspace.experiment.cache`).
* **Scenes** go to every worker once per render or sweep (again if the cluster loses them), as a pickled
  payload, and are unpickled once per worker process and kept there with their BVHs
  (:mod:`pathspace.cluster.scenes`).

Nothing here imports Dask until a client is used; :func:`start_client` starts or joins a cluster.
"""
from .client import require_distributed, start_client
from .scenes import ScenePayload, scene_loads

__all__ = ["ScenePayload", "require_distributed", "scene_loads", "start_client"]
