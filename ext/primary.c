/*
 * Primary sample space of Metropolis chains (pathspace.estimators.primary.ChainStates): a proposal's numbers
 * fetched, and the proposal settled, each in one pass over the numbers asked for.
 *
 * primary_fetch serves the proposal's numbers at (rows[i], columns[i]) of a (width, chains) state, each pair
 * asked for at most once per call: a number the proposal has drawn already (not NaN) is returned as it is;
 * any other is drawn now and kept in the proposal -- a fresh uniform for fresh states and large steps; else
 * the current number brought up to date (Kelemen et al. 2002, lazily as pbrt-v3's MLTSampler: a fresh uniform
 * if an accepted large step replaced it since it was stored, else the sum of the accepted small steps it
 * missed), stored as current, and, unless the proposal replays the current state, moved by one small step.
 * Uniforms come from draw(k) (the chains' own stream) in a fixed order: number by number as asked, each
 * number's catch-up before its step, a pair per step (so each number consumes exactly what SmallStep.steps
 * and SmallStep.single consume for that number alone; tests/estimators/test_primary.py checks the kernel
 * against them).  Pass 1 counts the uniforms; they are drawn at once and used with the GIL released when
 * they are at most PRIMARY_CHUNK, else in chunks of PRIMARY_CHUNK with the GIL held (a long catch-up: bounded
 * memory).  If the call fails (draw raises, or the state changed under it so that the count no longer
 * holds), no number it drew stays in the proposal.
 *
 * primary_settle ends a proposal: the chains that accept take its numbers (stamped with their accepted count
 * + 1), and every number it drew is forgotten (NaN); for fresh states (no current state) it only forgets.
 */
#include "native.h"

#define NPY_NO_DEPRECATED_API NPY_2_0_API_VERSION
#define NO_IMPORT_ARRAY
#define PY_ARRAY_UNIQUE_SYMBOL pathspace_native_ARRAY_API
#include <numpy/arrayobject.h>

#include <math.h>
#include <stdint.h>
#include <stdlib.h>

#define PRIMARY_CHUNK ((long long)1 << 20)

enum { MODE_CHAIN = 0, MODE_REPLAY = 1, MODE_FRESH = 2 };
enum { KERNEL_EXPONENTIAL = 0, KERNEL_GAUSSIAN = 1 };

typedef struct {
    double *proposal, *current;
    int64_t *stamp;
    const int64_t *accepted, *last_large;
    const npy_bool *large;
    npy_intp chains;
    int mode, kernel;
    double size, limit, log16;
} State;

/* Uniforms from the chains' stream: the current chunk and how many are still to be drawn after it.  With
 * nogil set (the GIL released) the chunk is never refilled: running short sets short_count instead. */
typedef struct {
    PyObject *draw, *chunk;
    const double *data;
    npy_intp length, used;
    long long pending;
    int nogil, short_count;
} Uniforms;

/* Replace the chunk by the next min(pending, PRIMARY_CHUNK) uniforms (GIL held); -1 on failure, with an
 * exception set or short_count. */
static int refill(Uniforms *u)
{
    long long k = u->pending < PRIMARY_CHUNK ? u->pending : PRIMARY_CHUNK;
    if (k <= 0) {
        u->short_count = 1;
        return -1;
    }
    Py_CLEAR(u->chunk);
    PyObject *drawn = PyObject_CallFunction(u->draw, "L", k);
    if (!drawn)
        return -1;
    if (!PyArray_Check(drawn) || PyArray_TYPE((PyArrayObject *)drawn) != NPY_DOUBLE ||
        PyArray_NDIM((PyArrayObject *)drawn) != 1 || PyArray_DIM((PyArrayObject *)drawn, 0) != k) {
        PyErr_Format(PyExc_ValueError, "draw(%lld) must return %lld uniforms as a 1-D float64 array, got %R", k, k,
                     drawn);
        Py_DECREF(drawn);
        return -1;
    }
    PyArrayObject *a = (PyArrayObject *)PyArray_FROMANY(drawn, NPY_DOUBLE, 1, 1, NPY_ARRAY_IN_ARRAY);
    Py_DECREF(drawn);
    if (!a)
        return -1;
    u->chunk = (PyObject *)a;
    u->data = (const double *)PyArray_DATA(a);
    u->length = k;
    u->used = 0;
    u->pending -= k;
    return 0;
}

/* The next uniform in *x; -1 if there is none (see Uniforms and refill). */
static inline int next_uniform(Uniforms *u, double *x)
{
    if (u->used == u->length) {
        if (u->nogil) {
            u->short_count = 1;
            return -1;
        }
        if (refill(u) < 0)
            return -1;
    }
    *x = u->data[u->used++];
    return 0;
}

/* x mod 1 in [0, 1): x - floor(x), but a value that rounds up to 1.0 becomes 0.0. */
static inline double wrap(double x)
{
    double y = x - floor(x);
    return y >= 1.0 ? 0.0 : y;
}

static inline double exponential_step(const State *s, double magnitude, double sign)
{
    return s->size * exp(-s->log16 * magnitude) * (sign < 0.5 ? -1.0 : 1.0);
}

/* How many uniforms the catch-up of the current number at flat (of chain r) consumes. */
static long long catch_up_uniforms(const State *s, npy_intp flat, npy_intp r)
{
    int64_t stamp = s->stamp[flat], accepted = s->accepted[r];
    if (stamp < s->last_large[r])
        return 1;
    if (stamp >= accepted)
        return 0;
    if (s->kernel == KERNEL_GAUSSIAN)
        return 2;                              /* one normal of sigma sqrt(n): a pair */
    if ((double)(accepted - stamp) >= s->limit)
        return 1;                              /* past the catch-up limit: one uniform */
    return 2 * (long long)(accepted - stamp);  /* a pair per exponential step */
}

/* How many uniforms drawing the proposal's number at flat (of chain r) consumes. */
static long long uniforms_needed(const State *s, npy_intp flat, npy_intp r)
{
    if (s->mode == MODE_FRESH || (s->mode == MODE_CHAIN && s->large[r]))
        return 1;
    return catch_up_uniforms(s, flat, r) + (s->mode == MODE_CHAIN ? 2 : 0);
}

/* The sum of n small steps in *sum (primary.SmallStep.steps for one number: a pair of uniforms per step);
 * -1 if the uniforms ran out. */
static int small_steps(const State *s, int64_t n, Uniforms *u, double *sum)
{
    if (s->kernel == KERNEL_GAUSSIAN) {
        double a, b;
        if (next_uniform(u, &a) < 0 || next_uniform(u, &b) < 0)
            return -1;
        double normal = sqrt(-2.0 * log1p(-a)) * cos(2.0 * M_PI * b);   /* Box-Muller */
        *sum = s->size * sqrt((double)n) * normal;
        return 0;
    }
    if ((double)n >= s->limit)
        return next_uniform(u, sum);    /* their sum modulo 1 is uniform to within 1e-12 */
    double total = 0.0;
    for (int64_t k = 0; k < n; ++k) {
        double magnitude, sign;
        if (next_uniform(u, &magnitude) < 0 || next_uniform(u, &sign) < 0)
            return -1;
        total += exponential_step(s, magnitude, sign);
    }
    *sum = total;
    return 0;
}

/* Draw the proposal's number at flat (of chain r) into *value (see the file's comment); -1 if the uniforms
 * ran out, the proposal then untouched (a caught-up current number stays: it is the chain's state). */
static int draw_number(const State *s, npy_intp flat, npy_intp r, Uniforms *u, double *value)
{
    if (s->mode == MODE_FRESH || (s->mode == MODE_CHAIN && s->large[r]))
        return next_uniform(u, value);
    double current = s->current[flat], step;
    int64_t stamp = s->stamp[flat], accepted = s->accepted[r];
    if (stamp < s->last_large[r]) {
        if (next_uniform(u, &current) < 0)
            return -1;
    } else if (stamp < accepted) {
        if (small_steps(s, accepted - stamp, u, &step) < 0)
            return -1;
        current = wrap(current + step);
    }
    s->current[flat] = current;
    s->stamp[flat] = accepted;
    if (s->mode == MODE_REPLAY) {
        *value = current;
        return 0;
    }
    if (small_steps(s, 1, u, &step) < 0)
        return -1;
    *value = wrap(current + step);
    return 0;
}

/* Draw the missing numbers (flat[k], chain[k]) into the proposal and out[at[k]]; -1 if the uniforms ran out. */
static int draw_missing(const State *s, npy_intp missing, const npy_intp *flat, const npy_intp *chain,
                        const npy_intp *at, double *out, Uniforms *u)
{
    for (npy_intp k = 0; k < missing; ++k) {
        double value;
        if (draw_number(s, flat[k], chain[k], u, &value) < 0)
            return -1;
        s->proposal[flat[k]] = value;
        out[at[k]] = value;
    }
    return 0;
}

/* obj as a 1-D array of type and length n (-1: any), C-contiguous; NULL with an exception otherwise. */
static PyArrayObject *vector(PyObject *obj, const char *name, int type, const char *type_name, npy_intp n)
{
    PyArrayObject *a = (PyArrayObject *)ps_checked_array(obj, name, type, -1, type_name, 1);
    if (a && n >= 0 && PyArray_DIM(a, 0) != n) {
        PyErr_Format(PyExc_ValueError, "%s must have length %zd, got %zd", name, (Py_ssize_t)n,
                     (Py_ssize_t)PyArray_DIM(a, 0));
        return NULL;
    }
    return a;
}

/* obj as a writeable 2-D array (see ps_checked_array); NULL with an exception otherwise. */
static PyArrayObject *state_array(PyObject *obj, const char *name, int type, const char *type_name)
{
    PyArrayObject *a = (PyArrayObject *)ps_checked_array(obj, name, type, -1, type_name, 2);
    if (a && !PyArray_ISWRITEABLE(a)) {
        PyErr_Format(PyExc_ValueError, "%s must be writeable", name);
        return NULL;
    }
    return a;
}

/* proposal, and unless fresh, current (float64) and stamp (int64), all (width, chains); NULL on error. */
static PyArrayObject *state_arrays(PyObject *objs[3], int fresh, State *s)
{
    PyArrayObject *proposal = state_array(objs[0], "proposal", NPY_DOUBLE, "float64");
    if (!proposal)
        return NULL;
    s->proposal = (double *)PyArray_DATA(proposal);
    s->chains = PyArray_DIM(proposal, 1);
    s->current = NULL;
    s->stamp = NULL;
    if (fresh)
        return proposal;
    PyArrayObject *current = state_array(objs[1], "current", NPY_DOUBLE, "float64");
    PyArrayObject *stamp = current ? state_array(objs[2], "stamp", NPY_INT64, "int64") : NULL;
    if (!stamp)
        return NULL;
    if (!PyArray_SAMESHAPE(proposal, current) || !PyArray_SAMESHAPE(proposal, stamp)) {
        PyErr_SetString(PyExc_ValueError, "proposal, current and stamp must have the same (width, chains) shape");
        return NULL;
    }
    s->current = (double *)PyArray_DATA(current);
    s->stamp = (int64_t *)PyArray_DATA(stamp);
    return proposal;
}

/* Marks a number as being drawn by the current call (pass 1 to pass 2): not a uniform in [0, 1), not NaN. */
#define PENDING (-1.0)

PyObject *ps_primary_fetch(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *objs[8], *draw;
    State s;
    if (!PyArg_ParseTuple(args, "OOOOOOOOiiddO:primary_fetch", &objs[0], &objs[1], &objs[2], &objs[3], &objs[4],
                          &objs[5], &objs[6], &objs[7], &s.mode, &s.kernel, &s.size, &s.limit, &draw))
        return NULL;
    if (s.mode < MODE_CHAIN || s.mode > MODE_FRESH || s.kernel < KERNEL_EXPONENTIAL || s.kernel > KERNEL_GAUSSIAN) {
        PyErr_Format(PyExc_ValueError, "mode must be 0, 1 or 2 and kernel 0 or 1, got %d and %d", s.mode, s.kernel);
        return NULL;
    }
    if (!(isfinite(s.size) && s.size > 0.0) || !(s.limit >= 1.0)) {   /* the limit may be infinite, not NaN */
        PyErr_Format(PyExc_ValueError, "size must be finite and positive and limit at least 1, got %R and %R",
                     PyTuple_GET_ITEM(args, 10), PyTuple_GET_ITEM(args, 11));
        return NULL;
    }
    if (!PyCallable_Check(draw)) {
        PyErr_SetString(PyExc_TypeError, "draw must be callable: k -> k uniforms");
        return NULL;
    }
    int fresh = s.mode == MODE_FRESH;
    PyArrayObject *proposal = state_arrays(objs, fresh, &s);
    PyArrayObject *rows = proposal ? vector(objs[3], "rows", NPY_INT64, "int64", -1) : NULL;
    PyArrayObject *columns = rows ? vector(objs[4], "columns", NPY_INT64, "int64", PyArray_DIM(rows, 0)) : NULL;
    if (!columns)
        return NULL;
    s.accepted = s.last_large = NULL;
    s.large = NULL;
    if (!fresh) {
        PyArrayObject *accepted = vector(objs[5], "accepted", NPY_INT64, "int64", s.chains);
        PyArrayObject *last_large = accepted ? vector(objs[6], "last_large", NPY_INT64, "int64", s.chains) : NULL;
        PyArrayObject *large = last_large ? vector(objs[7], "large", NPY_BOOL, "bool", s.chains) : NULL;
        if (!large)
            return NULL;
        s.accepted = (const int64_t *)PyArray_DATA(accepted);
        s.last_large = (const int64_t *)PyArray_DATA(last_large);
        s.large = (const npy_bool *)PyArray_DATA(large);
    }
    s.log16 = log(16.0);
    npy_intp n = PyArray_DIM(rows, 0), width = PyArray_DIM(proposal, 0);
    const int64_t *row = (const int64_t *)PyArray_DATA(rows), *column = (const int64_t *)PyArray_DATA(columns);
    PyArrayObject *out = (PyArrayObject *)PyArray_SimpleNew(1, &n, NPY_DOUBLE);
    npy_intp *scratch = malloc(3 * (size_t)(n > 0 ? n : 1) * sizeof(npy_intp));
    if (!out || !scratch) {
        Py_XDECREF(out);
        free(scratch);
        return PyErr_NoMemory();
    }
    npy_intp *flat = scratch, *chain = scratch + n, *at = scratch + 2 * n;
    double *u = (double *)PyArray_DATA(out);
    npy_intp missing = 0, bad = -1;
    int repeated = 0;
    long long needed = 0;
    /* Pass 1: the numbers drawn already, and what the others need (each index read once, then checked); the
     * others are marked PENDING, so that a pair asked for twice is found. */
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp i = 0; i < n; ++i) {
        int64_t r = row[i], c = column[i];
        if (r < 0 || r >= s.chains || c < 0 || c >= width) {
            bad = i;
            break;
        }
        npy_intp f = (npy_intp)c * s.chains + (npy_intp)r;
        double value = s.proposal[f];
        if (value == PENDING) {
            bad = i;
            repeated = 1;
            break;
        }
        if (!isnan(value)) {
            u[i] = value;
            continue;
        }
        s.proposal[f] = PENDING;
        flat[missing] = f;
        chain[missing] = (npy_intp)r;
        at[missing++] = i;
        needed += uniforms_needed(&s, f, (npy_intp)r);
    }
    Py_END_ALLOW_THREADS
    /* Pass 2: draw them, in order. */
    Uniforms uniforms = {draw, NULL, NULL, 0, 0, needed, 0, 0};
    int failed = bad >= 0;
    if (!failed && needed > 0 && refill(&uniforms) < 0)
        failed = 1;
    else if (!failed && uniforms.pending == 0) {   /* every uniform at hand: no Python call needed */
        uniforms.nogil = 1;
        Py_BEGIN_ALLOW_THREADS
        failed = draw_missing(&s, missing, flat, chain, at, u, &uniforms) < 0;
        Py_END_ALLOW_THREADS
    } else if (!failed) {
        failed = draw_missing(&s, missing, flat, chain, at, u, &uniforms) < 0;
    }
    Py_XDECREF(uniforms.chunk);
    if (failed) {   /* nothing this call drew stays in the proposal */
        for (npy_intp k = 0; k < missing; ++k)
            s.proposal[flat[k]] = NAN;
        if (repeated)
            PyErr_Format(PyExc_ValueError, "(rows, columns)[%zd] asks again for a number of this call",
                         (Py_ssize_t)bad);
        else if (bad >= 0)
            PyErr_Format(PyExc_IndexError, "(rows, columns)[%zd] is outside the (%zd, %zd) state", (Py_ssize_t)bad,
                         (Py_ssize_t)width, (Py_ssize_t)s.chains);
        else if (uniforms.short_count && !PyErr_Occurred())
            PyErr_SetString(PyExc_RuntimeError, "primary_fetch ran out of the uniforms it counted: the chains' "
                                                "state changed during the call");
        Py_DECREF(out);
        free(scratch);
        return NULL;
    }
    PyArrayObject *drawn = (PyArrayObject *)PyArray_SimpleNew(1, &missing, NPY_INT64);
    if (!drawn) {
        Py_DECREF(out);
        free(scratch);
        return NULL;
    }
    int64_t *d = (int64_t *)PyArray_DATA(drawn);
    for (npy_intp k = 0; k < missing; ++k)
        d[k] = (int64_t)flat[k];
    free(scratch);
    return Py_BuildValue("(NN)", out, drawn);
}

PyObject *ps_primary_settle(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *objs[6];
    if (!PyArg_ParseTuple(args, "OOOOOO:primary_settle", &objs[0], &objs[1], &objs[2], &objs[3], &objs[4],
                          &objs[5]))
        return NULL;
    State s;
    int fresh = objs[1] == Py_None;
    PyArrayObject *proposal = state_arrays(objs, fresh, &s);
    PyArrayObject *flats = proposal ? vector(objs[3], "flat", NPY_INT64, "int64", -1) : NULL;
    if (!flats)
        return NULL;
    const npy_bool *accept = NULL;
    const int64_t *accepted = NULL;
    if (!fresh) {
        PyArrayObject *a = vector(objs[4], "accept", NPY_BOOL, "bool", s.chains);
        PyArrayObject *b = a ? vector(objs[5], "accepted", NPY_INT64, "int64", s.chains) : NULL;
        if (!b)
            return NULL;
        accept = (const npy_bool *)PyArray_DATA(a);
        accepted = (const int64_t *)PyArray_DATA(b);
    }
    npy_intp n = PyArray_DIM(flats, 0), size = PyArray_SIZE(proposal), bad = -1;
    const int64_t *flat = (const int64_t *)PyArray_DATA(flats);
    double per_chain = 1.0 / (double)(s.chains > 0 ? s.chains : 1);
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp i = 0; i < n; ++i) {
        int64_t f = flat[i];
        if (f < 0 || f >= size) {
            bad = i;
            break;
        }
        if (!fresh) {
            /* The chain f % chains, by a multiplication (an integer division per number cost about 15% of
             * the call); the quotient is off by at most one, which the remainder's range check corrects. */
            int64_t r = f - (int64_t)((double)f * per_chain) * (int64_t)s.chains;
            r = r < 0 ? r + s.chains : r >= s.chains ? r - s.chains : r;
            if (accept[r]) {
                s.current[f] = s.proposal[f];
                s.stamp[f] = accepted[r] + 1;
            }
        }
        s.proposal[f] = NAN;
    }
    Py_END_ALLOW_THREADS
    if (bad >= 0) {
        PyErr_Format(PyExc_IndexError, "flat[%zd] is outside the state of %zd numbers", (Py_ssize_t)bad,
                     (Py_ssize_t)size);
        return NULL;
    }
    Py_RETURN_NONE;
}
