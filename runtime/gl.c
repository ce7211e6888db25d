/* Loading the GL entry points (gl.h). */
#include "runtime/gl.h"
#include "tiles/tiles-internal.h"

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

/* Capabilities the library turns off while it draws (bit k of
 * tw_gl_state.enabled), then the ones it sets itself. */
static const GLenum capabilities[] = {
    GL_SCISSOR_TEST, GL_STENCIL_TEST, GL_BLEND, GL_POLYGON_OFFSET_FILL,
    GL_POLYGON_OFFSET_LINE, GL_RASTERIZER_DISCARD, GL_SAMPLE_ALPHA_TO_COVERAGE,
    GL_SAMPLE_COVERAGE, GL_SAMPLE_MASK, GL_FRAMEBUFFER_SRGB, GL_PRIMITIVE_RESTART,
    GL_COLOR_LOGIC_OP, GL_DEPTH_CLAMP, GL_CLIP_DISTANCE0,
    /* set by the library as it needs them */
    GL_DEPTH_TEST, GL_CULL_FACE,
};
enum { TURNED_OFF = 14 };

/* What the library relies on besides the capabilities it turns off. */
static void set_library_state(const struct tw_gl *gl)
{
    gl->FrontFace(GL_CCW);
    gl->PolygonMode(GL_FRONT_AND_BACK, GL_FILL);
    gl->DepthRange(0.0, 1.0);
    gl->BindBuffer(GL_PIXEL_PACK_BUFFER, 0);
    gl->BindBuffer(GL_PIXEL_UNPACK_BUFFER, 0);
    gl->PixelStorei(GL_PACK_ROW_LENGTH, 0);
    gl->PixelStorei(GL_PACK_SKIP_ROWS, 0);
    gl->PixelStorei(GL_PACK_SKIP_PIXELS, 0);
}

void tw_gl_state_enter(const struct tw_gl *gl, bool has_clip_control, struct tw_gl_state *s)
{
    gl->GetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &s->draw_fbo);
    gl->GetIntegerv(GL_READ_FRAMEBUFFER_BINDING, &s->read_fbo);
    gl->GetIntegerv(GL_RENDERBUFFER_BINDING, &s->renderbuffer);
    gl->GetIntegerv(GL_CURRENT_PROGRAM, &s->program);
    gl->GetIntegerv(GL_VERTEX_ARRAY_BINDING, &s->vertex_array);
    gl->GetIntegerv(GL_ARRAY_BUFFER_BINDING, &s->array_buffer);
    gl->GetIntegerv(GL_PIXEL_PACK_BUFFER_BINDING, &s->pixel_pack_buffer);
    gl->GetIntegerv(GL_PIXEL_UNPACK_BUFFER_BINDING, &s->pixel_unpack_buffer);
    gl->GetIntegerv(GL_VIEWPORT, s->viewport);
    gl->GetIntegerv(GL_DEPTH_FUNC, &s->depth_func);
    gl->GetIntegerv(GL_CULL_FACE_MODE, &s->cull_face_mode);
    gl->GetIntegerv(GL_FRONT_FACE, &s->front_face);
    gl->GetIntegerv(GL_POLYGON_MODE, s->polygon_mode);
    gl->GetIntegerv(GL_BLEND_SRC_RGB, &s->blend_src_rgb);
    gl->GetIntegerv(GL_BLEND_DST_RGB, &s->blend_dst_rgb);
    gl->GetIntegerv(GL_BLEND_SRC_ALPHA, &s->blend_src_alpha);
    gl->GetIntegerv(GL_BLEND_DST_ALPHA, &s->blend_dst_alpha);
    gl->GetIntegerv(GL_PACK_ALIGNMENT, &s->pack_alignment);
    gl->GetIntegerv(GL_PACK_ROW_LENGTH, &s->pack_row_length);
    gl->GetIntegerv(GL_PACK_SKIP_ROWS, &s->pack_skip_rows);
    gl->GetIntegerv(GL_PACK_SKIP_PIXELS, &s->pack_skip_pixels);
    if (has_clip_control) {
        gl->GetIntegerv(GL_CLIP_ORIGIN, &s->clip_origin);
        gl->GetIntegerv(GL_CLIP_DEPTH_MODE, &s->clip_depth_mode);
    }
    gl->GetBooleanv(GL_DEPTH_WRITEMASK, &s->depth_mask);
    gl->GetBooleanv(GL_COLOR_WRITEMASK, s->color_mask);
    gl->GetFloatv(GL_COLOR_CLEAR_VALUE, s->clear_color);
    gl->GetDoublev(GL_DEPTH_CLEAR_VALUE, &s->clear_depth);
    gl->GetDoublev(GL_DEPTH_RANGE, s->depth_range);
    s->enabled = 0;
    for (uint32_t k = 0; k < sizeof(capabilities) / sizeof(capabilities[0]); k++)
        if (gl->IsEnabled(capabilities[k]))
            s->enabled |= 1u << k;
    for (uint32_t k = 0; k < TURNED_OFF; k++)
        if (s->enabled & (1u << k))
            gl->Disable(capabilities[k]);
    set_library_state(gl);
}

void tw_gl_state_reset(const struct tw_gl *gl)
{
    for (uint32_t k = 0; k < TURNED_OFF; k++)
        gl->Disable(capabilities[k]);
    set_library_state(gl);
}

void tw_gl_state_leave(const struct tw_gl *gl, bool has_clip_control, const struct tw_gl_state *s)
{
    for (uint32_t k = 0; k < sizeof(capabilities) / sizeof(capabilities[0]); k++) {
        if (s->enabled & (1u << k))
            gl->Enable(capabilities[k]);
        else
            gl->Disable(capabilities[k]);
    }
    gl->BindFramebuffer(GL_DRAW_FRAMEBUFFER, (GLuint)s->draw_fbo);
    gl->BindFramebuffer(GL_READ_FRAMEBUFFER, (GLuint)s->read_fbo);
    gl->BindRenderbuffer(GL_RENDERBUFFER, (GLuint)s->renderbuffer);
    gl->UseProgram((GLuint)s->program);
    gl->BindVertexArray((GLuint)s->vertex_array);
    gl->BindBuffer(GL_ARRAY_BUFFER, (GLuint)s->array_buffer);
    gl->BindBuffer(GL_PIXEL_PACK_BUFFER, (GLuint)s->pixel_pack_buffer);
    gl->BindBuffer(GL_PIXEL_UNPACK_BUFFER, (GLuint)s->pixel_unpack_buffer);
    gl->Viewport(s->viewport[0], s->viewport[1], s->viewport[2], s->viewport[3]);
    gl->DepthFunc((GLenum)s->depth_func);
    gl->CullFace((GLenum)s->cull_face_mode);
    gl->FrontFace((GLenum)s->front_face);
    gl->PolygonMode(GL_FRONT_AND_BACK, (GLenum)s->polygon_mode[0]);
    gl->BlendFuncSeparate((GLenum)s->blend_src_rgb, (GLenum)s->blend_dst_rgb,
                          (GLenum)s->blend_src_alpha, (GLenum)s->blend_dst_alpha);
    gl->PixelStorei(GL_PACK_ALIGNMENT, s->pack_alignment);
    gl->PixelStorei(GL_PACK_ROW_LENGTH, s->pack_row_length);
    gl->PixelStorei(GL_PACK_SKIP_ROWS, s->pack_skip_rows);
    gl->PixelStorei(GL_PACK_SKIP_PIXELS, s->pack_skip_pixels);
    if (has_clip_control)
        gl->ClipControl((GLenum)s->clip_origin, (GLenum)s->clip_depth_mode);
    gl->DepthMask(s->depth_mask);
    gl->ColorMask(s->color_mask[0], s->color_mask[1], s->color_mask[2], s->color_mask[3]);
    gl->ClearColor(s->clear_color[0], s->clear_color[1], s->clear_color[2], s->clear_color[3]);
    gl->ClearDepth(s->clear_depth);
    gl->DepthRange(s->depth_range[0], s->depth_range[1]);
}

void tw_gl_compute_state_enter(const struct tw_gl *gl, struct tw_gl_compute_state *s)
{
    gl->GetIntegerv(GL_ACTIVE_TEXTURE, &s->active_texture);
    gl->ActiveTexture(GL_TEXTURE0);
    gl->GetIntegerv(GL_TEXTURE_BINDING_2D, &s->texture);
    gl->ActiveTexture((GLenum)s->active_texture);
    gl->GetIntegerv(GL_COPY_READ_BUFFER_BINDING, &s->copy_read);
    gl->GetIntegerv(GL_COPY_WRITE_BUFFER_BINDING, &s->copy_write);
    gl->GetIntegerv(GL_SHADER_STORAGE_BUFFER_BINDING, &s->ssbo);
    for (GLuint k = 0; k < TW_GL_COMPUTE_SSBOS; k++) {
        gl->GetIntegeri_v(GL_SHADER_STORAGE_BUFFER_BINDING, k, &s->ssbo_name[k]);
        gl->GetInteger64i_v(GL_SHADER_STORAGE_BUFFER_START, k, &s->ssbo_start[k]);
        gl->GetInteger64i_v(GL_SHADER_STORAGE_BUFFER_SIZE, k, &s->ssbo_size[k]);
    }
}

void tw_gl_compute_state_leave(const struct tw_gl *gl, const struct tw_gl_compute_state *s)
{
    gl->ActiveTexture(GL_TEXTURE0);
    gl->BindTexture(GL_TEXTURE_2D, (GLuint)s->texture);
    gl->ActiveTexture((GLenum)s->active_texture);
    gl->BindBuffer(GL_COPY_READ_BUFFER, (GLuint)s->copy_read);
    gl->BindBuffer(GL_COPY_WRITE_BUFFER, (GLuint)s->copy_write);
    for (GLuint k = 0; k < TW_GL_COMPUTE_SSBOS; k++) {
        if (s->ssbo_size[k] > 0)
            gl->BindBufferRange(GL_SHADER_STORAGE_BUFFER, k, (GLuint)s->ssbo_name[k],
                                (GLintptr)s->ssbo_start[k], (GLsizeiptr)s->ssbo_size[k]);
        else
            gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, k, (GLuint)s->ssbo_name[k]);
    }
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, (GLuint)s->ssbo);
}
