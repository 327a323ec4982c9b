/*
 * Shadow rays between surface points (Accel.occluded_between, _native.shadow_rays): each segment's ray is
 * built as pathspace.vecmath.shadow_ray builds it, in the same float32 operations in the same order (so the
 * rays are bit for bit the NumPy reference's; setup.py turns FMA contraction off, and a build that would
 * reassociate or keep excess precision is refused in native.h).
 */
#ifndef PATHSPACE_SHADOW_H
#define PATHSPACE_SHADOW_H

#include "native.h"

#include <float.h>
#include <math.h>
#include <stdint.h>

/* pathspace.vecmath's gamma(SHADOW_END_ROUNDINGS = 4) in float32, as NumPy multiplies a float32 array by it. */
#define SHADOW_END_SLACK ((float)(4.0 * 0x1p-24 / (1.0 - 4.0 * 0x1p-24)))
/* pathspace.vecmath.RAY_TMIN: the least normal float32. */
#define SHADOW_RAY_TMIN FLT_MIN

/* Segments between surface points a and b: (3, N) points and unit normals and (N,) error bounds, all
 * C-contiguous float32; segment i joins point lanes[i] (or i) of a and point b_lanes[i] (or the same lane) of b,
 * whose arrays are N_b wide (N unless b_lanes is given). */
typedef struct {
    const float *a, *n_a, *eps_a, *b, *n_b, *eps_b;
    const int64_t *lanes, *b_lanes;
    Py_ssize_t width;   /* N */
    Py_ssize_t width_b; /* N_b */
    Py_ssize_t count;   /* segments: the length of lanes, or N */
} Segments;

/* The ray of segment i as float32 {org xyz, tnear, dir xyz, tfar} (see pathspace.vecmath.shadow_ray: both ends
 * offset toward each other by their error bounds, tmax short of the far surface by the slack of its plane
 * test), with tnear RAY_TMIN; returns 0 if the ray is invalid or its lane is out of range (lanes are read once
 * here, so an array changed while the GIL is released cannot send the reads out of bounds). */
static inline int ps_segment_ray(const Segments *s, Py_ssize_t i, float r[8])
{
    Py_ssize_t n = s->width, n_b = s->width_b, lane = s->lanes ? (Py_ssize_t)s->lanes[i] : i;
    Py_ssize_t lane_b = s->b_lanes ? (Py_ssize_t)s->b_lanes[i] : lane;
    if ((size_t)lane >= (size_t)n || (size_t)lane_b >= (size_t)n_b)
        return 0;
    float a[3], na[3], b[3], nb[3], w[3], back[3], end[3];
    for (int c = 0; c < 3; ++c) {
        a[c] = s->a[c * n + lane];
        na[c] = s->n_a[c * n + lane];
        b[c] = s->b[c * n_b + lane_b];
        nb[c] = s->n_b[c * n_b + lane_b];
        w[c] = b[c] - a[c];
        back[c] = -w[c];
    }
    float eps_a = s->eps_a[lane], eps_b = s->eps_b[lane_b];
    float side_a = ps_dot3(na, w) < 0.0f ? -eps_a : eps_a;       /* offset_origin(a, n_a, eps_a, w) */
    float side_b = ps_dot3(nb, back) < 0.0f ? -eps_b : eps_b;    /* offset_origin(b, n_b, eps_b, -w) */
    for (int c = 0; c < 3; ++c) {
        r[c] = a[c] + na[c] * side_a;
        end[c] = b[c] + nb[c] * side_b;
    }
    for (int c = 0; c < 3; ++c)
        r[4 + c] = end[c] - r[c];
    const float *d = r + 4;
    float spread = (fabsf(nb[0] * d[0]) + fabsf(nb[1] * d[1])) + fabsf(nb[2] * d[2]);
    float slack = eps_b > 0.0f ? SHADOW_END_SLACK * spread : 0.0f;
    float across = fabsf(ps_dot3(d, nb));
    float tmax = slack > 0.0f ? 1.0f - slack / across : 1.0f;
    r[3] = SHADOW_RAY_TMIN;
    r[7] = isnan(tmax) || tmax > 0.0f ? tmax : 0.0f; /* np.maximum(tmax, 0), which keeps NaN */
    for (int k = 0; k < 7; ++k)
        if (!isfinite(r[k]))
            return 0;
    if (r[4] == 0.0f && r[5] == 0.0f && r[6] == 0.0f)
        return 0;
    return !isnan(r[7]);
}

/* Fill *s from the six arrays a, n_a, eps_a, b, n_b, eps_b, lanes and b_lanes (None or int64 (M,)); 0, or -1
 * with a Python exception naming the argument. */
int ps_parse_segments(PyObject *const arrays[6], PyObject *lanes, PyObject *b_lanes, Segments *s);
/* The exception for segment i, which ps_segment_ray found invalid; returns NULL. */
PyObject *ps_bad_segment(const Segments *s, Py_ssize_t i);

#endif
