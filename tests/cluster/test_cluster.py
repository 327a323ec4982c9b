"""Renders, sweeps and convergence runs on a local Dask cluster of two single-threaded worker processes:
the same images as in one process, no sample lost or counted twice when a worker dies, failed cells
reported, scenes loaded once per worker."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

import pathspace as ps
from pathspace.cluster import ScenePayload, scene_loads, scenes, start_client
from pathspace.experiment import converge, sweep
from pathspace.film import Film
from conftest import scene_dict

ESTIMATORS = [("pt", {}), ("lt", {}), ("bdpt", {"pyramid": 2}), ("bdpt", {"pyramid": 1, "spectral": True})]


@pytest.fixture(scope="module")
def client():
    client = start_client(workers=2)
    yield client
    client.close()


@pytest.fixture
def workers(client):
    """The client, with both workers up (a test may have killed one; its nanny restarts it)."""
    client.wait_for_workers(2, timeout=120)
    return client


def box(resolution=(32, 32)):
    return ps.scene_from_dict(scene_dict("cornell-box", resolution))


def assert_same_to_rounding(a: Film, b: Film) -> None:
    """Films of the same passes, merged in different ways: equal counts, images equal to a few ulps."""
    assert a.passes == b.passes and a.nonfinite == b.nonfinite
    assert np.array_equal(a.count, b.count)
    scale = np.abs(a.image()).max()
    assert np.abs(a.image() - b.image()).max() <= 1e-13 * scale
    assert np.abs(a.image_variance() - b.image_variance()).max() <= 1e-11 * np.abs(a.image_variance()).max()
    assert sorted(a.layers) == sorted(b.layers)
    for name in a.layers:
        assert np.abs(a.layer_mean(name) - b.layer_mean(name)).max() <= 1e-13 * max(scale, 1e-300)


@pytest.mark.parametrize("estimator, params", ESTIMATORS)
def test_a_cluster_render_is_the_single_process_render(workers, estimator, params):
    """Same seed and spp: equal to the render in one process to rounding (Chan's merge of task films vs
    Welford's pass by pass), and bit for bit the in-process renders of the tasks' pass ranges merged in
    task order -- which a second cluster render repeats exactly."""
    scene = box()
    single = ps.render(scene, estimator, spp=10, seed=5, **params)
    on_cluster = ps.render(scene, estimator, spp=10, seed=5, client=workers, task_passes=3, **params)
    cluster = on_cluster.stats["cluster"]
    assert cluster["tasks"] == 4 and on_cluster.stats["spp"] == 10
    assert 1 <= cluster["tasks_waiting_peak"] <= 2 * cluster["threads"]   # finished films waiting on the workers
    assert on_cluster.stats["rays"] == single.stats["rays"]
    assert_same_to_rounding(single.film, on_cluster.film)
    merged = Film(32, 32, covariance=single.film.covariance, to_srgb=single.film.to_srgb)
    for first in (0, 3, 6, 9):
        merged.merge(ps.render(scene, estimator, spp=min(3, 10 - first), seed=5, first_pass=first, threads=1,
                               **params).film)
    assert np.array_equal(merged.image(), on_cluster.image)
    assert np.array_equal(merged.image_variance(), on_cluster.variance)
    again = ps.render(scene, estimator, spp=10, seed=5, client=workers, task_passes=3, **params)
    assert np.array_equal(again.image, on_cluster.image)
    if params.get("pyramid"):
        for key, images in single.strategies.items():
            assert np.abs(images["weighted"] - on_cluster.strategies[key]["weighted"]).max() <= 1e-13


def test_one_task_of_all_passes_is_bit_for_bit_the_single_process_render(workers):
    """Merging one film into an empty one is exact."""
    scene = box()
    single = ps.render(scene, "pt", spp=6, seed=2)
    on_cluster = ps.render(scene, "pt", spp=6, seed=2, client=workers, task_passes=6)
    assert np.array_equal(single.image, on_cluster.image) and np.array_equal(single.variance, on_cluster.variance)


def kill_when_executing(client, prefix: str, kill: dict) -> threading.Thread:
    """A thread that SIGKILLs the worker running a task whose key starts with ``prefix`` as soon as one runs;
    it records the worker and the time in ``kill`` and gives up when ``kill`` gets "done"."""

    def executing(dask_worker):
        return os.getpid(), [str(ts.key) for ts in dask_worker.state.executing]

    def killer():
        while "done" not in kill:
            running = client.run(executing)
            busy = [address for address, (_, keys) in running.items() if any(k.startswith(prefix) for k in keys)]
            if busy:
                os.kill(running[busy[0]][0], signal.SIGKILL)
                kill.update(victim=busy[0], at=time.perf_counter())
                return
            time.sleep(0.01)

    thread = threading.Thread(target=killer, daemon=True)
    thread.start()
    return thread


def test_a_worker_killed_mid_render_loses_no_sample(workers):
    """SIGKILL a worker while it executes a task of the render: that task cannot have delivered its film,
    so the render completes only if Dask ran it again elsewhere; each task's film is merged once, and the
    image equals the single-process render."""
    scene = box((64, 64))
    kill = {}
    thread = kill_when_executing(workers, "pathspace-passes", kill)
    result = ps.render(scene, "bdpt", spp=24, seed=9, client=workers, task_passes=2)
    finished = time.perf_counter()
    kill["done"] = True
    thread.join()
    assert "at" in kill and kill["at"] < finished, kill
    assert result.stats["spp"] == 24 and result.stats["cluster"]["tasks"] == 12
    single = ps.render(scene, "bdpt", spp=24, seed=9)
    assert_same_to_rounding(single.film, result.film)


def lose_first_shipment(monkeypatch, client) -> list:
    """Make the cluster lose the first value a render or sweep ships: it goes to one worker alone (as if Dask's
    active memory manager had dropped the other copies), which is SIGKILLed before any task runs (its nanny
    starts a new one).  Returns the list of the values shipped."""
    shipped = []

    def getpid():
        return os.getpid()

    def ship(client, value):
        shipped.append(value)
        if len(shipped) > 1:
            return original(client, value)
        victim = sorted(client.nthreads())[0]
        future = client.scatter([value], workers=[victim], broadcast=False, hash=False)[0]
        os.kill(client.run(getpid)[victim], signal.SIGKILL)
        deadline = time.perf_counter() + 60
        while future.status != "cancelled" and time.perf_counter() < deadline:
            time.sleep(0.01)
        assert future.status == "cancelled"
        return future

    original = scenes.ship
    monkeypatch.setattr(scenes, "ship", ship)
    return shipped


def payloads(shipped: list) -> int:
    """How many of the values ``shipped`` were scenes."""
    return sum(isinstance(value, ScenePayload) for value in shipped)


def test_a_render_whose_scene_the_cluster_lost_ships_it_again(workers, monkeypatch):
    """Scattered data is not computed again: when every worker holding the scene has died, Dask forgets it
    and cancels the tasks that need it ("lost dependencies").  The render ships the scene again, once, and
    runs those tasks again: the image equals the single-process render."""
    scene = box((32, 32))
    shipped = lose_first_shipment(monkeypatch, workers)
    result = ps.render(scene, "bdpt", spp=8, seed=9, client=workers, task_passes=2)
    assert payloads(shipped) == 2 and result.stats["cluster"]["scene_reships"] == 1
    assert result.stats["spp"] == 8 and result.stats["cluster"]["tasks"] == 4
    assert_same_to_rounding(ps.render(scene, "bdpt", spp=8, seed=9).film, result.film)


def test_a_sweep_whose_scene_the_cluster_lost_ships_it_again(workers, monkeypatch):
    """The same for the tasks of a sweep: every cell renders, equal to the sweep in one process."""
    scene = box((16, 16))
    reference = ps.render(scene, "pt", spp=16, seed=1)
    shipped = lose_first_shipment(monkeypatch, workers)
    grid = {"rr": ["albedo", "off"]}
    remote = sweep(scene, "pt", grid, reference, spp=4, seeds=(0, 1), client=workers, cache=False)
    assert payloads(shipped) == 2
    assert remote.failed.empty and len(remote.table) == 4
    local = sweep(scene, "pt", grid, reference, spp=4, seeds=(0, 1))
    assert np.array_equal(local.table["mean"], remote.table["mean"])


def test_a_render_gives_up_on_a_cluster_that_keeps_losing_its_scene(workers, monkeypatch):
    """Every shipment lost: the render ships the scene RESHIPS times again, then stops with an error that
    says why."""
    shipped = []

    def lost(client, value):
        shipped.append(value)
        future = client.scatter([value], hash=False)[0]
        client.cancel([future])
        return future

    monkeypatch.setattr(scenes, "ship", lost)
    with pytest.raises(RuntimeError, match=r"lost the data shipped to it \(payload\) 4 times"):
        ps.render(box((16, 16)), "pt", spp=2, seed=1, client=workers, task_passes=1)
    assert scenes.RESHIPS == 3 and payloads(shipped) == 4


def test_a_sweep_finishes_around_a_failing_cell_and_resumes_from_its_cache(workers, tmp_path):
    """light_sampling='none' cannot reach a point light: that cell fails (on the worker) with the error, the
    other renders; run again, every finished render comes from the cache (the same seconds), only the
    failed cell is tried again."""
    scene = ps.scene_from_dict(scene_dict("cornell-box-point-light", (16, 16)))
    reference = ps.render(scene, "pt", spp=64, seed=1)
    grid = {"light_sampling": ["mis", "none", "nee"]}
    first = sweep(scene, "pt", grid, reference, spp=4, seeds=(0, 1), client=workers, cache=tmp_path)
    failed = first.failed
    assert list(failed["light_sampling"]) == ["none"] and "cannot reach point" in failed["error"].iloc[0]
    assert len(first.table) == 4 and set(first.table["light_sampling"]) == {"mis", "nee"}
    succeeded = first.cells.set_index("light_sampling")["error"].isna().to_dict()
    assert succeeded == {"mis": True, "none": False, "nee": True}
    assert len(list(tmp_path.glob("*.npz"))) == 4
    again = sweep(scene, "pt", grid, reference, spp=4, seeds=(0, 1), client=workers, cache=tmp_path)
    assert list(again.table["seconds"]) == list(first.table["seconds"])
    assert list(again.failed["light_sampling"]) == ["none"]   # tried again, and failed again
    local = sweep(scene, "pt", {"light_sampling": ["mis", "nee"]}, reference, spp=4, seeds=(0, 1))
    assert np.allclose(local.table["mean"], first.table["mean"], rtol=0, atol=0)


def test_a_sweep_on_the_cluster_equals_the_sweep_in_one_process(workers):
    scene = box((16, 16))
    reference = ps.render(scene, "pt", spp=64, seed=1)
    grid = {"rr": ["albedo", "off"]}
    local = sweep(scene, "pt", grid, reference, spp=4, seeds=(0, 1))
    remote = sweep(scene, "pt", grid, reference, spp=4, seeds=(0, 1), client=workers, cache=False)
    for column in ("mean", "relmse", "mse", "variance_per_sample"):
        assert np.array_equal(local.table[column], remote.table[column]), column
    assert list(local.cells["biased"]) == list(remote.cells["biased"])


def test_convergence_runs_on_the_cluster_equal_the_runs_in_one_process(workers):
    scene = box((16, 16))
    reference = ps.render(scene, "pt", spp=64, seed=1)
    local = converge(scene, ["pt", "lt"], reference, spp=8, checkpoints=[2, 4], seeds=(0, 1))
    remote = converge(scene, ["pt", "lt"], reference, spp=8, checkpoints=[2, 4], seeds=(0, 1), client=workers)
    columns = ["estimator", "seed", "spp", "relmse", "mse", "predicted_relmse"]
    assert local.table[columns].equals(remote.table[columns])


def test_a_scene_is_loaded_once_per_worker(workers):
    """Four renders and a sweep of the same scene (38 tasks): each worker unpickles it at most once."""
    scene = box((24, 24))   # a fingerprint no other test uses
    before = workers.run(scene_loads)
    for seed in range(4):
        ps.render(scene, "pt", spp=8, seed=seed, client=workers, task_passes=1)
    sweep(scene, "pt", {"rr": ["albedo"]}, np.zeros((24, 24, 3)), spp=2, seeds=(0, 1, 2, 3, 4, 5), client=workers,
          cache=False)
    after = workers.run(scene_loads)
    loads = {w: after[w] - before.get(w, 0) for w in after}
    assert set(loads.values()) <= {0, 1} and sum(loads.values()) >= 1, loads


def test_import_pathspace_does_not_import_dask():
    done = subprocess.run([sys.executable, "-c", "import sys, pathspace, pathspace.cluster; "
                           "print(sorted(m for m in ('dask', 'distributed', 'dask_jobqueue') if m in sys.modules))"],
                          capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]"


def test_what_a_cluster_render_refuses(workers):
    scene = box((8, 8))
    with pytest.raises(ValueError, match="time: a render on a cluster takes spp"):
        ps.render(scene, "pt", time=1.0, client=workers)
    with pytest.raises(ValueError, match="Markov chains"):
        ps.render(scene, "pssmlt", spp=1, client=workers)
    with pytest.raises(ValueError, match="task_passes: only for renders on a cluster"):
        ps.render(scene, "pt", spp=1, task_passes=2)
    with pytest.raises(ValueError, match="threads: a render on a cluster"):
        ps.render(scene, "pt", spp=1, threads=2, client=workers)
    with pytest.raises(ValueError, match="task_passes: expected"):
        ps.render(scene, "pt", spp=1, task_passes=0, client=workers)
    with pytest.raises(ValueError, match="workers: expected"):
        start_client(workers=0)
    with pytest.raises(ValueError, match="client: expected a dask.distributed.Client"):
        ps.render(scene, "pt", spp=1, client="tcp://127.0.0.1:8786")
    with pytest.raises(ValueError, match="seeds: expected distinct"):
        sweep(scene, "pt", {"rr": ["albedo"]}, np.zeros((8, 8, 3)), spp=1, seeds=(0, 0), client=workers)


def test_a_task_that_raises_stops_the_render_naming_its_passes(workers):
    scene = ps.scene_from_dict(scene_dict("cornell-box-point-light", (8, 8)))
    estimator = ps.estimators.make_estimator("pt", light_sampling="none")   # refused by check() on the worker
    from pathspace.cluster.render import render_on_cluster
    from pathspace.spectra import RGBMode

    with pytest.raises(ValueError, match="cannot reach point") as caught:
        render_on_cluster(workers, scene, estimator, RGBMode(), spp=4, seed=0, first_pass=0, spectral=None,
                          wavelength_sampling="uniform", task_passes=2)
    assert any("in the cluster task of passes" in note for note in caught.value.__notes__)
