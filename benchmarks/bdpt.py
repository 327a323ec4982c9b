"""Bidirectional benchmark: BDPT and light tracing against path tracing, in time to a given error.

Measured in one run (the machine is shared; only ratios within a run mean much), per scene
(the diffuse Cornell box and its glass-and-mirror variant, 256x256):
1. a high-spp path-traced reference;
2. for pt, lt and bdpt: samples per second, and relMSE = mean((x - r)^2 / (r^2 + 0.01)) against
   the reference at a few spp, corrected for the reference's own noise (its variance term is
   subtracted); relMSE falls as 1 / time, so the time to reach relMSE 1e-2 is
   seconds x relMSE / 1e-2 (the fit over the spp levels is printed);
3. the ratio of each estimator's time-to-error to the path tracer's
   (targets: BDPT within 2x of pt on the diffuse box, better than pt on the glass box);
4. the MIS kernel alone: path pairs (connections) per second on one core for typical lengths
   (target: at least 1M per second).

    python benchmarks/bdpt.py [--reference-spp 1024] [--scenes cornell-box,cornell-box-specular]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import pathspace as ps
from pathspace.mis import Connections, SubpathPdfs, mis_weights
from pathspace.metrics import RELMSE_EPSILON, relmse

ROOT = Path(__file__).resolve().parent.parent
TARGET = 1e-2
SPP = {"pt": (16, 64), "lt": (16, 64), "bdpt": (4, 16)}


def reference_floor(reference) -> float:
    """The reference's own expected contribution to relMSE (its variance over the relMSE denominator)."""
    return float(np.mean(reference.variance / (reference.image ** 2 + RELMSE_EPSILON)))


def rel_mse(result, reference) -> float:
    """relMSE against the reference, minus the reference's own expected contribution."""
    return relmse(result.image, reference.image) - reference_floor(reference)


def mis_kernel_rate(connections: int = 1_000_000, length: int = 5) -> float:
    """Connections per second of the C MIS kernel on random paths of ``length`` segments."""
    rng = np.random.default_rng(0)
    lanes = connections // length
    per = length + 1
    offset = np.arange(lanes + 1) * per
    sub = lambda: SubpathPdfs(offset, 10 ** rng.uniform(-3, 3, lanes * per), 10 ** rng.uniform(-3, 3, lanes * per),
                              np.zeros(lanes * per, bool))  # noqa: E731
    light, eye = sub(), sub()
    s = rng.integers(0, per + 1, connections).astype(np.int32)
    c = Connections(s, (per - s).astype(np.int32), rng.integers(0, lanes, connections),
                    *(10 ** rng.uniform(-3, 3, connections) for _ in range(6)))
    flags = np.zeros(connections, np.uint8)
    t0 = time.perf_counter()
    mis_weights(c, light, eye, flags, False)
    return connections / (time.perf_counter() - t0)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--reference-spp", type=int, default=1024)
    parser.add_argument("--scenes", default="cornell-box,cornell-box-specular")
    parser.add_argument("--threads", type=int, default=None)
    args = parser.parse_args(argv)

    print(f"MIS kernel: {mis_kernel_rate() / 1e6:.2f} M connections/s on one core (5-segment paths; target >= 1)")
    for name in args.scenes.split(","):
        scene = ps.load_scene(ROOT / "scenes" / name / "scene.toml")
        for estimator in SPP:
            ps.render(scene, estimator, spp=1, seed=0, threads=args.threads)
        t0 = time.perf_counter()
        reference = ps.render(scene, "pt", spp=args.reference_spp, seed=1000, threads=args.threads)
        floor = reference_floor(reference)
        print(f"\n{name}: reference pt {args.reference_spp} spp in {time.perf_counter() - t0:.0f} s "
              f"(its own relMSE {floor:.2e}, subtracted)")
        times = {}
        for estimator, levels in SPP.items():
            rows = []
            for spp in levels:
                result = ps.render(scene, estimator, spp=spp, seed=1, threads=args.threads)
                seconds = result.stats["seconds"]
                error = rel_mse(result, reference)
                rows.append((spp, seconds, error, seconds * error / TARGET, result.stats["samples_per_second"]))
            for spp, seconds, error, to_target, rate in rows:
                print(f"  {estimator:4s} {spp:4d} spp: {seconds:6.2f} s, {rate / 1e6:.3f} M samples/s, "
                      f"relMSE {error:.3e} -> {to_target:7.1f} s to relMSE {TARGET:g}")
            times[estimator] = rows[-1][3]
        for estimator in ("lt", "bdpt"):
            print(f"  time to relMSE {TARGET:g}: {estimator} / pt = {times[estimator] / times['pt']:.2f}")


if __name__ == "__main__":
    main()
