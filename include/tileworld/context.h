/*
 * context: a headless OpenGL context for tileworld (OSMesa, Mesa's llvmpipe),
 * a library of its own (tileworld-headless) so that a program with a window
 * (GLFW, libGL) links no libOSMesa and the two sets of gl* symbols never meet.
 * A host with its own GL context does not need it: it passes its loader as
 * tw_world_settings.get_proc.
 *
 * Threading: a context is current on one thread at a time; it is made current
 * on the thread that creates it.
 */
#ifndef TW_CONTEXT_H
#define TW_CONTEXT_H

#include <stdint.h>

#include "tileworld/runtime.h"
#include "tileworld/tiles.h"

#ifdef __cplusplus
extern "C" {
#endif

/* A headless OpenGL context rendering into memory. */
struct tw_context;

/* Creates a 3.3+ core context with a width x height framebuffer (each in
 * [1, 16384]) and makes it current on the calling thread. log is copied (may
 * be NULL). The caller owns *out and frees it with tw_context_destroy(). */
int tw_context_create_headless(uint32_t width, uint32_t height,
                               const struct tw_log *log, struct tw_context **out);
/* The loader of the context's GL entry points (for tw_world_settings.get_proc). */
tw_gl_get_proc_fn tw_context_get_proc(const struct tw_context *ctx);
/* Makes the context current again (after another context was). */
int tw_context_make_current(struct tw_context *ctx);
/* Frees the context; accepts NULL. Destroy every world that uses it first. */
void tw_context_destroy(struct tw_context *ctx);

#ifdef __cplusplus
}
#endif

#endif
