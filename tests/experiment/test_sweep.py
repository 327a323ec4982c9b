"""Sweeps: a grid of settings, a tidy table, and a biased setting that cannot hide."""
from __future__ import annotations

import numpy as np
import pytest

import pathspace as ps
from pathspace.experiment import grid_cells, sweep
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
