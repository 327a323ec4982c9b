/*
 * Hit geometry: the points, unit geometric normals and ray offsets of hits on the scene's triangles, from
 * the mesh's per-triangle table (pathspace.scene.mesh.TriangleMesh.table) and Embree's barycentrics, in one
 * pass with the GIL released.  The point is p0 + b1 e1 + b2 e2 in float32, in the operations and order of
 * the NumPy expression it replaces ((p0 + e1 b1) + e2 b2; built without FMA contraction), so hits are bit
 * for bit the same.  Triangle indices are int32 (Embree's) or int64, each read once and checked.
 */
#include "native.h"

#define NPY_NO_DEPRECATED_API NPY_2_0_API_VERSION
#define NO_IMPORT_ARRAY
#define PY_ARRAY_UNIQUE_SYMBOL pathspace_native_ARRAY_API
#include <numpy/arrayobject.h>

#include <stdint.h>

#define TABLE_ROWS 13 /* p0 (3), e1 (3), e2 (3), unit normal (3), ray offset (1) */

PyObject *ps_checked_array(PyObject *obj, const char *name, int type, int other, const char *type_name, int ndim)
{
    if (!PyArray_Check(obj) || (PyArray_TYPE((PyArrayObject *)obj) != type &&
                                PyArray_TYPE((PyArrayObject *)obj) != other) ||
        PyArray_NDIM((PyArrayObject *)obj) != ndim || !PyArray_ISNOTSWAPPED((PyArrayObject *)obj)) {
        PyErr_Format(PyExc_TypeError, "%s must be a %dD %s array", name, ndim, type_name);
        return NULL;
    }
    PyArrayObject *a = (PyArrayObject *)obj;
    if (!PyArray_IS_C_CONTIGUOUS(a) || !PyArray_ISALIGNED(a)) {
        PyErr_Format(PyExc_ValueError, "%s must be C-contiguous and aligned", name);
        return NULL;
    }
    return obj;
}

int ps_checked_arrays(PyObject *const *objs, const PsArraySpec *specs, int count, PyObject **arrays)
{
    for (int k = 0; k < count; ++k) {
        const PsArraySpec *spec = &specs[k];
        arrays[k] = spec->optional && objs[k] == Py_None
                        ? NULL
                        : ps_checked_array(objs[k], spec->name, spec->type, -1, spec->type_name, spec->ndim);
        if (!arrays[k] && !(spec->optional && objs[k] == Py_None))
            return -1;
    }
    return 0;
}

PyObject *ps_rows_array(PyObject *obj, const char *name, int type, const char *type_name, Py_ssize_t rows)
{
    PyArrayObject *a = (PyArrayObject *)obj;
    if (!PyArray_Check(obj) || PyArray_TYPE(a) != type || PyArray_NDIM(a) != 2 || !PyArray_ISNOTSWAPPED(a)) {
        PyErr_Format(PyExc_TypeError, "%s must be a 2D %s array", name, type_name);
        return NULL;
    }
    if (!PyArray_ISALIGNED(a) || (PyArray_DIM(a, 1) > 1 && PyArray_STRIDE(a, 1) != PyArray_ITEMSIZE(a)) ||
        PyArray_STRIDE(a, 0) % PyArray_ITEMSIZE(a) != 0) {
        PyErr_Format(PyExc_ValueError, "%s must be aligned, with contiguous rows", name);
        return NULL;
    }
    if (rows >= 0 && PyArray_DIM(a, 0) != rows) {
        PyErr_Format(PyExc_ValueError, "%s must have %zd rows, got %zd", name, rows, (Py_ssize_t)PyArray_DIM(a, 0));
        return NULL;
    }
    return obj;
}

PyObject *ps_hit_geometry(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *objs[4];
    if (!PyArg_ParseTuple(args, "OOOO:hit_geometry", &objs[0], &objs[1], &objs[2], &objs[3]))
        return NULL;
    PyArrayObject *table = (PyArrayObject *)ps_checked_array(objs[0], "table", NPY_FLOAT, -1, "float32", 2);
    PyArrayObject *prim = table ? (PyArrayObject *)ps_checked_array(objs[1], "prim", NPY_INT32, NPY_INT64,
                                                                    "int32 or int64", 1) : NULL;
    PyArrayObject *b1 = prim ? (PyArrayObject *)ps_checked_array(objs[2], "b1", NPY_FLOAT, -1, "float32", 1) : NULL;
    PyArrayObject *b2 = b1 ? (PyArrayObject *)ps_checked_array(objs[3], "b2", NPY_FLOAT, -1, "float32", 1) : NULL;
    if (!b2)
        return NULL;
    if (PyArray_DIM(table, 0) != TABLE_ROWS) {
        PyErr_Format(PyExc_ValueError, "table must have %d rows, got %zd", TABLE_ROWS,
                     (Py_ssize_t)PyArray_DIM(table, 0));
        return NULL;
    }
    npy_intp n = PyArray_DIM(prim, 0), count = PyArray_DIM(table, 1);
    if (PyArray_DIM(b1, 0) != n || PyArray_DIM(b2, 0) != n) {
        PyErr_Format(PyExc_ValueError, "prim, b1 and b2 must have the same length, got %zd, %zd and %zd",
                     (Py_ssize_t)n, (Py_ssize_t)PyArray_DIM(b1, 0), (Py_ssize_t)PyArray_DIM(b2, 0));
        return NULL;
    }
    const int32_t *tri32 = (const int32_t *)PyArray_DATA(prim);
    const int64_t *tri64 = (const int64_t *)PyArray_DATA(prim);
    int wide = PyArray_TYPE(prim) == NPY_INT64;
    npy_intp dims[2] = {3, n};
    PyArrayObject *p = (PyArrayObject *)PyArray_SimpleNew(2, dims, NPY_FLOAT);
    PyArrayObject *normal = (PyArrayObject *)PyArray_SimpleNew(2, dims, NPY_FLOAT);
    PyArrayObject *eps = (PyArrayObject *)PyArray_SimpleNew(1, &n, NPY_FLOAT);
    if (!p || !normal || !eps) {
        Py_XDECREF(p);
        Py_XDECREF(normal);
        Py_XDECREF(eps);
        return NULL;
    }
    const float *t = (const float *)PyArray_DATA(table), *u = (const float *)PyArray_DATA(b1),
                *v = (const float *)PyArray_DATA(b2);
    float *out_p = (float *)PyArray_DATA(p), *out_n = (float *)PyArray_DATA(normal);
    float *out_eps = (float *)PyArray_DATA(eps);
    npy_intp bad = -1;
    long long bad_value = 0;
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp i = 0; i < n; ++i) {
        long long k = wide ? (long long)tri64[i] : (long long)tri32[i];   /* read once: checked, then used */
        if (k < 0 || k >= (long long)count) {
            bad = i;
            bad_value = k;
            break;
        }
        for (int c = 0; c < 3; ++c) {
            out_p[c * n + i] = ps_triangle_coordinate(t, count, (Py_ssize_t)k, c, u[i], v[i]);
            out_n[c * n + i] = t[(9 + c) * count + k];
        }
        out_eps[i] = t[12 * count + k];
    }
    Py_END_ALLOW_THREADS
    if (bad >= 0) {
        PyErr_Format(PyExc_IndexError, "prim[%zd] = %lld is not a triangle (0 .. %zd)", (Py_ssize_t)bad, bad_value,
                     (Py_ssize_t)count - 1);
        Py_DECREF(p);
        Py_DECREF(normal);
        Py_DECREF(eps);
        return NULL;
    }
    return Py_BuildValue("(NNN)", p, normal, eps);
}

PyObject *ps_first_entries(PyObject *array, Py_ssize_t count)
{
    if (count == PyArray_DIM((PyArrayObject *)array, 0))
        return array;
    PyObject *start = PyLong_FromSsize_t(0), *stop = PyLong_FromSsize_t((Py_ssize_t)count);
    PyObject *slice = start && stop ? PySlice_New(start, stop, NULL) : NULL;
    PyObject *part = slice ? PyObject_GetItem(array, slice) : NULL;
    Py_XDECREF(start);
    Py_XDECREF(stop);
    Py_XDECREF(slice);
    Py_DECREF(array);
    return part;
}
