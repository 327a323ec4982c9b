"""Convergence from one run: snapshots equal renders of their passes, errors fall at the Monte Carlo
rate, tables and equal-time/equal-spp views say what the numbers are."""
from __future__ import annotations

import numpy as np
import pytest

import pathspace as ps
from pathspace.experiment import EstimatorSpec, converge, default_checkpoints
from pathspace.experiment.convergence import Convergence
from conftest import scene_dict


@pytest.fixture(scope="module")
def box():
    scene = ps.scene_from_dict(scene_dict("cornell-box", (32, 32)))
    return scene, ps.render(scene, "pt", spp=4096, seed=99)


def test_pt_relmse_falls_at_the_monte_carlo_rate(box):
    """relMSE against samples per pixel has a fitted log-log slope near -1 (from 4 to 512 spp)."""
    scene, reference = box
    result = converge(scene, ["pt"], reference, spp=512, checkpoints=[4, 16, 64, 128], seeds=(0, 1))
    floor = np.mean(reference.variance / (reference.image ** 2 + 0.01))  # the reference's own noise
    table = result.table
    for seed, run in table.groupby("seed"):
        slope = np.polyfit(np.log(run["spp"]), np.log(run["relmse"] - floor), 1)[0]
        assert -1.2 < slope < -0.8, (seed, slope)
    assert set(table.columns) >= {"estimator", "params", "seed", "spp", "seconds", "relmse", "mse", "mape", "smape",
                                  "predicted_relmse", "overhead_seconds", "final"}
    assert table["final"].sum() == 2 and (table["spp"].max() == 512)


def test_snapshots_equal_independent_renders(box):
    scene, reference = box
    result = converge(scene, ["bdpt"], reference, spp=24, checkpoints=[3, 10], seeds=(5,), keep_images=True)
    for (label, seed, passes), image in result.images.items():
        np.testing.assert_array_equal(image, ps.render(scene, "bdpt", spp=passes, seed=seed).image)
    assert sorted(passes for _, _, passes in result.images) == [3, 10, 24]


def test_time_budgets_and_views(box):
    # A budget of many passes even when the tests share the cores (pytest -n auto): under a 0.6-s budget an
    # LT run whose first items were slowed down that much completed no pass.
    scene, reference = box
    budget = 1.5
    result = converge(scene, ["pt", ("lt", {"rr": "fixed"})], reference, time=budget, seeds=(0, 1))
    table = result.table
    assert set(table["estimator"]) == {"pt", "lt (rr=fixed)"}
    final = table[table["final"]]
    # Runs end with their last whole work item: by the budget, and not before half of it.
    assert np.all(final["seconds"] < budget + 0.2) and np.all(final["seconds"] >= budget * 0.5)
    at = result.at(spp=int(final["spp"].min()))
    assert list(at.columns) == ["relmse", "relmse_error"] and len(at) == 2
    summary = result.summary()
    assert {"slope", "efficiency", "overhead_seconds"} <= set(summary.columns)
    assert np.all(summary["overhead_seconds"] < 0.2 * summary["seconds"])


def test_equal_spp_views_skip_runs_without_passes():
    """A time budget shorter than a pass leaves a run with no pass (spp 0): it has no curve to interpolate."""
    import pandas as pd

    table = pd.DataFrame({"estimator": ["pt", "pt", "lt"], "seed": [0, 0, 0], "spp": [2, 8, 0],
                          "seconds": [0.1, 0.7, 0.6], "relmse": [0.4, 0.1, np.nan]})
    at = Convergence(table, ("relmse",)).at(spp=4)
    assert list(at.index) == ["pt"] and at["relmse"].iloc[0] == pytest.approx(0.2)
    at = Convergence(table, ("relmse",)).at(seconds=0.6)
    assert list(at.index) == ["pt"] and np.isfinite(at["relmse"]).all()
    with pytest.warns(UserWarning, match=r"at\(seconds=0.8\): left out 1 run\(s\) that ended before it: pt seed 0 \(0.7\)"):
        assert Convergence(table, ("relmse",)).at(seconds=0.8).empty
    with pytest.raises(ValueError, match="spp: expected a number > 0"):
        Convergence(table, ("relmse",)).at(spp=0)


def test_specs_and_checkpoints():
    assert EstimatorSpec.parse("bdpt:mis=balance,mis_beta=3").params == {"mis": "balance", "mis_beta": 3}
    assert EstimatorSpec.parse(("pt", {"rr": "off"})).label == "pt (rr=off)"
    assert default_checkpoints(64, None) == [1, 2, 3, 6, 11, 20, 35]
    assert len(default_checkpoints(None, 10.0)) == 6
    with pytest.raises(ValueError, match="either time"):
        converge(None, ["pt"], np.zeros((2, 2, 3)), time=1, spp=1)
