"""Views of subpath vertices: what connections gather is the vertices' own data, however a view was narrowed."""
from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np

from pathspace.estimators.subpaths import FIELDS, Subpaths, Vertices


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
