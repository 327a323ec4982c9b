"""Film benchmark: what accumulating moments costs in a render, measured in one run.

1. A 256x256 Cornell-box path-traced render: the CPU time spent in the film
   (``add_samples`` / ``add_splats``, which commit passes into the moments;
   the main thread runs them) as a share of the render's CPU time over all
   threads (target: under 3%).
2. Committing one 256x256 pass into the film's moments (scaled Welford/Chan
   updates, non-finite check and pass statistics included) against the
   one-pass sums of samples and squares they replace (the naive baseline,
   which overflows from about 1e154), as a ratio of CPU times.

CPU times (``time.thread_time`` / ``process_time``), not wall time: on a
shared machine a process that is preempted in the middle of a step would
charge the wait to whatever it was doing.

    python benchmarks/film.py [--spp 32] [--repeats 50]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import pathspace as ps
from pathspace.film import Film

ROOT = Path(__file__).resolve().parent.parent


def film_share(spp: int) -> tuple[float, float]:
    """(render CPU seconds over all threads, CPU seconds inside the film's add methods) of a 256x256
    Cornell-box pt render."""
    spent = [0.0]
    originals = {name: getattr(Film, name) for name in ("add_samples", "add_splats")}

    def timed(method):
        def wrapper(self, *args, **kwargs):
            start = time.thread_time()
            try:
                return method(self, *args, **kwargs)
            finally:
                spent[0] += time.thread_time() - start
        return wrapper

    scene = ps.load_scene(ROOT / "scenes" / "cornell-box" / "scene.toml")
    ps.render(scene, "pt", spp=2, seed=0)  # warm up (BVH, allocator)
    try:
        for name, method in originals.items():
            setattr(Film, name, timed(method))
        start = time.process_time()
        ps.render(scene, "pt", spp=spp, seed=0)
        cpu = time.process_time() - start
    finally:
        for name, method in originals.items():
            setattr(Film, name, method)
    return cpu, spent[0]


def commit_ratio(repeats: int, pixels: int = 256 * 256) -> tuple[float, float]:
    """(CPU seconds per pass committed by the film, per pass of naive sums of samples and squares)."""
    rng = np.random.default_rng(0)
    passes = rng.exponential(1.0, size=(8, 3, pixels))
    film = Film(pixels, 1)
    total, total_sq = np.zeros((3, pixels)), np.zeros((3, pixels))
    film_seconds = naive_seconds = 0.0
    for k in range(repeats):
        values = passes[k % len(passes)]
        start = time.thread_time()
        film.add_samples(k, 0, values)
        film_seconds += time.thread_time() - start
        start = time.thread_time()
        finite = np.isfinite(values).all(axis=0)
        if finite.all():
            total += values
            total_sq += values * values
        naive_seconds += time.thread_time() - start
    return film_seconds / repeats, naive_seconds / repeats


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--spp", type=int, default=32)
    parser.add_argument("--repeats", type=int, default=50)
    args = parser.parse_args()
    seconds, in_film = film_share(args.spp)
    print(f"pt 256x256, {args.spp} spp: {seconds:.2f} CPU s, film {in_film * 1e3:.1f} ms = {in_film / seconds:.2%} "
          f"of the render ({in_film / args.spp * 1e3:.2f} ms per pass)")
    film_pass, naive_pass = commit_ratio(args.repeats)
    print(f"one 256x256 pass: film {film_pass * 1e3:.2f} ms, naive sums {naive_pass * 1e3:.2f} ms "
          f"(ratio {film_pass / naive_pass:.1f})")


if __name__ == "__main__":
    main()
