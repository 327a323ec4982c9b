/*
 * Accel: an Embree BVH over one triangle mesh, queried with whole NumPy
 * arrays of rays.
 *
 * Rays come in as two (3, N) arrays (origins, directions; float32 or float64,
 * any strides) plus tmin/tmax (scalars or (N,) arrays).  Closest-hit queries
 * are packed into 16-wide SoA packets for rtcIntersect16, occlusion queries
 * into packets for rtcOccluded16.  Both run on a configurable number of threads with
 * the GIL released.  Work is handed out in
 * chunks through an atomic counter, so threads that draw cheap rays take more.
 *
 * A watertight Accel (the default) is built with Embree's robust flag: no ray slips
 * between triangles that share an edge, and hits match embreex's exactly.  Without
 * it (watertight=False) Embree's faster arithmetic lets rays aimed within rounding
 * of a shared edge pass through it; its traversal then meets denormal numbers, so
 * Embree's calls run with flush-to-zero and denormals-are-zero set in the calling
 * thread's MXCSR (x86; restored right after each call: neither the rays built here
 * nor NumPy's arithmetic see the modes).
 * On the Cornell box's bounce rays this reaches 1.5x the watertight rays per
 * second (README, Performance).
 *
 * occluded_between tests segments between surface points: it builds each shadow
 * ray as pathspace.vecmath.shadow_ray does (shadow.h), gathering the points of
 * chosen lanes itself.
 *
 * Invalid rays (NaN or infinite origin or direction, zero direction, NaN,
 * infinite or negative tmin, NaN tmax) are never traced: the call raises
 * ValueError naming the first such ray.  A ray whose tmax is below its tmin
 * (tmax = -inf, say) is valid and empty: it misses and is not occluded.
 */
#include "native.h"
#include "shadow.h"

#define NPY_NO_DEPRECATED_API NPY_2_0_API_VERSION
#define NO_IMPORT_ARRAY
#define PY_ARRAY_UNIQUE_SYMBOL pathspace_native_ARRAY_API
#include <numpy/arrayobject.h>

#include <math.h>
#include <pthread.h>
#include <sched.h>
#include <stdatomic.h>
#include <stdint.h>
#include <string.h>
#include <unistd.h>
#if defined(__x86_64__) || defined(__i386__)
#include <pmmintrin.h>
#define PS_HAS_MXCSR 1
#endif

#define PACKET 16
#define CHUNK_RAYS 512             /* rays handed to a thread at a time */
#define MIN_RAYS_PER_THREAD 4096   /* below this, extra threads cost more than they save */
#define MAX_THREADS 256

typedef struct {
    PyObject_HEAD
    RTCScene scene;
    Py_ssize_t n_vertices;
    Py_ssize_t n_triangles;
    int threads;
    int watertight; /* built with RTC_SCENE_FLAG_ROBUST */
} PsAccel;

int ps_default_thread_count(void)
{
    cpu_set_t set;
    if (sched_getaffinity(0, sizeof(set), &set) == 0) {
        int n = CPU_COUNT(&set);
        if (n > 0)
            return n;
    }
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    return n > 0 ? (int)n : 1;
}

/* ------------------------------------------------------------------------ */
/* Views of the query arrays                                                 */

typedef struct {
    const char *base;
    npy_intp stride_comp; /* bytes between x, y and z */
    npy_intp stride_ray;  /* bytes between consecutive rays */
    int is_double;
} Vec3View;

typedef struct {
    const char *base; /* NULL for a scalar */
    npy_intp stride;
    int is_double;
    double scalar;
} ScalarView;

/* memcpy: the arrays may be unaligned (views into byte buffers); compilers turn it into a plain load. */
static inline double read_value(const char *p, int is_double)
{
    if (is_double) {
        double d;
        memcpy(&d, p, sizeof(d));
        return d;
    }
    float f;
    memcpy(&f, p, sizeof(f));
    return (double)f;
}

static inline double vec3_get(const Vec3View *v, npy_intp ray, int comp)
{
    return read_value(v->base + comp * v->stride_comp + ray * v->stride_ray, v->is_double);
}

static inline double scalar_get(const ScalarView *v, npy_intp ray)
{
    return v->base ? read_value(v->base + ray * v->stride, v->is_double) : v->scalar;
}

static int make_vec3_view(PyObject *obj, const char *name, Vec3View *view, npy_intp *n_out)
{
    if (!PyArray_Check(obj)) {
        PyErr_Format(PyExc_TypeError, "%s must be a NumPy array of shape (3, N), got %s", name,
                     Py_TYPE(obj)->tp_name);
        return -1;
    }
    PyArrayObject *a = (PyArrayObject *)obj;
    int type = PyArray_TYPE(a);
    if (PyArray_NDIM(a) != 2 || PyArray_DIM(a, 0) != 3) {
        PyErr_Format(PyExc_ValueError, "%s must have shape (3, N) (one row per coordinate), got ndim=%d%s",
                     name, PyArray_NDIM(a),
                     PyArray_NDIM(a) == 2 && PyArray_DIM(a, 1) == 3 ? " with shape (N, 3): transpose it" : "");
        return -1;
    }
    if ((type != NPY_FLOAT && type != NPY_DOUBLE) || !PyArray_ISNOTSWAPPED(a)) {
        PyErr_Format(PyExc_TypeError, "%s must be float32 or float64 in native byte order", name);
        return -1;
    }
    view->base = PyArray_BYTES(a);
    view->stride_comp = PyArray_STRIDE(a, 0);
    view->stride_ray = PyArray_STRIDE(a, 1);
    view->is_double = type == NPY_DOUBLE;
    *n_out = PyArray_DIM(a, 1);
    return 0;
}

static int make_scalar_view(PyObject *obj, const char *name, npy_intp n, ScalarView *view)
{
    view->base = NULL;
    view->stride = 0;
    view->is_double = 1;
    if (PyArray_Check(obj) && PyArray_NDIM((PyArrayObject *)obj) == 1) {
        PyArrayObject *a = (PyArrayObject *)obj;
        int type = PyArray_TYPE(a);
        if ((type != NPY_FLOAT && type != NPY_DOUBLE) || !PyArray_ISNOTSWAPPED(a)) {
            PyErr_Format(PyExc_TypeError, "%s must be float32 or float64 in native byte order", name);
            return -1;
        }
        if (PyArray_DIM(a, 0) != n) {
            PyErr_Format(PyExc_ValueError, "%s has %zd entries but there are %zd rays", name,
                         (Py_ssize_t)PyArray_DIM(a, 0), (Py_ssize_t)n);
            return -1;
        }
        view->base = PyArray_BYTES(a);
        view->stride = PyArray_STRIDE(a, 0);
        view->is_double = type == NPY_DOUBLE;
        return 0;
    }
    if (PyArray_Check(obj) && PyArray_NDIM((PyArrayObject *)obj) > 1) {
        PyErr_Format(PyExc_ValueError, "%s must be a scalar or an array of shape (N,)", name);
        return -1;
    }
    double value = PyFloat_AsDouble(obj);
    if (value == -1.0 && PyErr_Occurred()) {
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "%s must be a number or an array of shape (N,), got %s", name,
                     Py_TYPE(obj)->tp_name);
        return -1;
    }
    view->scalar = value;
    return 0;
}

/* ------------------------------------------------------------------------ */
/* The threaded query                                                        */

typedef struct {
    RTCScene scene;
    int occlusion_only;
    int flush_denormals; /* trace with MXCSR's FTZ and DAZ set (fast, non-watertight scenes) */
    const Segments *segments; /* occlusion of segments instead of the org/dir/tmin/tmax rays */
    npy_intp n;
    Vec3View org, dir;
    ScalarView tmin, tmax;
    /* outputs */
    float *t, *u, *v, *ng;  /* ng: (3, N) contiguous, or NULL */
    int32_t *prim;
    npy_bool *occluded;
    /* shared state */
    atomic_llong next_ray;
    atomic_llong first_bad;
} Query;

/* Ray i as float32 {org xyz, tnear, dir xyz, tfar}; returns 0 if the ray is invalid. */
static inline int read_ray(const Query *q, npy_intp i, float r[8])
{
    double ox = vec3_get(&q->org, i, 0), oy = vec3_get(&q->org, i, 1), oz = vec3_get(&q->org, i, 2);
    double dx = vec3_get(&q->dir, i, 0), dy = vec3_get(&q->dir, i, 1), dz = vec3_get(&q->dir, i, 2);
    double t0 = scalar_get(&q->tmin, i), t1 = scalar_get(&q->tmax, i);
    if (isnan(t1))
        return 0;
    /* Checked after the conversion: values that overflow or underflow float32 are invalid too. */
    r[0] = (float)ox;
    r[1] = (float)oy;
    r[2] = (float)oz;
    r[3] = (float)t0;
    r[4] = (float)dx;
    r[5] = (float)dy;
    r[6] = (float)dz;
    r[7] = t1 > 3.0e38 ? INFINITY : (float)t1;
    for (int k = 0; k < 7; ++k)
        if (!isfinite(r[k]))
            return 0;
    if (r[4] == 0.0f && r[5] == 0.0f && r[6] == 0.0f)
        return 0;
    return r[3] >= 0.0f;
}

static void note_bad_ray(Query *q, npy_intp i)
{
    long long current = atomic_load(&q->first_bad);
    while ((long long)i < current && !atomic_compare_exchange_weak(&q->first_bad, &current, (long long)i)) {
    }
}

/* A fast (non-watertight) scene's queries: Embree runs with MXCSR's flush-to-zero and denormals-are-zero set
 * (x86 only), and the thread gets its own modes back before anything else runs -- building the rays included,
 * which stays bit for bit the NumPy reference.  Returns the modes to restore. */
static unsigned int flush_denormals(const Query *q)
{
#ifdef PS_HAS_MXCSR
    if (q->flush_denormals) {
        const unsigned int modes = _mm_getcsr();
        _mm_setcsr(modes | _MM_FLUSH_ZERO_ON | _MM_DENORMALS_ZERO_ON);
        return modes;
    }
#else
    (void)q;
#endif
    return 0;
}

static void restore_modes(const Query *q, unsigned int modes)
{
#ifdef PS_HAS_MXCSR
    if (q->flush_denormals)
        _mm_setcsr(modes);
#else
    (void)q;
    (void)modes;
#endif
}

/* Occlusion in 16-wide packets, like closest hits: on the shadow rays of path tracing and light tracing
 * they test 1.2-1.3x the rays per second of one rtcOccluded1 call per ray (README, Performance). */
static void occlude_range(Query *q, npy_intp begin, npy_intp end)
{
    struct RTCRay16 rays;
    _Alignas(64) int valid[PACKET];
    for (npy_intp p = begin; p < end; p += PACKET) {
        int count = (int)(end - p < PACKET ? end - p : PACKET);
        int any = 0;
        for (int k = 0; k < PACKET; ++k) {
            valid[k] = 0;
            if (k >= count)
                continue;
            float r[8];
            npy_intp i = p + k;
            if (!(q->segments ? ps_segment_ray(q->segments, i, r) : read_ray(q, i, r))) {
                note_bad_ray(q, i);
                continue;
            }
            if (!(r[7] >= r[3])) /* an empty interval (tmax < tmin): nothing can lie on it */
                continue;
            rays.org_x[k] = r[0];
            rays.org_y[k] = r[1];
            rays.org_z[k] = r[2];
            rays.tnear[k] = r[3];
            rays.dir_x[k] = r[4];
            rays.dir_y[k] = r[5];
            rays.dir_z[k] = r[6];
            rays.tfar[k] = r[7];
            rays.time[k] = 0.0f;
            rays.mask[k] = 0xFFFFFFFFu;
            rays.id[k] = (unsigned int)k;
            rays.flags[k] = 0;
            valid[k] = -1;
            any = 1;
        }
        if (any) {
            const unsigned int modes = flush_denormals(q);
            ps_embree.rtcOccluded16(valid, q->scene, &rays, NULL);
            restore_modes(q, modes);
        }
        for (int k = 0; k < count; ++k)
            q->occluded[p + k] = valid[k] && rays.tfar[k] < 0.0f; /* Embree sets tfar to -inf on occlusion */
    }
}

static void intersect_range(Query *q, npy_intp begin, npy_intp end)
{
    struct RTCRayHit16 rh;
    _Alignas(64) int valid[PACKET]; /* Embree requires the mask aligned like the packet */
    for (npy_intp p = begin; p < end; p += PACKET) {
        int count = (int)(end - p < PACKET ? end - p : PACKET);
        int any = 0;
        for (int k = 0; k < PACKET; ++k) {
            valid[k] = 0;
            if (k < count) {
                float r[8];
                if (read_ray(q, p + k, r)) {
                    rh.ray.org_x[k] = r[0];
                    rh.ray.org_y[k] = r[1];
                    rh.ray.org_z[k] = r[2];
                    rh.ray.tnear[k] = r[3];
                    rh.ray.dir_x[k] = r[4];
                    rh.ray.dir_y[k] = r[5];
                    rh.ray.dir_z[k] = r[6];
                    rh.ray.tfar[k] = r[7];
                    rh.ray.time[k] = 0.0f;
                    rh.ray.mask[k] = 0xFFFFFFFFu;
                    rh.ray.id[k] = (unsigned int)k;
                    rh.ray.flags[k] = 0;
                    valid[k] = -1;
                    any = 1;
                    rh.hit.geomID[k] = PS_RTC_INVALID_GEOMETRY_ID;
                    rh.hit.primID[k] = PS_RTC_INVALID_GEOMETRY_ID;
                    rh.hit.instID[0][k] = PS_RTC_INVALID_GEOMETRY_ID;
                } else {
                    note_bad_ray(q, p + k);
                }
            }
        }
        if (any) {
            const unsigned int modes = flush_denormals(q);
            ps_embree.rtcIntersect16(valid, q->scene, &rh, NULL);
            restore_modes(q, modes);
        }
        for (int k = 0; k < count; ++k) {
            npy_intp i = p + k;
            if (valid[k] && rh.hit.geomID[k] != PS_RTC_INVALID_GEOMETRY_ID) {
                q->t[i] = rh.ray.tfar[k];
                q->prim[i] = (int32_t)rh.hit.primID[k];
                q->u[i] = rh.hit.u[k];
                q->v[i] = rh.hit.v[k];
                if (q->ng) {
                    q->ng[i] = rh.hit.Ng_x[k];
                    q->ng[q->n + i] = rh.hit.Ng_y[k];
                    q->ng[2 * q->n + i] = rh.hit.Ng_z[k];
                }
            } else {
                q->t[i] = INFINITY;
                q->prim[i] = -1;
                q->u[i] = 0.0f;
                q->v[i] = 0.0f;
                if (q->ng) {
                    q->ng[i] = 0.0f;
                    q->ng[q->n + i] = 0.0f;
                    q->ng[2 * q->n + i] = 0.0f;
                }
            }
        }
    }
}

static void *trace_worker(void *arg)
{
    Query *q = (Query *)arg;
    for (;;) {
        long long begin = atomic_fetch_add(&q->next_ray, CHUNK_RAYS);
        if (begin >= (long long)q->n)
            break;
        long long end = begin + CHUNK_RAYS < (long long)q->n ? begin + CHUNK_RAYS : (long long)q->n;
        if (q->occlusion_only)
            occlude_range(q, (npy_intp)begin, (npy_intp)end);
        else
            intersect_range(q, (npy_intp)begin, (npy_intp)end);
    }
    return NULL;
}

static void run_query(Query *q, int threads)
{
    npy_intp max_useful = q->n / MIN_RAYS_PER_THREAD;
    if (threads > max_useful)
        threads = (int)(max_useful > 1 ? max_useful : 1);
    pthread_t ids[MAX_THREADS];
    if (threads > MAX_THREADS)
        threads = MAX_THREADS;
    int started = 0;
    for (int k = 1; k < threads; ++k) {
        if (pthread_create(&ids[started], NULL, trace_worker, q) == 0)
            ++started;
    }
    trace_worker(q);
    for (int k = 0; k < started; ++k)
        pthread_join(ids[k], NULL);
}

static PyObject *describe_bad_ray(const Query *q, npy_intp i)
{
    double o[3], d[3];
    for (int c = 0; c < 3; ++c) {
        o[c] = vec3_get(&q->org, i, c);
        d[c] = vec3_get(&q->dir, i, c);
    }
    double t0 = scalar_get(&q->tmin, i), t1 = scalar_get(&q->tmax, i);
    char text[512];
    const char *why = "its origin or direction is not finite in float32";
    int finite = 1;
    for (int c = 0; c < 3; ++c)
        finite &= isfinite((float)o[c]) && isfinite((float)d[c]);
    if (finite) {
        if ((float)d[0] == 0.0f && (float)d[1] == 0.0f && (float)d[2] == 0.0f)
            why = "its direction is the zero vector (in float32)";
        else if (!(t0 >= 0.0) || !isfinite((float)t0))
            why = "tmin must be finite and >= 0";
        else
            why = "tmax is NaN";
    }
    snprintf(text, sizeof(text),
             "invalid ray %zd: %s (origin=(%g, %g, %g), direction=(%g, %g, %g), tmin=%g, tmax=%g)",
             (Py_ssize_t)i, why, o[0], o[1], o[2], d[0], d[1], d[2], t0, t1);
    PyErr_SetString(PyExc_ValueError, text);
    return NULL;
}

/* Make q a query of self's scene on *threads threads (0: the Accel's default); 0, or -1 with a Python error. */
static int start_query(PsAccel *self, Query *q, int *threads, int occlusion_only)
{
    if (self->scene == NULL) {
        PyErr_SetString(PyExc_RuntimeError, "Accel was not initialised");
        return -1;
    }
    if (*threads < 0 || *threads > MAX_THREADS) {
        PyErr_Format(PyExc_ValueError, "threads must be between 0 (the Accel's default) and %d, got %d", MAX_THREADS,
                     *threads);
        return -1;
    }
    if (*threads == 0)
        *threads = self->threads;
    q->scene = self->scene;
    q->occlusion_only = occlusion_only;
    q->flush_denormals = !self->watertight;
    atomic_init(&q->next_ray, 0);
    atomic_init(&q->first_bad, LLONG_MAX);
    return 0;
}

/* Trace q's rays for occlusion, with the GIL released, into a new bool array (N,); NULL with *bad the index of
 * the first invalid ray (-1: the array could not be made). */
static PyObject *trace_occlusion(Query *q, int threads, long long *bad)
{
    npy_intp n = q->n;
    PyArrayObject *out = (PyArrayObject *)PyArray_SimpleNew(1, &n, NPY_BOOL);
    *bad = -1;
    if (!out)
        return NULL;
    q->occluded = (npy_bool *)PyArray_DATA(out);
    Py_BEGIN_ALLOW_THREADS
    run_query(q, threads);
    Py_END_ALLOW_THREADS
    if (atomic_load(&q->first_bad) != LLONG_MAX) {
        *bad = atomic_load(&q->first_bad);
        Py_DECREF(out);
        return NULL;
    }
    return (PyObject *)out;
}

static int parse_query(PsAccel *self, PyObject *args, PyObject *kwargs, Query *q, int *threads,
                       int *normals, int occlusion_only)
{
    static char *kwlist_hit[] = {"origins", "directions", "tmin", "tmax", "threads", "normals", NULL};
    static char *kwlist_occ[] = {"origins", "directions", "tmin", "tmax", "threads", NULL};
    PyObject *org, *dir, *tmin = NULL, *tmax = NULL;
    *threads = 0;
    *normals = 1;
    int ok = occlusion_only
                 ? PyArg_ParseTupleAndKeywords(args, kwargs, "OO|OO$i:occluded", kwlist_occ, &org, &dir, &tmin,
                                               &tmax, threads)
                 : PyArg_ParseTupleAndKeywords(args, kwargs, "OO|OO$ip:intersect", kwlist_hit, &org, &dir, &tmin,
                                               &tmax, threads, normals);
    if (!ok)
        return -1;
    npy_intp n_org, n_dir;
    if (make_vec3_view(org, "origins", &q->org, &n_org) < 0 || make_vec3_view(dir, "directions", &q->dir, &n_dir) < 0)
        return -1;
    if (n_org != n_dir) {
        PyErr_Format(PyExc_ValueError, "origins has %zd rays but directions has %zd", (Py_ssize_t)n_org,
                     (Py_ssize_t)n_dir);
        return -1;
    }
    q->n = n_org;
    if (tmin == NULL) {
        q->tmin.base = NULL;
        q->tmin.scalar = 0.0;
    } else if (make_scalar_view(tmin, "tmin", q->n, &q->tmin) < 0) {
        return -1;
    }
    if (tmax == NULL) {
        q->tmax.base = NULL;
        q->tmax.scalar = INFINITY;
    } else if (make_scalar_view(tmax, "tmax", q->n, &q->tmax) < 0) {
        return -1;
    }
    return start_query(self, q, threads, occlusion_only);
}

static PyObject *Accel_intersect(PsAccel *self, PyObject *args, PyObject *kwargs)
{
    Query q;
    memset(&q, 0, sizeof(q));
    int threads, normals;
    if (parse_query(self, args, kwargs, &q, &threads, &normals, 0) < 0)
        return NULL;
    npy_intp n = q.n, dims_ng[2] = {3, n};
    PyArrayObject *t = (PyArrayObject *)PyArray_SimpleNew(1, &n, NPY_FLOAT);
    PyArrayObject *prim = (PyArrayObject *)PyArray_SimpleNew(1, &n, NPY_INT32);
    PyArrayObject *u = (PyArrayObject *)PyArray_SimpleNew(1, &n, NPY_FLOAT);
    PyArrayObject *v = (PyArrayObject *)PyArray_SimpleNew(1, &n, NPY_FLOAT);
    PyArrayObject *ng = normals ? (PyArrayObject *)PyArray_SimpleNew(2, dims_ng, NPY_FLOAT) : NULL;
    if (!t || !prim || !u || !v || (normals && !ng))
        goto fail;
    q.t = (float *)PyArray_DATA(t);
    q.prim = (int32_t *)PyArray_DATA(prim);
    q.u = (float *)PyArray_DATA(u);
    q.v = (float *)PyArray_DATA(v);
    q.ng = ng ? (float *)PyArray_DATA(ng) : NULL;
    Py_BEGIN_ALLOW_THREADS
    run_query(&q, threads);
    Py_END_ALLOW_THREADS
    if (atomic_load(&q.first_bad) != LLONG_MAX) {
        describe_bad_ray(&q, (npy_intp)atomic_load(&q.first_bad));
        goto fail;
    }
    if (ng == NULL) {
        Py_INCREF(Py_None);
        ng = (PyArrayObject *)Py_None;
    }
    return Py_BuildValue("(NNNNN)", t, prim, u, v, ng);
fail:
    Py_XDECREF(t);
    Py_XDECREF(prim);
    Py_XDECREF(u);
    Py_XDECREF(v);
    Py_XDECREF(ng);
    return NULL;
}

static PyObject *Accel_occluded(PsAccel *self, PyObject *args, PyObject *kwargs)
{
    Query q;
    memset(&q, 0, sizeof(q));
    int threads, normals;
    if (parse_query(self, args, kwargs, &q, &threads, &normals, 1) < 0)
        return NULL;
    long long bad;
    PyObject *out = trace_occlusion(&q, threads, &bad);
    return out != NULL || bad < 0 ? out : describe_bad_ray(&q, (npy_intp)bad);
}

static PyObject *Accel_occluded_between(PsAccel *self, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"a", "n_a", "eps_a", "b", "n_b", "eps_b", "lanes", "b_lanes", "threads", NULL};
    PyObject *arrays[6], *lanes = Py_None, *b_lanes = Py_None;
    int threads = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOOOOO|OO$i:occluded_between", kwlist, &arrays[0], &arrays[1],
                                     &arrays[2], &arrays[3], &arrays[4], &arrays[5], &lanes, &b_lanes, &threads))
        return NULL;
    Segments seg;
    Query q;
    memset(&q, 0, sizeof(q));
    if (ps_parse_segments(arrays, lanes, b_lanes, &seg) < 0 || start_query(self, &q, &threads, 1) < 0)
        return NULL;
    q.segments = &seg;
    q.n = seg.count;
    long long bad;
    PyObject *out = trace_occlusion(&q, threads, &bad);
    return out != NULL || bad < 0 ? out : ps_bad_segment(&seg, (Py_ssize_t)bad);
}

/* ------------------------------------------------------------------------ */
/* Construction                                                              */

static PyArrayObject *require_table(PyObject *obj, const char *name, int type, const char *type_name)
{
    if (!PyArray_Check(obj)) {
        PyErr_Format(PyExc_TypeError, "%s must be a NumPy %s array of shape (M, 3), got %s", name, type_name,
                     Py_TYPE(obj)->tp_name);
        return NULL;
    }
    PyArrayObject *a = (PyArrayObject *)obj;
    if (PyArray_TYPE(a) != type || !PyArray_ISNOTSWAPPED(a)) {
        PyErr_Format(PyExc_TypeError, "%s must have dtype %s, got %R", name, type_name,
                     (PyObject *)PyArray_DESCR(a));
        return NULL;
    }
    if (PyArray_NDIM(a) != 2 || PyArray_DIM(a, 1) != 3) {
        PyErr_Format(PyExc_ValueError, "%s must have shape (M, 3), got ndim=%d", name, PyArray_NDIM(a));
        return NULL;
    }
    if (!PyArray_IS_C_CONTIGUOUS(a) || !PyArray_ISALIGNED(a)) {
        PyErr_Format(PyExc_ValueError, "%s must be C-contiguous and aligned (use numpy.require(%s, requirements='CA'))",
                     name, name);
        return NULL;
    }
    return a;
}

static int Accel_init(PsAccel *self, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"vertices", "indices", "threads", "watertight", NULL};
    PyObject *vobj, *iobj;
    int threads = 0, watertight = 1;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OO|$ip:Accel", kwlist, &vobj, &iobj, &threads, &watertight))
        return -1;
    if (ps_require_embree() < 0)
        return -1;
    if (self->scene != NULL) {
        PyErr_SetString(PyExc_RuntimeError, "Accel is already initialised");
        return -1;
    }
    if (threads < 0 || threads > MAX_THREADS) {
        PyErr_Format(PyExc_ValueError, "threads must be between 0 (all available cores) and %d, got %d", MAX_THREADS,
                     threads);
        return -1;
    }
    PyArrayObject *verts = require_table(vobj, "vertices", NPY_FLOAT, "float32");
    if (!verts)
        return -1;
    PyArrayObject *tris = require_table(iobj, "indices", NPY_UINT32, "uint32");
    if (!tris)
        return -1;
    npy_intp nv = PyArray_DIM(verts, 0), nt = PyArray_DIM(tris, 0);
    const float *vdata = (const float *)PyArray_DATA(verts);
    const uint32_t *idata = (const uint32_t *)PyArray_DATA(tris);
    if (nv >= (npy_intp)UINT32_MAX || nt >= (npy_intp)UINT32_MAX) {
        PyErr_SetString(PyExc_ValueError, "Accel supports fewer than 2**32 - 1 vertices and triangles");
        return -1;
    }
    for (npy_intp k = 0; k < 3 * nv; ++k) {
        if (!isfinite(vdata[k])) {
            PyErr_Format(PyExc_ValueError, "vertex %zd has a non-finite coordinate", (Py_ssize_t)(k / 3));
            return -1;
        }
    }
    for (npy_intp k = 0; k < 3 * nt; ++k) {
        if ((npy_intp)idata[k] >= nv) {
            PyErr_Format(PyExc_ValueError, "triangle %zd refers to vertex %u but there are only %zd vertices",
                         (Py_ssize_t)(k / 3), idata[k], (Py_ssize_t)nv);
            return -1;
        }
    }

    ps_embree_clear_error();
    RTCScene scene = ps_embree.rtcNewScene(ps_embree_device);
    if (scene == NULL) {
        PyErr_Format(PyExc_RuntimeError, "rtcNewScene failed: %s", ps_embree_last_error());
        return -1;
    }
    ps_embree.rtcSetSceneFlags(scene, watertight ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE);
    ps_embree.rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_HIGH);
    if (nt > 0) {
        RTCGeometry geom = ps_embree.rtcNewGeometry(ps_embree_device, RTC_GEOMETRY_TYPE_TRIANGLE);
        float *vb = geom ? (float *)ps_embree.rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0,
                                                                      RTC_FORMAT_FLOAT3, 3 * sizeof(float),
                                                                      (size_t)nv)
                         : NULL;
        uint32_t *ib = geom ? (uint32_t *)ps_embree.rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0,
                                                                            RTC_FORMAT_UINT3, 3 * sizeof(uint32_t),
                                                                            (size_t)nt)
                            : NULL;
        if (!geom || !vb || !ib) {
            PyErr_Format(PyExc_MemoryError, "Embree could not allocate the mesh buffers: %s", ps_embree_last_error());
            if (geom)
                ps_embree.rtcReleaseGeometry(geom);
            ps_embree.rtcReleaseScene(scene);
            return -1;
        }
        memcpy(vb, vdata, (size_t)nv * 3 * sizeof(float));
        memcpy(ib, idata, (size_t)nt * 3 * sizeof(uint32_t));
        ps_embree.rtcCommitGeometry(geom);
        ps_embree.rtcAttachGeometry(scene, geom);
        ps_embree.rtcReleaseGeometry(geom);
    }
    Py_BEGIN_ALLOW_THREADS
    ps_embree.rtcCommitScene(scene);
    Py_END_ALLOW_THREADS
    if (ps_embree.rtcGetDeviceError(ps_embree_device) != RTC_ERROR_NONE) {
        PyErr_Format(PyExc_RuntimeError, "building the Embree scene failed: %s", ps_embree_last_error());
        ps_embree.rtcReleaseScene(scene);
        return -1;
    }
    self->scene = scene;
    self->n_vertices = nv;
    self->n_triangles = nt;
    self->threads = threads > 0 ? threads : ps_default_thread_count();
    self->watertight = watertight;
    return 0;
}

static void Accel_dealloc(PsAccel *self)
{
    if (self->scene != NULL)
        ps_embree.rtcReleaseScene(self->scene);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyObject *Accel_repr(PsAccel *self)
{
    return PyUnicode_FromFormat("Accel(%zd triangles, %zd vertices, threads=%d, watertight=%s)", self->n_triangles,
                                self->n_vertices, self->threads, self->watertight ? "True" : "False");
}

static PyObject *Accel_get_threads(PsAccel *self, void *closure)
{
    (void)closure;
    return PyLong_FromLong(self->threads);
}

static int Accel_set_threads(PsAccel *self, PyObject *value, void *closure)
{
    (void)closure;
    if (value == NULL) {
        PyErr_SetString(PyExc_AttributeError, "the threads attribute cannot be deleted");
        return -1;
    }
    long n = PyLong_AsLong(value);
    if (n == -1 && PyErr_Occurred())
        return -1;
    if (n < 0 || n > MAX_THREADS) {
        PyErr_Format(PyExc_ValueError, "threads must be between 0 (all cores) and %d", MAX_THREADS);
        return -1;
    }
    self->threads = n > 0 ? (int)n : ps_default_thread_count();
    return 0;
}

static PyObject *Accel_get_triangle_count(PsAccel *self, void *closure)
{
    (void)closure;
    return PyLong_FromSsize_t(self->n_triangles);
}

static PyObject *Accel_get_vertex_count(PsAccel *self, void *closure)
{
    (void)closure;
    return PyLong_FromSsize_t(self->n_vertices);
}

static PyObject *Accel_get_watertight(PsAccel *self, void *closure)
{
    (void)closure;
    return PyBool_FromLong(self->watertight);
}

static PyMethodDef Accel_methods[] = {
    {"intersect", (PyCFunction)(void (*)(void))Accel_intersect, METH_VARARGS | METH_KEYWORDS,
     "intersect(origins, directions, tmin=0.0, tmax=inf, *, threads=0, normals=True)\n--\n\n"
     "Closest hit of each ray.  origins, directions: (3, N) float32/float64; tmin, tmax: scalars or (N,).\n"
     "Returns (t, prim, u, v, ng): t float32 (inf on a miss), prim int32 (-1 on a miss), barycentrics u, v\n"
     "float32 (the hit is (1-u-v)*p0 + u*p1 + v*p2), and the unnormalised geometric normal ng (3, N)\n"
     "float32 = (p1-p0) x (p2-p0), or None when normals=False."},
    {"occluded", (PyCFunction)(void (*)(void))Accel_occluded, METH_VARARGS | METH_KEYWORDS,
     "occluded(origins, directions, tmin=0.0, tmax=inf, *, threads=0)\n--\n\n"
     "True where some triangle lies on the ray between tmin and tmax.  Returns a bool array (N,)."},
    {"occluded_between", (PyCFunction)(void (*)(void))Accel_occluded_between, METH_VARARGS | METH_KEYWORDS,
     "occluded_between(a, n_a, eps_a, b, n_b, eps_b, lanes=None, b_lanes=None, *, threads=0)\n--\n\n"
     "True where some triangle lies between surface points a and b: (3, N) float32 points and unit normals,\n"
     "(N,) float32 error bounds, tested along the shadow ray pathspace.vecmath.shadow_ray makes (bit for bit),\n"
     "from tmin = RAY_TMIN.  lanes: int64 (M,) indices of the segments to test (default: all N); b_lanes: int64\n"
     "(M,) indices into b, n_b and eps_b, which may then be N_b wide (default: lanes).  Returns a bool array\n"
     "(M,) or (N,)."},
    {NULL, NULL, 0, NULL},
};

static PyGetSetDef Accel_getset[] = {
    {"threads", (getter)Accel_get_threads, (setter)Accel_set_threads, "threads used by queries", NULL},
    {"triangle_count", (getter)Accel_get_triangle_count, NULL, "number of triangles", NULL},
    {"vertex_count", (getter)Accel_get_vertex_count, NULL, "number of vertices", NULL},
    {"watertight", (getter)Accel_get_watertight, NULL, "whether no ray slips between triangles sharing an edge",
     NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

PyTypeObject PsAccelType = {
    PyVarObject_HEAD_INIT(NULL, 0).tp_name = "pathspace._native.Accel",
    .tp_basicsize = sizeof(PsAccel),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_BASETYPE,
    .tp_doc = "Accel(vertices, indices, *, threads=0, watertight=True)\n--\n\n"
              "Embree BVH over a triangle mesh.  vertices: (V, 3) float32, C-contiguous;\n"
              "indices: (F, 3) uint32, C-contiguous.  threads: default number of query threads (0: all cores).\n"
              "watertight: Embree's robust build (no ray slips between triangles sharing an edge); False traces\n"
              "faster but lets rays aimed within rounding of a shared edge pass through it.",
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)Accel_init,
    .tp_dealloc = (destructor)Accel_dealloc,
    .tp_repr = (reprfunc)Accel_repr,
    .tp_methods = Accel_methods,
    .tp_getset = Accel_getset,
};
