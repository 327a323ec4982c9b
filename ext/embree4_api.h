/*
 * The subset of the Embree 4 C API that pathspace uses, declared by hand.
 *
 * The `embreex` wheel bundles libembree4 but no headers, so the types, enum
 * values and struct layouts below restate those of Embree 4.4's public headers
 * (include/embree4/rtcore_*.h).  The library is loaded at run time with dlopen
 * and the functions are reached through the pointer table `EmbreeAPI`.
 *
 * Layout facts that matter:
 *   - RTC_MAX_INSTANCE_LEVEL_COUNT is 1 in the bundled build;
 *   - since Embree 4.3 the hit record carries instPrimID[] after instID[]
 *     (the bundled single-ray RTCRayHit is 96 bytes); the 16-wide hit packet
 *     therefore has 9 arrays of 16 words.
 */
#ifndef PATHSPACE_EMBREE4_API_H
#define PATHSPACE_EMBREE4_API_H

#include <stddef.h>

#define PS_RTC_INVALID_GEOMETRY_ID ((unsigned int)-1)

typedef struct RTCDeviceTy *RTCDevice;
typedef struct RTCSceneTy *RTCScene;
typedef struct RTCGeometryTy *RTCGeometry;

enum RTCError {
    RTC_ERROR_NONE = 0,
    RTC_ERROR_UNKNOWN = 1,
    RTC_ERROR_INVALID_ARGUMENT = 2,
    RTC_ERROR_INVALID_OPERATION = 3,
    RTC_ERROR_OUT_OF_MEMORY = 4,
    RTC_ERROR_UNSUPPORTED_CPU = 5,
    RTC_ERROR_CANCELLED = 6,
};

enum RTCGeometryType { RTC_GEOMETRY_TYPE_TRIANGLE = 0 };
enum RTCBufferType { RTC_BUFFER_TYPE_INDEX = 0, RTC_BUFFER_TYPE_VERTEX = 1 };
enum RTCFormat { RTC_FORMAT_UINT3 = 0x5003, RTC_FORMAT_FLOAT3 = 0x9003 };
enum RTCSceneFlags { RTC_SCENE_FLAG_NONE = 0, RTC_SCENE_FLAG_ROBUST = (1 << 2) };
enum RTCBuildQuality { RTC_BUILD_QUALITY_MEDIUM = 1, RTC_BUILD_QUALITY_HIGH = 2 };

typedef void (*RTCErrorFunction)(void *user_ptr, enum RTCError code, const char *str);

/* 16-wide ray packet, structure of arrays (rtcore_ray.h). */
struct __attribute__((aligned(64))) RTCRay16 {
    float org_x[16], org_y[16], org_z[16], tnear[16];
    float dir_x[16], dir_y[16], dir_z[16], time[16];
    float tfar[16];
    unsigned int mask[16], id[16], flags[16];
};

struct __attribute__((aligned(64))) RTCHit16 {
    float Ng_x[16], Ng_y[16], Ng_z[16];
    float u[16], v[16];
    unsigned int primID[16], geomID[16];
    unsigned int instID[1][16];
    unsigned int instPrimID[1][16];
};

struct RTCRayHit16 {
    struct RTCRay16 ray;
    struct RTCHit16 hit;
};

/* Single-ray structures. */
struct __attribute__((aligned(16))) RTCRay {
    float org_x, org_y, org_z, tnear;
    float dir_x, dir_y, dir_z, time;
    float tfar;
    unsigned int mask, id, flags;
};

struct __attribute__((aligned(16))) RTCHit {
    float Ng_x, Ng_y, Ng_z;
    float u, v;
    unsigned int primID, geomID;
    unsigned int instID[1];
    unsigned int instPrimID[1];
};

struct RTCRayHit {
    struct RTCRay ray;
    struct RTCHit hit;
};

/* Function table filled by dlsym (the extension loads all but rtcIntersect1 and rtcOccluded1,
 * which only the benchmark's plain loop uses).  Argument structs are passed as NULL (Embree then
 * uses its defaults: incoherent rays, all features). */
typedef struct EmbreeAPI {
    RTCDevice (*rtcNewDevice)(const char *config);
    void (*rtcReleaseDevice)(RTCDevice device);
    enum RTCError (*rtcGetDeviceError)(RTCDevice device);
    void (*rtcSetDeviceErrorFunction)(RTCDevice device, RTCErrorFunction fn, void *user_ptr);
    RTCScene (*rtcNewScene)(RTCDevice device);
    void (*rtcReleaseScene)(RTCScene scene);
    void (*rtcSetSceneFlags)(RTCScene scene, enum RTCSceneFlags flags);
    void (*rtcSetSceneBuildQuality)(RTCScene scene, enum RTCBuildQuality quality);
    void (*rtcCommitScene)(RTCScene scene);
    RTCGeometry (*rtcNewGeometry)(RTCDevice device, enum RTCGeometryType type);
    void *(*rtcSetNewGeometryBuffer)(RTCGeometry geometry, enum RTCBufferType type, unsigned int slot,
                                     enum RTCFormat format, size_t byte_stride, size_t item_count);
    void (*rtcCommitGeometry)(RTCGeometry geometry);
    unsigned int (*rtcAttachGeometry)(RTCScene scene, RTCGeometry geometry);
    void (*rtcReleaseGeometry)(RTCGeometry geometry);
    void (*rtcIntersect1)(RTCScene scene, struct RTCRayHit *rayhit, void *args);
    void (*rtcIntersect16)(const int *valid, RTCScene scene, struct RTCRayHit16 *rayhit, void *args);
    void (*rtcOccluded1)(RTCScene scene, struct RTCRay *ray, void *args);
    void (*rtcOccluded16)(const int *valid, RTCScene scene, struct RTCRay16 *ray, void *args);
} EmbreeAPI;

#endif
