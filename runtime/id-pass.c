/* The oracle's object-ID pass (renderer.h, DESIGN §8): clusters drawn with
 * their ids into a buffer of their own, through the scene's vertex stage
 * and depth state, then read back. */
#include "runtime/renderer-private.h"
#include "tiles/tiles-internal.h"

int tw_renderer_id_init(struct tw_renderer *r, GLenum depth_format)
{
    const struct tw_gl *gl = &r->gl;
    gl->GenFramebuffers(1, &r->id_fbo);
    gl->BindFramebuffer(GL_FRAMEBUFFER, r->id_fbo);
    gl->GenRenderbuffers(1, &r->id_rb);
    gl->BindRenderbuffer(GL_RENDERBUFFER, r->id_rb);
    gl->RenderbufferStorage(GL_RENDERBUFFER, GL_R32UI, (GLsizei)r->width, (GLsizei)r->height);
    gl->FramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, r->id_rb);
    gl->GenRenderbuffers(1, &r->id_depth_rb);
    gl->BindRenderbuffer(GL_RENDERBUFFER, r->id_depth_rb);
    gl->RenderbufferStorage(GL_RENDERBUFFER, depth_format, (GLsizei)r->width,
                            (GLsizei)r->height);
    gl->FramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER,
                                r->id_depth_rb);
    if (gl->CheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
        return tw_renderer_framebuffer_failed(r, "object-ID image");
    return TW_OK;
}

void tw_renderer_id_finish(struct tw_renderer *r)
{
    if (!r->gl_loaded)
        return;
    r->gl.DeleteRenderbuffers(1, &r->id_rb);
    r->gl.DeleteRenderbuffers(1, &r->id_depth_rb);
    r->gl.DeleteFramebuffers(1, &r->id_fbo);
}

void tw_renderer_id_begin(struct tw_renderer *r, const struct tw_view *v)
{
    const struct tw_gl *gl = &r->gl;
    gl->BindFramebuffer(GL_FRAMEBUFFER, r->id_fbo);
    gl->Viewport(0, 0, (GLsizei)r->width, (GLsizei)r->height);
    gl->ColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
    gl->DepthMask(GL_TRUE);
    const GLuint none[4] = {TW_RENDERER_NO_ID, 0, 0, 0};
    gl->ClearBufferuiv(GL_COLOR, 0, none);
    const GLfloat far_depth = r->reversed_z ? 0.0f : 1.0f;     /* reversed depth: far is 0 */
    gl->ClearBufferfv(GL_DEPTH, 0, &far_depth);
    gl->Enable(GL_DEPTH_TEST);
    gl->DepthFunc(r->reversed_z ? GL_GEQUAL : GL_LEQUAL);
    gl->Enable(GL_CULL_FACE);
    gl->CullFace(GL_BACK);
    gl->UseProgram(r->programs.id.program);
    gl->UniformMatrix4fv(r->programs.id.view_proj, 1, GL_FALSE,
                         r->reversed_z ? v->view_proj_rz : v->view_proj);
    r->bound_vao = 0;
    r->mode = TW_RENDERER_MODE_NONE;
}

struct id_run {
    const float *offset;
    uint32_t first_id;
};

static void id_run(struct tw_renderer *r, void *user, uint32_t part, const uint32_t *clusters,
                   uint32_t count, uint32_t at)
{
    const struct id_run *run = user;
    tw_renderer_id_draw(r, part, run->offset, clusters, count, run->first_id + at);
}

void tw_renderer_id_draw(struct tw_renderer *r, uint32_t content, const float offset[3],
                         const uint32_t *clusters, uint32_t count, uint32_t first_id)
{
    if (count == 0)
        return;
    struct id_run run = {offset, first_id};
    if (tw_renderer_split(r, content, clusters, count, id_run, &run))
        return;     /* a composite: its parts drawn, ids in the order given */
    const struct tw_prototype *proto;
    const struct tw_gpu_buffers *b = tw_renderer_bind_content(r, content, &proto);
    /* Ids travel as floats in the records: exact below 2^24. */
    if ((uint64_t)first_id + count > (1u << 24)) {
        tw_log_printf(&r->log, TW_LOG_ERROR, "the ID pass holds at most 2^24 clusters");
        return;
    }
    uint32_t records;
    if (!tw_renderer_stage_clusters(r, b, proto, offset, clusters, count, first_id, &records)) {
        tw_log_printf(&r->log, TW_LOG_ERROR, "out of memory staging the ID pass's draws");
        return;
    }
    tw_renderer_draws_submit(r, r->stage_records, records, r->stage_commands, count);
}

void tw_renderer_id_read(struct tw_renderer *r, uint32_t *ids, float *depth)
{
    const struct tw_gl *gl = &r->gl;
    gl->BindFramebuffer(GL_FRAMEBUFFER, r->id_fbo);
    gl->ReadBuffer(GL_COLOR_ATTACHMENT0);
    gl->PixelStorei(GL_PACK_ALIGNMENT, 4);
    gl->ReadPixels(0, 0, (GLsizei)r->width, (GLsizei)r->height, GL_RED_INTEGER, GL_UNSIGNED_INT,
                   ids);
    if (depth)
        gl->ReadPixels(0, 0, (GLsizei)r->width, (GLsizei)r->height, GL_DEPTH_COMPONENT, GL_FLOAT,
                       depth);
    gl->BindFramebuffer(GL_FRAMEBUFFER, r->fbo);
}
