/*
 * GL programs: compiling and linking GLSL through a struct tw_gl, and the
 * renderer's own programs with their uniform locations. Private to
 * runtime/ and the programs in tools/ (the viewer links its overlay with
 * tw_programs_link).
 */
#ifndef TW_RUNTIME_PROGRAMS_H
#define TW_RUNTIME_PROGRAMS_H

#include <stdbool.h>

#include "runtime/gl.h"
#include "tileworld/tiles.h"

/* Compiles the shaders of vs, gs (NULL: none) and fs (GLSL sources) and
 * links them into a program: its name, or 0 with the reason in log. A
 * failure for the driver's memory sets *out_of_memory and is logged only
 * while it was false, so that a set of programs says it once; any other
 * failure is a bug of the sources. The context must be current; the
 * sources are only read during the call. */
GLuint tw_programs_link(const struct tw_gl *gl, const struct tw_log *log, const char *vs,
                        const char *gs, const char *fs, bool *out_of_memory);

/* The same for a compute shader (GL 4.3). */
GLuint tw_programs_link_compute(const struct tw_gl *gl, const struct tw_log *log,
                                const char *cs, bool *out_of_memory);

/* The renderer's programs: the scene (lit, fogged clusters), the query
 * boxes (one instance per box, depth only), the oracle's object IDs (the
 * scene's vertex stage), and the debug boxes as edges (screen-space quads)
 * or as translucent faces. Each program's uniforms by name. */
struct tw_programs {
    struct {
        GLuint program;
        GLint view_proj, eye, fog;   /* per draw: runtime/draws.c's records */
    } scene;
    struct {
        GLuint program;
        GLint view_proj;
    } query;
    struct {
        GLuint program;
        GLint view_proj;             /* the id: a record's offset.w */
    } id;
    struct {
        GLuint program;
        GLint view_proj, min, max, color, viewport;
    } line;
    struct {
        GLuint program;
        GLint view_proj, min, max, color;
    } fill;
};

/* Links every program of p (zeroed first) and looks up its uniforms;
 * TW_ERR_NOMEM when the driver ran out of memory, TW_ERR_GL for any other
 * failure (logged). log is only used during the call. The context must be
 * current; tw_programs_finish() frees what was made, on failure too. */
int tw_programs_init(struct tw_programs *p, const struct tw_gl *gl, const struct tw_log *log);
/* Deletes the programs of p. The context must be current. */
void tw_programs_finish(struct tw_programs *p, const struct tw_gl *gl);

#endif
