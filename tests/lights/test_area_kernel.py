"""The C kernel of area-light sampling (ext/lights.c) against the NumPy code it replaces.

Where every light is an area light and points are sampled by area, ``LightSet.sample_li`` chooses the emitting
triangle and the point on it with ``_native.area_light_sample``.  The reference is the NumPy code every other
light set still runs (``select``, ``AreaLight.sample_li`` over ``AreaTables.sample``, the pmf), compared bit for
bit on receivers all over and around a one-sided and a two-sided lamp: on the lamps themselves, at the very
point sampled (distance 0), behind them, at grazing angles and far away, with uniforms on the selection CDF's
steps, at 0 and 1 - 2^-53 and NaN; then the kernel's refusals.
"""
from __future__ import annotations

import numpy as np
import pytest

import pathspace as ps
from pathspace import _native
from pathspace.lights import AreaLight, LightSample
from pathspace.spectra import RGBColours
from conftest import cornell_dict
from lights.test_light_set import two_light_scene


def reference_sample(lights, receivers: np.ndarray, u: np.ndarray, selection: str) -> LightSample:
    """LightSet.sample_li's NumPy code for area lights by area."""
    entity = lights.select(u[0], selection)
    pmf = lights.pmf(selection).take(entity)
    sample = AreaLight.sample_li(lights.area, lights.index.take(entity), receivers, u[1:3], RGBColours, "area")
    sample.pdf = sample.pdf * pmf
    sample.entity = entity
    return sample


def receivers_around(lights, rng: np.random.Generator, n: int) -> np.ndarray:
    """Points in and around the box, a tenth of them on the lamps (where samples can land on them), some far."""
    x = rng.uniform(-1.2, 1.2, (3, n))
    on = rng.random(n) < 0.1
    b1, b2 = rng.random((2, n))
    b1, b2 = np.where(b1 + b2 > 1, 1 - b1, b1), np.where(b1 + b2 > 1, 1 - b2, b2)
    points, _, _ = lights.area.mesh.hit_geometry(lights.area.triangles.take(rng.integers(0, lights.area.count, n)),
                                                 b1, b2)
    x[:, on] = points[:, on]
    x[:, rng.random(n) < 0.05] *= 1e4
    return x.astype(np.float32)


def uniforms(lights, selection: str, rng: np.random.Generator, n: int) -> np.ndarray:
    u = rng.random((4, n))   # a fourth row, as BDPT's vertices carry: the kernel reads the first three
    cdf = lights._cdfs[selection]
    steps = rng.random(n) < 0.2
    u[0, steps] = cdf.take(rng.integers(0, cdf.size, np.count_nonzero(steps)))
    u[:3, :4] = [[0.0, 1 - 2 ** -53, 0.5, 1 - 2 ** -53], [0.0, 1 - 2 ** -53, 0.0, 1.0], [0.0, 1 - 2 ** -53, 1.0, 0.0]]
    u[0, 4] = np.nan   # chooses the last triangle, as searchsorted sorts NaN last
    return u


def tilted_lamp_scene():
    """The Cornell box's lamp and a second one tilted on every axis (a normal with three non-zero components)."""
    data = cornell_dict((8, 8))
    data["shapes"][0]["emitter"] = {"radiance": [1.0] * 3}
    data["shapes"].append({"name": "lamp3", "type": "quad", "corner": [0.2, -0.3, 0.1], "edge_u": [0.3, 0.1, -0.05],
                           "edge_v": [-0.07, 0.2, 0.15], "material": "white",
                           "emitter": {"radiance": [3.0, 2.0, 1.0], "two_sided": True}})
    data["render"] = {"origin": [0.0, 0.0, 0.0]}
    return ps.scene_from_dict(data)


@pytest.mark.parametrize("tilted", [False, True])
@pytest.mark.parametrize("selection", ["power", "uniform"])
def test_area_light_sample_equals_the_numpy_reference(selection, tilted):
    lights = (tilted_lamp_scene() if tilted else two_light_scene()).lights
    assert lights.models == [AreaLight]
    rng = np.random.default_rng(11)
    receivers = receivers_around(lights, rng, 20000)
    u = uniforms(lights, selection, rng, 20000)
    same = rng.random(20000) < 0.02   # receivers at the very point their sample finds (the point ignores them)
    receivers[:, same] = reference_sample(lights, receivers, u, selection).point[:, same]
    got = lights.sample_li(receivers, u, RGBColours, selection, "area")
    expected = reference_sample(lights, receivers, u, selection)
    for name in ("entity", "wi", "distance", "point", "normal", "value", "facing", "pdf", "delta", "epsilon"):
        a, b = getattr(got, name), getattr(expected, name)
        assert a.dtype == b.dtype and a.shape == b.shape, name
        np.testing.assert_array_equal(a, b, err_msg=name)
    assert (got.distance == 0).any() and (~got.facing).any() and np.isinf(got.pdf).sum() < got.pdf.size


def test_area_light_sample_reads_rows_of_wider_arrays():
    lights = two_light_scene().lights
    rng = np.random.default_rng(3)
    wide = np.concatenate([receivers_around(lights, rng, 300), np.zeros((3, 5), np.float32)], axis=1)
    u = uniforms(lights, "power", rng, 305)
    got = lights.sample_li(wide[:, :300], u[:, :300], RGBColours)
    expected = reference_sample(lights, wide[:, :300], u[:, :300], "power")
    np.testing.assert_array_equal(got.pdf, expected.pdf)
    np.testing.assert_array_equal(got.point, expected.point)


def test_sample_li_runs_the_kernel_where_it_applies(monkeypatch):
    """Area lights by area with float32 receivers and float64 uniforms go through the kernel; the
    solid-angle measure, float64 receivers and float32 uniforms through the NumPy code."""
    calls = []
    kernel = _native.area_light_sample
    monkeypatch.setattr(_native, "area_light_sample", lambda *args: calls.append(1) or kernel(*args))
    lights = two_light_scene().lights
    rng = np.random.default_rng(2)
    receivers, u = receivers_around(lights, rng, 50), rng.random((3, 50))
    lights.sample_li(receivers, u, RGBColours)
    assert len(calls) == 1
    lights.sample_li(receivers, u, RGBColours, measure="solid_angle")
    lights.sample_li(receivers.astype(np.float64), u, RGBColours)
    lights.sample_li(receivers, u.astype(np.float32), RGBColours)
    assert len(calls) == 1


def test_sample_li_takes_receivers_and_uniforms_of_any_layout():
    """Broadcast and transposed receivers, transposed uniforms: copied for the kernel, same samples."""
    lights = two_light_scene().lights
    rng = np.random.default_rng(4)
    point = np.float32([0.1, 0.5, -0.2])
    u = rng.random((3, 40))
    expected = reference_sample(lights, np.repeat(point[:, None], 40, axis=1), u, "power")
    for receivers, uniforms in ((np.broadcast_to(point[:, None], (3, 40)), u),
                                (np.ascontiguousarray(np.repeat(point[:, None], 40, axis=1).T).T, u.T.copy().T)):
        got = lights.sample_li(receivers, uniforms, RGBColours)
        np.testing.assert_array_equal(got.pdf, expected.pdf)
        np.testing.assert_array_equal(got.wi, expected.wi)


def arguments():
    area = two_light_scene().lights.area
    cdf = np.cumsum(area.area) / area.area.sum()
    return [area.table, area.area, area.two_sided, cdf, area.area / area.area.sum(), np.zeros((3, 4)),
            np.zeros((3, 4), np.float32)]


@pytest.mark.parametrize("position, value, error, match", [
    (0, lambda a: a[:12], ValueError, "must agree"),
    (1, lambda a: a[:-1], ValueError, "must agree"),
    (2, lambda a: a.astype(np.int8), TypeError, "two_sided"),
    (3, lambda a: a.astype(np.float32), TypeError, "cdf"),
    (5, lambda a: a[:2], ValueError, "u must have 3 rows"),
    (5, lambda a: np.asfortranarray(a), ValueError, "contiguous rows"),
    (6, lambda a: a.astype(np.float64), TypeError, "receivers"),
    (6, lambda a: a[:, :3], ValueError, "as many columns"),
    (0, lambda a: a[:, :0], ValueError, "must agree"),
    (2, lambda a: a[:-1], ValueError, "must agree"),
    (3, lambda a: a[:-1], ValueError, "must agree"),
    (4, lambda a: a[:-1], ValueError, "must agree"),
    (5, lambda a: a.astype(a.dtype.newbyteorder()), TypeError, "u must be a 2D float64"),
    (5, lambda a: np.lib.stride_tricks.as_strided(np.zeros(16), (3, 4), (12, 8)), ValueError, "u must be aligned"),
])
def test_area_light_sample_refuses_bad_arguments(position, value, error, match):
    args = arguments()
    args[position] = value(args[position])
    with pytest.raises(error, match=match):
        _native.area_light_sample(*args)
