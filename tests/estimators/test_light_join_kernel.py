"""BDPT's fused joins of camera vertices to light samples (s = 1, ext/join.c) against the NumPy code they stand for.

Whole renders with both kernels are compared in test_join_kernel.py (which counts this kernel's calls too).  Here:
the light samples of made-up camera vertices with extreme values (throughputs, densities and survival
probabilities over 300 decades and zero, infinite or NaN; vertices seen from both sides and edge-on; zero and NaN
normals; NaN directions and positions; NaN connection numbers), on one-sided, two-sided and many emitting
triangles, through the shadow rays and without them, compared bit for bit; then the scenes and settings left to
NumPy, and the kernel's refusals.
"""
from __future__ import annotations

import numpy as np
import pytest

import pathspace as ps
from pathspace import _native
from pathspace.estimators import connections
from pathspace.estimators.bdpt import BDPT
from pathspace.estimators.connections import Batch, light_samples
from pathspace.estimators.join_fused import light_sample_kernel
from pathspace.spectra import RGBColours, SpectralColours
from conftest import count_lanes, made_up_side, nothing_blocked, same_bits, scene_dict
from conftest import repository_scene as scene

DENSITIES = ("qs_fwd", "qs_rev", "qs_minus_rev", "pt_fwd", "pt_rev", "pt_minus_rev")


def two_sided_box() -> ps.Scene:
    """The Cornell box with its light emitting on both sides."""
    data = scene_dict("cornell-box", (24, 24))
    light = next(shape for shape in data["shapes"] if shape["name"] == "light")
    light["emitter"]["two_sided"] = True
    return ps.scene_from_dict(data)


def around_the_light(rng: np.random.Generator, n: int) -> np.ndarray:
    """n points (3, n) over and under the Cornell box's light (at y = 0.99, below the ceiling at y = 1)."""
    return np.stack([rng.uniform(-0.5, 0.5, n), rng.uniform(0.5, 1.5, n), rng.uniform(-0.5, 0.5, n)])


# The scenes compared, and where their made-up vertices lie (None: anywhere in the scene's bounds).
SCENES = {"cornell-box": (lambda: scene("cornell-box"), None), "two-sided light": (two_sided_box, around_the_light),
          "furnace": (lambda: scene("furnace"), None)}


@pytest.mark.parametrize("name, seed", [("cornell-box", 1), ("two-sided light", 2), ("furnace", 3)])
@pytest.mark.parametrize("occlusion", [True, False])
@pytest.mark.parametrize("technique", ["cosine", "uniform"])
def test_fused_light_samples_equal_numpy_on_extreme_vertices(name, seed, occlusion, technique, monkeypatch):
    """Every vertex's contribution and densities compared (without shadow rays, the blocked ones too)."""
    make_scene, place = SCENES[name]
    sc, rng, n = make_scene(), np.random.default_rng(seed), 8000
    eye = made_up_side(sc, rng, n, 3, None if place is None else place(rng, n))
    eye.u[:, rng.random(n) < 0.01] = np.nan
    eye.u[0, rng.random(n) < 0.01] = 1.0          # the last emitting triangle, at the CDF's end
    if not occlusion:
        monkeypatch.setattr(connections, "segment_blocked", nothing_blocked)
        monkeypatch.setattr(connections, "light_sample_blocked",
                            lambda scene, p, eps, n, ls, lanes: np.zeros(lanes.size, bool))
    options = {"diffuse_sampling": technique}
    parts = {}
    for kernel in ("fused", "numpy"):
        fused, _ = light_sample_kernel(sc, RGBColours, options, kernel)
        assert (fused is not None) == (kernel == "fused")
        batch = Batch(sc, eye, eye, None, RGBColours, options, 100, np.array([0, n]), light_kernel=fused)
        with np.errstate(all="ignore"):
            parts[kernel] = (light_samples(batch), batch.rays, batch.nonfinite)
    (fused, rays_f, bad_f), (numpy, rays_n, bad_n) = parts["fused"], parts["numpy"]
    assert (rays_f, bad_f) == (rays_n, bad_n) and bad_f > 0 and fused.count > (1500 if not occlusion else 300)
    for density in ("qs_rev", "pt_minus_rev"):   # the extremes reach zero and positive densities
        values = getattr(fused, density)
        assert (values > 0).any() and (values == 0).any(), density
    # a contribution needs the light to face the vertex: emission toward it, from a point of positive area
    assert not np.isfinite(fused.pt_minus_rev).all() and (fused.pt_rev > 0).all() and (fused.qs_fwd > 0).all()
    for field in ("value", "raster", "lane", "s", "t", "flags", *DENSITIES):
        same_bits(getattr(fused, field), getattr(numpy, field), field)


def test_two_sided_lights_reach_vertices_on_both_sides():
    """A two-sided light sends light samples to made-up vertices on both of its sides (so that the comparison
    above covers both sides of the emission density)."""
    sc = two_sided_box()
    assert sc.lights.area.two_sided.all()
    rng, n = np.random.default_rng(2), 4000
    eye = made_up_side(sc, rng, n, 3, around_the_light(rng, n))
    fused, _ = light_sample_kernel(sc, RGBColours, {}, "fused")
    joined = fused(eye, np.arange(n))
    side = np.einsum("ij,ij->j", joined.normal.astype(np.float64), eye.p.astype(np.float64) - joined.point)
    lit = (joined.value > 0).any(axis=0)
    assert (lit & (side > 0)).sum() > 100 and (lit & (side < 0)).sum() > 100


def test_fused_bdpt_equals_numpy_with_a_thin_lens(monkeypatch):
    """A thin lens: the light samples joined in C, the lens samples in NumPy (their segments' far ends on the lens
    indexed on their own); the whole image bit for bit."""
    sc = scene("cornell-box-thin-lens")
    light_joins = count_lanes(monkeypatch, "join_light_samples", 9)
    fused = ps.render(sc, "bdpt", spp=2, seed=3, threads=1)
    assert light_joins[0] > 0
    numpy = ps.render(sc, "bdpt", spp=2, seed=3, threads=1, kernel="numpy")
    assert light_joins[0] > 0 and fused.stats["rays"] == numpy.stats["rays"]
    same_bits(fused.image, numpy.image)


# -- what the kernel leaves to NumPy, and its refusals -------------------------------------------------------

def test_scenes_and_settings_the_kernel_does_not_serve_say_why():
    box = scene("cornell-box")
    cases = [
        (scene("veach-mis"), RGBColours, "fused", "material 'plate1' is conductor"),
        (scene("cornell-box-point-light"), RGBColours, "fused", "lights other than area lights"),
        (box, SpectralColours(np.full((4, 1), 550.0), None, None), "fused", "spectral"),
        (box, RGBColours, "numpy", "kernel='numpy'"),
    ]
    for sc, colours, kernel, reason in cases:
        fused, why = light_sample_kernel(sc, colours, {}, kernel)
        assert fused is None and reason in why
    assert light_sample_kernel(scene("cornell-box-thin-lens"), RGBColours, {}, "fused")[0] is not None
    plan = BDPT().plan(scene("cornell-box-point-light"))
    assert "camera vertices joined to light samples in NumPy (lights other than area lights)" in plan
    assert ("camera vertices joined to light samples in one C pass (a fused kernel) in RGB, in NumPy when spectral"
            in BDPT().plan(box))


def kernel_args(k: int = 3):
    sc = scene("cornell-box")
    fused, _ = light_sample_kernel(sc, RGBColours, {}, "fused")
    v = 4
    side = [np.ones((3, v), np.float32)] * 3 + [np.ones((3, v)), np.zeros(v, np.int64)] + [np.ones(v)] * 3
    return [*side, np.full((3, v), 0.5), np.arange(k, dtype=np.int64), fused.diffuse, fused.reflectance,
            *fused.lights, 0]


@pytest.mark.parametrize("position, value, error, match", [
    (9, np.array([0, 4, 1]), IndexError, r"z\[1\] is not a vertex"),
    (9, np.array([-1, 0, 1]), IndexError, r"z\[0\] is not a vertex"),
    (4, np.full(4, 99), IndexError, r"z\[0\] has no diffuse material"),
    (4, np.array([0, -1, 0, 0]), IndexError, r"z\[1\] has no diffuse material"),
    (0, np.ones((3, 5), np.float32), ValueError, "the camera subpaths' .* must agree"),
    (7, np.ones(5), ValueError, "the camera subpaths' .* must agree"),
    (8, np.full((2, 4), 0.5), ValueError, "u must have at least 3 rows"),
    (8, np.full((3, 5), 0.5), ValueError, "u must have at least 3 rows and a column per camera vertex"),
    (11, np.ones((3, 1)), ValueError, r"diffuse \(M,\) and reflectance \(3, M\) must agree"),
    (12, np.ones((12, 2), np.float32), ValueError, r"table \(13, E\)"),
    (16, np.ones(3), ValueError, r"table \(13, E\)"),
    (17, np.ones((3, 3)), ValueError, r"radiance \(3, E\) must agree"),
    (3, np.ones((3, 4), np.float32), TypeError, "beta"),
    (8, np.full((3, 4), 0.5, np.float32), TypeError, "u"),
    (18, 2, ValueError, r"technique must be 0 \(cosine\) or 1 \(uniform\), got 2"),
])
def test_join_light_samples_refuses_bad_arguments(position, value, error, match):
    args = kernel_args()
    args[position] = value
    with pytest.raises(error, match=match):
        _native.join_light_samples(*args)


def test_join_light_samples_refuses_a_material_that_is_not_diffuse():
    args = kernel_args()
    args[10] = np.zeros_like(args[10])
    with pytest.raises(IndexError, match=r"z\[0\] has no diffuse material"):
        _native.join_light_samples(*args)


def test_join_light_samples_refuses_no_lights():
    args = kernel_args()
    args[12:18] = [np.zeros((13, 0), np.float32), np.zeros(0), np.zeros(0, bool), np.zeros(0), np.zeros(0),
                   np.zeros((3, 0))]
    with pytest.raises(ValueError, match="E >= 1"):
        _native.join_light_samples(*args)


def test_join_light_samples_takes_no_vertices():
    out = _native.join_light_samples(*kernel_args(0))
    assert out[0].shape == (3, 0) and out[2].shape == (3, 0) and out[3].shape == (3, 0)
    assert all(a.shape == (0,) for a in (out[1], *out[4:]))
