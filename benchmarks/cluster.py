"""Distributed benchmark: scaling over single-threaded Dask workers on this machine, and the cost of a task.

The clusters run without Dask's dashboard unless ``--dashboard`` (its monitoring shares the cores).

1. **Scaling**: samples per second of one render on a LocalCluster of N single-threaded worker
   processes over that of a cluster of one (goal: >= 0.9 N), for pt, lt and bdpt, with the render's
   wall time (first submission to last merge) as the clock; the in-process render on one thread is
   printed beside it as the baseline of the same run, and the machine's own limit: N plain processes
   rendering single-threaded side by side (no Dask), their summed rate over one's.
2. **Overhead per task**: on one worker, renders cut into tasks of decreasing size; the overhead of a
   task is (wall time - the tasks' own render seconds) / tasks -- scheduling, moving the task and its
   film, developing the film on the worker and merging it on the client -- and the task size (seconds,
   and samples at the measured rate) below which it exceeds 5% of a task is overhead / 0.05.
   Each line also gives the most finished tasks whose films waited on the workers for their turn
   (``tasks_waiting_peak``); the client holds one task film at a time.

    python benchmarks/cluster.py [--workers 2] [--spp 64] [--size 256] [--repeats 3]
"""
from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
from pathlib import Path

import pathspace as ps
from pathspace.cluster import start_client

ROOT = Path(__file__).resolve().parent.parent
ESTIMATORS = ("pt", "lt", "bdpt")


def spread(values: list[float]) -> str:
    return f"{min(values):.3g} / {statistics.median(values):.3g} / {max(values):.3g}"


def rate(result) -> float:
    return result.stats["samples"] / result.stats["seconds"]


def warm(client, scene, estimator: str) -> None:
    """Every worker has the scene and its BVH, and has run the estimator once."""
    ps.render(scene, estimator, spp=len(client.nthreads()), seed=0, client=client, task_passes=1)


def plain_processes(count: int, estimator: str, args) -> float:
    """Samples per second of ``count`` plain processes rendering single-threaded side by side, summed."""
    script = ("import sys, pathspace as ps; s = ps.load_scene(sys.argv[1], resolution=(int(sys.argv[2]),) * 2); "
              "ps.render(s, sys.argv[3], spp=1, threads=1); "
              "print(ps.render(s, sys.argv[3], spp=int(sys.argv[4]), threads=1).stats['samples_per_second'])")
    scene = ROOT / "scenes" / "cornell-box" / "scene.toml"
    runs = [subprocess.Popen([sys.executable, "-c", script, str(scene), str(args.size), estimator, str(args.spp // 2)],
                             stdout=subprocess.PIPE, text=True) for _ in range(count)]
    return sum(float(run.communicate()[0]) for run in runs)


def scaling(scene, args) -> None:
    print(f"\n1. Scaling: samples/s of {args.workers} single-threaded workers over one worker "
          f"(min / median / max of {args.repeats}; goal >= {0.9 * args.workers:.2f})")
    rates: dict = {}
    for workers in (1, args.workers):
        with start_client(workers=workers, dashboard=args.dashboard) as client:
            for estimator in ESTIMATORS:
                warm(client, scene, estimator)
                for repeat in range(args.repeats):
                    result = ps.render(scene, estimator, spp=args.spp, seed=repeat + 1, client=client)
                    rates.setdefault((estimator, workers), []).append(rate(result))
    for estimator in ESTIMATORS:
        ps.render(scene, estimator, spp=1, seed=0, threads=1)
        local = [rate(ps.render(scene, estimator, spp=args.spp, seed=r + 1, threads=1)) for r in range(args.repeats)]
        ratios = [many / one for one, many in zip(rates[(estimator, 1)], rates[(estimator, args.workers)])]
        millions = {key: spread([r / 1e6 for r in values]) for key, values in rates.items()}
        plain = [plain_processes(args.workers, estimator, args) / plain_processes(1, estimator, args)
                 for _ in range(args.repeats)]
        print(f"  {estimator:5s} {spread(ratios)}   (M samples/s: in-process 1 thread "
              f"{spread([r / 1e6 for r in local])}, 1 worker {millions[(estimator, 1)]}, {args.workers} workers "
              f"{millions[(estimator, args.workers)]}; {args.workers} plain processes / 1: {spread(plain)})")


def overhead(scene, args) -> None:
    print("\n2. Overhead per task on one worker (pt): wall time not spent rendering, per task")
    with start_client(workers=1, dashboard=args.dashboard) as client:
        warm(client, scene, "pt")
        per_task = []
        for task_passes in (8, 4, 2, 1):
            result = ps.render(scene, "pt", spp=args.spp, seed=1, client=client, task_passes=task_passes)
            cluster = result.stats["cluster"]
            cost = (result.stats["seconds"] - cluster["task_seconds"]) / cluster["tasks"]
            task = cluster["task_seconds"] / cluster["tasks"]
            per_task.append(cost)
            print(f"  {task_passes} passes per task ({cluster['tasks']} tasks of {task * 1e3:.0f} ms): overhead "
                  f"{cost * 1e3:.1f} ms per task ({100 * cost / (task + cost):.1f}% of the wall time); at most "
                  f"{cluster['tasks_waiting_peak']} finished tasks waited for their turn")
        cost = statistics.median(per_task)
        seconds = cost / 0.05
        samples = seconds * rate(ps.render(scene, "pt", spp=args.spp, seed=1, threads=1))
        print(f"  median overhead {cost * 1e3:.1f} ms: tasks shorter than {seconds:.2f} s "
              f"(~{samples / 1e6:.2f} M samples of pt here) spend more than 5% on it")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=ps.default_thread_count())
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--only", default="scaling,overhead")
    parser.add_argument("--dashboard", action="store_true", help="serve Dask's dashboard (costs ~5%% on 2 cores)")
    args = parser.parse_args(argv)
    scene = ps.load_scene(ROOT / "scenes" / "cornell-box" / "scene.toml", resolution=(args.size, args.size))
    print(f"Cornell box {args.size}x{args.size}, {args.spp} spp per render; Dask dashboard "
          f"{'on' if args.dashboard else 'off'}")
    if "scaling" in args.only:
        scaling(scene, args)
    if "overhead" in args.only:
        overhead(scene, args)


if __name__ == "__main__":
    main()
