/*
 * One sample added to each of a run of pixels' moments (pathspace.film.Moments.add), in one pass with the GIL
 * released: the pass over the film that a render makes for every completed pass (on the thread that
 * collects the workers' results, where NumPy's dozen passes over the chunk held the GIL between them).
 *
 * Pixel i keeps its count n, a binary exponent e and its mean and M2 in units of 2^e and 4^e (see the film
 * module's docstring).  A sample x (C channels) of largest |x_c| = peak:
 *   - is left out if peak is not finite (NaN or Inf in a channel): the pixel's count does not grow;
 *   - else raises e to frexp(max(peak, DBL_MIN)) if that is larger, rescaling the stored mean by 2^(e_old - e)
 *     and M2 by 4^(e_old - e) (exact: powers of two) where the pixel has samples;
 *   - joins the moments by Chan, Golub & LeVeque's pairwise update (The American Statistician 37(3), 1983,
 *     eq. 1.5) with n_b = 1: delta = x 2^-e - mean, mean += delta / n, M2 += delta (delta n_a / n), or
 *     M2_cd += delta_c (delta_d n_a / n) for covariance moments.
 * Every value is computed in the operations and order of the NumPy expressions of the reference
 * (tests/test_film_kernel.py keeps them), so the moments are bit for bit the same.  The samples must not
 * overlap the moments' arrays (pixel i's update may change what a later column reads; the film's samples
 * are buffers of their own).
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

/* A writeable state array of the moments (checked as ps_checked_array does, and writeable). */
static PyArrayObject *state_array(PyObject *obj, const char *name, int type, const char *type_name, int ndim)
{
    PyArrayObject *a = (PyArrayObject *)ps_checked_array(obj, name, type, -1, type_name, ndim);
    if (a && !PyArray_ISWRITEABLE(a)) {
        PyErr_Format(PyExc_ValueError, "%s must be writeable", name);
        return NULL;
    }
    return a;
}

/* The binary exponent e of a normal, finite x > 0 (x = m 2^e, 0.5 <= m < 1: frexp's), read from its bits. */
static int exponent_of(double x)
{
    uint64_t bits;
    memcpy(&bits, &x, sizeof bits);
    return (int)((bits >> 52) & 0x7ff) - 1022;
}

/* 2^k, exact: built from its bits where it is a normal double, else by ldexp (subnormal powers). */
static double power_of_two(int k)
{
    if (k < -1022 || k > 1023)
        return ldexp(1.0, k);
    uint64_t bits = (uint64_t)(k + 1023) << 52;
    double x;
    memcpy(&x, &bits, sizeof x);
    return x;
}

/* The largest |x_c| over the channels of column i (rows `row` apart), NaN if any channel is NaN (as NumPy's max
 * propagates it). */
static double column_peak(const double *x, npy_intp row, npy_intp channels, npy_intp i)
{
    double peak = fabs(x[i]);
    for (npy_intp c = 1; c < channels && !isnan(peak); ++c) {
        double a = fabs(x[c * row + i]);
        if (isnan(a) || a > peak)
            peak = a;
    }
    return peak;
}

PyObject *ps_moments_add(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *objs[5];
    Py_ssize_t start;
    if (!PyArg_ParseTuple(args, "OOOOnO:moments_add", &objs[0], &objs[1], &objs[2], &objs[3], &start, &objs[4]))
        return NULL;
    PyArrayObject *count = state_array(objs[0], "count", NPY_INT64, "int64", 1);
    PyArrayObject *exponent = count ? state_array(objs[1], "exponent", NPY_INT32, "int32", 1) : NULL;
    PyArrayObject *mean = exponent ? state_array(objs[2], "scaled_mean", NPY_DOUBLE, "float64", 2) : NULL;
    if (!mean)
        return NULL;
    int covariance = PyArray_Check(objs[3]) && PyArray_NDIM((PyArrayObject *)objs[3]) == 3;
    PyArrayObject *m2 = state_array(objs[3], "scaled_m2", NPY_DOUBLE, "float64", covariance ? 3 : 2);
    if (!m2)
        return NULL;
    /* The samples may be a range of columns of a wider array. */
    PyArrayObject *values = (PyArrayObject *)ps_rows_array(objs[4], "values", NPY_DOUBLE, "float64", -1);
    if (!values)
        return NULL;
    npy_intp pixels = PyArray_DIM(count, 0), channels = PyArray_DIM(mean, 0), n = PyArray_DIM(values, 1);
    int shapes = PyArray_DIM(exponent, 0) == pixels && PyArray_DIM(mean, 1) == pixels && channels >= 1 &&
                 PyArray_DIM(m2, 0) == channels && PyArray_DIM(m2, covariance ? 2 : 1) == pixels &&
                 (!covariance || PyArray_DIM(m2, 1) == channels) && PyArray_DIM(values, 0) == channels;
    if (!shapes) {
        PyErr_SetString(PyExc_ValueError, "moments_add: count and exponent (P,), scaled_mean (C, P), scaled_m2 "
                                          "(C, P) or (C, C, P) and values (C, n) must agree");
        return NULL;
    }
    if (start < 0 || start > pixels - n) {
        PyErr_Format(PyExc_ValueError, "moments_add: %zd pixels from %zd are outside the film's %zd",
                     (Py_ssize_t)n, start, (Py_ssize_t)pixels);
        return NULL;
    }
    PyArrayObject *peaks = (PyArrayObject *)PyArray_SimpleNew(1, &n, NPY_DOUBLE);
    double *delta = malloc(2 * (size_t)channels * sizeof(double));   /* per channel: delta, then delta n_a / n */
    if (!peaks || !delta) {
        Py_XDECREF(peaks);
        free(delta);
        return PyErr_NoMemory();
    }
    double *step = delta + channels;
    int64_t *cnt = (int64_t *)PyArray_DATA(count) + start;
    int32_t *exp2 = (int32_t *)PyArray_DATA(exponent) + start;
    double *mu = (double *)PyArray_DATA(mean) + start, *sq = (double *)PyArray_DATA(m2) + start;
    const double *x = (const double *)PyArray_DATA(values);
    npy_intp row = PyArray_STRIDE(values, 0) / (npy_intp)sizeof(double), entries = covariance ? channels : 1;
    double *peak = (double *)PyArray_DATA(peaks);
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp i = 0; i < n; ++i) {
        double top = column_peak(x, row, channels, i);
        peak[i] = top;
        int finite = isfinite(top);
        int e = exponent_of(finite && top > DBL_MIN ? top : DBL_MIN);
        if (e > exp2[i]) {   /* only finite samples raise it: the others' exponent is the floor */
            if (cnt[i] > 0) {
                int shift = exp2[i] - e;
                for (npy_intp c = 0; c < channels; ++c)
                    mu[c * pixels + i] = ldexp(mu[c * pixels + i], shift);
                for (npy_intp c = 0; c < channels * entries; ++c)
                    sq[c * pixels + i] = ldexp(sq[c * pixels + i], 2 * shift);
            }
            exp2[i] = e;
        }
        int64_t n_a = cnt[i], n_b = finite ? 1 : 0, total = n_a + n_b;
        double weight_b = (double)n_b / (double)(total > 1 ? total : 1);   /* n_b / n */
        double unit = power_of_two(-exp2[i]), spread = (double)n_a * weight_b;   /* n_a n_b / n */
        for (npy_intp c = 0; c < channels; ++c) {
            double sample = finite ? x[c * row + i] : 0.0;
            double d = sample * unit - mu[c * pixels + i];
            mu[c * pixels + i] += d * weight_b;
            delta[c] = d;
            step[c] = d * spread;
        }
        if (covariance) {
            for (npy_intp c = 0; c < channels; ++c)
                for (npy_intp k = 0; k < channels; ++k)
                    sq[(c * channels + k) * pixels + i] += delta[c] * step[k];
        } else {
            for (npy_intp c = 0; c < channels; ++c)
                sq[c * pixels + i] += step[c] * delta[c];
        }
        cnt[i] = total;
    }
    Py_END_ALLOW_THREADS
    free(delta);
    return (PyObject *)peaks;
}

/* splat_add(buffer, pixels, values): buffer[c, pixels[i]] += values[c, i] for every splat i in order, channel by
 * channel -- np.add.at(buffer[c], pixels, values[c]) for every c, bit for bit (the same additions in the same
 * order), in one pass with the GIL released: light tracing's and BDPT's splats land on the film on the thread
 * that collects the workers' results, where np.add.at held the GIL.  Every pixel index is checked first
 * (IndexError naming the first outside 0 .. P - 1; the buffer is then unchanged). */
PyObject *ps_splat_add(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *objs[3];
    if (!PyArg_ParseTuple(args, "OOO:splat_add", &objs[0], &objs[1], &objs[2]))
        return NULL;
    PyArrayObject *buffer = state_array(objs[0], "buffer", NPY_DOUBLE, "float64", 2);
    PyArrayObject *pixels = buffer ? (PyArrayObject *)ps_checked_array(objs[1], "pixels", NPY_INT64, -1, "int64", 1)
                                   : NULL;
    PyArrayObject *values = pixels ? (PyArrayObject *)ps_rows_array(objs[2], "values", NPY_DOUBLE, "float64", -1)
                                   : NULL;
    if (!values)
        return NULL;
    npy_intp channels = PyArray_DIM(buffer, 0), size = PyArray_DIM(buffer, 1), n = PyArray_DIM(pixels, 0);
    if (PyArray_DIM(values, 0) != channels || PyArray_DIM(values, 1) != n) {
        PyErr_Format(PyExc_ValueError, "splat_add: values of shape (%zd, %zd) for a buffer of %zd channels and %zd "
                     "pixels; expected (%zd, %zd)", (Py_ssize_t)PyArray_DIM(values, 0),
                     (Py_ssize_t)PyArray_DIM(values, 1), (Py_ssize_t)channels, (Py_ssize_t)n, (Py_ssize_t)channels,
                     (Py_ssize_t)n);
        return NULL;
    }
    const int64_t *pixel = (const int64_t *)PyArray_DATA(pixels);
    double *out = (double *)PyArray_DATA(buffer);
    const double *x = (const double *)PyArray_DATA(values);
    npy_intp row = PyArray_STRIDE(values, 0) / (npy_intp)sizeof(double), bad = -1;
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp i = 0; i < n && bad < 0; ++i)
        if (pixel[i] < 0 || pixel[i] >= size)
            bad = i;
    for (npy_intp c = 0; c < channels && bad < 0; ++c) {
        double *film = out + c * size;
        const double *splat = x + c * row;
        for (npy_intp i = 0; i < n; ++i)
            film[pixel[i]] += splat[i];
    }
    Py_END_ALLOW_THREADS
    if (bad >= 0) {
        PyErr_Format(PyExc_IndexError, "splat_add: pixel %lld of splat %zd is outside the film's 0 .. %zd",
                     (long long)pixel[bad], (Py_ssize_t)bad, (Py_ssize_t)(size - 1));
        return NULL;
    }
    Py_RETURN_NONE;
}
