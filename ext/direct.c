/*
 * Path tracing's two ways of reaching emitters (pathspace.estimators.pt), each in one pass with the GIL released.
 *
 * next_event_value: light samples (next-event estimation).  Per lane, from the throughput beta, the BSDF's
 * f |cos| toward the light sample and its solid-angle density pdf_bsdf of that direction, the light sample's
 * value Le (radiance, I / d^2 or irradiance), its solid-angle density pdf_light and whether the light faces
 * the receiver:
 *     scale = w / pdf_light,   w = the MIS weight of light sampling against BSDF sampling (Veach 1997,
 *                              eq. 9.13: balance, power, or uniform), 1 for delta lights or without MIS;
 *     useful = facing and scale > 0 and some channel of f |cos| > 0 (NaN in any channel: not useful);
 *     value = useful ? (beta f |cos|) (Le scale) : 0                              (Veach 1997, eq. 9.4)
 *
 * area_emission: area lights hit by the walk's rays.  Per lane whose ray hit an emitting triangle e (from
 * `origin`, the offset previous vertex, along `direction` to the point p with geometric normal n), the weight
 * of its emission Le(e):
 *     weight = facing ? w : 0,   facing = e is two-sided or dot(n, -direction) > 0;
 *     w = 1 after a delta lobe or the camera (light sampling cannot make the path), else by strategy:
 *         MIS: the weight of BSDF sampling (density pdf_prev, the walk's) against light sampling, whose
 *              density is pmf_e |p - origin|^2 / (area_e |cos_light|) (Veach 1997, eq. 8.10; area measure);
 *         light samples alone ("nee"): 0;  BSDF sampling alone: 1.
 *
 * The MIS weight is pathspace.mis.mis_weight's, ratio-based: w = 1 / (1 + r) with r = p_other / p_own
 * (power: r^beta), 0/0 -> 0 and inf/inf -> 1/2.  Every value is computed in the operations and order of the
 * NumPy code the tests keep as the reference (tests/estimators/test_next_event_kernel.py and
 * test_emission_kernel.py), bit for bit, with two exceptions: an exponent other than 2 goes through C's pow
 * (NumPy's own power agrees to within an ulp), and a light sample counts as useful when any channel of
 * f |cos| is positive, where the NumPy code read only the first three of spectral rendering's four.
 */
#include "direct.h"
#include "light_sample.h"

#define NPY_NO_DEPRECATED_API NPY_2_0_API_VERSION
#define NO_IMPORT_ARRAY
#define PY_ARRAY_UNIQUE_SYMBOL pathspace_native_ARRAY_API
#include <numpy/arrayobject.h>

#include <math.h>
#include <stdint.h>


PyObject *ps_next_event_value(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *objs[7];
    int heuristic;
    double exponent;
    if (!PyArg_ParseTuple(args, "OOOOOOOid:next_event_value", &objs[0], &objs[1], &objs[2], &objs[3], &objs[4],
                          &objs[5], &objs[6], &heuristic, &exponent))
        return NULL;
    if (heuristic < MIS_NONE || heuristic > MIS_UNIFORM) {
        PyErr_Format(PyExc_ValueError, "next_event_value: heuristic must be 0 (none), 1 (balance), 2 (power) or "
                                       "3 (uniform), got %d", heuristic);
        return NULL;
    }
    static const PsArraySpec specs[7] = {
        {"beta", NPY_DOUBLE, "float64", 2, 0},     {"f_cos", NPY_DOUBLE, "float64", 2, 0},
        {"le", NPY_DOUBLE, "float64", 2, 0},       {"pdf_light", NPY_DOUBLE, "float64", 1, 0},
        {"pdf_bsdf", NPY_DOUBLE, "float64", 1, 0}, {"facing", NPY_BOOL, "bool", 1, 0},
        {"delta", NPY_BOOL, "bool", 1, 1},
    };
    PyArrayObject *a[7];
    if (ps_checked_arrays(objs, specs, 7, (PyObject **)a) < 0)
        return NULL;
    PyArrayObject *beta = a[0], *f_cos = a[1], *le = a[2], *pdf_light = a[3], *pdf_bsdf = a[4], *facing = a[5],
                  *delta = a[6];
    npy_intp channels = PyArray_DIM(beta, 0), n = PyArray_DIM(beta, 1);
    if (channels < 1 || channels > PS_MAX_CHANNELS || PyArray_DIM(f_cos, 0) != channels ||
        PyArray_DIM(le, 0) != channels ||
        PyArray_DIM(f_cos, 1) != n || PyArray_DIM(le, 1) != n || PyArray_DIM(pdf_light, 0) != n ||
        PyArray_DIM(pdf_bsdf, 0) != n || PyArray_DIM(facing, 0) != n || (delta && PyArray_DIM(delta, 0) != n)) {
        PyErr_Format(PyExc_ValueError, "next_event_value: beta, f_cos and le (C, N) with 1 <= C <= 4, and pdf_light, "
                                       "pdf_bsdf, facing and delta (N,) must agree; beta is (%zd, %zd)",
                     (Py_ssize_t)channels, (Py_ssize_t)n);
        return NULL;
    }
    npy_intp dims[2] = {channels, n};
    PyObject *out[2] = {PyArray_SimpleNew(2, dims, NPY_DOUBLE), PyArray_SimpleNew(1, &n, NPY_BOOL)};
    if (!ps_outputs_allocated(out, 2))
        return NULL;
    const double *b = (const double *)PyArray_DATA(beta), *f = (const double *)PyArray_DATA(f_cos),
                 *l = (const double *)PyArray_DATA(le), *pl = (const double *)PyArray_DATA(pdf_light),
                 *pb = (const double *)PyArray_DATA(pdf_bsdf);
    const npy_bool *faces = (const npy_bool *)PyArray_DATA(facing),
                   *is_delta = delta ? (const npy_bool *)PyArray_DATA(delta) : NULL;
    double *value = (double *)PyArray_DATA((PyArrayObject *)out[0]);
    npy_bool *useful = (npy_bool *)PyArray_DATA((PyArrayObject *)out[1]);
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp i = 0; i < n; ++i) {
        double bi[PS_MAX_CHANNELS], fi[PS_MAX_CHANNELS], li[PS_MAX_CHANNELS], vi[PS_MAX_CHANNELS];
        for (npy_intp c = 0; c < channels; ++c) {
            bi[c] = b[c * n + i];
            fi[c] = f[c * n + i];
            li[c] = l[c * n + i];
        }
        useful[i] = (npy_bool)ps_next_event(channels, bi, fi, li, pl[i], pb[i], faces[i], is_delta && is_delta[i],
                                            heuristic, exponent, vi);
        for (npy_intp c = 0; c < channels; ++c)
            value[c * n + i] = vi[c];
    }
    Py_END_ALLOW_THREADS
    return Py_BuildValue("(NN)", out[0], out[1]);
}

/* The emitting-triangle index of the triangle prim[i] (-1: none, or prim[i] is outside 0 .. triangles - 1, in
 * which case *bad becomes i if it is still negative).  Each prim is read once. */
static npy_intp emitter_of(const int32_t *prim, const int64_t *emitter_of_triangle, npy_intp triangles, npy_intp i,
                           npy_intp *bad)
{
    int32_t triangle = prim[i];
    if (triangle < 0 || triangle >= triangles) {
        if (*bad < 0)
            *bad = i;
        return -1;
    }
    return (npy_intp)emitter_of_triangle[triangle];
}

PyObject *ps_area_emission(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *objs[12];
    int strategy;
    double exponent;
    if (!PyArg_ParseTuple(args, "OOOOOOOOOOOOid:area_emission", &objs[0], &objs[1], &objs[2], &objs[3], &objs[4],
                          &objs[5], &objs[6], &objs[7], &objs[8], &objs[9], &objs[10], &objs[11], &strategy,
                          &exponent))
        return NULL;
    if (strategy < MIS_NONE || strategy > LIGHT_SAMPLES_ONLY) {
        PyErr_Format(PyExc_ValueError, "area_emission: strategy must be 0 (none), 1 (balance), 2 (power), 3 "
                                       "(uniform) or 4 (light samples only), got %d", strategy);
        return NULL;
    }
    static const PsArraySpec specs[12] = {
        {"prim", NPY_INT32, "int32", 1, 0},      {"emitter_of_triangle", NPY_INT64, "int64", 1, 0},
        {"table", NPY_FLOAT, "float32", 2, 0},   {"area", NPY_DOUBLE, "float64", 1, 0},
        {"two_sided", NPY_BOOL, "bool", 1, 0},   {"pmf", NPY_DOUBLE, "float64", 1, 0},
        {"origin", NPY_FLOAT, "float32", 2, 0},  {"p", NPY_FLOAT, "float32", 2, 0},
        {"normal", NPY_FLOAT, "float32", 2, 0},  {"direction", NPY_FLOAT, "float32", 2, 0},
        {"pdf_prev", NPY_DOUBLE, "float64", 1, 0}, {"delta_prev", NPY_BOOL, "bool", 1, 0},
    };
    PyArrayObject *a[12];
    if (ps_checked_arrays(objs, specs, 12, (PyObject **)a) < 0)
        return NULL;
    npy_intp n = PyArray_DIM(a[0], 0), triangles = PyArray_DIM(a[1], 0), emitters = PyArray_DIM(a[2], 1);
    int agree = PyArray_DIM(a[2], 0) == AREA_TABLE_ROWS && PyArray_DIM(a[3], 0) == emitters &&
                PyArray_DIM(a[4], 0) == emitters && PyArray_DIM(a[5], 0) >= emitters &&
                PyArray_DIM(a[10], 0) == n && PyArray_DIM(a[11], 0) == n;
    for (int k = 6; k < 10; ++k)
        agree = agree && PyArray_DIM(a[k], 0) == 3 && PyArray_DIM(a[k], 1) == n;
    if (!agree) {
        PyErr_Format(PyExc_ValueError, "area_emission: table (%d, E), area and two_sided (E,), pmf (at least E,), "
                                       "prim, pdf_prev and delta_prev (N,) and origin, p, normal and direction "
                                       "(3, N) must agree", AREA_TABLE_ROWS);
        return NULL;
    }
    const int32_t *prim = (const int32_t *)PyArray_DATA(a[0]);
    const int64_t *emitter_of_triangle = (const int64_t *)PyArray_DATA(a[1]);
    npy_intp count = 0, bad = -1, bad_emitter = -1;
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp i = 0; i < n; ++i) {
        npy_intp e = emitter_of(prim, emitter_of_triangle, triangles, i, &bad);
        if (e >= emitters && bad_emitter < 0)
            bad_emitter = i;
        count += e >= 0;
    }
    Py_END_ALLOW_THREADS
    if (bad >= 0 || bad_emitter >= 0) {
        PyErr_Format(PyExc_IndexError, bad >= 0 ? "area_emission: prim[%zd] is not a triangle of the mesh"
                                                : "area_emission: the triangle prim[%zd] hit has no emitter in table",
                     (Py_ssize_t)(bad >= 0 ? bad : bad_emitter));
        return NULL;
    }
    PyObject *out[3] = {PyArray_SimpleNew(1, &count, NPY_INT64), PyArray_SimpleNew(1, &count, NPY_INT64),
                        PyArray_SimpleNew(1, &count, NPY_DOUBLE)};
    if (!ps_outputs_allocated(out, 3))
        return NULL;
    const float *table = (const float *)PyArray_DATA(a[2]), *origin = (const float *)PyArray_DATA(a[6]),
                *p = (const float *)PyArray_DATA(a[7]), *normal = (const float *)PyArray_DATA(a[8]),
                *direction = (const float *)PyArray_DATA(a[9]);
    const double *area = (const double *)PyArray_DATA(a[3]), *pmf = (const double *)PyArray_DATA(a[5]),
                 *pdf_prev = (const double *)PyArray_DATA(a[10]);
    const npy_bool *two_sided = (const npy_bool *)PyArray_DATA(a[4]),
                   *delta_prev = (const npy_bool *)PyArray_DATA(a[11]);
    int64_t *lanes = (int64_t *)PyArray_DATA((PyArrayObject *)out[0]),
            *emitter = (int64_t *)PyArray_DATA((PyArrayObject *)out[1]);
    double *weight = (double *)PyArray_DATA((PyArrayObject *)out[2]);
    npy_intp m = 0;
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp i = 0; i < n && m < count; ++i) {
        npy_intp e = emitter_of(prim, emitter_of_triangle, triangles, i, &bad);
        if (e < 0 || e >= emitters)   /* checked above, but the arrays may have changed since: read once here */
            continue;
        float cos_view = (normal[i] * -direction[i] + normal[n + i] * -direction[n + i]) +
                         normal[2 * n + i] * -direction[2 * n + i];
        double w = 1.0;
        if (!delta_prev[i] && strategy == LIGHT_SAMPLES_ONLY) {
            w = 0.0;
        } else if (!delta_prev[i] && strategy != MIS_NONE) {
            float d[3];
            for (int k = 0; k < 3; ++k)
                d[k] = p[k * n + i] - origin[k * n + i];
            double dist2 = (double)((d[0] * d[0] + d[1] * d[1]) + d[2] * d[2]);
            const float *light_normal = table + 9 * emitters + e;
            double cos_light = (double)fabsf((light_normal[0] * d[0] + light_normal[emitters] * d[1]) +
                                             light_normal[2 * emitters] * d[2]) / sqrt(dist2);
            double pdf_light = pmf[e] * (dist2 > 0.0 ? dist2 / (area[e] * cos_light) : 0.0);
            w = ps_mis_weight(strategy, exponent, pdf_prev[i], pdf_light);
        }
        lanes[m] = i;
        emitter[m] = e;
        weight[m] = two_sided[e] || cos_view > 0.0f ? w : 0.0;
        ++m;
    }
    Py_END_ALLOW_THREADS
    if (m != count) {
        for (int k = 0; k < 3; ++k)
            Py_DECREF(out[k]);
        PyErr_SetString(PyExc_RuntimeError, "area_emission: prim or emitter_of_triangle changed during the call");
        return NULL;
    }
    return Py_BuildValue("(NNN)", out[0], out[1], out[2]);
}
