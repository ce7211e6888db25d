/* The renderer (renderer.h): creation, the offscreen framebuffer, the
 * frame, and the host's GL state saved and restored around the library's
 * calls. Its other parts: gpu-store.c, query-backend.c, id-pass.c, and
 * the debug drawing in debug.c. */
#include "runtime/renderer-private.h"
#include "tiles/tiles-internal.h"

#include <stdlib.h>
#include <string.h>
#include <time.h>

double tw_renderer_cpu_ms(void)
{
    struct timespec t;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return (double)t.tv_sec * 1e3 + (double)t.tv_nsec * 1e-6;
}

static void upload_box(struct tw_renderer *r)
{
    const struct tw_gl *gl = &r->gl;
    static const float corners[8 * 3] = {
        0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0, 0, 0, 1, 1, 0, 1, 0, 1, 1, 1, 1, 1,
    };
    /* 36 face indices (wound inwards: front faces are the inside), then
     * 24 edge indices for debug drawing. */
    static const uint8_t faces[36 + 24] = {
        0, 1, 3, 0, 3, 2, 4, 6, 7, 4, 7, 5, 0, 2, 6, 0, 6, 4,
        1, 5, 7, 1, 7, 3, 0, 4, 5, 0, 5, 1, 2, 3, 7, 2, 7, 6,
        0, 1, 1, 3, 3, 2, 2, 0, 4, 5, 5, 7, 7, 6, 6, 4, 0, 4, 1, 5, 3, 7, 2, 6,
    };
    gl->GenVertexArrays(1, &r->box_vao);
    gl->BindVertexArray(r->box_vao);
    gl->GenBuffers(1, &r->box_vbo);
    gl->BindBuffer(GL_ARRAY_BUFFER, r->box_vbo);
    gl->BufferData(GL_ARRAY_BUFFER, sizeof(corners), corners, GL_STATIC_DRAW);
    gl->GenBuffers(1, &r->box_ibo);
    gl->BindBuffer(GL_ELEMENT_ARRAY_BUFFER, r->box_ibo);
    gl->BufferData(GL_ELEMENT_ARRAY_BUFFER, sizeof(faces), faces, GL_STATIC_DRAW);
    gl->EnableVertexAttribArray(0);
    gl->VertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 12, (const void *)0);
    gl->BindVertexArray(0);
}

/* Most often the driver's memory (a software rasteriser under an
 * address-space limit). */
int tw_renderer_framebuffer_failed(struct tw_renderer *r, const char *what)
{
    if (r->gl.GetError() == GL_OUT_OF_MEMORY) {
        tw_log_printf(&r->log, TW_LOG_ERROR, "the OpenGL driver is out of memory for the %s "
                      "(%u x %u pixels)", what, r->width, r->height);
        return TW_ERR_NOMEM;
    }
    tw_log_printf(&r->log, TW_LOG_ERROR, "the OpenGL driver cannot make the offscreen %s "
                  "(%u x %u pixels)", what, r->width, r->height);
    return TW_ERR_GL;
}

static int create_framebuffer(struct tw_renderer *r)
{
    const struct tw_gl *gl = &r->gl;
    gl->GenFramebuffers(1, &r->fbo);
    gl->BindFramebuffer(GL_FRAMEBUFFER, r->fbo);
    gl->GenRenderbuffers(1, &r->color_rb);
    gl->BindRenderbuffer(GL_RENDERBUFFER, r->color_rb);
    gl->RenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, (GLsizei)r->width, (GLsizei)r->height);
    gl->FramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER,
                                r->color_rb);
    const GLenum depth_format = r->reversed_z ? GL_DEPTH_COMPONENT32F : GL_DEPTH_COMPONENT24;
    if (r->has_compute) {
        /* A texture, which the GPU HZB's compute passes read. */
        gl->GenTextures(1, &r->depth_texture);
        gl->BindTexture(GL_TEXTURE_2D, r->depth_texture);
        gl->TexStorage2D(GL_TEXTURE_2D, 1, depth_format, (GLsizei)r->width, (GLsizei)r->height);
        gl->TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
        gl->TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
        gl->TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_COMPARE_MODE, GL_NONE);
        gl->BindTexture(GL_TEXTURE_2D, 0);
        gl->FramebufferTexture2D(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_TEXTURE_2D,
                                 r->depth_texture, 0);
    } else {
        gl->GenRenderbuffers(1, &r->depth_rb);
        gl->BindRenderbuffer(GL_RENDERBUFFER, r->depth_rb);
        gl->RenderbufferStorage(GL_RENDERBUFFER, depth_format, (GLsizei)r->width,
                                (GLsizei)r->height);
        gl->FramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER,
                                    r->depth_rb);
    }
    if (gl->CheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
        return tw_renderer_framebuffer_failed(r, "image");
    const int err = tw_renderer_id_init(r, depth_format);
    if (err)
        return err;
    gl->BindFramebuffer(GL_FRAMEBUFFER, r->fbo);
    return TW_OK;
}

static bool has_extension(const struct tw_gl *gl, const char *name)
{
    GLint count = 0;
    gl->GetIntegerv(GL_NUM_EXTENSIONS, &count);
    for (GLint k = 0; k < count; k++) {
        const GLubyte *e = gl->GetStringi(GL_EXTENSIONS, (GLuint)k);
        if (e && strcmp((const char *)e, name) == 0)
            return true;
    }
    return false;
}

int tw_renderer_create(uint32_t width, uint32_t height, tw_gl_get_proc_fn get_proc,
                       const struct tw_log *log, struct tw_renderer **out)
{
    struct tw_renderer *r = calloc(1, sizeof(*r));
    if (!r)
        return TW_ERR_NOMEM;
    if (log)
        r->log = *log;
    r->query_target = GL_ANY_SAMPLES_PASSED;
    r->width = width;
    r->height = height;
    int err = tw_gl_load(&r->gl, get_proc, &r->log);
    if (err)
        goto fail;
    r->gl_loaded = true;
    const struct tw_gl *gl = &r->gl;
    if (!gl->GetString(GL_VERSION)) {
        /* Without a current context every GL call is a no-op answering 0. */
        tw_log_printf(&r->log, TW_LOG_ERROR, "no OpenGL context is current on the calling "
                      "thread: make the world's context current before creating it");
        r->gl_loaded = false;
        err = TW_ERR_STATE;
        goto fail;
    }
    {
        /* An error left by the host's own calls is not ours (cleared); one
         * of memory is the context's: nothing drawn with it can be trusted. */
        const GLenum pending = gl->GetError();
        if (pending == GL_OUT_OF_MEMORY) {
            tw_log_printf(&r->log, TW_LOG_ERROR, "the OpenGL driver ran out of memory before "
                          "the world was set up");
            err = TW_ERR_NOMEM;
            goto fail;
        }
        if (pending != GL_NO_ERROR)
            tw_log_printf(&r->log, TW_LOG_DEBUG, "OpenGL error 0x%x was pending when the world "
                          "was set up (left by earlier calls): cleared", pending);
    }
    GLint major = 0, minor = 0;
    gl->GetIntegerv(GL_MAJOR_VERSION, &major);
    gl->GetIntegerv(GL_MINOR_VERSION, &minor);
    if (major * 10 + minor < 33) {
        tw_log_printf(&r->log, TW_LOG_ERROR, "OpenGL %d.%d is too old: 3.3 core is needed",
                      major, minor);
        err = TW_ERR_GL;
        goto fail;
    }
    r->software = tw_renderer_name_is_software((const char *)gl->GetString(GL_RENDERER));
    /* Reversed depth needs [0, 1] clip depth: core since 4.5. */
    r->has_clip_control = gl->ClipControl &&
                          (major * 10 + minor >= 45 || has_extension(gl, "GL_ARB_clip_control"));
    r->reversed_z = r->has_clip_control;
    /* Compute shaders, shader storage and fences: core since 4.3. */
    r->has_compute = major * 10 + minor >= 43 && gl->DispatchCompute && gl->MemoryBarrier &&
                     gl->BindBufferRange && gl->BindBufferBase &&
                     gl->TexStorage2D && gl->FenceSync && gl->ClientWaitSync && gl->DeleteSync &&
                     gl->GetBufferSubData && gl->CopyBufferSubData && gl->ClearBufferData && gl->GetIntegeri_v &&
                     gl->GetInteger64i_v && gl->Uniform1i && gl->Uniform1iv && gl->Uniform1f && gl->Uniform2i &&
                     gl->GenTextures && gl->DeleteTextures && gl->BindTexture &&
                     gl->ActiveTexture && gl->TexParameteri && gl->FramebufferTexture2D &&
                     gl->MultiDrawElementsIndirect;
    tw_renderer_enter(r);
    if (!r->reversed_z) {
        tw_log_printf(&r->log, TW_LOG_WARN,
                      "OpenGL %d.%d has no glClipControl: standard 24-bit depth instead of "
                      "reversed float depth (less precision far away)", major, minor);
    }
    err = tw_programs_init(&r->programs, gl, &r->log);
    if (err)
        goto fail;
    upload_box(r);
    if (gl->FenceSync && gl->IsSync && gl->DeleteSync)
        r->token = gl->FenceSync(GL_SYNC_GPU_COMMANDS_COMPLETE, 0);
    tw_renderer_queries_init(r);
    /* Draws go out as one multi-draw of indirect commands where the
     * context has them (core since 4.3, base instances since 4.2). */
    tw_renderer_draws_init(r, gl->MultiDrawElementsIndirect && major * 10 + minor >= 43);
    if (r->has_compute && !tw_renderer_gpu_hzb_init(r)) {
        tw_gl_compute_state_leave(gl, &r->host_compute);
        r->has_compute = false;     /* the depth stays a renderbuffer */
    }
    err = create_framebuffer(r);
    if (err)
        goto fail;
    GLenum gl_err = gl->GetError();
    if (gl_err == GL_OUT_OF_MEMORY) {
        tw_log_printf(&r->log, TW_LOG_ERROR, "the OpenGL driver ran out of memory while the "
                      "world was set up");
        err = TW_ERR_NOMEM;
        goto fail;
    }
    if (gl_err != GL_NO_ERROR) {
        tw_log_printf(&r->log, TW_LOG_ERROR, "OpenGL error 0x%x while the world was set up",
                      gl_err);
        err = TW_ERR_GL;
        goto fail;
    }
    tw_renderer_leave(r);
    *out = r;
    return TW_OK;
fail:
    if (r->entered)
        tw_renderer_leave(r);
    tw_renderer_destroy(r);
    return err;
}

uint32_t tw_renderer_depth_format(const struct tw_renderer *r)
{
    return r->reversed_z ? GL_DEPTH_COMPONENT32F : GL_DEPTH_COMPONENT24;
}

int tw_renderer_blit_depth(struct tw_renderer *r, uint32_t target)
{
    const struct tw_gl *gl = &r->gl;
    /* An error the host's calls left is not this call's. */
    for (int k = 0; k < 16 && gl->GetError() != GL_NO_ERROR; k++)
        ;
    gl->BindFramebuffer(GL_READ_FRAMEBUFFER, r->fbo);
    gl->BindFramebuffer(GL_DRAW_FRAMEBUFFER, target);
    gl->BlitFramebuffer(0, 0, (GLint)r->width, (GLint)r->height, 0, 0, (GLint)r->width,
                        (GLint)r->height, GL_DEPTH_BUFFER_BIT, GL_NEAREST);
    const GLenum err = gl->GetError();
    if (err == GL_NO_ERROR)
        return TW_OK;
    tw_log_printf(&r->log, TW_LOG_ERROR, "cannot copy the depth into framebuffer %u: OpenGL "
                  "error 0x%x (its depth attachment must be %s, the world's, and complete)",
                  target, err, r->reversed_z ? "GL_DEPTH_COMPONENT32F" : "GL_DEPTH_COMPONENT24");
    return TW_ERR_GL;
}

bool tw_renderer_current(const struct tw_renderer *r)
{
    if (!r->gl_loaded)
        return false;
    const struct tw_gl *gl = &r->gl;
    if (r->token && !gl->IsSync(r->token))
        return false;
    return !r->box_vao || gl->IsVertexArray(r->box_vao);
}

const struct tw_gl *tw_renderer_gl(const struct tw_renderer *r)
{
    return &r->gl;
}

void tw_renderer_enter(struct tw_renderer *r)
{
    if (r->entered++ > 0)
        return;
    tw_gl_state_enter(&r->gl, r->has_clip_control, &r->host_state);
    if (r->has_mdi)
        r->gl.GetIntegerv(GL_DRAW_INDIRECT_BUFFER_BINDING, &r->host_indirect_buffer);
    if (r->has_compute)
        tw_gl_compute_state_enter(&r->gl, &r->host_compute);
    r->bound_vao = 0;
    if (r->reversed_z)
        r->gl.ClipControl(GL_LOWER_LEFT, GL_ZERO_TO_ONE);
    r->mode = TW_RENDERER_MODE_NONE;
}

void tw_renderer_leave(struct tw_renderer *r)
{
    if (r->entered == 0 || --r->entered > 0)
        return;
    tw_gl_state_leave(&r->gl, r->has_clip_control, &r->host_state);
    if (r->has_mdi)
        r->gl.BindBuffer(GL_DRAW_INDIRECT_BUFFER, (GLuint)r->host_indirect_buffer);
    if (r->has_compute)
        tw_gl_compute_state_leave(&r->gl, &r->host_compute);
    r->mode = TW_RENDERER_MODE_NONE;
}

void tw_renderer_destroy(struct tw_renderer *r)
{
    if (!r)
        return;
    const struct tw_gl *gl = &r->gl;
    if (r->gl_loaded && !tw_renderer_current(r)) {
        /* Its GL objects went with the context, or belong to one that is not
         * current here: deleting names in another context would free the
         * host's objects. Only memory is freed. */
        tw_log_printf(&r->log, TW_LOG_WARN, "the world was destroyed without its OpenGL "
                      "context current on the calling thread: its GL objects were left to "
                      "the context (freed with it)");
        r->gl_loaded = false;
    }
    if (r->gl_loaded)
        tw_renderer_enter(r);
    tw_renderer_queries_finish(r);
    tw_renderer_draws_finish(r);
    tw_renderer_gpu_hzb_finish(r);
    tw_renderer_store_finish(r);
    tw_renderer_id_finish(r);
    if (r->gl_loaded) {
        gl->DeleteBuffers(1, &r->box_vbo);
        gl->DeleteBuffers(1, &r->box_ibo);
        gl->DeleteVertexArrays(1, &r->box_vao);
        gl->DeleteRenderbuffers(1, &r->color_rb);
        if (r->depth_rb)
            gl->DeleteRenderbuffers(1, &r->depth_rb);
        if (r->depth_texture)
            gl->DeleteTextures(1, &r->depth_texture);
        gl->DeleteFramebuffers(1, &r->fbo);
        if (r->token)
            gl->DeleteSync(r->token);
        tw_programs_finish(&r->programs, gl);
        tw_renderer_leave(r);
    }
    free(r);
}

void tw_renderer_set_host(struct tw_renderer *r, const struct tw_renderer_host *host)
{
    r->host = host ? *host : (struct tw_renderer_host){0};
}

bool tw_renderer_host_mode(const struct tw_renderer *r)
{
    return r->host.draw != NULL;
}

/* Where a frame draws: the renderer's framebuffer, or the host's. */
static void bind_target(struct tw_renderer *r)
{
    const struct tw_gl *gl = &r->gl;
    gl->BindFramebuffer(GL_FRAMEBUFFER, r->host.draw ? r->host_fbo : r->fbo);
    gl->Viewport(0, 0, (GLsizei)r->width, (GLsizei)r->height);
    gl->Enable(GL_DEPTH_TEST);
    gl->DepthFunc(r->reversed_z ? GL_GEQUAL : GL_LEQUAL);
}

void tw_renderer_after_host(struct tw_renderer *r)
{
    const struct tw_gl *gl = &r->gl;
    if (r->in_frame)
        bind_target(r);
    tw_gl_state_reset(gl);
    if (r->reversed_z)
        gl->ClipControl(GL_LOWER_LEFT, GL_ZERO_TO_ONE);
    r->bound_vao = 0;
    r->mode = TW_RENDERER_MODE_NONE;
}

void tw_renderer_begin_frame(struct tw_renderer *r, const struct tw_view *v)
{
    const struct tw_gl *gl = &r->gl;
    tw_renderer_queries_begin_frame(r, v);
    r->host_fbo = (GLuint)r->host_state.draw_fbo;
    r->in_frame = true;
    bind_target(r);
    gl->DepthMask(GL_TRUE);
    gl->ColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
    gl->ClearColor(0.70f, 0.80f, 0.92f, 1.0f);
    gl->ClearDepth(r->reversed_z ? 0.0 : 1.0);
    if (!r->host.draw || r->host.clear)
        gl->Clear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    const float *view_proj = r->reversed_z ? v->view_proj_rz : v->view_proj;
    gl->UseProgram(r->programs.query.program);
    gl->UniformMatrix4fv(r->programs.query.view_proj, 1, GL_FALSE, view_proj);
    gl->UseProgram(r->programs.scene.program);
    gl->UniformMatrix4fv(r->programs.scene.view_proj, 1, GL_FALSE, view_proj);
    gl->Uniform3fv(r->programs.scene.eye, 1, v->eye);
    const float fog[2] = {0.45f * v->view_distance, 0.9f * v->view_distance};
    gl->Uniform2fv(r->programs.scene.fog, 1, fog);
    r->mode = TW_RENDERER_MODE_NONE;
}

void tw_renderer_end_frame(struct tw_renderer *r)
{
    r->in_frame = false;
    r->gl.Flush();
}

void tw_renderer_finish(struct tw_renderer *r)
{
    r->gl.Finish();
}

void tw_renderer_clear_depth(struct tw_renderer *r, bool occluded)
{
    const struct tw_gl *gl = &r->gl;
    gl->DepthMask(GL_TRUE);
    gl->ClearDepth(occluded != r->reversed_z ? 0.0 : 1.0);
    gl->Clear(GL_DEPTH_BUFFER_BIT);
    r->mode = TW_RENDERER_MODE_NONE;   /* the next draw or query sets its own masks */
}

int tw_renderer_read_rgb(struct tw_renderer *r, uint8_t *rgb)
{
    const struct tw_gl *gl = &r->gl;
    const size_t row = (size_t)r->width * 4;
    uint8_t *rgba = malloc(row * r->height);
    if (!rgba)
        return TW_ERR_NOMEM;
    gl->BindFramebuffer(GL_FRAMEBUFFER, r->fbo);
    gl->ReadBuffer(GL_COLOR_ATTACHMENT0);
    gl->PixelStorei(GL_PACK_ALIGNMENT, 1);
    gl->ReadPixels(0, 0, (GLsizei)r->width, (GLsizei)r->height, GL_RGBA, GL_UNSIGNED_BYTE, rgba);
    for (uint32_t y = 0; y < r->height; y++) {
        const uint8_t *src = rgba + row * (r->height - 1 - y);
        uint8_t *dst = rgb + (size_t)y * r->width * 3;
        for (uint32_t x = 0; x < r->width; x++) {
            dst[3 * x] = src[4 * x];
            dst[3 * x + 1] = src[4 * x + 1];
            dst[3 * x + 2] = src[4 * x + 2];
        }
    }
    free(rgba);
    return TW_OK;
}

void tw_renderer_read_depth(struct tw_renderer *r, float *depth)
{
    const struct tw_gl *gl = &r->gl;
    /* In host rendering, the host's framebuffer holds the frame's depth. */
    gl->BindFramebuffer(GL_FRAMEBUFFER, r->host.draw ? r->host_fbo : r->fbo);
    gl->PixelStorei(GL_PACK_ALIGNMENT, 4);
    gl->ReadPixels(0, 0, (GLsizei)r->width, (GLsizei)r->height, GL_DEPTH_COMPONENT, GL_FLOAT,
                   depth);
}

void tw_renderer_blit(struct tw_renderer *r, uint32_t target, uint32_t width, uint32_t height)
{
    const struct tw_gl *gl = &r->gl;
    gl->BindFramebuffer(GL_READ_FRAMEBUFFER, r->fbo);
    gl->BindFramebuffer(GL_DRAW_FRAMEBUFFER, target);
    const bool same = width == r->width && height == r->height;
    gl->BlitFramebuffer(0, 0, (GLint)r->width, (GLint)r->height, 0, 0, (GLint)width,
                        (GLint)height, GL_COLOR_BUFFER_BIT, same ? GL_NEAREST : GL_LINEAR);
    gl->BindFramebuffer(GL_FRAMEBUFFER, r->fbo);
    r->mode = TW_RENDERER_MODE_NONE;
}

bool tw_renderer_reversed_z(const struct tw_renderer *r)
{
    return r->reversed_z;
}
