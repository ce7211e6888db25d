/*
 * A good guest in a host's GL context (runtime.h, tw_world_frame): a host
 * sets GL state of its own, in every way the world's drawing could be
 * disturbed by it or could disturb it; the world's calls leave that state
 * exactly as they found it, and their images are the same as in a context
 * with default state.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "runtime/gl.h"
#include "runtime/runtime-internal.h"
#include "tests/check.h"
#include "tiles/tiles-internal.h"
#include "tileworld/context.h"
#include "tileworld/runtime.h"
#include "tileworld/tilesets.h"

enum { W = 160, H = 96, FRAMES = 6 };

struct host {
    GLuint fbo, rb, program, vao, vbo, pbo;
};

static GLuint host_program(const struct tw_gl *gl)
{
    static const char *vs = "#version 330 core\nvoid main() { gl_Position = vec4(0.0); }\n";
    static const char *fs = "#version 330 core\nout vec4 c;\nvoid main() { c = vec4(1.0); }\n";
    GLuint p = gl->CreateProgram();
    const char *src[2] = {vs, fs};
    const GLenum type[2] = {GL_VERTEX_SHADER, GL_FRAGMENT_SHADER};
    for (int k = 0; k < 2; k++) {
        GLuint s = gl->CreateShader(type[k]);
        gl->ShaderSource(s, 1, &src[k], NULL);
        gl->CompileShader(s);
        gl->AttachShader(p, s);
        gl->DeleteShader(s);
    }
    gl->LinkProgram(p);
    return p;
}

/* State no renderer would leave by accident. */
static void set_host_state(const struct tw_gl *gl, struct host *h)
{
    gl->GenRenderbuffers(1, &h->rb);
    gl->BindRenderbuffer(GL_RENDERBUFFER, h->rb);
    gl->RenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, 8, 8);
    gl->GenFramebuffers(1, &h->fbo);
    gl->BindFramebuffer(GL_FRAMEBUFFER, h->fbo);
    gl->FramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, h->rb);
    h->program = host_program(gl);
    gl->UseProgram(h->program);
    gl->GenVertexArrays(1, &h->vao);
    gl->BindVertexArray(h->vao);
    gl->GenBuffers(1, &h->vbo);
    gl->BindBuffer(GL_ARRAY_BUFFER, h->vbo);
    gl->GenBuffers(1, &h->pbo);
    gl->BindBuffer(GL_PIXEL_PACK_BUFFER, h->pbo);
    gl->BufferData(GL_PIXEL_PACK_BUFFER, 64, NULL, GL_STREAM_READ);
    gl->Viewport(1, 2, 3, 4);
    gl->Enable(GL_SCISSOR_TEST);
    gl->Enable(GL_BLEND);
    gl->Enable(GL_STENCIL_TEST);
    gl->Enable(GL_POLYGON_OFFSET_FILL);
    gl->Disable(GL_DEPTH_TEST);
    gl->Enable(GL_CULL_FACE);
    gl->CullFace(GL_FRONT);
    gl->FrontFace(GL_CW);
    gl->PolygonMode(GL_FRONT_AND_BACK, GL_LINE);
    gl->DepthFunc(GL_GREATER);
    gl->DepthMask(GL_FALSE);
    gl->ColorMask(GL_TRUE, GL_FALSE, GL_TRUE, GL_FALSE);
    gl->BlendFuncSeparate(GL_ONE, GL_ONE, GL_ZERO, GL_SRC_COLOR);
    gl->ClearColor(0.25f, 0.5f, 0.75f, 1.0f);
    gl->ClearDepth(0.5);
    gl->DepthRange(0.2, 0.8);
    gl->PixelStorei(GL_PACK_ALIGNMENT, 2);
    gl->PixelStorei(GL_PACK_ROW_LENGTH, 7);
    if (gl->ClipControl)
        gl->ClipControl(GL_UPPER_LEFT, GL_NEGATIVE_ONE_TO_ONE);
}

static void snapshot(const struct tw_gl *gl, struct tw_gl_state *s)
{
    /* tw_gl_state_enter() reads every field; leave puts them back unchanged. */
    tw_gl_state_enter(gl, gl->ClipControl != NULL, s);
    tw_gl_state_leave(gl, gl->ClipControl != NULL, s);
}

static int states_differ(const struct tw_gl_state *a, const struct tw_gl_state *b)
{
    int n = 0;
#define SAME(field) \
    do { \
        if (memcmp(&a->field, &b->field, sizeof(a->field)) != 0) { \
            fprintf(stderr, "GL state changed: %s\n", #field); \
            n++; \
        } \
    } while (0)
    SAME(draw_fbo);
    SAME(read_fbo);
    SAME(renderbuffer);
    SAME(program);
    SAME(vertex_array);
    SAME(array_buffer);
    SAME(pixel_pack_buffer);
    SAME(pixel_unpack_buffer);
    SAME(viewport);
    SAME(depth_func);
    SAME(cull_face_mode);
    SAME(front_face);
    SAME(polygon_mode);
    SAME(blend_src_rgb);
    SAME(blend_dst_rgb);
    SAME(blend_src_alpha);
    SAME(blend_dst_alpha);
    SAME(pack_alignment);
    SAME(pack_row_length);
    SAME(clip_origin);
    SAME(clip_depth_mode);
    SAME(depth_mask);
    SAME(color_mask);
    SAME(clear_color);
    SAME(clear_depth);
    SAME(depth_range);
    SAME(enabled);
#undef SAME
    return n;
}

static struct tw_camera camera(int f)
{
    struct tw_camera c = {.pos = {.cell = {0, 0}, .local = {7.0f, 1.7f, 5.0f + 4.0f * (float)f}}};
    c.yaw = 10.0f * (float)f;
    return c;
}

/* The world's depth copied into a framebuffer of the host's: far exactly
 * where the image shows the sky (fog never reaches its colour), and a
 * framebuffer of another depth format refused without a GL error left. */
static void check_depth_copy(struct tw_world *w, const struct tw_gl *gl, const uint8_t *rgb)
{
    GLuint fbo[2], rb[2];
    gl->GenFramebuffers(2, fbo);
    gl->GenRenderbuffers(2, rb);
    GLint old_fbo = 0, old_rb = 0;
    gl->GetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &old_fbo);
    gl->GetIntegerv(GL_RENDERBUFFER_BINDING, &old_rb);
    const GLenum formats[2] = {(GLenum)tw_world_depth_format(w), GL_DEPTH_COMPONENT16};
    CHECK(formats[0] == (tw_world_reversed_z(w) ? GL_DEPTH_COMPONENT32F : GL_DEPTH_COMPONENT24));
    for (int k = 0; k < 2; k++) {
        gl->BindRenderbuffer(GL_RENDERBUFFER, rb[k]);
        gl->RenderbufferStorage(GL_RENDERBUFFER, formats[k], W, H);
        gl->BindFramebuffer(GL_FRAMEBUFFER, fbo[k]);
        gl->FramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, rb[k]);
    }
    gl->BindFramebuffer(GL_FRAMEBUFFER, (GLuint)old_fbo);
    gl->BindRenderbuffer(GL_RENDERBUFFER, (GLuint)old_rb);
    CHECK(tw_world_blit_depth(w, fbo[0]) == TW_OK);
    CHECK(tw_world_blit_depth(w, fbo[1]) == TW_ERR_GL);
    CHECK(gl->GetError() == GL_NO_ERROR);
    float *depth = malloc(sizeof(float) * W * H);
    if (depth) {
        /* The host's own read: its pack state set aside, then put back. */
        GLint pack = 4, row = 0, read = 0, pbo = 0;
        gl->GetIntegerv(GL_PACK_ALIGNMENT, &pack);
        gl->GetIntegerv(GL_PACK_ROW_LENGTH, &row);
        gl->GetIntegerv(GL_READ_FRAMEBUFFER_BINDING, &read);
        gl->GetIntegerv(GL_PIXEL_PACK_BUFFER_BINDING, &pbo);
        gl->BindFramebuffer(GL_READ_FRAMEBUFFER, fbo[0]);
        gl->BindBuffer(GL_PIXEL_PACK_BUFFER, 0);
        gl->PixelStorei(GL_PACK_ALIGNMENT, 4);
        gl->PixelStorei(GL_PACK_ROW_LENGTH, 0);
        gl->ReadPixels(0, 0, W, H, GL_DEPTH_COMPONENT, GL_FLOAT, depth);
        gl->PixelStorei(GL_PACK_ALIGNMENT, pack);
        gl->PixelStorei(GL_PACK_ROW_LENGTH, row);
        gl->BindBuffer(GL_PIXEL_PACK_BUFFER, (GLuint)pbo);
        gl->BindFramebuffer(GL_READ_FRAMEBUFFER, (GLuint)read);
        const float far = tw_world_reversed_z(w) ? 0.0f : 1.0f;
        int wrong = 0, sky = 0;
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++) {
                const uint8_t *c = rgb + 3 * ((size_t)(H - 1 - y) * W + x);
                const bool is_sky = abs(c[0] - 179) <= 1 && abs(c[1] - 204) <= 1 &&
                                    abs(c[2] - 235) <= 1;
                sky += is_sky;
                wrong += is_sky != (depth[(size_t)y * W + x] == far);
            }
        CHECK_MSG(wrong == 0 && sky > 0 && sky < W * H, "%d pixels disagree, %d of sky", wrong,
                  sky);
        free(depth);
    }
    gl->DeleteFramebuffers(2, fbo);
    gl->DeleteRenderbuffers(2, rb);
}

/* Runs the world's calls; the last frame's image goes into rgb. */
static int run_world(struct tw_context *ctx, const struct tw_tileset *ts, uint8_t *rgb,
                     const struct tw_gl *gl, const struct tw_gl_state *host)
{
    struct tw_world_settings s = {0};
    s.tileset = ts;
    s.width = W;
    s.height = H;
    s.get_proc = tw_context_get_proc(ctx);
    s.deterministic = true;
    struct tw_world *w = NULL;
    int changed = 0;
    struct tw_gl_state now;
    CHECK(tw_world_create(&s, &w) == TW_OK);
    if (!w)
        return 1;
    if (host) {
        snapshot(gl, &now);
        changed += states_differ(host, &now);
    }
    CHECK(tw_world_set_debug(w, TW_DEBUG_ALL) == TW_OK);
    for (int f = 0; f < FRAMES; f++) {
        struct tw_frame_stats st;
        const struct tw_camera cam = camera(f);
        CHECK(tw_world_frame(w, &cam, &st) == TW_OK);
        CHECK(tw_world_finish(w, &st) == TW_OK);
        CHECK(st.triangles > 0);
        if (host) {
            snapshot(gl, &now);
            changed += states_differ(host, &now);
        }
    }
    size_t n = 0;
    const struct tw_debug_box *boxes = tw_world_debug_boxes(w, &n);
    CHECK(tw_world_read_rgb(w, rgb) == TW_OK);
    if (host) {
        /* What the host's own calls changed, put back; the world's copy then
         * changes nothing either. */
        check_depth_copy(w, gl, rgb);
        snapshot(gl, &now);
        changed += states_differ(host, &now);
    }
    CHECK(tw_world_draw_debug(w, boxes, n) == TW_OK);
    CHECK(tw_world_blit(w, 0, W, H) == TW_OK);
    if (host) {
        snapshot(gl, &now);
        changed += states_differ(host, &now);
    }
    tw_world_destroy(w);
    if (host) {
        snapshot(gl, &now);
        changed += states_differ(host, &now);
    }
    return changed;
}

/* A world that counts samples (T > 0) after its calibration's any-samples
 * queries: no GL error, queries answered (a query object keeps its first
 * target: reusing the calibration's was GL_INVALID_OPERATION). */
static void run_counting_world(struct tw_context *ctx, const struct tw_tileset *ts,
                               const struct tw_gl *gl)
{
    struct tw_world_settings s = {0};
    s.tileset = ts;
    s.width = W;
    s.height = H;
    s.get_proc = tw_context_get_proc(ctx);
    const struct tw_world_tuning t = {.chc.threshold = 2, .tilequery.threshold = 2};
    struct tw_world *w = NULL;
    CHECK(gl->GetError() == GL_NO_ERROR);
    CHECK(tw_world_create_tuned(&s, &t, &w) == TW_OK);
    if (!w)
        return;
    CHECK(tw_world_calibration(w)->measured);
    uint64_t triangles = 0, queries = 0;
    for (int f = 0; f < FRAMES; f++) {
        struct tw_frame_stats st;
        const struct tw_camera cam = camera(f);
        CHECK(tw_world_frame(w, &cam, &st) == TW_OK);
        CHECK(tw_world_finish(w, &st) == TW_OK);
        triangles += st.triangles;
        queries += st.queries;
    }
    tw_world_destroy(w);
    CHECK(triangles > 0 && queries > 0);
    CHECK(gl->GetError() == GL_NO_ERROR);
}

int main(void)
{
    struct tw_context *ctx = NULL;
    struct tw_tileset *ts = NULL;
    uint8_t *plain = malloc(W * H * 3), *guest = malloc(W * H * 3);
    struct tw_gl gl;
    if (tw_context_create_headless(W, H, NULL, &ctx) != TW_OK ||
        tw_tilesets_builtin("city", 1, 0, NULL, &ts) != TW_OK || !plain || !guest ||
        tw_gl_load(&gl, tw_context_get_proc(ctx), NULL) != TW_OK) {
        fprintf(stderr, "test-guest: cannot set up\n");
        return 1;
    }
    /* In a context with default state: the reference image. */
    CHECK(run_world(ctx, ts, plain, &gl, NULL) == 0);

    /* In a host's state: the same image, and the state as it was. */
    struct host h;
    set_host_state(&gl, &h);
    struct tw_gl_state before;
    snapshot(&gl, &before);
    CHECK(before.enabled != 0 && before.viewport[2] == 3 && before.pack_row_length == 7);
    const int changed = run_world(ctx, ts, guest, &gl, &before);
    CHECK(changed == 0);
    CHECK(memcmp(plain, guest, W * H * 3) == 0);
    CHECK(gl.GetError() == GL_NO_ERROR);
    run_counting_world(ctx, ts, &gl);
    printf("guest: %d GL state fields changed by the world's calls; images %s\n", changed,
           memcmp(plain, guest, W * H * 3) == 0 ? "identical" : "differ");
    free(plain);
    free(guest);
    tw_tileset_destroy(ts);
    tw_context_destroy(ctx);
    return check_summary("test-guest");
}
