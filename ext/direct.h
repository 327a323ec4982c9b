/*
 * Path tracing's weights of emitters reached by light samples and by the walk (ext/direct.c, and the fused
 * vertex of ext/pt_vertex.c): multiple importance weights and the value of one light sample (see direct.c for
 * the formulas and the NumPy reference).
 */
#ifndef PATHSPACE_DIRECT_H
#define PATHSPACE_DIRECT_H

#include "native.h"

#include <math.h>

/* Strategies, as pathspace.estimators.pt.MIS_CODES numbers them: unweighted, three MIS heuristics, and (emitters
 * hit only) the weight of BSDF samples where light samples are taken alone. */
enum { MIS_NONE, MIS_BALANCE, MIS_POWER, MIS_UNIFORM, LIGHT_SAMPLES_ONLY };

/* Weight of a strategy of density a against one of density b, as pathspace.mis.mis_weight. */
static inline double ps_mis_weight(int heuristic, double exponent, double a, double b)
{
    double ratio;
    if (heuristic == MIS_UNIFORM) {
        ratio = a > 0.0 ? (b > 0.0 ? 1.0 : 0.0) : INFINITY;
    } else {
        ratio = b / a;
        if (heuristic == MIS_POWER)
            ratio = exponent == 2.0 ? ratio * ratio : pow(ratio, exponent);
    }
    double weight = 1.0 / (1.0 + ratio);
    if (isnan(weight))
        weight = isinf(a) ? 0.5 : 0.0;
    return weight;
}

/* The value of one light sample into value[c] (c < channels <= PS_MAX_CHANNELS): beta f |cos| (Le w / pdf_light),
 * or 0 where it is not useful; returns whether it is.  `delta`: the light is a delta light (no MIS weight). */
static inline int ps_next_event(Py_ssize_t channels, const double *beta, const double *f_cos, const double *le,
                                double pdf_light, double pdf_bsdf, int facing, int delta, int heuristic,
                                double exponent, double *value)
{
    double scale = 1.0 / pdf_light;
    if (heuristic != MIS_NONE && !delta)
        scale *= ps_mis_weight(heuristic, exponent, pdf_light, pdf_bsdf);
    int reflects = 0, nan = 0;
    for (Py_ssize_t c = 0; c < channels; ++c) {
        nan |= isnan(f_cos[c]);
        reflects |= f_cos[c] > 0.0;
    }
    int useful = facing && scale > 0.0 && reflects && !nan;
    for (Py_ssize_t c = 0; c < channels; ++c)
        value[c] = useful ? beta[c] * f_cos[c] * (le[c] * scale) : 0.0;
    return useful;
}

#endif
