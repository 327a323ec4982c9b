"""Speed benchmark: every figure of the speed goals, measured in one run (min / median / max over repeats).

Per scene (the diffuse Cornell box and its glass-and-mirror variant, 256x256):
1. a path-traced reference of ``--reference-spp`` (cached by :func:`pathspace.reference`); its own
   expected relMSE is subtracted from every relMSE below;
2. for each repeat, interleaved: pt, lt and bdpt for ``--time`` seconds each on every core, and Mitsuba 3
   (``llvm_ad_rgb`` with its JIT warm, or ``scalar_rgb`` where the LLVM variant cannot run -- it needs
   libLLVM, e.g. the ``libllvm19`` system package; the variant used is printed) on the same scene, exported
   with :func:`pathspace.scene.mitsuba_export.mitsuba_dict`, at the spp that takes about as long;
   time to relMSE ``--target`` = seconds x relMSE / target (relMSE falls as 1 / time), and the ratios
   within the repeat: pt / Mitsuba, bdpt / pt, lt / pt; and pt again with ``[render] traversal = "fast"``
   (Embree without its robust mode, as Mitsuba builds it: see :class:`pathspace.accel.Accel`), against
   Mitsuba (skip it with ``--no-fast``)
   (goals: pt <= 1.0x Mitsuba on the diffuse box and <= 1.5x on the specular one; bdpt <= 1.3x pt on
   the diffuse box and <= 0.3x on the specular one; lt <= 1.5x pt on the diffuse box).
On the diffuse box:
3. thread scaling: samples per second on every core over one thread, per estimator (goal >= 1.85 on
   2 cores), beside the machine's ceiling for it: as many one-thread renders as cores, in processes of
   their own, at once, over one alone (no GIL between them; on a machine whose cores slow each other
   down, this is below the core count);
4. where the time goes, one thread: the share of the render's CPU time spent in ray queries
   (``Accel.intersect`` / ``occluded`` / ``occluded_between``: Embree, the C packing of rays into its
   packets and the shadow rays built in C; goal >= 40% for pt), and the largest NumPy costs (cProfile of
   the worker thread, a separate render: profiling slows Python calls, so its shares are of the profiled
   time);
5. peak memory above the loaded scene at two resolutions (each render in a child process, see
   ``memory.py``), split into a constant part (the wavefront and the BVH's scratch) and bytes per pixel.

    python benchmarks/speed.py [--time 10] [--repeats 3] [--reference-spp 2048] [--scenes cornell-box,...]
"""
from __future__ import annotations

import argparse
import cProfile
import pstats
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

import pathspace as ps
from pathspace.accel import Accel

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from bdpt import reference_floor, rel_mse  # noqa: E402  (benchmarks are scripts: shared relMSE helpers)
from memory import measure as measure_memory  # noqa: E402

ROOT = HERE.parent
ESTIMATORS = ("pt", "lt", "bdpt")
TARGET = 1e-3


def spread(values: list[float]) -> str:
    """min / median / max of ``values``."""
    return f"{min(values):.2f} / {statistics.median(values):.2f} / {max(values):.2f}"


class Mitsuba:
    """Mitsuba 3's path tracer on a pathspace scene: ``llvm_ad_rgb`` if it renders here, else ``scalar_rgb``."""

    def __init__(self, scene: ps.Scene, folder: Path) -> None:
        import mitsuba as mi

        from pathspace.scene.mitsuba_export import mitsuba_dict

        self.mi = mi
        for variant in ("llvm_ad_rgb", "scalar_rgb"):
            try:
                mi.set_variant(variant)
                config = mitsuba_dict(scene, folder / variant)
                config["integrator"] = {"type": "path", "max_depth": -1}
                self.scene = mi.load_dict(config)
                mi.render(self.scene, spp=1)
                self.variant = variant
                break
            except Exception as error:  # the LLVM variant raises when libLLVM is missing or unusable
                print(f"  Mitsuba {variant} unavailable: {error}")
        else:
            raise RuntimeError("no Mitsuba variant renders here")
        self.spp = 0

    def calibrate(self, seconds: float) -> None:
        """Choose the spp of a render of about ``seconds`` and warm the JIT at that spp."""
        self.spp = 16
        rate = self.spp / self.render(seed=0)[1]  # Dr.Jit is lazy: render() converts, so it is evaluated
        self.spp = max(1, int(rate * seconds))
        self.render(seed=0)

    def render(self, seed: int) -> tuple[np.ndarray, float]:
        """Image (H, W, 3) and seconds of one render at the calibrated spp."""
        start = time.perf_counter()
        image = np.array(self.mi.render(self.scene, spp=self.spp, seed=seed), dtype=np.float64)[..., :3]
        return image, time.perf_counter() - start


def time_to_target(scene_name: str, args) -> None:
    """Figures 1 and 2 for one scene."""
    scene = ps.load_scene(ROOT / "scenes" / scene_name / "scene.toml")
    reference = ps.reference(scene, spp=args.reference_spp, threads=args.threads)
    print(f"\n{scene_name}: reference pt {args.reference_spp} spp ({'cached' if reference.cached else 'rendered'})")
    for estimator in ESTIMATORS:
        ps.render(scene, estimator, spp=1, seed=0, threads=args.threads)
    mitsuba = None
    try:
        mitsuba = Mitsuba(scene, Path(tempfile.mkdtemp()))
        mitsuba.calibrate(args.time)
        print(f"  Mitsuba {mitsuba.mi.__version__} {mitsuba.variant}: {mitsuba.spp} spp per render")
    except ImportError:
        print("  Mitsuba 3 not installed (pip install mitsuba): its column is left out")
    runs = [(estimator, estimator, scene) for estimator in ESTIMATORS]
    if args.fast:
        fast = ps.load_scene(ROOT / "scenes" / scene_name / "scene.toml", **{"render.traversal": "fast"})
        runs.append(("pt-fast", "pt", fast))
        ps.render(runs[-1][2], "pt", spp=1, seed=0, threads=args.threads)
    ratios: dict[str, list[float]] = {"pt / mitsuba": [], "pt-fast / mitsuba": [], "bdpt / pt": [], "lt / pt": []}
    for repeat in range(args.repeats):
        seconds = {}
        for name, estimator, rendered in runs:
            result = ps.render(rendered, estimator, time=args.time, seed=100 + repeat, threads=args.threads)
            stats, error = result.stats, rel_mse(result, reference)
            seconds[name] = stats["seconds"] * error / TARGET
            print(f"  run {repeat + 1} {name:7s}: {stats['spp']:5d} spp in {stats['seconds']:5.1f} s, "
                  f"relMSE {error:.3e} -> {seconds[name]:7.1f} s to {TARGET:g}")
        if mitsuba is not None:
            image, took = mitsuba.render(seed=100 + repeat)
            error = ps.metrics.relmse(image, reference.image) - reference_floor(reference)
            seconds["mitsuba"] = took * error / TARGET
            print(f"  run {repeat + 1} mitsuba: {mitsuba.spp:5d} spp in {took:5.1f} s, relMSE {error:.3e} -> "
                  f"{seconds['mitsuba']:7.1f} s to {TARGET:g}")
            ratios["pt / mitsuba"].append(seconds["pt"] / seconds["mitsuba"])
            if args.fast:
                ratios["pt-fast / mitsuba"].append(seconds["pt-fast"] / seconds["mitsuba"])
        ratios["bdpt / pt"].append(seconds["bdpt"] / seconds["pt"])
        ratios["lt / pt"].append(seconds["lt"] / seconds["pt"])
    for name, values in ratios.items():
        if values:
            print(f"  time to relMSE {TARGET:g}, {name}: {spread(values)} (min / median / max)")


# A one-thread render in a process of its own, for the machine's ceiling of thread scaling: once the scene and
# its BVH are built and a warm-up pass is rendered, it says "ready" and waits for a line on stdin before it
# renders, so that the renders of several such processes run at the same time; then it prints samples/s.
SOLO = """
import sys
import pathspace as ps
scene, estimator, spp, seed = ps.load_scene(sys.argv[1]), sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
ps.render(scene, estimator, spp=1, seed=0, threads=1)
print("ready", flush=True)
sys.stdin.readline()
print(ps.render(scene, estimator, spp=spp, seed=seed, threads=1).stats["samples_per_second"], flush=True)
"""


def solo_rates(scene_file: Path, estimator: str, spp: int, seed: int, processes: int) -> list[float]:
    """Samples per second of ``processes`` one-thread renders run at once, each in a process of its own (all set
    up and warmed up before any starts)."""
    runs = [subprocess.Popen([sys.executable, "-c", SOLO, str(scene_file), estimator, str(spp), str(seed + k)],
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True) for k in range(processes)]
    for run in runs:
        if run.stdout.readline().strip() != "ready":
            raise RuntimeError(f"a one-thread render of {estimator} failed before it started (exit code "
                               f"{run.wait()})")
    for run in runs:
        run.stdin.write("go\n")
        run.stdin.flush()
    rates = []
    for run in runs:
        out, _ = run.communicate()
        if run.returncode != 0:
            raise RuntimeError(f"a one-thread render of {estimator} failed (exit code {run.returncode})")
        rates.append(float(out))
    return rates


def thread_scaling(scene_file: Path, args) -> None:
    """Figure 3: samples per second on every core over one thread; and the machine's ceiling for it: as many
    one-thread renders as cores, each in its own process (no GIL, nothing shared but the machine), at once,
    over one such render alone."""
    scene = ps.load_scene(scene_file)
    cores = args.threads or ps.default_thread_count()
    print(f"\nThread scaling on {cores} cores ({scene.camera.pixel_count} pixels, {args.scaling_spp} spp), and "
          f"{cores} one-thread processes at once over one alone (the machine's ceiling):")
    for estimator in ESTIMATORS:
        ps.render(scene, estimator, spp=1, seed=0, threads=cores)
        factors, ceilings = [], []
        for repeat in range(args.repeats):
            rate = {}
            for threads in (1, cores):
                result = ps.render(scene, estimator, spp=args.scaling_spp, seed=repeat, threads=threads)
                rate[threads] = result.stats["samples_per_second"]
            factors.append(rate[cores] / rate[1])
            alone = solo_rates(scene_file, estimator, args.scaling_spp, repeat, 1)[0]
            ceilings.append(sum(solo_rates(scene_file, estimator, args.scaling_spp, repeat, cores)) / alone)
        print(f"  {estimator:4s}: threads {spread(factors)}, processes {spread(ceilings)} (last run "
              f"{rate[1] / 1e3:.0f} k -> {rate[cores] / 1e3:.0f} k samples/s)")


class QueryClock:
    """Wall seconds spent in Accel's queries (intersect, occluded, occluded_between) while installed (renders on
    one thread)."""

    METHODS = ("intersect", "occluded", "occluded_between")

    def __init__(self) -> None:
        self.seconds = 0.0
        self.lock = threading.Lock()
        self.saved = [getattr(Accel, name) for name in self.METHODS]

    def __enter__(self) -> "QueryClock":
        def timed(method):
            def call(accel, *args, **kwargs):
                start = time.perf_counter()
                try:
                    return method(accel, *args, **kwargs)
                finally:
                    with self.lock:
                        self.seconds += time.perf_counter() - start
            return call
        for name, method in zip(self.METHODS, self.saved):
            setattr(Accel, name, timed(method))
        return self

    def __exit__(self, *exc) -> None:
        for name, method in zip(self.METHODS, self.saved):
            setattr(Accel, name, method)


def numpy_costs(scene: ps.Scene, estimator: str, spp: int, top: int = 5) -> list[tuple[str, float]]:
    """The ``top`` NumPy functions by own time in a one-thread render, as shares of the profiled time."""
    cls = type(ps.estimators.make_estimator(estimator))
    original = cls.render_items
    profiles: list[cProfile.Profile] = []

    def render_items(self, *args, **kwargs):
        profile = cProfile.Profile()
        profiles.append(profile)
        profile.enable()
        try:
            yield from original(self, *args, **kwargs)
        finally:
            profile.disable()

    cls.render_items = render_items
    try:
        ps.render(scene, estimator, spp=spp, seed=0, threads=1)
    finally:
        cls.render_items = original
    stats = pstats.Stats(profiles[0])
    total = sum(entry[2] for entry in stats.stats.values())
    numpy_rows = [(name, entry[2]) for (filename, _, name), entry in stats.stats.items()
                  if "numpy" in filename or "numpy" in name]
    numpy_rows.sort(key=lambda row: -row[1])
    return [(name, seconds / total) for name, seconds in numpy_rows[:top]]


def time_shares(scene: ps.Scene, args) -> None:
    """Figure 4: ray-query share of the CPU time and the top NumPy costs, per estimator, one thread."""
    print(f"\nWhere the time goes (one thread, {args.scaling_spp} spp):")
    for estimator in ESTIMATORS:
        shares = []
        for repeat in range(args.repeats):
            with QueryClock() as clock:
                cpu = time.process_time()
                ps.render(scene, estimator, spp=args.scaling_spp, seed=repeat, threads=1)
                cpu = time.process_time() - cpu
            shares.append(100 * clock.seconds / cpu)
        costs = ", ".join(f"{name} {share:.0%}" for name, share in numpy_costs(scene, estimator, args.scaling_spp))
        print(f"  {estimator:4s}: ray queries {spread(shares)} % of CPU time; top NumPy: {costs}")


def memory(args) -> None:
    """Figure 5: peak memory above the loaded scene at two resolutions, per estimator."""
    sizes = (256, 1024)
    print(f"\nPeak memory above the loaded scene ({args.threads or ps.default_thread_count()} threads, 4 spp):")
    for estimator in ESTIMATORS:
        peaks = [measure_memory(estimator, size, 4, args.threads or ps.default_thread_count(), {})
                 for size in sizes]
        above = [(p["peak"] - p["base"]) / 2 ** 20 for p in peaks]
        per_pixel = (above[1] - above[0]) * 2 ** 20 / (sizes[1] ** 2 - sizes[0] ** 2)
        constant = above[0] - per_pixel * sizes[0] ** 2 / 2 ** 20
        print(f"  {estimator:4s}: {above[0]:6.0f} MiB at {sizes[0]}^2, {above[1]:6.0f} MiB at {sizes[1]}^2 "
              f"= {constant:5.0f} MiB + {per_pixel:5.0f} bytes per pixel")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--time", type=float, default=10.0, help="seconds per render for time to error")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--reference-spp", type=int, default=2048)
    parser.add_argument("--scaling-spp", type=int, default=16)
    parser.add_argument("--scenes", default="cornell-box,cornell-box-specular")
    parser.add_argument("--threads", type=int, default=None)
    parser.add_argument("--no-fast", dest="fast", action="store_false",
                        help="leave out pt with the fast (non-watertight) traversal")
    parser.add_argument("--only", default="target,scaling,shares,memory",
                        help="which parts to run (comma-separated)")
    args = parser.parse_args(argv)
    parts = set(args.only.split(","))
    if "target" in parts:
        for name in args.scenes.split(","):
            time_to_target(name, args)
    box_file = ROOT / "scenes" / "cornell-box" / "scene.toml"
    box = ps.load_scene(box_file)
    if "scaling" in parts:
        thread_scaling(box_file, args)
    if "shares" in parts:
        time_shares(box, args)
    if "memory" in parts:
        memory(args)


if __name__ == "__main__":
    main()
