"""Every path-tracing strategy estimates the same image, block by block; a wrong pdf is caught."""
from __future__ import annotations

import tomllib

import numpy as np
import pytest

import pathspace as ps
from pathspace.bsdfs import Diffuse
from pathspace.validate import compare_estimates
from conftest import ROOT, agree


def scene(name: str, resolution=(64, 64), **changes) -> ps.Scene:
    data = tomllib.loads((ROOT / "scenes" / name / "scene.toml").read_text())
    data["camera"]["resolution"] = list(resolution)
    for key, value in changes.items():
        data[key] = value
    return ps.scene_from_dict(data, source=name)


@pytest.fixture(scope="module")
def cornell():
    s = scene("cornell-box")
    return s, ps.render(s, spp=256, seed=1)


@pytest.mark.parametrize("params, spp", [
    ({"diffuse_sampling": "uniform"}, 256),
    ({"light_sampling": "nee"}, 256),
    ({"light_sampling": "none"}, 1024),
    ({"light_sampling": "none", "diffuse_sampling": "uniform"}, 1024),
    ({"mis": "balance"}, 256),
    ({"mis": "uniform"}, 256),
    ({"mis": "power", "mis_beta": 4.0}, 256),
    ({"light_sampling": "mixture", "mixture_alpha": 0.25}, 256),
    ({"light_sampling": "mixture", "mixture_alpha": 0.5}, 256),
    ({"rr": "off"}, 256),
    ({"rr": "fixed", "rr_depth": 2, "rr_probability": 0.3}, 256),
    ({"rr": "albedo", "rr_depth": 1}, 256),
    ({"light_selection": "uniform"}, 256),
    ({"light_measure": "solid_angle"}, 256),
], ids=lambda v: str(v))
def test_cornell_box_strategies_agree(cornell, params, spp):
    s, reference = cornell
    ok, report = agree(reference, ps.render(s, spp=spp, seed=2, **params))
    assert ok, (params, report)


def test_a_wrong_pdf_is_detected(cornell, monkeypatch):
    """Cosine samples divided by the uniform hemisphere pdf (the bug of 'Rest of Your Life', ch. 5)."""
    s, reference = cornell
    real_sample = Diffuse.sample

    def wrong(params, surface, u, mode="radiance"):
        sample = real_sample(params, surface, u, mode)
        cos = np.abs(surface.n[0] * sample.wi[0] + surface.n[1] * sample.wi[1] + surface.n[2] * sample.wi[2])
        sample.weight = params.albedo / np.pi * cos * (2 * np.pi)  # f cos / (1 / 2 pi): the wrong density
        sample.pdf = np.full(cos.shape, 0.5 / np.pi)
        return sample

    monkeypatch.setattr(Diffuse, "sample", staticmethod(wrong))
    biased = ps.render(s, spp=256, seed=3)
    ok, report = agree(reference, biased)
    assert not ok, report


@pytest.fixture(scope="module")
def specular():
    s = scene("cornell-box-specular")
    return s, ps.render(s, spp=512, seed=1)


@pytest.mark.parametrize("params, spp", [
    ({"light_sampling": "nee"}, 512),
    ({"light_sampling": "none"}, 1024),
    ({"mis": "balance"}, 512),
    ({"light_sampling": "mixture", "mixture_alpha": 0.5}, 512),
    ({"rr": "albedo", "rr_depth": 2}, 512),
], ids=lambda v: str(v))
def test_specular_cornell_box_strategies_agree(specular, params, spp):
    """Mirror and glass: caustics come from BSDF-sampled chains only; every strategy must still agree."""
    s, reference = specular
    ok, report = agree(reference, ps.render(s, spp=spp, seed=2, **params), block=16)
    assert ok, (params, report)


def test_delta_lights_agree_and_refuse_bsdf_only():
    s = scene("cornell-box-point-light")
    mis = ps.render(s, spp=128, seed=1)
    nee = ps.render(s, spp=128, seed=2, light_sampling="nee")
    ok, report = agree(mis, nee, block=16)
    assert ok, report
    with pytest.raises(ValueError, match="cannot reach point, spot or directional lights"):
        ps.render(s, spp=1, light_sampling="none")


def test_spot_directional_and_environment_lights():
    lights = [{"type": "spot", "position": [0.3, 0.9, 0.2], "look_at": [0.0, -1.0, 0.0], "intensity": [3, 2, 1],
               "cone_angle": 40, "falloff_start": 30},
              {"type": "directional", "direction": [0.2, -1.0, -0.5], "irradiance": [0.5, 0.5, 0.5]},
              {"type": "environment", "radiance": [0.2, 0.3, 0.4]}]
    s = scene("cornell-box", lights=lights)
    mis = ps.render(s, spp=128, seed=1)
    for seed, params in enumerate([{"light_sampling": "nee"}, {"light_selection": "uniform"}], start=2):
        ok, report = agree(mis, ps.render(s, spp=128, seed=seed, **params), block=16)
        assert ok, (params, report)
    # The environment alone: BSDF sampling and mixture sampling reach it too.
    env_only = scene("cornell-box", lights=lights[2:])
    reference = ps.render(env_only, spp=128, seed=1)
    for seed, params in enumerate([{"light_sampling": "none"}, {"light_sampling": "mixture"}], start=2):
        ok, report = agree(reference, ps.render(env_only, spp=128, seed=seed, **params), block=16)
        assert ok, (params, report)


def test_thin_lens_strategies_agree():
    s = scene("cornell-box-thin-lens")
    mis = ps.render(s, spp=128, seed=1)
    ok, report = agree(mis, ps.render(s, spp=128, seed=2, light_sampling="nee"), block=16)
    assert ok, report


def test_veach_mis_scene_strategies_agree():
    s = scene("veach-mis", resolution=(96, 64))
    mis = ps.render(s, spp=128, seed=1)
    for seed, params in enumerate([{"light_sampling": "nee"}, {"mis": "balance"}], start=2):
        ok, report = agree(mis, ps.render(s, spp=128, seed=seed, **params), block=16)
        assert ok, (params, report)
    # MIS is never much worse than the better of its two strategies, and clearly better than each overall.
    nee = ps.render(s, spp=128, seed=4, light_sampling="nee")
    bsdf = ps.render(s, spp=128, seed=5, light_sampling="none")
    assert mis.variance.sum() < 0.5 * nee.variance.sum() and mis.variance.sum() < 0.5 * bsdf.variance.sum()


def test_lights_add_up():
    """Light transport is linear in the emitters: an area light plus an environment renders as the sum of the
    two rendered apart (a shadow-ray bug that hit light surfaces only showed up with both present)."""
    def load(area, env):
        data = tomllib.loads((ROOT / "scenes" / "cornell-box" / "scene.toml").read_text())
        data["camera"]["resolution"] = [64, 64]
        if env:
            data["lights"] = [{"type": "environment", "radiance": [0.2, 0.3, 0.4]}]
        if not area:
            for shape in data["shapes"]:
                shape.pop("emitter", None)
        return ps.scene_from_dict(data)

    for mode in ("mis", "nee"):
        both = ps.render(load(True, True), spp=256, seed=1, light_sampling=mode, max_depth=3)
        area = ps.render(load(True, False), spp=256, seed=2, light_sampling=mode, max_depth=3)
        env = ps.render(load(False, True), spp=256, seed=3, light_sampling=mode, max_depth=3)
        result = compare_estimates(both.image, both.variance, area.image + env.image, area.variance + env.variance)
        assert result.passed, (mode, str(result))
