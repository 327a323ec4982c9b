"""Honest time budgets: every estimator on every scene in scenes/ stops within 5% (or 0.2 s) of its budget,
however long its paths, and not before half of it (its workers stop taking items that could not end by the
deadline); the seconds reported are render time (scene load and BVH builds excluded)."""
from __future__ import annotations

import time
from pathlib import Path

import pytest

import pathspace as ps

SCENES = sorted(path / "scene.toml" for path in (Path(__file__).parents[1] / "scenes").iterdir())
ESTIMATORS = ["pt", "lt", "bdpt"]


def allowed(budget: float) -> float:
    return budget + max(0.05 * budget, 0.2)


def check_budget(scene, estimator: str, budget: float) -> None:
    start = time.perf_counter()
    result = ps.render(scene, estimator, time=budget, seed=1, threads=2)
    wall = time.perf_counter() - start
    seconds = result.stats["seconds"]
    assert 0.5 * budget <= seconds <= allowed(budget), (estimator, seconds)
    assert wall <= allowed(budget) + 0.5, (estimator, wall)  # BVH builds and film development on top
    assert "BVH builds excluded" in result.stats["clock"]
    if result.stats["spp"] == 0:
        assert any("no pass was complete" in w for w in result.stats["warnings"])


@pytest.mark.parametrize("scene_file", SCENES, ids=[path.parent.name for path in SCENES])
def test_budgets_are_met_on_every_scene(scene_file):
    scene = ps.load_scene(scene_file, resolution=(64, 48))
    for estimator in ESTIMATORS:
        check_budget(scene, estimator, 0.3)


@pytest.mark.slow
@pytest.mark.parametrize("scene_file", SCENES, ids=[path.parent.name for path in SCENES])
def test_budgets_are_met_at_full_resolution(scene_file):
    scene = ps.load_scene(scene_file)
    for estimator in ESTIMATORS:
        for budget in (0.5, 2.0):
            check_budget(scene, estimator, budget)
