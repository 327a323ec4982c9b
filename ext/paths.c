/*
 * Geometry of explicit paths (pathspace.estimators.paths.evaluate): per segment of every path, its unit
 * direction and the geometric factors that turn solid-angle densities into area densities (Veach 1997, eq.
 * 8.3, G = |cos_o| |cos_i| / d^2, split at its two ends), in one pass with the GIL released.
 *
 * Path j has k[j] segments, x_i -> x_{i+1} for i < k[j], between the vertices p[:, j, i] with normals
 * n[:, j, i] ((3, N, K) float32, computed in float64).  Per segment on the path:
 *   w = (x_{i+1} - x_i) / |x_{i+1} - x_i|                          (3, N, K-1); 0 off the path, NaN if d = 0
 *   g_fwd[j, i+1] = |n_{i+1} . w| / d^2,  g_rev[j, i] = |n_i . w| / d^2   (N, K); 0 off the path or if d = 0
 *   segments[j] = prod_i g_rev[j, i]                                (N,): the path's cosines at the start of
 *                                                                   each segment over d^2
 * in the operations of the NumPy expressions they replace (tests/estimators/test_paths.py keeps them as the
 * reference): sums of three products left to right, the square root then the division.
 */
#include "native.h"

#define NPY_NO_DEPRECATED_API NPY_2_0_API_VERSION
#define NO_IMPORT_ARRAY
#define PY_ARRAY_UNIQUE_SYMBOL pathspace_native_ARRAY_API
#include <numpy/arrayobject.h>

#include <math.h>
#include <stdint.h>
#include <stdlib.h>

PyObject *ps_path_geometry(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *objs[3];
    if (!PyArg_ParseTuple(args, "OOO:path_geometry", &objs[0], &objs[1], &objs[2]))
        return NULL;
    PyArrayObject *p = (PyArrayObject *)ps_checked_array(objs[0], "p", NPY_FLOAT, -1, "float32", 3);
    PyArrayObject *n = p ? (PyArrayObject *)ps_checked_array(objs[1], "n", NPY_FLOAT, -1, "float32", 3) : NULL;
    PyArrayObject *k = n ? (PyArrayObject *)ps_checked_array(objs[2], "k", NPY_INT64, -1, "int64", 1) : NULL;
    if (!k)
        return NULL;
    if (PyArray_DIM(p, 0) != 3 || PyArray_DIM(p, 2) < 1 || !PyArray_SAMESHAPE(p, n)) {
        PyErr_SetString(PyExc_ValueError, "p and n must have the same shape (3, N, K) with K >= 1");
        return NULL;
    }
    npy_intp count = PyArray_DIM(p, 1), slots = PyArray_DIM(p, 2);
    if (PyArray_DIM(k, 0) != count) {
        PyErr_Format(PyExc_ValueError, "k must have length N = %zd, got %zd", (Py_ssize_t)count,
                     (Py_ssize_t)PyArray_DIM(k, 0));
        return NULL;
    }
    npy_intp dims_w[3] = {3, count, slots - 1}, dims_g[2] = {count, slots};
    PyArrayObject *w = (PyArrayObject *)PyArray_ZEROS(3, dims_w, NPY_DOUBLE, 0);
    PyArrayObject *g_fwd = (PyArrayObject *)PyArray_ZEROS(2, dims_g, NPY_DOUBLE, 0);
    PyArrayObject *g_rev = (PyArrayObject *)PyArray_ZEROS(2, dims_g, NPY_DOUBLE, 0);
    PyArrayObject *segments = (PyArrayObject *)PyArray_SimpleNew(1, &count, NPY_DOUBLE);
    if (!w || !g_fwd || !g_rev || !segments) {
        Py_XDECREF(w);
        Py_XDECREF(g_fwd);
        Py_XDECREF(g_rev);
        Py_XDECREF(segments);
        return NULL;
    }
    const float *pp = (const float *)PyArray_DATA(p), *nn = (const float *)PyArray_DATA(n);
    const int64_t *kk = (const int64_t *)PyArray_DATA(k);
    double *ww = (double *)PyArray_DATA(w), *gf = (double *)PyArray_DATA(g_fwd), *gr = (double *)PyArray_DATA(g_rev);
    double *seg = (double *)PyArray_DATA(segments);
    npy_intp plane = count * slots, wplane = count * (slots - 1), bad = -1;
    int64_t bad_value = 0;
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp j = 0; j < count; ++j) {
        int64_t length = kk[j];   /* read once: checked, then used */
        if (length < 0 || length > slots - 1) {
            bad = j;
            bad_value = length;
            break;
        }
        double product = 1.0;
        for (npy_intp i = 0; i < (npy_intp)length; ++i) {
            npy_intp at = j * slots + i;
            double e[3], dir[3];
            for (int c = 0; c < 3; ++c)
                e[c] = (double)pp[c * plane + at + 1] - (double)pp[c * plane + at];
            double d2 = (e[0] * e[0] + e[1] * e[1]) + e[2] * e[2];
            double d = sqrt(d2);
            for (int c = 0; c < 3; ++c) {
                dir[c] = e[c] / d;
                ww[c * wplane + j * (slots - 1) + i] = dir[c];
            }
            double cos_start = fabs(((double)nn[at] * dir[0] + (double)nn[plane + at] * dir[1]) +
                                    (double)nn[2 * plane + at] * dir[2]);
            double cos_end = fabs(((double)nn[at + 1] * dir[0] + (double)nn[plane + at + 1] * dir[1]) +
                                  (double)nn[2 * plane + at + 1] * dir[2]);
            double start = d2 > 0.0 ? cos_start / d2 : 0.0;
            gf[at + 1] = d2 > 0.0 ? cos_end / d2 : 0.0;
            gr[at] = start;
            product *= start;
        }
        seg[j] = product;
    }
    Py_END_ALLOW_THREADS
    if (bad >= 0) {
        PyErr_Format(PyExc_ValueError, "k[%zd] = %lld: a path of K = %zd vertex slots has 0 .. %zd segments",
                     (Py_ssize_t)bad, (long long)bad_value, (Py_ssize_t)slots, (Py_ssize_t)slots - 1);
        Py_DECREF(w);
        Py_DECREF(g_fwd);
        Py_DECREF(g_rev);
        Py_DECREF(segments);
        return NULL;
    }
    return Py_BuildValue("(NNNN)", w, g_fwd, g_rev, segments);
}

/*
 * The density of making vertices first .. first + count - 1 of a path by a walk from each of its ends, summed
 * over the count + 1 splits (pathspace.estimators.path_mutations.split_densities; Veach 1997, sec. 11.4.2.1):
 * split j takes j vertices from the light side (the product of their fwd densities) and the rest from the
 * camera side (the product of their rev densities); splits whose join touches a specular vertex count 0.
 * Vertex slots past the path's K are read as NumPy's clip reads them; products are formed in the order of
 * NumPy's cumprod (light side from the first vertex on, camera side from the last back), so the sums are
 * those of the reference bit for bit.
 */
PyObject *ps_split_densities(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *objs[5];
    if (!PyArg_ParseTuple(args, "OOOOO:split_densities", &objs[0], &objs[1], &objs[2], &objs[3], &objs[4]))
        return NULL;
    PyArrayObject *fwd = (PyArrayObject *)ps_checked_array(objs[0], "fwd", NPY_DOUBLE, -1, "float64", 2);
    PyArrayObject *rev = fwd ? (PyArrayObject *)ps_checked_array(objs[1], "rev", NPY_DOUBLE, -1, "float64", 2) : NULL;
    PyArrayObject *delta = rev ? (PyArrayObject *)ps_checked_array(objs[2], "delta", NPY_BOOL, -1, "bool", 2) : NULL;
    PyArrayObject *first = delta ? (PyArrayObject *)ps_checked_array(objs[3], "first", NPY_INT64, -1, "int64", 1)
                                 : NULL;
    PyArrayObject *count = first ? (PyArrayObject *)ps_checked_array(objs[4], "count", NPY_INT64, -1, "int64", 1)
                                 : NULL;
    if (!count)
        return NULL;
    npy_intp lanes = PyArray_DIM(fwd, 0), slots = PyArray_DIM(fwd, 1);
    if (!PyArray_SAMESHAPE(fwd, rev) || !PyArray_SAMESHAPE(fwd, delta) || slots < 1 ||
        PyArray_DIM(first, 0) != lanes || PyArray_DIM(count, 0) != lanes) {
        PyErr_SetString(PyExc_ValueError, "fwd, rev and delta must have one shape (N, K), K >= 1, and first and "
                                          "count length N");
        return NULL;
    }
    PyArrayObject *total = (PyArrayObject *)PyArray_SimpleNew(1, &lanes, NPY_DOUBLE);
    double *walks = malloc(2 * (size_t)slots * sizeof(double));
    if (!total || !walks) {
        Py_XDECREF(total);
        free(walks);
        return PyErr_NoMemory();
    }
    const double *f = (const double *)PyArray_DATA(fwd), *r = (const double *)PyArray_DATA(rev);
    const npy_bool *d = (const npy_bool *)PyArray_DATA(delta);
    const int64_t *start = (const int64_t *)PyArray_DATA(first), *length = (const int64_t *)PyArray_DATA(count);
    double *out = (double *)PyArray_DATA(total), *light_walk = walks, *camera_walk = walks + slots;
    npy_intp bad = -1;
    int64_t bad_first = 0, bad_count = 0;
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp i = 0; i < lanes; ++i) {
        int64_t a = start[i], m = length[i];   /* read once: checked, then used */
        if (a < 0 || m < 0 || a > INT64_MAX / 2 || m > INT64_MAX / 2) {
            bad = i;
            bad_first = a;
            bad_count = m;
            break;
        }
        const double *fi = f + i * slots, *ri = r + i * slots;
        const npy_bool *di = d + i * slots;
        double product = 1.0;
        for (npy_intp s = 0; s < slots; ++s) {   /* prod fwd over first .. s (inside the run) */
            if (s >= a && s < a + m)
                product *= fi[s];
            light_walk[s] = product;
        }
        product = 1.0;
        for (npy_intp s = slots - 1; s >= 0; --s) {   /* prod rev over s .. end (inside the run) */
            if (s >= a && s < a + m)
                product *= ri[s];
            camera_walk[s] = product;
        }
        double sum = 0.0;
        for (int64_t j = 0; j <= m; ++j) {
            int64_t last = a - 1 + j;   /* the light side's last vertex (-1: the camera side found the light) */
            npy_intp here = last < 0 ? 0 : last >= slots ? slots - 1 : (npy_intp)last;
            npy_intp next = last + 1 >= slots ? slots - 1 : (npy_intp)(last + 1);
            double light = last >= a ? light_walk[here] : 1.0;
            double camera = last + 1 < a + m ? camera_walk[next] : 1.0;
            int joinable = last < 0 || !(di[here] || di[next]);
            sum += joinable ? light * camera : 0.0;
        }
        out[i] = sum;
    }
    Py_END_ALLOW_THREADS
    free(walks);
    if (bad >= 0) {
        PyErr_Format(PyExc_ValueError, "first[%zd] = %lld and count[%zd] = %lld: both must be >= 0", (Py_ssize_t)bad,
                     (long long)bad_first, (Py_ssize_t)bad, (long long)bad_count);
        Py_DECREF(total);
        return NULL;
    }
    return (PyObject *)total;
}
