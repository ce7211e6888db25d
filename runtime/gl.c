/* Loading the GL entry points (gl.h). */
#include "runtime/gl.h"

#include <string.h>

int tw_gl_load(struct tw_gl *gl, tw_gl_get_proc_fn get_proc, const struct tw_log *log)
{
    if (!get_proc) {
        tw_log_printf(log, TW_LOG_ERROR, "no GL loader given (settings.get_proc is NULL)");
        return TW_ERR_INVALID;
    }
    memset(gl, 0, sizeof(*gl));
    /* A data pointer to function pointer conversion is what every GL loader
     * does; POSIX guarantees it works. */
#define TW_GL_LOAD(type, name) \
    do { \
        void *p = get_proc("gl" #name); \
        if (!p) { \
            tw_log_printf(log, TW_LOG_ERROR, "OpenGL entry point gl%s is missing", #name); \
            return TW_ERR_GL; \
        } \
        memcpy(&gl->name, &p, sizeof(p)); \
    } while (0);
    TW_GL_FUNCTIONS(TW_GL_LOAD)
#undef TW_GL_LOAD
#define TW_GL_LOAD_OPTIONAL(type, name) \
    do { \
        void *p = get_proc("gl" #name); \
        memcpy(&gl->name, &p, sizeof(p)); \
    } while (0);
    TW_GL_OPTIONAL_FUNCTIONS(TW_GL_LOAD_OPTIONAL)
#undef TW_GL_LOAD_OPTIONAL
    return TW_OK;
}
