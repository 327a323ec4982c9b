/*
 * Shadow rays between surface points: the arguments of Accel.occluded_between and _native.shadow_rays, their
 * errors, and shadow_rays itself, which returns the rays (to test them against pathspace.vecmath.shadow_ray).
 * The rays are built by ps_segment_ray (shadow.h).
 */
#include "shadow.h"

#define NPY_NO_DEPRECATED_API NPY_2_0_API_VERSION
#define NO_IMPORT_ARRAY
#define PY_ARRAY_UNIQUE_SYMBOL pathspace_native_ARRAY_API
#include <numpy/arrayobject.h>

static const char *const NAMES[6] = {"a", "n_a", "eps_a", "b", "n_b", "eps_b"};

/* The float32 data of argument k ((3, N) points and normals, (N,) error bounds), its N checked against *width
 * (-1: not known yet, taken from this one), the width of argument `first`. */
static const float *segment_array(PyObject *obj, int k, int first, Py_ssize_t *width)
{
    const char *name = NAMES[k];
    int vectors = k % 3 != 2;
    if (!PyArray_Check(obj)) {
        PyErr_Format(PyExc_TypeError, "%s must be a NumPy float32 array, got %s", name, Py_TYPE(obj)->tp_name);
        return NULL;
    }
    PyArrayObject *x = (PyArrayObject *)obj;
    if (PyArray_TYPE(x) != NPY_FLOAT || !PyArray_ISNOTSWAPPED(x)) {
        PyErr_Format(PyExc_TypeError, "%s must have dtype float32 (the points' own precision), got %R", name,
                     (PyObject *)PyArray_DESCR(x));
        return NULL;
    }
    if (vectors ? PyArray_NDIM(x) != 2 || PyArray_DIM(x, 0) != 3 : PyArray_NDIM(x) != 1) {
        PyErr_Format(PyExc_ValueError, "%s must have shape %s, got ndim=%d", name, vectors ? "(3, N)" : "(N,)",
                     PyArray_NDIM(x));
        return NULL;
    }
    Py_ssize_t n = PyArray_DIM(x, PyArray_NDIM(x) - 1);
    if (*width >= 0 && n != *width) {
        PyErr_Format(PyExc_ValueError, "%s has N = %zd, but %s has N = %zd", name, n, NAMES[first], *width);
        return NULL;
    }
    if (!PyArray_IS_C_CONTIGUOUS(x) || !PyArray_ISALIGNED(x)) {
        PyErr_Format(PyExc_ValueError, "%s must be C-contiguous and aligned", name);
        return NULL;
    }
    *width = n;
    return (const float *)PyArray_DATA(x);
}

/* The int64 indices `obj` (None: NULL, and *count left alone) into arrays `width` wide, checked: 0, or -1 with a
 * Python exception naming them. */
static int checked_lanes(PyObject *obj, const char *name, Py_ssize_t width, const int64_t **lanes, Py_ssize_t *count)
{
    *lanes = NULL;
    if (obj == Py_None)
        return 0;
    PyArrayObject *l = (PyArrayObject *)obj;
    if (!PyArray_Check(obj) || PyArray_TYPE(l) != NPY_INT64 || PyArray_NDIM(l) != 1 || !PyArray_IS_C_CONTIGUOUS(l) ||
        !PyArray_ISALIGNED(l)) {
        PyErr_Format(PyExc_TypeError, "%s must be a contiguous int64 array of shape (M,)", name);
        return -1;
    }
    const int64_t *data = (const int64_t *)PyArray_DATA(l);
    Py_ssize_t m = PyArray_DIM(l, 0), bad = -1;
    long long lane = 0;
    Py_BEGIN_ALLOW_THREADS   /* a wavefront's worth of lanes: other threads need not wait for the check */
    for (Py_ssize_t i = 0; i < m && bad < 0; ++i)
        if (data[i] < 0 || data[i] >= width) {
            bad = i;
            lane = (long long)data[i];
        }
    Py_END_ALLOW_THREADS
    if (bad >= 0) {
        PyErr_Format(PyExc_IndexError, "%s[%zd] = %lld is outside 0 .. %zd", name, bad, lane, width - 1);
        return -1;
    }
    *lanes = data;
    *count = m;
    return 0;
}

int ps_parse_segments(PyObject *const arrays[6], PyObject *lanes, PyObject *b_lanes, Segments *s)
{
    const float *data[6];
    s->width = s->width_b = -1;
    for (int k = 0; k < 6; ++k) { /* without b_lanes, b's arrays are as wide as a's */
        int own = k >= 3 && b_lanes != Py_None;
        if (!(data[k] = segment_array(arrays[k], k, own ? 3 : 0, own ? &s->width_b : &s->width)))
            return -1;
    }
    if (b_lanes == Py_None)
        s->width_b = s->width;
    s->a = data[0];
    s->n_a = data[1];
    s->eps_a = data[2];
    s->b = data[3];
    s->n_b = data[4];
    s->eps_b = data[5];
    s->count = s->width;
    Py_ssize_t count_b = s->count;
    if (checked_lanes(lanes, "lanes", s->width, &s->lanes, &s->count) < 0 ||
        checked_lanes(b_lanes, "b_lanes", s->width_b, &s->b_lanes, &count_b) < 0)
        return -1;
    if (s->b_lanes && count_b != s->count) {
        PyErr_Format(PyExc_ValueError, "b_lanes has %zd segments, but lanes (or a) %zd", count_b, s->count);
        return -1;
    }
    return 0;
}

PyObject *ps_bad_segment(const Segments *s, Py_ssize_t i)
{
    Py_ssize_t lane = s->lanes ? (Py_ssize_t)s->lanes[i] : i, n = s->width;
    Py_ssize_t lane_b = s->b_lanes ? (Py_ssize_t)s->b_lanes[i] : lane, n_b = s->width_b;
    if ((size_t)lane >= (size_t)n || (size_t)lane_b >= (size_t)n_b) {
        int a_side = (size_t)lane >= (size_t)n;
        PyErr_Format(PyExc_IndexError, "%s[%zd] = %zd is outside 0 .. %zd (changed during the call?)",
                     a_side ? "lanes" : "b_lanes", i, a_side ? lane : lane_b, (a_side ? n : n_b) - 1);
        return NULL;
    }
    float r[8] = {0};
    char text[512];
    ps_segment_ray(s, i, r);
    snprintf(text, sizeof(text),
             "invalid shadow ray %zd: the segment from (%g, %g, %g) to (%g, %g, %g) gives origin (%g, %g, %g), "
             "direction (%g, %g, %g) and tmax %g (origin and direction must be finite, the direction not zero, "
             "tmax not NaN)", (Py_ssize_t)i, s->a[lane], s->a[n + lane], s->a[2 * n + lane], s->b[lane_b],
             s->b[n_b + lane_b], s->b[2 * n_b + lane_b], r[0], r[1], r[2], r[4], r[5], r[6], r[7]);
    PyErr_SetString(PyExc_ValueError, text);
    return NULL;
}

PyObject *ps_shadow_rays(PyObject *module, PyObject *args, PyObject *kwargs)
{
    (void)module;
    static char *kwlist[] = {"a", "n_a", "eps_a", "b", "n_b", "eps_b", "lanes", "b_lanes", NULL};
    PyObject *arrays[6], *lanes = Py_None, *b_lanes = Py_None;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOOOOO|OO:shadow_rays", kwlist, &arrays[0], &arrays[1],
                                     &arrays[2], &arrays[3], &arrays[4], &arrays[5], &lanes, &b_lanes))
        return NULL;
    Segments s;
    if (ps_parse_segments(arrays, lanes, b_lanes, &s) < 0)
        return NULL;
    npy_intp dims[2] = {3, s.count}, m = s.count;
    PyArrayObject *origin = (PyArrayObject *)PyArray_SimpleNew(2, dims, NPY_FLOAT);
    PyArrayObject *direction = (PyArrayObject *)PyArray_SimpleNew(2, dims, NPY_FLOAT);
    PyArrayObject *tmax = (PyArrayObject *)PyArray_SimpleNew(1, &m, NPY_FLOAT);
    if (!origin || !direction || !tmax) {
        Py_XDECREF(origin);
        Py_XDECREF(direction);
        Py_XDECREF(tmax);
        return NULL;
    }
    float *o = (float *)PyArray_DATA(origin), *d = (float *)PyArray_DATA(direction), *t = (float *)PyArray_DATA(tmax);
    for (Py_ssize_t i = 0; i < m; ++i) {   /* ps_segment_ray bounds-checks each lane as it reads it */
        float r[8] = {0};
        ps_segment_ray(&s, i, r);
        for (int c = 0; c < 3; ++c) {
            o[c * m + i] = r[c];
            d[c * m + i] = r[4 + c];
        }
        t[i] = r[7];
    }
    return Py_BuildValue("(NNN)", origin, direction, tmax);
}
