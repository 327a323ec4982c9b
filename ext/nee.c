/*
 * The value of path tracing's light samples (pathspace.estimators.pt, next-event estimation), in one pass
 * with the GIL released.  Per lane, from the throughput beta, the BSDF's f |cos| toward the light sample and
 * its solid-angle density pdf_bsdf of that direction, the light sample's value Le (radiance, I / d^2 or
 * irradiance), its solid-angle density pdf_light and whether the light faces the receiver:
 *     scale = w / pdf_light,   w = the MIS weight of light sampling against BSDF sampling (Veach 1997,
 *                              eq. 9.13: balance, power, or uniform), 1 for delta lights or without MIS;
 *     useful = facing and scale > 0 and some channel of f |cos| > 0 (NaN in any channel: not useful);
 *     value = useful ? (beta f |cos|) (Le scale) : 0                              (Veach 1997, eq. 9.4)
 * The MIS weight is pathspace.mis.mis_weight's, ratio-based: w = 1 / (1 + r) with r = pdf_bsdf / pdf_light
 * (power: r^beta), 0/0 -> 0 and inf/inf -> 1/2.  Every value is computed in the operations and order of the
 * NumPy code the tests keep as the reference (tests/estimators/test_next_event_kernel.py), bit for bit (an
 * exponent other than 2 goes through C's pow, NumPy's through its own: equal to within an ulp).
 */
#include "native.h"

#define NPY_NO_DEPRECATED_API NPY_2_0_API_VERSION
#define NO_IMPORT_ARRAY
#define PY_ARRAY_UNIQUE_SYMBOL pathspace_native_ARRAY_API
#include <numpy/arrayobject.h>

#include <math.h>

enum { MIS_NONE, MIS_BALANCE, MIS_POWER, MIS_UNIFORM };

/* Weight of light sampling (density a) against BSDF sampling (density b), as pathspace.mis.mis_weight. */
static double mis_weight(int heuristic, double exponent, double a, double b)
{
    double ratio;
    if (heuristic == MIS_UNIFORM) {
        ratio = a > 0.0 ? (b > 0.0 ? 1.0 : 0.0) : INFINITY;
    } else {
        ratio = b / a;
        if (heuristic == MIS_POWER)
            ratio = exponent == 2.0 ? ratio * ratio : pow(ratio, exponent);
    }
    double weight = 1.0 / (1.0 + ratio);
    if (isnan(weight))
        weight = isinf(a) ? 0.5 : 0.0;
    return weight;
}

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
    PyArrayObject *beta = (PyArrayObject *)ps_checked_array(objs[0], "beta", NPY_DOUBLE, -1, "float64", 2);
    PyArrayObject *f_cos = beta ? (PyArrayObject *)ps_checked_array(objs[1], "f_cos", NPY_DOUBLE, -1, "float64", 2)
                                : NULL;
    PyArrayObject *le = f_cos ? (PyArrayObject *)ps_checked_array(objs[2], "le", NPY_DOUBLE, -1, "float64", 2)
                              : NULL;
    PyArrayObject *pdf_light = le ? (PyArrayObject *)ps_checked_array(objs[3], "pdf_light", NPY_DOUBLE, -1,
                                                                      "float64", 1) : NULL;
    PyArrayObject *pdf_bsdf = pdf_light ? (PyArrayObject *)ps_checked_array(objs[4], "pdf_bsdf", NPY_DOUBLE, -1,
                                                                            "float64", 1) : NULL;
    PyArrayObject *facing = pdf_bsdf ? (PyArrayObject *)ps_checked_array(objs[5], "facing", NPY_BOOL, -1, "bool", 1)
                                     : NULL;
    PyArrayObject *delta = NULL;
    if (facing && objs[6] != Py_None)
        delta = (PyArrayObject *)ps_checked_array(objs[6], "delta", NPY_BOOL, -1, "bool", 1);
    if (!facing || (objs[6] != Py_None && !delta))
        return NULL;
    npy_intp channels = PyArray_DIM(beta, 0), n = PyArray_DIM(beta, 1);
    if (channels < 1 || PyArray_DIM(f_cos, 0) != channels || PyArray_DIM(le, 0) != channels ||
        PyArray_DIM(f_cos, 1) != n || PyArray_DIM(le, 1) != n || PyArray_DIM(pdf_light, 0) != n ||
        PyArray_DIM(pdf_bsdf, 0) != n || PyArray_DIM(facing, 0) != n || (delta && PyArray_DIM(delta, 0) != n)) {
        PyErr_Format(PyExc_ValueError, "next_event_value: beta, f_cos and le (C, N) with C >= 1, and pdf_light, "
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
        double scale = 1.0 / pl[i];
        if (heuristic != MIS_NONE && !(is_delta && is_delta[i]))
            scale *= mis_weight(heuristic, exponent, pl[i], pb[i]);
        int reflects = 0, nan = 0;
        for (npy_intp c = 0; c < channels; ++c) {
            double fc = f[c * n + i];
            nan |= isnan(fc);
            reflects |= fc > 0.0;
        }
        useful[i] = faces[i] && scale > 0.0 && reflects && !nan;
        for (npy_intp c = 0; c < channels; ++c)
            value[c * n + i] = useful[i] ? b[c * n + i] * f[c * n + i] * (l[c * n + i] * scale) : 0.0;
    }
    Py_END_ALLOW_THREADS
    return Py_BuildValue("(NN)", out[0], out[1]);
}
