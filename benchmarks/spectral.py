"""Spectral benchmark: cost of spectral against RGB path tracing, and of the colour conversions.

Measured in one run on the Cornell box at 256x256:
1. samples per second of "pt" in RGB and in spectral mode (4 hero wavelengths, XYZ film), and
   their ratio (target: spectral at most 1.5x the RGB cost per sample);
2. converting a megapixel XYZ image to 8-bit sRGB: pathspace's matrix path (colour-science's
   XYZ-to-sRGB matrix, then its sRGB transfer function) against colour.XYZ_to_sRGB
   (target: under 0.1 s);
3. if Mitsuba 3 is installed, its scalar_spectral path tracer on the same box, for the mean
   pixel value and the speed.

    python benchmarks/spectral.py [--spp 64] [--repeats 3]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

import pathspace as ps
from pathspace import spectra
from pathspace.imageio import to_srgb8

ROOT = Path(__file__).resolve().parent.parent


def best(repeats: int, fn):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)

    scene = ps.load_scene(ROOT / "scenes" / "cornell-box" / "scene.toml")
    ps.render(scene, spp=1)
    ps.render(scene, spp=1, spectral=True)
    rates = {}
    for mode in (False, True):
        seconds, result = best(args.repeats, lambda: ps.render(scene, spp=args.spp, seed=1, spectral=mode))
        rates[mode] = 256 * 256 * args.spp / result.stats["seconds"]
        print(f"pt {'spectral' if mode else 'rgb':8s}: {rates[mode] / 1e6:6.3f} M samples/s, "
              f"mean pixel {np.round(result.image.mean(axis=(0, 1)), 4)}")
    print(f"spectral cost per sample: {rates[False] / rates[True]:.2f}x the RGB cost (target <= 1.5)")

    film = ps.Film(1000, 1000, covariance=True)
    film.add_tile(0, np.random.default_rng(0).random((3, 1000 * 1000)))
    film.add_tile(0, np.random.default_rng(1).random((3, 1000 * 1000)))
    matrix = spectra.xyz_to_srgb_matrix()
    linear, image = best(args.repeats, lambda: film.mean(matrix))
    variance, _ = best(args.repeats, lambda: film.variance(matrix))
    encoded, _ = best(args.repeats, lambda: to_srgb8(image))
    from pathspace._colour import colour

    theirs, _ = best(1, lambda: colour.XYZ_to_sRGB(film.mean()))
    print(f"megapixel XYZ film -> linear sRGB: {linear:.3f} s (matrix; its variance through the XYZ covariances: "
          f"{variance:.3f} s); -> 8-bit sRGB PNG pixels: +{encoded:.3f} s; colour.XYZ_to_sRGB: {theirs:.3f} s "
          f"(target: under 0.1 s)")

    try:
        import mitsuba as mi
    except ImportError:
        print("Mitsuba 3 not installed (pip install mitsuba): no spectral comparison")
        return
    mi.set_variant("scalar_spectral")
    config = mi.cornell_box()
    config["sensor"]["film"]["rfilter"] = {"type": "box"}
    config["integrator"] = {"type": "path", "max_depth": -1}
    mscene = mi.load_dict(config)
    mi.render(mscene, spp=1)
    seconds, image = best(args.repeats, lambda: np.array(mi.render(mscene, spp=args.spp)))
    print(f"Mitsuba {mi.__version__} scalar_spectral: {256 * 256 * args.spp / seconds / 1e6:6.3f} M samples/s, "
          f"mean pixel {np.round(image.mean(axis=(0, 1)), 4)} (its RGB uplifting is Jakob-Hanika's, ours "
          f"Mallett-Yuksel's: expect differences of about a percent)")


if __name__ == "__main__":
    sys.exit(main())
