/*
 * Bidirectional path tracing's joins in one pass each, with the GIL released (for the scenes
 * pathspace.estimators.join_fused serves).
 *
 * join_vertices: a light vertex y = y_{s-1} and a camera vertex z = z_{t-1} (strategies s, t >= 2:
 * pathspace.estimators.connections._join).  Per pair, with d = z - y, w = d / |d| (float32) and both vertices diffuse:
 *   - the unweighted contribution C*_{s,t} = beta_y f_y(w) f_z(-w) beta_z / |d|^2 (Veach 1997, eq. 10.8; f |cos|
 *     of each surface turned toward the vertex its walk came from, ext/diffuse.h), before the shadow ray;
 *   - the densities MIS needs of the two vertices the join changes (ext/mis.c's qs_rev, qs_minus_rev, pt_rev and
 *     pt_minus_rev): the density with which each vertex's BSDF samples the other, turned into area measure
 *     (p |cos| / d^2, Veach 1997, eq. 8.10; times the roulette's survival q there), and with which each samples
 *     its own predecessor when light arrives along the join (times q_rev and g_prev, Veach 1997, eq. 10.7).
 *
 * join_light_samples: a camera vertex z = z_{t-1} and a fresh point y_0 on an area light (s = 1, next-event
 * estimation: pathspace.estimators.connections.light_samples).  Per vertex, the light sample of ext/light_sample.h
 * from the vertex's first three connection numbers (a triangle by the selection CDF, a point uniform in its area;
 * density pdf_light in solid angle, with the pmf), w the direction toward it, d its distance:
 *   - the unweighted contribution C*_{1,t} = beta_z f_z(w) Le / pdf_light (Veach 1997, eq. 10.8 with the light
 *     sample's density in solid angle), 0 where the light does not face z or pdf_light is not positive;
 *   - the light point, its normal and ray offset (for the shadow ray), its emitting triangle;
 *   - the densities of the vertices the join changes: y_0's origin density pmf / area (qs_fwd), the density with
 *     which z's BSDF samples y_0, in area measure (qs_rev), the light's cosine-weighted emission toward z in area
 *     measure (pt_rev: cos / pi, halved for two-sided lights, times |cos_z| / d^2), and z sampling its
 *     predecessor when light arrives from y_0 (pt_minus_rev, times q_rev and g_prev).
 *
 * join_pairs: the pairs a batch joins (connections.joins), lane by lane in a range of its pairs: lane l's pair
 * nz_l i + j joins its i-th joinable light vertex and j-th joinable camera vertex, kept if the path has at most
 * max_depth segments (the NumPy reference is in the tests).
 *
 * Every value is computed in the operations and order of the NumPy code (which the tests keep as the reference:
 * tests/estimators/test_join_kernel.py and test_light_join_kernel.py), so the contributions and densities are bit
 * for bit the same.  RGB only.
 */
#include "diffuse.h"
#include "light_sample.h"

#define NPY_NO_DEPRECATED_API NPY_2_0_API_VERSION
#define NO_IMPORT_ARRAY
#define PY_ARRAY_UNIQUE_SYMBOL pathspace_native_ARRAY_API
#include <numpy/arrayobject.h>

#include <math.h>
#include <stdint.h>

#define CHANNELS 3

/* Pairs (or vertices) per block: the kernels take each block in two stages, so that the long chains of divisions
 * and square roots of several pairs overlap (as ext/pt_vertex.c does). */
#define JOIN_BLOCK 64

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

/* 0 if the fields of the subpath at a[first] agree with V = the columns of its p; else -1 with a ValueError naming
 * the kernel and the subpaths. */
static int side_of(PyArrayObject **a, int first, const char *kernel, const char *name, Side *side)
{
    npy_intp v = PyArray_DIM(a[first + F_P], 1);
    int ok = PyArray_DIM(a[first + F_BETA], 0) == CHANNELS && PyArray_DIM(a[first + F_BETA], 1) == v;
    for (int f = F_P; f <= F_WO; ++f)
        ok = ok && PyArray_DIM(a[first + f], 0) == 3 && PyArray_DIM(a[first + f], 1) == v;
    for (int f = F_MATERIAL; f < F_COUNT; ++f)
        ok = ok && PyArray_DIM(a[first + f], 0) == v;
    if (!ok) {
        PyErr_Format(PyExc_ValueError, "%s: the %s subpaths' p, n and wo (3, V), beta (3, V), material, q, q_rev and "
                     "g_prev (V,) must agree", kernel, name);
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
    if (ps_checked_arrays(objs, SPECS, A_COUNT, (PyObject **)a) < 0 ||
        side_of(a, A_LIGHT, "join_vertices", "light", &light) < 0 ||
        side_of(a, A_EYE, "join_vertices", "camera", &eye) < 0)
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
    /* In blocks: the ends and the direction between them of a block's pairs, then the rest (see JOIN_BLOCK). */
    for (npy_intp first = 0; first < k && bad < 0; first += JOIN_BLOCK) {
        npy_intp stop = first + JOIN_BLOCK < k ? first + JOIN_BLOCK : k;
        int64_t ib[JOIN_BLOCK], lb[JOIN_BLOCK], myb[JOIN_BLOCK], mzb[JOIN_BLOCK];
        End yb[JOIN_BLOCK], zb[JOIN_BLOCK];
        double dist2b[JOIN_BLOCK];
        float wb[JOIN_BLOCK][3];
        for (npy_intp j = first; j < stop; ++j) {
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
            npy_intp b = j - first;
            ib[b] = i, lb[b] = l, myb[b] = my, mzb[b] = mz;
            end_at(&light, i, yb + b);
            end_at(&eye, l, zb + b);
            double d[3];
            for (int c = 0; c < 3; ++c)
                d[c] = (double)zb[b].p[c] - (double)yb[b].p[c];
            double dist2 = (d[0] * d[0] + d[1] * d[1]) + d[2] * d[2], dist = sqrt(dist2);
            for (int c = 0; c < 3; ++c) /* y -> z */
                wb[b][c] = (float)(d[c] / dist);
            dist2b[b] = dist2;
        }
        if (bad >= 0)
            break;
        for (npy_intp j = first; j < stop; ++j) {
            npy_intp b = j - first;
            int64_t i = ib[b], l = lb[b], my = myb[b], mz = mzb[b];
            const End *y = yb + b, *z = zb + b;
            const float *w = wb[b];
            float back[3] = {-w[0], -w[1], -w[2]}; /* z -> y */
            double dist2 = dist2b[b], pdf_y, pdf_z;
            double cos_y = ps_diffuse_eval(technique, y->nf, w, &pdf_y);
            double cos_z = ps_diffuse_eval(technique, z->nf, back, &pdf_z);
            int apart = dist2 > 0.0;
            for (int c = 0; c < CHANNELS; ++c) {
                double f_y = reflectance[c * m + my] * cos_y, f_z = reflectance[c * m + mz] * cos_z;
                double beta_y = light.beta[c * light.count + i], beta_z = eye.beta[c * eye.count + l];
                value[c * k + j] = apart ? beta_y * f_y * f_z * beta_z / dist2 : 0.0;
            }
            qs_rev[j] = apart ? pdf_z * eye.q[l] * cos_at(y->n, w) / dist2 : 0.0;
            pt_rev[j] = apart ? pdf_y * light.q[i] * cos_at(z->n, w) / dist2 : 0.0;
            /* each end sampling its predecessor, light arriving from the other end */
            qs_minus_rev[j] = ps_diffuse_reverse_pdf(technique, y->n, w, y->wo) * light.q_rev[i] * light.g_prev[i];
            pt_minus_rev[j] = ps_diffuse_reverse_pdf(technique, z->n, back, z->wo) * eye.q_rev[l] * eye.g_prev[l];
        }
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


/* join_light_samples' arguments: the camera subpaths, their connection numbers, the vertices joined, the
 * materials' tables and the emitting triangles'. */
enum {
    L_EYE = 0, L_U = F_COUNT, L_Z, L_DIFFUSE, L_REFLECTANCE, L_TABLE, L_AREA, L_TWO_SIDED, L_CDF, L_PMF, L_RADIANCE,
    L_COUNT
};

static const PsArraySpec LIGHT_SPECS[L_COUNT] = {
    SUBPATH_SPECS,
    {"u", NPY_DOUBLE, "float64", 2, 0},        {"z", NPY_INT64, "int64", 1, 0},
    {"diffuse", NPY_BOOL, "bool", 1, 0},       {"reflectance", NPY_DOUBLE, "float64", 2, 0},
    {"table", NPY_FLOAT, "float32", 2, 0},     {"area", NPY_DOUBLE, "float64", 1, 0},
    {"two_sided", NPY_BOOL, "bool", 1, 0},     {"cdf", NPY_DOUBLE, "float64", 1, 0},
    {"pmf", NPY_DOUBLE, "float64", 1, 0},      {"radiance", NPY_DOUBLE, "float64", 2, 0},
};

/* The outputs of join_light_samples, in the order it returns them. */
enum { O_VALUE, O_ENTITY, O_POINT, O_NORMAL, O_EPSILON, O_QS_FWD, O_QS_REV, O_PT_REV, O_PT_MINUS_REV, O_COUNT };

PyObject *ps_join_light_samples(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *objs[L_COUNT];
    int technique;
    if (!PyArg_ParseTuple(args, "OOOOOOOOOOOOOOOOOOi:join_light_samples", &objs[0], &objs[1], &objs[2], &objs[3],
                          &objs[4], &objs[5], &objs[6], &objs[7], &objs[8], &objs[9], &objs[10], &objs[11],
                          &objs[12], &objs[13], &objs[14], &objs[15], &objs[16], &objs[17], &technique))
        return NULL;
    PyArrayObject *a[L_COUNT];
    Side eye;
    if (ps_checked_arrays(objs, LIGHT_SPECS, L_COUNT, (PyObject **)a) < 0 ||
        side_of(a, L_EYE, "join_light_samples", "camera", &eye) < 0)
        return NULL;
    npy_intp k = PyArray_DIM(a[L_Z], 0), m = PyArray_DIM(a[L_DIFFUSE], 0), e = PyArray_DIM(a[L_AREA], 0);
    if (PyArray_DIM(a[L_U], 0) < 3 || PyArray_DIM(a[L_U], 1) != eye.count) {
        PyErr_SetString(PyExc_ValueError, "join_light_samples: u must have at least 3 rows and a column per camera "
                                          "vertex");
        return NULL;
    }
    if (PyArray_DIM(a[L_REFLECTANCE], 0) != CHANNELS || PyArray_DIM(a[L_REFLECTANCE], 1) != m) {
        PyErr_SetString(PyExc_ValueError, "join_light_samples: diffuse (M,) and reflectance (3, M) must agree");
        return NULL;
    }
    if (e < 1 || PyArray_DIM(a[L_TABLE], 0) != AREA_TABLE_ROWS || PyArray_DIM(a[L_TABLE], 1) != e ||
        PyArray_DIM(a[L_TWO_SIDED], 0) != e || PyArray_DIM(a[L_CDF], 0) != e || PyArray_DIM(a[L_PMF], 0) != e ||
        PyArray_DIM(a[L_RADIANCE], 0) != CHANNELS || PyArray_DIM(a[L_RADIANCE], 1) != e) {
        PyErr_Format(PyExc_ValueError, "join_light_samples: table (%d, E) with E >= 1, area, two_sided, cdf and pmf "
                     "(E,) and radiance (3, E) must agree", AREA_TABLE_ROWS);
        return NULL;
    }
    if (technique != DIFFUSE_COSINE && technique != DIFFUSE_UNIFORM) {
        PyErr_Format(PyExc_ValueError, "join_light_samples: technique must be %d (cosine) or %d (uniform), got %d",
                     DIFFUSE_COSINE, DIFFUSE_UNIFORM, technique);
        return NULL;
    }
    npy_intp dims[2] = {CHANNELS, k};
    PyObject *out[O_COUNT] = {
        PyArray_SimpleNew(2, dims, NPY_DOUBLE), PyArray_SimpleNew(1, &k, NPY_INT64),
        PyArray_SimpleNew(2, dims, NPY_FLOAT),  PyArray_SimpleNew(2, dims, NPY_FLOAT),
        PyArray_SimpleNew(1, &k, NPY_FLOAT),    PyArray_SimpleNew(1, &k, NPY_DOUBLE),
        PyArray_SimpleNew(1, &k, NPY_DOUBLE),   PyArray_SimpleNew(1, &k, NPY_DOUBLE),
        PyArray_SimpleNew(1, &k, NPY_DOUBLE),
    };
    if (!ps_outputs_allocated(out, O_COUNT))
        return NULL;
#define OUTPUT(j) PyArray_DATA((PyArrayObject *)out[j])
    double *value = OUTPUT(O_VALUE), *qs_fwd = OUTPUT(O_QS_FWD), *qs_rev = OUTPUT(O_QS_REV),
           *pt_rev = OUTPUT(O_PT_REV), *pt_minus_rev = OUTPUT(O_PT_MINUS_REV);
    int64_t *entity = OUTPUT(O_ENTITY);
    float *point = OUTPUT(O_POINT), *normal = OUTPUT(O_NORMAL), *epsilon = OUTPUT(O_EPSILON);
#undef OUTPUT
    const int64_t *zs = (const int64_t *)PyArray_DATA(a[L_Z]);
    const double *u = (const double *)PyArray_DATA(a[L_U]);
    const npy_bool *diffuse = (const npy_bool *)PyArray_DATA(a[L_DIFFUSE]);
    const double *reflectance = (const double *)PyArray_DATA(a[L_REFLECTANCE]),
                 *radiance = (const double *)PyArray_DATA(a[L_RADIANCE]);
    PsAreaLights lights = {(const float *)PyArray_DATA(a[L_TABLE]), (const double *)PyArray_DATA(a[L_AREA]),
                           (const double *)PyArray_DATA(a[L_CDF]), (const double *)PyArray_DATA(a[L_PMF]),
                           (const npy_bool *)PyArray_DATA(a[L_TWO_SIDED]), e};
    npy_intp v = eye.count, bad = -1;
    int bad_material = 0;
    Py_BEGIN_ALLOW_THREADS
    /* In blocks: the light samples of a block's vertices, then their evaluation (see JOIN_BLOCK). */
    for (npy_intp first = 0; first < k && bad < 0; first += JOIN_BLOCK) {
        npy_intp stop = first + JOIN_BLOCK < k ? first + JOIN_BLOCK : k;
        int64_t lb[JOIN_BLOCK], mb[JOIN_BLOCK];
        End zb[JOIN_BLOCK];
        PsLightSample sb[JOIN_BLOCK];
        for (npy_intp j = first; j < stop; ++j) {
            int64_t l = zs[j]; /* read once: checked, then used */
            if (l < 0 || l >= v) {
                bad = j;
                break;
            }
            int64_t mz = eye.material[l];
            if (mz < 0 || mz >= m || !diffuse[mz]) {
                bad = j, bad_material = 1;
                break;
            }
            lb[j - first] = l, mb[j - first] = mz;
            end_at(&eye, l, zb + (j - first));
            /* LightSet.sample_li: AreaLight.sample_li_selected */
            ps_sample_area_light(&lights, u[l], u[v + l], u[2 * v + l], zb[j - first].p, sb + (j - first));
        }
        if (bad >= 0)
            break;
        for (npy_intp j = first; j < stop; ++j) {
            int64_t l = lb[j - first], mz = mb[j - first];
            const End *z = zb + (j - first);
            const PsLightSample *s = sb + (j - first);
            double pdf_bsdf, cos_z = ps_diffuse_eval(technique, z->nf, s->wi, &pdf_bsdf);
            int lit = s->facing && s->pdf > 0.0;
            for (int c = 0; c < CHANNELS; ++c) {
                double f_z = reflectance[c * m + mz] * cos_z;
                value[c * k + j] = lit ? eye.beta[c * v + l] * f_z * radiance[c * e + s->entity] / s->pdf : 0.0;
                point[c * k + j] = s->point[c];
                normal[c * k + j] = s->normal[c];
            }
            entity[j] = s->entity;
            epsilon[j] = s->epsilon;
            /* a distance that is not finite (NaN points) is taken as a light at infinity: no area measure */
            double dist = (double)s->distance;
            int infinite = !isfinite(dist);
            double dist2 = infinite ? 1.0 : dist * dist;
            /* LightSet.pdf_le toward z (AreaLight.pdf_le): the pmf times 1 / area, and the emission's density */
            float back[3] = {-s->wi[0], -s->wi[1], -s->wi[2]};
            double cos_light = (double)ps_dot3(s->normal, back);
            double pdf_emit = (lights.two_sided[s->entity] ? fabs(cos_light) * 0.5 : ps_max_zero_double(cos_light)) *
                              PS_INV_PI;
            double pdf_bsdf_q = pdf_bsdf * eye.q[l];
            qs_fwd[j] = lights.pmf[s->entity] * (1.0 / lights.area[s->entity]);
            qs_rev[j] = infinite ? pdf_bsdf_q : dist2 > 0.0 ? pdf_bsdf_q * cos_at(s->normal, s->wi) / dist2 : 0.0;
            pt_rev[j] = infinite ? pdf_emit * (double)fabsf(ps_dot3(z->n, s->wi))
                                 : dist2 > 0.0 ? pdf_emit * cos_at(z->n, s->wi) / dist2 : 0.0;
            pt_minus_rev[j] = ps_diffuse_reverse_pdf(technique, z->n, s->wi, z->wo) * eye.q_rev[l] * eye.g_prev[l];
        }
    }
    Py_END_ALLOW_THREADS
    if (bad >= 0) {
        for (int j = 0; j < O_COUNT; ++j)
            Py_DECREF(out[j]);
        if (bad_material)
            PyErr_Format(PyExc_IndexError, "join_light_samples: z[%zd] has no diffuse material of the table",
                         (Py_ssize_t)bad);
        else
            PyErr_Format(PyExc_IndexError, "join_light_samples: z[%zd] is not a vertex", (Py_ssize_t)bad);
        return NULL;
    }
    return Py_BuildValue("(NNNNNNNNN)", out[0], out[1], out[2], out[3], out[4], out[5], out[6], out[7], out[8]);
}


/* join_pairs' arguments: per lane, where its pairs start (pair_start, lanes + 1), its camera vertices joined
 * (nz) and where its light and camera vertices start in cy and cz; the vertices that can be joined (indices
 * into the subpaths); each subpath vertex's index along its subpath. */
enum { P_PAIR_START, P_NZ, P_Y_START, P_Z_START, P_CY, P_CZ, P_LIGHT_INDEX, P_EYE_INDEX, P_COUNT };

static const PsArraySpec PAIR_SPECS[P_COUNT] = {
    {"pair_start", NPY_INT64, "int64", 1, 0}, {"nz", NPY_INT64, "int64", 1, 0},
    {"y_start", NPY_INT64, "int64", 1, 0},    {"z_start", NPY_INT64, "int64", 1, 0},
    {"cy", NPY_INT64, "int64", 1, 0},         {"cz", NPY_INT64, "int64", 1, 0},
    {"light_index", NPY_INT64, "int64", 1, 0}, {"eye_index", NPY_INT64, "int64", 1, 0},
};

PyObject *ps_join_pairs(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *objs[P_COUNT];
    Py_ssize_t begin, end, max_depth;
    if (!PyArg_ParseTuple(args, "OOOOOOOOnnn:join_pairs", &objs[0], &objs[1], &objs[2], &objs[3], &objs[4], &objs[5],
                          &objs[6], &objs[7], &begin, &end, &max_depth))
        return NULL;
    PyArrayObject *a[P_COUNT];
    if (ps_checked_arrays(objs, PAIR_SPECS, P_COUNT, (PyObject **)a) < 0)
        return NULL;
    npy_intp lanes = PyArray_DIM(a[P_NZ], 0);
    if (PyArray_DIM(a[P_PAIR_START], 0) != lanes + 1 || PyArray_DIM(a[P_Y_START], 0) != lanes ||
        PyArray_DIM(a[P_Z_START], 0) != lanes) {
        PyErr_SetString(PyExc_ValueError, "join_pairs: pair_start (L + 1,), nz, y_start and z_start (L,) must agree");
        return NULL;
    }
    const int64_t *pair_start = (const int64_t *)PyArray_DATA(a[P_PAIR_START]);
    if (pair_start[0] != 0) {
        PyErr_Format(PyExc_ValueError, "join_pairs: pair_start must start at 0, got %lld", (long long)pair_start[0]);
        return NULL;
    }
    if (begin < 0 || begin > end || end > pair_start[lanes]) {
        PyErr_Format(PyExc_ValueError, "join_pairs: the pairs %zd .. %zd are not within 0 .. %lld", begin, end,
                     (long long)pair_start[lanes]);
        return NULL;
    }
    npy_intp k = end - begin;
    PyObject *out[2] = {PyArray_SimpleNew(1, &k, NPY_INT64), PyArray_SimpleNew(1, &k, NPY_INT64)};
    if (!ps_outputs_allocated(out, 2))
        return NULL;
    const int64_t *nz = (const int64_t *)PyArray_DATA(a[P_NZ]), *y_start = (const int64_t *)PyArray_DATA(a[P_Y_START]),
                  *z_start = (const int64_t *)PyArray_DATA(a[P_Z_START]), *cy = (const int64_t *)PyArray_DATA(a[P_CY]),
                  *cz = (const int64_t *)PyArray_DATA(a[P_CZ]),
                  *light_index = (const int64_t *)PyArray_DATA(a[P_LIGHT_INDEX]),
                  *eye_index = (const int64_t *)PyArray_DATA(a[P_EYE_INDEX]);
    npy_intp ny_c = PyArray_DIM(a[P_CY], 0), nz_c = PyArray_DIM(a[P_CZ], 0);
    npy_intp nl = PyArray_DIM(a[P_LIGHT_INDEX], 0), ne = PyArray_DIM(a[P_EYE_INDEX], 0);
    int64_t *ys = (int64_t *)PyArray_DATA((PyArrayObject *)out[0]);
    int64_t *zs = (int64_t *)PyArray_DATA((PyArrayObject *)out[1]);
    npy_intp count = 0;
    const char *bad = NULL;
    npy_intp bad_at = 0;
    int bad_layout = 0; /* a ValueError: the lanes' counts disagree (else an IndexError: indices outside) */
    Py_BEGIN_ALLOW_THREADS
    /* the lane of pair `begin`: the last whose pairs start at or before it (pair_start increases) */
    npy_intp lo = 0, hi = lanes;
    while (hi - lo > 1) {
        npy_intp mid = lo + (hi - lo) / 2;
        if (pair_start[mid] <= begin)
            lo = mid;
        else
            hi = mid;
    }
    for (npy_intp lane = lo, pair = begin; pair < end && lane < lanes; ++lane) {
        int64_t first = pair_start[lane], last = pair_start[lane + 1], per_y = nz[lane];
        if (last < first || (last > first && (per_y <= 0 || (last - first) % per_y != 0))) {
            bad = "pair_start and nz disagree", bad_at = lane, bad_layout = 1;
            break;
        }
        if (pair >= last)
            continue;
        /* the lane's pair per_y nth_y + nth_z: its light vertex nth_y and camera vertex nth_z, z fastest */
        int64_t nth_y = (pair - first) / per_y, nth_z = (pair - first) % per_y;
        for (; pair < end && pair < last; ++pair) {
            int64_t iy, iz, y, z, segments;
            if (__builtin_add_overflow(y_start[lane], nth_y, &iy) ||
                __builtin_add_overflow(z_start[lane], nth_z, &iz) || iy < 0 || iy >= ny_c || iz < 0 || iz >= nz_c) {
                bad = "y_start or z_start is outside cy or cz", bad_at = lane;
                break;
            }
            y = cy[iy], z = cz[iz];
            if (y < 0 || y >= nl || z < 0 || z >= ne) {
                bad = "cy or cz is outside the subpaths", bad_at = lane;
                break;
            }
            /* s + t - 1 segments, s - 1 and t - 1 the vertices' indices (absurd ones that overflow: too long) */
            if (!__builtin_add_overflow(light_index[y], eye_index[z], &segments) && segments < max_depth) {
                ys[count] = y;
                zs[count] = z;
                ++count;
            }
            if (++nth_z == per_y)
                nth_z = 0, ++nth_y;
        }
        if (bad)
            break;
    }
    Py_END_ALLOW_THREADS
    if (bad) {
        Py_DECREF(out[0]);
        Py_DECREF(out[1]);
        PyErr_Format(bad_layout ? PyExc_ValueError : PyExc_IndexError, "join_pairs: lane %zd: %s", (Py_ssize_t)bad_at,
                     bad);
        return NULL;
    }
    PyObject *y = ps_first_entries(out[0], count), *z = y ? ps_first_entries(out[1], count) : NULL;
    if (!y || !z) {
        Py_XDECREF(y);
        if (!y)
            Py_DECREF(out[1]);
        return NULL;
    }
    return Py_BuildValue("(NN)", y, z);
}
