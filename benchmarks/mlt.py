"""Metropolis benchmark: time to a relMSE target for PT, BDPT, PSSMLT (over PT and BDPT), MMLT and path-space MLT.

Measured in one run (the machine is shared; only ratios within a run mean much), per scene (the caustic
glass sphere with its lamp and with a nine times smaller one, the pool's caustics seen through its rippled
water and the ajar door, all 128x128; every estimator at the same ``max_depth``):
1. a BDPT reference rendered for ``--reference-time`` seconds;
2. for every estimator, renders of ``--time`` / 4 and ``--time`` seconds: relMSE against the reference
   (minus the reference's own expected contribution), and the time to reach ``--target`` extrapolated
   from the longer render as seconds x relMSE / target (relMSE falls as 1 / time for every estimator
   here once its chains have spread; the two budgets show how far that holds);
3. the ratio of each estimator's time to the target to BDPT's (target: the best MLT variant below 1 on
   the caustic scenes with a small lamp (the pool, the small-lamp glass sphere) and the gap scene);
4. on the Cornell box: Metropolis mutations per second against BDPT's samples per second at the same
   thread count (target: at least 1).

    python benchmarks/mlt.py [--time 40] [--reference-time 600] [--scenes pool,ajar-door] [--seeds 3]
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import pathspace as ps
from pathspace.metrics import RELMSE_EPSILON, relmse

ROOT = Path(__file__).resolve().parent.parent
ESTIMATORS = {"pt": ("pt", {}), "bdpt": ("bdpt", {}), "pssmlt-pt": ("pssmlt", {}),
              "pssmlt-bdpt": ("pssmlt", {"over": "bdpt"}), "mmlt": ("mmlt", {}), "mlt": ("mlt", {}),
              # Path-space MLT with Veach's direct lighting (paths of 1 and 2 segments by BDPT; the default is 4).
              "mlt-direct-2": ("mlt", {"direct": 2})}


def rel_mse(result, reference) -> float:
    """relMSE against the reference, minus the reference's own expected contribution."""
    floor = float(np.mean(reference.variance / (reference.image ** 2 + RELMSE_EPSILON)))
    return relmse(result.image, reference.image) - floor


def time_to_target(scene, name: str, seconds: float, reference, target: float, max_depth: int, threads: int,
                   seeds: int) -> dict:
    """Renders of seconds / 4 and seconds at ``seeds`` seeds (7, 8, ...): the mean time and relMSE over the
    seeds (Metropolis errors are heavy-tailed: a single seed can be far from typical)."""
    estimator, params = ESTIMATORS[name]
    rows = []
    for budget in (seconds / 4, seconds):
        results = [ps.render(scene, estimator, time=budget, seed=7 + k, max_depth=max_depth, threads=threads, **params)
                   for k in range(seeds)]
        rows.append((np.mean([r.stats["seconds"] for r in results]),
                     np.mean([rel_mse(r, reference) for r in results]), results[-1]))
    (t1, e1, _), (t2, e2, last) = rows
    slope = np.log(e2 / e1) / np.log(t2 / t1) if e1 > 0 and e2 > 0 else float("nan")
    row = {"name": name, "seconds": t2, "relmse": e2, "relmse_short": e1, "slope": slope,
           "time_to_target": t2 * e2 / target}
    if "metropolis" in last.stats:
        m = last.stats["metropolis"]
        row.update(mutations_per_second=m["mutations_per_second"], acceptance=m["acceptance"],
                   longest_rejection_run=m["longest_rejection_run"],
                   brightness_error=m["brightness_standard_error"] / m["brightness"])
    return row


def mutation_rate(threads: int, seconds: float) -> None:
    """Mutations per second of the Metropolis estimators against BDPT's samples per second (Cornell box)."""
    scene = ps.load_scene(ROOT / "scenes" / "cornell-box" / "scene.toml", resolution=(128, 128))
    bdpt = ps.render(scene, "bdpt", time=seconds, seed=1, max_depth=16, threads=threads)
    rate = bdpt.stats["samples_per_second"]
    print(f"\nCornell box 128x128, {threads} threads: BDPT {rate / 1e3:.1f} k samples/s")
    for name in ("pssmlt-pt", "pssmlt-bdpt", "mmlt", "mlt"):
        estimator, params = ESTIMATORS[name]
        result = ps.render(scene, estimator, time=seconds, seed=1, max_depth=16, threads=threads, **params)
        m = result.stats["metropolis"]
        if "mutations_per_second" not in m:   # the bootstrap and the first pass took longer than the budget
            print(f"  {name:12s} no pass completed in {seconds:g} s: give a longer --time")
            continue
        print(f"  {name:12s} {m['mutations_per_second'] / 1e3:8.1f} k mutations/s = "
              f"{m['mutations_per_second'] / rate:.2f} x BDPT's samples/s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--time", type=float, default=40.0, help="seconds of the longer render per estimator")
    parser.add_argument("--reference-time", type=float, default=600.0)
    parser.add_argument("--target", type=float, default=1e-2, help="relMSE target")
    parser.add_argument("--scenes", default="caustic-glass,caustic-glass-small-lamp,pool,ajar-door")
    parser.add_argument("--max-depth", type=int, default=10)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--estimators", default=",".join(ESTIMATORS))
    parser.add_argument("--seeds", type=int, default=2, help="renders per budget and estimator (relMSE averaged)")
    args = parser.parse_args()
    for name in args.scenes.split(","):
        scene = ps.load_scene(ROOT / "scenes" / name / "scene.toml")
        reference = ps.render(scene, "bdpt", time=args.reference_time, seed=1, max_depth=args.max_depth,
                              threads=args.threads)
        print(f"\n{name}: reference BDPT {reference.stats['spp']} spp in {reference.stats['seconds']:.0f} s")
        rows = [time_to_target(scene, e, args.time, reference, args.target, args.max_depth, args.threads, args.seeds)
                for e in args.estimators.split(",")]
        base = next((r["time_to_target"] for r in rows if r["name"] == "bdpt"), float("nan"))
        print(f"  {'estimator':12s} {'relMSE':>9s} {'(t/4)':>9s} {'slope':>6s} {'t->target':>10s} {'vs BDPT':>8s}")
        for r in rows:
            extra = ""
            if "mutations_per_second" in r:
                acceptance = " ".join(f"{kind} {rate:.2f}" for kind, rate in r["acceptance"].items()
                                      if rate is not None)
                extra = (f"  {r['mutations_per_second'] / 1e3:.0f} k mut/s, acceptance {acceptance}, longest "
                         f"rejection run {r['longest_rejection_run']}, b error {r['brightness_error']:.2%}")
            print(f"  {r['name']:12s} {r['relmse']:9.4f} {r['relmse_short']:9.4f} {r['slope']:6.2f} "
                  f"{r['time_to_target']:9.1f}s {r['time_to_target'] / base:8.2f}{extra}")
    mutation_rate(args.threads, args.time / 2)


if __name__ == "__main__":
    main()
