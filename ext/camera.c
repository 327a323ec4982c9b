/*
 * Receivers joined to a pinhole camera (pathspace.camera.PinholeCamera.sample_importance: light tracing's and
 * BDPT's t = 1 strategy), in one pass with the GIL released.  Per receiver x (float32 or float64), with the
 * pinhole at o, the unit axis f and the image's right r and up u (float64), all in float64:
 *   - w = (o - x) / |o - x|, the direction to the lens, and d^2 = |o - x|^2;
 *   - the raster position of x: with p = x - o and depth = f . p,
 *         s_x = ((r . p) / depth) / tan_x,   s_y = ((u . p) / depth) / tan_y,
 *         X = ((s_x + 1) 0.5) W,   Y = ((1 - s_y) 0.5) H,
 *     on the film if depth > 0, 0 <= X < W and 0 <= Y < H;
 *   - cos = f . (-w), the cosine at the lens, and the lens point's density at x in solid angle
 *     d^2 / (|cos| A_lens) (pbrt's conversion of the pinhole's delta position).
 * Every value is computed in the operations and order of the NumPy code of the thin-lens camera's
 * sample_importance, which the pinhole used before (tests/test_camera_kernel.py compares them), so the
 * results are bit for bit the same.
 */
#include "camera.h"

#define NPY_NO_DEPRECATED_API NPY_2_0_API_VERSION
#define NO_IMPORT_ARRAY
#define PY_ARRAY_UNIQUE_SYMBOL pathspace_native_ARRAY_API
#include <numpy/arrayobject.h>

#include <math.h>

/* Three doubles from a sequence (the camera's vectors). */
static int vector3(PyObject *obj, const char *name, double out[3])
{
    PyArrayObject *a = (PyArrayObject *)ps_checked_array(obj, name, NPY_DOUBLE, -1, "float64", 1);
    if (!a)
        return -1;
    if (PyArray_DIM(a, 0) != 3) {
        PyErr_Format(PyExc_ValueError, "%s must have 3 entries", name);
        return -1;
    }
    for (int c = 0; c < 3; ++c)
        out[c] = ((const double *)PyArray_DATA(a))[c];
    return 0;
}

int ps_parse_pinhole(PyObject *const vectors[4], double tan_x, double tan_y, Py_ssize_t width, Py_ssize_t height,
                     double lens_area, PsPinhole *cam)
{
    if (vector3(vectors[0], "position", cam->o) || vector3(vectors[1], "forward", cam->f) ||
        vector3(vectors[2], "right", cam->r) || vector3(vectors[3], "image_up", cam->u))
        return -1;
    cam->tan_x = tan_x;
    cam->tan_y = tan_y;
    cam->width = (double)width;
    cam->height = (double)height;
    cam->lens_area = lens_area;
    return 0;
}

PyObject *ps_pinhole_connect(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *objs[5];
    double tan_x, tan_y, lens_area;
    Py_ssize_t width, height;
    if (!PyArg_ParseTuple(args, "OOOOOddnnd:pinhole_connect", &objs[0], &objs[1], &objs[2], &objs[3], &objs[4],
                          &tan_x, &tan_y, &width, &height, &lens_area))
        return NULL;
    PyArrayObject *receivers = (PyArrayObject *)ps_checked_array(objs[0], "receivers", NPY_FLOAT, NPY_DOUBLE,
                                                                 "float32 or float64", 2);
    if (!receivers)
        return NULL;
    if (PyArray_DIM(receivers, 0) != 3) {
        PyErr_SetString(PyExc_ValueError, "receivers must have 3 rows");
        return NULL;
    }
    PsPinhole cam;
    if (ps_parse_pinhole(objs + 1, tan_x, tan_y, width, height, lens_area, &cam) < 0)
        return NULL;
    npy_intp n = PyArray_DIM(receivers, 1), dims_w[2] = {3, n}, dims_r[2] = {2, n};
    PyObject *out[5] = {
        PyArray_SimpleNew(2, dims_w, NPY_DOUBLE), /* w */
        PyArray_SimpleNew(1, &n, NPY_DOUBLE),     /* pdf */
        PyArray_SimpleNew(2, dims_r, NPY_DOUBLE), /* raster */
        PyArray_SimpleNew(1, &n, NPY_BOOL),       /* on the film */
        PyArray_SimpleNew(1, &n, NPY_DOUBLE),     /* cos */
    };
    if (!ps_outputs_allocated(out, 5))
        return NULL;
    int wide = PyArray_TYPE(receivers) == NPY_DOUBLE;
    const float *x32 = (const float *)PyArray_DATA(receivers);
    const double *x64 = (const double *)PyArray_DATA(receivers);
    double *w = (double *)PyArray_DATA((PyArrayObject *)out[0]);
    double *pdf = (double *)PyArray_DATA((PyArrayObject *)out[1]);
    double *raster = (double *)PyArray_DATA((PyArrayObject *)out[2]);
    npy_bool *inside = (npy_bool *)PyArray_DATA((PyArrayObject *)out[3]);
    double *cosine = (double *)PyArray_DATA((PyArrayObject *)out[4]);
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp i = 0; i < n; ++i) {
        double x[3], dir[3], at[2];
        int on_film;
        for (int c = 0; c < 3; ++c)
            x[c] = wide ? x64[c * n + i] : (double)x32[c * n + i];
        ps_join_pinhole(&cam, x, dir, pdf + i, at, &on_film, cosine + i);
        for (int c = 0; c < 3; ++c)
            w[c * n + i] = dir[c];
        raster[i] = at[0];
        raster[n + i] = at[1];
        inside[i] = (npy_bool)on_film;
    }
    Py_END_ALLOW_THREADS
    return Py_BuildValue("(NNNNN)", out[0], out[1], out[2], out[3], out[4]);
}
