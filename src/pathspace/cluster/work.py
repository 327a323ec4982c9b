"""Independent tasks on a cluster (sweep cells, convergence runs), results streamed as they finish."""
from __future__ import annotations

import os
import uuid
from typing import Any, Callable, Iterator

from ..progress import progress_bar
from .client import require_distributed
from .scenes import ScenePayload, Shipments

__all__ = ["run_tasks"]


def run_tasks(client, scene, function: Callable, tasks: list[dict], *, shared: dict[str, Any] | None = None,
              progress: bool = False, unit: str = "task") -> Iterator[tuple[int, Any]]:
    """Run ``function(payload, **shared, **task)`` for every task on ``client``'s cluster (``payload``: the
    scene's :class:`~pathspace.cluster.scenes.ScenePayload`; ``shared`` values travel once, like the scene)
    and yield (task index, output) as they finish; a task that raised yields its exception.  If the cluster
    loses the scene or a shared value, it is shipped again and the tasks that lost it are submitted again
    (:class:`~pathspace.cluster.scenes.Shipments`).  Tasks still running when the caller stops are
    cancelled."""
    distributed = require_distributed()
    if isinstance(scene, (str, os.PathLike)):
        from ..scene import load_scene

        scene = load_scene(scene)
    token = uuid.uuid4().hex[:12]
    shipments = Shipments(client, ScenePayload.of(scene), **(shared or {}))
    index_of: dict = {}   # task key -> (task index, times submitted before, the futures it was given)
    done = distributed.as_completed(loop=client.loop)

    def submit(index: int, attempt: int = 0) -> None:
        future, given = shipments.submit(function, key=f"pathspace-{unit}-{token}-{index}", attempt=attempt,
                                         **tasks[index])
        index_of[future.key] = (index, attempt, given)
        done.add(future)

    bar = progress_bar(progress, len(tasks), unit, f"{unit}s on the cluster")
    try:
        for index in range(len(tasks)):
            submit(index)
        for future in done:
            index, attempt, given = index_of.pop(future.key)
            try:
                output = future.result()
            except Exception as error:
                if future.status == "cancelled" and shipments.lost_by(given):
                    submit(index, attempt + 1)   # a value it needed was lost with a worker, and is shipped again
                    continue
                output = error
            future.release()
            if bar is not None:
                bar.update(1)
            yield index, output
    finally:
        outstanding = list(done.futures)
        if outstanding:  # the caller stopped early
            client.cancel(outstanding)
        shipments.release()
        if bar is not None:
            bar.close()
