"""Scenes on workers: shipped once as a pickled payload, unpickled once per worker process, kept with their BVHs.

A task gets a :class:`ScenePayload` (a key and the pickled scene: geometry, materials, lights and
camera, without BVHs; see :meth:`pathspace.scene.Scene.__getstate__`) and calls :func:`scene_on_worker`,
which returns the scene of that key from the process's cache or unpickles it there.  The payload
is scattered to every worker once per render or sweep (:class:`Shipments`), and again if the cluster
loses it.
"""
from __future__ import annotations

import hashlib
import pickle
import threading
from collections import OrderedDict
from dataclasses import dataclass

__all__ = ["ScenePayload", "Shipments", "ship", "scene_on_worker", "scene_loads"]

# Scenes kept per worker process (the least recently used is dropped beyond this).
KEPT_SCENES = 4
# How many times a render or sweep ships its values again after the cluster lost them.
RESHIPS = 3

_scenes: "OrderedDict[str, object]" = OrderedDict()
_lock = threading.Lock()
_loads = [0]


@dataclass(frozen=True)
class ScenePayload:
    """A scene as it travels to workers: ``key`` (its fingerprint, or a hash of the payload for scenes
    built in memory) and ``data`` (the pickled scene)."""

    key: str
    data: bytes

    @classmethod
    def of(cls, scene) -> "ScenePayload":
        """The payload of ``scene``."""
        data = pickle.dumps(scene, protocol=pickle.HIGHEST_PROTOCOL)
        key = scene.fingerprint or hashlib.sha256(data).hexdigest()
        return cls(key, data)


def ship(client, value):
    """A future of ``value`` copied to every worker (``scatter(broadcast=True)``), for tasks to depend on: it
    travels straight to the workers, not through the scheduler's task graph, and every worker holds it
    before any task needs it -- else Dask keeps the tasks near the one worker that holds it (measured: 5
    tasks to 3 on two workers, the second waiting 0.2 s for its copy).  A worker that joins later, or
    restarts, fetches it from another; when every worker holding it has died, it is lost (see
    :class:`Shipments`)."""
    return client.scatter([value], broadcast=True, hash=False)[0]  # in a list: lists and dicts are one value too


class Shipments:
    """The scene's payload and other values copied to every worker for a render's or sweep's tasks to depend
    on (:attr:`futures`, by name), shipped again when the cluster loses one.

    Scattered data has no task that could compute it again: when every worker holding it has died, Dask
    forgets it and cancels the tasks that need it ("already forgotten"; "lost dependencies" for tasks
    submitted after), finished ones whose results were on the dead workers too.  :func:`ship` gives every
    worker a copy, but Dask's active memory manager drops the copies that no assigned task needs (its
    ReduceReplicas policy, on by default), so the death of one worker can lose a value.  Tasks go through
    :meth:`submit`; a caller whose task comes back cancelled asks :meth:`lost_by` with the futures the task
    was given, and if a value it needed was lost (that value is then shipped again), submits it again.
    """

    def __init__(self, client, payload: ScenePayload, **shared) -> None:
        self.client, self.values, self.renewals = client, {"payload": payload, **shared}, 0
        self.futures = {name: ship(client, value) for name, value in self.values.items()}

    def submit(self, function, *args, key: str, attempt: int = 0, **kwargs) -> tuple[object, dict]:
        """Submit ``function(payload, *args, **shared, **kwargs)`` (the values' current futures) as task ``key``
        (its ``attempt``-th submission again: ``key-again-attempt``); returns its future and the futures it
        was given (for :meth:`lost_by`)."""
        given = dict(self.futures)
        shared = {name: future for name, future in given.items() if name != "payload"}
        future = self.client.submit(function, given["payload"], *args, **shared, **kwargs, pure=False,
                                    key=f"{key}-again-{attempt}" if attempt else key)
        return future, given

    def lost_by(self, given: dict) -> bool:
        """Whether a cancelled task lost a value it was ``given`` (by :meth:`submit`): shipped again since, or
        lost now (then shipped again here).  Raises RuntimeError after ``RESHIPS`` renewals: a cluster that
        keeps losing every worker cannot finish the work."""
        renewed = any(self.futures[name] is not future for name, future in given.items())
        lost = [name for name, future in self.futures.items() if future.status != "finished"]
        if lost:
            if self.renewals == RESHIPS:
                raise RuntimeError(f"the cluster lost the data shipped to it ({', '.join(lost)}) "
                                   f"{RESHIPS + 1} times: every worker holding it died")
            self.renewals += 1
            for name in lost:
                self.futures[name].release()
                self.futures[name] = ship(self.client, self.values[name])
        return renewed or bool(lost)

    def release(self) -> None:
        """Let the cluster drop the values."""
        for future in self.futures.values():
            future.release()


def scene_on_worker(payload: ScenePayload):
    """The scene of ``payload`` in this process: cached, or unpickled (and counted) on first use."""
    with _lock:
        scene = _scenes.get(payload.key)
        if scene is None:
            scene = pickle.loads(payload.data)
            _loads[0] += 1
            _scenes[payload.key] = scene
            while len(_scenes) > KEPT_SCENES:
                _scenes.popitem(last=False)
        _scenes.move_to_end(payload.key)
        return scene


def scene_loads() -> int:
    """How many scenes this process has unpickled (run it on the workers: ``client.run(scene_loads)``)."""
    return _loads[0]
