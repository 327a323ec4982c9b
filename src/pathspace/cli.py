"""Command line: ``pathspace render``, ``pathspace compare``, ``pathspace info``.

    pathspace render scenes/cornell-box/scene.toml --spp 64 -o cornell.exr
    pathspace render SCENE --time 30 -p max_depth=8 -p rr=off -o out.exr
    pathspace compare test.exr reference.exr [--json]
    pathspace info SCENE [--estimator pt]
"""
from __future__ import annotations

import argparse
import json
import sys
import tomllib
from pathlib import Path

from . import metrics
from .contact_sheet import strategy_layers, write_contact_sheet
from .driver import render
from .imageio import read_exr, write_exr, write_png
from .estimators import ESTIMATORS, make_estimator
from .scene import SceneError, load_scene

__all__ = ["main"]


def _parse_param(text: str) -> tuple[str, object]:
    """``key=value`` with value read as a TOML value (number, bool, string...) or else a bare string."""
    key, sep, value = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"expected key=value, got {text!r}")
    try:
        parsed = tomllib.loads(f"v = {value}")["v"]
    except tomllib.TOMLDecodeError:
        parsed = value
    return key.strip().replace("-", "_"), parsed


def _build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="pathspace", description="Light-transport research renderer.")
    commands = parser.add_subparsers(dest="command", required=True)

    r = commands.add_parser("render", help="render a scene to EXR (and a PNG beside it)")
    r.add_argument("scene", help="scene file (.toml)")
    r.add_argument("--estimator", "-e", default="pt", choices=sorted(ESTIMATORS), help="estimator (default: pt)")
    budget = r.add_mutually_exclusive_group()
    budget.add_argument("--spp", type=int, help="samples per pixel (default 16)")
    budget.add_argument("--time", type=float, help="time budget in seconds instead of --spp")
    r.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    r.add_argument("--threads", type=int, default=None, help="worker threads (default: all cores)")
    r.add_argument("-p", "--param", action="append", type=_parse_param, default=[], metavar="KEY=VALUE",
                   help="estimator parameter, repeatable (e.g. -p max_depth=5 -p rr=off)")
    colour = r.add_mutually_exclusive_group()
    colour.add_argument("--spectral", dest="spectral", action="store_true", default=None,
                        help="render spectrally (default: when the scene has spectra or dispersion)")
    colour.add_argument("--rgb", dest="spectral", action="store_false", help="render in RGB")
    r.add_argument("--wavelengths", default="uniform", choices=("uniform", "visible"),
                   help="wavelength sampling of spectral renders (default uniform)")
    r.add_argument("--xyz", action="store_true", help="also write CIE XYZ (spectral renders) as an EXR layer")
    r.add_argument("-o", "--output", default="render.exr", help="output EXR path (default render.exr)")
    r.add_argument("--exposure", type=float, default=0.0, help="PNG exposure in stops (default 0)")
    r.add_argument("--no-png", action="store_true", help="do not write the PNG")
    r.add_argument("--quiet", "-q", action="store_true", help="no progress bar")

    c = commands.add_parser("compare", help="error metrics of a test image against a reference")
    c.add_argument("test", help="test EXR")
    c.add_argument("reference", help="reference EXR")
    c.add_argument("--json", action="store_true", help="print JSON")

    i = commands.add_parser("info", help="describe a scene and what an estimator would do with it")
    i.add_argument("scene")
    i.add_argument("--estimator", "-e", default="pt", choices=sorted(ESTIMATORS))
    i.add_argument("-p", "--param", action="append", type=_parse_param, default=[], metavar="KEY=VALUE")
    return parser


def _render(args) -> int:
    scene = load_scene(args.scene)
    params = dict(args.param)
    result = render(scene, args.estimator, spp=args.spp, time=args.time, seed=args.seed, threads=args.threads,
                    progress=not args.quiet, spectral=args.spectral, wavelength_sampling=args.wavelengths, **params)
    out = Path(args.output)
    if out.suffix.lower() != ".exr":
        out = out.with_suffix(".exr")
    metadata = {k: v for k, v in result.stats.items() if k != "plan"}
    layers = strategy_layers(result.strategies) if result.strategies else None
    write_exr(out, result.image, result.variance, metadata, xyz=result.xyz if args.xyz else None, layers=layers)
    written = [str(out)]
    if not args.no_png:
        png = out.with_suffix(".png")
        write_png(png, result.image, exposure=args.exposure)
        written.append(str(png))
        for kind in ("weighted", "unweighted") if result.strategies else ():
            sheet = out.with_name(f"{out.stem}.strategies-{kind}.png")
            write_contact_sheet(sheet, result.strategies, kind, exposure=args.exposure)
            written.append(str(sheet))
    print(f"colour: {result.stats['mode']} ({result.stats['mode_reason']})")
    for line in result.stats["plan"]:
        print(f"plan: {line}")
    print(result.summary())
    print("wrote " + ", ".join(written))
    return 0


def _compare(args) -> int:
    test, _, _ = read_exr(args.test)
    reference, _, _ = read_exr(args.reference)
    values = metrics.compare(test, reference)
    if args.json:
        print(json.dumps(values))
    else:
        for name, value in values.items():
            print(f"{name:7s} {value:.6g}")
    return 0


def _info(args) -> int:
    scene = load_scene(args.scene)
    print(scene.describe())
    reasons = scene.spectral_reasons()
    print(f"colour: {'spectral (' + '; '.join(reasons) + ')' if reasons else 'rgb (every colour is RGB)'}")
    for line in make_estimator(args.estimator, **dict(args.param)).plan(scene):
        print(f"plan: {line}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``pathspace`` command."""
    args = _build_parser().parse_args(argv)
    try:
        return {"render": _render, "compare": _compare, "info": _info}[args.command](args)
    except (SceneError, ValueError, FileNotFoundError) as error:
        print(f"pathspace {args.command}: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
