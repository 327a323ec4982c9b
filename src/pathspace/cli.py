"""Command line: ``pathspace render | compare | info | reference | converge``.

    pathspace render scenes/cornell-box/scene.toml --spp 64 -o cornell.exr
    pathspace render SCENE --time 30 -p max_depth=8 -p rr=off --set camera.fov=30 -o out.exr
    pathspace compare test.exr reference.exr [--json]
    pathspace info SCENE [--estimator pt]
    pathspace reference SCENE [-e pt] [--spp 4096] [-o ref.exr]
    pathspace converge SCENE -e pt,lt,bdpt --time 60 --reference REF.exr [--seeds 3] [-o table.csv]

``-p KEY=VALUE`` sets an estimator parameter (``render --help`` lists them
all), ``--set KEY=VALUE`` changes the scene (``materials.white.reflectance=[0.5,0.5,0.5]``,
``camera.resolution=[128,128]``; see :mod:`pathspace.scene.overrides`).
Values are TOML values: numbers, true/false, "strings", [lists].
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from . import __version__, metrics
from .contact_sheet import strategy_layers, write_contact_sheet
from .driver import render
from .estimators import ESTIMATORS, make_estimator
from .experiment.specs import EstimatorSpec, parse_assignment
from .imageio import read_exr, write_exr, write_png
from .scene import SceneError, load_scene

__all__ = ["main"]


def _assignment(text: str) -> tuple[str, object]:
    try:
        key, value = parse_assignment(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None
    return key, value


def _param(text: str) -> tuple[str, object]:
    """An estimator parameter ``key=value`` (dashes in the key read as underscores)."""
    key, value = _assignment(text)
    return key.replace("-", "_"), value


def _writable(path: Path) -> Path:
    """``path``, after making sure a file can be written there (before an hour of rendering, not after)."""
    folder = path.parent if str(path.parent) else Path(".")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        probe = folder / f".{path.name}.probe"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as error:
        raise ValueError(f"cannot write {path}: {error.strerror or error}") from None
    return path


def _parameter_help() -> str:
    lines = ["estimator parameters (-p KEY=VALUE):"]
    for name, cls in ESTIMATORS.items():
        lines.append(f"  {name}:")
        lines += [f"    {key} (default {default!r}): {meaning}" for key, default, meaning in cls.parameters()]
    return "\n".join(lines)


def _scene_arguments(command: argparse.ArgumentParser) -> None:
    command.add_argument("scene", help="scene file (.toml)")
    command.add_argument("--set", dest="overrides", action="append", type=_assignment, default=[],
                         metavar="KEY=VALUE", help="change the scene, repeatable (e.g. --set camera.fov=30)")


def _build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="pathspace", description="Light-transport research renderer.")
    parser.add_argument("--version", action="version", version=f"pathspace {__version__}")
    commands = parser.add_subparsers(dest="command", required=True)

    r = commands.add_parser("render", help="render a scene to EXR (and a PNG beside it)", epilog=_parameter_help(),
                            formatter_class=argparse.RawDescriptionHelpFormatter)
    _scene_arguments(r)
    r.add_argument("--estimator", "-e", default="pt", choices=sorted(ESTIMATORS), help="estimator (default: pt)")
    budget = r.add_mutually_exclusive_group()
    budget.add_argument("--spp", type=int, help="samples per pixel (default: the scene's [render] spp, else 16)")
    budget.add_argument("--time", type=float, help="time budget in seconds instead of --spp")
    r.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    r.add_argument("--threads", type=int, default=None, help="worker threads (default: all cores)")
    r.add_argument("-p", "--param", action="append", type=_param, default=[], metavar="KEY=VALUE",
                   help="estimator parameter, repeatable (e.g. -p max_depth=5 -p rr=off); listed below")
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
    _scene_arguments(i)
    i.add_argument("--estimator", "-e", default="pt", choices=sorted(ESTIMATORS))
    i.add_argument("-p", "--param", action="append", type=_param, default=[], metavar="KEY=VALUE")

    f = commands.add_parser("reference", help="render (or reuse from the cache) a high-quality reference")
    _scene_arguments(f)
    f.add_argument("--estimator", "-e", default="pt", choices=sorted(ESTIMATORS))
    f.add_argument("--spp", type=int, default=4096, help="samples per pixel (default 4096)")
    f.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    f.add_argument("-p", "--param", action="append", type=_param, default=[], metavar="KEY=VALUE")
    f.add_argument("--cache", default=None, help="cache folder (default $PATHSPACE_CACHE/references)")
    f.add_argument("--force", action="store_true", help="render even if a cached reference matches")
    f.add_argument("-o", "--output", default=None, help="also copy the reference to this EXR")
    f.add_argument("--quiet", "-q", action="store_true", help="no progress bar")

    v = commands.add_parser("converge", help="error against render time of several estimators, from one run each")
    _scene_arguments(v)
    v.add_argument("--estimator", "-e", action="append", required=True,
                   help="estimators: comma-separated names (pt,lt,bdpt), or one 'name:key=value,...'; repeatable")
    run = v.add_mutually_exclusive_group(required=True)
    run.add_argument("--time", type=float, help="seconds per run")
    run.add_argument("--spp", type=int, help="samples per pixel per run")
    v.add_argument("--reference", required=True, help="reference EXR (e.g. from pathspace reference)")
    v.add_argument("--seeds", type=int, default=1, help="independent runs per estimator (default 1)")
    v.add_argument("--checkpoints", default=None, help="comma-separated seconds or spp (default: log-spaced)")
    v.add_argument("--metric", default="relmse", choices=sorted(metrics.METRICS), help="metric to plot and fit")
    v.add_argument("-o", "--output", default="convergence.csv", help="CSV table (the plot goes beside it, .png)")
    v.add_argument("--threads", type=int, default=None)
    return parser


def _load(args):
    return load_scene(args.scene, **dict(args.overrides))


def _render(args) -> int:
    out = Path(args.output)
    if out.suffix.lower() != ".exr":
        out = out.with_suffix(".exr")
    _writable(out)
    scene = _load(args)
    result = render(scene, args.estimator, spp=args.spp, time=args.time, seed=args.seed, threads=args.threads,
                    progress=not args.quiet, spectral=args.spectral, wavelength_sampling=args.wavelengths,
                    **dict(args.param))
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
    for line in result.stats["warnings"]:
        print(f"warning: {line}")
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
    scene = _load(args)
    print(scene.describe())
    reasons = scene.spectral_reasons()
    print(f"colour: {'spectral (' + '; '.join(reasons) + ')' if reasons else 'rgb (every colour is RGB)'}")
    estimator = make_estimator(args.estimator, **dict(args.param))
    for line in estimator.plan(scene):
        print(f"plan: {line}")
    for line in estimator.warnings(scene):
        print(f"warning: {line}")
    return 0


def _reference(args) -> int:
    from .reference import reference

    result = reference(_load(args), args.estimator, spp=args.spp, seed=args.seed, folder=args.cache, force=args.force,
                       progress=not args.quiet, **dict(args.param))
    print(result.summary())
    print(f"cached at {result.path}")
    if args.output:
        write_exr(args.output, result.image, result.variance, {"reference": json.dumps(result.metadata, default=str)})
        print(f"wrote {args.output}")
    return 0


def _converge(args) -> int:
    from .experiment import converge
    from .plot import convergence_plot

    specs = []
    for value in args.estimator:
        specs += [value] if ":" in value else [name.strip() for name in value.split(",") if name.strip()]
    checkpoints = [float(x) for x in args.checkpoints.split(",")] if args.checkpoints else None
    out = _writable(Path(args.output))
    reference, _, _ = read_exr(args.reference)
    result = converge(_load(args), [EstimatorSpec.parse(s) for s in specs], reference, time=args.time, spp=args.spp,
                      checkpoints=checkpoints, seeds=range(args.seeds), threads=args.threads)
    result.to_csv(out)
    axes = convergence_plot(result, args.metric)
    axes.figure.savefig(out.with_suffix(".png"), dpi=150, bbox_inches="tight")
    print(result.summary(args.metric).to_string())
    print(f"render time only (scene loading, BVH builds and snapshots excluded); wrote {out}, {out.with_suffix('.png')}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``pathspace`` command."""
    args = _build_parser().parse_args(argv)
    commands = {"render": _render, "compare": _compare, "info": _info, "reference": _reference, "converge": _converge}
    try:
        return commands[args.command](args)
    except (SceneError, ValueError, FileNotFoundError, ImportError) as error:
        print(f"pathspace {args.command}: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
