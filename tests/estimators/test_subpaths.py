"""Views of subpath vertices: what connections gather is the vertices' own data, however a view was narrowed; light
vertices streamed to a light tracer are the vertices kept for BDPT."""
from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

import pathspace as ps
from conftest import CORNELL, sky_quad_scene
from pathspace.estimators.base import Counters
from pathspace.estimators.bidirectional import STREAMS, Bidirectional
from pathspace.estimators.control import RenderControl
from pathspace.estimators.lt import LightTracer
from pathspace.estimators.subpaths import FIELDS, Subpaths, Vertices, light_subpaths, stream_light_vertices
from pathspace.sampler import StreamSamplers
from pathspace.spectra import RGBMode


def test_narrowed_views_gather_the_vertices_own_fields():
    rng = np.random.default_rng(0)
    count = 50
    fields = {name: rng.random((3, count)) if name in ("p", "n", "beta") else rng.random(count) for name in FIELDS}
    view = Vertices(SimpleNamespace(**fields), rng.permutation(count)[:30])
    gathered = view.p.copy(), view.fwd.copy()   # gathered by the wide view: the narrowed views take from them
    first, second = np.array([3, 0, 7, 29, 11]), np.array([4, 1, 2])
    once = view.keep(first)
    np.testing.assert_array_equal(once.p, gathered[0][:, first])
    twice = once.keep(second)
    vertices = view.v[first][second]
    for name in ("p", "fwd", "n", "q"):     # n and q were never gathered by the wider views
        np.testing.assert_array_equal(getattr(twice, name), np.take(fields[name], vertices, axis=-1))
    assert twice.size == 3 and "beta" not in twice.__dict__ and "n" not in view.__dict__


def test_subpaths_know_where_they_are_specular():
    """``Subpaths.any_specular``: whether a specular vertex lies in a range of each lane's vertices."""
    delta = np.array([0, 1, 0, 0, 0, 1, 0, 0, 0, 1], bool)   # lane 0: vertices 0 .. 2, lane 1: 0 .. 4, lane 2: 0 .. 1
    fields = dict.fromkeys(f.name for f in dataclasses.fields(Subpaths))
    sub = Subpaths(**{**fields, "offset": np.array([0, 3, 8, 10]), "delta": delta})
    lane = np.array([0, 0, 0, 1, 1, 1, 1, 2, 2])
    last = np.array([0, 1, 2, 1, 2, 3, -1, 0, 1])
    assert sub.any_specular(lane, 1, last).tolist() == [False, True, True, False, True, True, False, False, True]
    assert sub.any_specular(np.array([1, 1]), 3, np.array([3, 4])).tolist() == [False, False]


def _samplers(count: int) -> dict:
    return {stream: StreamSamplers(9).open([(0, 0, code)], [count]) for stream, code in STREAMS.items()}


def _light_walk(count: int):
    """What a light tracer's walks of ``count`` lanes on the Cornell box share, and their sampler."""
    samplers = _samplers(count)
    _, settings = LightTracer()._walk_settings(ps.load_scene(CORNELL), RGBMode(), samplers, Counters(),
                                                RenderControl())
    return settings, samplers["light"]


def test_streamed_light_vertices_are_the_kept_ones():
    count, chunk = 4096, 500
    settings, sampler = _light_walk(count)
    kept, _ = light_subpaths(settings, count, sampler, False)
    settings, sampler = _light_walk(count)   # the same numbers again
    calls = []
    terminated = stream_light_vertices(settings, count, sampler, calls.append, chunk=chunk)
    np.testing.assert_array_equal(terminated, kept.terminated)
    assert calls[0].index.tolist() == [0] * count and calls[0].lane.tolist() == list(range(count))
    sizes = [call.lane.size for call in calls[1:]]
    assert len(sizes) > 2 and min(sizes[:-1]) >= chunk and max(sizes) < count   # later depths, joined in chunks
    assert all(call.fwd is None and call.rev is None for call in calls)  # no densities
    assert calls[0].offset.tolist() == list(range(count + 1)) and all(call.offset is None for call in calls[1:])
    lane, index = (np.concatenate([getattr(call, name) for call in calls]) for name in ("lane", "index"))
    order = np.lexsort((index, lane))   # kept subpaths: lane after lane, by index
    assert index.max() > 10
    for name in ("lane", "index", "p", "n", "eps", "wo", "beta", "delta", "kind", "material", "entity",
                 "infinite", "u"):
        streamed = np.concatenate([getattr(call, name) for call in calls], axis=-1)
        np.testing.assert_array_equal(np.take(streamed, order, axis=-1), getattr(kept, name), err_msg=name)


def test_walks_with_densities_do_not_stream():
    settings, sampler = _light_walk(64)
    settings.densities = True
    with pytest.raises(ValueError, match="walks that keep densities cannot stream"):
        stream_light_vertices(settings, 64, sampler, lambda vertices: None)


def test_no_lanes_stream_nothing():
    settings, sampler = _light_walk(0)
    calls = []
    assert stream_light_vertices(settings, 0, sampler, calls.append).size == 0
    assert [call.lane.size for call in calls] == [0]


def test_the_light_tracer_makes_while_walking_the_connections_of_kept_subpaths():
    count = 40_000    # vertices 0, then depths of more than STREAM_CHUNK vertices alone, then the last ones joined
    scene = ps.load_scene(CORNELL)
    lt = LightTracer()
    made = []
    for streamed in (True, False):
        counters = Counters()
        args = (scene, RGBMode(), np.arange(count) % scene.camera.pixel_count, _samplers(count), np.array([0, count]),
                counters, RenderControl())
        batch, _ = lt._subpaths(*args) if streamed else Bidirectional._subpaths(lt, *args)
        assert (batch.made is not None) == streamed
        parts = list(lt._contributions(batch))
        assert len(parts) > 3 if streamed else len(parts) == 1
        rows = {name: np.concatenate([getattr(part, name) for part in parts], axis=-1)
                for name in ("lane", "s", "t", "value", "raster", "flags")}
        order = np.lexsort((rows["s"], rows["lane"]))
        made.append({name: np.take(value, order, axis=-1) for name, value in rows.items()}
                    | {"rays": batch.rays, "counted rays": counters.rays, "longest": counters.longest})
    assert made[0]["lane"].size > count and made[0]["longest"] > 10
    for name, value in made[0].items():
        np.testing.assert_array_equal(value, made[1][name], err_msg=name)


@pytest.mark.parametrize("kernel", ["fused", "numpy"])
def test_walks_without_densities_carry_and_record_none(kernel, monkeypatch):
    """A light tracer's walks keep no density state per lane (q, the previous vertex's normal) and record no
    densities; BDPT's keep and record them."""
    from pathspace.estimators import subpaths

    fields, recorded = [], []
    vertex, add = subpaths._Growth._vertex, subpaths._Recorder.add

    def seen_vertex(self, *args, **kwargs):
        fields.append(self.walk.lanes.fields)
        return vertex(self, *args, **kwargs)

    def seen_add(self, *args, **kwargs):
        record = add(self, *args, **kwargs)
        recorded.append(set(record))
        return record

    monkeypatch.setattr(subpaths._Growth, "_vertex", seen_vertex)
    monkeypatch.setattr(subpaths._Recorder, "add", seen_add)
    scene = ps.load_scene(CORNELL, resolution=(8, 8))
    for estimator, densities in (("lt", False), ("bdpt", True)):
        fields.clear()
        recorded.clear()
        ps.render(scene, estimator, spp=1, threads=1, kernel=kernel)
        assert fields and recorded
        assert all(("q" in f and "prev_n" in f and "prev_infinite" in f) == densities for f in fields), estimator
        assert all(({"rev", "g_prev", "q", "q_rev"} <= names) == densities for names in recorded), estimator


def test_walks_without_densities_cannot_record_lens_hits_or_vertices_at_infinity():
    """Rays through a thin lens and vertices at infinity are recorded with their densities."""
    from pathspace.estimators.subpaths import SubpathSettings, camera_subpaths
    from pathspace.roulette import RussianRoulette
    from pathspace.sampler import ReplaySampler
    from pathspace.spectra import RGBColours

    thin_lens = ps.load_scene(CORNELL.parent.parent / "cornell-box-thin-lens" / "scene.toml", resolution=(8, 8))
    environment = sky_quad_scene()
    roulette = RussianRoulette("albedo", 1)
    for sc, walk in ((thin_lens, lambda settings, sampler: light_subpaths(settings, 4, sampler, True)),
                     (environment, lambda settings, sampler: camera_subpaths(settings, np.arange(4), sampler))):
        settings = SubpathSettings(sc, RGBColours, {}, roulette, roulette, 8, Counters(), RenderControl(),
                                   densities=False)
        with pytest.raises(ValueError, match="recorded with their densities"):
            walk(settings, ReplaySampler(np.full((4, 64), 0.5)))
