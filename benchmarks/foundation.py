"""Foundation benchmark: ray traversal and path tracing on the Cornell box, with ratios measured in one run.

1. Traversal: Accel.intersect / occluded against a plain C loop over the same
   Embree scene (robust build) and the same rays, one thread each.  The plain
   loop (plain_loop.c, compiled here with the system C compiler) calls
   rtcIntersect1/rtcOccluded1 per ray and, as a second baseline,
   rtcIntersect16/rtcOccluded16 on packets packed before its clock starts.
   Accel also runs on every core.
2. Path tracing at 256x256: pathspace's "pt" against Mitsuba 3's scalar_rgb
   path integrator (box filter, unbounded depth) on mitsuba.cornell_box() at
   the same spp, if Mitsuba is installed (pip install mitsuba); each renderer
   uses every core.

    python benchmarks/foundation.py [--rays 1000000] [--repeats 5] [--spp 64]
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


def traversal(scene, args) -> None:
    """Rays per second of Accel against the plain C loops."""
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


def mitsuba_samples_per_second(spp: int, repeats: int):
    """Samples per second and mean pixel value of Mitsuba 3 scalar_rgb on its Cornell box, or None."""
    try:
        import mitsuba as mi
    except ImportError:
        return None
    mi.set_variant("scalar_rgb")
    config = mi.cornell_box()
    config["sensor"]["film"]["rfilter"] = {"type": "box"}
    config["sensor"]["film"]["width"] = config["sensor"]["film"]["height"] = 256
    config["integrator"] = {"type": "path", "max_depth": -1}
    mscene = mi.load_dict(config)
    mi.render(mscene, spp=1)
    best, image = np.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        image = np.array(mi.render(mscene, spp=spp))
        best = min(best, time.perf_counter() - t0)
    return 256 * 256 * spp / best, image.mean(axis=(0, 1)), mi.__version__


def path_tracing(scene, args) -> None:
    """Samples per second of pathspace's path tracer, beside Mitsuba 3's."""
    ps.render(scene, spp=1, seed=0)
    best, result = np.inf, None
    for repeat in range(args.pt_repeats):
        result = ps.render(scene, spp=args.spp, seed=repeat)
        best = min(best, result.stats["seconds"])
    ours = 256 * 256 * args.spp / best
    print(f"path tracing, Cornell box 256x256, {args.spp} spp, best of {args.pt_repeats}:")
    print(f"  pathspace pt      {ours / 1e6:6.3f} M samples/s  (mean pixel {np.round(result.image.mean(axis=(0, 1)), 4)})")
    theirs = mitsuba_samples_per_second(args.spp, args.pt_repeats)
    if theirs is None:
        print("  Mitsuba 3 not installed (pip install mitsuba): no comparison")
        return
    rate, mean, version = theirs
    print(f"  Mitsuba {version} scalar_rgb {rate / 1e6:6.3f} M samples/s  (mean pixel {np.round(mean, 4)})")
    print(f"  ratio pathspace / Mitsuba: {ours / rate:.2f}")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rays", type=int, default=1_000_000, help="rays per traversal query")
    parser.add_argument("--repeats", type=int, default=5, help="repeats of each traversal timing (best is kept)")
    parser.add_argument("--spp", type=int, default=64, help="samples per pixel of the path-tracing renders")
    parser.add_argument("--pt-repeats", type=int, default=3, help="repeats of each render (best is kept)")
    args = parser.parse_args(argv)
    scene = ps.load_scene(ROOT / "scenes" / "cornell-box" / "scene.toml")
    traversal(scene, args)
    path_tracing(scene, args)


if __name__ == "__main__":
    sys.exit(main())
