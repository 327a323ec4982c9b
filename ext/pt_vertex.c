/*
 * One vertex of a random walk, fused, in one pass with the GIL released: a path tracer's (pathspace.estimators.pt,
 * PathTracer._scatter for the scenes its fused kernel serves), or a camera or light subpath's (pathspace.estimators
 * .subpaths, _Growth._vertex).  Per lane, at the surface point p its ray reached:
 *   1. the path tracer's next-event estimation (materials that are not specular, with light sampling on): a light
 *      sample on the area lights (ext/light_sample.h), the BSDF's f |cos| and density toward it, and its
 *      MIS-weighted value (ext/direct.h; Veach 1997, eqs. 9.4 and 9.13), left for the caller to test with a shadow
 *      ray;
 *   2. a BSDF sample: Lambertian (cosine-weighted, ext/warp.h, or uniform over the hemisphere), a delta mirror,
 *      or a smooth dielectric (Fresnel-weighted choice of reflection and refraction, radiance scaled by
 *      1 / eta^2 on refraction, importance not; Veach 1997, sec. 5.2); for subpaths, the density with which the
 *      BSDF would sample the way back with light arriving along the sample (Veach 1997, eq. 10.7), and at
 *      specular vertices both MIS densities of the module pathspace.estimators.subpaths (the lobe's probability
 *      times eta^2 |cos| of the sample, and times |cos| of the arrival: the deltas left out, not the geometry);
 *   3. Russian roulette's survival probability (pathspace.roulette.RussianRoulette.survival, every policy), and
 *      the step to the next ray: throughput, survival and origin (ext/scatter.h).
 * The BSDFs are those of pathspace.bsdfs (diffuse.py, mirror.py, dielectric.py and fresnel.py), which stay the
 * reference: every value is computed in the operations and order of the NumPy code, so that a render through
 * this kernel is bit for bit the render through NumPy (tests/estimators/test_pt_vertex_kernel.py and
 * test_walk_kernel.py).  RGB only.
 */
#include "diffuse.h"
#include "direct.h"
#include "light_sample.h"
#include "scatter.h"
#include "warp.h"

#define NPY_NO_DEPRECATED_API NPY_2_0_API_VERSION
#define NO_IMPORT_ARRAY
#define PY_ARRAY_UNIQUE_SYMBOL pathspace_native_ARRAY_API
#include <numpy/arrayobject.h>

#include <math.h>
#include <stdint.h>

/* Material kinds, in the order of _native.PT_VERTEX_KINDS (pathspace.estimators.pt_fused numbers them by it). */
enum { KIND_DIFFUSE, KIND_MIRROR, KIND_DIELECTRIC, KIND_COUNT };
static const char *const KIND_NAMES[KIND_COUNT] = {"diffuse", "mirror", "dielectric"};
/* Roulette policies, in the order of pathspace.roulette.POLICIES. */
enum { ROULETTE_OFF, ROULETTE_FIXED, ROULETTE_ALBEDO, ROULETTE_THROUGHPUT, ROULETTE_COUNT };

#define CHANNELS 3

typedef struct {
    int diffuse_technique, heuristic, policy, start_depth, trapped_depth;
    double exponent, probability, cap;
    /* Walks other than the path tracer's (subpaths): the first row of the BSDF's numbers in u (3 after the light
     * sample's, 0 for a subpath's), light transport from the lights ("importance") or not, and whether to give
     * the reverse densities of the sampled directions. */
    int bsdf_row, importance, reverse;
} Options;

/* pathspace.bsdfs.fresnel.fresnel_dielectric: the reflectance F and the cosine of the transmitted angle. */
static inline double fresnel_dielectric(double cos_i, double eta, double *cos_t)
{
    cos_i = cos_i < 0.0 ? 0.0 : (cos_i > 1.0 ? 1.0 : cos_i);
    double sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    double rest = 1.0 - sin2_t;
    *cos_t = sqrt(isnan(rest) || rest > 0.0 ? rest : 0.0); /* np.maximum(0, rest): NaN stays NaN */
    double r_parl = (eta * cos_i - *cos_t) / (eta * cos_i + *cos_t);
    double r_perp = (cos_i - eta * *cos_t) / (cos_i + eta * *cos_t);
    double f = 0.5 * (r_parl * r_parl + r_perp * r_perp);
    return sin2_t >= 1.0 || isnan(f) ? 1.0 : f;
}

/* A BSDF sample: direction, weight f |cos| / pdf, density, whether it is a delta lobe, and the relative index
 * it crossed (1: none). */
typedef struct {
    float wi[3];
    double weight[CHANNELS], pdf, eta;
    int delta;
} Sample;

/* Diffuse.sample: n the normal on the side of wo, u1 the uniform of the height, cos_phi and sin_phi those of
 * the azimuth of the uniform u2. */
static void sample_diffuse(const Options *o, const double *albedo, const float n[3], double u1, float cos_phi,
                           float sin_phi, Sample *s)
{
    if (o->diffuse_technique == DIFFUSE_UNIFORM) {
        float z = 1.0f - 2.0f * (float)u1;
        float r = sqrtf(ps_max_zero(1.0f - z * z));
        float sphere[3] = {r * cos_phi, r * sin_phi, z};
        float side = copysignf(1.0f, ps_dot3(n, sphere));
        for (int k = 0; k < 3; ++k)
            s->wi[k] = sphere[k] * side;
        double cos_i = (double)fabsf(ps_dot3(n, s->wi));
        for (int c = 0; c < CHANNELS; ++c)
            s->weight[c] = albedo[c] * (2.0 * cos_i);
        s->pdf = PS_INV_TWO_PI;
    } else {
        ps_cosine_direction(n, u1, cos_phi, sin_phi, s->wi);
        s->pdf = (double)ps_max_zero(ps_dot3(n, s->wi)) * PS_INV_PI;
        for (int c = 0; c < CHANNELS; ++c)
            s->weight[c] = albedo[c];
    }
    s->delta = 0;
    s->eta = 1.0;
}

/* Mirror.sample: the reflection of wo about n (cos_o = dot(n, wo)). */
static void sample_mirror(const double *reflectance, const float n[3], const float wo[3], float cos_o, Sample *s)
{
    float twice = 2.0f * cos_o;
    for (int k = 0; k < 3; ++k)
        s->wi[k] = twice * n[k] - wo[k];
    for (int c = 0; c < CHANNELS; ++c)
        s->weight[c] = reflectance[c];
    s->pdf = 1.0;
    s->delta = 1;
    s->eta = 1.0;
}

/* Dielectric.sample: interior index ior, wo arriving from the outside or not, u0 choosing between reflection
 * (probability F) and refraction; radiance scaled by 1 / eta^2 on refraction unless transporting importance. */
static void sample_dielectric(double ior, int outside, const float n[3], const float wo[3], float cos_o, double u0,
                              int importance, Sample *s)
{
    double eta = outside ? ior : 1.0 / ior, cos_i = (double)cos_o, cos_t;
    double fresnel = fresnel_dielectric(cos_i, eta, &cos_t);
    int reflects = u0 < fresnel;
    double w[3];
    for (int k = 0; k < 3; ++k) {
        double nk = (double)n[k], wk = (double)wo[k];
        w[k] = reflects ? 2.0 * cos_i * nk - wk : -wk / eta + (cos_i / eta - cos_t) * nk;
    }
    double length = sqrt((w[0] * w[0] + w[1] * w[1]) + w[2] * w[2]);
    for (int k = 0; k < 3; ++k)
        s->wi[k] = (float)(w[k] / length);
    s->pdf = reflects ? fresnel : 1.0 - fresnel;
    double scale = importance ? 1.0 : 1.0 / (eta * eta);
    for (int c = 0; c < CHANNELS; ++c)
        s->weight[c] = reflects ? 1.0 : scale;
    s->delta = 1;
    s->eta = reflects ? 1.0 : eta;
}

/* NumPy's max over channels and clip to [0, cap], NaN propagating. */
static inline double clipped_max(const double *x, double cap)
{
    double m = x[0];
    for (int c = 1; c < CHANNELS; ++c)
        if (isnan(x[c]) || x[c] > m)
            m = isnan(m) ? m : x[c];
    if (isnan(m))
        return m;
    return m < 0.0 ? 0.0 : (m > cap ? cap : m);
}

/* RussianRoulette.survival at a vertex reached after `depth` segments, of a material with `albedo` (specular
 * or not), for a walk of throughput beta taking the sample s: "albedo" survives specular vertices with 1 before
 * the trapped depth; "throughput" reads beta weight scale (Walk.survival: scale = eta_scale eta^2 undoes the
 * 1 / eta^2 of a radiance walk's refractions; a light subpath's is its rr_scale, the throughput relative to the
 * ray leaving the light) and survives specular vertices with at most their albedo from the trapped depth on. */
static double survival(const Options *o, int depth, double albedo, int specular, const double *beta,
                       const Sample *s, double scale)
{
    if (depth < o->start_depth)
        return 1.0;
    if (o->policy == ROULETTE_FIXED)
        return 1.0 - o->probability;
    if (o->policy == ROULETTE_ALBEDO) {
        if (specular && depth < o->trapped_depth)
            return 1.0;
        return albedo < 0.0 ? 0.0 : (albedo > 1.0 ? 1.0 : albedo);
    }
    double throughput[CHANNELS];
    for (int c = 0; c < CHANNELS; ++c)
        throughput[c] = beta[c] * s->weight[c] * scale;
    double q = clipped_max(throughput, o->cap);
    if (specular && depth >= o->trapped_depth)
        q = isnan(q) || isnan(albedo) ? NAN : (albedo < q ? albedo : q);
    return q;
}

/* Lanes are taken in blocks: each stage runs over a block's lanes before the next, so that the long chains of
 * divisions and square roots of one lane overlap with those of the others (one lane at a time through every
 * stage measured 1.6x slower). */
#define BLOCK 64

/* The arrays of a call: the tables, the lanes' inputs and their outputs. */
typedef struct {
    npy_intp n, materials;
    const int8_t *kind;
    const double *reflectance, *ior, *albedo, *radiance;
    PsAreaLights lights;
    const float *p, *normal, *eps, *cos, *direction, *cos_phi, *sin_phi;
    const int32_t *material, *depth;
    const double *beta, *eta_scale, *rr_scale, *u;
    double *value, *beta_out, *pdf, *eta_out, *pdf_back;
    npy_bool *useful, *alive, *delta;
    float *light_point, *light_normal, *light_eps, *normal_out, *origin, *wi;
} VertexArrays;

/* The surface seen from lane i's ray (pathspace.bsdfs.Surface.facing): the geometric normal turned toward the
 * ray's origin, and whether it was (the ray arrives from the outside). */
static inline int facing_normal(const VertexArrays *va, npy_intp i, float nf[3])
{
    npy_intp n = va->n;
    int outside = va->cos[i] >= 0.0f;
    for (int c = 0; c < 3; ++c)
        nf[c] = va->normal[c * n + i] * (outside ? 1.0f : -1.0f);
    return outside;
}

/* Next-event estimation at the lanes start .. end - 1 (of materials mat[i - start], checked) whose material is
 * diffuse, with light samples on: their values, usefulness and light points; the turned normals of every lane.
 * Returns the number of light samples. */
static npy_intp next_events(const VertexArrays *va, const Options *o, const int32_t *mat, npy_intp start,
                            npy_intp end)
{
    npy_intp n = va->n, count = 0;
    PsLightSample ls[BLOCK];
    int sampled[BLOCK];
    for (npy_intp i = start; i < end; ++i) {
        PsLightSample *s = ls + (i - start);
        sampled[i - start] = o->heuristic >= 0 && va->kind[mat[i - start]] == KIND_DIFFUSE;
        if (!sampled[i - start]) {
            *s = (PsLightSample){0};
            continue;
        }
        float x[3] = {va->p[i], va->p[n + i], va->p[2 * n + i]};
        ps_sample_area_light(&va->lights, va->u[i], va->u[n + i], va->u[2 * n + i], x, s);
    }
    for (npy_intp i = start; i < end; ++i) {
        const PsLightSample *s = ls + (i - start);
        int32_t m = mat[i - start];
        float nf[3];
        facing_normal(va, i, nf);
        double v[CHANNELS] = {0.0, 0.0, 0.0};
        int useful = 0;
        if (sampled[i - start]) {
            ++count;
            double pdf_bsdf, f_cos[CHANNELS], le[CHANNELS], b[CHANNELS];
            double cos_over_pi = ps_diffuse_eval(o->diffuse_technique, nf, s->wi, &pdf_bsdf);
            for (int c = 0; c < CHANNELS; ++c) {
                f_cos[c] = va->reflectance[c * va->materials + m] * cos_over_pi;
                le[c] = va->radiance[c * va->lights.count + s->entity];
                b[c] = va->beta[c * n + i];
            }
            useful = ps_next_event(CHANNELS, b, f_cos, le, s->pdf, pdf_bsdf, s->facing, 0, o->heuristic,
                                   o->exponent, v);
        }
        va->useful[i] = (npy_bool)useful;
        for (int c = 0; c < 3; ++c) {
            va->value[c * n + i] = v[c];
            va->light_point[c * n + i] = s->point[c];
            va->light_normal[c * n + i] = s->normal[c];
            va->normal_out[c * n + i] = nf[c];
        }
        va->light_eps[i] = s->epsilon;
    }
    return count;
}

/* The BSDF samples of the lanes start .. end - 1 (of materials mat[i - start], checked), their roulette (if
 * `roulette`) and their next rays. */
static void scatter(const VertexArrays *va, const Options *o, int roulette, const int32_t *mat, npy_intp start,
                    npy_intp end)
{
    npy_intp n = va->n;
    Sample samples[BLOCK];
    for (npy_intp i = start; i < end; ++i) {
        Sample *s = samples + (i - start);
        int32_t m = mat[i - start];
        int k = va->kind[m];
        float nf[3], wo[3], cos_o = fabsf(va->cos[i]);
        int outside = facing_normal(va, i, nf);
        for (int c = 0; c < 3; ++c)
            wo[c] = -va->direction[c * n + i];
        const double *colour = va->reflectance + m;
        double tint[CHANNELS] = {colour[0], colour[va->materials], colour[2 * va->materials]};
        const double *u = va->u + o->bsdf_row * n + i; /* the BSDF's numbers u[0], u[n], u[2 n] */
        if (k == KIND_DIFFUSE)
            sample_diffuse(o, tint, nf, u[n], va->cos_phi[i], va->sin_phi[i], s);
        else if (k == KIND_MIRROR)
            sample_mirror(tint, nf, wo, cos_o, s);
        else
            sample_dielectric(va->ior[m], outside, nf, wo, cos_o, u[0], o->importance, s);
    }
    for (npy_intp i = start; i < end; ++i) {
        const Sample *s = samples + (i - start);
        int32_t m = mat[i - start];
        double b[CHANNELS], next[CHANNELS];
        for (int c = 0; c < CHANNELS; ++c)
            b[c] = va->beta[c * n + i];
        double eta_scale = va->eta_scale ? va->eta_scale[i] : 1.0;
        double scale = o->importance ? (va->rr_scale ? va->rr_scale[i] : 1.0) : eta_scale * s->eta * s->eta;
        double q = roulette ? survival(o, va->depth[i], va->albedo[m], va->kind[m] != KIND_DIFFUSE, b, s, scale) : 1.0;
        float x[3] = {va->p[i], va->p[n + i], va->p[2 * n + i]}, from[3],
              ng[3] = {va->normal[i], va->normal[n + i], va->normal[2 * n + i]};
        va->alive[i] = (npy_bool)ps_scatter(CHANNELS, b, s->weight, roulette ? &q : NULL,
                                           va->u[(o->bsdf_row + 3) * n + i], x, ng, va->eps[i], s->wi, next, from);
        for (int c = 0; c < 3; ++c) {
            va->beta_out[c * n + i] = next[c];
            va->origin[c * n + i] = from[c];
            va->wi[c * n + i] = s->wi[c];
        }
        va->pdf[i] = s->pdf;
        va->delta[i] = (npy_bool)s->delta;
        if (va->eta_out)
            va->eta_out[i] = eta_scale * s->eta * s->eta;
        if (va->pdf_back && s->delta) { /* MIS densities of a specular vertex: the lobe's probability times the
                                           * geometry of its directions (subpaths.specular_densities) */
            va->pdf[i] = s->pdf * (s->eta * s->eta) * (double)fabsf(ps_dot3(ng, s->wi));
            va->pdf_back[i] = s->pdf * (double)fabsf(va->cos[i]);
        } else if (va->pdf_back) { /* light arriving along the sample, toward where the walk came from */
            float back[3] = {-va->direction[i], -va->direction[n + i], -va->direction[2 * n + i]};
            va->pdf_back[i] = ps_diffuse_reverse_pdf(o->diffuse_technique, ng, s->wi, back);
        }
    }
}

enum {
    A_KIND, A_REFLECTANCE, A_IOR, A_ALBEDO,                                  /* materials */
    A_TABLE, A_AREA, A_TWO_SIDED, A_CDF, A_PMF, A_RADIANCE,                  /* emitting triangles */
    A_P, A_NORMAL, A_EPS, A_COS, A_DIRECTION, A_MATERIAL, A_BETA, A_ETA_SCALE, A_RR_SCALE, A_DEPTH, A_U,
    A_COS_PHI, A_SIN_PHI,                                                    /* lanes */
    A_COUNT
};

static const PsArraySpec SPECS[A_COUNT] = {
    {"kind", NPY_INT8, "int8", 1, 0},           {"reflectance", NPY_DOUBLE, "float64", 2, 0},
    {"ior", NPY_DOUBLE, "float64", 1, 0},       {"albedo", NPY_DOUBLE, "float64", 1, 0},
    {"table", NPY_FLOAT, "float32", 2, 1},      {"area", NPY_DOUBLE, "float64", 1, 1},
    {"two_sided", NPY_BOOL, "bool", 1, 1},      {"cdf", NPY_DOUBLE, "float64", 1, 1},
    {"pmf", NPY_DOUBLE, "float64", 1, 1},       {"radiance", NPY_DOUBLE, "float64", 2, 1},
    {"p", NPY_FLOAT, "float32", 2, 0},          {"normal", NPY_FLOAT, "float32", 2, 0},
    {"eps", NPY_FLOAT, "float32", 1, 0},        {"cos", NPY_FLOAT, "float32", 1, 0},
    {"direction", NPY_FLOAT, "float32", 2, 0},  {"material", NPY_INT32, "int32", 1, 0},
    {"beta", NPY_DOUBLE, "float64", 2, 0},      {"eta_scale", NPY_DOUBLE, "float64", 1, 1},
    {"rr_scale", NPY_DOUBLE, "float64", 1, 1},  {"depth", NPY_INT32, "int32", 1, 0},
    {"u", NPY_DOUBLE, "float64", 2, 0},
    {"cos_phi", NPY_FLOAT, "float32", 1, 0},    {"sin_phi", NPY_FLOAT, "float32", 1, 0},
};

/* The shapes of the arguments: materials (M,) and (3, M), emitting triangles (13, E), (E,) and (3, E) (all or
 * none of them), lanes (N,), (3, N) and u (R, N) with the BSDF's and roulette's numbers in rows bsdf_row ..
 * bsdf_row + 3 and, with light samples, the light's in rows 0 .. 2 below them; 0, or -1 with a ValueError. */
static int check_shapes(PyArrayObject **a, Options *o)
{
    npy_intp m = PyArray_DIM(a[A_KIND], 0), n = PyArray_DIM(a[A_DEPTH], 0);
    int ok = m >= 1 && PyArray_DIM(a[A_REFLECTANCE], 0) == CHANNELS && PyArray_DIM(a[A_REFLECTANCE], 1) == m &&
             PyArray_DIM(a[A_IOR], 0) == m && PyArray_DIM(a[A_ALBEDO], 0) == m;
    if (!ok) {
        PyErr_SetString(PyExc_ValueError, "pt_vertex: kind, ior and albedo (M,) with M >= 1 and reflectance (3, M) "
                                          "must agree");
        return -1;
    }
    int lights = a[A_TABLE] != NULL;
    for (int k = A_AREA; k <= A_RADIANCE; ++k)
        ok = ok && (a[k] != NULL) == lights;
    if (!ok || lights != (o->heuristic >= 0)) {
        PyErr_SetString(PyExc_ValueError, "pt_vertex: the light tables are given exactly when light samples are "
                                          "taken (heuristic >= 0)");
        return -1;
    }
    if (lights) {
        npy_intp e = PyArray_DIM(a[A_TABLE], 1);
        ok = e >= 1 && PyArray_DIM(a[A_TABLE], 0) == AREA_TABLE_ROWS && PyArray_DIM(a[A_AREA], 0) == e &&
             PyArray_DIM(a[A_TWO_SIDED], 0) == e && PyArray_DIM(a[A_CDF], 0) == e && PyArray_DIM(a[A_PMF], 0) == e &&
             PyArray_DIM(a[A_RADIANCE], 0) == CHANNELS && PyArray_DIM(a[A_RADIANCE], 1) == e;
        if (!ok) {
            PyErr_Format(PyExc_ValueError, "pt_vertex: table (%d, E) with E >= 1, area, two_sided, cdf and pmf (E,) "
                                           "and radiance (3, E) must agree", AREA_TABLE_ROWS);
            return -1;
        }
    }
    for (int k = A_P; k < A_COUNT; ++k) {
        PyArrayObject *x = a[k];
        if (!x || k == A_U)
            continue;
        int rows = PyArray_NDIM(x) == 2 ? 3 : 0;
        if (PyArray_DIM(x, PyArray_NDIM(x) - 1) != n || (rows && PyArray_DIM(x, 0) != rows)) {
            PyErr_Format(PyExc_ValueError, "pt_vertex: %s must have shape %s with N = %zd (the lanes of depth)",
                         SPECS[k].name, rows ? "(3, N)" : "(N,)", (Py_ssize_t)n);
            return -1;
        }
    }
    if (o->bsdf_row < (lights ? 3 : 0) || PyArray_DIM(a[A_U], 0) < (npy_intp)o->bsdf_row + 4 ||
        PyArray_DIM(a[A_U], 1) != n) {
        PyErr_Format(PyExc_ValueError, "pt_vertex: u must have shape (R, N) with N = %zd and the BSDF's and roulette's "
                                       "numbers in rows %d .. %lld, after the light sample's (rows 0 .. 2) if taken",
                     (Py_ssize_t)n, o->bsdf_row, (long long)o->bsdf_row + 3);
        return -1;
    }
    if (o->policy == ROULETTE_THROUGHPUT && !o->importance && !a[A_ETA_SCALE]) {
        PyErr_SetString(PyExc_ValueError, "pt_vertex: throughput roulette reads eta_scale, which is None");
        return -1;
    }
    if (o->policy == ROULETTE_THROUGHPUT && o->importance && !a[A_RR_SCALE]) {
        PyErr_SetString(PyExc_ValueError, "pt_vertex: throughput roulette of importance reads rr_scale, which is None");
        return -1;
    }
    if ((a[A_ETA_SCALE] && o->importance) || (a[A_RR_SCALE] && !o->importance)) {
        PyErr_SetString(PyExc_ValueError, "pt_vertex: eta_scale is for radiance, rr_scale for importance");
        return -1;
    }
    return 0;
}

/* The outputs, in the order returned. */
enum {
    O_VALUE, O_USEFUL, O_LIGHT_POINT, O_LIGHT_NORMAL, O_LIGHT_EPS, O_NORMAL, O_BETA, O_ALIVE, O_ORIGIN, O_WI, O_PDF,
    O_DELTA, O_ETA_SCALE, O_PDF_BACK, O_COUNT
};

int ps_add_pt_vertex_constants(PyObject *module)
{
    PyObject *kinds = PyTuple_New(KIND_COUNT);
    if (!kinds)
        return -1;
    for (int k = 0; k < KIND_COUNT; ++k) {
        PyObject *name = PyUnicode_FromString(KIND_NAMES[k]);
        if (!name) {
            Py_DECREF(kinds);
            return -1;
        }
        PyTuple_SET_ITEM(kinds, k, name);
    }
    PyObject *inv_pi = PyFloat_FromDouble(PS_INV_PI), *inv_two_pi = PyFloat_FromDouble(PS_INV_TWO_PI);
    int status = inv_pi && inv_two_pi && PyModule_AddObjectRef(module, "PT_VERTEX_KINDS", kinds) == 0 &&
                         PyModule_AddObjectRef(module, "INV_PI", inv_pi) == 0 &&
                         PyModule_AddObjectRef(module, "INV_TWO_PI", inv_two_pi) == 0
                     ? 0
                     : -1;
    Py_DECREF(kinds);
    Py_XDECREF(inv_pi);
    Py_XDECREF(inv_two_pi);
    return status;
}

PyObject *ps_pt_vertex(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *objs[A_COUNT];
    Options o;
    if (!PyArg_ParseTuple(args, "OOOOOOOOOOOOOOOOOOOOOOOiiiiidddiii:pt_vertex", &objs[0], &objs[1], &objs[2],
                          &objs[3], &objs[4], &objs[5], &objs[6], &objs[7], &objs[8], &objs[9], &objs[10],
                          &objs[11], &objs[12], &objs[13], &objs[14], &objs[15], &objs[16], &objs[17], &objs[18],
                          &objs[19], &objs[20], &objs[21], &objs[22], &o.diffuse_technique, &o.heuristic, &o.policy,
                          &o.start_depth, &o.trapped_depth, &o.exponent, &o.probability, &o.cap, &o.bsdf_row,
                          &o.importance, &o.reverse))
        return NULL;
    if (o.diffuse_technique < DIFFUSE_COSINE || o.diffuse_technique > DIFFUSE_UNIFORM || o.heuristic < -1 ||
        o.heuristic > MIS_UNIFORM || o.policy < ROULETTE_OFF || o.policy >= ROULETTE_COUNT) {
        PyErr_Format(PyExc_ValueError, "pt_vertex: diffuse technique 0 or 1, heuristic -1 (no light samples) to 3 "
                                       "and roulette policy 0 to 3 expected, got %d, %d and %d",
                     o.diffuse_technique, o.heuristic, o.policy);
        return NULL;
    }
    if (o.bsdf_row < 0 || (o.importance != 0 && o.importance != 1) || (o.reverse != 0 && o.reverse != 1) ||
        (o.importance && o.heuristic >= 0)) {
        PyErr_Format(PyExc_ValueError, "pt_vertex: bsdf_row >= 0, importance and reverse 0 or 1, and no light "
                                       "samples when transporting importance expected, got %d, %d and %d",
                     o.bsdf_row, o.importance, o.reverse);
        return NULL;
    }
    PyArrayObject *a[A_COUNT];
    if (ps_checked_arrays(objs, SPECS, A_COUNT, (PyObject **)a) < 0 || check_shapes(a, &o) < 0)
        return NULL;
    npy_intp n = PyArray_DIM(a[A_DEPTH], 0), materials = PyArray_DIM(a[A_KIND], 0);
    const int8_t *kind = (const int8_t *)PyArray_DATA(a[A_KIND]);
    for (npy_intp m = 0; m < materials; ++m)
        if (kind[m] < 0 || kind[m] >= KIND_COUNT) {
            PyErr_Format(PyExc_ValueError, "pt_vertex: kind[%zd] = %d is not a material kind (0 to %d)",
                         (Py_ssize_t)m, kind[m], KIND_COUNT - 1);
            return NULL;
        }
    npy_intp dims[2] = {CHANNELS, n}, dims3[2] = {3, n};
    PyObject *out[O_COUNT] = {
        PyArray_SimpleNew(2, dims, NPY_DOUBLE), PyArray_SimpleNew(1, &n, NPY_BOOL),
        PyArray_SimpleNew(2, dims3, NPY_FLOAT),  PyArray_SimpleNew(2, dims3, NPY_FLOAT),
        PyArray_SimpleNew(1, &n, NPY_FLOAT),     PyArray_SimpleNew(2, dims3, NPY_FLOAT),
        PyArray_SimpleNew(2, dims, NPY_DOUBLE), PyArray_SimpleNew(1, &n, NPY_BOOL),
        PyArray_SimpleNew(2, dims3, NPY_FLOAT),  PyArray_SimpleNew(2, dims3, NPY_FLOAT),
        PyArray_SimpleNew(1, &n, NPY_DOUBLE),    PyArray_SimpleNew(1, &n, NPY_BOOL),
        a[A_ETA_SCALE] ? PyArray_SimpleNew(1, &n, NPY_DOUBLE) : Py_NewRef(Py_None),
        o.reverse ? PyArray_SimpleNew(1, &n, NPY_DOUBLE) : Py_NewRef(Py_None),
    };
    if (!ps_outputs_allocated(out, O_COUNT))
        return NULL;
#define IN(k, type) ((const type *)(a[k] ? PyArray_DATA(a[k]) : NULL))
#define OUT(k, type) ((type *)PyArray_DATA((PyArrayObject *)out[k]))
    VertexArrays va = {
        .n = n, .materials = materials, .kind = kind, .reflectance = IN(A_REFLECTANCE, double),
        .ior = IN(A_IOR, double), .albedo = IN(A_ALBEDO, double), .radiance = IN(A_RADIANCE, double),
        .lights = {IN(A_TABLE, float), IN(A_AREA, double), IN(A_CDF, double), IN(A_PMF, double),
                   IN(A_TWO_SIDED, npy_bool), a[A_TABLE] ? PyArray_DIM(a[A_TABLE], 1) : 0},
        .p = IN(A_P, float), .normal = IN(A_NORMAL, float), .eps = IN(A_EPS, float), .cos = IN(A_COS, float),
        .direction = IN(A_DIRECTION, float), .cos_phi = IN(A_COS_PHI, float), .sin_phi = IN(A_SIN_PHI, float),
        .material = IN(A_MATERIAL, int32_t), .depth = IN(A_DEPTH, int32_t), .beta = IN(A_BETA, double),
        .eta_scale = IN(A_ETA_SCALE, double), .rr_scale = IN(A_RR_SCALE, double), .u = IN(A_U, double),
        .value = OUT(O_VALUE, double), .useful = OUT(O_USEFUL, npy_bool), .light_point = OUT(O_LIGHT_POINT, float),
        .light_normal = OUT(O_LIGHT_NORMAL, float), .light_eps = OUT(O_LIGHT_EPS, float),
        .normal_out = OUT(O_NORMAL, float), .beta_out = OUT(O_BETA, double), .alive = OUT(O_ALIVE, npy_bool),
        .origin = OUT(O_ORIGIN, float), .wi = OUT(O_WI, float), .pdf = OUT(O_PDF, double),
        .delta = OUT(O_DELTA, npy_bool), .eta_out = a[A_ETA_SCALE] ? OUT(O_ETA_SCALE, double) : NULL,
        .pdf_back = o.reverse ? OUT(O_PDF_BACK, double) : NULL,
    };
#undef IN
#undef OUT
    npy_intp bad = -1, light_samples = 0;
    Py_BEGIN_ALLOW_THREADS
    int deep = 0; /* RussianRoulette.survival gives None (every lane survives) if no lane is deep enough */
    for (npy_intp i = 0; i < n; ++i)
        deep |= va.depth[i] >= o.start_depth;
    int roulette = o.policy != ROULETTE_OFF && deep;
    for (npy_intp start = 0; start < n && bad < 0; start += BLOCK) {
        npy_intp end = start + BLOCK < n ? start + BLOCK : n;
        int32_t mat[BLOCK]; /* the block's material ids, read once: checked here, used below */
        for (npy_intp i = start; i < end; ++i) {
            mat[i - start] = va.material[i];
            if ((uint32_t)mat[i - start] >= (uint64_t)materials && bad < 0)
                bad = i;
        }
        if (bad >= 0)
            break;
        light_samples += next_events(&va, &o, mat, start, end);
        scatter(&va, &o, roulette, mat, start, end);
    }
    Py_END_ALLOW_THREADS
    if (bad >= 0) {
        for (int k = 0; k < O_COUNT; ++k)
            Py_DECREF(out[k]);
        PyErr_Format(PyExc_IndexError, "pt_vertex: material[%zd] is not a material of the table", (Py_ssize_t)bad);
        return NULL;
    }
    return Py_BuildValue("(NNNNNNNNNNNNNNn)", out[0], out[1], out[2], out[3], out[4], out[5], out[6], out[7], out[8],
                         out[9], out[10], out[11], out[12], out[13], (Py_ssize_t)light_samples);
}
