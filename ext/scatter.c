/*
 * A random walk leaving its vertices (pathspace.estimators.walk.Walk.scatter), in one pass with the GIL
 * released.  Per lane, from the throughput beta, the BSDF sample's weight f |cos| / pdf and direction w, the
 * roulette's survival probability q (or none: every lane survives) and its uniform u, and the vertex's point p,
 * unit geometric normal n and error bound eps:
 *     alive  = some channel of the weight > 0 (none NaN), and u < q;
 *     beta'  = beta weight / q   (beta weight where q <= 0, a lane that dies: Veach 1997, sec. 10.4.1);
 *     origin = p + n (dot(n, w) < 0 ? -eps : eps), the next ray's origin off the surface on w's side
 *              (pathspace.vecmath.offset_origin; pbrt-v4, sec. 6.8.6).
 * Every value is computed in the operations and order of the NumPy code the tests keep as the reference
 * (tests/estimators/test_scatter_kernel.py), so the walks are bit for bit the same.
 */
#include "scatter.h"

#define NPY_NO_DEPRECATED_API NPY_2_0_API_VERSION
#define NO_IMPORT_ARRAY
#define PY_ARRAY_UNIQUE_SYMBOL pathspace_native_ARRAY_API
#include <numpy/arrayobject.h>

#include <math.h>

PyObject *ps_scatter_step(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *objs[8];
    if (!PyArg_ParseTuple(args, "OOOOOOOO:scatter_step", &objs[0], &objs[1], &objs[2], &objs[3], &objs[4],
                          &objs[5], &objs[6], &objs[7]))
        return NULL;
    static const PsArraySpec specs[8] = {
        {"beta", NPY_DOUBLE, "float64", 2, 0},   {"weight", NPY_DOUBLE, "float64", 2, 0},
        {"survival", NPY_DOUBLE, "float64", 1, 1}, {"u", NPY_DOUBLE, "float64", 1, 0},
        {"p", NPY_FLOAT, "float32", 2, 0},       {"normal", NPY_FLOAT, "float32", 2, 0},
        {"eps", NPY_FLOAT, "float32", 1, 0},     {"wi", NPY_FLOAT, "float32", 2, 0},
    };
    PyArrayObject *a[8];
    if (ps_checked_arrays(objs, specs, 8, (PyObject **)a) < 0)
        return NULL;
    PyArrayObject *beta = a[0], *weight = a[1], *survival = a[2], *u = a[3], *p = a[4], *normal = a[5], *eps = a[6],
                  *wi = a[7];
    npy_intp channels = PyArray_DIM(beta, 0), n = PyArray_DIM(beta, 1);
    if (channels < 1 || channels > PS_MAX_CHANNELS || PyArray_DIM(weight, 0) != channels ||
        PyArray_DIM(weight, 1) != n ||
        (survival && PyArray_DIM(survival, 0) != n) || PyArray_DIM(u, 0) != n || PyArray_DIM(eps, 0) != n ||
        PyArray_DIM(p, 0) != 3 || PyArray_DIM(normal, 0) != 3 || PyArray_DIM(wi, 0) != 3 || PyArray_DIM(p, 1) != n ||
        PyArray_DIM(normal, 1) != n || PyArray_DIM(wi, 1) != n) {
        PyErr_Format(PyExc_ValueError, "scatter_step: beta and weight (C, N) with 1 <= C <= 4, survival, u and eps "
                                       "(N,), and p, normal and wi (3, N) must agree; beta is (%zd, %zd)",
                     (Py_ssize_t)channels, (Py_ssize_t)n);
        return NULL;
    }
    npy_intp dims[2] = {channels, n}, dims3[2] = {3, n};
    PyObject *out[3] = {PyArray_SimpleNew(2, dims, NPY_DOUBLE), PyArray_SimpleNew(1, &n, NPY_BOOL),
                        PyArray_SimpleNew(2, dims3, NPY_FLOAT)};
    if (!ps_outputs_allocated(out, 3))
        return NULL;
    const double *b = (const double *)PyArray_DATA(beta), *f = (const double *)PyArray_DATA(weight),
                 *q = survival ? (const double *)PyArray_DATA(survival) : NULL, *uu = (const double *)PyArray_DATA(u);
    const float *x = (const float *)PyArray_DATA(p), *nn = (const float *)PyArray_DATA(normal),
                *e = (const float *)PyArray_DATA(eps), *w = (const float *)PyArray_DATA(wi);
    double *beta_out = (double *)PyArray_DATA((PyArrayObject *)out[0]);
    npy_bool *alive = (npy_bool *)PyArray_DATA((PyArrayObject *)out[1]);
    float *origin = (float *)PyArray_DATA((PyArrayObject *)out[2]);
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp i = 0; i < n; ++i) {
        double bi[PS_MAX_CHANNELS], fi[PS_MAX_CHANNELS], out_i[PS_MAX_CHANNELS];
        for (npy_intp c = 0; c < channels; ++c) {
            bi[c] = b[c * n + i];
            fi[c] = f[c * n + i];
        }
        float xi[3] = {x[i], x[n + i], x[2 * n + i]}, ni[3] = {nn[i], nn[n + i], nn[2 * n + i]},
              wi_[3] = {w[i], w[n + i], w[2 * n + i]}, oi[3];
        alive[i] = (npy_bool)ps_scatter(channels, bi, fi, q ? q + i : NULL, uu[i], xi, ni, e[i], wi_, out_i, oi);
        for (npy_intp c = 0; c < channels; ++c)
            beta_out[c * n + i] = out_i[c];
        for (int k = 0; k < 3; ++k)
            origin[k * n + i] = oi[k];
    }
    Py_END_ALLOW_THREADS
    return Py_BuildValue("(NNN)", out[0], out[1], out[2]);
}
