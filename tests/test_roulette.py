"""Russian roulette: one vocabulary for every estimator, and survival probabilities that mean one thing."""
from __future__ import annotations

import numpy as np
import pytest

import pathspace as ps
from pathspace.bsdfs import Dielectric, Diffuse, MaterialTable, Mirror, Phong
from pathspace.roulette import ALBEDO_TRAPPED_DEPTH, POLICIES, SPECULAR_CONTINUATION, TRAPPED_DEPTH, RussianRoulette
from conftest import scene_dict


def test_survival_probabilities_of_each_policy():
    depth = np.array([1, 2, 3, 4])
    throughput = np.array([[0.2, 3.0, 0.5, 0.9], [0.1, 0.1, 0.7, 0.0], [0.0, 0.0, 0.0, 0.3]])
    albedo = np.array([0.8, 0.5, 0.3, 1.2])
    assert RussianRoulette("off", 1).survival(depth, throughput, albedo) is None
    assert RussianRoulette("fixed", 5).survival(depth, throughput, albedo) is None  # nobody at depth 5 yet
    np.testing.assert_array_equal(RussianRoulette("fixed", 3, probability=0.25).survival(depth, None, albedo),
                                  [1.0, 1.0, 0.75, 0.75])
    np.testing.assert_array_equal(RussianRoulette("albedo", 2).survival(depth, None, albedo), [1.0, 0.5, 0.3, 1.0])
    np.testing.assert_array_equal(RussianRoulette("throughput", 1, cap=0.95).survival(depth, throughput, albedo),
                                  [0.2, 0.95, 0.7, 0.9])


def test_throughput_survival_at_specular_vertices_is_at_most_their_albedo():
    """A walk trapped in glass by total internal reflection keeps throughput 1; at specular vertices past
    TRAPPED_DEPTH the survival is capped by their albedo (SPECULAR_CONTINUATION), elsewhere by rr_cap only."""
    depth = np.array([TRAPPED_DEPTH, TRAPPED_DEPTH, TRAPPED_DEPTH, TRAPPED_DEPTH - 1, 6])
    throughput = np.array([[1.0, 1.0, 0.5, 1.0, 0.7]] * 3)
    albedo = np.array([SPECULAR_CONTINUATION, 0.886, SPECULAR_CONTINUATION, SPECULAR_CONTINUATION,
                       SPECULAR_CONTINUATION])
    specular = np.array([True, False, True, True, True])
    roulette = RussianRoulette("throughput", 5)
    np.testing.assert_array_equal(roulette.survival(depth, throughput, albedo, specular),
                                  [SPECULAR_CONTINUATION, 1.0, 0.5, 1.0, 0.7])
    np.testing.assert_array_equal(roulette.survival(depth, throughput, albedo), [1.0, 1.0, 0.5, 1.0, 0.7])


def test_albedo_survival_at_specular_vertices_is_one_until_the_trapped_depth():
    """Specular vertices (capped at SPECULAR_CONTINUATION in the albedo table) survive with 1 on walks shorter than
    ALBEDO_TRAPPED_DEPTH, then with their capped albedo; other vertices with their albedo at every depth.  MIS sees
    1 at specular vertices whatever the depth (exact for the shorter walks)."""
    depth = np.array([ALBEDO_TRAPPED_DEPTH - 1, ALBEDO_TRAPPED_DEPTH, ALBEDO_TRAPPED_DEPTH - 1, 3, 1])
    albedo = np.array([SPECULAR_CONTINUATION, SPECULAR_CONTINUATION, 0.886, SPECULAR_CONTINUATION, 0.5])
    specular = np.array([True, True, False, True, False])
    roulette = RussianRoulette("albedo", 2)
    assert roulette.trapped_depth == ALBEDO_TRAPPED_DEPTH < TRAPPED_DEPTH == RussianRoulette("throughput").trapped_depth
    np.testing.assert_array_equal(roulette.survival(depth, None, albedo, specular),
                                  [1.0, SPECULAR_CONTINUATION, 0.886, 1.0, 1.0])
    np.testing.assert_array_equal(roulette.survival(depth, None, albedo), [SPECULAR_CONTINUATION] * 2 + [0.886] +
                                  [SPECULAR_CONTINUATION, 1.0])
    np.testing.assert_array_equal(roulette.mis_survival(albedo, specular), [1.0, 1.0, 0.886, 1.0, 0.5])
    fixed = RussianRoulette("fixed", 1, probability=0.25)   # the other local policy: specular vertices as any other
    np.testing.assert_array_equal(fixed.survival(depth, None, albedo, specular), np.full(5, 0.75))
    np.testing.assert_array_equal(fixed.mis_survival(albedo, specular), np.full(5, 0.75))


def test_paths_trapped_in_glass_end():
    """The tessellated glass sphere of the specular box traps some paths by total internal reflection;
    with survival 1 they ran for thousands of segments (4957 here), each a wavefront step of a few lanes."""
    result = ps.render(ps.scene_from_dict(scene_dict("cornell-box-specular", (64, 64))), "pt", spp=8, seed=1)
    assert result.stats["longest_subpath"] < TRAPPED_DEPTH + 150  # 0.9^150: 1e-7 of the trapped walks
    result = ps.render(ps.scene_from_dict(scene_dict("cornell-box-specular", (64, 64))), "bdpt", spp=8, seed=1)
    assert result.stats["longest_subpath"] < ALBEDO_TRAPPED_DEPTH + 150   # "albedo" on the subpaths


def test_only_throughput_depends_on_the_walk():
    assert [RussianRoulette(p).local for p in POLICIES] == [True, True, True, False]


def test_material_albedo_bounds():
    table = MaterialTable(["white", "glossy", "mirror", "glass"],
                          [Diffuse((0.2, 0.8, 0.4)), Phong((0.3, 0.3, 0.3), (0.5, 0.6, 0.2), 10),
                           Mirror((1.0, 1.0, 1.0)), Dielectric(1.5)])
    np.testing.assert_allclose(table.albedo, [0.8, 0.9, SPECULAR_CONTINUATION, SPECULAR_CONTINUATION])


@pytest.mark.parametrize("estimator", ["pt", "lt", "bdpt"])
def test_every_estimator_takes_the_same_parameters_with_the_same_messages(estimator):
    make = ps.estimators.make_estimator
    made = make(estimator, rr="fixed", rr_depth=3, rr_probability=0.2, rr_cap=0.9)
    assert made.roulette == RussianRoulette("fixed", 3, 0.2, 0.9)
    for params, message in (({"rr": "sometimes"}, r"rr: expected one of \('off', 'fixed', 'albedo', 'throughput'\)"),
                            ({"rr_depth": 0}, "rr_depth: expected an integer >= 1, got 0"),
                            ({"rr_probability": 1.0}, r"rr_probability: expected a termination probability in \[0, 1\)"),
                            ({"rr_cap": 0.0}, r"rr_cap: expected a survival cap in \(0, 1\]"),
                            ({"max_depth": 0}, r"max_depth: expected -1 \(unbounded\) or an integer >= 1, got 0"),
                            ({"diffuse_sampling": "sideways"}, "diffuse_sampling: expected one of")):
        with pytest.raises(ValueError, match=message):
            make(estimator, **params)


@pytest.mark.parametrize("policy", POLICIES)
def test_survival_left_out_of_the_mis_densities_samples_the_same(policy):
    """in_mis=False changes what MIS sees (q = 1), never the walk's own survival probabilities."""
    albedo, depth = np.array([0.2, 0.9, 1.0, 0.5]), np.array([1, 2, 3, 7])
    throughput = np.array([[0.3, 0.8, 1.2, 0.05]] * 3)
    kept, left = RussianRoulette(policy, 2, 0.3, 0.9), RussianRoulette(policy, 2, 0.3, 0.9, in_mis=False)
    assert kept.describe() == left.describe()
    sampled = kept.survival(depth, throughput, albedo)
    np.testing.assert_array_equal(left.survival(depth, throughput, albedo), sampled)
    np.testing.assert_array_equal(left.mis_survival(albedo), np.ones(4))
    expected = {"off": np.ones(4), "fixed": np.full(4, 0.7), "albedo": albedo, "throughput": np.ones(4)}[policy]
    np.testing.assert_array_equal(kept.mis_survival(albedo), expected)
    assert kept.samples_like(left) and left.samples_like(kept) and kept != left
    assert not kept.samples_like(RussianRoulette(policy, 2, 0.3 + 1e-9, 0.9, in_mis=False))  # beyond describe()'s
