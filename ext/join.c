/*
 * Bidirectional path tracing's joins of a light vertex y = y_{s-1} and a camera vertex z = z_{t-1} (strategies
 * s, t >= 2: pathspace.estimators.connections._join, for the scenes pathspace.estimators.join_fused serves), in
 * one pass with the GIL released.  Per pair, with d = z - y, w = d / |d| (float32) and both vertices diffuse:
 *   - the unweighted contribution C*_{s,t} = beta_y f_y(w) f_z(-w) beta_z / |d|^2 (Veach 1997, eq. 10.8; f |cos|
 *     of each surface turned toward the vertex its walk came from, ext/diffuse.h), before the shadow ray;
 *   - the densities MIS needs of the two vertices the join changes (ext/mis.c's qs_rev, qs_minus_rev, pt_rev and
 *     pt_minus_rev): the density with which each vertex's BSDF samples the other, turned into area measure
 *     (p |cos| / d^2, Veach 1997, eq. 8.10; times the roulette's survival q there), and with which each samples
 *     its own predecessor when light arrives along the join (times q_rev and g_prev, Veach 1997, eq. 10.7).
 * Every value is computed in the operations and order of the NumPy code (which the tests keep as the reference:
 * tests/estimators/test_join_kernel.py), so the contributions and densities are bit for bit the same.  RGB only.
 */
#include "diffuse.h"

#define NPY_NO_DEPRECATED_API NPY_2_0_API_VERSION
#define NO_IMPORT_ARRAY
#define PY_ARRAY_UNIQUE_SYMBOL pathspace_native_ARRAY_API
#include <numpy/arrayobject.h>

#include <math.h>
#include <stdint.h>

#define CHANNELS 3

/* The fields of one kind of subpath the join reads, in argument order (pathspace.estimators.subpaths). */
enum { F_P, F_N, F_WO, F_BETA, F_MATERIAL, F_Q, F_Q_REV, F_G_PREV, F_COUNT };
enum { A_LIGHT = 0, A_EYE = F_COUNT, A_Y = 2 * F_COUNT, A_Z, A_DIFFUSE, A_REFLECTANCE, A_COUNT };

#define SUBPATH_SPECS                                                                                                \
    {"p", NPY_FLOAT, "float32", 2, 0}, {"n", NPY_FLOAT, "float32", 2, 0}, {"wo", NPY_FLOAT, "float32", 2, 0},        \
    {"beta", NPY_DOUBLE, "float64", 2, 0}, {"material", NPY_INT64, "int64", 1, 0}, {"q", NPY_DOUBLE, "float64", 1, 0}, \
    {"q_rev", NPY_DOUBLE, "float64", 1, 0}, {"g_prev", NPY_DOUBLE, "float64", 1, 0}

static const PsArraySpec SPECS[A_COUNT] = {
    SUBPATH_SPECS, SUBPATH_SPECS,
    {"y", NPY_INT64, "int64", 1, 0},           {"z", NPY_INT64, "int64", 1, 0},
    {"diffuse", NPY_BOOL, "bool", 1, 0},       {"reflectance", NPY_DOUBLE, "float64", 2, 0},
};

/* The vertices of one subpath kind: V of them, each field's data. */
typedef struct {
    npy_intp count;
    const float *p, *n, *wo;
    const double *beta, *q, *q_rev, *g_prev;
    const int64_t *material;
} Side;

/* 0 if the fields of the subpath at a[first] agree with V = the columns of its p; else -1 with a ValueError. */
static int side_of(PyArrayObject **a, int first, const char *name, Side *side)
{
    npy_intp v = PyArray_DIM(a[first + F_P], 1);
    int ok = PyArray_DIM(a[first + F_BETA], 0) == CHANNELS && PyArray_DIM(a[first + F_BETA], 1) == v;
    for (int f = F_P; f <= F_WO; ++f)
        ok = ok && PyArray_DIM(a[first + f], 0) == 3 && PyArray_DIM(a[first + f], 1) == v;
    for (int f = F_MATERIAL; f < F_COUNT; ++f)
        ok = ok && PyArray_DIM(a[first + f], 0) == v;
    if (!ok) {
        PyErr_Format(PyExc_ValueError, "join_vertices: the %s subpaths' p, n and wo (3, V), beta (3, V), material, q, "
                     "q_rev and g_prev (V,) must agree", name);
        return -1;
    }
    *side = (Side){v, (const float *)PyArray_DATA(a[first + F_P]), (const float *)PyArray_DATA(a[first + F_N]),
                   (const float *)PyArray_DATA(a[first + F_WO]), (const double *)PyArray_DATA(a[first + F_BETA]),
                   (const double *)PyArray_DATA(a[first + F_Q]), (const double *)PyArray_DATA(a[first + F_Q_REV]),
                   (const double *)PyArray_DATA(a[first + F_G_PREV]),
                   (const int64_t *)PyArray_DATA(a[first + F_MATERIAL])};
    return 0;
}

/* One end of a join: a vertex's position, normal, direction toward its walk's previous vertex, and its normal
 * turned toward that vertex. */
typedef struct {
    float p[3], n[3], wo[3], nf[3];
} End;

static inline void end_at(const Side *side, npy_intp i, End *e)
{
    npy_intp v = side->count;
    float arriving[3];
    for (int c = 0; c < 3; ++c) {
        e->p[c] = side->p[c * v + i];
        e->n[c] = side->n[c * v + i];
        e->wo[c] = side->wo[c * v + i];
        arriving[c] = -e->wo[c];
    }
    ps_facing(e->n, arriving, e->nf); /* connections._surface: Surface.facing(n, -wo) */
}

/* subpaths.cos_at: |cos| between the normal and w, 1 for a zero normal (a point light). */
static inline double cos_at(const float n[3], const float w[3])
{
    return n[0] != 0.0f || n[1] != 0.0f || n[2] != 0.0f ? (double)fabsf(ps_dot3(n, w)) : 1.0;
}


PyObject *ps_join_vertices(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *objs[A_COUNT];
    int technique;
    if (!PyArg_ParseTuple(args, "OOOOOOOOOOOOOOOOOOOOi:join_vertices", &objs[0], &objs[1], &objs[2], &objs[3],
                          &objs[4], &objs[5], &objs[6], &objs[7], &objs[8], &objs[9], &objs[10], &objs[11], &objs[12],
                          &objs[13], &objs[14], &objs[15], &objs[16], &objs[17], &objs[18], &objs[19], &technique))
        return NULL;
    PyArrayObject *a[A_COUNT];
    Side light, eye;
    if (ps_checked_arrays(objs, SPECS, A_COUNT, (PyObject **)a) < 0 || side_of(a, A_LIGHT, "light", &light) < 0 ||
        side_of(a, A_EYE, "camera", &eye) < 0)
        return NULL;
    npy_intp k = PyArray_DIM(a[A_Y], 0), m = PyArray_DIM(a[A_DIFFUSE], 0);
    if (PyArray_DIM(a[A_Z], 0) != k || PyArray_DIM(a[A_REFLECTANCE], 0) != CHANNELS ||
        PyArray_DIM(a[A_REFLECTANCE], 1) != m) {
        PyErr_SetString(PyExc_ValueError, "join_vertices: y and z (K,), diffuse (M,) and reflectance (3, M) must "
                                          "agree");
        return NULL;
    }
    if (technique != DIFFUSE_COSINE && technique != DIFFUSE_UNIFORM) {
        PyErr_Format(PyExc_ValueError, "join_vertices: technique must be %d (cosine) or %d (uniform), got %d",
                     DIFFUSE_COSINE, DIFFUSE_UNIFORM, technique);
        return NULL;
    }
    npy_intp dims[2] = {CHANNELS, k};
    PyObject *out[5] = {PyArray_SimpleNew(2, dims, NPY_DOUBLE), PyArray_SimpleNew(1, &k, NPY_DOUBLE),
                        PyArray_SimpleNew(1, &k, NPY_DOUBLE), PyArray_SimpleNew(1, &k, NPY_DOUBLE),
                        PyArray_SimpleNew(1, &k, NPY_DOUBLE)};
    if (!ps_outputs_allocated(out, 5))
        return NULL;
    const int64_t *ys = (const int64_t *)PyArray_DATA(a[A_Y]), *zs = (const int64_t *)PyArray_DATA(a[A_Z]);
    const npy_bool *diffuse = (const npy_bool *)PyArray_DATA(a[A_DIFFUSE]);
    const double *reflectance = (const double *)PyArray_DATA(a[A_REFLECTANCE]);
    double *value = (double *)PyArray_DATA((PyArrayObject *)out[0]),
           *qs_rev = (double *)PyArray_DATA((PyArrayObject *)out[1]),
           *qs_minus_rev = (double *)PyArray_DATA((PyArrayObject *)out[2]),
           *pt_rev = (double *)PyArray_DATA((PyArrayObject *)out[3]),
           *pt_minus_rev = (double *)PyArray_DATA((PyArrayObject *)out[4]);
    npy_intp bad = -1;
    enum { BAD_Y, BAD_Z, BAD_MATERIAL } why = BAD_Y;
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp j = 0; j < k; ++j) {
        int64_t i = ys[j], l = zs[j]; /* every index is read once: checked, then used */
        if (i < 0 || i >= light.count || l < 0 || l >= eye.count) {
            bad = j, why = i < 0 || i >= light.count ? BAD_Y : BAD_Z;
            break;
        }
        int64_t my = light.material[i], mz = eye.material[l];
        if (my < 0 || my >= m || !diffuse[my] || mz < 0 || mz >= m || !diffuse[mz]) {
            bad = j, why = BAD_MATERIAL;
            break;
        }
        End y, z;
        end_at(&light, i, &y);
        end_at(&eye, l, &z);
        double d[3];
        for (int c = 0; c < 3; ++c)
            d[c] = (double)z.p[c] - (double)y.p[c];
        double dist2 = (d[0] * d[0] + d[1] * d[1]) + d[2] * d[2], dist = sqrt(dist2);
        float w[3], back[3]; /* y -> z and z -> y */
        for (int c = 0; c < 3; ++c) {
            w[c] = (float)(d[c] / dist);
            back[c] = -w[c];
        }
        double pdf_y, pdf_z;
        double cos_y = ps_diffuse_eval(technique, y.nf, w, &pdf_y);
        double cos_z = ps_diffuse_eval(technique, z.nf, back, &pdf_z);
        int apart = dist2 > 0.0;
        for (int c = 0; c < CHANNELS; ++c) {
            double f_y = reflectance[c * m + my] * cos_y, f_z = reflectance[c * m + mz] * cos_z;
            double beta_y = light.beta[c * light.count + i], beta_z = eye.beta[c * eye.count + l];
            value[c * k + j] = apart ? beta_y * f_y * f_z * beta_z / dist2 : 0.0;
        }
        qs_rev[j] = apart ? pdf_z * eye.q[l] * cos_at(y.n, w) / dist2 : 0.0;
        pt_rev[j] = apart ? pdf_y * light.q[i] * cos_at(z.n, w) / dist2 : 0.0;
        /* each end sampling its predecessor, light arriving from the other end */
        qs_minus_rev[j] = ps_diffuse_reverse_pdf(technique, y.n, w, y.wo) * light.q_rev[i] * light.g_prev[i];
        pt_minus_rev[j] = ps_diffuse_reverse_pdf(technique, z.n, back, z.wo) * eye.q_rev[l] * eye.g_prev[l];
    }
    Py_END_ALLOW_THREADS
    if (bad >= 0) {
        for (int j = 0; j < 5; ++j)
            Py_DECREF(out[j]);
        if (why == BAD_MATERIAL)
            PyErr_Format(PyExc_IndexError, "join_vertices: a vertex of pair %zd has no diffuse material of the table",
                         (Py_ssize_t)bad);
        else
            PyErr_Format(PyExc_IndexError, "join_vertices: %s[%zd] is not a vertex", why == BAD_Y ? "y" : "z",
                         (Py_ssize_t)bad);
        return NULL;
    }
    return Py_BuildValue("(NNNNN)", out[0], out[1], out[2], out[3], out[4]);
}
