"""Independent tasks on a cluster (sweep cells, convergence runs), results streamed as they finish."""
from __future__ import annotations

import os
import uuid
from typing import Any, Callable, Iterator

from ..progress import progress_bar
from .client import require_distributed
from .scenes import payload_future, ship

__all__ = ["run_tasks"]


def run_tasks(client, scene, function: Callable, tasks: list[dict], *, shared: dict[str, Any] | None = None,
              progress: bool = False, unit: str = "task") -> Iterator[tuple[int, Any]]:
    """Run ``function(payload, **shared, **task)`` for every task on ``client``'s cluster (``payload``: the
    scene's :class:`~pathspace.cluster.scenes.ScenePayload`; ``shared`` values travel once, like the scene)
    and yield (task index, output) as they finish; a task that raised yields its exception.  Tasks still
    running when the caller stops are cancelled."""
    distributed = require_distributed()
    if isinstance(scene, (str, os.PathLike)):
        from ..scene import load_scene

        scene = load_scene(scene)
    token = uuid.uuid4().hex[:12]
    scene_future = payload_future(client, scene)
    shared_futures = {name: ship(client, value) for name, value in (shared or {}).items()}
    futures = [client.submit(function, scene_future, **shared_futures, **task, key=f"pathspace-{unit}-{token}-{i}",
                             pure=False) for i, task in enumerate(tasks)]
    index_of = {future.key: i for i, future in enumerate(futures)}
    bar = progress_bar(progress, len(tasks), unit, f"{unit}s on the cluster")
    try:
        for future in distributed.as_completed(futures, loop=client.loop):
            try:
                output = future.result()
            except Exception as error:
                output = error
            future.release()
            if bar is not None:
                bar.update(1)
            yield index_of[future.key], output
    finally:
        outstanding = [future for future in futures if not future.done()]
        if outstanding:  # the caller stopped early
            client.cancel(outstanding)
        for future in (scene_future, *shared_futures.values()):
            future.release()
        if bar is not None:
            bar.close()
