"""The shape that makes new estimators and lights natural: parameters declared once and documented,
one registry entry to add an estimator, one model and one registry entry to add a light kind."""
from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest

import pathspace as ps
from pathspace.estimators import ESTIMATORS
from pathspace.lights import LIGHTS, PointLight
from conftest import agree, scene_dict


@pytest.mark.parametrize("name", sorted(ESTIMATORS))
def test_every_parameter_has_a_meaning_and_a_check(name):
    cls = ESTIMATORS[name]
    params = cls.parameters()
    assert params and all(meaning for _, _, meaning in params)
    estimator = cls()
    assert set(estimator.params) == {p for p, _, _ in params}
    for f in dataclasses.fields(cls):
        if f.init and f.name != "strategy":
            assert f.metadata.get("check") is not None, f.name


def test_mis_heuristics_speak_one_language():
    for name, allowed in (("pt", "('balance', 'power', 'uniform')"),
                          ("bdpt", "('balance', 'power', 'uniform', 'single', 'none')")):
        with pytest.raises(ValueError, match="mis: expected one of " + re.escape(allowed)):
            ps.estimators.make_estimator(name, mis="maximum")
        with pytest.raises(ValueError, match="mis_beta: expected a finite number > 0"):
            ps.estimators.make_estimator(name, mis_beta=-1.0)


@dataclasses.dataclass(frozen=True)
class Bulb(PointLight):
    """A new light kind, written as a user would: a model class (here reusing the point light's lane
    methods) and one entry in LIGHTS."""

    kind = "bulb"


def test_a_new_light_kind_is_one_model_and_one_registry_entry(monkeypatch):
    monkeypatch.setitem(LIGHTS, "bulb", Bulb)
    data = scene_dict("cornell-box-point-light", (16, 16))
    point = next(light for light in data["lights"] if light["type"] == "point")
    reference = ps.render(ps.scene_from_dict(data), "pt", spp=64, seed=1)
    point["type"] = "bulb"
    scene = ps.scene_from_dict(data)
    assert "1 bulb" in repr(scene.lights)
    for estimator in ("pt", "bdpt"):
        ok, report = agree(reference, ps.render(scene, estimator, spp=64, seed=2))
        assert ok, (estimator, report)


def test_unregistered_light_models_are_refused():
    with pytest.raises(ValueError, match="not a registered light model"):
        ps.lights.LightSet([Bulb((0, 0, 0), (1, 1, 1))], mesh=None, scene_radius=1.0, disk_center=np.zeros(3),
                           disk_radius=1.0)
