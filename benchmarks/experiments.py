"""Experiment-layer benchmark: what progressive snapshots cost, measured in one run.

For PT, LT and BDPT on the Cornell box (128x128 unless given), the same spp
is rendered (a) in one go and (b) through ``pathspace.experiment.converge``
with log-spaced checkpoints, each developed and scored against a reference;
reported per estimator: render seconds of both (the clock pauses at
checkpoints), their ratio (target: the checkpoints slow the render itself by
under 5%), and the wall seconds the snapshots add (developing the film and
computing the metrics, outside the render clock).  Repeats interleave (a)
and (b) and the medians are compared: the machine is shared and noisy.

    python benchmarks/experiments.py [--spp 64] [--resolution 128] [--repeats 3]
"""
from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import pathspace as ps
from pathspace.experiment import converge

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--resolution", type=int, default=128)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    scene = ps.load_scene(ROOT / "scenes" / "cornell-box" / "scene.toml", resolution=(args.resolution,) * 2)
    reference = ps.render(scene, "pt", spp=4 * args.spp, seed=99)
    print(f"Cornell box {args.resolution}x{args.resolution}, {args.spp} spp, median of {args.repeats}")
    print(f"{'estimator':10s} {'plain s':>9s} {'with checkpoints s':>19s} {'ratio':>7s} {'snapshot wall s':>16s}")
    for estimator in ("pt", "lt", "bdpt"):
        plain, stepped, overhead = [], [], []
        for repeat in range(args.repeats):
            plain.append(ps.render(scene, estimator, spp=args.spp, seed=repeat).stats["seconds"])
            start = time.perf_counter()
            study = converge(scene, [estimator], reference, spp=args.spp, seeds=(repeat,))
            wall = time.perf_counter() - start
            final = study.table[study.table["final"]]
            stepped.append(float(final["seconds"].iloc[0]))
            overhead.append(wall - stepped[-1])
        a, b = statistics.median(plain), statistics.median(stepped)
        print(f"{estimator:10s} {a:9.3f} {b:19.3f} {b / a:7.3f} {statistics.median(overhead):16.3f}")


if __name__ == "__main__":
    main()
