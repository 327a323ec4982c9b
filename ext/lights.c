/*
 * Light samples on area lights (pathspace.lights.LightSet.sample_li for scenes whose only lights are area
 * lights, points sampled by area), in one pass with the GIL released.  Per receiver x, from uniforms u (3, N):
 *   - an emitting triangle j chosen from the selection CDF: the number of CDF entries <= u_0 (NumPy's
 *     searchsorted(side="right"), NaN sorting last), at most E - 1;
 *   - a point y uniform in its area (Shirley & Chiu's square-root map: sqrt(u_1) (1 - u_2), sqrt(u_1) u_2, in
 *     float64, then float32 as Embree's barycentrics), on it p0 + b1 e1 + b2 e2 (as ext/geometry.c);
 *   - the unit direction w = (y - x) / |y - x| (0 if y = x), the distance, cos_light = -n . w, whether the
 *     light emits toward x (two-sided, or cos_light > 0), and the solid-angle density with the selection pmf
 *         pdf = pmf_j |y - x|^2 / (area_j |cos_light|)     (Veach 1997, eq. 8.10; 0 if y = x).
 * Every value is computed in the operations and order of the NumPy code of AreaTables.sample, which the tests
 * keep as the reference (tests/lights/test_area_kernel.py), so the samples are bit for bit the same.
 */
#include "light_sample.h"

#define NPY_NO_DEPRECATED_API NPY_2_0_API_VERSION
#define NO_IMPORT_ARRAY
#define PY_ARRAY_UNIQUE_SYMBOL pathspace_native_ARRAY_API
#include <numpy/arrayobject.h>

#include <math.h>
#include <stdint.h>

PyObject *ps_area_light_sample(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *objs[7];
    if (!PyArg_ParseTuple(args, "OOOOOOO:area_light_sample", &objs[0], &objs[1], &objs[2], &objs[3], &objs[4],
                          &objs[5], &objs[6]))
        return NULL;
    PyArrayObject *table = (PyArrayObject *)ps_checked_array(objs[0], "table", NPY_FLOAT, -1, "float32", 2);
    PyArrayObject *area = table ? (PyArrayObject *)ps_checked_array(objs[1], "area", NPY_DOUBLE, -1, "float64", 1)
                                : NULL;
    PyArrayObject *two_sided = area ? (PyArrayObject *)ps_checked_array(objs[2], "two_sided", NPY_BOOL, -1, "bool", 1)
                                    : NULL;
    PyArrayObject *cdf = two_sided ? (PyArrayObject *)ps_checked_array(objs[3], "cdf", NPY_DOUBLE, -1, "float64", 1)
                                   : NULL;
    PyArrayObject *pmf = cdf ? (PyArrayObject *)ps_checked_array(objs[4], "pmf", NPY_DOUBLE, -1, "float64", 1) : NULL;
    PyArrayObject *u = pmf ? (PyArrayObject *)ps_rows_array(objs[5], "u", NPY_DOUBLE, "float64", 3) : NULL;
    PyArrayObject *receivers = u ? (PyArrayObject *)ps_rows_array(objs[6], "receivers", NPY_FLOAT, "float32", 3)
                                 : NULL;
    if (!receivers)
        return NULL;
    npy_intp lights = PyArray_DIM(table, 1), n = PyArray_DIM(u, 1);
    if (PyArray_DIM(table, 0) != AREA_TABLE_ROWS || lights < 1 || PyArray_DIM(area, 0) != lights ||
        PyArray_DIM(two_sided, 0) != lights || PyArray_DIM(cdf, 0) != lights || PyArray_DIM(pmf, 0) != lights) {
        PyErr_Format(PyExc_ValueError, "area_light_sample: table (%d, E) with E >= 1, and area, two_sided, cdf and "
                                       "pmf (E,) must agree", AREA_TABLE_ROWS);
        return NULL;
    }
    if (PyArray_DIM(receivers, 1) != n) {
        PyErr_Format(PyExc_ValueError, "area_light_sample: u (3, %zd) and receivers (3, %zd) must have as many "
                                       "columns", (Py_ssize_t)n, (Py_ssize_t)PyArray_DIM(receivers, 1));
        return NULL;
    }
    npy_intp dims[2] = {3, n};
    PyObject *out[8] = {
        PyArray_SimpleNew(1, &n, NPY_INT64),   /* entity */
        PyArray_SimpleNew(2, dims, NPY_FLOAT), /* point */
        PyArray_SimpleNew(2, dims, NPY_FLOAT), /* normal */
        PyArray_SimpleNew(2, dims, NPY_FLOAT), /* wi */
        PyArray_SimpleNew(1, &n, NPY_FLOAT),   /* distance */
        PyArray_SimpleNew(1, &n, NPY_BOOL),    /* facing */
        PyArray_SimpleNew(1, &n, NPY_DOUBLE),  /* pdf */
        PyArray_SimpleNew(1, &n, NPY_FLOAT),   /* epsilon */
    };
    if (!ps_outputs_allocated(out, 8))
        return NULL;
    const float *t = (const float *)PyArray_DATA(table), *x = (const float *)PyArray_DATA(receivers);
    const double *a = (const double *)PyArray_DATA(area), *c = (const double *)PyArray_DATA(cdf),
                 *p = (const double *)PyArray_DATA(pmf), *uu = (const double *)PyArray_DATA(u);
    const npy_bool *two = (const npy_bool *)PyArray_DATA(two_sided);
    npy_intp u_row = PyArray_STRIDE(u, 0) / (npy_intp)sizeof(double);
    npy_intp x_row = PyArray_STRIDE(receivers, 0) / (npy_intp)sizeof(float);
    int64_t *entity = (int64_t *)PyArray_DATA((PyArrayObject *)out[0]);
    float *point = (float *)PyArray_DATA((PyArrayObject *)out[1]);
    float *normal = (float *)PyArray_DATA((PyArrayObject *)out[2]);
    float *wi = (float *)PyArray_DATA((PyArrayObject *)out[3]);
    float *distance = (float *)PyArray_DATA((PyArrayObject *)out[4]);
    npy_bool *facing = (npy_bool *)PyArray_DATA((PyArrayObject *)out[5]);
    double *pdf = (double *)PyArray_DATA((PyArrayObject *)out[6]);
    float *epsilon = (float *)PyArray_DATA((PyArrayObject *)out[7]);
    Py_BEGIN_ALLOW_THREADS
    PsAreaLights light_table = {t, a, c, p, two, lights};
    for (npy_intp i = 0; i < n; ++i) {
        float receiver[3] = {x[i], x[x_row + i], x[2 * x_row + i]};
        PsLightSample s;
        ps_sample_area_light(&light_table, uu[i], uu[u_row + i], uu[2 * u_row + i], receiver, &s);
        entity[i] = s.entity;
        for (int k = 0; k < 3; ++k) {
            point[k * n + i] = s.point[k];
            normal[k * n + i] = s.normal[k];
            wi[k * n + i] = s.wi[k];
        }
        distance[i] = s.distance;
        facing[i] = (npy_bool)s.facing;
        pdf[i] = s.pdf;
        epsilon[i] = s.epsilon;
    }
    Py_END_ALLOW_THREADS
    return Py_BuildValue("(NNNNNNNN)", out[0], out[1], out[2], out[3], out[4], out[5], out[6], out[7]);
}
