/*
 * Run-time loading of the Embree 4 library bundled in the embreex wheel.
 *
 * The library is opened with RTLD_LOCAL and every symbol is looked up on that
 * handle, so that another Embree loaded globally (a system Embree 3, say)
 * cannot capture the names.  The Python side finds the file through
 * importlib.metadata and passes its path to load_embree().  The handle stays
 * open for the life of the process.
 */
#include "native.h"

#include <dlfcn.h>
#include <pthread.h>
#include <string.h>

EmbreeAPI ps_embree;
RTCDevice ps_embree_device = NULL;
static char embree_path[4096];
static char last_error[1024];
static pthread_mutex_t last_error_lock = PTHREAD_MUTEX_INITIALIZER;

/* Embree may report errors from its own worker threads. */
static void record_error(void *user_ptr, enum RTCError code, const char *str)
{
    (void)user_ptr;
    pthread_mutex_lock(&last_error_lock);
    snprintf(last_error, sizeof(last_error), "Embree error %d: %s", (int)code, str ? str : "(no message)");
    pthread_mutex_unlock(&last_error_lock);
}

const char *ps_embree_last_error(void) { return last_error[0] ? last_error : "unknown Embree error"; }

void ps_embree_clear_error(void) { last_error[0] = '\0'; }

int ps_require_embree(void)
{
    if (ps_embree_device == NULL) {
        PyErr_SetString(PyExc_RuntimeError,
                        "Embree is not loaded: call pathspace._native.load_embree(path) first "
                        "(pathspace.accel does this with the library bundled in the embreex wheel)");
        return -1;
    }
    return 0;
}

#define LOAD_SYMBOL(name)                                                                       \
    do {                                                                                        \
        *(void **)(&api.name) = dlsym(handle, #name);                                           \
        if (api.name == NULL) {                                                                 \
            PyErr_Format(PyExc_ImportError, "the Embree library %s has no symbol %s: it is not " \
                         "Embree 4 (embreex >= 4 bundles Embree 4)", path, #name);               \
            dlclose(handle);                                                                    \
            return NULL;                                                                        \
        }                                                                                       \
    } while (0)

PyObject *ps_load_embree(PyObject *module, PyObject *args)
{
    (void)module;
    const char *path;
    const char *config = "";
    if (!PyArg_ParseTuple(args, "s|s:load_embree", &path, &config))
        return NULL;
    if (ps_embree_device != NULL) {
        if (strcmp(path, embree_path) != 0) {
            PyErr_Format(PyExc_RuntimeError, "Embree is already loaded from %s; cannot switch to %s",
                         embree_path, path);
            return NULL;
        }
        Py_RETURN_NONE;
    }
    void *handle = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (handle == NULL) {
        const char *why = dlerror();
        PyErr_Format(PyExc_ImportError, "cannot load the Embree 4 library %s: %s", path,
                     why ? why : "unknown dlopen error");
        return NULL;
    }
    EmbreeAPI api;
    LOAD_SYMBOL(rtcNewDevice);
    LOAD_SYMBOL(rtcReleaseDevice);
    LOAD_SYMBOL(rtcGetDeviceError);
    LOAD_SYMBOL(rtcSetDeviceErrorFunction);
    LOAD_SYMBOL(rtcNewScene);
    LOAD_SYMBOL(rtcReleaseScene);
    LOAD_SYMBOL(rtcSetSceneFlags);
    LOAD_SYMBOL(rtcSetSceneBuildQuality);
    LOAD_SYMBOL(rtcCommitScene);
    LOAD_SYMBOL(rtcNewGeometry);
    LOAD_SYMBOL(rtcSetNewGeometryBuffer);
    LOAD_SYMBOL(rtcCommitGeometry);
    LOAD_SYMBOL(rtcAttachGeometry);
    LOAD_SYMBOL(rtcReleaseGeometry);
    LOAD_SYMBOL(rtcIntersect16);
    LOAD_SYMBOL(rtcOccluded16);

    RTCDevice device = api.rtcNewDevice(config);
    if (device == NULL) {
        PyErr_Format(PyExc_RuntimeError, "Embree (%s) could not create a device with config \"%s\" "
                     "(unsupported CPU or invalid configuration)", path, config);
        dlclose(handle);
        return NULL;
    }
    api.rtcSetDeviceErrorFunction(device, record_error, NULL);
    ps_embree = api;
    ps_embree_device = device;
    snprintf(embree_path, sizeof(embree_path), "%s", path);
    Py_RETURN_NONE;
}

PyObject *ps_embree_loaded(PyObject *module, PyObject *unused)
{
    (void)module;
    (void)unused;
    if (ps_embree_device == NULL)
        Py_RETURN_NONE;
    return PyUnicode_FromString(embree_path);
}
