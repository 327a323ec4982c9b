"""Command line: ``pathspace render | compare | info | reference | converge | export | cluster``.

    pathspace render scenes/cornell-box/scene.toml --spp 64 -o cornell.exr
    pathspace render SCENE --time 30 -p max_depth=8 -p rr=off --set camera.fov=30 -o out.exr
    pathspace render SCENE --spp 4096 -o out.exr --save-every 60    # Ctrl-C, then the same with --resume
    pathspace compare test.exr reference.exr [--json]
    pathspace info SCENE [--estimator pt]
    pathspace reference SCENE [-e pt] [--spp 4096] [-o ref.exr]
    pathspace converge SCENE -e pt,lt,bdpt --time 60 --reference REF.exr [--seeds 3] [-o table.csv]
    pathspace export --mitsuba SCENE OUT.xml        # Mitsuba 3 scene XML, meshes in OUT-meshes/
    pathspace render SCENE --spp 1024 --workers 2   # on a local Dask cluster (render, reference, converge)
    pathspace render SCENE --spp 1024 --scheduler tcp://host:8786   # on a running Dask cluster
    pathspace cluster slurm --jobs 10 --cores 16 --memory 64GB --walltime 02:00:00   # workers on a batch queue

``-p KEY=VALUE`` sets an estimator parameter (``render --help`` lists them
all), ``--set KEY=VALUE`` changes the scene (``materials.white.reflectance=[0.5,0.5,0.5]``,
``camera.resolution=[128,128]``; see :mod:`pathspace.scene.overrides`).
Values are TOML values: numbers, true/false, "strings", [lists].

Output paths are checked before anything is rendered.  ``render`` saves its
state to ``OUT.exr.state`` every ``--save-every`` seconds and when stopped by
Ctrl-C (SIGINT) or SIGTERM -- then it writes the image of the completed
passes, says how to resume, and exits with 130 or 143 -- and ``--resume``
continues from it (see :mod:`pathspace.resume`); a render on a cluster
(``--workers``, ``--scheduler``; see :mod:`pathspace.cluster`) keeps no
state.  Errors are one line on stderr and exit code 2.
"""
from __future__ import annotations

import argparse
import json
import math
import shlex
import signal
import sys
import time
import warnings
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from . import __version__, metrics
from .cluster.client import JOBQUEUE_KINDS
from .contact_sheet import strategy_layers, write_contact_sheet
from .driver import RenderResult, can_save_state, render
from .estimators import ESTIMATORS, Estimator, make_estimator
from .experiment.specs import EstimatorSpec, parse_assignment
from .imageio import atomic_output, read_exr, write_exr, write_png
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


def _seconds(text: str) -> float:
    """A number of seconds >= 0 (for --save-every)."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value >= 0.0):
        raise argparse.ArgumentTypeError(f"expected a number of seconds >= 0, got {text!r}")
    return value


def _writable(path: Path) -> Path:
    """``path``, after making sure a file can be written there (before an hour of rendering, not after)."""
    folder = path.parent if str(path.parent) else Path(".")
    if path.is_dir():
        raise ValueError(f"cannot write {path}: it is a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        probe = folder / f".{path.name}.probe"
        probe.write_bytes(b"")
        probe.unlink()
    except (FileExistsError, NotADirectoryError):
        raise ValueError(f"cannot write {path}: its folder {folder} cannot be created (a file is in the way)") from None
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
    command.add_argument("scene", help="scene file (.toml, or Mitsuba scene .xml)")
    command.add_argument("--set", dest="overrides", action="append", type=_assignment, default=[],
                         metavar="KEY=VALUE", help="change the scene, repeatable (e.g. --set camera.fov=30)")


def _cluster_arguments(command: argparse.ArgumentParser) -> None:
    where = command.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=None, metavar="N",
                       help="render on a local Dask cluster of N single-threaded worker processes (the dask extra)")
    where.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="render on the Dask cluster of this scheduler (tcp://host:8786)")


@contextmanager
def _cluster_client(args):
    """The Dask client that --workers or --scheduler asks for (None without them), closed at the end."""
    if args.workers is None and args.scheduler is None:
        yield None
        return
    from .cluster import start_client

    if getattr(args, "threads", None) is not None:
        raise ValueError("--threads: a render on a cluster runs single-threaded tasks; choose --workers instead")
    client = start_client(workers=args.workers, scheduler=args.scheduler)
    print(f"Dask cluster: {client.scheduler.address}, {sum(client.nthreads().values())} worker threads; "
          f"dashboard {client.dashboard_link}")
    try:
        yield client
    finally:
        client.close()


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
    r.add_argument("--save-every", type=_seconds, default=60.0, metavar="SECONDS",
                   help="save the render's state to OUT.exr.state this often (default 60; 0: only when stopped by "
                        "Ctrl-C or SIGTERM); the file is removed once the image is written")
    _cluster_arguments(r)
    r.add_argument("--task-passes", type=int, default=None, metavar="N",
                   help="passes per cluster task (default: about eight tasks per worker)")
    r.add_argument("--resume", action="store_true",
                   help="continue the render saved in OUT.exr.state (same scene, estimator, parameters, seed, budget "
                        "and colour mode); without a state file, start from the beginning")

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
    _cluster_arguments(f)

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
    _cluster_arguments(v)

    x = commands.add_parser("export", help="write a scene for another renderer (Mitsuba 3: scene XML, PLY meshes)")
    target = x.add_mutually_exclusive_group(required=True)
    target.add_argument("--mitsuba", action="store_true", help="Mitsuba 3 scene XML; meshes go to OUT-meshes/ beside it")
    _scene_arguments(x)
    x.add_argument("output", help="output file (OUT.xml)")

    q = commands.add_parser("cluster", help="start Dask workers on a batch queue (dask-jobqueue) and wait")
    q.add_argument("kind", choices=sorted(JOBQUEUE_KINDS), help="the batch system")
    q.add_argument("--jobs", type=int, default=1, help="jobs to submit (default 1)")
    q.add_argument("--cores", type=int, required=True, help="cores per job (one worker process each)")
    q.add_argument("--memory", required=True, help="memory per job, e.g. 64GB")
    q.add_argument("--walltime", default="01:00:00", help="time limit per job (default 01:00:00)")
    q.add_argument("--queue", default=None, help="queue or partition")
    q.add_argument("--account", default=None, help="account (SLURM, PBS) or project (SGE, LSF) to charge")
    q.add_argument("--dry-run", action="store_true", help="print the job script and stop (submits nothing)")
    return parser


def _load(args):
    return load_scene(args.scene, **dict(args.overrides))


def _estimator(args) -> Estimator:
    """The estimator of ``-e`` and ``-p``: unknown keys and bad values fail before the scene is loaded."""
    return make_estimator(args.estimator, **dict(args.param))


def _write_render(out: Path, result: RenderResult, args) -> list[str]:
    """Write the EXR, and unless --no-png the PNG and (bidirectional pyramids) the contact sheets; the
    paths written."""
    metadata = {k: v for k, v in result.stats.items() if k != "plan"}
    layers = strategy_layers(result.strategies) if result.strategies else None
    variance = None if np.isnan(result.variance).all() else result.variance   # unknown for Markov chains
    write_exr(out, result.image, variance, metadata, xyz=result.xyz if args.xyz else None, layers=layers)
    written = [str(out)]
    if not args.no_png:
        png = out.with_suffix(".png")
        write_png(png, result.image, exposure=args.exposure)
        written.append(str(png))
        for kind in ("weighted", "unweighted") if result.strategies else ():
            sheet = out.with_name(f"{out.stem}.strategies-{kind}.png")
            write_contact_sheet(sheet, result.strategies, kind, exposure=args.exposure)
            written.append(str(sheet))
    return written


def _render(args) -> int:
    out = Path(args.output)
    if out.suffix.lower() != ".exr":
        out = out.with_suffix(".exr")
    _writable(out)
    estimator = _estimator(args)
    state = out.with_name(out.name + ".state") if can_save_state(estimator) else None
    if state is None and args.resume:
        raise ValueError(f"--resume: estimator {estimator.name!r} renders with its own loop (Markov chains): its "
                         "renders cannot be saved and resumed")
    on_cluster = args.workers is not None or args.scheduler is not None
    if on_cluster:
        if args.resume:
            raise ValueError("--resume: a render on a cluster keeps no state file")
        if args.time is not None:
            raise ValueError("--time: a render on a cluster takes --spp (its tasks are pass ranges)")
        state = None
        if args.task_passes is not None and args.task_passes < 1:
            raise ValueError(f"--task-passes: expected an integer >= 1, got {args.task_passes}")
    elif args.task_passes is not None:
        raise ValueError("--task-passes: only for renders on a cluster (--workers or --scheduler)")
    scene = _load(args)
    if args.resume and not state.exists():
        print(f"no saved state at {state}: starting from the beginning")
    with _cluster_client(args) as client:
        options = (dict(client=client, task_passes=args.task_passes) if on_cluster else
                   dict(threads=args.threads, state_file=state, save_every=(args.save_every or None) if state else None,
                        resume=args.resume, keep_state=state is not None, stop_on_signal=True))
        result = render(scene, estimator, spp=args.spp, time=args.time, seed=args.seed, progress=not args.quiet,
                        spectral=args.spectral, wavelength_sampling=args.wavelengths, **options)
    stats = result.stats
    written = _write_render(out, result, args) if stats["spp"] or not stats["stopped"] else []
    print(f"colour: {stats['mode']} ({stats['mode_reason']})")
    for line in stats["plan"]:
        print(f"plan: {line}")
    for line in stats["warnings"]:
        print(f"warning: {line}")
    print(result.summary())
    if stats["stopped"]:
        target = stats["budget"]
        budget = f"{stats['spp']} of {target['spp']} spp" if target["spp"] is not None else (
            f"{stats['spp']} spp in {stats['seconds']:.1f} of {target['time']:g} s")
        saved = f"wrote {', '.join(written)} ({stats['spp']} spp)" if written else "no pass was complete, no image"
        if state is None:
            print(f"stopped by {stats['stopped']} after {budget}: {saved} (this estimator cannot be resumed)")
            return 128 + signal.Signals[stats["stopped"]].value
        command = shlex.join(["pathspace", *args.argv] + ([] if args.resume else ["--resume"]))
        print(f"stopped by {stats['stopped']} after {budget}: {saved}; the render's state is in {state}\n"
              f"continue it with: {command}")
        return 128 + signal.Signals[stats["stopped"]].value
    if state is not None:
        state.unlink(missing_ok=True)
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
    estimator = _estimator(args)
    scene = _load(args)
    print(scene.describe())
    reasons = scene.spectral_reasons()
    print(f"colour: {'spectral (' + '; '.join(reasons) + ')' if reasons else 'rgb (every colour is RGB)'}")
    for line in estimator.plan(scene):
        print(f"plan: {line}")
    for line in estimator.warnings(scene):
        print(f"warning: {line}")
    return 0


def _reference(args) -> int:
    from .reference import cache_folder, reference

    _writable(Path(args.cache or cache_folder()) / "reference.exr")
    if args.output:
        _writable(Path(args.output))
    _estimator(args)
    with _cluster_client(args) as client:
        result = reference(_load(args), args.estimator, spp=args.spp, seed=args.seed, folder=args.cache,
                           force=args.force, progress=not args.quiet, client=client, **dict(args.param))
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
    specs = [EstimatorSpec.parse(s) for s in specs]
    for spec in specs:
        spec.make()  # unknown estimators, keys and bad values fail before anything is loaded
    reference, _, _ = read_exr(args.reference)
    with _cluster_client(args) as client:
        result = converge(_load(args), specs, reference, time=args.time, spp=args.spp, checkpoints=checkpoints,
                          seeds=range(args.seeds), **(dict(client=client) if client else dict(threads=args.threads)))
    with atomic_output(out) as temporary:
        result.to_csv(temporary)
    axes = convergence_plot(result, args.metric)
    with atomic_output(out.with_suffix(".png")) as temporary:
        axes.figure.savefig(temporary, format="png", dpi=150, bbox_inches="tight")
    print(result.summary(args.metric).to_string())
    print(f"render time only (scene loading, BVH builds and snapshots excluded); wrote {out}, {out.with_suffix('.png')}")
    return 0


def _export(args) -> int:
    from .scene.mitsuba_export import export_mitsuba

    out = _writable(Path(args.output))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        written = export_mitsuba(_load(args), out)
    for warning in caught:
        print(f"warning: {warning.message}")
    print(f"wrote {written[0]} and {len(written) - 1} PLY meshes in {out.parent / (out.stem + '-meshes')}")
    return 0


def _cluster(args) -> int:
    from .cluster.client import jobqueue_cluster

    if args.jobs < 1 or args.cores < 1:
        raise ValueError(f"--jobs and --cores: expected integers >= 1, got {args.jobs} and {args.cores}")
    cluster = jobqueue_cluster(args.kind, cores=args.cores, memory=args.memory, walltime=args.walltime,
                               queue=args.queue, account=args.account)
    try:
        if args.dry_run:
            print(cluster.job_script())
            return 0
        cluster.scale(jobs=args.jobs)
        print(f"Dask scheduler {cluster.scheduler_address}; dashboard {cluster.dashboard_link}\n"
              f"{args.jobs} job(s) of {args.cores} single-threaded workers submitted; render on them with\n"
              f"  pathspace render SCENE --scheduler {cluster.scheduler_address} ...\n"
              "or ps.render(..., client=Client(address)); Ctrl-C stops the cluster and its jobs")
        while True:
            time.sleep(3600)
    finally:
        cluster.close()


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``pathspace`` command: the exit code (0; 2 for an error, reported in one line
    on stderr; 130 or 143 for a render stopped by SIGINT or SIGTERM)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    args = _build_parser().parse_args(argv)
    args.argv = argv
    commands = {"render": _render, "compare": _compare, "info": _info, "reference": _reference, "converge": _converge,
                "export": _export, "cluster": _cluster}
    try:
        return commands[args.command](args)
    except (SceneError, ValueError, OSError, ImportError) as error:
        print(f"pathspace {args.command}: error: {error}", file=sys.stderr)
        return 2
    except MemoryError as error:
        print(f"pathspace {args.command}: error: {str(error) or 'out of memory'}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"pathspace {args.command}: interrupted", file=sys.stderr)
        return 128 + signal.SIGINT
    except Exception as error:  # the Dask cluster's own failures (a worker killed too often, a lost scheduler)
        if type(error).__module__.split(".")[0] != "distributed":
            raise
        print(f"pathspace {args.command}: error: on the Dask cluster: {type(error).__name__}: {error}",
              file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
