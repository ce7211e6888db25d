/* The headless OSMesa context (context.h). */
#include "tileworld/context.h"

#include <GL/osmesa.h>
#include <stdlib.h>
#include <string.h>

struct tw_context {
    OSMesaContext osmesa;
    void *buffer;          /* OSMesa's default framebuffer; we render to an FBO */
    uint32_t width, height;
    struct tw_log log;
};

static void *osmesa_get_proc(const char *name)
{
    void *p;
    OSMESAproc f = OSMesaGetProcAddress(name);
    memcpy(&p, &f, sizeof(p));
    return p;
}

int tw_context_create_headless(uint32_t width, uint32_t height, const struct tw_log *log,
                               struct tw_context **out)
{
    if (!out || width == 0 || height == 0 || width > 16384 || height > 16384)
        return TW_ERR_INVALID;
    struct tw_context *c = calloc(1, sizeof(*c));
    if (!c)
        return TW_ERR_NOMEM;
    if (log)
        c->log = *log;
    c->width = width;
    c->height = height;
    const int attribs[] = {
        OSMESA_FORMAT, OSMESA_RGBA,
        OSMESA_DEPTH_BITS, 24,
        OSMESA_PROFILE, OSMESA_CORE_PROFILE,
        OSMESA_CONTEXT_MAJOR_VERSION, 3,
        OSMESA_CONTEXT_MINOR_VERSION, 3,
        0,
    };
    c->osmesa = OSMesaCreateContextAttribs(attribs, NULL);
    if (!c->osmesa) {
        tw_log_printf(&c->log, TW_LOG_ERROR,
                      "OSMesa could not create an OpenGL 3.3 core context");
        free(c);
        return TW_ERR_GL;
    }
    c->buffer = calloc((size_t)width * height, 4);
    if (!c->buffer) {
        tw_context_destroy(c);
        return TW_ERR_NOMEM;
    }
    int err = tw_context_make_current(c);
    if (err) {
        tw_context_destroy(c);
        return err;
    }
    *out = c;
    return TW_OK;
}

tw_gl_get_proc_fn tw_context_get_proc(const struct tw_context *ctx)
{
    (void)ctx;
    return osmesa_get_proc;
}

int tw_context_make_current(struct tw_context *c)
{
    if (!OSMesaMakeCurrent(c->osmesa, c->buffer, GL_UNSIGNED_BYTE, (GLsizei)c->width,
                           (GLsizei)c->height)) {
        tw_log_printf(&c->log, TW_LOG_ERROR, "OSMesaMakeCurrent failed");
        return TW_ERR_GL;
    }
    return TW_OK;
}

void tw_context_destroy(struct tw_context *c)
{
    if (!c)
        return;
    if (c->osmesa)
        OSMesaDestroyContext(c->osmesa);
    free(c->buffer);
    free(c);
}
