/* pathspace._native: module definition. */
#include "native.h"
#include "shadow.h"

#ifdef __GLIBC__
#include <malloc.h>
#endif

#define NPY_NO_DEPRECATED_API NPY_2_0_API_VERSION
#define PY_ARRAY_UNIQUE_SYMBOL pathspace_native_ARRAY_API
#include <numpy/arrayobject.h>

static PyObject *default_thread_count(PyObject *module, PyObject *unused)
{
    (void)module;
    (void)unused;
    return PyLong_FromLong(ps_default_thread_count());
}

static PyObject *tune_allocator(PyObject *module, PyObject *args)
{
    (void)module;
    int mmap_threshold, trim_threshold;
    if (!PyArg_ParseTuple(args, "ii:tune_allocator", &mmap_threshold, &trim_threshold))
        return NULL;
    if (mmap_threshold <= 0 || trim_threshold <= 0) {
        PyErr_SetString(PyExc_ValueError, "thresholds must be positive byte counts (below 2**31)");
        return NULL;
    }
#ifdef __GLIBC__
    if (mallopt(M_MMAP_THRESHOLD, mmap_threshold) == 1 && mallopt(M_TRIM_THRESHOLD, trim_threshold) == 1)
        Py_RETURN_TRUE;
#endif
    Py_RETURN_FALSE;
}

static PyMethodDef module_methods[] = {
    {"load_embree", ps_load_embree, METH_VARARGS,
     "load_embree(path, config='')\n--\n\nOpen the Embree 4 shared library at `path` (dlopen, RTLD_LOCAL) and "
     "create the device used by every Accel.  Loading the same path twice is a no-op."},
    {"embree_loaded", ps_embree_loaded, METH_NOARGS,
     "embree_loaded()\n--\n\nPath of the loaded Embree library, or None."},
    {"tune_allocator", tune_allocator, METH_VARARGS,
     "tune_allocator(mmap_threshold, trim_threshold)\n--\n\nSet glibc's M_MMAP_THRESHOLD and M_TRIM_THRESHOLD "
     "(mallopt) so that wavefront-sized arrays reuse heap memory instead of fresh, page-faulting mappings. "
     "Returns False where this is not glibc."},
    {"mis_weights", (PyCFunction)(void (*)(void))ps_mis_weights, METH_VARARGS | METH_KEYWORDS,
     "mis_weights(s, t, lane, light_offset, light_fwd, light_rev, light_delta, eye_offset, eye_fwd, eye_rev, "
     "eye_delta, light_is_delta, qs_fwd, qs_rev, qs_minus_rev, pt_fwd, pt_rev, pt_minus_rev, *, camera_is_delta, "
     "heuristic, beta, target_s, target_t)\n--\n\nBDPT MIS weight of every connection (see ext/mis.c)."},
    {"hit_geometry", ps_hit_geometry, METH_VARARGS,
     "hit_geometry(table, prim, b1, b2)\n--\n\nPoints p0 + b1 e1 + b2 e2 (3, N), unit geometric normals (3, N) and "
     "ray offsets (N,), float32, of hits on triangles prim (int32) at barycentrics b1, b2 (float32), from a mesh's "
     "(13, F) float32 table (see ext/geometry.c)."},
    {"shadow_rays", (PyCFunction)(void (*)(void))ps_shadow_rays, METH_VARARGS | METH_KEYWORDS,
     "shadow_rays(a, n_a, eps_a, b, n_b, eps_b, lanes=None, b_lanes=None)\n--\n\n(origins (3, M), directions (3, M), "
     "tmax (M,)), "
     "float32: the rays Accel.occluded_between traces from tmin = RAY_TMIN, bit for bit those of "
     "pathspace.vecmath.shadow_ray (see ext/shadow.h)."},
    {"path_geometry", ps_path_geometry, METH_VARARGS,
     "path_geometry(p, n, k)\n--\n\n(w (3, N, K-1), g_fwd (N, K), g_rev (N, K), segments (N,)), float64: the unit "
     "directions of the segments of paths with vertices p and normals n ((3, N, K) float32) and k (N,) segments, "
     "their |cos| / d^2 at both ends and the product of those at their starts (see ext/paths.c)."},
    {"split_densities", ps_split_densities, METH_VARARGS,
     "split_densities(fwd, rev, delta, first, count)\n--\n\n(N,) float64: per path, the densities of making its "
     "vertices first .. first + count - 1 by walks from both ends, summed over the splits (see ext/paths.c)."},
    {"primary_fetch", ps_primary_fetch, METH_VARARGS,
     "primary_fetch(proposal, current, stamp, rows, columns, accepted, last_large, large, mode, kernel, size, "
     "limit, draw)\n--\n\n(numbers (N,), flat indices drawn (M,)): the proposal's numbers at (rows, columns) of "
     "Metropolis chain states, drawing those not drawn yet with uniforms from draw(k) (see ext/primary.c)."},
    {"primary_settle", ps_primary_settle, METH_VARARGS,
     "primary_settle(proposal, current, stamp, flat, accept, accepted)\n--\n\nEnd a proposal: the chains that "
     "accept take its numbers at flat, and they are forgotten; with current None (fresh states) they are only "
     "forgotten (see ext/primary.c)."},
    {"area_light_sample", ps_area_light_sample, METH_VARARGS,
     "area_light_sample(table, area, two_sided, cdf, pmf, u, receivers)\n--\n\n(entity, point, normal, wi, "
     "distance, facing, pdf, epsilon): a light sample per receiver ((3, N) float32) on area lights, the emitting "
     "triangle chosen from cdf by u[0], a point uniform in its area by u[1:3] (see ext/lights.c)."},
    {"pinhole_connect", ps_pinhole_connect, METH_VARARGS,
     "pinhole_connect(receivers, position, forward, right, image_up, tan_x, tan_y, width, height, lens_area)\n--\n\n"
     "(wi (3, N), pdf (N,), raster (2, N), on_film (N,), cos (N,)): receivers ((3, N) float32 or float64) joined "
     "to a pinhole camera (see ext/camera.c)."},
    {"next_event_value", ps_next_event_value, METH_VARARGS,
     "next_event_value(beta, f_cos, le, pdf_light, pdf_bsdf, facing, delta, heuristic, exponent)\n--\n\n"
     "(value (C, N) float64, useful (N,) bool): path tracing's light samples, (beta f_cos) (le w / pdf_light) "
     "where useful (facing, positive, some channel of f_cos > 0), with w the MIS weight (heuristic 0: none, "
     "1: balance, 2: power with `exponent`, 3: uniform; 1 where delta) (see ext/direct.c)."},
    {"area_emission", ps_area_emission, METH_VARARGS,
     "area_emission(prim, emitter_of_triangle, table, area, two_sided, pmf, origin, p, normal, direction, pdf_prev, "
     "delta_prev, strategy, exponent)\n--\n\n(lanes (M,) int64, emitter (M,) int64, weight (M,) float64): the "
     "lanes whose rays hit an area light, its emitting triangle and the weight of its emission (0 behind one-sided "
     "lights; MIS against light samples by area: strategy 1 balance, 2 power, 3 uniform; 0: 1; 4: 0 but after "
     "delta lobes) (see ext/direct.c)."},
    {"scatter_step", ps_scatter_step, METH_VARARGS,
     "scatter_step(beta, weight, survival, u, p, normal, eps, wi)\n--\n\n(beta (C, N) float64, alive (N,) bool, "
     "origin (3, N) float32): walks leaving points p along BSDF samples wi of weight `weight`, surviving roulette "
     "with probability `survival` (None: 1) decided by u (see ext/scatter.c)."},
    {"pt_vertex", ps_pt_vertex, METH_VARARGS,
     "pt_vertex(kind, reflectance, ior, albedo, table, area, two_sided, cdf, pmf, radiance, p, normal, eps, cos, "
     "direction, material, beta, eta_scale, rr_scale, depth, u, cos_phi, sin_phi, diffuse_technique, heuristic, "
     "policy, rr_depth, trapped_depth, exponent, probability, cap, bsdf_row, importance, reverse)\n--\n\n(value, "
     "useful, light_point, light_normal, light_eps, normal, beta, alive, origin, direction, pdf, delta, eta_scale, "
     "pdf_back, light_samples): one vertex of a path tracer's or a subpath's walks, next-event estimation, BSDF "
     "sample and roulette in one pass (see ext/pt_vertex.c and pathspace.estimators.pt_fused)."},
    {"lens_connect", ps_lens_connect, METH_VARARGS,
     "lens_connect(p, n, wo, beta, material, entity, chosen, on_light, diffuse, reflectance, radiance, two_sided, "
     "position, forward, right, image_up, tan_x, tan_y, width, height, lens_area, importance_scale, technique, q, "
     "q_rev, g_prev)\n--\n\n(value (3, K), raster (2, K)[, pt_rev, qs_minus_rev, qs_rev]): light vertices `chosen` "
     "joined to a pinhole camera (image area x lens area `importance_scale`), their contributions, and with q, "
     "q_rev and g_prev (not None) the MIS densities (see ext/lens_connect.c and pathspace.estimators.lens_fused)."},
    {"join_vertices", ps_join_vertices, METH_VARARGS,
     "join_vertices(light p, n, wo, beta, material, q, q_rev, g_prev, camera p, n, wo, beta, material, q, q_rev, "
     "g_prev, y, z, diffuse, reflectance, technique)\n--\n\n(value (3, K), qs_rev, qs_minus_rev, pt_rev, "
     "pt_minus_rev): light vertices y joined to camera vertices z, the unweighted contributions and the densities "
     "MIS reads (see ext/join.c and pathspace.estimators.join_fused)."},
    {"join_light_samples", ps_join_light_samples, METH_VARARGS,
     "join_light_samples(p, n, wo, beta, material, q, q_rev, g_prev, u, z, diffuse, reflectance, table, area, "
     "two_sided, cdf, pmf, radiance, technique)\n--\n\n(value (3, K), entity, point (3, K), normal (3, K), epsilon, "
     "qs_fwd, qs_rev, pt_rev, pt_minus_rev): camera vertices z joined to fresh light samples on area lights, the "
     "unweighted contributions, the light points and the densities MIS reads (see ext/join.c and "
     "pathspace.estimators.join_fused)."},
    {"join_pairs", ps_join_pairs, METH_VARARGS,
     "join_pairs(pair_start, nz, y_start, z_start, cy, cz, light_index, eye_index, begin, end, max_depth)\n--\n\n"
     "(y, z): the pairs begin .. end - 1 of a batch's joins, lane by lane (lane l's pair nz[l] i + j joins light "
     "vertex cy[y_start[l] + i] and camera vertex cz[z_start[l] + j]), those of at most max_depth segments (see "
     "ext/join.c and pathspace.estimators.connections.joins)."},
    {"useful_lanes", ps_useful_lanes, METH_VARARGS,
     "useful_lanes(value)\n--\n\n(lanes, nonfinite): the columns of `value` (C, n) float64, C-contiguous, finite in "
     "every row and not zero in some, in increasing order, and how many columns hold a NaN or an infinity (see "
     "ext/lanes.c)."},
    {"take_lanes", ps_take_lanes, METH_VARARGS,
     "take_lanes(indices, arrays)\n--\n\nlist: numpy.take(a, indices, axis=-1) of every array a of the list `arrays` "
     "(lanes along the last axis, as many in each), in one call with the GIL released (see ext/lanes.c)."},
    {"place_lanes", ps_place_lanes, METH_VARARGS,
     "place_lanes(positions, parts, width)\n--\n\nlist: for every field f, an array out of `width` lanes with "
     "out[..., positions[p]] = parts[p][f] for every part p (positions: int64 arrays covering 0 .. width - 1 once "
     "each), in one call with the GIL released (see ext/lanes.c)."},
    {"cosine_about", ps_cosine_about, METH_VARARGS,
     "cosine_about(n, u0, cos_phi, sin_phi)\n--\n\n(3, N) float32: directions cosine-distributed about unit normals "
     "n ((3, N) float32), n plus the point of the unit sphere at z = 1 - 2 u0 and angle phi, normalised "
     "(see ext/warp.c)."},
    {"moments_add", ps_moments_add, METH_VARARGS,
     "moments_add(count, exponent, scaled_mean, scaled_m2, start, values)\n--\n\n(n,) float64, each column's "
     "largest |value|: one sample (values (C, n)) added to the moments of pixels start .. start + n - 1, columns "
     "with a NaN or Inf left out (see ext/film.c and pathspace.film.Moments)."},
    {"splat_add", ps_splat_add, METH_VARARGS,
     "splat_add(buffer, pixels, values)\n--\n\nbuffer[c, pixels[i]] += values[c, i] for every splat in order "
     "(np.add.at per channel, bit for bit) with the GIL released; buffer (C, P) float64, pixels (n,) int64, values "
     "(C, n) float64 (see ext/film.c)."},
    {"default_thread_count", default_thread_count, METH_NOARGS,
     "default_thread_count()\n--\n\nNumber of cores this process may run on."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef native_module = {
    PyModuleDef_HEAD_INIT,
    .m_name = "pathspace._native",
    .m_doc = "C kernels of pathspace: Embree traversal over NumPy ray arrays.",
    .m_size = -1,
    .m_methods = module_methods,
};

PyMODINIT_FUNC PyInit__native(void)
{
    import_array();
    if (PyType_Ready(&PsAccelType) < 0)
        return NULL;
    PyObject *m = PyModule_Create(&native_module);
    if (m == NULL)
        return NULL;
    Py_INCREF(&PsAccelType);
    if (PyModule_AddObject(m, "Accel", (PyObject *)&PsAccelType) < 0) {
        Py_DECREF(&PsAccelType);
        Py_DECREF(m);
        return NULL;
    }
    PyObject *tmin = PyFloat_FromDouble(SHADOW_RAY_TMIN);   /* tested equal to pathspace.vecmath.RAY_TMIN */
    if (tmin == NULL || PyModule_AddObjectRef(m, "SHADOW_RAY_TMIN", tmin) < 0) {
        Py_XDECREF(tmin);
        Py_DECREF(m);
        return NULL;
    }
    Py_DECREF(tmin);
    if (ps_add_pt_vertex_constants(m) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
