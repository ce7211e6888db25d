/*
 * context: a headless OpenGL context for tileworld, a library of its own
 * (tileworld-headless) so that a program with a window (GLFW, libGL) never
 * loads a second set of gl* entry points. Two kinds:
 *  - EGL (libEGL.so.1, through glvnd on a GPU): the device platform
 *    (EGL_EXT_device_enumeration + EGL_EXT_platform_device), a hardware
 *    device preferred to a software one, or Mesa's surfaceless platform
 *    (llvmpipe);
 *  - OSMesa (libOSMesa.so.8, Mesa's llvmpipe; removed from Mesa 25.1, kept
 *    while distributions ship it).
 * Both libraries are loaded at run time, when asked for: a machine needs
 * only the one it uses. A host with its own GL context needs neither: it
 * passes its loader as tw_world_settings.get_proc.
 *
 * The context renders into memory (the library draws into its own FBO); it
 * is the highest core profile the driver gives, 4.6 down to 3.3, without the
 * debug flag.
 *
 * Threading: a context is current on one thread at a time; it is made current
 * on the thread that creates it, and moves to another thread by
 * tw_context_release() there and tw_context_make_current() on the other.
 * Every call taking a NULL context returns TW_ERR_INVALID (or does
 * nothing).
 */
#ifndef TW_CONTEXT_H
#define TW_CONTEXT_H

#include <stdbool.h>
#include <stdint.h>

#include "tileworld/runtime.h"
#include "tileworld/tiles.h"

#ifdef __cplusplus
extern "C" {
#endif

/* A headless OpenGL context rendering into memory. */
struct tw_context;

/* Which way to a context. */
enum tw_context_api {
    TW_CONTEXT_AUTO = 0,  /* an EGL hardware device if there is one, else OSMesa, else
                             EGL's software ways (Mesa's surfaceless platform, then a
                             software device) */
    TW_CONTEXT_EGL,       /* EGL only: a hardware device, then Mesa's surfaceless
                             platform, then a software device */
    TW_CONTEXT_OSMESA,    /* OSMesa only */
};

/* Settings of tw_context_create(); zero-initialised fields take the defaults. */
struct tw_context_settings {
    uint32_t width, height;    /* framebuffer, each in [1, 16384] */
    enum tw_context_api api;   /* default TW_CONTEXT_AUTO */
    bool pick_device;          /* EGL: use the device at index `device` of
                                  eglQueryDevicesEXT's list and no other (a software
                                  device too); with TW_CONTEXT_AUTO it implies EGL */
    uint32_t device;           /* that index, when pick_device */
    struct tw_log log;         /* where failures are told; copied */
};

/* What a context is, for reports. The strings belong to the context and live
 * as long as it does. */
struct tw_context_info {
    const char *kind;          /* "egl-device", "egl-surfaceless" or "osmesa" */
    const char *vendor;        /* GL_VENDOR */
    const char *renderer;      /* GL_RENDERER */
    const char *version;       /* GL_VERSION */
    const char *device;        /* egl-device: the EGL device's DRM node or extensions;
                                  "" otherwise */
    int32_t device_index;      /* egl-device: its index; -1 otherwise */
    uint32_t gl_major, gl_minor; /* the core profile made */
    bool software;             /* a CPU rasteriser (llvmpipe, softpipe, swrast): "GPU"
                                  time is then CPU work */
};

/* Creates a context as s says and makes it current on the calling thread.
 * On failure *out is untouched and one line naming what was tried and why
 * each way failed goes to s->log at TW_LOG_ERROR (TW_ERR_GL: no context could
 * be made; TW_ERR_INVALID: bad settings). The caller owns *out and frees it
 * with tw_context_destroy(). */
int tw_context_create(const struct tw_context_settings *s, struct tw_context **out);
/* tw_context_create() with api TW_CONTEXT_AUTO and no device picked. */
int tw_context_create_headless(uint32_t width, uint32_t height,
                               const struct tw_log *log, struct tw_context **out);
/* Fills *out with what the context is (see struct tw_context_info). */
void tw_context_describe(const struct tw_context *ctx, struct tw_context_info *out);
/* "auto", "egl", "osmesa"; NULL for a value out of range. */
const char *tw_context_api_name(enum tw_context_api api);
/* The loader of the context's GL entry points (for tw_world_settings.get_proc). */
tw_gl_get_proc_fn tw_context_get_proc(const struct tw_context *ctx);
/* Makes the context current on the calling thread (after another context
 * was, or to move it to this thread once released where it was). */
int tw_context_make_current(struct tw_context *ctx);
/* Releases the context from the calling thread, if it is current there
 * (else does nothing), so that another thread can make it current: a
 * context is current on one thread at a time, and a world is used where
 * its context is current. */
int tw_context_release(struct tw_context *ctx);
/* Frees the context; accepts NULL. Destroy every world that uses it first. */
void tw_context_destroy(struct tw_context *ctx);

#ifdef __cplusplus
}
#endif

#endif
