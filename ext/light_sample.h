/*
 * One light sample on area lights, per receiver (ext/lights.c's area_light_sample and ext/pt_vertex.c's fused
 * path-tracing vertex): the emitting triangle from the selection CDF, a point uniform in its area, and the
 * direction, distance and solid-angle density toward it (see lights.c for the formulas and the NumPy reference).
 */
#ifndef PATHSPACE_LIGHT_SAMPLE_H
#define PATHSPACE_LIGHT_SAMPLE_H

#include "native.h"

#include <math.h>
#include <stdint.h>

#define AREA_TABLE_ROWS 13 /* an emitting triangle's table: p0 (3), e1 (3), e2 (3), unit normal (3), ray offset (1) */

/* The emitting triangles: their table (AREA_TABLE_ROWS, count) float32, area, two-sidedness, and the selection's
 * increasing CDF and pmf, all (count,). */
typedef struct {
    const float *table;
    const double *area, *cdf, *pmf;
    const unsigned char *two_sided; /* npy_bool */
    Py_ssize_t count;
} PsAreaLights;

/* A light sample: emitting triangle, point, its unit normal and ray offset, unit direction and distance from
 * the receiver, whether the light emits toward it, and the solid-angle density (with the selection's pmf). */
typedef struct {
    Py_ssize_t entity;
    float point[3], normal[3], wi[3];
    float distance, epsilon;
    int facing;
    double pdf;
} PsLightSample;

/* The number of entries of the increasing cdf (n) that are <= x, NaN counting as larger than every number
 * (NumPy's searchsorted(side="right"), NaN sorting last). */
static inline Py_ssize_t ps_entries_at_most(const double *cdf, Py_ssize_t n, double x)
{
    if (isnan(x))
        return n;
    if (n < 1)
        return 0;
    /* the count lies in lo .. lo + len; halving without branches on the (random) comparisons */
    Py_ssize_t lo = 0, len = n;
    while (len > 1) {
        Py_ssize_t half = len / 2;
        lo += cdf[lo + half - 1] <= x ? half : 0;
        len -= half;
    }
    return lo + (cdf[lo] <= x);
}

/* The light sample for the receiver x from the uniforms u0 (selection), u1 and u2 (the point), in the
 * operations and order of AreaTables.sample. */
static inline void ps_sample_area_light(const PsAreaLights *lights, double u0, double u1, double u2,
                                        const float x[3], PsLightSample *s)
{
    Py_ssize_t count = lights->count, j = ps_entries_at_most(lights->cdf, count, u0);
    if (j > count - 1)
        j = count - 1;
    const float *t = lights->table;
    s->entity = j;
    double root = sqrt(u1);
    float b1 = (float)(root * (1.0 - u2)), b2 = (float)(root * u2);
    float w[3];
    for (int k = 0; k < 3; ++k) {
        s->point[k] = ps_triangle_coordinate(t, count, j, k, b1, b2);
        s->normal[k] = t[(9 + k) * count + j];
        w[k] = s->point[k] - x[k];
    }
    s->epsilon = t[12 * count + j];
    float dist2 = (w[0] * w[0] + w[1] * w[1]) + w[2] * w[2];
    float d = sqrtf(dist2);
    for (int k = 0; k < 3; ++k)
        s->wi[k] = d > 0.0f ? w[k] / d : 0.0f;
    float cos_light = -((s->normal[0] * s->wi[0] + s->normal[1] * s->wi[1]) + s->normal[2] * s->wi[2]);
    s->distance = d;
    s->facing = lights->two_sided[j] || cos_light > 0.0f;
    double density = d > 0.0f ? (double)dist2 / (lights->area[j] * (double)fabsf(cos_light)) : 0.0;
    s->pdf = density * lights->pmf[j];
}

#endif
