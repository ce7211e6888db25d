/* The renderer and the GL query backend (renderer.h). */
#include "runtime/renderer.h"
#include "tiles/array.h"
#include "tiles/clock.h"
#include "tiles/tiles-internal.h"

#include <assert.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

enum mode { MODE_NONE, MODE_DRAW, MODE_QUERY };

/* One uploaded tileset: every mesh in one vertex and one index buffer. */
struct gpu_buffers {
    const struct tw_tileset *ts;    /* borrowed until released */
    GLuint vao, vbo, ibo;
    uint32_t *base_vertex, *first_index;    /* per mesh */
    uint32_t first_content;         /* its prototypes' contents: first_content + p */
    uint64_t bytes;                 /* of the GL buffers */
    bool live;
};

struct gpu_content {
    uint32_t buffers;
    uint32_t proto;
    const struct tw_bvh *bvh;       /* the prototype's, borrowed */
    bool live;
};

struct tw_renderer {
    struct tw_gl gl;
    struct tw_log log;
    const struct tw_tileset *ts;
    uint32_t width, height;
    bool out_of_memory;         /* a shader failed for the driver's memory (said once) */

    GLuint program;
    GLint u_view_proj, u_model, u_offset, u_color, u_eye, u_fog;

    /* Uploaded tilesets (a shared tileset, or one generated tile each) and
     * the contents they hold: content c draws prototype contents[c].proto of
     * buffers contents[c].buffers. Freed slots go on free lists. */
    struct gpu_buffers *buffers;
    uint32_t buffer_count, buffer_cap, *free_buffers, free_buffer_count;
    struct gpu_content *contents;
    uint32_t content_count, content_cap, *free_contents, free_content_count;
    uint64_t gpu_bytes;
    GLuint bound_vao;

    GLuint box_vao, box_vbo, box_ibo;
    /* Query boxes: one instanced draw per query, each box an instance whose
     * corners (view-relative, margin included) come from a ring buffer of
     * QUERY_RING_BOXES boxes, orphaned when it wraps. */
    GLuint box_program;
    GLint ub_view_proj;
    GLuint query_vao, query_ring;
    uint32_t query_ring_next;          /* next free box of the ring */
    float *query_corners;              /* staging: min, max per box */
    uint32_t query_corner_cap;         /* boxes */

    GLuint fbo, color_rb, depth_rb;

    /* backend_draw's scratch: clusters grouped by instance (one multi-draw
     * each), run_seen[i] == run_stamp marking instances met in this call. */
    uint32_t *run_next, *run_clusters, run_cap;
    GLsizei *run_counts;
    const void **run_offsets;
    GLint *run_bases;
    uint32_t *run_seen, *run_first, *run_last, *run_order, run_instance_cap, run_stamp;

    GLuint id_program;
    GLint ui_view_proj, ui_model, ui_offset, ui_id;
    GLuint id_fbo, id_rb, id_depth_rb;

    /* Depth convention: reversed float depth (near = 1, far = 0) when
     * glClipControl is there, else standard 24-bit depth (near = 0). */
    bool reversed_z;

    /* Debug drawing (tw_renderer_draw_debug): edges as screen-space quads,
     * translucent faces. */
    GLuint line_program, fill_program;
    GLint ul_view_proj, ul_min, ul_max, ul_color, ul_viewport;
    GLint uf_view_proj, uf_min, uf_max, uf_color;

    /* Query objects: handle h (> 0) names queries[h - 1]; released handles
     * go on a free list and are reused. */
    GLuint *queries;
    uint32_t *free_queries;
    uint32_t query_count, free_count, query_cap;

    enum mode mode;
    struct tw_render_counters counters;
    float eye[3];

    bool recording;
    struct tw_drawn_cluster *drawn;
    size_t drawn_count, drawn_cap;

    /* Recording of query boxes for debugging: query_record[h - 1] is the
     * index + 1 of handle h's first record this frame (0: none). */
    bool recording_queries;
    const struct tw_box *tile_query_box;   /* queries on this box are tile queries */
    bool deterministic;    /* no query is ready before it is waited on */
    GLenum query_target;   /* GL_ANY_SAMPLES_PASSED, or GL_SAMPLES_PASSED to count them */
    float mutate_shrink;   /* testing: query boxes shrunk by this fraction */

    /* The host's GL state, saved while the library is inside a call. */
    struct tw_gl_state host_state;
    uint32_t entered;
    bool has_clip_control;
    bool gl_loaded;        /* every entry point of the table is there */
    struct tw_renderer_query_box *query_boxes;
    size_t query_box_count, query_box_cap;
    uint32_t *query_record;
};

double tw_renderer_cpu_ms(void)
{
    struct timespec t;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return (double)t.tv_sec * 1e3 + (double)t.tv_nsec * 1e-6;
}

static const char *const scene_vs =
    "#version 330 core\n"
    "layout(location = 0) in vec3 a_pos;\n"
    "layout(location = 1) in vec3 a_normal;\n"
    "layout(location = 2) in vec4 a_color;\n"
    "uniform mat4 u_view_proj;\n"
    "uniform vec4 u_model[3];\n"
    "uniform vec3 u_offset;\n"
    "out vec3 v_normal;\n"
    "out vec3 v_pos;\n"
    "out vec3 v_color;\n"
    "invariant gl_Position;\n"
    "void main() {\n"
    "    vec4 p = vec4(a_pos, 1.0);\n"
    "    vec3 w = vec3(dot(u_model[0], p), dot(u_model[1], p), dot(u_model[2], p)) + u_offset;\n"
    "    v_normal = vec3(dot(u_model[0].xyz, a_normal), dot(u_model[1].xyz, a_normal),\n"
    "                    dot(u_model[2].xyz, a_normal));\n"
    "    v_pos = w;\n"
    "    v_color = a_color.rgb;\n"
    "    gl_Position = u_view_proj * vec4(w, 1.0);\n"
    "}\n";

static const char *const scene_fs =
    "#version 330 core\n"
    "in vec3 v_normal;\n"
    "in vec3 v_pos;\n"
    "in vec3 v_color;\n"
    "uniform vec4 u_color;\n"
    "uniform vec3 u_eye;\n"
    "uniform vec2 u_fog;\n"
    "out vec4 o_color;\n"
    "void main() {\n"
    "    vec3 n = normalize(v_normal);\n"
    "    vec3 sun = normalize(vec3(0.45, 0.8, 0.3));\n"
    "    float light = 0.38 + 0.62 * max(dot(n, sun), 0.0) + 0.08 * max(-n.x, 0.0);\n"
    "    vec3 c = u_color.rgb * v_color * light;\n"
    "    float f = clamp((distance(v_pos, u_eye) - u_fog.x) / u_fog.y, 0.0, 0.85);\n"
    "    o_color = vec4(mix(c, vec3(0.70, 0.80, 0.92), f), 1.0);\n"
    "}\n";

/* The ID pass shares scene_vs (whose position is invariant) and the normal
 * pass's depth function, culling and clip control, and has no geometry
 * shader: it rasterises exactly the fragments, at exactly the depths, that
 * the normal pass would for the same clusters (DESIGN §8), so that the
 * oracle sees what the user sees. */
static const char *const id_fs =
    "#version 330 core\n"
    "uniform uint u_id;\n"
    "out uint o_id;\n"
    "void main() {\n"
    "    o_id = u_id;\n"
    "}\n";

static const char *const box_vs =
    "#version 330 core\n"
    "layout(location = 0) in vec3 a_corner;\n"
    "uniform mat4 u_view_proj;\n"
    "uniform vec3 u_min;\n"
    "uniform vec3 u_max;\n"
    "void main() {\n"
    "    gl_Position = u_view_proj * vec4(mix(u_min, u_max, a_corner), 1.0);\n"
    "}\n";

/* Query boxes: the box of each instance from per-instance attributes. */
static const char *const query_vs =
    "#version 330 core\n"
    "layout(location = 0) in vec3 a_corner;\n"
    "layout(location = 1) in vec3 i_min;\n"
    "layout(location = 2) in vec3 i_max;\n"
    "uniform mat4 u_view_proj;\n"
    "void main() {\n"
    "    gl_Position = u_view_proj * vec4(mix(i_min, i_max, a_corner), 1.0);\n"
    "}\n";

#define QUERY_RING_BOXES 16384u

static const char *const box_fs =
    "#version 330 core\n"
    "out vec4 o_color;\n"
    "void main() { o_color = vec4(1.0); }\n";

/* Debug edges: each line becomes a quad u_width pixels wide, so that boxes
 * stay readable where a core profile offers only 1-pixel lines. An end
 * behind the eye is first moved to just in front of it. */
static const char *const line_gs =
    "#version 330 core\n"
    "layout(lines) in;\n"
    "layout(triangle_strip, max_vertices = 4) out;\n"
    "uniform vec3 u_viewport;\n"   /* width, height in pixels; line width in pixels */
    "void main() {\n"
    "    vec4 a = gl_in[0].gl_Position, b = gl_in[1].gl_Position;\n"
    "    const float eps = 1e-3;\n"
    "    if (a.w < eps && b.w < eps) return;\n"
    "    if (a.w < eps) a = mix(a, b, (eps - a.w) / (b.w - a.w));\n"
    "    else if (b.w < eps) b = mix(b, a, (eps - b.w) / (a.w - b.w));\n"
    "    vec2 d = (b.xy / b.w - a.xy / a.w) * u_viewport.xy;\n"
    "    if (dot(d, d) < 1e-12) d = vec2(1.0, 0.0);\n"
    "    vec2 n = normalize(vec2(-d.y, d.x)) * u_viewport.z / u_viewport.xy;\n"
    "    gl_Position = a + vec4(n * a.w, 0.0, 0.0); EmitVertex();\n"
    "    gl_Position = a - vec4(n * a.w, 0.0, 0.0); EmitVertex();\n"
    "    gl_Position = b + vec4(n * b.w, 0.0, 0.0); EmitVertex();\n"
    "    gl_Position = b - vec4(n * b.w, 0.0, 0.0); EmitVertex();\n"
    "    EndPrimitive();\n"
    "}\n";

static const char *const color_fs =
    "#version 330 core\n"
    "uniform vec4 u_color;\n"
    "out vec4 o_color;\n"
    "void main() { o_color = u_color; }\n";

static GLuint compile(struct tw_renderer *r, GLenum type, const char *src)
{
    const struct tw_gl *gl = &r->gl;
    GLuint s = gl->CreateShader(type);
    gl->ShaderSource(s, 1, &src, NULL);
    gl->CompileShader(s);
    GLint ok = 0;
    gl->GetShaderiv(s, GL_COMPILE_STATUS, &ok);
    if (!ok) {
        char msg[1024] = "";
        gl->GetShaderInfoLog(s, sizeof(msg), NULL, msg);
        if (gl->GetError() == GL_OUT_OF_MEMORY && !r->out_of_memory) {
            r->out_of_memory = true;
            tw_log_printf(&r->log, TW_LOG_ERROR, "the OpenGL driver ran out of memory "
                          "compiling a shader");
        } else if (!r->out_of_memory) {
            tw_log_printf(&r->log, TW_LOG_ERROR, "a shader does not compile (a bug): %s", msg);
        }
        gl->DeleteShader(s);
        return 0;
    }
    return s;
}

static GLuint link_program(struct tw_renderer *r, const char *vs_src, const char *gs_src,
                           const char *fs_src)
{
    const struct tw_gl *gl = &r->gl;
    GLuint vs = compile(r, GL_VERTEX_SHADER, vs_src);
    GLuint gs = gs_src ? compile(r, GL_GEOMETRY_SHADER, gs_src) : 0;
    GLuint fs = compile(r, GL_FRAGMENT_SHADER, fs_src);
    GLuint p = 0;
    if (vs && fs && (gs || !gs_src)) {
        p = gl->CreateProgram();
        gl->AttachShader(p, vs);
        if (gs)
            gl->AttachShader(p, gs);
        gl->AttachShader(p, fs);
        gl->LinkProgram(p);
        GLint ok = 0;
        gl->GetProgramiv(p, GL_LINK_STATUS, &ok);
        if (!ok) {
            char msg[1024] = "";
            gl->GetProgramInfoLog(p, sizeof(msg), NULL, msg);
            if (gl->GetError() == GL_OUT_OF_MEMORY && !r->out_of_memory) {
                r->out_of_memory = true;
                tw_log_printf(&r->log, TW_LOG_ERROR, "the OpenGL driver ran out of memory "
                              "linking a shader program");
            } else if (!r->out_of_memory) {
                tw_log_printf(&r->log, TW_LOG_ERROR, "a shader program does not link (a bug): %s",
                              msg);
            }
            gl->DeleteProgram(p);
            p = 0;
        }
    }
    if (vs)
        gl->DeleteShader(vs);
    if (gs)
        gl->DeleteShader(gs);
    if (fs)
        gl->DeleteShader(fs);
    return p;
}

/* Bytes of one vertex in a vertex buffer: its position (three floats), its
 * normal (GL_INT_2_10_10_10_REV) and its colour (RGBA8), as
 * tw_tileset_geometry_bytes() counts them. */
#define VERTEX_BYTES TW_TILESET_GPU_VERTEX_BYTES
_Static_assert(TW_TILESET_GPU_VERTEX_BYTES == 12 + 4 + 4, "the vertex layout of upload_buffers");

/* n scaled to unit length, as signed normalised 10-bit x, y, z (x in the
 * low bits); a zero vector stays zero. The shader normalises after the
 * instance's transform, so only the direction matters. */
static uint32_t pack_normal(const float n[3])
{
    const float len = sqrtf(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    uint32_t word = 0;
    for (int k = 0; k < 3; k++) {
        const float x = len > 0.0f ? fminf(fmaxf(n[k] / len, -1.0f), 1.0f) : 0.0f;
        word |= ((uint32_t)(int32_t)lrintf(x * 511.0f) & 0x3ffu) << (10 * k);
    }
    return word;
}

/* Copies ts's meshes into b's GL buffers. */
static int upload_buffers(struct tw_renderer *r, const struct tw_tileset *ts, struct gpu_buffers *b)
{
    const struct tw_gl *gl = &r->gl;
    uint64_t vertices = 0, indices = 0;
    for (uint32_t k = 0; k < ts->mesh_count; k++) {
        vertices += ts->meshes[k].vertex_count;
        indices += 3ull * ts->meshes[k].triangle_count;
    }
    if (vertices > UINT32_MAX || indices > UINT32_MAX / 4) {
        tw_log_printf(&r->log, TW_LOG_ERROR, "tileset '%s' is too large to upload (%llu vertices)",
                      ts->name, (unsigned long long)vertices);
        return TW_ERR_LIMIT;
    }
    /* One allocation for both (a tile's few long-lived small arrays would
     * otherwise leave holes in the heap when it goes). */
    b->base_vertex = calloc(2 * (size_t)(ts->mesh_count ? ts->mesh_count : 1), sizeof(uint32_t));
    b->first_index = b->base_vertex ? b->base_vertex + (ts->mesh_count ? ts->mesh_count : 1)
                                    : NULL;
    uint8_t *interleaved = malloc((size_t)VERTEX_BYTES * (vertices ? vertices : 1));
    uint32_t *index_data = malloc(sizeof(uint32_t) * (indices ? indices : 1));
    int err = TW_OK;
    if (!b->base_vertex || !b->first_index || !interleaved || !index_data) {
        err = TW_ERR_NOMEM;
        goto out;
    }
    uint32_t vbase = 0, ibase = 0;
    for (uint32_t k = 0; k < ts->mesh_count; k++) {
        const struct tw_mesh *m = &ts->meshes[k];
        b->base_vertex[k] = vbase;
        b->first_index[k] = ibase;
        static const uint8_t white[4] = {255, 255, 255, 255};
        for (uint32_t v = 0; v < m->vertex_count; v++) {
            uint8_t *to = interleaved + (size_t)VERTEX_BYTES * (vbase + v);
            const uint32_t normal = pack_normal(m->normals + 3 * (size_t)v);
            memcpy(to, m->positions + 3 * (size_t)v, 12);
            memcpy(to + 12, &normal, 4);
            memcpy(to + 16, m->colors ? m->colors + 4 * (size_t)v : white, 4);
        }
        memcpy(index_data + ibase, m->indices, sizeof(uint32_t) * 3 * (size_t)m->triangle_count);
        vbase += m->vertex_count;
        ibase += 3 * m->triangle_count;
    }
    gl->GenVertexArrays(1, &b->vao);
    gl->BindVertexArray(b->vao);
    gl->GenBuffers(1, &b->vbo);
    gl->BindBuffer(GL_ARRAY_BUFFER, b->vbo);
    gl->BufferData(GL_ARRAY_BUFFER, (GLsizeiptr)(VERTEX_BYTES * vertices), interleaved,
                   GL_STATIC_DRAW);
    gl->GenBuffers(1, &b->ibo);
    gl->BindBuffer(GL_ELEMENT_ARRAY_BUFFER, b->ibo);
    gl->BufferData(GL_ELEMENT_ARRAY_BUFFER, (GLsizeiptr)(sizeof(uint32_t) * indices), index_data,
                   GL_STATIC_DRAW);
    gl->EnableVertexAttribArray(0);
    gl->VertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, VERTEX_BYTES, (const void *)0);
    gl->EnableVertexAttribArray(1);
    gl->VertexAttribPointer(1, 4, GL_INT_2_10_10_10_REV, GL_TRUE, VERTEX_BYTES, (const void *)12);
    gl->EnableVertexAttribArray(2);
    gl->VertexAttribPointer(2, 4, GL_UNSIGNED_BYTE, GL_TRUE, VERTEX_BYTES, (const void *)16);
    gl->BindVertexArray(0);
    r->bound_vao = 0;
    b->bytes = (uint64_t)VERTEX_BYTES * vertices + sizeof(uint32_t) * indices;
    /* Buffers without storage would draw nothing, silently: the driver's
     * memory, said by the caller as any other (it knows what the tileset is). */
    if (gl->GetError() == GL_OUT_OF_MEMORY)
        err = TW_ERR_NOMEM;
out:
    free(interleaved);
    free(index_data);
    return err;
}

static void free_buffers(struct tw_renderer *r, struct gpu_buffers *b)
{
    const struct tw_gl *gl = &r->gl;
    if (b->vbo)
        gl->DeleteBuffers(1, &b->vbo);
    if (b->ibo)
        gl->DeleteBuffers(1, &b->ibo);
    if (b->vao) {
        if (r->bound_vao == b->vao)
            r->bound_vao = 0;
        gl->DeleteVertexArrays(1, &b->vao);
    }
    free(b->base_vertex); /* first_index is in the same block */
    memset(b, 0, sizeof(*b));
}

/* A free slot of an array of slots with a free list: *index, or an error. */
static int take_slot(void **array, uint32_t *count, uint32_t *cap, uint32_t **free_list,
                     uint32_t *free_count, size_t elem, uint32_t *index)
{
    if (*free_count > 0) {
        *index = (*free_list)[--*free_count];
        return TW_OK;
    }
    if (*count == *cap) {
        const uint32_t n = *cap ? 2 * *cap : 64;
        void *a = realloc(*array, elem * n);
        if (!a)
            return TW_ERR_NOMEM;
        *array = a;
        uint32_t *f = realloc(*free_list, sizeof(*f) * n);
        if (!f)
            return TW_ERR_NOMEM;
        *free_list = f;
        *cap = n;
    }
    *index = (*count)++;
    return TW_OK;
}

/* Contents first .. first + n - 1, consecutive: taken from the end when a
 * free run is not at hand (n > 1 is only the shared tileset, at creation). */
static int take_contents(struct tw_renderer *r, uint32_t n, uint32_t *first)
{
    if (n == 1)
        return take_slot((void **)&r->contents, &r->content_count, &r->content_cap,
                         &r->free_contents, &r->free_content_count, sizeof(*r->contents), first);
    while (r->content_count + n > r->content_cap) {
        const uint32_t cap = r->content_cap ? 2 * r->content_cap : 64;
        struct gpu_content *c = realloc(r->contents, sizeof(*c) * cap);
        if (!c)
            return TW_ERR_NOMEM;
        r->contents = c;
        uint32_t *f = realloc(r->free_contents, sizeof(*f) * cap);
        if (!f)
            return TW_ERR_NOMEM;
        r->free_contents = f;
        r->content_cap = cap;
    }
    *first = r->content_count;
    r->content_count += n;
    return TW_OK;
}

int tw_renderer_upload(struct tw_renderer *r, const struct tw_tileset *ts,
                       const struct tw_bvh *const *bvhs, uint32_t *first_content, uint64_t *bytes)
{
    if (!ts || !ts->finished || ts->prototype_count == 0)
        return TW_ERR_INVALID;
    uint32_t bi, first;
    int err = take_slot((void **)&r->buffers, &r->buffer_count, &r->buffer_cap, &r->free_buffers,
                        &r->free_buffer_count, sizeof(*r->buffers), &bi);
    if (err)
        return err;
    struct gpu_buffers *b = &r->buffers[bi];
    memset(b, 0, sizeof(*b));
    err = upload_buffers(r, ts, b);
    if (!err)
        err = take_contents(r, ts->prototype_count, &first);
    if (err) {
        free_buffers(r, b);
        r->free_buffers[r->free_buffer_count++] = bi;
        return err;
    }
    b->ts = ts;
    b->first_content = first;
    b->live = true;
    for (uint32_t p = 0; p < ts->prototype_count; p++)
        r->contents[first + p] = (struct gpu_content){bi, p, bvhs ? bvhs[p] : NULL, true};
    r->gpu_bytes += b->bytes;
    *first_content = first;
    if (bytes)
        *bytes = b->bytes;
    return TW_OK;
}

void tw_renderer_release(struct tw_renderer *r, uint32_t first_content)
{
    if (first_content >= r->content_count || !r->contents[first_content].live)
        return;
    const uint32_t bi = r->contents[first_content].buffers;
    struct gpu_buffers *b = &r->buffers[bi];
    for (uint32_t p = 0; p < b->ts->prototype_count; p++) {
        r->contents[b->first_content + p].live = false;
        r->free_contents[r->free_content_count++] = b->first_content + p;
    }
    r->gpu_bytes -= b->bytes;
    free_buffers(r, b);
    r->free_buffers[r->free_buffer_count++] = bi;
}

const struct tw_prototype *tw_renderer_content(const struct tw_renderer *r, uint32_t content,
                                               const struct tw_bvh **bvh)
{
    if (content >= r->content_count || !r->contents[content].live)
        return NULL;
    const struct gpu_content *c = &r->contents[content];
    if (bvh)
        *bvh = c->bvh;
    return &r->buffers[c->buffers].ts->prototypes[c->proto];
}

uint64_t tw_renderer_gpu_bytes(const struct tw_renderer *r)
{
    return r->gpu_bytes;
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

    /* The query VAO: the same corners and faces, boxes per instance. */
    gl->GenVertexArrays(1, &r->query_vao);
    gl->BindVertexArray(r->query_vao);
    gl->BindBuffer(GL_ARRAY_BUFFER, r->box_vbo);
    gl->BindBuffer(GL_ELEMENT_ARRAY_BUFFER, r->box_ibo);
    gl->EnableVertexAttribArray(0);
    gl->VertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 12, (const void *)0);
    gl->GenBuffers(1, &r->query_ring);
    gl->BindBuffer(GL_ARRAY_BUFFER, r->query_ring);
    gl->BufferData(GL_ARRAY_BUFFER, (GLsizeiptr)(QUERY_RING_BOXES * 24u), NULL, GL_STREAM_DRAW);
    for (GLuint a = 1; a <= 2; a++) {
        gl->EnableVertexAttribArray(a);
        gl->VertexAttribDivisor(a, 1);
    }
    gl->BindVertexArray(0);
}

/* An offscreen framebuffer that cannot be completed: the driver's memory,
 * most often (a software rasteriser under an address-space limit). */
static int framebuffer_failed(struct tw_renderer *r, const char *what)
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
    gl->GenRenderbuffers(1, &r->depth_rb);
    gl->BindRenderbuffer(GL_RENDERBUFFER, r->depth_rb);
    const GLenum depth_format = r->reversed_z ? GL_DEPTH_COMPONENT32F : GL_DEPTH_COMPONENT24;
    gl->RenderbufferStorage(GL_RENDERBUFFER, depth_format, (GLsizei)r->width,
                            (GLsizei)r->height);
    gl->FramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER,
                                r->depth_rb);
    if (gl->CheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
        return framebuffer_failed(r, "image");
    /* The oracle's object-ID buffer: one uint per pixel, its own depth. */
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
        return framebuffer_failed(r, "object-ID image");
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
    /* Reversed depth needs [0, 1] clip depth: core since 4.5. */
    r->has_clip_control = gl->ClipControl &&
                          (major * 10 + minor >= 45 || has_extension(gl, "GL_ARB_clip_control"));
    r->reversed_z = r->has_clip_control;
    tw_renderer_enter(r);
    if (!r->reversed_z) {
        tw_log_printf(&r->log, TW_LOG_WARN,
                      "OpenGL %d.%d has no glClipControl: standard 24-bit depth instead of "
                      "reversed float depth (less precision far away)", major, minor);
    }
    r->program = link_program(r, scene_vs, NULL, scene_fs);
    r->box_program = link_program(r, query_vs, NULL, box_fs);
    r->id_program = link_program(r, scene_vs, NULL, id_fs);
    r->line_program = link_program(r, box_vs, line_gs, color_fs);
    r->fill_program = link_program(r, box_vs, NULL, color_fs);
    if (!r->program || !r->box_program || !r->id_program || !r->line_program ||
        !r->fill_program) {
        err = r->out_of_memory ? TW_ERR_NOMEM : TW_ERR_GL;
        goto fail;
    }
    r->u_view_proj = gl->GetUniformLocation(r->program, "u_view_proj");
    r->u_model = gl->GetUniformLocation(r->program, "u_model");
    r->u_offset = gl->GetUniformLocation(r->program, "u_offset");
    r->u_color = gl->GetUniformLocation(r->program, "u_color");
    r->u_eye = gl->GetUniformLocation(r->program, "u_eye");
    r->u_fog = gl->GetUniformLocation(r->program, "u_fog");
    r->ui_view_proj = gl->GetUniformLocation(r->id_program, "u_view_proj");
    r->ui_model = gl->GetUniformLocation(r->id_program, "u_model");
    r->ui_offset = gl->GetUniformLocation(r->id_program, "u_offset");
    r->ui_id = gl->GetUniformLocation(r->id_program, "u_id");
    r->ul_view_proj = gl->GetUniformLocation(r->line_program, "u_view_proj");
    r->ul_min = gl->GetUniformLocation(r->line_program, "u_min");
    r->ul_max = gl->GetUniformLocation(r->line_program, "u_max");
    r->ul_color = gl->GetUniformLocation(r->line_program, "u_color");
    r->ul_viewport = gl->GetUniformLocation(r->line_program, "u_viewport");
    r->uf_view_proj = gl->GetUniformLocation(r->fill_program, "u_view_proj");
    r->uf_min = gl->GetUniformLocation(r->fill_program, "u_min");
    r->uf_max = gl->GetUniformLocation(r->fill_program, "u_max");
    r->uf_color = gl->GetUniformLocation(r->fill_program, "u_color");
    r->ub_view_proj = gl->GetUniformLocation(r->box_program, "u_view_proj");
    upload_box(r);
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

const struct tw_gl *tw_renderer_gl(const struct tw_renderer *r)
{
    return &r->gl;
}

void tw_renderer_enter(struct tw_renderer *r)
{
    if (r->entered++ > 0)
        return;
    tw_gl_state_enter(&r->gl, r->has_clip_control, &r->host_state);
    r->bound_vao = 0;
    if (r->reversed_z)
        r->gl.ClipControl(GL_LOWER_LEFT, GL_ZERO_TO_ONE);
    r->mode = MODE_NONE;
}

void tw_renderer_leave(struct tw_renderer *r)
{
    if (r->entered == 0 || --r->entered > 0)
        return;
    tw_gl_state_leave(&r->gl, r->has_clip_control, &r->host_state);
    r->mode = MODE_NONE;
}

void tw_renderer_destroy(struct tw_renderer *r)
{
    if (!r)
        return;
    const struct tw_gl *gl = &r->gl;
    if (r->gl_loaded) {
        tw_renderer_enter(r);
        if (r->query_count)
            gl->DeleteQueries((GLsizei)r->query_count, r->queries);
        for (uint32_t b = 0; b < r->buffer_count; b++)
            if (r->buffers[b].live)
                free_buffers(r, &r->buffers[b]);
        gl->DeleteBuffers(1, &r->box_vbo);
        gl->DeleteBuffers(1, &r->box_ibo);
        gl->DeleteVertexArrays(1, &r->box_vao);
        gl->DeleteVertexArrays(1, &r->query_vao);
        gl->DeleteBuffers(1, &r->query_ring);
        gl->DeleteRenderbuffers(1, &r->color_rb);
        gl->DeleteRenderbuffers(1, &r->depth_rb);
        gl->DeleteFramebuffers(1, &r->fbo);
        gl->DeleteRenderbuffers(1, &r->id_rb);
        gl->DeleteRenderbuffers(1, &r->id_depth_rb);
        gl->DeleteFramebuffers(1, &r->id_fbo);
        if (r->id_program)
            gl->DeleteProgram(r->id_program);
        if (r->program)
            gl->DeleteProgram(r->program);
        if (r->box_program)
            gl->DeleteProgram(r->box_program);
        if (r->line_program)
            gl->DeleteProgram(r->line_program);
        if (r->fill_program)
            gl->DeleteProgram(r->fill_program);
        tw_renderer_leave(r);
    }
    free(r->query_boxes);
    free(r->query_corners);
    free(r->run_next);
    free(r->run_clusters);
    free(r->run_counts);
    free(r->run_offsets);
    free(r->run_bases);
    free(r->run_seen);
    free(r->run_first);
    free(r->run_last);
    free(r->run_order);
    free(r->query_record);
    free(r->drawn);
    free(r->queries);
    free(r->free_queries);
    free(r->buffers);
    free(r->free_buffers);
    free(r->contents);
    free(r->free_contents);
    free(r);
}

void tw_renderer_begin_frame(struct tw_renderer *r, const struct tw_view *v)
{
    const struct tw_gl *gl = &r->gl;
    memset(&r->counters, 0, sizeof(r->counters));
    r->drawn_count = 0;
    memcpy(r->eye, v->eye, sizeof(r->eye));
    gl->BindFramebuffer(GL_FRAMEBUFFER, r->fbo);
    gl->Viewport(0, 0, (GLsizei)r->width, (GLsizei)r->height);
    gl->DepthMask(GL_TRUE);
    gl->ColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
    gl->ClearColor(0.70f, 0.80f, 0.92f, 1.0f);
    gl->ClearDepth(r->reversed_z ? 0.0 : 1.0);
    gl->Clear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    gl->Enable(GL_DEPTH_TEST);
    gl->DepthFunc(r->reversed_z ? GL_GEQUAL : GL_LEQUAL);
    const float *view_proj = r->reversed_z ? v->view_proj_rz : v->view_proj;
    gl->UseProgram(r->box_program);
    gl->UniformMatrix4fv(r->ub_view_proj, 1, GL_FALSE, view_proj);
    gl->UseProgram(r->program);
    gl->UniformMatrix4fv(r->u_view_proj, 1, GL_FALSE, view_proj);
    gl->Uniform3fv(r->u_eye, 1, v->eye);
    const float fog[2] = {0.45f * v->view_distance, 0.9f * v->view_distance};
    gl->Uniform2fv(r->u_fog, 1, fog);
    r->mode = MODE_NONE;
    if (r->query_box_count) {
        for (size_t k = 0; k < r->query_box_count; k++)
            r->query_record[r->query_boxes[k].query - 1] = 0;
        r->query_box_count = 0;
    }
}

void tw_renderer_end_frame(struct tw_renderer *r)
{
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
    r->mode = MODE_NONE;   /* the next draw or query sets its own masks */
}

static void enter_draw_mode(struct tw_renderer *r)
{
    if (r->mode == MODE_DRAW)
        return;
    const struct tw_gl *gl = &r->gl;
    gl->UseProgram(r->program);
    r->bound_vao = 0;
    gl->ColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
    gl->DepthMask(GL_TRUE);
    gl->Enable(GL_CULL_FACE);
    gl->CullFace(GL_BACK);
    r->mode = MODE_DRAW;
}

static void enter_query_mode(struct tw_renderer *r)
{
    if (r->mode == MODE_QUERY)
        return;
    const struct tw_gl *gl = &r->gl;
    gl->UseProgram(r->box_program);
    gl->BindVertexArray(r->query_vao);
    r->bound_vao = r->query_vao;
    gl->ColorMask(GL_FALSE, GL_FALSE, GL_FALSE, GL_FALSE);
    gl->DepthMask(GL_FALSE);
    /* The eye is never inside a queried box (the near-plane rule,
     * tw_cull_near_box): its near faces cover its whole image and pass
     * wherever a far face would. Faces are wound inwards, so the near ones
     * are the back faces. */
    gl->Enable(GL_CULL_FACE);
    gl->CullFace(GL_FRONT);
    r->mode = MODE_QUERY;
}

static void record(struct tw_renderer *r, struct tw_cell cell, uint32_t prototype,
                   const uint32_t *clusters, uint32_t count)
{
    if (tw_array_reserve((void **)&r->drawn, &r->drawn_cap, r->drawn_count + count,
                         sizeof(*r->drawn), 4096)) {
        tw_log_printf(&r->log, TW_LOG_ERROR, "out of memory recording draws");
        return;
    }
    for (uint32_t k = 0; k < count; k++)
        r->drawn[r->drawn_count++] = (struct tw_drawn_cluster){cell, prototype, clusters[k]};
}

/* The buffers and prototype of content, with its vertex array bound. */
static const struct gpu_buffers *bind_content(struct tw_renderer *r, uint32_t content,
                                              const struct tw_prototype **proto)
{
    assert(content < r->content_count && r->contents[content].live);
    const struct gpu_content *c = &r->contents[content];
    const struct gpu_buffers *b = &r->buffers[c->buffers];
    if (r->bound_vao != b->vao) {
        r->gl.BindVertexArray(b->vao);
        r->bound_vao = b->vao;
    }
    *proto = &b->ts->prototypes[c->proto];
    return b;
}

/* Grows *p to n elements of elem bytes; false (and *p as it was) on failure. */
static bool regrow(void *p, size_t n, size_t elem)
{
    void *q = realloc(*(void **)p, n * elem);
    if (q)
        *(void **)p = q;
    return q != NULL;
}

/* Scratch of backend_draw for count clusters of a prototype of instances
 * instances; false if it cannot be had (one draw per cluster then). */
static bool multi_draw_room(struct tw_renderer *r, uint32_t count, uint32_t instances)
{
    if (count > r->run_cap) {
        if (!regrow(&r->run_next, count, sizeof(*r->run_next)) ||
            !regrow(&r->run_clusters, count, sizeof(*r->run_clusters)) ||
            !regrow(&r->run_counts, count, sizeof(*r->run_counts)) ||
            !regrow(&r->run_offsets, count, sizeof(*r->run_offsets)) ||
            !regrow(&r->run_bases, count, sizeof(*r->run_bases)))
            return false;
        r->run_cap = count;
    }
    if (instances > r->run_instance_cap) {
        if (!regrow(&r->run_seen, instances, sizeof(*r->run_seen)) ||
            !regrow(&r->run_first, instances, sizeof(*r->run_first)) ||
            !regrow(&r->run_last, instances, sizeof(*r->run_last)) ||
            !regrow(&r->run_order, instances, sizeof(*r->run_order)))
            return false;
        memset(r->run_seen + r->run_instance_cap, 0,
               (instances - r->run_instance_cap) * sizeof(*r->run_seen));
        r->run_instance_cap = instances;
    }
    if (r->run_stamp == UINT32_MAX) {
        memset(r->run_seen, 0, r->run_instance_cap * sizeof(*r->run_seen));
        r->run_stamp = 0;
    }
    return true;
}

/* Draws n clusters of one instance: one call (a multi-draw when
 * multi, else one draw per cluster). */
static void draw_run(struct tw_renderer *r, const struct tw_tileset *ts,
                     const struct gpu_buffers *b, const struct tw_prototype *proto,
                     const uint32_t *clusters, uint32_t n, bool multi)
{
    const struct tw_gl *gl = &r->gl;
    const struct tw_instance *in = &proto->instances[proto->clusters[clusters[0]].instance];
    gl->Uniform4fv(r->u_model, 3, in->transform);
    gl->Uniform4fv(r->u_color, 1, ts->materials[in->material].base_color);
    for (uint32_t k = 0; k < n; k++) {
        const struct tw_mesh_part *part = &ts->parts[proto->clusters[clusters[k]].part];
        const size_t first = (size_t)b->first_index[part->mesh] + 3u * part->first_triangle;
        const GLsizei indices = (GLsizei)(3u * part->triangle_count);
        const void *offset = (const void *)(first * sizeof(uint32_t));
        const GLint base = (GLint)b->base_vertex[part->mesh];
        r->counters.triangles += part->triangle_count;
        if (!multi) {
            gl->DrawElementsBaseVertex(GL_TRIANGLES, indices, GL_UNSIGNED_INT, offset, base);
            r->counters.draws++;
            continue;
        }
        r->run_counts[k] = indices;
        r->run_offsets[k] = offset;
        r->run_bases[k] = base;
    }
    if (multi) {
        gl->MultiDrawElementsBaseVertex(GL_TRIANGLES, r->run_counts, GL_UNSIGNED_INT,
                                        r->run_offsets, (GLsizei)n, r->run_bases);
        r->counters.draws++;
    }
}

static void backend_draw(void *ctx, struct tw_cell cell, uint32_t content,
                         const float offset[3], const uint32_t *clusters, uint32_t count)
{
    struct tw_renderer *r = ctx;
    if (count == 0)
        return;
    const double t0 = tw_clock_monotonic_ms();
    const struct tw_gl *gl = &r->gl;
    enter_draw_mode(r);
    const struct tw_prototype *proto;
    const struct gpu_buffers *b = bind_content(r, content, &proto);
    const struct tw_tileset *ts = b->ts;
    gl->Uniform3fv(r->u_offset, 1, offset);
    if (r->recording)
        record(r, cell, content, clusters, count);
    /* One multi-draw per instance (one transform, one material: a merged
     * instance is all of the prototype's small objects, their colours in its
     * vertices), instances in the order of their first cluster, clusters in
     * the order given. */
    if (!multi_draw_room(r, count, proto->instance_count)) {
        for (uint32_t k = 0; k < count; k++)
            draw_run(r, ts, b, proto, &clusters[k], 1, false);
    } else {
        const uint32_t stamp = ++r->run_stamp;
        uint32_t runs = 0;
        for (uint32_t k = 0; k < count; k++) {
            const uint32_t in = proto->clusters[clusters[k]].instance;
            if (r->run_seen[in] != stamp) {
                r->run_seen[in] = stamp;
                r->run_first[in] = UINT32_MAX;
                r->run_order[runs++] = in;
            }
            /* Chain the instance's clusters in order (run_next by position k). */
            r->run_next[k] = UINT32_MAX;
            if (r->run_first[in] == UINT32_MAX)
                r->run_first[in] = k;
            else
                r->run_next[r->run_last[in]] = k;
            r->run_last[in] = k;
        }
        for (uint32_t q = 0; q < runs; q++) {
            uint32_t n = 0;
            for (uint32_t k = r->run_first[r->run_order[q]]; k != UINT32_MAX; k = r->run_next[k])
                r->run_clusters[n++] = clusters[k];
            draw_run(r, ts, b, proto, r->run_clusters, n, n > 1);
        }
    }
    r->counters.clusters += count;
    r->counters.ms_backend += tw_clock_monotonic_ms() - t0;
}

/* Debugging: keeps the boxes of query handle, view-relative, until the
 * next frame; its result is filled in when it is read. */
static void record_query(struct tw_renderer *r, uint32_t handle, const struct tw_box *boxes,
                         uint32_t count, const float offset[3])
{
    if (tw_array_reserve((void **)&r->query_boxes, &r->query_box_cap, r->query_box_count + count,
                         sizeof(*r->query_boxes), 1024))
        return;
    r->query_record[handle - 1] = (uint32_t)r->query_box_count + 1;
    for (uint32_t k = 0; k < count; k++) {
        struct tw_renderer_query_box *q = &r->query_boxes[r->query_box_count++];
        for (int a = 0; a < 3; a++) {
            q->min[a] = boxes[k].min[a] + offset[a];
            q->max[a] = boxes[k].max[a] + offset[a];
        }
        q->query = handle;
        q->boxes = count;
        q->tile = boxes == r->tile_query_box;
        q->result = -1;
    }
}

/* The mutation of tw_world_settings.mutate_query_shrink: b shrunk by f of
 * its size on every axis, about its centre. */
static void shrink(struct tw_box *b, float f)
{
    for (int a = 0; a < 3; a++) {
        const float c = 0.5f * (b->min[a] + b->max[a]), h = 0.5f * (b->max[a] - b->min[a]);
        b->min[a] = c - h * (1.0f - f);
        b->max[a] = c + h * (1.0f - f);
    }
}

/* A query that could not be made: logged, counted, and read as visible. */
static uint32_t no_query(struct tw_renderer *r, double t0)
{
    if (r->counters.query_failures++ == 0)
        tw_log_printf(&r->log, TW_LOG_ERROR,
                      "out of memory for occlusion queries: boxes are taken as visible");
    r->counters.ms_backend += tw_clock_monotonic_ms() - t0;
    return TW_QUERY_VISIBLE;
}

static uint32_t backend_issue(void *ctx, const struct tw_box *boxes, uint32_t count,
                              const float offset[3])
{
    struct tw_renderer *r = ctx;
    const double t0 = tw_clock_monotonic_ms();
    const struct tw_gl *gl = &r->gl;
    uint32_t handle;
    if (r->free_count > 0) {
        handle = r->free_queries[--r->free_count];
    } else {
        if (r->query_count == r->query_cap) {
            uint32_t cap = r->query_cap ? r->query_cap * 2 : 256;
            GLuint *q = realloc(r->queries, sizeof(*q) * cap);
            if (q)
                r->queries = q;
            uint32_t *f = q ? realloc(r->free_queries, sizeof(*f) * cap) : NULL;
            if (f)
                r->free_queries = f;
            uint32_t *rec = f ? realloc(r->query_record, sizeof(*rec) * cap) : NULL;
            if (!rec)
                return no_query(r, t0);
            memset(rec + r->query_cap, 0, sizeof(*rec) * (cap - r->query_cap));
            r->query_record = rec;
            r->query_cap = cap;
        }
        gl->GenQueries(1, &r->queries[r->query_count]);
        handle = ++r->query_count;
    }
    if (count > r->query_corner_cap) {
        float *c = realloc(r->query_corners, sizeof(float) * 6 * (size_t)count);
        if (!c) {
            r->free_queries[r->free_count++] = handle;
            return no_query(r, t0);
        }
        r->query_corners = c;
        r->query_corner_cap = count;
    }
    for (uint32_t k = 0; k < count; k++) {
        struct tw_box q = tw_cull_query_box(r->eye, &boxes[k], offset);
        /* Only near faces are drawn: the eye must be outside. */
        assert(!(r->eye[0] >= q.min[0] && r->eye[0] <= q.max[0] && r->eye[1] >= q.min[1] &&
                 r->eye[1] <= q.max[1] && r->eye[2] >= q.min[2] && r->eye[2] <= q.max[2]));
        if (r->mutate_shrink > 0.0f)
            shrink(&q, r->mutate_shrink);
        memcpy(r->query_corners + 6 * (size_t)k, q.min, sizeof(q.min));
        memcpy(r->query_corners + 6 * (size_t)k + 3, q.max, sizeof(q.max));
    }
    enter_query_mode(r);
    gl->BindBuffer(GL_ARRAY_BUFFER, r->query_ring);
    gl->BeginQuery(r->query_target, r->queries[handle - 1]);
    for (uint32_t done = 0; done < count;) {
        if (r->query_ring_next == QUERY_RING_BOXES) {
            /* Wrapped: a fresh store, so that boxes still to be drawn are
             * never overwritten. */
            gl->BufferData(GL_ARRAY_BUFFER, (GLsizeiptr)(QUERY_RING_BOXES * 24u), NULL,
                           GL_STREAM_DRAW);
            r->query_ring_next = 0;
        }
        uint32_t n = count - done;
        if (n > QUERY_RING_BOXES - r->query_ring_next)
            n = QUERY_RING_BOXES - r->query_ring_next;
        const size_t at = (size_t)r->query_ring_next * 24u;
        gl->BufferSubData(GL_ARRAY_BUFFER, (GLintptr)at, (GLsizeiptr)(24u * n),
                          r->query_corners + 6 * (size_t)done);
        gl->VertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, 24, (const void *)at);
        gl->VertexAttribPointer(2, 3, GL_FLOAT, GL_FALSE, 24, (const void *)(at + 12));
        gl->DrawElementsInstanced(GL_TRIANGLES, 36, GL_UNSIGNED_BYTE, (const void *)0,
                                  (GLsizei)n);
        r->query_ring_next += n;
        done += n;
    }
    gl->EndQuery(r->query_target);
    r->counters.query_boxes += count;
    if (r->recording_queries)
        record_query(r, handle, boxes, count, offset);
    r->counters.queries++;
    r->counters.ms_backend += tw_clock_monotonic_ms() - t0;
    return handle;
}

static bool backend_ready(void *ctx, uint32_t query)
{
    struct tw_renderer *r = ctx;
    GLuint available = 0;
    if (query == TW_QUERY_VISIBLE)
        return true;
    if (r->deterministic)
        return false;
    r->gl.GetQueryObjectuiv(r->queries[query - 1], GL_QUERY_RESULT_AVAILABLE, &available);
    return available != 0;
}

static uint32_t backend_wait(void *ctx, uint32_t query)
{
    struct tw_renderer *r = ctx;
    if (query == TW_QUERY_VISIBLE)
        return UINT32_MAX;
    const double t0 = tw_clock_monotonic_ms();
    GLuint result = 0, available = 0;
    r->gl.GetQueryObjectuiv(r->queries[query - 1], GL_QUERY_RESULT_AVAILABLE, &available);
    r->counters.blocking_reads += available == 0;
    r->gl.GetQueryObjectuiv(r->queries[query - 1], GL_QUERY_RESULT, &result);
    r->free_queries[r->free_count++] = query;
    if (r->query_record[query - 1]) {
        /* Recorded this frame (a V-query of the previous one is not). */
        for (size_t k = r->query_record[query - 1] - 1;
             k < r->query_box_count && r->query_boxes[k].query == query; k++)
            r->query_boxes[k].result = result > 0;
        r->query_record[query - 1] = 0;
    }
    const double dt = tw_clock_monotonic_ms() - t0;
    r->counters.ms_wait += dt;
    r->counters.ms_backend += dt;
    return result;
}

/* On llvmpipe a flush closes the scene being binned and waits for an empty
 * one when the rasteriser holds them all: tilequery+chc flushes ~77 times a
 * frame in the city, and those waits (~4 ms a frame) are the GPU's time,
 * not culling's. */
static void backend_flush(void *ctx)
{
    struct tw_renderer *r = ctx;
    const double t0 = tw_clock_monotonic_ms();
    r->gl.Flush();
    const double dt = tw_clock_monotonic_ms() - t0;
    r->counters.ms_wait += dt;
    r->counters.ms_backend += dt;
}

/* The HZB methods' depth readback: on llvmpipe glReadPixels first finishes
 * what was drawn, so the time is counted as waiting, like a query's. */
static bool backend_read_depth(void *ctx, float *depth, uint32_t *width, uint32_t *height,
                               bool *reversed)
{
    struct tw_renderer *r = ctx;
    *width = r->width;
    *height = r->height;
    *reversed = r->reversed_z;
    if (!depth)
        return true;
    const double t0 = tw_clock_monotonic_ms();
    tw_renderer_read_depth(r, depth);
    const double dt = tw_clock_monotonic_ms() - t0;
    r->counters.ms_wait += dt;
    r->counters.ms_backend += dt;
    return true;
}

struct tw_query_backend tw_renderer_backend(struct tw_renderer *r)
{
    struct tw_query_backend be = {
        .ctx = r,
        .issue = backend_issue,
        .ready = backend_ready,
        .wait = backend_wait,
        .draw = backend_draw,
        .flush = backend_flush,
        .read_depth = backend_read_depth,
    };
    return be;
}

const struct tw_render_counters *tw_renderer_counters(const struct tw_renderer *r)
{
    return &r->counters;
}

void tw_renderer_record_draws(struct tw_renderer *r, bool on)
{
    r->recording = on;
}

const struct tw_drawn_cluster *tw_renderer_drawn(const struct tw_renderer *r, size_t *count)
{
    *count = r->drawn_count;
    return r->drawn;
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

/* ---- the oracle's object-ID pass -------------------------------------------------- */

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
    gl->UseProgram(r->id_program);
    gl->UniformMatrix4fv(r->ui_view_proj, 1, GL_FALSE,
                         r->reversed_z ? v->view_proj_rz : v->view_proj);
    r->bound_vao = 0;
    r->mode = MODE_NONE;
}

void tw_renderer_id_draw(struct tw_renderer *r, uint32_t content, const float offset[3],
                         const uint32_t *clusters, uint32_t count, uint32_t first_id)
{
    const struct tw_gl *gl = &r->gl;
    const struct tw_prototype *proto;
    const struct gpu_buffers *b = bind_content(r, content, &proto);
    const struct tw_tileset *ts = b->ts;
    gl->Uniform3fv(r->ui_offset, 1, offset);
    uint32_t last_instance = UINT32_MAX;
    for (uint32_t k = 0; k < count; k++) {
        const struct tw_cluster *c = &proto->clusters[clusters[k]];
        if (c->instance != last_instance) {
            gl->Uniform4fv(r->ui_model, 3, proto->instances[c->instance].transform);
            last_instance = c->instance;
        }
        gl->Uniform1ui(r->ui_id, first_id + k);
        const struct tw_mesh_part *part = &ts->parts[c->part];
        const size_t first = (size_t)b->first_index[part->mesh] + 3u * part->first_triangle;
        gl->DrawElementsBaseVertex(GL_TRIANGLES, (GLsizei)(3u * part->triangle_count),
                                   GL_UNSIGNED_INT, (const void *)(first * sizeof(uint32_t)),
                                   (GLint)b->base_vertex[part->mesh]);
    }
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

void tw_renderer_read_depth(struct tw_renderer *r, float *depth)
{
    const struct tw_gl *gl = &r->gl;
    gl->BindFramebuffer(GL_FRAMEBUFFER, r->fbo);
    gl->PixelStorei(GL_PACK_ALIGNMENT, 4);
    gl->ReadPixels(0, 0, (GLsizei)r->width, (GLsizei)r->height, GL_DEPTH_COMPONENT, GL_FLOAT,
                   depth);
}

/* ---- debugging and the viewer ------------------------------------------------------ */

void tw_renderer_record_queries(struct tw_renderer *r, bool on)
{
    r->recording_queries = on;
}

const struct tw_renderer_query_box *tw_renderer_queries(const struct tw_renderer *r, size_t *count)
{
    *count = r->query_box_count;
    return r->query_boxes;
}

void tw_renderer_draw_debug(struct tw_renderer *r, const struct tw_view *v,
                            const struct tw_renderer_debug_box *boxes, size_t count, bool fill,
                            float line_px)
{
    if (count == 0)
        return;
    const struct tw_gl *gl = &r->gl;
    const float *view_proj = r->reversed_z ? v->view_proj_rz : v->view_proj;
    gl->BindFramebuffer(GL_FRAMEBUFFER, r->fbo);
    gl->Viewport(0, 0, (GLsizei)r->width, (GLsizei)r->height);
    gl->BindVertexArray(r->box_vao);
    r->bound_vao = r->box_vao;
    gl->ColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
    gl->DepthMask(GL_FALSE);
    gl->Enable(GL_BLEND);
    gl->BlendFunc(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA);
    gl->DepthFunc(r->reversed_z ? GL_GEQUAL : GL_LEQUAL);
    if (fill) {
        /* Faces are wound inwards: culling front faces keeps the outside. */
        gl->UseProgram(r->fill_program);
        gl->UniformMatrix4fv(r->uf_view_proj, 1, GL_FALSE, view_proj);
        gl->Enable(GL_CULL_FACE);
        gl->CullFace(GL_FRONT);
        gl->Enable(GL_DEPTH_TEST);
        for (size_t k = 0; k < count; k++) {
            gl->Uniform3fv(r->uf_min, 1, boxes[k].min);
            gl->Uniform3fv(r->uf_max, 1, boxes[k].max);
            gl->Uniform4fv(r->uf_color, 1, boxes[k].color);
            gl->DrawElements(GL_TRIANGLES, 36, GL_UNSIGNED_BYTE, (const void *)0);
        }
    } else {
        gl->UseProgram(r->line_program);
        gl->UniformMatrix4fv(r->ul_view_proj, 1, GL_FALSE, view_proj);
        gl->Disable(GL_CULL_FACE);
        /* Hidden edges faint (x-ray), then visible edges at full strength. */
        for (int pass = 0; pass < 2; pass++) {
            if (pass == 0)
                gl->Disable(GL_DEPTH_TEST);
            else
                gl->Enable(GL_DEPTH_TEST);
            const float viewport[3] = {(float)r->width, (float)r->height,
                                       pass == 0 ? line_px * 0.75f : line_px};
            gl->Uniform3fv(r->ul_viewport, 1, viewport);
            for (size_t k = 0; k < count; k++) {
                float color[4];
                memcpy(color, boxes[k].color, sizeof(color));
                if (pass == 0)
                    color[3] *= 0.25f;
                gl->Uniform3fv(r->ul_min, 1, boxes[k].min);
                gl->Uniform3fv(r->ul_max, 1, boxes[k].max);
                gl->Uniform4fv(r->ul_color, 1, color);
                gl->DrawElements(GL_LINES, 24, GL_UNSIGNED_BYTE, (const void *)36);
            }
        }
    }
    gl->Disable(GL_BLEND);
    gl->Enable(GL_DEPTH_TEST);
    gl->DepthMask(GL_TRUE);
    gl->CullFace(GL_BACK);
    r->mode = MODE_NONE;
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
    r->mode = MODE_NONE;
}

void tw_renderer_set_deterministic(struct tw_renderer *r, bool on)
{
    r->deterministic = on;
}

void tw_renderer_set_count_samples(struct tw_renderer *r, bool on)
{
    const GLenum target = on ? GL_SAMPLES_PASSED : GL_ANY_SAMPLES_PASSED;
    if (target == r->query_target)
        return;
    r->query_target = target;
    /* A query object keeps the target it was first begun with (beginning
     * it with another is GL_INVALID_OPERATION): the pool made for the old
     * one (the calibration's queries) goes. Called between frames, when no
     * query is in flight. */
    assert(r->free_count == r->query_count);
    if (r->query_count) {
        tw_renderer_enter(r);
        r->gl.DeleteQueries((GLsizei)r->query_count, r->queries);
        tw_renderer_leave(r);
    }
    r->query_count = 0;
    r->free_count = 0;
}

void tw_renderer_set_mutation(struct tw_renderer *r, float shrink_fraction)
{
    r->mutate_shrink = shrink_fraction;
}

void tw_renderer_set_tile_query_box(struct tw_renderer *r, const struct tw_box *box)
{
    r->tile_query_box = box;
}

bool tw_renderer_reversed_z(const struct tw_renderer *r)
{
    return r->reversed_z;
}
