/*
 * A receiver joined to a pinhole camera, per lane (ext/camera.c's pinhole_connect and ext/lens_connect.c's light
 * tracer's connection; see camera.c for the formulas and the NumPy reference).
 */
#ifndef PATHSPACE_CAMERA_H
#define PATHSPACE_CAMERA_H

#include "native.h"

#include <math.h>

/* A pinhole camera: its position o, unit axis f, the image's right r and up u, the tangents of the half field
 * of view, the film's size in pixels and the lens area. */
typedef struct {
    double o[3], f[3], r[3], u[3];
    double tan_x, tan_y, width, height, lens_area;
} PsPinhole;

/* For the receiver x: the unit direction w to the pinhole, the pinhole's solid-angle density at x, the raster
 * position of x and whether it is on the film, and the cosine at the lens; returns the squared distance. */
static inline double ps_join_pinhole(const PsPinhole *cam, const double x[3], double w[3], double *pdf,
                                   double raster[2], int *on_film, double *cos_lens)
{
    double to_lens[3], p[3];
    for (int c = 0; c < 3; ++c) {
        to_lens[c] = cam->o[c] - x[c];
        p[c] = x[c] - cam->o[c];
    }
    double dist2 = (to_lens[0] * to_lens[0] + to_lens[1] * to_lens[1]) + to_lens[2] * to_lens[2];
    double dist = sqrt(dist2);
    for (int c = 0; c < 3; ++c)
        w[c] = to_lens[c] / dist;
    const double *f = cam->f, *r = cam->r, *u = cam->u;
    double depth = (f[0] * p[0] + f[1] * p[1]) + f[2] * p[2];
    double sx = (((r[0] * p[0] + r[1] * p[1]) + r[2] * p[2]) / depth) / cam->tan_x;
    double sy = (((u[0] * p[0] + u[1] * p[1]) + u[2] * p[2]) / depth) / cam->tan_y;
    double fx = ((sx + 1.0) * 0.5) * cam->width, fy = ((1.0 - sy) * 0.5) * cam->height;
    raster[0] = fx;
    raster[1] = fy;
    *on_film = depth > 0.0 && fx >= 0.0 && fx < cam->width && fy >= 0.0 && fy < cam->height;
    *cos_lens = (f[0] * -w[0] + f[1] * -w[1]) + f[2] * -w[2];
    *pdf = dist2 / (fabs(*cos_lens) * cam->lens_area);
    return dist2;
}

/* Fill cam from the Python arguments position, forward, right, image_up (three floats each) and the scalars;
 * 0, or -1 with an exception naming the argument (camera.c). */
int ps_parse_pinhole(PyObject *const vectors[4], double tan_x, double tan_y, Py_ssize_t width, Py_ssize_t height,
                     double lens_area, PsPinhole *cam);

#endif
