"""The shared random walk: the vertex densities it records are the densities of the directions it sampled.

Subpaths store, for every vertex, the area density with which their own walk
generated it (``fwd``) and with which the opposite walk would have (``rev``),
both with the roulette's survival probability when the policy is local --
at every vertex, also before ``rr_depth``, so that the densities are one
function of the path whichever strategy formed it.
Here they are recomputed independently from the vertex positions and the
materials' own pdfs."""
from __future__ import annotations

import numpy as np
import pytest

import pathspace as ps
from pathspace.bsdfs import MaterialLanes, Surface
from pathspace.bsdfs.fresnel import fresnel_dielectric
from pathspace.estimators.base import Counters
from pathspace.estimators.bidirectional import STREAMS
from pathspace.estimators.control import RenderControl
from pathspace.estimators.subpaths import SURFACE
from pathspace.estimators.walk import Dimensions
from pathspace.sampler import StreamSamplers
from pathspace.spectra import RGBColours, RGBMode
from conftest import scene_dict


def test_dimensions_name_the_rows_in_order():
    dims = Dimensions(light=3, bsdf=3) + Dimensions(roulette=1)
    u = np.arange(14.0).reshape(7, 2)
    parts = dims.split(u)
    assert dims.size == 7
    np.testing.assert_array_equal(parts.bsdf, u[3:6])
    np.testing.assert_array_equal(parts.roulette, u[6:7])


def subpaths(name, **params):
    scene = ps.scene_from_dict(scene_dict(name, (32, 32)))
    bdpt = ps.estimators.make_estimator("bdpt", **params)
    samplers = {stream: StreamSamplers(3).open([(0, 0, code)], [1024]) for stream, code in STREAMS.items()}
    batch, _ = bdpt._subpaths(scene, RGBMode(), np.arange(1024), samplers, np.array([0, 1024]), Counters(), RenderControl())
    return scene, bdpt, batch


def walk_densities(scene, sub, roulette, opposite=None):
    """(fwd, rev) of every surface vertex whose neighbours are surface vertices, recomputed with the survival
    ``roulette(vertices)`` of this walk and ``opposite(vertices)`` of the opposite one (default: the same)."""
    rows = []
    for i in range(sub.count):
        lane, index = sub.lane[i], sub.index[i]
        nxt = i + 1
        if index < 2 or nxt >= sub.count or sub.lane[nxt] != lane or sub.kind[i] != SURFACE or sub.kind[nxt] != SURFACE:
            continue
        prev, here = i - 1, i
        if sub.delta[prev] or sub.delta[here] or sub.kind[prev] != SURFACE:
            continue
        rows.append((prev, here, nxt))
    prev, here, nxt = (np.array(column) for column in zip(*rows))
    # float32 positions of nearly coincident vertices (in corners) do not give their distance to 1e-4, and a
    # ray leaves from its vertex moved off the surface by the error bound (~1e-6): at 0.02 apart the line
    # between two vertices and the sampled direction differ by ~1e-4 rad, up to 1e-3 in grazing cosines
    apart = np.minimum(np.linalg.norm(sub.p[:, nxt] - sub.p[:, here], axis=0),
                       np.linalg.norm(sub.p[:, prev] - sub.p[:, here], axis=0)) > 0.02
    prev, here, nxt = prev[apart], here[apart], nxt[apart]

    def pdf(at, toward, came_from):
        p = sub.p.astype(np.float64)
        wi = p[:, toward] - p[:, at]
        wi /= np.linalg.norm(wi, axis=0)
        wo = p[:, came_from] - p[:, at]
        wo /= np.linalg.norm(wo, axis=0)
        lanes = MaterialLanes(scene.materials, sub.material[at], RGBColours, {"diffuse_sampling": "cosine"})
        return lanes.eval(Surface.facing(sub.n[:, at], -wo.astype(np.float32)), wi.astype(np.float32))[1]

    def area(pdf_sa, frm, to):
        d = sub.p[:, to].astype(np.float64) - sub.p[:, frm]
        dist2 = (d * d).sum(0)
        return pdf_sa * np.abs((sub.n[:, to] * d).sum(0)) / np.sqrt(dist2) / dist2

    fwd = area(pdf(here, nxt, prev) * roulette(here), here, nxt)                # the walk: prev -> here -> nxt
    rev = area(pdf(here, prev, nxt) * (opposite or roulette)(here), here, prev)  # the opposite: nxt -> here -> prev
    return nxt, fwd, prev, rev


@pytest.mark.parametrize("params, local", [({"rr": "albedo"}, True), ({"rr": "fixed", "rr_probability": 0.3}, True),
                                           ({"rr": "albedo", "rr_depth": 3}, True),
                                           ({"rr": "throughput"}, False), ({"rr": "off"}, True),
                                           ({"rr": "albedo", "mis_roulette": "none"}, False)])
def test_recorded_densities_are_the_sampled_ones(params, local):
    """The vertex densities the walks record are those they sampled with, roulette included where the MIS
    densities hold it (mis_roulette "both"; "none": no walk's); recomputed from the vertices."""
    params = {"mis_roulette": "both", **params}
    scene, bdpt, batch = subpaths("cornell-box", **params)
    for sub in (batch.eye, batch.light):
        def roulette(v):
            if not local or params["rr"] == "off":
                return np.ones(v.size)
            if params["rr"] == "fixed":
                return np.full(v.size, 0.7)
            return scene.materials.albedo[sub.material[v]]
        nxt, fwd, prev, rev = walk_densities(scene, sub, roulette)
        assert nxt.size > 100
        np.testing.assert_allclose(sub.fwd[nxt], fwd, rtol=2e-3)
        np.testing.assert_allclose(sub.rev[prev], rev, rtol=2e-3)
        np.testing.assert_array_equal(sub.q[nxt - 1], roulette(nxt - 1))


def test_recorded_densities_leave_out_the_light_walks_roulette_by_default():
    """BDPT's default (mis_roulette "auto", which is "camera" under the default albedo roulette): the camera
    walk's survival in the densities either walk records for it, the light walk's in none."""
    scene, bdpt, batch = subpaths("cornell-box")
    assert bdpt.mis_roulette == "auto" and bdpt.roulette.in_mis and not bdpt.light_roulette.in_mis
    albedo = lambda sub: lambda v: scene.materials.albedo[sub.material[v]]  # noqa: E731
    ones = lambda v: np.ones(v.size)  # noqa: E731
    for sub, mine, theirs in ((batch.eye, albedo(batch.eye), ones), (batch.light, ones, albedo(batch.light))):
        nxt, fwd, prev, rev = walk_densities(scene, sub, mine, theirs)
        assert nxt.size > 100
        np.testing.assert_allclose(sub.fwd[nxt], fwd, rtol=2e-3)
        np.testing.assert_allclose(sub.rev[prev], rev, rtol=2e-3)
        np.testing.assert_array_equal(sub.q[nxt - 1], mine(nxt - 1))


@pytest.mark.parametrize("kernel", ["fused", "numpy"])
def test_densities_through_specular_vertices_keep_their_geometry(kernel):
    """Around a specular vertex x_i (mirror, glass) the walks record Veach's densities with the deltas left out:
    x_{i+1} has P G(x_i, x_{i+1}) (eta_next / eta_prev)^2 and x_{i-1} the reverse P G(x_{i-1}, x_i), P the
    probability of the lobe taken (1, or Fresnel's F or 1 - F), recomputed here from the vertices: no density
    0 that MIS would read as 1 (subpaths' module docstring)."""
    scene, _, batch = subpaths("cornell-box-specular", mis_roulette="none", kernel=kernel)
    ior = np.array([getattr(m, "ior", 1.0) for m in scene.materials.materials], dtype=np.float64)
    checked = 0
    for sub in (batch.eye, batch.light):
        here = np.flatnonzero(sub.delta & (sub.kind == SURFACE))
        here = here[(here >= 1) & (here + 1 < sub.count)]
        here = here[(sub.lane[here - 1] == sub.lane[here]) & (sub.lane[here + 1] == sub.lane[here])]
        p, n = sub.p.astype(np.float64), sub.n.astype(np.float64)
        to_prev, to_next = p[:, here - 1] - p[:, here], p[:, here + 1] - p[:, here]
        d_prev, d_next = np.linalg.norm(to_prev, axis=0), np.linalg.norm(to_next, axis=0)
        keep = (np.minimum(d_prev, d_next) > 0.02) & (sub.kind[here - 1] == SURFACE) & (sub.kind[here + 1] == SURFACE)
        here, to_prev, to_next, d_prev, d_next = (here[keep], to_prev[:, keep] / d_prev[keep],
                                                  to_next[:, keep] / d_next[keep], d_prev[keep], d_next[keep])
        cos_in, cos_out = (n[:, here] * to_prev).sum(0), (n[:, here] * to_next).sum(0)
        reflected = np.sign(cos_in) == np.sign(cos_out)
        eta = np.where(cos_in > 0, ior[sub.material[here]], 1.0 / ior[sub.material[here]])   # eta_next / eta_prev
        fresnel = fresnel_dielectric(np.abs(cos_in), eta)[0]
        glass = ior[sub.material[here]] != 1.0
        lobe = np.where(glass, np.where(reflected, fresnel, 1.0 - fresnel), 1.0)
        eta2 = np.where(glass & ~reflected, eta * eta, 1.0)
        cos_next = np.abs((n[:, here + 1] * to_next).sum(0))
        cos_prev = np.abs((n[:, here - 1] * to_prev).sum(0))
        np.testing.assert_allclose(sub.fwd[here + 1], lobe * eta2 * np.abs(cos_out) * cos_next / d_next ** 2,
                                   rtol=2e-3)
        np.testing.assert_allclose(sub.rev[here - 1], lobe * np.abs(cos_in) * cos_prev / d_prev ** 2, rtol=2e-3)
        checked += here.size
        assert (~reflected & glass).any() and (reflected & ~glass).any()
    assert checked > 200


def test_an_emptied_wavefront_keeps_its_dtypes_through_split_and_extend():
    """Regression (CI failure): a wavefront emptied, split and extended again once turned a field into an
    object array that Embree refused."""
    from pathspace.estimators.wavefront import Lanes

    lanes = Lanes(("depth", "origin"), depth=np.arange(4, dtype=np.int32), origin=np.zeros((3, 4), np.float32))
    lanes.keep(np.array([], dtype=np.int64))
    deep = lanes.split(np.array([], dtype=np.int64))
    deep.extend(Lanes(("depth", "origin"), depth=np.ones(3, np.int32), origin=np.full((3, 3), 0.5, np.float32)))
    assert deep.origin.dtype == np.float32 and deep.depth.dtype == np.int32
    np.testing.assert_array_equal(deep.origin, np.full((3, 3), 0.5))
