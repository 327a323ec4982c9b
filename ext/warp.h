/*
 * Cosine-weighted directions about unit normals, per lane (ext/warp.c's cosine_about and ext/pt_vertex.c's
 * fused path-tracing vertex; see warp.c for the construction and the NumPy reference).
 */
#ifndef PATHSPACE_WARP_H
#define PATHSPACE_WARP_H

#include <math.h>

/* pathspace.warp.INV_PI and INV_TWO_PI (1 / pi and 0.5 / pi in float64; exported and tested equal). */
#define PS_INV_PI (1.0 / M_PI)
#define PS_INV_TWO_PI (0.5 / M_PI)

/* The unit direction w about the unit normal n from the uniform u0 and the cosine and sine of the azimuth
 * 2 pi u1 (float32, as NumPy computes them). */
static inline void ps_cosine_direction(const float n[3], double u0, float cos_phi, float sin_phi, float w[3])
{
    float z = 1.0f - 2.0f * (float)u0;
    float t = 1.0f - z * z;
    float r = sqrtf(t < 0.0f ? 0.0f : t);
    float d[3] = {n[0] + r * cos_phi, n[1] + r * sin_phi, n[2] + z};
    float length = sqrtf((d[0] * d[0] + d[1] * d[1]) + d[2] * d[2]);
    for (int k = 0; k < 3; ++k)
        w[k] = length > 1e-6f ? d[k] / length : n[k];
}

#endif
