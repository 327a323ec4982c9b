/*
 * Cosine-weighted directions about unit normals (pathspace.warp.square_to_cosine_about), in one pass with the
 * GIL released.  Per lane, from the normal n (float32), a uniform u0 and the cosine and sine of the angle
 * phi = 2 pi u1 (computed by NumPy, whose float32 cos and sin a C library's would not match bit for bit):
 *     z = 1 - 2 u0,  r = sqrt(max(0, 1 - z^2)),  s = (r cos phi, r sin phi, z)   a uniform point on the sphere;
 *     d = n + s,  w = d / |d|  (n where |d| <= 1e-6: s = -n, probability 0)     density max(cos, 0) / pi
 * (Archimedes' hat-box theorem: no tangent frame).  Every value is computed in float32 in the operations and
 * order of the NumPy code the tests keep as the reference (tests/test_warp_kernel.py), bit for bit.
 */
#include "native.h"
#include "warp.h"

#define NPY_NO_DEPRECATED_API NPY_2_0_API_VERSION
#define NO_IMPORT_ARRAY
#define PY_ARRAY_UNIQUE_SYMBOL pathspace_native_ARRAY_API
#include <numpy/arrayobject.h>

#include <math.h>

PyObject *ps_cosine_about(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *objs[4];
    if (!PyArg_ParseTuple(args, "OOOO:cosine_about", &objs[0], &objs[1], &objs[2], &objs[3]))
        return NULL;
    static const PsArraySpec specs[4] = {
        {"n", NPY_FLOAT, "float32", 2, 0},       {"u0", NPY_DOUBLE, "float64", 1, 0},
        {"cos_phi", NPY_FLOAT, "float32", 1, 0}, {"sin_phi", NPY_FLOAT, "float32", 1, 0},
    };
    PyArrayObject *a[4];
    if (ps_checked_arrays(objs, specs, 4, (PyObject **)a) < 0)
        return NULL;
    PyArrayObject *normal = a[0], *u0 = a[1], *cos_phi = a[2], *sin_phi = a[3];
    npy_intp n = PyArray_DIM(normal, 1);
    if (PyArray_DIM(normal, 0) != 3 || PyArray_DIM(u0, 0) != n || PyArray_DIM(cos_phi, 0) != n ||
        PyArray_DIM(sin_phi, 0) != n) {
        PyErr_SetString(PyExc_ValueError, "cosine_about: n (3, N) and u0, cos_phi and sin_phi (N,) must agree");
        return NULL;
    }
    npy_intp dims[2] = {3, n};
    PyObject *out = PyArray_SimpleNew(2, dims, NPY_FLOAT);
    if (!out)
        return NULL;
    const float *nn = (const float *)PyArray_DATA(normal), *c = (const float *)PyArray_DATA(cos_phi),
                *s = (const float *)PyArray_DATA(sin_phi);
    const double *u = (const double *)PyArray_DATA(u0);
    float *w = (float *)PyArray_DATA((PyArrayObject *)out);
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp i = 0; i < n; ++i) {
        float ni[3] = {nn[i], nn[n + i], nn[2 * n + i]}, wi[3];
        ps_cosine_direction(ni, u[i], c[i], s[i], wi);
        for (int k = 0; k < 3; ++k)
            w[k * n + i] = wi[k];
    }
    Py_END_ALLOW_THREADS
    return out;
}
