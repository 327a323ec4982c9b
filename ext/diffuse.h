/*
 * The Lambertian BSDF's value and density per lane (pathspace.bsdfs.diffuse.Diffuse.eval, seen through
 * pathspace.bsdfs.Surface.facing), for the fused kernels (ext/pt_vertex.c, ext/join.c, ext/lens_connect.c): in
 * the operations and order of the NumPy code, so that they agree bit for bit.
 */
#ifndef PATHSPACE_DIFFUSE_H
#define PATHSPACE_DIFFUSE_H

#include "native.h"
#include "warp.h"

#include <math.h>

/* Diffuse sampling techniques, in the order of pathspace.bsdfs.DIFFUSE_SAMPLING. */
enum { DIFFUSE_COSINE, DIFFUSE_UNIFORM };

/* NumPy's maximum(x, 0) of a float32: NaN stays NaN (and -0 becomes +0). */
static inline float ps_max_zero(float x)
{
    return isnan(x) || x > 0.0f ? x : 0.0f;
}

/* The same of a float64. */
static inline double ps_max_zero_double(double x)
{
    return isnan(x) || x > 0.0 ? x : 0.0;
}

/* Surface.facing: the geometric normal n turned toward where rays along `direction` come from, into nf;
 * returns whether they arrive from the outside (the side n points to). */
static inline int ps_facing(const float n[3], const float direction[3], float nf[3])
{
    float cos = -(ps_dot3(n, direction));
    int outside = cos >= 0.0f;
    for (int k = 0; k < 3; ++k)
        nf[k] = n[k] * (outside ? 1.0f : -1.0f);
    return outside;
}

/* Diffuse.eval toward wi of a surface whose turned normal is nf: returns |cos| / pi where wi is on nf's side (0
 * elsewhere; f |cos| is the albedo times it), and puts the technique's solid-angle density into *pdf. */
static inline double ps_diffuse_eval(int technique, const float nf[3], const float wi[3], double *pdf)
{
    float cos_i = ps_dot3(nf, wi);
    double cos_over_pi = (double)ps_max_zero(cos_i) * PS_INV_PI;
    *pdf = technique == DIFFUSE_COSINE ? cos_over_pi : (cos_i > 0.0f ? PS_INV_TWO_PI : 0.0);
    return cos_over_pi;
}

/* pathspace.estimators.subpaths.reverse_pdf: the density with which a diffuse surface of geometric normal n
 * samples wo (toward its walk's previous vertex) when light arrives from `toward` (Surface.facing(n, -toward),
 * then Diffuse.eval toward wo; Veach 1997, eq. 10.7). */
static inline double ps_diffuse_reverse_pdf(int technique, const float n[3], const float toward[3],
                                            const float wo[3])
{
    float away[3] = {-toward[0], -toward[1], -toward[2]}, nf[3];
    ps_facing(n, away, nf);
    double pdf;
    ps_diffuse_eval(technique, nf, wo, &pdf);
    return pdf;
}

#endif
