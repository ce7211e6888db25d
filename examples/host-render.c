/*
 * host-render.c: tileworld streams, culls and budgets; the host draws.
 *
 * A host with a renderer of its own (here: its own shader, its own vertex
 * buffers, its own framebuffer) sets tw_world_settings.host. Every frame,
 * tileworld calls host.draw() with batches of visible clusters (tile, level
 * of detail, cluster indices, camera-relative offset) and draws its
 * occlusion queries between them into the host's framebuffer, against the
 * depth the host's draws wrote. host.release() says when a generated tile
 * leaves the cache, so the host frees its copy.
 *
 * This host walks a street of the city-gen world generator with a small
 * cache budget (tiles come and go), and checks that its image matches the
 * one tileworld draws itself for the same frames (a second world, side by
 * side), and that every tile it uploaded and was told to release is freed.
 * It exits 0 when every check holds, else 1 with a message.
 *
 * Build it against an installed tileworld (glcorearb.h: libgl-dev):
 *     cc -std=c11 host-render.c $(pkg-config --cflags --libs tileworld tileworld-headless) -o host-render
 */
#include <GL/glcorearb.h>
#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tileworld/context.h"
#include "tileworld/runtime.h"
#include "tileworld/tilesets.h"

enum { WIDTH = 320, HEIGHT = 180, FRAMES = 60 };

/* ---- the GL entry points this host uses, loaded from the context -------------------- */

#define HOST_GL(X) \
    X(PFNGLGENFRAMEBUFFERSPROC, GenFramebuffers) \
    X(PFNGLBINDFRAMEBUFFERPROC, BindFramebuffer) \
    X(PFNGLFRAMEBUFFERRENDERBUFFERPROC, FramebufferRenderbuffer) \
    X(PFNGLDELETEFRAMEBUFFERSPROC, DeleteFramebuffers) \
    X(PFNGLGENRENDERBUFFERSPROC, GenRenderbuffers) \
    X(PFNGLBINDRENDERBUFFERPROC, BindRenderbuffer) \
    X(PFNGLRENDERBUFFERSTORAGEPROC, RenderbufferStorage) \
    X(PFNGLDELETERENDERBUFFERSPROC, DeleteRenderbuffers) \
    X(PFNGLCREATESHADERPROC, CreateShader) \
    X(PFNGLSHADERSOURCEPROC, ShaderSource) \
    X(PFNGLCOMPILESHADERPROC, CompileShader) \
    X(PFNGLGETSHADERIVPROC, GetShaderiv) \
    X(PFNGLDELETESHADERPROC, DeleteShader) \
    X(PFNGLCREATEPROGRAMPROC, CreateProgram) \
    X(PFNGLATTACHSHADERPROC, AttachShader) \
    X(PFNGLLINKPROGRAMPROC, LinkProgram) \
    X(PFNGLGETPROGRAMIVPROC, GetProgramiv) \
    X(PFNGLDELETEPROGRAMPROC, DeleteProgram) \
    X(PFNGLUSEPROGRAMPROC, UseProgram) \
    X(PFNGLGETUNIFORMLOCATIONPROC, GetUniformLocation) \
    X(PFNGLUNIFORMMATRIX4FVPROC, UniformMatrix4fv) \
    X(PFNGLUNIFORM4FVPROC, Uniform4fv) \
    X(PFNGLUNIFORM3FVPROC, Uniform3fv) \
    X(PFNGLUNIFORM2FVPROC, Uniform2fv) \
    X(PFNGLGENVERTEXARRAYSPROC, GenVertexArrays) \
    X(PFNGLBINDVERTEXARRAYPROC, BindVertexArray) \
    X(PFNGLDELETEVERTEXARRAYSPROC, DeleteVertexArrays) \
    X(PFNGLGENBUFFERSPROC, GenBuffers) \
    X(PFNGLBINDBUFFERPROC, BindBuffer) \
    X(PFNGLBUFFERDATAPROC, BufferData) \
    X(PFNGLDELETEBUFFERSPROC, DeleteBuffers) \
    X(PFNGLVERTEXATTRIBPOINTERPROC, VertexAttribPointer) \
    X(PFNGLENABLEVERTEXATTRIBARRAYPROC, EnableVertexAttribArray) \
    X(PFNGLDISABLEVERTEXATTRIBARRAYPROC, DisableVertexAttribArray) \
    X(PFNGLVERTEXATTRIB4FPROC, VertexAttrib4f) \
    X(PFNGLDRAWELEMENTSPROC, DrawElements) \
    X(PFNGLCLEARCOLORPROC, ClearColor) \
    X(PFNGLCLEARDEPTHPROC, ClearDepth) \
    X(PFNGLCLEARPROC, Clear) \
    X(PFNGLDEPTHMASKPROC, DepthMask) \
    X(PFNGLCOLORMASKPROC, ColorMask) \
    X(PFNGLENABLEPROC, Enable) \
    X(PFNGLCULLFACEPROC, CullFace) \
    X(PFNGLREADPIXELSPROC, ReadPixels) \
    X(PFNGLPIXELSTOREIPROC, PixelStorei) \
    X(PFNGLGETERRORPROC, GetError)

struct gl {
#define FIELD(type, name) type name;
    HOST_GL(FIELD)
#undef FIELD
};

static int load_gl(struct gl *gl, tw_gl_get_proc_fn get_proc)
{
#define LOAD(type, name) \
    if (!(gl->name = (type)get_proc("gl" #name))) { \
        fprintf(stderr, "host-render: no gl" #name "\n"); \
        return 1; \
    }
    HOST_GL(LOAD)
#undef LOAD
    return 0;
}

/* ---- the host's renderer ------------------------------------------------------------ */

/* Its own shader: the world's positions (instance transform, then the
 * tile's offset, then the view) and the look of tileworld's own (a sun,
 * the material times the vertex colour, fog toward the sky). */
static const char *const vs_src =
    "#version 330 core\n"
    "layout(location = 0) in vec3 a_pos;\n"
    "layout(location = 1) in vec3 a_normal;\n"
    "layout(location = 2) in vec4 a_color;\n"
    "uniform vec4 u_model[3];\n"
    "uniform vec3 u_offset;\n"
    "uniform mat4 u_view_proj;\n"
    "out vec3 v_normal;\n"
    "out vec3 v_pos;\n"
    "out vec3 v_color;\n"
    "void main() {\n"
    "    vec4 p = vec4(a_pos, 1.0);\n"
    "    vec3 w = vec3(dot(u_model[0], p), dot(u_model[1], p), dot(u_model[2], p)) + u_offset;\n"
    "    v_normal = vec3(dot(u_model[0].xyz, a_normal), dot(u_model[1].xyz, a_normal),\n"
    "                    dot(u_model[2].xyz, a_normal));\n"
    "    v_pos = w;\n"
    "    v_color = a_color.rgb;\n"
    "    gl_Position = u_view_proj * vec4(w, 1.0);\n"
    "}\n";

static const char *const fs_src =
    "#version 330 core\n"
    "in vec3 v_normal;\n"
    "in vec3 v_pos;\n"
    "in vec3 v_color;\n"
    "uniform vec4 u_material;\n"
    "uniform vec3 u_eye;\n"
    "uniform vec2 u_fog;\n"
    "out vec4 o_color;\n"
    "void main() {\n"
    "    vec3 n = normalize(v_normal);\n"
    "    vec3 sun = normalize(vec3(0.45, 0.8, 0.3));\n"
    "    float light = 0.38 + 0.62 * max(dot(n, sun), 0.0) + 0.08 * max(-n.x, 0.0);\n"
    "    vec3 c = u_material.rgb * v_color * light;\n"
    "    float f = clamp((distance(v_pos, u_eye) - u_fog.x) / u_fog.y, 0.0, 0.85);\n"
    "    o_color = vec4(mix(c, vec3(0.70, 0.80, 0.92), f), 1.0);\n"
    "}\n";

/* The host's copy of one tileset: a vertex array per mesh. */
struct mesh_set {
    const struct tw_tileset *ts;
    uint32_t owner;             /* the prototype whose release frees it */
    GLuint *vao, *buffers;      /* mesh_count, and 4 buffers per mesh */
};

struct host {
    struct gl gl;
    struct tw_world *world;
    GLuint fbo, color, depth, program;
    GLint u_model, u_offset, u_view_proj, u_material, u_eye, u_fog;
    bool new_frame;             /* set before each tw_world_frame(): the view changed */
    struct mesh_set *sets;
    size_t set_count, set_cap;
    uint64_t uploads, releases, batches;
    int failed;
};

static GLuint compile(const struct gl *gl, GLenum type, const char *src)
{
    GLuint s = gl->CreateShader(type);
    gl->ShaderSource(s, 1, &src, NULL);
    gl->CompileShader(s);
    GLint ok = 0;
    gl->GetShaderiv(s, GL_COMPILE_STATUS, &ok);
    return ok ? s : 0;
}

static int host_init(struct host *h, tw_gl_get_proc_fn get_proc)
{
    struct gl *gl = &h->gl;
    if (load_gl(gl, get_proc))
        return 1;
    gl->GenRenderbuffers(1, &h->color);
    gl->BindRenderbuffer(GL_RENDERBUFFER, h->color);
    gl->RenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, WIDTH, HEIGHT);
    gl->GenRenderbuffers(1, &h->depth);
    gl->BindRenderbuffer(GL_RENDERBUFFER, h->depth);
    gl->RenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT32F, WIDTH, HEIGHT);
    gl->GenFramebuffers(1, &h->fbo);
    gl->BindFramebuffer(GL_FRAMEBUFFER, h->fbo);
    gl->FramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, h->color);
    gl->FramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, h->depth);
    const GLuint vs = compile(gl, GL_VERTEX_SHADER, vs_src);
    const GLuint fs = compile(gl, GL_FRAGMENT_SHADER, fs_src);
    if (!vs || !fs) {
        fprintf(stderr, "host-render: the shaders do not compile\n");
        return 1;
    }
    h->program = gl->CreateProgram();
    gl->AttachShader(h->program, vs);
    gl->AttachShader(h->program, fs);
    gl->LinkProgram(h->program);
    gl->DeleteShader(vs);
    gl->DeleteShader(fs);
    GLint ok = 0;
    gl->GetProgramiv(h->program, GL_LINK_STATUS, &ok);
    if (!ok) {
        fprintf(stderr, "host-render: the program does not link\n");
        return 1;
    }
    h->u_model = gl->GetUniformLocation(h->program, "u_model");
    h->u_offset = gl->GetUniformLocation(h->program, "u_offset");
    h->u_view_proj = gl->GetUniformLocation(h->program, "u_view_proj");
    h->u_material = gl->GetUniformLocation(h->program, "u_material");
    h->u_eye = gl->GetUniformLocation(h->program, "u_eye");
    h->u_fog = gl->GetUniformLocation(h->program, "u_fog");
    return 0;
}

static void free_set(const struct gl *gl, struct mesh_set *set)
{
    gl->DeleteVertexArrays((GLsizei)set->ts->mesh_count, set->vao);
    gl->DeleteBuffers((GLsizei)(4 * set->ts->mesh_count), set->buffers);
    free(set->vao);
    free(set->buffers);
}

/* The host's copy of ts, uploaded the first time one of its clusters is drawn. */
static const struct mesh_set *upload(struct host *h, const struct tw_tileset *ts, uint32_t owner)
{
    for (size_t k = 0; k < h->set_count; k++)
        if (h->sets[k].ts == ts)
            return &h->sets[k];
    if (h->set_count == h->set_cap) {
        const size_t cap = h->set_cap ? 2 * h->set_cap : 64;
        struct mesh_set *s = realloc(h->sets, cap * sizeof(*s));
        if (!s)
            return NULL;
        h->sets = s;
        h->set_cap = cap;
    }
    const struct gl *gl = &h->gl;
    struct mesh_set *set = &h->sets[h->set_count];
    set->ts = ts;
    set->owner = owner;
    set->vao = calloc(ts->mesh_count ? ts->mesh_count : 1, sizeof(GLuint));
    set->buffers = calloc(4 * (ts->mesh_count ? ts->mesh_count : 1), sizeof(GLuint));
    if (!set->vao || !set->buffers) {
        free(set->vao);
        free(set->buffers);
        return NULL;
    }
    gl->GenVertexArrays((GLsizei)ts->mesh_count, set->vao);
    gl->GenBuffers((GLsizei)(4 * ts->mesh_count), set->buffers);
    for (uint32_t m = 0; m < ts->mesh_count; m++) {
        const struct tw_mesh *mesh = &ts->meshes[m];
        const GLuint *b = &set->buffers[4 * m];
        gl->BindVertexArray(set->vao[m]);
        gl->BindBuffer(GL_ARRAY_BUFFER, b[0]);
        gl->BufferData(GL_ARRAY_BUFFER, (GLsizeiptr)(sizeof(float) * 3 * mesh->vertex_count),
                       mesh->positions, GL_STATIC_DRAW);
        gl->VertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 0, NULL);
        gl->EnableVertexAttribArray(0);
        gl->BindBuffer(GL_ARRAY_BUFFER, b[1]);
        gl->BufferData(GL_ARRAY_BUFFER, (GLsizeiptr)(sizeof(float) * 3 * mesh->vertex_count),
                       mesh->normals, GL_STATIC_DRAW);
        gl->VertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, 0, NULL);
        gl->EnableVertexAttribArray(1);
        if (mesh->colors) {
            gl->BindBuffer(GL_ARRAY_BUFFER, b[2]);
            gl->BufferData(GL_ARRAY_BUFFER, (GLsizeiptr)(4 * mesh->vertex_count), mesh->colors,
                           GL_STATIC_DRAW);
            gl->VertexAttribPointer(2, 4, GL_UNSIGNED_BYTE, GL_TRUE, 0, NULL);
            gl->EnableVertexAttribArray(2);
        } else {
            gl->DisableVertexAttribArray(2);   /* the current value: white (set per draw) */
        }
        gl->BindBuffer(GL_ELEMENT_ARRAY_BUFFER, b[3]);
        gl->BufferData(GL_ELEMENT_ARRAY_BUFFER,
                       (GLsizeiptr)(sizeof(uint32_t) * 3 * mesh->triangle_count), mesh->indices,
                       GL_STATIC_DRAW);
    }
    gl->BindVertexArray(0);
    h->uploads++;
    return &h->sets[h->set_count++];
}

/* tileworld's callback: draw this batch now. */
static void host_draw(void *user, const struct tw_host_draw *d)
{
    struct host *h = user;
    const struct gl *gl = &h->gl;
    const struct tw_tileset *ts = NULL;
    const struct tw_prototype *proto = tw_world_level(h->world, d->prototype, d->level, &ts);
    const struct mesh_set *set = proto ? upload(h, ts, d->prototype) : NULL;
    if (!set) {
        h->failed++;
        return;
    }
    h->batches++;
    gl->UseProgram(h->program);
    struct tw_world_view view;
    if (h->new_frame && tw_world_last_view(h->world, &view) == TW_OK) {
        /* The first batch of a frame: its view, as tileworld draws it. */
        h->new_frame = false;
        gl->UniformMatrix4fv(h->u_view_proj, 1, GL_FALSE,
                             tw_world_reversed_z(h->world) ? view.view_proj_rz : view.view_proj);
        gl->Uniform3fv(h->u_eye, 1, view.eye);
        const float distance = tw_world_settings(h->world)->view_distance;
        const float fog[2] = {0.45f * distance, 0.9f * distance};
        gl->Uniform2fv(h->u_fog, 1, fog);
    }
    gl->Uniform3fv(h->u_offset, 1, d->offset);
    gl->VertexAttrib4f(2, 1.0f, 1.0f, 1.0f, 1.0f);
    gl->Enable(GL_CULL_FACE);
    gl->CullFace(GL_BACK);
    gl->DepthMask(GL_TRUE);
    gl->ColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
    for (uint32_t k = 0; k < d->count; k++) {
        const struct tw_cluster *c = &proto->clusters[d->clusters[k]];
        const struct tw_instance *in = &proto->instances[c->instance];
        const struct tw_mesh_part *part = &ts->parts[c->part];
        gl->Uniform4fv(h->u_model, 3, in->transform);
        gl->Uniform4fv(h->u_material, 1, ts->materials[in->material].base_color);
        gl->BindVertexArray(set->vao[part->mesh]);
        gl->DrawElements(GL_TRIANGLES, (GLsizei)(3 * part->triangle_count), GL_UNSIGNED_INT,
                         (const void *)(uintptr_t)(sizeof(uint32_t) * 3 * part->first_triangle));
    }
}

/* tileworld's callback: a generated tile left the cache. */
static void host_release(void *user, uint32_t prototype)
{
    struct host *h = user;
    h->releases++;
    for (size_t k = 0; k < h->set_count;) {
        if (h->sets[k].owner == prototype) {
            free_set(&h->gl, &h->sets[k]);
            h->sets[k] = h->sets[--h->set_count];
        } else {
            k++;
        }
    }
}

static void read_host_image(const struct host *h, uint8_t *rgb)
{
    static uint8_t rgba[WIDTH * HEIGHT * 4];
    h->gl.BindFramebuffer(GL_FRAMEBUFFER, h->fbo);
    h->gl.PixelStorei(GL_PACK_ALIGNMENT, 1);
    h->gl.ReadPixels(0, 0, WIDTH, HEIGHT, GL_RGBA, GL_UNSIGNED_BYTE, rgba);
    for (int y = 0; y < HEIGHT; y++)
        for (int x = 0; x < WIDTH; x++)
            memcpy(rgb + 3 * ((size_t)y * WIDTH + x),
                   rgba + 4 * ((size_t)(HEIGHT - 1 - y) * WIDTH + x), 3);
}

int main(void)
{
    const struct tw_log log = {tw_log_stderr, (void *)(intptr_t)TW_LOG_WARN};
    struct tw_context *ctx = NULL;
    struct tw_tilesets_provider *gen = NULL;
    struct tw_world *own = NULL;
    struct host h = {0};
    int failures = 0;
    if (tw_context_create_headless(WIDTH, HEIGHT, &log, &ctx) != TW_OK ||
        tw_tilesets_provider_create("city-gen", 1, 0, &log, &gen) != TW_OK ||
        host_init(&h, tw_context_get_proc(ctx))) {
        fprintf(stderr, "host-render: cannot set up\n");
        return 1;
    }
    const struct tw_tile_provider *provider = tw_tilesets_provider_get(gen);

    /* The same world twice: drawn by tileworld, and by this host. */
    struct tw_world_settings s = {0};
    s.provider = provider;
    s.width = WIDTH;
    s.height = HEIGHT;
    s.view_distance = 400.0f;
    s.cache_budget_bytes = 48u << 20;   /* tiles leave the cache as the walk goes on */
    s.deterministic = true;
    s.get_proc = tw_context_get_proc(ctx);
    s.log = log;
    if (tw_world_create(&s, &own) != TW_OK)
        return 1;
    s.host = (struct tw_host_renderer){.draw = host_draw, .release = host_release, .user = &h};
    if (tw_world_create(&s, &h.world) != TW_OK)
        return 1;

    struct tw_path path;
    if (tw_path_builtin("street", 1, FRAMES, 6.0f, provider->footprint[0], provider->footprint[1],
                        &path) != TW_OK)
        return 1;
    static uint8_t mine[WIDTH * HEIGHT * 3], theirs[WIDTH * HEIGHT * 3];
    uint64_t worst = 0, triangles_own = 0, triangles_host = 0;
    /* Every method host rendering has, in turn (each keeps its own state). */
    static const enum tw_method methods[] = {TW_METHOD_TILEQUERY_CHC, TW_METHOD_CHC,
                                             TW_METHOD_TILEQUERY, TW_METHOD_VFC};
    for (uint32_t f = 0; f < FRAMES; f++) {
        struct tw_frame_stats so, sh;
        const enum tw_method m = methods[f % 4];
        if (tw_world_set_method(own, m) != TW_OK || tw_world_set_method(h.world, m) != TW_OK)
            return 1;
        if (tw_world_frame(own, &path.keys[f], &so) != TW_OK ||
            tw_world_read_rgb(own, theirs) != TW_OK) {
            fprintf(stderr, "host-render: frame %u: tileworld's own frame failed\n", f);
            return 1;
        }
        /* The host's frame: its framebuffer bound and cleared, the world's
         * depth convention. */
        h.gl.BindFramebuffer(GL_FRAMEBUFFER, h.fbo);
        h.gl.DepthMask(GL_TRUE);
        h.gl.ColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
        h.gl.ClearColor(0.70f, 0.80f, 0.92f, 1.0f);
        h.gl.ClearDepth(tw_world_reversed_z(h.world) ? 0.0 : 1.0);
        h.gl.Clear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
        h.new_frame = true;
        if (tw_world_frame(h.world, &path.keys[f], &sh) != TW_OK) {
            fprintf(stderr, "host-render: frame %u: the host's frame failed\n", f);
            return 1;
        }
        read_host_image(&h, mine);
        /* Pixels that differ by more than the normals' quantisation (the
         * world packs them in 10 bits, this host keeps floats) explains. */
        uint64_t differ = 0;
        for (size_t p = 0; p < (size_t)WIDTH * HEIGHT; p++) {
            int d = 0;
            for (int c = 0; c < 3; c++) {
                const int e = abs((int)mine[3 * p + c] - (int)theirs[3 * p + c]);
                d = e > d ? e : d;
            }
            differ += d > 4;
        }
        worst = differ > worst ? differ : worst;
        if (getenv("HOST_RENDER_VERBOSE"))
            printf("frame %u %s: %llu differ, triangles %llu %llu\n", f, tw_method_name(m), (unsigned long long)differ, (unsigned long long)so.triangles, (unsigned long long)sh.triangles);
        triangles_own += so.triangles;
        triangles_host += sh.triangles;
    }
    printf("host-render: %u frames, worst frame %llu of %u pixels differ; triangles %llu "
           "(tileworld) and %llu (host); %llu batches, %llu tilesets uploaded, %llu released\n",
           FRAMES, (unsigned long long)worst, WIDTH * HEIGHT, (unsigned long long)triangles_own,
           (unsigned long long)triangles_host, (unsigned long long)h.batches,
           (unsigned long long)h.uploads, (unsigned long long)h.releases);
    if (worst > (uint64_t)WIDTH * HEIGHT / 1000) {
        fprintf(stderr, "host-render: the host's image differs from tileworld's in %llu pixels\n",
                (unsigned long long)worst);
        failures++;
    }
    if (h.failed || h.batches == 0 || h.releases == 0) {
        fprintf(stderr, "host-render: %d batches not drawn, %llu drawn, %llu releases\n", h.failed,
                (unsigned long long)h.batches, (unsigned long long)h.releases);
        failures++;
    }
    tw_path_finish(&path);
    tw_world_destroy(own);
    tw_world_destroy(h.world);   /* releases every generated tile still held */
    /* Every generated tile was released with the world: what is left is
     * shared content (none in city-gen). */
    if (h.set_count != 0) {
        fprintf(stderr, "host-render: %zu tilesets never released\n", h.set_count);
        failures++;
    }
    for (size_t k = 0; k < h.set_count; k++)
        free_set(&h.gl, &h.sets[k]);
    free(h.sets);
    h.gl.DeleteProgram(h.program);
    h.gl.DeleteFramebuffers(1, &h.fbo);
    h.gl.DeleteRenderbuffers(1, &h.color);
    h.gl.DeleteRenderbuffers(1, &h.depth);
    tw_tilesets_provider_destroy(gen);
    tw_context_destroy(ctx);
    return failures ? 1 : 0;
}
