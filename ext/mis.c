/*
 * MIS weights of bidirectional path tracing strategies, from ratios of vertex pdfs.
 *
 * A path x_0 .. x_k (x_0 on a light, x_k on the camera) built by strategy (s, t),
 * s + t = k + 1, has s light-subpath vertices x_0 .. x_{s-1} and t eye-subpath
 * vertices x_k .. x_s.  Every vertex has two densities in area measure: p_fwd,
 * with which its own subpath generated it, and p_rev, with which the other
 * subpath would have.  The probability of strategy s' relative to that of s is
 * a product of p_rev / p_fwd over the vertices between the two split points
 * (Veach 1997, eq. 10.9); the weight is 1 / sum over strategies s' of
 * (p_s' / p_s)^beta (power heuristic; beta = 1: balance).  Ratios are built up
 * one vertex at a time, as in pbrt-v4's MISWeight, so no product of raw pdfs
 * is ever formed, and carried as a double that takes a separate binary exponent
 * whenever it nears over- or underflow, so that paths of hundreds of vertices
 * whose densities span hundreds of decades stay exact to rounding; a pdf of 0
 * (one that does not exist, as pbrt-v4 stores around delta vertices) is
 * remapped to 1 -- BDPT's subpaths give a specular vertex's neighbours the
 * densities of Veach's convention instead (pathspace.estimators.subpaths) --,
 * and a strategy is counted only if the connection it needs joins two
 * non-delta vertices (s' = 0: the light can be hit; s' = k + 1: the camera
 * can be hit).
 *
 * Inputs per connection m: s, t, lane, flags of the light at x_0 (LIGHT_DELTA:
 * it cannot be hit by rays -- point, spot and directional lights;
 * LIGHT_INFINITE: it lies at infinity -- environment and directional lights --
 * so strategy (1, 1), which would join it to a camera point, cannot produce
 * the path); the subpaths
 * of each lane as flat arrays (CSR offsets per lane) of p_fwd, p_rev and
 * delta; and the values that
 * change for this connection: p_fwd and p_rev of the two connection vertices
 * x_{s-1} ("qs") and x_s ("pt"), and p_rev of their neighbours x_{s-2} and
 * x_{s+1} (pbrt's ScopedAssignments).  The connection vertices are read from
 * these overrides only, so they need not exist in the subpath arrays (a fresh
 * light sample for s = 1, a lens sample for t = 1, a lens hit for t = 0), and
 * their own delta flags are not consulted where they end the path (s = 0: the
 * eye vertex that found the light; t = 0: the lens a light subpath hit).
 *
 * MIS over a subset of the strategies: an optional table allowed[s * size + t]
 * (s, t < size) names the strategies that take part; the others get weight 0
 * and are left out of every sum, so the weights of a path still add up to one
 * over the strategies of the subset that can produce it.
 */
#include "native.h"

#define NPY_NO_DEPRECATED_API NPY_2_0_API_VERSION
#define NO_IMPORT_ARRAY
#define PY_ARRAY_UNIQUE_SYMBOL pathspace_native_ARRAY_API
#include <numpy/arrayobject.h>

#include <math.h>
#include <stdint.h>
#include <string.h>

enum { H_BALANCE = 0, H_POWER = 1, H_UNIFORM = 2, H_SINGLE = 3, H_NONE = 4 };
enum { LIGHT_DELTA = 1, LIGHT_INFINITE = 2 };

static inline double remap0(double x) { return x != 0.0 ? x : 1.0; }

/* A positive ratio kept as mantissa * 2^exponent, so that long products of pdf ratios spanning
 * hundreds of decades neither overflow nor underflow before they are compared. */
typedef struct {
    double mantissa;
    long exponent;
} Ratio;

static inline void ratio_times(Ratio *r, double numerator, double denominator)
{
    /* Common case: the factor and the product stay far from overflow and underflow, so a plain
     * multiply is exact to rounding; otherwise fall back to exponent bookkeeping. */
    double factor = numerator / denominator, product = r->mantissa * factor;
    if (factor > 0x1p-300 && factor < 0x1p300 && product > 0x1p-600 && product < 0x1p600) {
        r->mantissa = product;
        return;
    }
    int en, ed, er;
    double mn = frexp(numerator, &en), md = frexp(denominator, &ed);
    r->mantissa = frexp(r->mantissa * (mn / md), &er);
    r->exponent += (long)en - ed + er;
}

typedef struct {
    const int32_t *s, *t;
    const int64_t *lane;
    const int64_t *light_offset, *eye_offset;
    const double *light_fwd, *light_rev, *eye_fwd, *eye_rev;
    const uint8_t *light_delta, *eye_delta, *light_flags;
    const double *qs_fwd, *qs_rev, *qs_minus_rev, *pt_fwd, *pt_rev, *pt_minus_rev;
    int camera_is_delta;
    int heuristic;
    double beta;
    int target_s, target_t;
    const uint8_t *allowed;  /* NULL: every strategy takes part */
    int allowed_size;
    npy_intp allowed_stride[2];  /* in bytes (= entries): the table is read in place, never copied */
    double *out;
} MisBatch;

static inline int takes_part(const MisBatch *b, int s, int t)
{
    if (b->allowed == NULL)
        return 1;
    return s < b->allowed_size && t < b->allowed_size &&
           b->allowed[(npy_intp)s * b->allowed_stride[0] + (npy_intp)t * b->allowed_stride[1]];
}

/* The heuristic's term for a strategy whose probability is r times the current one's. */
static inline double term(const Ratio *r, const MisBatch *b)
{
    if (b->heuristic == H_UNIFORM)
        return 1.0;
    double beta = b->heuristic == H_POWER ? b->beta : 1.0;
    if (r->exponent == 0 && r->mantissa > 0x1p-500 && r->mantissa < 0x1p500) {
        if (beta == 1.0)
            return r->mantissa;
        if (beta == 2.0)
            return r->mantissa * r->mantissa;
    }
    int e;
    double mantissa = frexp(r->mantissa, &e);
    long exponent = r->exponent + e;
    if (beta == 1.0 && labs(exponent) < 2000)
        return ldexp(mantissa, (int)exponent);
    if (beta == 2.0 && labs(exponent) < 1000)
        return ldexp(mantissa * mantissa, (int)(2 * exponent));
    double log2_value = beta * (log2(mantissa) + (double)exponent);
    return log2_value > 1100.0 ? INFINITY : exp2(log2_value);
}

static double weight_of(const MisBatch *b, npy_intp m)
{
    int s = b->s[m], t = b->t[m];
    int64_t lane = b->lane[m];
    const double *lf = b->light_fwd + b->light_offset[lane], *lr = b->light_rev + b->light_offset[lane];
    const uint8_t *ld = b->light_delta + b->light_offset[lane];
    const double *ef = b->eye_fwd + b->eye_offset[lane], *er = b->eye_rev + b->eye_offset[lane];
    const uint8_t *ed = b->eye_delta + b->eye_offset[lane];
    int64_t light_len = b->light_offset[lane + 1] - b->light_offset[lane];
    int64_t eye_len = b->eye_offset[lane + 1] - b->eye_offset[lane];
    int light_delta = b->light_flags[m] & LIGHT_DELTA;
    /* Strategy (1, 1) of a path whose light lies at infinity: no camera point can be joined to it. */
    int no_11 = (b->light_flags[m] & LIGHT_INFINITE) && s + t == 2;
    /* A strategy that cannot produce the path has weight 0: it would connect through a delta vertex,
     * hit a light that cannot be hit (s = 0), or hit a camera that cannot be hit (t = 0). */
    if ((s == 0 && light_delta) || (t == 0 && b->camera_is_delta) || (s == 1 && t == 1 && no_11) ||
        (s >= 1 && t >= 1 && s - 1 < light_len && ld[s - 1]) || (t >= 1 && s >= 1 && t - 1 < eye_len && ed[t - 1]) ||
        !takes_part(b, s, t))
        return 0.0;
    if (b->heuristic == H_NONE)
        return 1.0;
    if (b->heuristic == H_SINGLE)
        return (s == b->target_s && t == b->target_t) ? 1.0 : 0.0;
    double sum = 0.0;
    Ratio r = {1.0, 0};

    /* Eye side: move the split toward the camera, one eye vertex at a time (t' = t-1 .. 0). */
    for (int i = t - 1; i >= 0; --i) {
        double fwd = i == t - 1 ? b->pt_fwd[m] : ef[i];
        double rev = i == t - 1 ? b->pt_rev[m] : (i == t - 2 ? b->pt_minus_rev[m] : er[i]);
        ratio_times(&r, remap0(rev), remap0(fwd));
        int delta_here = i == t - 1 ? 0 : ed[i];
        int valid = i > 0 ? (!delta_here && !ed[i - 1]) : (!delta_here && !b->camera_is_delta);
        if (valid && !(i == 1 && no_11) && takes_part(b, s + t - i, i))
            sum += term(&r, b);
    }
    /* Light side: move the split toward the light (s' = s-1 .. 0). */
    r.mantissa = 1.0;
    r.exponent = 0;
    for (int i = s - 1; i >= 0; --i) {
        double fwd = i == s - 1 ? b->qs_fwd[m] : lf[i];
        double rev = i == s - 1 ? b->qs_rev[m] : (i == s - 2 ? b->qs_minus_rev[m] : lr[i]);
        ratio_times(&r, remap0(rev), remap0(fwd));
        int delta_here = i == s - 1 ? 0 : ld[i];
        int delta_before = i > 0 ? ld[i - 1] : light_delta;
        if (!delta_here && !delta_before && !(i == 1 && no_11) && takes_part(b, i, s + t - i))
            sum += term(&r, b);
    }
    return 1.0 / (1.0 + sum);
}

static PyArrayObject *as_array(PyObject *obj, int type, const char *name, npy_intp length)
{
    PyArrayObject *a = (PyArrayObject *)PyArray_FROMANY(obj, type, 1, 1, NPY_ARRAY_C_CONTIGUOUS | NPY_ARRAY_ALIGNED);
    if (a == NULL) {
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "mis_weights: %s must be a 1-D array convertible to the expected dtype", name);
        return NULL;
    }
    if (length >= 0 && PyArray_DIM(a, 0) != length) {
        PyErr_Format(PyExc_ValueError, "mis_weights: %s has %zd entries, expected %zd", name,
                     (Py_ssize_t)PyArray_DIM(a, 0), (Py_ssize_t)length);
        Py_DECREF(a);
        return NULL;
    }
    return a;
}

PyObject *ps_mis_weights(PyObject *module, PyObject *args, PyObject *kwargs)
{
    (void)module;
    static char *kwlist[] = {"s", "t", "lane", "light_offset", "light_fwd", "light_rev", "light_delta",
                             "eye_offset", "eye_fwd", "eye_rev", "eye_delta", "light_flags",
                             "qs_fwd", "qs_rev", "qs_minus_rev", "pt_fwd", "pt_rev", "pt_minus_rev",
                             "camera_is_delta", "heuristic", "beta", "target_s", "target_t", "allowed", NULL};
    PyObject *o[18];
    PyObject *allowed_obj = Py_None;
    int camera_is_delta = 0, heuristic = H_POWER, target_s = -1, target_t = -1;
    double beta = 2.0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOOOOOOOOOOOOOOOOO|$pidiiO:mis_weights", kwlist, &o[0], &o[1],
                                     &o[2], &o[3], &o[4], &o[5], &o[6], &o[7], &o[8], &o[9], &o[10], &o[11], &o[12],
                                     &o[13], &o[14], &o[15], &o[16], &o[17], &camera_is_delta, &heuristic, &beta,
                                     &target_s, &target_t, &allowed_obj))
        return NULL;
    if (heuristic < H_BALANCE || heuristic > H_NONE) {
        PyErr_SetString(PyExc_ValueError, "mis_weights: unknown heuristic code");
        return NULL;
    }
    if (!(beta > 0.0) || !isfinite(beta)) {
        PyErr_SetString(PyExc_ValueError, "mis_weights: beta must be finite and > 0");
        return NULL;
    }
    PyArrayObject *a[18] = {NULL};
    PyArrayObject *allowed = NULL;
    PyObject *result = NULL;
    if (allowed_obj != Py_None) {
        /* Any strides (a uint8 array is used as it is), so the size is checked before anything is copied. */
        allowed = (PyArrayObject *)PyArray_FROMANY(allowed_obj, NPY_UINT8, 2, 2, 0);
        if (allowed == NULL || PyArray_DIM(allowed, 0) != PyArray_DIM(allowed, 1) || PyArray_DIM(allowed, 0) > 1 << 20) {
            PyErr_Clear();
            PyErr_SetString(PyExc_ValueError, "mis_weights: allowed must be a square (size, size) array of flags");
            goto done;
        }
    }
    static const int types[18] = {NPY_INT32, NPY_INT32, NPY_INT64, NPY_INT64, NPY_DOUBLE, NPY_DOUBLE, NPY_UINT8,
                                  NPY_INT64, NPY_DOUBLE, NPY_DOUBLE, NPY_UINT8, NPY_UINT8, NPY_DOUBLE, NPY_DOUBLE,
                                  NPY_DOUBLE, NPY_DOUBLE, NPY_DOUBLE, NPY_DOUBLE};
    for (int k = 0; k < 18; ++k) {
        a[k] = as_array(o[k], types[k], kwlist[k], -1);
        if (a[k] == NULL)
            goto done;
    }
    npy_intp m_count = PyArray_DIM(a[0], 0);
    npy_intp lanes = PyArray_DIM(a[3], 0) - 1;
    if (lanes < 0 || PyArray_DIM(a[7], 0) != lanes + 1) {
        PyErr_SetString(PyExc_ValueError, "mis_weights: light_offset and eye_offset need lanes + 1 entries");
        goto done;
    }
    for (int k = 1; k < 18; ++k) {
        if (k >= 3 && k <= 10)
            continue;
        if (PyArray_DIM(a[k], 0) != m_count) {
            PyErr_Format(PyExc_ValueError, "mis_weights: %s has %zd entries, expected one per connection (%zd)",
                         kwlist[k], (Py_ssize_t)PyArray_DIM(a[k], 0), (Py_ssize_t)m_count);
            goto done;
        }
    }
    const int64_t *loff = (const int64_t *)PyArray_DATA(a[3]), *eoff = (const int64_t *)PyArray_DATA(a[7]);
    npy_intp light_vertices = PyArray_DIM(a[4], 0), eye_vertices = PyArray_DIM(a[8], 0);
    if (PyArray_DIM(a[5], 0) != light_vertices || PyArray_DIM(a[6], 0) != light_vertices ||
        PyArray_DIM(a[9], 0) != eye_vertices || PyArray_DIM(a[10], 0) != eye_vertices ||
        loff[lanes] != light_vertices || eoff[lanes] != eye_vertices) {
        PyErr_SetString(PyExc_ValueError, "mis_weights: subpath arrays disagree with their offsets");
        goto done;
    }
    const int32_t *s = (const int32_t *)PyArray_DATA(a[0]), *t = (const int32_t *)PyArray_DATA(a[1]);
    const int64_t *lane = (const int64_t *)PyArray_DATA(a[2]);
    npy_intp dims[1] = {m_count};
    result = PyArray_SimpleNew(1, dims, NPY_DOUBLE);
    if (result == NULL)
        goto done;
    MisBatch b = {
        s, t, lane, loff, eoff,
        (const double *)PyArray_DATA(a[4]), (const double *)PyArray_DATA(a[5]),
        (const double *)PyArray_DATA(a[8]), (const double *)PyArray_DATA(a[9]),
        (const uint8_t *)PyArray_DATA(a[6]), (const uint8_t *)PyArray_DATA(a[10]),
        (const uint8_t *)PyArray_DATA(a[11]),
        (const double *)PyArray_DATA(a[12]), (const double *)PyArray_DATA(a[13]),
        (const double *)PyArray_DATA(a[14]), (const double *)PyArray_DATA(a[15]),
        (const double *)PyArray_DATA(a[16]), (const double *)PyArray_DATA(a[17]),
        camera_is_delta, heuristic, beta, target_s, target_t,
        allowed ? (const uint8_t *)PyArray_DATA(allowed) : NULL, allowed ? (int)PyArray_DIM(allowed, 0) : 0,
        {allowed ? PyArray_STRIDE(allowed, 0) : 0, allowed ? PyArray_STRIDE(allowed, 1) : 0},
        (double *)PyArray_DATA((PyArrayObject *)result),
    };
    /* The checks read every offset and connection, so they run with the GIL released too (another render thread
     * has it meanwhile); the first offset or connection that breaks them is reported once it is taken back. */
    npy_intp broken_offset = -1, broken_connection = -1;
    Py_BEGIN_ALLOW_THREADS
    /* Every lane's vertices must lie within the arrays: offsets start at 0 and never decrease. */
    for (npy_intp j = 0; j <= lanes; ++j) {
        if (j == 0 ? loff[0] != 0 || eoff[0] != 0 : loff[j] < loff[j - 1] || eoff[j] < eoff[j - 1]) {
            broken_offset = j;
            break;
        }
    }
    for (npy_intp m = 0; broken_offset < 0 && m < m_count; ++m) {
        if (lane[m] < 0 || lane[m] >= lanes || s[m] < 0 || t[m] < 0 || (int64_t)s[m] + t[m] < 2 ||
            s[m] - 1 > loff[lane[m] + 1] - loff[lane[m]] || t[m] - 1 > eoff[lane[m] + 1] - eoff[lane[m]]) {
            broken_connection = m;
            break;
        }
    }
    if (broken_offset < 0 && broken_connection < 0)
        for (npy_intp m = 0; m < m_count; ++m)
            b.out[m] = weight_of(&b, m);
    Py_END_ALLOW_THREADS
    if (broken_offset >= 0) {
        PyErr_Format(PyExc_ValueError, "mis_weights: light_offset and eye_offset must start at 0 and never "
                     "decrease (entry %zd breaks this)", (Py_ssize_t)broken_offset);
        Py_CLEAR(result);
    } else if (broken_connection >= 0) {
        npy_intp m = broken_connection;
        PyErr_Format(PyExc_ValueError, "mis_weights: connection %zd (lane %lld, s=%d, t=%d) does not fit its "
                     "subpaths", (Py_ssize_t)m, (long long)lane[m], s[m], t[m]);
        Py_CLEAR(result);
    }
done:
    for (int k = 0; k < 18; ++k)
        Py_XDECREF(a[k]);
    Py_XDECREF(allowed);
    return result;
}
