"""Metropolis light transport (PSSMLT over PT and BDPT, MMLT) renders the image BDPT renders.

MLT's passes are correlated, so its error is estimated from independent renders (seeds): block means per
render, their spread across renders (Student's t with renders - 1 degrees of freedom, Sidak-corrected
over the block-channels).  The global brightness is the bootstrap's estimate b: the renders' mean
luminance must lie within 0.5% of BDPT's beyond three standard errors (and the error must be small enough
for that to mean something).  Further: the brightness does not depend on the seed or the bootstrap size
beyond its stated error; the share of the energy in the light's pixels does not drift with the bootstrap
size; no chain stays stuck; checkpoints, time budgets, spectral renders and bad parameters.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import pathspace as ps
from conftest import scene_dict
from pathspace.estimators.bootstrap import GROUPS
from pathspace.estimators.metropolis import contribution_function
from pathspace.estimators.workers import PIECE
from pathspace.spectra import RGBMode

ALPHA = 1e-3
MAX_DEPTH = 8
RESOLUTION = (16, 16)
Y = contribution_function("luminance", RGBMode())

# (name, estimator, parameters): every Metropolis variant; bootstrap sizes give standard errors of b
# around 0.3-0.6% per render on the 16 x 16 Cornell box (PT's samples are the noisiest).
VARIANTS = [("pssmlt-pt", "pssmlt", {"bootstrap": 1 << 18}),
            ("pssmlt-bdpt", "pssmlt", {"over": "bdpt", "bootstrap": 1 << 15}),
            ("mmlt", "mmlt", {"bootstrap": 1 << 14})]
SLOW_BOOTSTRAP = {"pssmlt-pt": 1 << 18, "pssmlt-bdpt": 1 << 17, "mmlt": 1 << 18}


def scene(name: str, resolution=RESOLUTION) -> ps.Scene:
    return ps.scene_from_dict(scene_dict(name, resolution), source=f"{name}-{resolution[0]}")


_REFERENCES: dict = {}


def reference(name: str) -> ps.RenderResult:
    """BDPT at MAX_DEPTH, rendered once per session."""
    if name not in _REFERENCES:
        _REFERENCES[name] = ps.render(scene(name), "bdpt", spp=4096, seed=1, max_depth=MAX_DEPTH)
    return _REFERENCES[name]


def renders(name: str, estimator: str, params: dict, count: int, spp: int = 32, first_seed: int = 10) -> list:
    return [ps.render(scene(name), estimator, spp=spp, seed=first_seed + k, max_depth=MAX_DEPTH, chains=4096,
                      **params) for k in range(count)]


def luminance(image: np.ndarray) -> np.ndarray:
    return Y(image.reshape(-1, 3).T).reshape(image.shape[:2])


def blocks(image: np.ndarray, block: int) -> np.ndarray:
    h, w, c = image.shape
    return image.reshape(h // block, block, w // block, block, c).mean(axis=(1, 3))


def luminance_and_error(result: ps.RenderResult) -> tuple[float, float]:
    """The mean luminance of an RGB render with independent passes, and a bound on its standard error (the
    channels' errors added, as if perfectly correlated)."""
    sd = luminance(np.sqrt(result.variance))
    return float(luminance(result.image).mean()), float(np.sqrt((sd ** 2).sum()) / sd.size)


def check_blocks(results: list, ref: ps.RenderResult, block: int = 4) -> None:
    """Block-wise t-test of independent Markov-chain renders against the reference."""
    count = len(results)
    per_render = np.stack([blocks(r.image, block) for r in results])
    mean, var = per_render.mean(axis=0), per_render.var(axis=0, ddof=1) / count
    ref_mean, ref_var = blocks(ref.image, block), blocks(ref.variance, block) / block ** 2
    t = (mean - ref_mean) / np.sqrt(var + ref_var)
    critical = stats.t.isf(ALPHA / (2 * t.size), count - 1)
    assert np.abs(t).max() < critical, f"max |t| = {np.abs(t).max():.2f} (critical {critical:.2f})"


def check_brightness(y: np.ndarray, ref: ps.RenderResult) -> None:
    """The mean luminance ``y`` of independent renders lies within 0.5% of the reference's beyond three standard
    errors (and the error is small enough for that to mean something)."""
    ref_y, ref_error = luminance_and_error(ref)
    error = np.sqrt(y.var(ddof=1) / y.size + ref_error ** 2)
    assert error < 0.004 * ref_y, f"the brightness error {error / ref_y:.2%} is too large to test 0.5%"
    excess = max(abs(y.mean() - ref_y) - 3 * error, 0.0)
    assert excess < 0.005 * ref_y, f"mean Y {y.mean():.5f} vs BDPT {ref_y:.5f} (error {error:.5f})"


def check_agreement(results: list, ref: ps.RenderResult, block: int = 4) -> None:
    """Block-wise agreement of independent MLT renders with the reference, and the global brightness: the
    renders' mean luminance is their bootstrap's b."""
    check_blocks(results, ref, block)
    b = np.array([r.stats["metropolis"]["brightness"] for r in results])
    np.testing.assert_allclose([luminance(r.image).mean() for r in results], b, rtol=1e-9)
    check_brightness(b, ref)


@pytest.mark.parametrize("label,estimator,params", VARIANTS, ids=[v[0] for v in VARIANTS])
def test_mlt_agrees_with_bdpt_on_the_cornell_box(label, estimator, params):
    results = renders("cornell-box", estimator, params, 6)
    check_agreement(results, reference("cornell-box"))
    for r in results:
        assert r.stats["nonfinite"] == 0 and r.stats["nonfinite_contributions"] == 0
        assert r.stats["metropolis"]["longest_rejection_run"] < 100


@pytest.mark.slow
@pytest.mark.parametrize("name", ["cornell-box", "cornell-box-specular"])
@pytest.mark.parametrize("label,estimator,params", VARIANTS, ids=[v[0] for v in VARIANTS])
def test_mlt_agrees_with_bdpt_slow(name, label, estimator, params):
    params = {**params, "bootstrap": SLOW_BOOTSTRAP[label]}   # the glass box's brightness is noisier
    results = renders(name, estimator, params, 12, spp=64)
    check_agreement(results, reference(name))
    for r in results:
        assert r.stats["metropolis"]["longest_rejection_run"] < 300


def light_share(image: np.ndarray, light: np.ndarray) -> float:
    y = luminance(image)
    return float(y[light].sum() / y.sum())


@pytest.mark.parametrize("label,estimator,params",
                         [VARIANTS[0], VARIANTS[2], pytest.param("mlt", "mlt", {"direct": 0}, marks=pytest.mark.slow)],
                         ids=["pssmlt-pt", "mmlt", "mlt"])  # path-space MLT's run takes a minute: slow
def test_brightness_and_light_share_do_not_drift_with_the_bootstrap_size(label, estimator, params):
    """Small and large bootstraps: every seed's brightness agrees with BDPT's within its stated error, and the
    light's share of the energy is the same (Welch's t-test over seeds, and within 1% beyond 3 standard
    errors).  A small bootstrap starts the chains from fewer distinct samples: the share is noisier, not
    shifted (pbrt-v3's MLT shifts it by several percent)."""
    ref = reference("cornell-box")
    light = luminance(ref.image) > 2.0   # pixels that see the light directly
    assert 0 < light.sum() < light.size // 4
    shares, brightness = {}, {}
    for size, count in ((1 << 13, 12), (1 << 15, 5)):
        results = renders("cornell-box", estimator, {**params, "bootstrap": size}, count, spp=16, first_seed=100)
        shares[size] = np.array([light_share(r.image, light) for r in results])
        brightness[size] = [(r.stats["metropolis"]["brightness"], r.stats["metropolis"]["brightness_standard_error"])
                            for r in results]
    for size, values in brightness.items():
        b, se = np.array(values).T
        # Each seed's b agrees with BDPT within its own stated error, which comes from GROUPS group means:
        # Student's t with GROUPS - 1 degrees of freedom.
        ref_y, ref_error = luminance_and_error(ref)
        z = (b - ref_y) / np.sqrt(se ** 2 + ref_error ** 2)
        dof = {r.stats["metropolis"]["brightness_degrees_of_freedom"] for r in results}
        assert dof == {GROUPS - 1}
        assert np.abs(z).max() < stats.t.isf(ALPHA / (2 * z.size * 2), GROUPS - 1), (size, z)
    small, large = shares[1 << 13], shares[1 << 15]
    t = stats.ttest_ind(small, large, equal_var=False)
    assert t.pvalue > ALPHA, (small, large)
    error = np.sqrt(small.var(ddof=1) / small.size + large.var(ddof=1) / large.size)
    assert error < 0.02 * large.mean(), "too noisy to see a drift of several percent"
    assert abs(small.mean() - large.mean()) < 3 * error + 0.01 * large.mean(), (small, large)


def test_checkpoint_equals_the_render_of_its_passes():
    snapshots = []
    params = dict(max_depth=MAX_DEPTH, chains=512, bootstrap=1 << 12, seed=3)
    ps.render(scene("cornell-box"), "mmlt", spp=6, checkpoints=[3], on_checkpoint=lambda c: snapshots.append(
        c.film.image().copy()), **params)
    shorter = ps.render(scene("cornell-box"), "mmlt", spp=3, **params)
    assert len(snapshots) == 1
    np.testing.assert_array_equal(snapshots[0], shorter.image)


def test_same_seed_same_image_and_stats_are_reported():
    a = ps.render(scene("cornell-box"), "pssmlt", spp=4, seed=5, chains=256, bootstrap=4096)
    b = ps.render(scene("cornell-box"), "pssmlt", spp=4, seed=5, chains=256, bootstrap=4096)
    np.testing.assert_array_equal(a.image, b.image)
    m = a.stats["metropolis"]
    assert m["chains"] == 256 and m["bootstrap"] == 4096 and m["steps_per_pass"] == 1
    assert m["mutations"] == 4 * 256 and m["mutations_per_second"] > 0
    assert 0 < m["acceptance"]["small"] <= 1 and 0 < m["acceptance"]["large"] <= 1
    assert m["brightness_standard_error"] > 0
    assert np.isnan(a.variance).all()   # correlated passes: no per-pixel variance
    assert "bootstrap" in " ".join(a.stats["plan"])


@pytest.mark.parametrize("estimator", ["pssmlt", "mmlt", "mlt"])
def test_images_do_not_depend_on_threads(estimator):
    """More chains than one group (workers.PIECE): groups, bootstrap batches and (with more pixels than a piece)
    mlt's pixel ranges of direct paths, alongside its chains, run on several threads, and the image is bit for bit
    that of one thread."""
    params = dict(spp=2, seed=7, max_depth=MAX_DEPTH, chains=PIECE + 1000, bootstrap=3 * (1 << 14) // 2)
    resolution = (136, 128) if estimator == "mlt" else (64, 72)
    one = ps.render(scene("cornell-box", resolution), estimator, threads=1, **params)
    two = ps.render(scene("cornell-box", resolution), estimator, threads=2, **params)
    np.testing.assert_array_equal(one.image, two.image)
    assert one.stats["metropolis"] == {**two.stats["metropolis"],
                                       "mutations_per_second": one.stats["metropolis"]["mutations_per_second"]}
    assert one.stats["rays"] == two.stats["rays"]


def test_time_budget():
    result = ps.render(scene("cornell-box"), "pssmlt", time=1.5, chains=256, bootstrap=2048, seed=1)
    assert result.stats["spp"] > 0 and np.isfinite(result.image).all()


def test_spectral_pssmlt_agrees_with_spectral_pt():
    """The wavelengths are part of the state: a spectral render's luminance agrees with the path tracer's."""
    s = scene("cornell-box-measured")
    results = [ps.render(s, "pssmlt", spp=16, seed=20 + k, spectral=True, max_depth=MAX_DEPTH, chains=2048,
                         bootstrap=1 << 15) for k in range(4)]
    assert all(r.stats["mode"] == "spectral" for r in results)
    ref = ps.render(s, "pt", spp=1024, seed=1, spectral=True, max_depth=MAX_DEPTH)
    y = np.array([r.xyz[..., 1].mean() for r in results])
    ref_y = ref.xyz[..., 1].mean()
    ref_error = np.sqrt(ref.film.variance(np.array([[0.0, 1.0, 0.0]])).sum()) / ref.xyz[..., 1].size
    error = np.sqrt(y.var(ddof=1) / y.size + ref_error ** 2)
    assert abs(y.mean() - ref_y) < 4 * error + 0.005 * ref_y, (y, ref_y, error)


@pytest.mark.parametrize("estimator,params,field", [
    ("pssmlt", {"chains": 0}, "chains"), ("pssmlt", {"bootstrap": -1}, "bootstrap"),
    ("pssmlt", {"p_large": 1.5}, "p_large"), ("pssmlt", {"step_size": 0.5}, "step_size"),
    ("pssmlt", {"small_step": "cauchy"}, "small_step"), ("pssmlt", {"over": "lt"}, "over"),
    ("pssmlt", {"max_depth": -1}, "max_depth"), ("mmlt", {"max_depth": 0}, "max_depth"),
    ("mmlt", {"mis": "single"}, "mis"), ("pssmlt", {"contribution": "blue"}, "contribution"),
    ("pssmlt", {"rr": "sometimes"}, "rr")])
def test_bad_parameters_name_the_field(estimator, params, field):
    with pytest.raises(ValueError, match=field):
        ps.estimators.make_estimator(estimator, **params)


@pytest.mark.parametrize("kind", ["luminance", "xyz", "max"])
def test_every_contribution_function_renders_the_same_image(kind):
    """The contribution function changes where the chains go, not the image."""
    results = renders("cornell-box", "pssmlt", {"over": "bdpt", "bootstrap": 1 << 14, "contribution": kind}, 4,
                      spp=16, first_seed=40)
    ref = reference("cornell-box")
    mean = np.mean([r.image.mean(axis=(0, 1)) for r in results], axis=0)
    spread = np.std([r.image.mean(axis=(0, 1)) for r in results], axis=0, ddof=1) / 2
    assert np.all(np.abs(mean - ref.image.mean(axis=(0, 1))) < 5 * spread + 0.01 * mean), (mean, spread)
