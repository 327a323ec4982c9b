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
 * (-1: not known yet, taken from this one). */
static const float *segment_array(PyObject *obj, int k, Py_ssize_t *width)
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
        PyErr_Format(PyExc_ValueError, "%s has N = %zd, but a has N = %zd", name, n, *width);
        return NULL;
    }
    if (!PyArray_IS_C_CONTIGUOUS(x) || !PyArray_ISALIGNED(x)) {
        PyErr_Format(PyExc_ValueError, "%s must be C-contiguous and aligned", name);
        return NULL;
    }
    *width = n;
    return (const float *)PyArray_DATA(x);
}

int ps_parse_segments(PyObject *const arrays[6], PyObject *lanes, Segments *s)
{
    const float *data[6];
    s->width = -1;
    for (int k = 0; k < 6; ++k)
        if (!(data[k] = segment_array(arrays[k], k, &s->width)))
            return -1;
    s->a = data[0];
    s->n_a = data[1];
    s->eps_a = data[2];
    s->b = data[3];
    s->n_b = data[4];
    s->eps_b = data[5];
    s->lanes = NULL;
    s->count = s->width;
    if (lanes == Py_None)
        return 0;
    PyArrayObject *l = (PyArrayObject *)lanes;
    if (!PyArray_Check(lanes) || PyArray_TYPE(l) != NPY_INT64 || PyArray_NDIM(l) != 1 ||
        !PyArray_IS_C_CONTIGUOUS(l) || !PyArray_ISALIGNED(l)) {
        PyErr_SetString(PyExc_TypeError, "lanes must be a contiguous int64 array of shape (M,)");
        return -1;
    }
    s->lanes = (const int64_t *)PyArray_DATA(l);
    s->count = PyArray_DIM(l, 0);
    Py_ssize_t bad = -1;
    long long lane = 0;
    Py_BEGIN_ALLOW_THREADS   /* a wavefront's worth of lanes: other threads need not wait for the check */
    for (Py_ssize_t i = 0; i < s->count && bad < 0; ++i)
        if (s->lanes[i] < 0 || s->lanes[i] >= s->width) {
            bad = i;
            lane = (long long)s->lanes[i];
        }
    Py_END_ALLOW_THREADS
    if (bad >= 0) {
        PyErr_Format(PyExc_IndexError, "lanes[%zd] = %lld is outside 0 .. %zd", bad, lane, s->width - 1);
        return -1;
    }
    return 0;
}

PyObject *ps_bad_segment(const Segments *s, Py_ssize_t i)
{
    Py_ssize_t lane = s->lanes ? (Py_ssize_t)s->lanes[i] : i, n = s->width;
    if ((size_t)lane >= (size_t)n) {
        PyErr_Format(PyExc_IndexError, "lanes[%zd] = %zd is outside 0 .. %zd (changed during the call?)", i, lane,
                     n - 1);
        return NULL;
    }
    float r[8] = {0};
    char text[512];
    ps_segment_ray(s, i, r);
    snprintf(text, sizeof(text),
             "invalid shadow ray %zd: the segment from (%g, %g, %g) to (%g, %g, %g) gives origin (%g, %g, %g), "
             "direction (%g, %g, %g) and tmax %g (origin and direction must be finite, the direction not zero, "
             "tmax not NaN)", (Py_ssize_t)i, s->a[lane], s->a[n + lane], s->a[2 * n + lane], s->b[lane],
             s->b[n + lane], s->b[2 * n + lane], r[0], r[1], r[2], r[4], r[5], r[6], r[7]);
    PyErr_SetString(PyExc_ValueError, text);
    return NULL;
}

PyObject *ps_shadow_rays(PyObject *module, PyObject *args, PyObject *kwargs)
{
    (void)module;
    static char *kwlist[] = {"a", "n_a", "eps_a", "b", "n_b", "eps_b", "lanes", NULL};
    PyObject *arrays[6], *lanes = Py_None;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOOOOO|O:shadow_rays", kwlist, &arrays[0], &arrays[1],
                                     &arrays[2], &arrays[3], &arrays[4], &arrays[5], &lanes))
        return NULL;
    Segments s;
    if (ps_parse_segments(arrays, lanes, &s) < 0)
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
