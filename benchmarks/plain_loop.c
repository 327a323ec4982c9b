/*
 * Baseline for the traversal benchmark: a plain C loop over the same Embree
 * scene and rays, with no Python, no NumPy and no packing.  Built and loaded
 * by traversal.py (ctypes); it opens the same libembree4 the extension uses.
 *
 * plain_loop(lib_path, vertices, nv, indices, nt, rays, n, occlusion, repeats, packet)
 *   rays: n x 8 floats (org xyz, tnear, dir xyz, tfar)
 *   packet: 1 -> rtcIntersect1 per ray; 16 -> rtcIntersect16 on pre-packed SoA packets
 * returns the best wall-clock seconds of `repeats` runs (single thread), and the number of hits.
 */
#include <dlfcn.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "embree4_api.h"

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

#define SYM(name) *(void **)(&api.name) = dlsym(h, #name)

double plain_loop(const char *lib_path, const float *vertices, long nv, const uint32_t *indices, long nt,
                  const float *rays, long n, int occlusion, int repeats, int packet, long *hits_out)
{
    void *h = dlopen(lib_path, RTLD_NOW | RTLD_LOCAL);
    if (!h)
        return -1.0;
    EmbreeAPI api;
    SYM(rtcNewDevice); SYM(rtcReleaseDevice); SYM(rtcNewScene); SYM(rtcReleaseScene); SYM(rtcSetSceneFlags);
    SYM(rtcSetSceneBuildQuality); SYM(rtcCommitScene); SYM(rtcNewGeometry); SYM(rtcSetNewGeometryBuffer);
    SYM(rtcCommitGeometry); SYM(rtcAttachGeometry); SYM(rtcReleaseGeometry); SYM(rtcIntersect1);
    SYM(rtcIntersect16); SYM(rtcOccluded16);
    void (*occluded1)(RTCScene, struct RTCRay *, void *) = dlsym(h, "rtcOccluded1");

    RTCDevice dev = api.rtcNewDevice("");
    RTCScene scene = api.rtcNewScene(dev);
    api.rtcSetSceneFlags(scene, RTC_SCENE_FLAG_ROBUST);
    api.rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_HIGH);
    RTCGeometry g = api.rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
    memcpy(api.rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 12, nv), vertices, nv * 12);
    memcpy(api.rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 12, nt), indices, nt * 12);
    api.rtcCommitGeometry(g);
    api.rtcAttachGeometry(scene, g);
    api.rtcReleaseGeometry(g);
    api.rtcCommitScene(scene);

    long npackets = (n + 15) / 16;
    struct RTCRayHit16 *packets = NULL;
    int *valid = NULL;
    if (packet == 16) {
        packets = aligned_alloc(64, npackets * sizeof(struct RTCRayHit16));
        valid = malloc(npackets * 16 * sizeof(int));
    }
    double best = 1e300;
    long hits = 0;
    for (int r = 0; r < repeats; ++r) {
        if (packet == 16) { /* pack outside the timed region: the baseline pays nothing for layout */
            for (long i = 0; i < npackets * 16; ++i) {
                long p = i / 16, k = i % 16;
                struct RTCRayHit16 *rh = &packets[p];
                valid[i] = i < n ? -1 : 0;
                const float *ray = rays + 8 * (i < n ? i : 0);
                rh->ray.org_x[k] = ray[0]; rh->ray.org_y[k] = ray[1]; rh->ray.org_z[k] = ray[2];
                rh->ray.tnear[k] = ray[3];
                rh->ray.dir_x[k] = ray[4]; rh->ray.dir_y[k] = ray[5]; rh->ray.dir_z[k] = ray[6];
                rh->ray.tfar[k] = ray[7];
                rh->ray.time[k] = 0; rh->ray.mask[k] = 0xFFFFFFFFu; rh->ray.id[k] = 0; rh->ray.flags[k] = 0;
                rh->hit.geomID[k] = PS_RTC_INVALID_GEOMETRY_ID;
                rh->hit.instID[0][k] = PS_RTC_INVALID_GEOMETRY_ID;
            }
        }
        double t0 = now();
        hits = 0;
        if (packet == 16) {
            for (long p = 0; p < npackets; ++p) {
                if (occlusion) {
                    api.rtcOccluded16(valid + 16 * p, scene, &packets[p].ray, NULL);
                    for (int k = 0; k < 16; ++k)
                        hits += valid[16 * p + k] && packets[p].ray.tfar[k] < 0;
                } else {
                    api.rtcIntersect16(valid + 16 * p, scene, &packets[p], NULL);
                    for (int k = 0; k < 16; ++k)
                        hits += valid[16 * p + k] && packets[p].hit.geomID[k] != PS_RTC_INVALID_GEOMETRY_ID;
                }
            }
        } else {
            for (long i = 0; i < n; ++i) {
                const float *ray = rays + 8 * i;
                struct RTCRayHit rh;
                rh.ray.org_x = ray[0]; rh.ray.org_y = ray[1]; rh.ray.org_z = ray[2]; rh.ray.tnear = ray[3];
                rh.ray.dir_x = ray[4]; rh.ray.dir_y = ray[5]; rh.ray.dir_z = ray[6]; rh.ray.tfar = ray[7];
                rh.ray.time = 0; rh.ray.mask = 0xFFFFFFFFu; rh.ray.id = 0; rh.ray.flags = 0;
                rh.hit.geomID = PS_RTC_INVALID_GEOMETRY_ID;
                rh.hit.instID[0] = PS_RTC_INVALID_GEOMETRY_ID;
                if (occlusion) {
                    occluded1(scene, &rh.ray, NULL);
                    hits += rh.ray.tfar < 0;
                } else {
                    api.rtcIntersect1(scene, &rh, NULL);
                    hits += rh.hit.geomID != PS_RTC_INVALID_GEOMETRY_ID;
                }
            }
        }
        double dt = now() - t0;
        if (dt < best)
            best = dt;
    }
    free(packets);
    free(valid);
    api.rtcReleaseScene(scene);
    api.rtcReleaseDevice(dev);
    *hits_out = hits;
    return best;
}
