/*
 * Compaction of a wavefront's lanes (pathspace.estimators.wavefront.Lanes.keep): the columns `indices` of every
 * per-lane array (lanes along the last axis), in one call with the GIL released, array by array and row by row
 * as numpy.take(a, indices, axis=-1) gathers them, into new arrays of the same types.  Arrays this loop does not
 * handle (not C-contiguous and aligned, more than two dimensions, not of a bool or numeric type) go through
 * NumPy's own take.  The indices (0 .. N - 1; no negative ones) are copied and checked once, so an array changed
 * by another thread during the call cannot send the reads out of bounds.  (Checking each index where it is read
 * instead, without the copy, made one-row gathers 1.7x faster but the compaction of a walk's dozen arrays 1.1x
 * slower.)  place_lanes, below, is the inverse.  useful_lanes finds the lanes of a wavefront's contributions worth
 * weighting (finite and not zero), in one pass instead of NumPy's five.
 */
#include "native.h"

#define NPY_NO_DEPRECATED_API NPY_2_0_API_VERSION
#define NO_IMPORT_ARRAY
#define PY_ARRAY_UNIQUE_SYMBOL pathspace_native_ARRAY_API
#include <numpy/arrayobject.h>

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
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

/* A new C-contiguous array of `array`'s type and rows (one or two dimensions) with `lanes` lanes; NULL with the
 * exception set if the allocation fails. */
static PyObject *lanes_like(PyArrayObject *array, npy_intp lanes)
{
    int ndim = PyArray_NDIM(array);
    npy_intp dims[2] = {ndim == 2 ? PyArray_DIM(array, 0) : lanes, lanes};
    PyArray_Descr *descr = PyArray_DESCR(array);
    Py_INCREF(descr);
    return PyArray_NewFromDescr(&PyArray_Type, descr, ndim, dims, NULL, NULL, 0, NULL);
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
        PyObject *taken = lanes_like(array, k);
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

/*
 * The inverse of a gather: several wavefront parts placed into one (pathspace.estimators.wavefront.place_lanes,
 * the flattening of subpaths recorded depth by depth into lane order).  For every field f, a new array out_f of
 * `width` lanes with out_f[r, positions[p][i]] = parts[p][f][r, i]: what numpy.concatenate over the parts
 * followed by a gather into the inverse order gives, in one pass over memory with the GIL released.  The
 * positions must cover 0 .. width - 1 once each (checked on a copy, before anything is written, so an array
 * changed by another thread cannot send the writes out of bounds, and no output keeps an unwritten lane).  The
 * parts of a field must share its type and rows, one or two dimensions, C-contiguous, aligned, native byte order,
 * bool or numeric (the Python wrapper casts or copies them there).
 */

typedef struct {
    const char *src;
    npy_intp lanes;           /* of this part */
    const int64_t *positions; /* into the copied positions */
} Part;

/* out[r, positions[i]] = src[r, i] for every row r and i0 <= i < i1, of one field from one part. */
static void place(char *out, npy_intp width, npy_intp rows, npy_intp size, const Part *part, npy_intp i0,
                  npy_intp i1)
{
    const int64_t *at = part->positions;
    npy_intp k = part->lanes;
    for (npy_intp r = 0; r < rows; ++r) {
        const char *s = part->src + r * k * size;
        char *d = out + r * width * size;
        switch (size) {
        case 1:
            for (npy_intp i = i0; i < i1; ++i)
                d[at[i]] = s[i];
            break;
        case 4:
            for (npy_intp i = i0; i < i1; ++i)
                memcpy(d + 4 * at[i], s + 4 * i, 4);
            break;
        case 8:
            for (npy_intp i = i0; i < i1; ++i)
                memcpy(d + 8 * at[i], s + 8 * i, 8);
            break;
        default:
            for (npy_intp i = i0; i < i1; ++i)
                memcpy(d + size * at[i], s + size * i, (size_t)size);
        }
    }
}

/* Output columns written per window when every part's positions increase (subpaths: each part a depth, its lanes
 * in order): a part's writes into a window of a few kilobytes per row stay in the first-level cache, where one
 * part after another strides through the whole output (1.2-1.4x slower on 217k vertices of 32 depths). */
#define PLACE_WINDOW 2048

/* The field f of part p as the kernel reads it, checked against the field's first part `first` (NULL for p = 0):
 * borrowed, or NULL with a TypeError or ValueError. */
static PyArrayObject *part_field(PyObject *fields, Py_ssize_t p, Py_ssize_t f, npy_intp lanes, PyArrayObject *first)
{
    PyObject *item = PySequence_Fast_GET_ITEM(fields, f);
    if (!PyArray_Check(item)) {
        PyErr_Format(PyExc_TypeError, "place_lanes: parts[%zd][%zd] is not a NumPy array", p, f);
        return NULL;
    }
    PyArrayObject *array = (PyArrayObject *)item;
    int ndim = PyArray_NDIM(array), type = PyArray_TYPE(array);
    if (ndim < 1 || ndim > 2 || !(PyTypeNum_ISBOOL(type) || PyTypeNum_ISNUMBER(type)) ||
        !PyArray_IS_C_CONTIGUOUS(array) || !PyArray_ISALIGNED(array) || !PyArray_ISNOTSWAPPED(array)) {
        PyErr_Format(PyExc_TypeError, "place_lanes: parts[%zd][%zd] is not a C-contiguous, aligned, native bool or "
                     "numeric array of one or two dimensions", p, f);
        return NULL;
    }
    if (PyArray_DIM(array, ndim - 1) != lanes) {
        PyErr_Format(PyExc_ValueError, "place_lanes: parts[%zd][%zd] has %zd lanes, positions[%zd] %zd", p, f,
                     (Py_ssize_t)PyArray_DIM(array, ndim - 1), p, (Py_ssize_t)lanes);
        return NULL;
    }
    if (first && (ndim != PyArray_NDIM(first) || (ndim == 2 && PyArray_DIM(array, 0) != PyArray_DIM(first, 0)) ||
                  !PyArray_EquivTypes(PyArray_DESCR(array), PyArray_DESCR(first)))) {
        PyErr_Format(PyExc_TypeError, "place_lanes: parts[%zd][%zd] differs from parts[0][%zd] in type or rows",
                     p, f, f);
        return NULL;
    }
    return array;
}

PyObject *ps_place_lanes(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *positions_list, *parts_list;
    Py_ssize_t width;
    if (!PyArg_ParseTuple(args, "O!O!n:place_lanes", &PyList_Type, &positions_list, &PyList_Type, &parts_list,
                          &width))
        return NULL;
    Py_ssize_t count = PyList_GET_SIZE(positions_list);
    if (PyList_GET_SIZE(parts_list) != count || count == 0 || width < 0) {
        PyErr_Format(PyExc_ValueError, "place_lanes: %zd position lists for %zd parts, width %zd (expected as many, "
                     "at least one, width >= 0)", count, PyList_GET_SIZE(parts_list), width);
        return NULL;
    }
    /* every part's fields as a fast sequence (owned), all parts with as many fields */
    PyObject **fields = PyMem_Calloc((size_t)count, sizeof(PyObject *));
    Part *parts = NULL;
    int64_t *positions = NULL;
    const int64_t **given = NULL;
    unsigned char *seen = NULL;
    PyObject *out = NULL;
    if (!fields)
        return PyErr_NoMemory();
    Py_ssize_t nfields = -1, total = 0;
    for (Py_ssize_t p = 0; p < count; ++p) {
        fields[p] = PySequence_Fast(PyList_GET_ITEM(parts_list, p), "place_lanes: parts[p] is not a sequence");
        if (!fields[p])
            goto done;
        if (nfields >= 0 && PySequence_Fast_GET_SIZE(fields[p]) != nfields) {
            PyErr_Format(PyExc_ValueError, "place_lanes: parts[%zd] has %zd fields, parts[0] %zd", p,
                         PySequence_Fast_GET_SIZE(fields[p]), nfields);
            goto done;
        }
        nfields = PySequence_Fast_GET_SIZE(fields[p]);
        PyObject *index = ps_checked_array(PyList_GET_ITEM(positions_list, p), "positions[p]", NPY_INT64, -1,
                                           "int64", 1);
        if (!index)
            goto done;
        total += PyArray_DIM((PyArrayObject *)index, 0);
    }
    if (total != width) {
        PyErr_Format(PyExc_ValueError, "place_lanes: %zd positions for a width of %zd (expected each lane once)",
                     total, width);
        goto done;
    }
    /* parts[p] (field 0's) has the lanes of part p even without fields; given[p] its positions */
    parts = PyMem_Calloc((size_t)count * (size_t)(nfields ? nfields : 1), sizeof(Part));
    given = PyMem_Calloc((size_t)count, sizeof(int64_t *));
    positions = PyMem_Malloc(width ? (size_t)width * sizeof(int64_t) : 1);
    seen = PyMem_Calloc(width ? (size_t)width : 1, 1);
    out = PyList_New(nfields);
    if (!parts || !given || !positions || !seen || !out) {
        if (!PyErr_Occurred())
            PyErr_NoMemory();
        goto fail;
    }
    npy_intp start = 0;
    for (Py_ssize_t p = 0; p < count; ++p) {
        PyArrayObject *index = (PyArrayObject *)PyList_GET_ITEM(positions_list, p);
        npy_intp lanes = PyArray_DIM(index, 0);
        parts[p] = (Part){NULL, lanes, positions + start};
        for (Py_ssize_t f = 0; f < nfields; ++f) {
            PyArrayObject *first = p ? (PyArrayObject *)PySequence_Fast_GET_ITEM(fields[0], f) : NULL;
            PyArrayObject *array = part_field(fields[p], p, f, lanes, first);
            if (!array)
                goto fail;
            parts[f * count + p] = (Part){PyArray_BYTES(array), lanes, positions + start};
        }
        start += lanes;
    }
    for (Py_ssize_t f = 0; f < nfields; ++f) {
        PyObject *array = lanes_like((PyArrayObject *)PySequence_Fast_GET_ITEM(fields[0], f), width);
        if (!array)
            goto fail;
        PyList_SET_ITEM(out, f, array);
    }
    for (Py_ssize_t p = 0; p < count; ++p)
        given[p] = PyArray_DATA((PyArrayObject *)PyList_GET_ITEM(positions_list, p));
    npy_intp bad = -1, bad_part = 0;
    Py_BEGIN_ALLOW_THREADS
    start = 0;
    for (Py_ssize_t p = 0; p < count && bad < 0; ++p) {
        npy_intp lanes = parts[p].lanes;
        for (npy_intp i = 0; i < lanes; ++i) {
            int64_t at = given[p][i];
            if (at < 0 || at >= width || seen[at]) {
                bad = i, bad_part = p;
                break;
            }
            seen[at] = 1;
            positions[start + i] = at;
        }
        start += lanes;
    }
    /* windows[w * count + p]: the first lane of part p placed at or after column w * PLACE_WINDOW, if every part's
     * positions increase (else no windows: each part in one go) */
    npy_intp nwindows = (width + PLACE_WINDOW - 1) / PLACE_WINDOW;
    npy_intp *windows = NULL;
    int increasing = bad < 0;
    for (Py_ssize_t p = 0; p < count && increasing; ++p)
        for (npy_intp i = 1; i < parts[p].lanes; ++i)
            if (parts[p].positions[i] < parts[p].positions[i - 1]) {
                increasing = 0;
                break;
            }
    if (increasing)
        windows = malloc((size_t)(nwindows + 1) * (size_t)count * sizeof(npy_intp));
    if (windows)
        for (Py_ssize_t p = 0; p < count; ++p) {
            npy_intp i = 0;
            for (npy_intp w = 0; w <= nwindows; ++w) {
                while (i < parts[p].lanes && parts[p].positions[i] < w * PLACE_WINDOW)
                    ++i;
                windows[w * count + p] = w == nwindows ? parts[p].lanes : i;
            }
        }
    if (bad < 0)
        for (Py_ssize_t f = 0; f < nfields; ++f) {
            PyArrayObject *array = (PyArrayObject *)PyList_GET_ITEM(out, f);
            npy_intp rows = PyArray_NDIM(array) == 2 ? PyArray_DIM(array, 0) : 1, size = PyArray_ITEMSIZE(array);
            const Part *field = &parts[f * count];
            if (windows)
                for (npy_intp w = 0; w < nwindows; ++w)
                    for (Py_ssize_t p = 0; p < count; ++p)
                        place(PyArray_BYTES(array), width, rows, size, &field[p], windows[w * count + p],
                              windows[(w + 1) * count + p]);
            else
                for (Py_ssize_t p = 0; p < count; ++p)
                    place(PyArray_BYTES(array), width, rows, size, &field[p], 0, field[p].lanes);
        }
    free(windows);
    Py_END_ALLOW_THREADS
    if (bad >= 0) {
        PyErr_Format(PyExc_ValueError, "place_lanes: positions[%zd][%zd] is outside 0 .. %zd or repeats a lane",
                     (Py_ssize_t)bad_part, (Py_ssize_t)bad, width - 1);
        goto fail;
    }
    goto done;
fail:
    Py_CLEAR(out);
done:
    for (Py_ssize_t p = 0; p < count; ++p)
        Py_XDECREF(fields[p]);
    PyMem_Free(fields);
    PyMem_Free(parts);
    PyMem_Free(given);
    PyMem_Free(positions);
    PyMem_Free(seen);
    return out;
}

/* The lanes (columns) of a wavefront's contributions worth weighting (pathspace.estimators.connections.Batch.useful):
 * those whose values are finite in every row and not zero in some, in increasing order; and how many lanes hold
 * a NaN or an infinity. */
PyObject *ps_useful_lanes(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *obj;
    if (!PyArg_ParseTuple(args, "O:useful_lanes", &obj))
        return NULL;
    PyArrayObject *value = (PyArrayObject *)ps_checked_array(obj, "value", NPY_DOUBLE, -1, "float64", 2);
    if (!value)
        return NULL;
    npy_intp rows = PyArray_DIM(value, 0), n = PyArray_DIM(value, 1);
    PyObject *out = PyArray_SimpleNew(1, &n, NPY_INT64);
    if (!out)
        return NULL;
    const double *v = (const double *)PyArray_DATA(value);
    int64_t *lanes = (int64_t *)PyArray_DATA((PyArrayObject *)out);
    npy_intp count = 0, nonfinite = 0;
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp i = 0; i < n; ++i) {
        int finite = 1, nonzero = 0;
        for (npy_intp r = 0; r < rows; ++r) {
            double x = v[r * n + i];
            finite &= isfinite(x) != 0;
            nonzero |= x != 0.0;
        }
        nonfinite += !finite;
        lanes[count] = i;
        count += finite && nonzero;
    }
    Py_END_ALLOW_THREADS
    PyObject *useful = ps_first_entries(out, count);
    return useful ? Py_BuildValue("(Nn)", useful, (Py_ssize_t)nonfinite) : NULL;
}
