/*
 * A random walk leaving a vertex, per lane (ext/scatter.c's scatter_step and ext/pt_vertex.c's fused
 * path-tracing vertex; see scatter.c for the formulas and the NumPy reference).
 */
#ifndef PATHSPACE_SCATTER_H
#define PATHSPACE_SCATTER_H

#include "native.h"

#include <math.h>

/* From the throughput beta and the BSDF sample's weight (channels each), the survival probability *q (q NULL:
 * every lane survives) and its uniform u, the vertex's point p, unit geometric normal n and error bound eps and
 * the sampled direction w: the next throughput beta_out and ray origin; returns whether the walk goes on. */
static inline int ps_scatter(Py_ssize_t channels, const double *beta, const double *weight, const double *q,
                             double u, const float p[3], const float n[3], float eps, const float w[3],
                             double *beta_out, float origin[3])
{
    int positive = 0, nan = 0;
    for (Py_ssize_t c = 0; c < channels; ++c) {
        nan |= isnan(weight[c]);
        positive |= weight[c] > 0.0;
        beta_out[c] = beta[c] * weight[c];
    }
    int lives = positive && !nan;
    if (q) {
        lives = lives && u < *q;
        if (*q > 0.0)
            for (Py_ssize_t c = 0; c < channels; ++c)
                beta_out[c] = beta_out[c] / *q;
    }
    float cos_w = (n[0] * w[0] + n[1] * w[1]) + n[2] * w[2];
    float side = cos_w < 0.0f ? -eps : eps;
    for (int k = 0; k < 3; ++k)
        origin[k] = p[k] + n[k] * side;
    return lives;
}

#endif
