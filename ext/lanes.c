/*
 * Compaction of a wavefront's lanes (pathspace.estimators.wavefront.Lanes.keep): the columns `indices` of every
 * per-lane array (lanes along the last axis), in one call with the GIL released, array by array and row by row
 * as numpy.take(a, indices, axis=-1) gathers them, into new arrays of the same types.  Arrays this loop does not
 * handle (not C-contiguous and aligned, more than two dimensions, not of a bool or numeric type) go through
 * NumPy's own take.  The indices (0 .. N - 1; no negative ones) are copied and checked once, so an array changed
 * by another thread during the call cannot send the reads out of bounds.
 */
#include "native.h"

#define NPY_NO_DEPRECATED_API NPY_2_0_API_VERSION
#define NO_IMPORT_ARRAY
#define PY_ARRAY_UNIQUE_SYMBOL pathspace_native_ARRAY_API
#include <numpy/arrayobject.h>

#include <stdint.h>
#include <string.h>

typedef struct {
    const char *src;
    char *dst;
    npy_intp rows, width, itemsize;
} Gather;

/* dst[r, i] = src[r, indices[i]] for every row r of g, element by element of g->itemsize bytes. */
static void gather(const Gather *g, const int64_t *indices, npy_intp k)
{
    npy_intp size = g->itemsize;
    for (npy_intp r = 0; r < g->rows; ++r) {
        const char *s = g->src + r * g->width * size;
        char *d = g->dst + r * k * size;
        switch (size) {
        case 1:
            for (npy_intp i = 0; i < k; ++i)
                d[i] = s[indices[i]];
            break;
        case 4:
            for (npy_intp i = 0; i < k; ++i)
                memcpy(d + 4 * i, s + 4 * indices[i], 4);
            break;
        case 8:
            for (npy_intp i = 0; i < k; ++i)
                memcpy(d + 8 * i, s + 8 * indices[i], 8);
            break;
        default:
            for (npy_intp i = 0; i < k; ++i)
                memcpy(d + size * i, s + size * indices[i], (size_t)size);
        }
    }
}

PyObject *ps_take_lanes(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *index_obj, *arrays;
    if (!PyArg_ParseTuple(args, "OO!:take_lanes", &index_obj, &PyList_Type, &arrays))
        return NULL;
    PyArrayObject *index = (PyArrayObject *)ps_checked_array(index_obj, "indices", NPY_INT64, -1, "int64", 1);
    if (!index)
        return NULL;
    npy_intp k = PyArray_DIM(index, 0);
    Py_ssize_t count = PyList_GET_SIZE(arrays);
    PyObject *out = PyList_New(count);
    if (out && count == 0)
        return out;
    Gather *gathers = PyMem_Calloc(count ? (size_t)count : 1, sizeof(Gather));
    int64_t *indices = PyMem_Malloc(k ? (size_t)k * sizeof(int64_t) : 1);
    if (!out || !gathers || !indices) {
        Py_XDECREF(out);
        PyMem_Free(gathers);
        PyMem_Free(indices);
        return PyErr_NoMemory();
    }
    npy_intp width = -1, loops = 0;
    for (Py_ssize_t a = 0; a < count; ++a) {
        PyObject *item = PyList_GET_ITEM(arrays, a);
        if (!PyArray_Check(item) || PyArray_NDIM((PyArrayObject *)item) < 1) {
            PyErr_Format(PyExc_TypeError, "take_lanes: arrays[%zd] is not a NumPy array of lanes", a);
            goto fail;
        }
        PyArrayObject *array = (PyArrayObject *)item;
        int ndim = PyArray_NDIM(array);
        npy_intp lanes = PyArray_DIM(array, ndim - 1);
        if (width >= 0 && lanes != width) {
            PyErr_Format(PyExc_ValueError, "take_lanes: arrays[%zd] has %zd lanes, arrays[0] %zd", a,
                         (Py_ssize_t)lanes, (Py_ssize_t)width);
            goto fail;
        }
        width = lanes;
        int numeric = PyTypeNum_ISBOOL(PyArray_TYPE(array)) || PyTypeNum_ISNUMBER(PyArray_TYPE(array));
        if (ndim > 2 || !numeric || !PyArray_IS_C_CONTIGUOUS(array) || !PyArray_ISALIGNED(array) ||
            !PyArray_ISNOTSWAPPED(array)) {
            PyObject *taken = PyArray_TakeFrom(array, index_obj, ndim - 1, NULL, NPY_RAISE);
            if (!taken)
                goto fail;
            PyList_SET_ITEM(out, a, taken);
            continue;
        }
        npy_intp dims[2] = {ndim == 2 ? PyArray_DIM(array, 0) : k, k};
        PyArray_Descr *descr = PyArray_DESCR(array);
        Py_INCREF(descr);
        PyObject *taken = PyArray_NewFromDescr(&PyArray_Type, descr, ndim, dims, NULL, NULL, 0, NULL);
        if (!taken)
            goto fail;
        PyList_SET_ITEM(out, a, taken);
        gathers[loops++] = (Gather){PyArray_BYTES(array), PyArray_BYTES((PyArrayObject *)taken),
                                    ndim == 2 ? PyArray_DIM(array, 0) : 1, lanes, PyArray_ITEMSIZE(array)};
    }
    npy_intp bad = -1;
    Py_BEGIN_ALLOW_THREADS
    if (k > 0)
        memcpy(indices, PyArray_DATA(index), (size_t)k * sizeof(int64_t));
    for (npy_intp i = 0; i < k && bad < 0; ++i)
        if (indices[i] < 0 || indices[i] >= width)
            bad = i;
    if (bad < 0)
        for (npy_intp g = 0; g < loops; ++g)
            gather(&gathers[g], indices, k);
    Py_END_ALLOW_THREADS
    if (bad >= 0) {
        PyErr_Format(PyExc_IndexError, "take_lanes: indices[%zd] = %lld is outside 0 .. %zd", (Py_ssize_t)bad,
                     (long long)indices[bad], (Py_ssize_t)width - 1);
        goto fail;
    }
    PyMem_Free(gathers);
    PyMem_Free(indices);
    return out;
fail:
    Py_DECREF(out);
    PyMem_Free(gathers);
    PyMem_Free(indices);
    return NULL;
}
