"""Warnings a researcher needs: infinite-variance roulette (from the parameters and from the running
statistics) and paths of extreme length."""
from __future__ import annotations

import pathspace as ps
from pathspace.diagnostics import second_moment_share
from conftest import ROOT, scene_dict


def test_fixed_roulette_with_infinite_variance_is_named():
    scene = ps.scene_from_dict(scene_dict("cornell-box", (8, 8)))
    for estimator in ("pt", "lt", "bdpt"):
        bad = ps.estimators.make_estimator(estimator, rr="fixed", rr_probability=0.3).warnings(scene)
        assert len(bad) == 1 and "'white' (albedo 0.886)" in bad[0] and "infinite variance" in bad[0]
        assert not ps.estimators.make_estimator(estimator, rr="fixed", rr_probability=0.2).warnings(scene)
        assert not ps.estimators.make_estimator(estimator, rr="albedo").warnings(scene)
    assert ps.estimators.make_estimator("pt", rr="throughput", rr_cap=0.8).warnings(scene)
    assert ps.estimators.make_estimator("bdpt", light_rr="fixed", light_rr_probability=0.5).warnings(scene)


def test_exploding_second_moment_is_seen_in_the_running_statistics():
    """Termination probability 0.75 in the specular box: one sample keeps a large share of the second
    moment as passes accumulate (and the render says so); the default roulette's share keeps falling."""
    scene = ps.scene_from_dict(scene_dict("cornell-box-specular", (48, 48)))
    bad = ps.render(scene, "pt", spp=512, seed=1, rr="fixed", rr_probability=0.75)
    assert any("not falling" in w for w in bad.stats["warnings"]), bad.stats["warnings"]
    good = ps.render(scene, "pt", spp=512, seed=1)
    share, share_half = second_moment_share(good.film)
    assert share < 0.01 and share < share_half and not any("not falling" in w for w in good.stats["warnings"])


def test_long_paths_are_reported():
    """A closed white furnace without roulette: every path runs to max_depth."""
    scene = ps.load_scene(ROOT / "scenes" / "furnace" / "scene.toml", resolution=(2, 2),
                          **{"materials.wall.reflectance": [1.0, 1.0, 1.0]})
    trapped = ps.render(scene, "pt", spp=1, seed=1, rr="off", max_depth=1000)
    assert trapped.stats["longest_subpath"] == 1000
    assert any("paths of up to 1000 segments" in w for w in trapped.stats["warnings"])
