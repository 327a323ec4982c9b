"""The partition of path space between MLT's chains and BDPT (``explore='specular'``): both sides classify a
path alike, so their images add up to the whole.

First the classification of every BDPT connection, against the path's vertices listed strategy by strategy
(a lamp with a mirror finish, so that the vertex where a camera subpath finds the light is specular, and a
thin lens, whose strategies t = 0 end at the lens); then, per path length, the chains' energy (their bootstrap,
f = 0 without a specular vertex) against the energy BDPT leaves out on the same seeds.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import pathspace as ps
from conftest import scene_dict
from pathspace.estimators.base import Counters
from pathspace.estimators.bdpt import BDPT
from pathspace.estimators.bidirectional import STREAMS
from pathspace.estimators.control import RenderControl
from pathspace.estimators.partition import UnexploredBDPT, explored
from pathspace.estimators.path_mutations import fresh_paths
from pathspace.estimators.paths import Space
from pathspace.sampler import StreamSamplers
from pathspace.spectra import RGBMode

from .test_metropolis import ALPHA, luminance, scene

Y = np.array([0.2126, 0.7152, 0.0722])


def mirror_lamp() -> ps.Scene:
    """The specular box with a mirror-finished lamp: camera subpaths that find the light end on a specular vertex."""
    data = scene_dict("cornell-box-specular", (16, 16))
    next(shape for shape in data["shapes"] if shape["name"] == "light")["material"] = "mirror"
    return ps.scene_from_dict(data, source="mirror-lamp.toml")


def thin_lens_mirror() -> ps.Scene:
    """The thin-lens box with a mirror for a red wall: light subpaths reach the lens (t = 0) past specular vertices."""
    data = scene_dict("cornell-box-thin-lens", (16, 16))
    data["camera"]["aperture_radius"] = 0.5     # a wide lens, which light subpaths pass through often
    data["materials"]["mirror"] = {"type": "mirror", "reflectance": [0.95, 0.95, 0.95]}
    next(shape for shape in data["shapes"] if shape["material"] == "red")["material"] = "mirror"
    return ps.scene_from_dict(data, source="thin-lens-mirror.toml")


def strategy_vertices(batch, lane: int, s: int, t: int) -> list:
    """x_0 .. x_k of strategy (s, t) of ``lane`` as (subpaths, flat index) pairs; None for the vertices no subpath
    stores (a fresh light sample for s = 1, a fresh lens point for t = 1, the lens a light subpath passed for t = 0)."""
    light, eye = batch.light, batch.eye
    ys = [(light, light.offset[lane] + i) for i in range(s)]
    zs = [(eye, eye.offset[lane] + i) for i in range(t)]
    if s == 1:
        ys = [None]
    if t == 1:
        zs = [None]
    if t == 0:
        ys[-1] = None
    return ys + zs[::-1]


@pytest.mark.parametrize("make", [mirror_lamp, thin_lens_mirror], ids=["mirror-lamp", "thin-lens"])
def test_every_connection_is_classified_by_its_paths_vertices(make):
    scene, count, direct = make(), 4096, 2
    bdpt = BDPT(max_depth=6)
    samplers = {stream: StreamSamplers(5).open([(0, 0, code)], [count]) for stream, code in STREAMS.items()}
    batch, _ = bdpt._subpaths(scene, RGBMode(), np.arange(count) % 256, samplers, np.array([0, count]), Counters(),
                              RenderControl())
    owned, on_specular_lamp = {}, 0
    for part in bdpt._contributions(batch):
        found = explored(part, batch, direct)
        for lane, s, t, verdict in zip(part.lane, part.s, part.t, found):
            path = strategy_vertices(batch, lane, s, t)
            specular = any(vertex is not None and vertex[0].delta[vertex[1]] for vertex in path[1:-1])
            assert verdict == (len(path) - 1 > direct and specular), (lane, s, t)
            kind = (min(s, 2), min(t, 2))
            owned[kind] = owned.get(kind, 0) + int(verdict)
            on_specular_lamp += int(s == 0 and len(path) - 1 > direct and path[0][0].delta[path[0][1]])
    # The chains own connections of every kind of strategy: s = 0, 1, >= 2 against t = 1, >= 2 (and t = 0 through
    # the thin lens); s = 0 connections end on the mirror-finished lamp, which is x_0, not an interior vertex.
    kinds = {(0, 2), (1, 2), (2, 1), (2, 2)} | ({(2, 0)} if make is thin_lens_mirror else set())
    assert all(owned.get(kind, 0) > 0 for kind in kinds), owned
    assert make is thin_lens_mirror or on_specular_lamp > 0


def test_the_chains_energy_is_what_bdpt_leaves_out():
    """Per path length, the bootstrap's energy of the paths the chains own (f = 0 without a specular vertex) equals
    the energy BDPT loses when it leaves them out (the same seeds rendered with and without those paths).  A
    classification that forgot the light subpath's vertices is off by z = 28."""
    s = scene("cornell-box-specular")
    rng = np.random.default_rng(11)
    for length in (3, 4):
        count = 48000 // (length + 1)
        chains = [Y @ fresh_paths(Space(s, specular_only=True), np.full(count, length), length + 1,
                                  rng.random).weights().sum(axis=1) / count for _ in range(8)]
        left_out = []
        for seed in range(8):
            full = ps.render(s, "bdpt", spp=256, seed=seed, max_depth=length)
            rest = ps.render(s, UnexploredBDPT(max_depth=length, direct=length - 1), spp=256, seed=seed)
            left_out.append(luminance(full.image).mean() - luminance(rest.image).mean())
        energy, error = np.mean(chains), np.std(chains, ddof=1) / np.sqrt(8)
        bdpt, bdpt_error = np.mean(left_out), np.std(left_out, ddof=1) / np.sqrt(8)
        z = (energy - bdpt) / np.hypot(error, bdpt_error)
        assert abs(z) < stats.norm.isf(ALPHA / 4), (length, energy, bdpt, z)
        assert np.hypot(error, bdpt_error) < 0.05 * energy, "too noisy to test"
