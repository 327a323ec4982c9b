"""Renders do not depend on the scene's scale or on far-away geometry; tiny bright lights stay unbiased."""
from __future__ import annotations

import pytest

import pathspace as ps
from conftest import agree, scaled, scene_dict


@pytest.mark.parametrize("name", ["cornell-box", "cornell-box-specular"])
@pytest.mark.parametrize("factor", [1e-6, 1e6])
def test_scaling_the_scene_changes_nothing(name, factor):
    data = scene_dict(name)
    reference = ps.render(ps.scene_from_dict(data), spp=128, seed=1)
    other = ps.render(ps.scene_from_dict(scaled(data, factor)), spp=128, seed=2)
    assert other.stats["nonfinite"] == 0
    ok, report = agree(reference, other)
    assert ok, report


@pytest.mark.parametrize("distance", [1e4, 1e5])
def test_far_away_geometry_changes_nothing(distance):
    """A small quad far outside the box (seen by no path) leaves the image unchanged: ray offsets
    depend on the geometry where a ray starts, not on the scene's extent."""
    data = scene_dict("cornell-box")
    reference = ps.render(ps.scene_from_dict(data), spp=128, seed=1)
    data["shapes"].append({"type": "quad", "corner": [distance] * 3, "edge_u": [1, 0, 0], "edge_v": [0, 1, 0],
                           "material": "white"})
    ok, report = agree(reference, ps.render(ps.scene_from_dict(data), spp=128, seed=2))
    assert ok, report


def test_tiny_bright_light_mixture_agrees_with_mis():
    """A light 1e-4 on a side with radiance 1e8: mixture sampling (whose light density is evaluated along
    the traced ray) agrees with NEE + MIS; a ray that left its surface off the sampled line would miss
    such a light and bias the mixture."""
    data = scene_dict("cornell-box", (16, 16))
    data["materials"]["black"] = {"type": "diffuse", "reflectance": [0, 0, 0]}
    data["shapes"][0] = {"type": "quad", "corner": [0, 0.98, 0], "edge_u": [1e-4, 0, 0], "edge_v": [0, 0, 1e-4],
                         "material": "black", "emitter": {"radiance": [1e8, 1e8, 1e8]}}
    scene = ps.scene_from_dict(data)
    mis = ps.render(scene, spp=256, seed=1)
    mixture = ps.render(scene, spp=1024, seed=2, light_sampling="mixture", mixture_alpha=0.5)
    ok, report = agree(mis, mixture, block=16)
    assert ok, report


def test_mixture_alpha_one_is_refused():
    with pytest.raises(ValueError, match=r"mixture_alpha: expected a number in \[0, 1\)"):
        ps.estimators.make_estimator("pt", light_sampling="mixture", mixture_alpha=1.0)
