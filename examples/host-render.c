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
 * This host walks a street of the city-gen world generator under a cache
 * budget (tiles come and go), converting each tile to its vertex format on
 * tileworld's workers (host.prepare_worker) and uploading it when it is
 * ready (host.prepare), and checks that its image matches the one
 * tileworld draws itself for the same frames (a second world, side by
 * side, with every method host rendering has, each in turn), that the world's budget
 * counts the bytes the host holds, and that every tile is freed. 400 cars
 * drive the streets: tileworld culls them with the tiles and lists them in
 * batches like any tile's (their prototype's instances are the cars,
 * placed), which this host draws as it draws shared content. Set
 * HOST_RENDER_VERBOSE for a line a frame.
 * It exits 0 when every check holds, else 1 with a message.
 *
 * Build it against an installed tileworld (glcorearb.h: libgl-dev):
 *     cc -std=c11 host-render.c $(pkg-config --cflags --libs tileworld tileworld-headless) -o host-render
 */
#include <GL/glcorearb.h>
#include <math.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tileworld/context.h"
#include "tileworld/runtime.h"
#include "tileworld/tilesets.h"

enum { WIDTH = 320, HEIGHT = 180, FRAMES = 60, CARS = 400 };

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

/* The host's vertex format: position, normal, colour (RGBA8 as a float's
 * bytes), 7 floats a vertex, interleaved. */
enum { VERTEX_FLOATS = 7 };

/* One tileset in the host's format: on the CPU (made on a worker), then
 * on the GPU (a vertex array per mesh). */
struct mesh_set {
    const struct tw_tileset *ts;
    float **vertices;           /* per mesh, freed once uploaded */
    GLuint *vao, *buffers;      /* per mesh; 2 buffers a mesh */
    uint64_t bytes;             /* on the GPU */
};

/* What the host keeps for a generated tile: the tile and its levels. */
struct tile_data {
    struct mesh_set tile, levels;
};

struct host {
    struct gl gl;
    struct tw_world *world;
    GLuint fbo, color, depth, program;
    GLint u_model, u_offset, u_view_proj, u_material, u_eye, u_fog;
    bool new_frame;             /* set before each tw_world_frame(): the view changed */
    const struct tw_tileset *cars;  /* the moving objects' models */
    uint64_t car_batches;       /* batches of cars drawn */
    struct mesh_set *shared;    /* shared content, uploaded when first drawn */
    size_t shared_count, shared_cap;
    atomic_ulong staged;        /* tiles made on the workers */
    uint64_t prepared, released, dropped, batches, bytes;
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

/* On any thread: ts in the host's vertex format. */
static int stage(struct mesh_set *set, const struct tw_tileset *ts)
{
    set->ts = ts;
    set->vertices = calloc(ts->mesh_count ? ts->mesh_count : 1, sizeof(float *));
    if (!set->vertices)
        return 1;
    for (uint32_t m = 0; m < ts->mesh_count; m++) {
        const struct tw_mesh *mesh = &ts->meshes[m];
        float *v = malloc(sizeof(float) * VERTEX_FLOATS * (mesh->vertex_count ? mesh->vertex_count : 1));
        if (!v)
            return 1;
        for (uint32_t k = 0; k < mesh->vertex_count; k++) {
            static const uint8_t white[4] = {255, 255, 255, 255};
            memcpy(v + VERTEX_FLOATS * k, mesh->positions + 3 * k, sizeof(float) * 3);
            memcpy(v + VERTEX_FLOATS * k + 3, mesh->normals + 3 * k, sizeof(float) * 3);
            memcpy(v + VERTEX_FLOATS * k + 6, mesh->colors ? mesh->colors + 4 * k : white, 4);
        }
        set->vertices[m] = v;
    }
    return 0;
}

static void free_staged(struct mesh_set *set)
{
    for (uint32_t m = 0; set->vertices && m < set->ts->mesh_count; m++)
        free(set->vertices[m]);
    free(set->vertices);
    set->vertices = NULL;
}

/* On the render thread: the staged set into GL buffers. */
static int upload(struct host *h, struct mesh_set *set)
{
    const struct gl *gl = &h->gl;
    const struct tw_tileset *ts = set->ts;
    const uint32_t n = ts->mesh_count;
    set->vao = calloc(n ? n : 1, sizeof(GLuint));
    set->buffers = calloc(2 * (n ? n : 1), sizeof(GLuint));
    if (!set->vao || !set->buffers)
        return 1;
    gl->GenVertexArrays((GLsizei)n, set->vao);
    gl->GenBuffers((GLsizei)(2 * n), set->buffers);
    for (uint32_t m = 0; m < n; m++) {
        const struct tw_mesh *mesh = &ts->meshes[m];
        const GLsizeiptr vbytes = (GLsizeiptr)(sizeof(float) * VERTEX_FLOATS * mesh->vertex_count);
        const GLsizeiptr ibytes = (GLsizeiptr)(sizeof(uint32_t) * 3 * mesh->triangle_count);
        const GLsizei stride = sizeof(float) * VERTEX_FLOATS;
        gl->BindVertexArray(set->vao[m]);
        gl->BindBuffer(GL_ARRAY_BUFFER, set->buffers[2 * m]);
        gl->BufferData(GL_ARRAY_BUFFER, vbytes, set->vertices[m], GL_STATIC_DRAW);
        gl->VertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, stride, (const void *)0);
        gl->VertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, stride, (const void *)12);
        gl->VertexAttribPointer(2, 4, GL_UNSIGNED_BYTE, GL_TRUE, stride, (const void *)24);
        for (GLuint a = 0; a < 3; a++)
            gl->EnableVertexAttribArray(a);
        gl->BindBuffer(GL_ELEMENT_ARRAY_BUFFER, set->buffers[2 * m + 1]);
        gl->BufferData(GL_ELEMENT_ARRAY_BUFFER, ibytes, mesh->indices, GL_STATIC_DRAW);
        set->bytes += (uint64_t)(vbytes + ibytes);
    }
    gl->BindVertexArray(0);
    free_staged(set);
    return 0;
}

static void free_set(const struct gl *gl, struct mesh_set *set)
{
    if (!set->ts)
        return;
    free_staged(set);
    if (set->vao) {
        gl->DeleteVertexArrays((GLsizei)set->ts->mesh_count, set->vao);
        gl->DeleteBuffers((GLsizei)(2 * set->ts->mesh_count), set->buffers);
    }
    free(set->vao);
    free(set->buffers);
    memset(set, 0, sizeof(*set));
}

/* tileworld's callback on a worker: the tile in the host's format. */
static void *host_prepare_worker(void *user, struct tw_cell cell, const struct tw_tileset *tile,
                                 const struct tw_tileset *levels)
{
    struct host *h = user;
    (void)cell;
    struct tile_data *t = calloc(1, sizeof(*t));
    if (!t)
        return NULL;
    if (stage(&t->tile, tile) || (levels && stage(&t->levels, levels))) {
        free_staged(&t->tile);
        free_staged(&t->levels);
        free(t);
        return NULL;
    }
    atomic_fetch_add(&h->staged, 1);
    return t;
}

/* tileworld's callback on the render thread: the tile is ready, upload it. */
static void *host_prepare(void *user, uint32_t prototype, const struct tw_tileset *tile,
                          const struct tw_tileset *levels, void *worker_data, uint64_t *bytes)
{
    struct host *h = user;
    struct tile_data *t = worker_data;
    (void)prototype;
    if (!t || t->tile.ts != tile || (levels && t->levels.ts != levels) ||
        upload(h, &t->tile) || (levels && upload(h, &t->levels))) {
        h->failed++;
        return t;
    }
    h->prepared++;
    *bytes = t->tile.bytes + t->levels.bytes;
    h->bytes += *bytes;
    return t;
}

/* tileworld's callback: a generated tile left, or was dropped before it was ready. */
static void host_release(void *user, uint32_t prototype, void *data)
{
    struct host *h = user;
    struct tile_data *t = data;
    if (prototype == TW_HOST_NOT_READY)
        h->dropped++;
    else
        h->released++;
    if (!t)
        return;
    h->bytes -= t->tile.bytes + t->levels.bytes;
    free_set(&h->gl, &t->tile);
    free_set(&h->gl, &t->levels);
    free(t);
}

/* Shared content (a fixed tileset's, a provider's shared prototypes):
 * never released; uploaded the first time it is drawn. */
static const struct mesh_set *shared_set(struct host *h, const struct tw_tileset *ts)
{
    for (size_t k = 0; k < h->shared_count; k++)
        if (h->shared[k].ts == ts)
            return &h->shared[k];
    if (h->shared_count == h->shared_cap) {
        const size_t cap = h->shared_cap ? 2 * h->shared_cap : 8;
        struct mesh_set *s = realloc(h->shared, cap * sizeof(*s));
        if (!s)
            return NULL;
        h->shared = s;
        h->shared_cap = cap;
    }
    struct mesh_set *set = &h->shared[h->shared_count];
    memset(set, 0, sizeof(*set));
    if (stage(set, ts) || upload(h, set)) {
        free_set(&h->gl, set);
        return NULL;
    }
    return &h->shared[h->shared_count++];
}

/* tileworld's callback: draw this batch now. */
static void host_draw(void *user, const struct tw_host_draw *d)
{
    struct host *h = user;
    const struct gl *gl = &h->gl;
    const struct tw_tileset *ts = NULL;
    const struct tw_prototype *proto = tw_world_level(h->world, d->prototype, d->level, &ts);
    const struct tile_data *t = d->host_data;
    const struct mesh_set *set = !proto ? NULL
                                 : t    ? (d->level == 0 ? &t->tile : &t->levels)
                                        : shared_set(h, ts);
    if (!set || set->ts != ts || !set->vao) {
        h->failed++;
        return;
    }
    h->batches++;
    h->car_batches += ts == h->cars;
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
    s.cache_budget_bytes = 224u << 20;  /* tiles leave the cache as the walk goes on */
    s.deterministic = true;
    s.get_proc = tw_context_get_proc(ctx);
    s.log = log;
    /* Cars on the streets, moving (objects: tileworld culls them with the
     * tiles they drive through, and lists them for the host to draw: a
     * batch of their cell's objects names a prototype whose instances are
     * the cars, placed, and the car models' tileset). */
    struct tw_tileset *cars = NULL;
    struct tw_traffic traffic;
    const struct tw_traffic_settings ts_cars = {.cars = CARS, .radius_m = 400.0f, .seed = 1};
    if (tw_tilesets_car_models(&log, &cars) != TW_OK ||
        tw_traffic_init(&traffic, &ts_cars, &log) != TW_OK)
        return 1;
    s.object_models = cars;
    h.cars = cars;
    if (tw_world_create(&s, &own) != TW_OK)
        return 1;
    s.host = (struct tw_host_renderer){.draw = host_draw,
                                       .prepare_worker = host_prepare_worker,
                                       .prepare = host_prepare,
                                       .release = host_release,
                                       .user = &h};
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
                                             TW_METHOD_TILEQUERY, TW_METHOD_VFC,
                                             TW_METHOD_HZB, TW_METHOD_TILEQUERY_HZB};
    const uint32_t method_count = sizeof(methods) / sizeof(methods[0]);
    static uint32_t car_own[CARS], car_host[CARS];
    for (uint32_t f = 0; f < FRAMES; f++) {
        struct tw_frame_stats so, sh;
        const enum tw_method m = methods[f % method_count];
        for (uint32_t k = 0; k < CARS; k++) {
            struct tw_traffic_car c;
            if (tw_traffic_place(&traffic, k, f / 30.0, &c) != TW_OK)
                return 1;
            const struct tw_object o = {c.pos, c.yaw, c.model};
            const int err = f == 0 ? tw_world_object_add(own, &o, &car_own[k]) |
                                         tw_world_object_add(h.world, &o, &car_host[k])
                                   : tw_world_object_update(own, car_own[k], &o) |
                                         tw_world_object_update(h.world, car_host[k], &o);
            if (err != TW_OK)
                return 1;
        }
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
            printf("frame %u %s: %llu pixels differ; triangles %llu and %llu; GPU bytes %llu "
                   "and %llu\n", f, tw_method_name(m), (unsigned long long)differ,
                   (unsigned long long)so.triangles, (unsigned long long)sh.triangles,
                   (unsigned long long)so.bytes_gpu, (unsigned long long)sh.bytes_gpu);
        /* The budget counts what the host holds, not a copy of tileworld's. */
        if (sh.bytes_gpu != h.bytes) {
            fprintf(stderr, "host-render: frame %u: the world counts %llu GPU bytes, the host "
                    "holds %llu\n", f, (unsigned long long)sh.bytes_gpu,
                    (unsigned long long)h.bytes);
            failures++;
        }
        triangles_own += so.triangles;
        triangles_host += sh.triangles;
    }
    printf("host-render: %u frames, worst frame %llu of %u pixels differ; triangles %llu "
           "(tileworld) and %llu (host); %llu batches (%llu of cars); tiles: %lu made on workers, %llu "
           "prepared, %llu released, %llu dropped before they were ready\n",
           FRAMES, (unsigned long long)worst, WIDTH * HEIGHT, (unsigned long long)triangles_own,
           (unsigned long long)triangles_host, (unsigned long long)h.batches,
           (unsigned long long)h.car_batches, (unsigned long)atomic_load(&h.staged), (unsigned long long)h.prepared,
           (unsigned long long)h.released, (unsigned long long)h.dropped);
    if (worst > (uint64_t)WIDTH * HEIGHT / 1000) {
        fprintf(stderr, "host-render: the host's image differs from tileworld's in %llu pixels\n",
                (unsigned long long)worst);
        failures++;
    }
    if (h.car_batches == 0) {
        fprintf(stderr, "host-render: no batch of cars was drawn\n");
        failures++;
    }
    if (h.failed || h.batches == 0 || h.released == 0) {
        fprintf(stderr, "host-render: %d batches not drawn, %llu drawn, %llu releases\n", h.failed,
                (unsigned long long)h.batches, (unsigned long long)h.released);
        failures++;
    }
    tw_path_finish(&path);
    tw_world_destroy(own);
    tw_world_destroy(h.world);   /* releases every generated tile still held */
    /* Every tile made on a worker was prepared and released, or dropped. */
    if (h.bytes != 0 || h.prepared != h.released ||
        atomic_load(&h.staged) != h.prepared + h.dropped) {
        fprintf(stderr, "host-render: %llu bytes still held after the world; %lu tiles made, "
                "%llu prepared, %llu released, %llu dropped\n", (unsigned long long)h.bytes,
                (unsigned long)atomic_load(&h.staged), (unsigned long long)h.prepared,
                (unsigned long long)h.released, (unsigned long long)h.dropped);
        failures++;
    }
    for (size_t k = 0; k < h.shared_count; k++)
        free_set(&h.gl, &h.shared[k]);
    free(h.shared);
    h.gl.DeleteProgram(h.program);
    h.gl.DeleteFramebuffers(1, &h.fbo);
    h.gl.DeleteRenderbuffers(1, &h.color);
    h.gl.DeleteRenderbuffers(1, &h.depth);
    tw_tilesets_provider_destroy(gen);
    tw_tileset_destroy(cars);
    tw_context_destroy(ctx);
    return failures ? 1 : 0;
}
