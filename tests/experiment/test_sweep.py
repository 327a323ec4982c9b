"""Sweeps: a grid of settings, a tidy table, and a biased setting that cannot hide."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

import pathspace as ps
from pathspace.experiment import grid_cells, sweep
from pathspace.experiment.sweep import _pooled
from conftest import scene_dict


def test_grid_cells():
    assert grid_cells({"a": [1, 2], "b": ["x"]}) == [{"a": 1, "b": "x"}, {"a": 2, "b": "x"}]


def test_a_truncated_path_depth_is_flagged_and_the_unbiased_settings_are_not():
    scene = ps.scene_from_dict(scene_dict("cornell-box", (32, 32)))
    reference = ps.render(scene, "pt", spp=4096, seed=7)
    result = sweep(scene, "pt", {"max_depth": [3, -1], "rr": ["off", "albedo", "throughput"]}, reference, spp=64,
                   seeds=(1, 2))
    cells = result.cells.set_index(["max_depth", "rr"])
    assert cells.loc[(3, "off"), "biased"] and cells.loc[(3, "albedo"), "biased"]
    assert not cells.xs(-1, level="max_depth")["biased"].any()
    assert len(result.table) == 12 and {"mean", "mean_error", "variance_per_sample", "time_per_sample",
                                        "efficiency", "relmse"} <= set(result.table.columns)
    best = result.best()
    assert best["max_depth"] == -1


def test_a_bad_cell_fails_before_rendering():
    scene = ps.scene_from_dict(scene_dict("cornell-box", (8, 8)))
    with pytest.raises(ValueError, match="rr: expected one of"):
        sweep(scene, "pt", {"rr": ["sometimes"]}, np.zeros((8, 8, 3)), spp=1)


def chain_renders(rng, truth, seeds, bias=0.0):
    """Synthetic Markov-chain renders: every pixel of a seed's image shares its random brightness scale
    (5%, as the bootstrap's error in b does), plus independent pixel noise; variance NaN."""
    scale = 1.0 + 0.05 * rng.standard_normal(seeds)
    images = truth * scale[:, None, None, None] + 0.05 * rng.standard_normal((seeds, *truth.shape)) + bias
    return [SimpleNamespace(image=image, variance=np.full(image.shape, np.nan)) for image in images]


def test_markov_chain_cells_are_flagged_at_the_stated_rate():
    """4 seeds, alpha 0.1: an unbiased Markov chain is flagged in 10% of cells (1000 cells: 7%..13%, 3.2
    standard deviations), its blocks in at most 10% (Sidak, conservative for correlated blocks).  Per-pixel
    variances summed as if pixels were independent flag nearly every cell; the right variance with normal
    quantiles instead of Student's t (3 degrees of freedom) flags 20%."""
    rng, alpha, trials = np.random.default_rng(3), 0.1, 1000
    truth = rng.uniform(0.2, 1.0, (16, 16, 3))
    zero = np.zeros_like(truth)
    cells = [_pooled(chain_renders(rng, truth, 4), truth, zero, alpha, 8, independent=False)
             for _ in range(trials)]
    biased = np.mean([c["biased"] for c in cells])
    assert 0.07 < biased < 0.13, biased
    assert np.mean([not c["blocks_agree"] for c in cells]) < 0.13
    z = np.array([c["mean_z"] for c in cells])   # normal equivalents of t with 3 degrees of freedom
    assert stats.kstest(z, "norm").pvalue > 1e-3
    # Detected: a 25% bias of the whole image (4 seeds' standard error: 2.5%), and 0.3 in one block.
    assert all(_pooled(chain_renders(rng, truth, 4, 0.15), truth, zero, alpha, 8, independent=False)["biased"]
               for _ in range(50))
    local = np.zeros_like(truth)
    local[:8, :8] = 0.3
    assert not any(_pooled(chain_renders(rng, truth, 4, local), truth, zero, alpha, 8, independent=False)
                   ["blocks_agree"] for _ in range(50))
    # One seed: no error estimate, not tested.
    assert _pooled(chain_renders(rng, truth, 1), truth, zero, alpha, 8)["biased"] is None


def test_a_noisy_reference_keeps_the_rate():
    """The reference's error comparable to the seeds' (Welch-Satterthwaite degrees of freedom): 10% at alpha
    0.1 (1000 cells: 7%..13%)."""
    rng, alpha = np.random.default_rng(4), 0.1
    truth = rng.uniform(0.2, 1.0, (16, 16, 3))
    variance = np.full(truth.shape, 0.16)   # the reference mean's error ~ the 4 seeds' (1.4% vs 1.5%)
    flagged = [_pooled(chain_renders(rng, truth, 4), truth + 0.4 * rng.standard_normal(truth.shape), variance,
                       alpha, 8, independent=False)["biased"] for _ in range(1000)]
    assert 0.07 < np.mean(flagged) < 0.13


def test_a_markov_chain_sweep_flags_a_truncated_depth():
    scene = ps.scene_from_dict(scene_dict("cornell-box", (8, 8)))
    reference = ps.render(scene, "bdpt", spp=512, seed=7)
    result = sweep(scene, ("pssmlt", {"chains": 256, "bootstrap": 4096}), {"max_depth": [2, 16]}, reference,
                   spp=8, seeds=(1, 2, 3, 4), block=4, alpha=0.01)
    cells = result.cells.set_index("max_depth")
    assert cells.loc[2, "biased"] and not cells.loc[16, "biased"]
    assert np.isnan(result.table["variance_per_sample"]).all()


def test_a_cell_whose_render_fails_is_reported_and_the_others_finish(tmp_path):
    """light_sampling='none' cannot reach a point light: the scene refuses it when it renders.  The cell is
    marked failed with the error, the other renders and is pooled; ``on_render`` sees each finished render;
    with a cache, a second run renders nothing it has (the same seconds)."""
    scene = ps.scene_from_dict(scene_dict("cornell-box-point-light", (8, 8)))
    seen = []
    result = sweep(scene, "pt", {"light_sampling": ["none", "mis"]}, np.zeros((8, 8, 3)), spp=2, seeds=(0, 1),
                   on_render=seen.append, cache=tmp_path)
    assert [(row["light_sampling"], row["seed"]) for row in seen] == [("mis", 0), ("mis", 1)]
    assert list(result.failed["light_sampling"]) == ["none"]
    error = result.failed["error"].iloc[0]
    assert "cannot reach point" in error and "seed 0: ValueError" in error and "seed 1: ValueError" in error
    assert list(result.table["light_sampling"]) == ["mis", "mis"]
    again = sweep(scene, "pt", {"light_sampling": ["none", "mis"]}, np.zeros((8, 8, 3)), spp=2, seeds=(0, 1),
                  cache=tmp_path)
    assert list(again.table["seconds"]) == list(result.table["seconds"])
