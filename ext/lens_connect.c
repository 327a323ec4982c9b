/*
 * Light vertices joined to a pinhole camera (the t = 1 strategy: pathspace.estimators.connections.lens_samples,
 * for the scenes pathspace.estimators.lens_fused serves), in one pass with the GIL released.  Per chosen vertex y
 * of a subpath:
 *   - the pinhole's direction w from y, its solid-angle density at y, the raster position of y, whether it is on
 *     the film, and the cosine at the lens (ext/camera.h);
 *   - what y sends along w (Veach 1997, eq. 10.8): at a point on an area light, its radiance toward w (0 behind
 *     a one-sided light) times |cos| at the light; at a diffuse surface, f |cos| = albedo max(cos, 0) / pi with
 *     the surface turned toward the vertex the walk came from (pathspace.bsdfs.Diffuse.eval);
 *   - the contribution: y's throughput beta times what it sends, times the camera's importance
 *     We = 1 / (A lens_area cos^4) at the lens (PinholeCamera.importance_of; 0 off the film) over the pinhole's
 *     density (0 where either is not positive);
 *   - for BDPT, given the vertices' roulette survivals q, q_rev and g_prev (else None), the MIS densities the
 *     join changes (ext/mis.c): pt_rev, the density with which y samples w (the light's cosine-weighted
 *     emission, or the BSDF's technique) times q, in area measure at the pinhole (|cos| at the lens / d^2;
 *     Veach 1997, eq. 8.10); qs_minus_rev, the density with which y samples its predecessor with light arriving
 *     from the lens (0 on a light) times q_rev and g_prev (eq. 10.7); and qs_rev, the camera's density of y:
 *     its direction's, We lens_area |cos| at the lens (see pathspace.camera), in area measure at y.
 * Every value is computed in the operations and order of the NumPy code (lens_samples, _toward_lens, the
 * camera's importance_of and the lights' pdf_le, which the tests keep as the reference:
 * tests/estimators/test_lens_kernel.py), so the contributions and densities are bit for bit the same.  RGB only.
 */
#include "camera.h"
#include "diffuse.h"

#define NPY_NO_DEPRECATED_API NPY_2_0_API_VERSION
#define NO_IMPORT_ARRAY
#define PY_ARRAY_UNIQUE_SYMBOL pathspace_native_ARRAY_API
#include <numpy/arrayobject.h>

#include <math.h>
#include <stdint.h>

#define CHANNELS 3

enum {
    A_P, A_N, A_WO, A_BETA, A_MATERIAL, A_ENTITY, /* the subpaths' vertices (V) */
    A_CHOSEN, A_ON_LIGHT,                        /* the vertices joined (K) */
    A_DIFFUSE, A_REFLECTANCE,                    /* materials (M) */
    A_RADIANCE, A_TWO_SIDED,                     /* emitting triangles (E) */
    A_COUNT
};
/* The vertices' densities, for BDPT (V each; all None for light tracing). */
enum { D_Q, D_Q_REV, D_G_PREV, D_COUNT };

static const PsArraySpec DENSITY_SPECS[D_COUNT] = {
    {"q", NPY_DOUBLE, "float64", 1, 1}, {"q_rev", NPY_DOUBLE, "float64", 1, 1}, {"g_prev", NPY_DOUBLE, "float64", 1, 1},
};

/* The density with which a diffuse surface (geometric normal n, previous vertex along wo) samples wo when light
 * arrives along -w (subpaths.reverse_pdf: Surface.facing(n, -w) in float64, then Diffuse.eval in float32). */
static inline double reverse_pdf(int technique, const float n[3], const double w[3], const float wo[3])
{
    double cos = -(((double)n[0] * -w[0] + (double)n[1] * -w[1]) + (double)n[2] * -w[2]);
    float side = cos >= 0.0 ? 1.0f : -1.0f, nf[3] = {n[0] * side, n[1] * side, n[2] * side};
    double pdf;
    ps_diffuse_eval(technique, nf, wo, &pdf);
    return pdf;
}

static const PsArraySpec SPECS[A_COUNT] = {
    {"p", NPY_FLOAT, "float32", 2, 0},         {"n", NPY_FLOAT, "float32", 2, 0},
    {"wo", NPY_FLOAT, "float32", 2, 0},        {"beta", NPY_DOUBLE, "float64", 2, 0},
    {"material", NPY_INT64, "int64", 1, 0},    {"entity", NPY_INT64, "int64", 1, 0},
    {"chosen", NPY_INT64, "int64", 1, 0},      {"on_light", NPY_BOOL, "bool", 1, 0},
    {"diffuse", NPY_BOOL, "bool", 1, 0},       {"reflectance", NPY_DOUBLE, "float64", 2, 0},
    {"radiance", NPY_DOUBLE, "float64", 2, 0}, {"two_sided", NPY_BOOL, "bool", 1, 0},
};

/* 0 if the arrays agree: (3, V) vertex vectors and (C, V) beta, (V,) materials and entities, (K,) chosen and
 * on_light, (M,) diffuse and (3, M) reflectance, (3, E) radiance and (E,) two_sided; else -1 with a ValueError. */
static int check_shapes(PyArrayObject **a)
{
    npy_intp v = PyArray_DIM(a[A_P], 1), k = PyArray_DIM(a[A_CHOSEN], 0), m = PyArray_DIM(a[A_DIFFUSE], 0),
             e = PyArray_DIM(a[A_TWO_SIDED], 0);
    int ok = PyArray_DIM(a[A_BETA], 0) == CHANNELS && PyArray_DIM(a[A_BETA], 1) == v &&
             PyArray_DIM(a[A_MATERIAL], 0) == v && PyArray_DIM(a[A_ENTITY], 0) == v &&
             PyArray_DIM(a[A_ON_LIGHT], 0) == k &&
             PyArray_DIM(a[A_REFLECTANCE], 0) == CHANNELS && PyArray_DIM(a[A_REFLECTANCE], 1) == m &&
             PyArray_DIM(a[A_RADIANCE], 0) == CHANNELS && PyArray_DIM(a[A_RADIANCE], 1) == e;
    for (int j = A_P; j <= A_WO; ++j)
        ok = ok && PyArray_DIM(a[j], 0) == 3 && PyArray_DIM(a[j], 1) == v;
    if (!ok)
        PyErr_SetString(PyExc_ValueError, "lens_connect: p, n and wo (3, V), beta (3, V), material and entity (V,), "
                                          "chosen and on_light (K,), diffuse (M,) and reflectance (3, M), radiance "
                                          "(3, E) and two_sided (E,) must agree");
    return ok ? 0 : -1;
}

PyObject *ps_lens_connect(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *objs[A_COUNT], *vectors[4], *density_objs[D_COUNT];
    double tan_x, tan_y, lens_area, importance_scale;
    Py_ssize_t width, height;
    int technique;
    if (!PyArg_ParseTuple(args, "OOOOOOOOOOOOOOOOddnnddiOOO:lens_connect", &objs[0], &objs[1], &objs[2], &objs[3],
                          &objs[4], &objs[5], &objs[6], &objs[7], &objs[8], &objs[9], &objs[10], &objs[11],
                          &vectors[0], &vectors[1], &vectors[2], &vectors[3], &tan_x, &tan_y, &width, &height,
                          &lens_area, &importance_scale, &technique, &density_objs[0], &density_objs[1],
                          &density_objs[2]))
        return NULL;
    PyArrayObject *a[A_COUNT], *da[D_COUNT];
    PsPinhole cam;
    if (ps_checked_arrays(objs, SPECS, A_COUNT, (PyObject **)a) < 0 || check_shapes(a) < 0 ||
        ps_parse_pinhole(vectors, tan_x, tan_y, width, height, lens_area, &cam) < 0)
        return NULL;
    npy_intp v = PyArray_DIM(a[A_P], 1), k = PyArray_DIM(a[A_CHOSEN], 0), m = PyArray_DIM(a[A_DIFFUSE], 0),
             e = PyArray_DIM(a[A_TWO_SIDED], 0), dims[2] = {CHANNELS, k}, dims_r[2] = {2, k};
    if (ps_checked_arrays(density_objs, DENSITY_SPECS, D_COUNT, (PyObject **)da) < 0)
        return NULL;
    int densities = da[D_Q] != NULL;
    for (int j = 0; j < D_COUNT; ++j)
        if ((da[j] != NULL) != densities || (densities && PyArray_DIM(da[j], 0) != v)) {
            PyErr_SetString(PyExc_ValueError, "lens_connect: q, q_rev and g_prev must all be None or all (V,)");
            return NULL;
        }
    if (technique != DIFFUSE_COSINE && technique != DIFFUSE_UNIFORM) {
        PyErr_Format(PyExc_ValueError, "lens_connect: technique must be %d (cosine) or %d (uniform), got %d",
                     DIFFUSE_COSINE, DIFFUSE_UNIFORM, technique);
        return NULL;
    }
    int outputs = densities ? 5 : 2;
    PyObject *out[5] = {PyArray_SimpleNew(2, dims, NPY_DOUBLE), PyArray_SimpleNew(2, dims_r, NPY_DOUBLE), NULL, NULL,
                        NULL};
    for (int j = 2; j < outputs; ++j)
        out[j] = PyArray_SimpleNew(1, &k, NPY_DOUBLE);
    if (!ps_outputs_allocated(out, outputs))
        return NULL;
    const float *p = (const float *)PyArray_DATA(a[A_P]), *nn = (const float *)PyArray_DATA(a[A_N]),
                *wo = (const float *)PyArray_DATA(a[A_WO]);
    const double *beta = (const double *)PyArray_DATA(a[A_BETA]),
                 *reflectance = (const double *)PyArray_DATA(a[A_REFLECTANCE]),
                 *radiance = (const double *)PyArray_DATA(a[A_RADIANCE]);
    const int64_t *material = (const int64_t *)PyArray_DATA(a[A_MATERIAL]),
                  *entity = (const int64_t *)PyArray_DATA(a[A_ENTITY]),
                  *chosen = (const int64_t *)PyArray_DATA(a[A_CHOSEN]);
    const npy_bool *on_light = (const npy_bool *)PyArray_DATA(a[A_ON_LIGHT]),
                   *diffuse = (const npy_bool *)PyArray_DATA(a[A_DIFFUSE]),
                   *two_sided = (const npy_bool *)PyArray_DATA(a[A_TWO_SIDED]);
    const double *q = densities ? (const double *)PyArray_DATA(da[D_Q]) : NULL,
                 *q_rev = densities ? (const double *)PyArray_DATA(da[D_Q_REV]) : NULL,
                 *g_prev = densities ? (const double *)PyArray_DATA(da[D_G_PREV]) : NULL;
    double *contribution = (double *)PyArray_DATA((PyArrayObject *)out[0]),
           *raster = (double *)PyArray_DATA((PyArrayObject *)out[1]);
    double *pt_rev = densities ? (double *)PyArray_DATA((PyArrayObject *)out[2]) : NULL,
           *qs_minus_rev = densities ? (double *)PyArray_DATA((PyArrayObject *)out[3]) : NULL,
           *qs_rev = densities ? (double *)PyArray_DATA((PyArrayObject *)out[4]) : NULL;
    npy_intp bad = -1;
    enum { BAD_VERTEX, BAD_LIGHT, BAD_MATERIAL } why = BAD_VERTEX;
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp j = 0; j < k; ++j) {
        int64_t i = chosen[j]; /* every index is read once: checked, then used */
        if (i < 0 || i >= v) {
            bad = j, why = BAD_VERTEX;
            break;
        }
        double x[3], w[3], at[2], value[CHANNELS], pdf, cos_lens, pdf_fwd, pdf_back = 0.0;
        float n[3];
        int on_film;
        for (int c = 0; c < 3; ++c) {
            x[c] = (double)p[c * v + i];
            n[c] = nn[c * v + i];
        }
        double dist2 = ps_join_pinhole(&cam, x, w, &pdf, at, &on_film, &cos_lens);
        raster[j] = at[0];
        raster[k + j] = at[1];
        double cos_w = ((double)n[0] * w[0] + (double)n[1] * w[1]) + (double)n[2] * w[2]; /* vecmath.dot */
        double cos_at = n[0] != 0.0f || n[1] != 0.0f || n[2] != 0.0f ? fabs(cos_w) : 1.0; /* subpaths.cos_at */
        if (on_light[j]) {
            int64_t light = entity[i];
            if (light < 0 || light >= e) {
                bad = j, why = BAD_LIGHT;
                break;
            }
            int faces = two_sided[light] || cos_w > 0.0;
            for (int c = 0; c < CHANNELS; ++c)
                value[c] = radiance[c * e + light] * (faces ? 1.0 : 0.0) * cos_at;
            /* AreaLight.pdf_le: cosine-weighted emission, over both sides of a two-sided light */
            pdf_fwd = (two_sided[light] ? fabs(cos_w) * 0.5 : ps_max_zero_double(cos_w)) * PS_INV_PI;
        } else {
            int64_t id = material[i];
            if (id < 0 || id >= m || !diffuse[id]) {
                bad = j, why = BAD_MATERIAL;
                break;
            }
            /* Surface.facing(n, -wo), then Diffuse.eval toward w (float64: w is) */
            float d[3] = {-wo[i], -wo[v + i], -wo[2 * v + i]}, back[3] = {wo[i], wo[v + i], wo[2 * v + i]}, nf[3];
            ps_facing(n, d, nf);
            double cos_i = ((double)nf[0] * w[0] + (double)nf[1] * w[1]) + (double)nf[2] * w[2];
            double cos_over_pi = ps_max_zero_double(cos_i) * PS_INV_PI;
            for (int c = 0; c < CHANNELS; ++c)
                value[c] = reflectance[c * m + id] * cos_over_pi;
            pdf_fwd = technique == DIFFUSE_COSINE ? cos_over_pi : (cos_i > 0.0 ? PS_INV_TWO_PI : 0.0);
            if (densities)
                pdf_back = reverse_pdf(technique, n, w, back);
        }
        double cos2 = cos_lens * cos_lens;
        double we = on_film ? 1.0 / (importance_scale * (cos2 * cos2)) : 0.0;
        int seen = on_film && we > 0.0 && pdf > 0.0;
        for (int c = 0; c < CHANNELS; ++c)
            contribution[c * k + j] = seen ? beta[c * v + i] * value[c] * (we / pdf) : 0.0;
        if (densities) {
            pt_rev[j] = dist2 > 0.0 ? pdf_fwd * q[i] * fabs(cos_lens) / dist2 : 0.0;
            qs_minus_rev[j] = pdf_back * q_rev[i] * g_prev[i];
            qs_rev[j] = dist2 > 0.0 ? we * lens_area * fabs(cos_lens) * cos_at / dist2 : 0.0;
        }
    }
    Py_END_ALLOW_THREADS
    if (bad >= 0) {
        for (int j = 0; j < outputs; ++j)
            Py_DECREF(out[j]);
        if (why == BAD_VERTEX)
            PyErr_Format(PyExc_IndexError, "chosen[%zd] is not a vertex", (Py_ssize_t)bad);
        else if (why == BAD_LIGHT)
            PyErr_Format(PyExc_IndexError, "the light of chosen[%zd] is not an emitting triangle", (Py_ssize_t)bad);
        else
            PyErr_Format(PyExc_IndexError, "the material of chosen[%zd] is not a diffuse material of the table",
                         (Py_ssize_t)bad);
        return NULL;
    }
    if (densities)
        return Py_BuildValue("(NNNNN)", out[0], out[1], out[2], out[3], out[4]);
    return Py_BuildValue("(NN)", out[0], out[1]);
}
