"""The C kernel of the area lights path tracing's rays hit (ext/direct.c) against the NumPy code it replaces.

``PathTracer._emission`` takes the lanes whose rays hit an area light, its emitting triangle and the weight of
its emission from ``_native.area_emission``; ``PathTracer._emitters_hit`` is the NumPy code, which path tracing
keeps for MIS against light samples by solid angle and the tests use as the reference (by area).  Compared bit
for bit on the scenes with several lights, two-sided lights, and a point light beside an area light, for every
strategy and both light selections, with densities from 0 to infinity, rays from both sides of the lights and
rays that hit nothing emitting; then the kernel's refusals.
"""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import pathspace as ps
from conftest import cornell_dict
from pathspace import _native
from pathspace.estimators.pt import MIS_CODES, PathTracer
from pathspace.spectra import RGBMode

SCENES = Path(__file__).resolve().parents[2] / "scenes"


def load(name: str):
    """A scene of ``scenes/``, or "cornell-box+point": the Cornell box with a point light beside its lamp."""
    if name != "cornell-box+point":
        return ps.load_scene(SCENES / name / "scene.toml")
    data = cornell_dict()
    data["lights"] = [{"type": "point", "position": [0.3, 0.9, 0.2], "intensity": [3.0, 2.0, 1.0]}]
    return ps.scene_from_dict(data)


def rays(scene, rng: np.random.Generator, n: int):
    """Arrivals (prim, p, normal) and the rays that made them (origin, direction, pdf, delta): two thirds on
    emitting triangles, from points on either side."""
    mesh, area = scene.mesh, scene.lights.area
    prim = rng.integers(0, mesh.triangle_count, n)
    on_light = rng.random(n) < 2 / 3
    prim[on_light] = rng.choice(area.triangles, np.count_nonzero(on_light))
    b1, b2 = rng.random((2, n)) * 0.5
    p, normal, _ = mesh.hit_geometry(prim.astype(np.int32), b1.astype(np.float32), b2.astype(np.float32))
    normal = normal * np.where(rng.random(n) < 0.3, -1, 1).astype(np.float32)     # either side of the triangle
    origin = (p + rng.normal(size=(3, n)).astype(np.float32)).astype(np.float32)
    origin[:, :20] = p[:, :20]                                                      # at the point itself
    d = (p - origin).astype(np.float64)
    with np.errstate(invalid="ignore"):
        direction = (d / np.linalg.norm(d, axis=0)).astype(np.float32)
    direction[:, :20] = normal[:, :20]
    pdf = 10.0 ** rng.uniform(-30, 30, n)
    pdf[rng.random(n) < 0.05] = 0.0
    pdf[rng.random(n) < 0.03] = np.inf
    arrival = SimpleNamespace(prim=prim.astype(np.int32), p=p, normal=normal)
    lanes = SimpleNamespace(origin=origin, direction=direction, pdf=pdf, delta=rng.random(n) < 0.2)
    return arrival, lanes


@pytest.mark.parametrize("scene_name", ["veach-mis", "prism", "cornell-box+point"])
@pytest.mark.parametrize("strategy, mis, beta", [("mis", "power", 2.0), ("mis", "balance", 2.0), ("mis", "uniform", 2.0),
                                                 ("nee", "power", 2.0), ("none", "power", 2.0)])
@pytest.mark.parametrize("selection", ["power", "uniform"])
def test_area_emission_equals_the_numpy_reference(scene_name, strategy, mis, beta, selection):
    scene = load(scene_name)
    pt = PathTracer(light_sampling=strategy, mis=mis, mis_beta=beta, light_selection=selection)
    arrival, lanes = rays(scene, np.random.default_rng(len(scene_name)), 3000)
    area = scene.lights.area
    got = _native.area_emission(arrival.prim, area.emitter_of_triangle, area.table, area.area, area.two_sided,
                                scene.lights.pmf(selection), lanes.origin, arrival.p, arrival.normal, lanes.direction,
                                lanes.pdf, lanes.delta, MIS_CODES[mis if strategy == "mis" else strategy], beta)
    with np.errstate(divide="ignore", invalid="ignore"):
        expected = pt._emitters_hit(scene, arrival, lanes, SimpleNamespace(strategy=strategy))
    for name, a, b in zip(("lanes", "emitter", "weight"), got, expected):
        assert a.dtype == b.dtype and a.shape == b.shape, name
        np.testing.assert_array_equal(a, b, err_msg=name)
    weight = got[2]
    assert got[0].size > 1000 and (weight > 0).any()
    if strategy == "mis":
        assert ((weight > 0) & (weight < 1)).any()
    if strategy == "nee":
        assert (weight == 0).any() and (weight == 1).any()


def test_a_power_heuristic_of_another_exponent_is_within_ulps():
    scene = ps.load_scene(SCENES / "veach-mis" / "scene.toml")
    pt = PathTracer(mis="power", mis_beta=3.0)
    arrival, lanes = rays(scene, np.random.default_rng(5), 3000)
    area = scene.lights.area
    got = _native.area_emission(arrival.prim, area.emitter_of_triangle, area.table, area.area, area.two_sided,
                                scene.lights.pmf("power"), lanes.origin, arrival.p, arrival.normal, lanes.direction,
                                lanes.pdf, lanes.delta, MIS_CODES["power"], 3.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        expected = pt._emitters_hit(scene, arrival, lanes, SimpleNamespace(strategy="mis"))
    np.testing.assert_array_equal(got[0], expected[0])
    np.testing.assert_allclose(got[2], expected[2], rtol=1e-14, atol=0.0)


def arguments(scene) -> list:
    area, n = scene.lights.area, 4
    return [np.zeros(n, np.int32), area.emitter_of_triangle, area.table, area.area, area.two_sided,
            scene.lights.pmf("power"), *(np.ones((3, n), np.float32) for _ in range(4)), np.ones(n),
            np.zeros(n, bool), MIS_CODES["power"], 2.0]


@pytest.mark.parametrize("position, value, error, match", [
    (0, np.zeros(4, np.int64), TypeError, "prim must be a 1D int32"),
    (0, np.full(4, 10 ** 6, np.int32), IndexError, r"prim\[0\] is not a triangle"),
    (2, np.zeros((12, 2), np.float32), ValueError, "must agree"),
    (5, np.ones(0), ValueError, "must agree"),
    (7, np.ones((3, 5), np.float32), ValueError, "must agree"),
    (11, np.zeros(4), TypeError, "delta_prev must be a 1D bool"),
    (12, 5, ValueError, "strategy must be"),
])
def test_area_emission_refuses_bad_arguments(position, value, error, match):
    args = arguments(ps.load_scene(SCENES / "cornell-box" / "scene.toml"))
    args[position] = value
    with pytest.raises(error, match=match):
        _native.area_emission(*args)


def test_a_triangle_without_an_emitter_in_the_table_is_refused():
    scene = ps.load_scene(SCENES / "cornell-box" / "scene.toml")
    args = arguments(scene)
    light = int(scene.lights.area.triangles[-1])
    args[0] = np.full(4, light, np.int32)
    args[2], args[3], args[4] = np.ascontiguousarray(args[2][:, :1]), args[3][:1], args[4][:1]   # one emitter
    with pytest.raises(IndexError, match="has no emitter in table"):
        _native.area_emission(*args)


def former_emission(pt: PathTracer, scene, arrival, lanes, strategy: str, colours) -> None:
    """``PathTracer._emission`` as it was before the kernel (NumPy), adding to ``lanes.radiance``."""
    lights = scene.lights
    entity = lights.area.emitter_of_triangle.take(arrival.prim)
    emits = np.flatnonzero(entity >= 0)
    entity = entity.take(emits)
    normal, wo = np.take(arrival.normal, emits, axis=1), -np.take(lanes.direction, emits, axis=1)
    le = lights.le(entity, normal, wo, colours.take(emits))
    pdf_light = None
    if strategy == "mis":
        pdf_light = lights.pdf_li(entity, np.take(lanes.origin, emits, axis=1), np.take(arrival.p, emits, axis=1),
                                  pt.light_selection, pt.light_measure)
    le = le * pt._weight_of_hits(lanes.pdf.take(emits), pdf_light, lanes.delta.take(emits), strategy)
    lanes.radiance[:, emits] += np.take(lanes.beta, emits, axis=1) * le


@pytest.mark.parametrize("scene_name", ["veach-mis", "prism"])
@pytest.mark.parametrize("strategy", ["mis", "nee", "none", "mixture"])
@pytest.mark.parametrize("measure", ["area", "solid_angle"])
def test_path_tracings_emission_equals_its_former_numpy_code(scene_name, strategy, measure):
    """Through ``PathTracer._emission`` (the kernel, or the NumPy code for MIS by solid angle): the radiance
    the emitters hit add is bit for bit what the code before the kernel added."""
    scene = load(scene_name)
    pt = PathTracer(light_sampling=strategy, light_measure=measure)
    arrival, lanes = rays(scene, np.random.default_rng(8), 3000)
    rng = np.random.default_rng(9)
    lanes.beta = rng.random((3, 3000))
    initial = rng.random((3, 3000))
    expected = SimpleNamespace(**vars(lanes), radiance=initial.copy())
    lanes.radiance = initial.copy()
    mode = RGBMode()
    with np.errstate(divide="ignore", invalid="ignore"):
        pt._emission(scene, arrival, lanes, SimpleNamespace(strategy=strategy, mode=mode))
        former_emission(pt, scene, arrival, expected, strategy, mode.colours(expected))
    np.testing.assert_array_equal(lanes.radiance, expected.radiance)
    assert (lanes.radiance != initial).any()     # the emitters hit added something
