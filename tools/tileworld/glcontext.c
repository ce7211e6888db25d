/* --gl, --gpu and TW_GPU (glcontext.h). */
#include "tools/tileworld/glcontext.h"

#include <stdlib.h>
#include <string.h>

const char tw_gl_usage[] =
    "--gl auto|egl|osmesa  the headless OpenGL context: auto (default) an EGL GPU device if\n"
    "                      there is one, else OSMesa; egl: a GPU device, else Mesa's\n"
    "                      surfaceless platform, else a software device; osmesa: OSMesa only\n"
    "--gpu N               the EGL device of that index and no other (implies EGL; default:\n"
    "                      the environment's TW_GPU, else the first GPU that works)\n";

static uint32_t device_index(const char *place, const char *v)
{
    return (uint32_t)tw_cli_u64("tileworld", place, v, 0, 63);
}

bool tw_gl_option(struct tw_context_settings *s, int opt, const char *name, const char *v)
{
    switch (opt) {
    case TW_GL_OPT_API:
        if (strcmp(v, "auto") == 0)
            s->api = TW_CONTEXT_AUTO;
        else if (strcmp(v, "egl") == 0)
            s->api = TW_CONTEXT_EGL;
        else if (strcmp(v, "osmesa") == 0)
            s->api = TW_CONTEXT_OSMESA;
        else
            tw_cli_fail("tileworld", name, "'%s' is not auto, egl or osmesa", v);
        return true;
    case TW_GL_OPT_GPU:
        s->pick_device = true;
        s->device = device_index(name, v);
        return true;
    default:
        return false;
    }
}

int tw_gl_context_create(const struct tw_context_settings *given, uint32_t width,
                         uint32_t height, const struct tw_log *log, struct tw_context **out)
{
    struct tw_context_settings s = *given;
    s.width = width;
    s.height = height;
    s.log = *log;
    const char *env = getenv("TW_GPU");
    if (!s.pick_device && env && *env) {
        s.pick_device = true;
        s.device = device_index("TW_GPU", env);
    }
    if (s.pick_device && s.api == TW_CONTEXT_OSMESA)
        tw_cli_fail("tileworld", "--gl", "osmesa has no devices: --gpu (or TW_GPU) asks for an "
                    "EGL device");
    return tw_context_create(&s, out);
}
