"""Memory benchmark: peak resident memory of renders of the Cornell box, by estimator, resolution and spp.

Each configuration runs in a fresh Python process (so peaks do not mix); the
child reports its peak RSS (``VmHWM``; ``ru_maxrss`` off Linux), its RSS once the scene and its BVH
are ready (the baseline every render pays), the render time, and
:func:`pathspace.memory.estimate_render_memory`'s estimate.  Peaks that grow with
spp would mean something accumulates per pass; the peak above the baseline,
divided by the pixel count, is the per-pixel cost (film moments, the open pass,
the result images).

    python benchmarks/memory.py [--estimators pt,lt,bdpt] [--sizes 512,1024,2048] [--spp 4,16]
                                [--threads 2] [--option pyramid=2]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

CHILD = r"""
import json, resource, sys, time, tomllib
import psutil
import pathspace as ps
from pathspace.memory import estimate_render_memory

estimator, size, spp, threads, options = json.loads(sys.argv[1])
data = tomllib.loads(open(sys.argv[2]).read())
data["camera"]["resolution"] = [size, size]
scene = ps.scene_from_dict(data)
scene.accel
base = psutil.Process().memory_info().rss
start = time.perf_counter()
result = ps.render(scene, estimator, spp=spp, seed=0, threads=threads, **options)
seconds = time.perf_counter() - start
try:  # VmHWM: this process image's own peak (ru_maxrss keeps the peak of the parent that forked it)
    peak = next(int(line.split()[1]) * 1024 for line in open("/proc/self/status") if line.startswith("VmHWM:"))
except OSError:
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
estimate = estimate_render_memory(scene, ps.estimators.make_estimator(estimator, **options), result.film.covariance,
                                  threads)
print(json.dumps({"peak": peak, "base": base, "seconds": seconds, "estimate": estimate}))
"""


def measure(estimator: str, size: int, spp: int, threads: int, options: dict) -> dict:
    """Run one render in a child process and return its measurements."""
    out = subprocess.run([sys.executable, "-c", CHILD, json.dumps([estimator, size, spp, threads, options]),
                          str(ROOT / "scenes" / "cornell-box" / "scene.toml")], capture_output=True, text=True)
    if out.returncode:
        raise RuntimeError(f"{estimator} at {size}x{size}, {spp} spp failed:\n{out.stderr}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--estimators", default="pt,lt,bdpt")
    parser.add_argument("--sizes", default="512,1024,2048")
    parser.add_argument("--spp", default="4,16")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--option", action="append", default=[], help="an estimator parameter key=value (JSON value)")
    args = parser.parse_args()
    options = {key: json.loads(value) for key, value in (o.split("=", 1) for o in args.option)}
    mib = 1 << 20
    print(f"{'estimator':9} {'size':>5} {'spp':>4} {'peak MiB':>9} {'base MiB':>9} {'peak-base':>9} "
          f"{'B/pixel':>8} {'estimate MiB':>12} {'seconds':>8}")
    for estimator in args.estimators.split(","):
        for size in map(int, args.sizes.split(",")):
            for spp in map(int, args.spp.split(",")):
                m = measure(estimator, size, spp, args.threads, options)
                above = m["peak"] - m["base"]
                print(f"{estimator:9} {size:5d} {spp:4d} {m['peak'] / mib:9.0f} {m['base'] / mib:9.0f} "
                      f"{above / mib:9.0f} {above / size ** 2:8.0f} {m['estimate'] / mib:12.0f} "
                      f"{m['seconds']:8.1f}", flush=True)


if __name__ == "__main__":
    main()
