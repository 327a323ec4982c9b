"""Traversal benchmark: Accel.intersect / occluded against a plain C loop over Embree.

Both sides trace the same rays through the same Embree scene (robust build of
the Cornell box) on one thread; the plain loop (plain_loop.c, compiled here
with the system C compiler) calls rtcIntersect1 per ray, and, as a second
baseline, rtcIntersect16 on packets packed before the clock starts.  Accel
also runs on every core.  Ratios are measured in the same run.

    python benchmarks/traversal.py [--rays 1000000] [--repeats 5]
"""
from __future__ import annotations

import argparse
import ctypes
import os
import subprocess
import sys
import sysconfig
import tempfile
import time
from pathlib import Path

import numpy as np

import pathspace as ps
from pathspace.accel import embree_library_path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent


def build_plain_loop() -> ctypes.CDLL:
    """Compile plain_loop.c into a temporary shared library and load it."""
    out = Path(tempfile.mkdtemp()) / "plain_loop.so"
    cc = os.environ.get("CC") or sysconfig.get_config_var("CC").split()[0] or "cc"
    subprocess.run([cc, "-O3", "-shared", "-fPIC", "-std=c11", "-D_GNU_SOURCE", f"-I{ROOT / 'ext'}",
                    str(HERE / "plain_loop.c"), "-o", str(out), "-ldl"], check=True)
    lib = ctypes.CDLL(str(out))
    lib.plain_loop.restype = ctypes.c_double
    lib.plain_loop.argtypes = [ctypes.c_char_p, ctypes.c_void_p, ctypes.c_long, ctypes.c_void_p, ctypes.c_long,
                               ctypes.c_void_p, ctypes.c_long, ctypes.c_int, ctypes.c_int, ctypes.c_int,
                               ctypes.POINTER(ctypes.c_long)]
    return lib


def cornell_rays(scene, n: int, seed: int = 1):
    """Half camera rays (coherent), half random interior rays (incoherent, like bounces); and shadow segments."""
    rng = np.random.default_rng(seed)
    half = n // 2
    pixels = rng.integers(0, scene.camera.pixel_count, half)
    o_cam, d_cam = scene.camera.generate_rays(pixels, rng.random((2, half)))
    o_in = rng.uniform(-0.99, 0.99, (3, n - half)).astype(np.float32)
    d_in = rng.normal(size=(3, n - half)).astype(np.float32)
    d_in /= np.linalg.norm(d_in, axis=0)
    origins = np.ascontiguousarray(np.concatenate([np.asarray(o_cam), o_in], axis=1))
    directions = np.ascontiguousarray(np.concatenate([d_cam, d_in], axis=1))
    a = rng.uniform(-0.99, 0.99, (3, n)).astype(np.float32)
    b = rng.uniform(-0.99, 0.99, (3, n)).astype(np.float32)
    return origins, directions, a, b - a


def best_of(repeats: int, fn) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rays", type=int, default=1_000_000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)

    scene = ps.load_scene(ROOT / "scenes" / "cornell-box" / "scene.toml")
    accel = scene.accel
    vertices = np.ascontiguousarray(scene.mesh.vertices, dtype=np.float32)
    indices = scene.mesh.indices
    origins, directions, seg_o, seg_d = cornell_rays(scene, args.rays)
    lib = build_plain_loop()
    cores = ps.default_thread_count()
    print(f"{args.rays} rays, Cornell box ({scene.mesh.triangle_count} triangles), best of {args.repeats}; "
          f"{cores} cores")

    for query, (o, d, tmax) in (("intersect", (origins, directions, np.inf)), ("occluded", (seg_o, seg_d, 1.0))):
        packed = np.empty((args.rays, 8), dtype=np.float32)
        packed[:, 0:3], packed[:, 3], packed[:, 4:7], packed[:, 7] = o.T, 0.0, d.T, tmax
        hits = ctypes.c_long()
        base = {}
        for width in (1, 16):
            base[width] = lib.plain_loop(embree_library_path().encode(), vertices.ctypes.data, len(vertices),
                                         indices.ctypes.data, len(indices), packed.ctypes.data, args.rays,
                                         int(query == "occluded"), args.repeats, width, ctypes.byref(hits))
        run = getattr(accel, query)
        one = best_of(args.repeats, lambda: run(o, d, 0.0, tmax, threads=1))
        every = best_of(args.repeats, lambda: run(o, d, 0.0, tmax, threads=cores))
        mrays = lambda seconds: args.rays / seconds / 1e6
        print(f"{query:9s}: plain C rtc{query.capitalize()[:9]}1 loop {mrays(base[1]):6.2f} Mrays/s | "
              f"plain C 16-wide pre-packed {mrays(base[16]):6.2f} | Accel 1 thread {mrays(one):6.2f} "
              f"({one and base[1] / one:.2f}x the rtc*1 loop, {base[16] / one:.2f}x the pre-packed loop) | "
              f"Accel {cores} threads {mrays(every):6.2f}")


if __name__ == "__main__":
    sys.exit(main())
