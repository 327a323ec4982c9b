/* Shared declarations of the pathspace._native extension. */
#ifndef PATHSPACE_NATIVE_H
#define PATHSPACE_NATIVE_H

#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include <float.h>

/* The kernels that replace NumPy expressions compute as NumPy does, in plain IEEE arithmetic (and setup.py
 * turns FMA contraction off): a build that would reassociate or keep excess precision is refused. */
#if defined(__FAST_MATH__) || FLT_EVAL_METHOD != 0
#error "the C kernels must be built in plain IEEE arithmetic, as NumPy computes: no -ffast-math or excess precision"
#endif

#include "embree4_api.h"

/* The most colour channels a lane carries (RGB: 3; spectral: 4 wavelengths), which per-lane kernels keep in
 * local arrays. */
#define PS_MAX_CHANNELS 4

/* Embree loader (embree_loader.c). */
extern EmbreeAPI ps_embree;     /* function table, valid once ps_embree_device != NULL */
extern RTCDevice ps_embree_device;
int ps_require_embree(void);    /* 0 if loaded; else sets a Python RuntimeError, returns -1 */
const char *ps_embree_last_error(void);
void ps_embree_clear_error(void);
PyObject *ps_load_embree(PyObject *module, PyObject *args);
PyObject *ps_embree_loaded(PyObject *module, PyObject *unused);

/* BDPT MIS weights (mis.c). */
PyObject *ps_mis_weights(PyObject *module, PyObject *args, PyObject *kwargs);

/* Hit points, normals and ray offsets on the mesh's triangles (geometry.c). */
PyObject *ps_hit_geometry(PyObject *module, PyObject *args);
/* obj (borrowed) if it is a NumPy array of type `type` or `other` (NPY_ type numbers; -1: none) with ndim
 * dimensions, native byte order, C-contiguous and aligned; else NULL with a TypeError or ValueError naming
 * `name` (geometry.c). */
PyObject *ps_checked_array(PyObject *obj, const char *name, int type, int other, const char *type_name, int ndim);

/* One argument array of a kernel: its name, NPY_ type number and name, dimensions, and whether None may stand
 * for it. */
typedef struct {
    const char *name;
    int type;
    const char *type_name;
    int ndim;
    int optional;
} PsArraySpec;

/* arrays[k] = objs[k] (borrowed) checked as ps_checked_array checks it against specs[k] (NULL for None where
 * the spec is optional), for k < count; 0, or -1 with the error of the first that fails (geometry.c). */
int ps_checked_arrays(PyObject *const *objs, const PsArraySpec *specs, int count, PyObject **arrays);

/* obj (borrowed) if it is a 2D NumPy array of type `type` with `rows` rows, native byte order and aligned, whose
 * rows are contiguous (any stride between them: a range of columns of a wider array); else NULL with a
 * TypeError or ValueError naming `name` (geometry.c). */
PyObject *ps_rows_array(PyObject *obj, const char *name, int type, const char *type_name, Py_ssize_t rows);

/* The first `count` entries of `array`, a new 1-D array whose reference this takes: a view of them (the array
 * itself if count is its length); NULL with the exception set if the view cannot be made (geometry.c). */
PyObject *ps_first_entries(PyObject *array, Py_ssize_t count);

/* 1 if every one of `count` newly allocated outputs exists; else releases them all and returns 0 (the failed
 * allocation has set the exception). */
static inline int ps_outputs_allocated(PyObject **out, int count)
{
    for (int k = 0; k < count; ++k)
        if (!out[k]) {
            for (int j = 0; j < count; ++j)
                Py_XDECREF(out[j]);
            return 0;
        }
    return 1;
}

/* The float32 dot product of two 3-vectors in the order NumPy's x[0] * y[0] + x[1] * y[1] + x[2] * y[2] takes. */
static inline float ps_dot3(const float x[3], const float y[3])
{
    return (x[0] * y[0] + x[1] * y[1]) + x[2] * y[2];
}

/* Coordinate c of the point p0 + b1 e1 + b2 e2 on triangle k of a mesh table (rows p0, e1, e2, ... of `count`
 * columns, float32), in the operations of the NumPy expression (p0 + e1 b1) + e2 b2. */
static inline float ps_triangle_coordinate(const float *table, Py_ssize_t count, Py_ssize_t k, int c, float b1,
                                           float b2)
{
    return (table[c * count + k] + table[(3 + c) * count + k] * b1) + table[(6 + c) * count + k] * b2;
}

/* Segment directions and geometric factors of explicit paths (paths.c). */
PyObject *ps_path_geometry(PyObject *module, PyObject *args);
/* Densities of regenerating a run of a path's vertices, summed over the splits between its two walks (paths.c). */
PyObject *ps_split_densities(PyObject *module, PyObject *args);

/* Primary sample space of Metropolis chains: a proposal's numbers fetched, a proposal settled (primary.c). */
PyObject *ps_primary_fetch(PyObject *module, PyObject *args);
PyObject *ps_primary_settle(PyObject *module, PyObject *args);

/* Light samples on area lights, selected from a CDF, by area (lights.c). */
PyObject *ps_area_light_sample(PyObject *module, PyObject *args);

/* Receivers joined to a pinhole camera: direction, density, raster position, cosine (camera.c). */
PyObject *ps_pinhole_connect(PyObject *module, PyObject *args);

/* Path tracing's light samples (their MIS-weighted value, whether each is worth a shadow ray) and the weights of
 * the area lights its rays hit (direct.c). */
PyObject *ps_next_event_value(PyObject *module, PyObject *args);
PyObject *ps_area_emission(PyObject *module, PyObject *args);

/* Random walks leaving their vertices: throughput, roulette, the next ray's origin (scatter.c). */
PyObject *ps_scatter_step(PyObject *module, PyObject *args);
/* One vertex of a path tracer's walks, fused (pt_vertex.c), and the constants it shares with Python (0, or -1
 * with an exception). */
PyObject *ps_pt_vertex(PyObject *module, PyObject *args);
int ps_add_pt_vertex_constants(PyObject *module);
/* Light vertices joined to a pinhole camera, what they send toward it (lens_connect.c). */
PyObject *ps_lens_connect(PyObject *module, PyObject *args);
/* BDPT's joins of light and camera vertices, and of camera vertices and light samples: contributions and MIS
 * densities (join.c). */
PyObject *ps_join_vertices(PyObject *module, PyObject *args);
PyObject *ps_join_light_samples(PyObject *module, PyObject *args);
/* The pairs of light and camera vertices BDPT joins, in a range of a batch's pairs (join.c). */
PyObject *ps_join_pairs(PyObject *module, PyObject *args);

/* The columns `indices` of every per-lane array: a wavefront's compaction; and its inverse, parts of a wavefront
 * placed into one at given columns: subpaths flattened into lane order; the lanes of contributions worth weighting
 * (lanes.c). */
PyObject *ps_take_lanes(PyObject *module, PyObject *args);
PyObject *ps_place_lanes(PyObject *module, PyObject *args);
PyObject *ps_useful_lanes(PyObject *module, PyObject *args);

/* Cosine-weighted directions about unit normals (warp.c). */
PyObject *ps_cosine_about(PyObject *module, PyObject *args);

/* One sample added to a run of pixels' film moments; splats added to a pass's buffer (film.c). */
PyObject *ps_moments_add(PyObject *module, PyObject *args);
PyObject *ps_splat_add(PyObject *module, PyObject *args);

/* Shadow rays between surface points, returned (shadow.c; Accel.occluded_between traces them). */
PyObject *ps_shadow_rays(PyObject *module, PyObject *args, PyObject *kwargs);

/* Accel type (accel.c). */
extern PyTypeObject PsAccelType;
int ps_default_thread_count(void);

#endif
