/* The HZB on the GPU (cull.h's gpu_hzb_* backend operations; DESIGN §6):
 * the depth pyramid reduced by compute passes from the depth texture,
 * candidate boxes tested against it by a compute pass that also turns the
 * indirect draws of the hidden ones off, one multi-draw per tileset's
 * buffers, and one bit per candidate copied into a read-back buffer under
 * a fence, read a frame (or more) later without waiting.
 *
 * The test mirrors cull/hzb.c's box_hidden() and split_visible(): the same
 * screen rectangle (one pixel more on each side), the same level choice
 * (TW_HZB_SPAN texels at most along each axis), the same two levels of
 * halving; its depth tolerance is wider (float arithmetic throughout). */
#include "runtime/renderer-private.h"
#include "tiles/array.h"
#include "tiles/clock.h"
#include "tiles/tiles-internal.h"

#include <stdlib.h>
#include <string.h>

#define GROUP 64u
/* The pyramid's levels, at most (65536 pixels wide: 17). */
#define MAX_LEVELS 24

static const char *const reduce_cs =
    "#version 430 core\n"
    "layout(local_size_x = 8, local_size_y = 8) in;\n"
    "layout(binding = 0) uniform sampler2D u_depth;\n"
    "layout(std430, binding = 5) buffer Pyramid { float pyramid[]; };\n"
    "uniform ivec2 u_src_size;\n"
    "uniform ivec2 u_dst_size;\n"
    "uniform int u_src_at;\n"         /* -1: the depth texture */
    "uniform int u_dst_at;\n"
    "uniform int u_reversed;\n"
    /* the farther of two depths: reversed depth has far = 0 */
    "float farther(float a, float b) { return u_reversed != 0 ? min(a, b) : max(a, b); }\n"
    "float fetch(ivec2 p) {\n"
    "    p = min(p, u_src_size - 1);\n"
    "    return u_src_at < 0 ? texelFetch(u_depth, p, 0).r\n"
    "                        : pyramid[u_src_at + p.y * u_src_size.x + p.x];\n"
    "}\n"
    "void main() {\n"
    "    ivec2 d = ivec2(gl_GlobalInvocationID.xy);\n"
    "    if (any(greaterThanEqual(d, u_dst_size))) return;\n"
    "    ivec2 s = 2 * d;\n"
    "    float f = farther(farther(fetch(s), fetch(s + ivec2(1, 0))),\n"
    "                      farther(fetch(s + ivec2(0, 1)), fetch(s + ivec2(1, 1))));\n"
    "    pyramid[u_dst_at + d.y * u_dst_size.x + d.x] = f;\n"
    "}\n";

/* REL: reversed float depth, relative (a few ulps of float arithmetic in
 * the projection on top of cull/hzb.c's 1e-6); ABS: standard 24-bit
 * depth, eight steps. */
static const char *const test_cs =
    "#version 430 core\n"
    "layout(local_size_x = 64) in;\n"
    "layout(std430, binding = 0) readonly buffer Boxes { vec4 boxes[]; };\n"
    "layout(std430, binding = 1) readonly buffer Info { uvec4 info[]; };\n"
    "layout(std430, binding = 2) buffer Commands { uint commands[]; };\n"
    /* the triangles and clusters drawn, then a bit per candidate */
    "layout(std430, binding = 3) buffer Results { uint drawn_triangles; uint drawn_clusters;\n"
    "                                            uint bits[]; };\n"
    "layout(binding = 0) uniform sampler2D u_depth;\n"
    "layout(std430, binding = 5) readonly buffer Pyramid { float pyramid[]; };\n"
    "uniform int u_level_at[24];\n"  /* the pyramid's levels 1.. in the buffer */
    "uniform int u_level_w[24];\n"
    "uniform mat4 u_view_proj;\n"
    "uniform vec2 u_proj;\n"          /* proj[10], proj[14] of the depth convention */
    "uniform float u_near;\n"
    "uniform ivec2 u_size;\n"
    "uniform int u_levels;\n"         /* the depth buffer and its reductions */
    "uniform int u_reversed;\n"
    "uniform int u_built;\n"
    "uniform uint u_count;\n"
    "const int SPAN = 8;\n"
    "const float REL = 4e-6;\n"
    "const float ABS = 8.0 / 16777216.0;\n"
    "bool screen_rect(vec3 a, vec3 b, out vec2 lo, out vec2 hi, out float wmin) {\n"
    "    lo = vec2(1e30); hi = vec2(-1e30); wmin = 1e30;\n"
    "    for (int c = 0; c < 8; c++) {\n"
    "        vec3 p = vec3((c & 1) != 0 ? b.x : a.x, (c & 2) != 0 ? b.y : a.y,\n"
    "                      (c & 4) != 0 ? b.z : a.z);\n"
    "        vec4 q = u_view_proj * vec4(p, 1.0);\n"
    "        if (!(q.w > u_near)) return false;\n"
    "        vec2 ndc = q.xy / q.w;\n"
    "        lo = min(lo, ndc); hi = max(hi, ndc); wmin = min(wmin, q.w);\n"
    "    }\n"
    "    return lo.x <= hi.x && lo.y <= hi.y;\n"
    "}\n"
    "float texel(int k, ivec2 p) {\n"
    "    return k == 0 ? texelFetch(u_depth, p, 0).r\n"
    "                  : pyramid[u_level_at[k - 1] + p.y * u_level_w[k - 1] + p.x];\n"
    "}\n"
    "bool hidden(vec3 a, vec3 b) {\n"
    "    vec2 lo, hi; float wmin;\n"
    "    if (!screen_rect(a, b, lo, hi, wmin)) return false;\n"
    "    float ndc = -u_proj.x + u_proj.y / wmin;\n"
    "    float dn = u_reversed != 0 ? ndc : 0.5 * ndc + 0.5;\n"
    "    vec2 S = vec2(u_size);\n"
    "    vec2 f0 = floor((lo * 0.5 + 0.5) * S - 0.5);\n"
    "    vec2 f1 = floor((hi * 0.5 + 0.5) * S - 0.5) + 1.0;\n"
    "    if (f1.x < 0.0 || f1.y < 0.0 || f0.x > S.x - 1.0 || f0.y > S.y - 1.0) return true;\n"
    "    ivec2 p0 = ivec2(max(f0, vec2(0.0)));\n"
    "    ivec2 p1 = ivec2(min(f1, S - 1.0));\n"
    "    int k = 0;\n"
    "    while (k + 1 < u_levels && ((p1.x >> k) - (p0.x >> k) >= SPAN ||\n"
    "                                (p1.y >> k) - (p0.y >> k) >= SPAN)) k++;\n"
    "    for (int ty = p0.y >> k; ty <= p1.y >> k; ty++)\n"
    "        for (int tx = p0.x >> k; tx <= p1.x >> k; tx++) {\n"
    "            float t = texel(k, ivec2(tx, ty));\n"
    "            if (u_reversed != 0 ? !(dn < t - REL * abs(t)) : !(dn > t + ABS)) return false;\n"
    "        }\n"
    "    return true;\n"
    "}\n"
    /* half h (0, 1) of box a..b along its longest axis */
    "void half_box(vec3 a, vec3 b, int h, out vec3 ha, out vec3 hb) {\n"
    "    vec3 e = b - a;\n"
    "    int ax = e.y > e.x ? (e.z > e.y ? 2 : 1) : (e.z > e.x ? 2 : 0);\n"
    "    ha = a; hb = b;\n"
    "    float m = 0.5 * (a[ax] + b[ax]);\n"
    "    if (h == 0) hb[ax] = m; else ha[ax] = m;\n"
    "}\n"
    "bool split_visible(vec3 a, vec3 b) {\n"
    "    if (hidden(a, b)) return false;\n"
    "    for (int i = 0; i < 2; i++) {\n"
    "        vec3 a1, b1;\n"
    "        half_box(a, b, i, a1, b1);\n"
    "        if (hidden(a1, b1)) continue;\n"
    "        for (int j = 0; j < 2; j++) {\n"
    "            vec3 a2, b2;\n"
    "            half_box(a1, b1, j, a2, b2);\n"
    "            if (!hidden(a2, b2)) return true;\n"
    "        }\n"
    "    }\n"
    "    return false;\n"
    "}\n"
    "void main() {\n"
    "    uint i = gl_GlobalInvocationID.x;\n"
    "    if (i >= u_count) return;\n"
    "    vec4 a = boxes[2u * i], b = boxes[2u * i + 1u];\n"
    "    bool visible = a.w != 0.0 || u_built == 0 || split_visible(a.xyz, b.xyz);\n"
    "    uvec4 n = info[i];\n"
    "    if (visible) {\n"
    "        atomicOr(bits[i >> 5], 1u << (i & 31u));\n"
    "        if (n.y > 0u) {\n"
    "            atomicAdd(drawn_triangles, n.z);\n"
    "            atomicAdd(drawn_clusters, n.y);\n"
    "        }\n"
    "    }\n"
    "    for (uint k = 0u; k < n.y; k++) commands[5u * (n.x + k) + 1u] = visible ? 1u : 0u;\n"
    "}\n";

bool tw_renderer_gpu_hzb_init(struct tw_renderer *r)
{
    struct tw_gpu_hzb *g = &r->ghzb;
    const struct tw_gl *gl = &r->gl;
    bool out_of_memory = false;
    g->reduce = tw_programs_link_compute(gl, &r->log, reduce_cs, &out_of_memory);
    g->test = tw_programs_link_compute(gl, &r->log, test_cs, &out_of_memory);
    if (!g->reduce || !g->test) {
        tw_log_printf(&r->log, TW_LOG_WARN, "no GPU HZB: the HZB methods build their "
                      "pyramid on the CPU");
        tw_renderer_gpu_hzb_finish(r);
        return false;
    }
    GLint align = 0;
    gl->GetIntegerv(GL_SHADER_STORAGE_BUFFER_OFFSET_ALIGNMENT, &align);
    if (align <= 0 || align > 256) {
        tw_log_printf(&r->log, TW_LOG_WARN, "shader storage offsets align to %d bytes: the HZB "
                      "is built on the CPU", align);
        tw_renderer_gpu_hzb_finish(r);
        return false;
    }
#define U(name) gl->GetUniformLocation(g->test, name)
    g->u_view_proj = U("u_view_proj");
    g->u_proj = U("u_proj");
    g->u_near = U("u_near");
    g->u_size = U("u_size");
    g->u_levels = U("u_levels");
    g->u_reversed = U("u_reversed");
    g->u_built = U("u_built");
    g->u_count = U("u_count");
    g->u_level_at = U("u_level_at");
    g->u_level_w = U("u_level_w");
    g->u_src_size = gl->GetUniformLocation(g->reduce, "u_src_size");
    g->u_dst_size = gl->GetUniformLocation(g->reduce, "u_dst_size");
    g->u_src_at = gl->GetUniformLocation(g->reduce, "u_src_at");
    g->u_dst_at = gl->GetUniformLocation(g->reduce, "u_dst_at");
#undef U
    g->u_reduce_reversed = gl->GetUniformLocation(g->reduce, "u_reversed");
    gl->GenBuffers(4, g->buffers);
    gl->GenBuffers(TW_GPU_HZB_SLOTS, g->readback);
    g->live = true;
    return true;
}

void tw_renderer_gpu_hzb_finish(struct tw_renderer *r)
{
    struct tw_gpu_hzb *g = &r->ghzb;
    const struct tw_gl *gl = &r->gl;
    if (r->gl_loaded) {
        if (g->reduce)
            gl->DeleteProgram(g->reduce);
        if (g->test)
            gl->DeleteProgram(g->test);
        if (g->live) {
            gl->DeleteBuffers(4, g->buffers);
            gl->DeleteBuffers(TW_GPU_HZB_SLOTS, g->readback);
        }
        for (int k = 0; k < TW_GPU_HZB_SLOTS; k++)
            if (g->slot[k].fence)
                gl->DeleteSync(g->slot[k].fence);
    }
    free(g->boxes);
    free(g->info);
    free(g->where);
    free(g->commands);
    free(g->records);
    free(g->cluster_ids);
    free(g->segments);
    free(g->result);
    memset(g, 0, sizeof(*g));
}

/* ---- the pyramid -------------------------------------------------------------- */

static bool build(void *ctx, const void *owner, uint64_t frame)
{
    struct tw_renderer *r = ctx;
    struct tw_gpu_hzb *g = &r->ghzb;
    const struct tw_gl *gl = &r->gl;
    g->count = g->command_count = g->record_count = g->segment_count = 0;
    g->cluster_id_count = 0;
    g->frame = frame;
    g->owner = owner;
    g->key_valid = false;
    g->built = false;
    if (r->width < 2 && r->height < 2)
        return false;
    if (g->pyramid_w != r->width || g->pyramid_h != r->height) {
        /* Levels 1.. of the pyramid (level 0 is the depth texture itself),
         * one after the other in one buffer, as cull/hzb.c lays them out. */
        uint32_t w = r->width, h = r->height, n = 0, at = 0;
        while (w > 1 || h > 1) {
            w = (w + 1) / 2;
            h = (h + 1) / 2;
            g->level_w[n] = (GLint)w;
            g->level_h[n] = (GLint)h;
            g->level_at[n] = (GLint)at;
            at += w * h;
            n++;
        }
        g->levels = n;
        gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, g->buffers[2]);
        gl->BufferData(GL_SHADER_STORAGE_BUFFER, (GLsizeiptr)((size_t)at * 4u), NULL,
                       GL_DYNAMIC_COPY);
        g->pyramid_w = r->width;
        g->pyramid_h = r->height;
    }
    gl->UseProgram(g->reduce);
    r->mode = TW_RENDERER_MODE_NONE;
    gl->Uniform1i(g->u_reduce_reversed, r->reversed_z);
    gl->ActiveTexture(GL_TEXTURE0);
    gl->BindTexture(GL_TEXTURE_2D, r->depth_texture);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, 5, g->buffers[2]);
    uint32_t sw = r->width, sh = r->height;
    for (uint32_t k = 0; k < g->levels; k++) {
        gl->Uniform2i(g->u_src_size, (GLint)sw, (GLint)sh);
        gl->Uniform2i(g->u_dst_size, g->level_w[k], g->level_h[k]);
        gl->Uniform1i(g->u_src_at, k == 0 ? -1 : g->level_at[k - 1]);
        gl->Uniform1i(g->u_dst_at, g->level_at[k]);
        gl->DispatchCompute(((GLuint)g->level_w[k] + 7) / 8, ((GLuint)g->level_h[k] + 7) / 8, 1);
        gl->MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
        sw = (uint32_t)g->level_w[k];
        sh = (uint32_t)g->level_h[k];
    }
    gl->BindTexture(GL_TEXTURE_2D, 0);
    g->built = true;
    return true;
}

/* ---- candidates --------------------------------------------------------------- */

/* Room for one more candidate drawing count clusters. */
static bool room(struct tw_gpu_hzb *g, uint32_t count)
{
    const size_t n = g->count + 1;
    return !tw_array_reserve((void **)&g->boxes, &g->box_cap, 2 * n, sizeof(*g->boxes), 1024) &&
           !tw_array_reserve((void **)&g->info, &g->info_cap, n, sizeof(*g->info), 512) &&
           !tw_array_reserve((void **)&g->where, &g->where_cap, n, sizeof(*g->where), 512) &&
           !tw_array_reserve((void **)&g->commands, &g->command_cap, g->command_count + count,
                             sizeof(*g->commands), 1024) &&
           !tw_array_reserve((void **)&g->records, &g->record_cap, g->record_count + count,
                             sizeof(*g->records), 1024) &&
           !tw_array_reserve((void **)&g->cluster_ids, &g->cluster_id_cap,
                             g->cluster_id_count + count, sizeof(*g->cluster_ids), 1024) &&
           !tw_array_reserve((void **)&g->segments, &g->segment_cap, g->segment_count + 1,
                             sizeof(*g->segments), 16);
}

/* One candidate drawing clusters of content (not a composite), recorded as
 * record_content's record_clusters (a composite's, or the same). */
static uint32_t candidate_part(struct tw_renderer *r, const struct tw_box *box, bool always,
                               struct tw_cell cell, uint32_t content, const float offset[3],
                               const uint32_t *clusters, uint32_t count, uint32_t record_content,
                               const uint32_t *record_clusters)
{
    struct tw_gpu_hzb *g = &r->ghzb;
    if (!room(g, count)) {
        /* Out of memory: drawn at once, untested. */
        if (count > 0)
            tw_renderer_backend(r).draw(r, cell, content, offset, clusters, count);
        return UINT32_MAX;
    }
    const uint32_t i = (uint32_t)g->count++;
    g->boxes[2 * i] = (struct tw_gpu_vec4){{box->min[0], box->min[1], box->min[2],
                                            always ? 1.0f : 0.0f}};
    g->boxes[2 * i + 1] = (struct tw_gpu_vec4){{box->max[0], box->max[1], box->max[2], 0.0f}};
    g->info[i][0] = (uint32_t)g->command_count;
    g->info[i][1] = count;
    g->info[i][2] = g->info[i][3] = 0;
    g->where[i] = (struct tw_gpu_hzb_where){cell, record_content, (uint32_t)g->cluster_id_count};
    if (count == 0 || content >= r->content_count || !r->contents[content].live) {
        g->info[i][1] = 0;
        return i;
    }
    const uint32_t buffers = r->contents[content].buffers;
    const struct tw_gpu_buffers *b = &r->buffers[buffers];
    const struct tw_prototype *proto = tw_renderer_content(r, content, NULL);
    /* A new tile placement: its instances get records afresh. */
    if (!g->key_valid || g->key_content != content || g->key_cell.i != cell.i ||
        g->key_cell.j != cell.j) {
        g->key_valid = true;
        g->key_content = content;
        g->key_cell = cell;
        g->key_stamp = tw_renderer_instance_map(r, proto->instance_count) ? ++r->run_stamp : 0;
    }
    /* A segment per run of candidates drawn from the same buffers. */
    if (g->segment_count == 0 || g->segments[g->segment_count - 1].buffers != buffers)
        g->segments[g->segment_count++] = (struct tw_gpu_segment){buffers, content,
                                                                   (uint32_t)g->command_count, 0};
    const struct tw_tileset *ts = b->ts;
    const bool mapped = g->key_stamp != 0;
    for (uint32_t k = 0; k < count; k++) {
        const struct tw_cluster *c = &proto->clusters[clusters[k]];
        uint32_t rec;
        if (mapped && r->run_seen[c->instance] == g->key_stamp) {
            rec = r->run_record[c->instance];
        } else {
            rec = (uint32_t)g->record_count++;
            if (mapped) {
                r->run_seen[c->instance] = g->key_stamp;
                r->run_record[c->instance] = rec;
            }
            const struct tw_instance *in = &proto->instances[c->instance];
            tw_renderer_draws_record(&g->records[rec], in, offset,
                                     ts->materials[in->material].base_color, 0.0f);
        }
        tw_renderer_draws_command(&g->commands[g->command_count++], b, ts, c, rec);
        g->cluster_ids[g->cluster_id_count++] = record_clusters[k];
        g->info[i][2] += c->triangle_count;
    }
    g->segments[g->segment_count - 1].count += count;
    return i;
}

struct candidate_run {
    const struct tw_box *box;
    bool always;
    struct tw_cell cell;
    uint32_t content;
    const float *offset;
    const uint32_t *clusters;
    uint32_t first;
};

static void run_candidate(struct tw_renderer *r, void *user, uint32_t part,
                          const uint32_t *clusters, uint32_t count, uint32_t at)
{
    struct candidate_run *c = user;
    const uint32_t i = candidate_part(r, c->box, c->always, c->cell, part, c->offset, clusters,
                                      count, c->content, c->clusters + at);
    if (c->first == UINT32_MAX)
        c->first = i;
}

static uint32_t candidate(void *ctx, const struct tw_box *box, bool always, struct tw_cell cell,
                          uint32_t content, const float offset[3], const uint32_t *clusters,
                          uint32_t count)
{
    struct tw_renderer *r = ctx;
    /* A tile with moving objects: a candidate per run of one part, each
     * testing the same box (the same answer); the first one's answer is
     * the node's. */
    struct candidate_run run = {box, always, cell, content, offset, clusters, UINT32_MAX};
    if (count > 0 && tw_renderer_split(r, content, clusters, count, run_candidate, &run))
        return run.first;
    return candidate_part(r, box, always, cell, content, offset, clusters, count, content,
                          clusters);
}

/* ---- the test ------------------------------------------------------------------ */

/* Words of the result buffer for n candidates. */
static size_t result_words(size_t n)
{
    return TW_GPU_HZB_RESULT_HEAD + (n + 31) / 32;
}

/* Reads slot s's results (its fence signalled) into g->result and counts
 * what its candidates drew; false when out of memory. */
static bool read_slot(struct tw_renderer *r, int s)
{
    struct tw_gpu_hzb *g = &r->ghzb;
    const struct tw_gl *gl = &r->gl;
    struct tw_gpu_hzb_slot *sl = &g->slot[s];
    const size_t words = result_words(sl->count);
    gl->DeleteSync(sl->fence);
    sl->fence = NULL;
    sl->pending = false;
    if (tw_array_reserve((void **)&g->result, &g->result_cap, words, sizeof(*g->result), 64))
        return false;
    gl->BindBuffer(GL_COPY_READ_BUFFER, g->readback[s]);
    gl->GetBufferSubData(GL_COPY_READ_BUFFER, 0, (GLsizeiptr)(words * 4u), g->result);
    gl->BindBuffer(GL_COPY_READ_BUFFER, 0);
    r->counters.bytes_read_back += words * 4u;
    r->counters.triangles += g->result[0];
    r->counters.clusters += g->result[1];
    g->result_count = sl->count;
    g->result_frame = sl->frame;
    return true;
}

/* The slot to copy this frame's results into: a free one, else the oldest
 * in flight, waited for (the GPU is TW_GPU_HZB_SLOTS frames behind). */
static int free_slot(struct tw_renderer *r)
{
    struct tw_gpu_hzb *g = &r->ghzb;
    for (int k = 0; k < TW_GPU_HZB_SLOTS; k++)
        if (!g->slot[k].pending)
            return k;
    int s = 0;
    for (int k = 1; k < TW_GPU_HZB_SLOTS; k++)
        if (g->slot[k].frame < g->slot[s].frame)
            s = k;
    r->gl.ClientWaitSync(g->slot[s].fence, GL_SYNC_FLUSH_COMMANDS_BIT, UINT64_MAX);
    r->counters.waits++;
    read_slot(r, s);
    return s;
}

/* Recording what was drawn (the oracle's comparison, debugging) needs the
 * answers now: this waits for slot s. Not for timings. */
static void record_passed(struct tw_renderer *r, int s)
{
    struct tw_gpu_hzb *g = &r->ghzb;
    const struct tw_gl *gl = &r->gl;
    const size_t words = result_words(g->count);
    if (tw_array_reserve((void **)&g->result, &g->result_cap, words, sizeof(*g->result), 64))
        return;
    gl->ClientWaitSync(g->slot[s].fence, GL_SYNC_FLUSH_COMMANDS_BIT, UINT64_MAX);
    gl->BindBuffer(GL_COPY_READ_BUFFER, g->readback[s]);
    gl->GetBufferSubData(GL_COPY_READ_BUFFER, 0, (GLsizeiptr)(words * 4u), g->result);
    gl->BindBuffer(GL_COPY_READ_BUFFER, 0);
    const uint32_t *bits = g->result + TW_GPU_HZB_RESULT_HEAD;
    for (size_t i = 0; i < g->count; i++)
        if (g->info[i][1] && (bits[i >> 5] >> (i & 31) & 1u))
            tw_renderer_record_clusters(r, g->where[i].cell, g->where[i].content,
                                        g->cluster_ids + g->where[i].first_cluster,
                                        g->info[i][1]);
}

static void upload(const struct tw_gl *gl, GLuint buffer, const void *data, size_t bytes)
{
    gl->BindBuffer(GL_SHADER_STORAGE_BUFFER, buffer);
    gl->BufferData(GL_SHADER_STORAGE_BUFFER, (GLsizeiptr)(bytes ? bytes : 16), data,
                   GL_STREAM_DRAW);
}

static void test(void *ctx)
{
    struct tw_renderer *r = ctx;
    struct tw_gpu_hzb *g = &r->ghzb;
    const struct tw_gl *gl = &r->gl;
    const uint32_t n = (uint32_t)g->count;
    if (n == 0)
        return;
    const double t0 = tw_clock_monotonic_ms();
    /* Records into the ring, commands naming them. */
    const uint32_t first =
        g->record_count ? tw_renderer_draws_put_records(r, g->records, (uint32_t)g->record_count)
                        : 0;
    for (size_t k = 0; k < g->command_count; k++)
        g->commands[k].base_instance += first;
    size_t at = 0;
    if (g->command_count)
        at = tw_renderer_draws_put_commands(r, g->commands, (uint32_t)g->command_count);
    const size_t words = result_words(n);
    upload(gl, g->buffers[0], g->boxes, (size_t)n * 2 * sizeof(*g->boxes));
    upload(gl, g->buffers[1], g->info, (size_t)n * sizeof(*g->info));
    upload(gl, g->buffers[3], NULL, words * 4u);
    gl->ClearBufferData(GL_SHADER_STORAGE_BUFFER, GL_R32UI, GL_RED_INTEGER, GL_UNSIGNED_INT,
                        NULL);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, g->buffers[0]);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, 1, g->buffers[1]);
    if (g->command_count)
        gl->BindBufferRange(GL_SHADER_STORAGE_BUFFER, 2, r->command_ring, (GLintptr)at,
                            (GLsizeiptr)(g->command_count * sizeof(*g->commands)));
    else
        gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, 2, g->buffers[3]);   /* not written */
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, 3, g->buffers[3]);
    gl->UseProgram(g->test);
    r->mode = TW_RENDERER_MODE_NONE;
    const float *vp = r->reversed_z ? g->view.view_proj_rz : g->view.view_proj;
    const float *proj = r->reversed_z ? g->view.proj_rz : g->view.proj;
    gl->UniformMatrix4fv(g->u_view_proj, 1, GL_FALSE, vp);
    gl->Uniform2fv(g->u_proj, 1, (const float[2]){proj[10], proj[14]});
    gl->Uniform1f(g->u_near, g->view.near_plane);
    gl->Uniform2i(g->u_size, (GLint)r->width, (GLint)r->height);
    gl->Uniform1i(g->u_levels, (GLint)g->levels + 1);
    gl->Uniform1i(g->u_reversed, r->reversed_z);
    gl->Uniform1i(g->u_built, g->built);
    gl->Uniform1ui(g->u_count, n);
    gl->ActiveTexture(GL_TEXTURE0);
    gl->BindTexture(GL_TEXTURE_2D, r->depth_texture);
    gl->BindBufferBase(GL_SHADER_STORAGE_BUFFER, 5, g->buffers[2]);
    gl->Uniform1iv(g->u_level_at, (GLsizei)g->levels, g->level_at);
    gl->Uniform1iv(g->u_level_w, (GLsizei)g->levels, g->level_w);
    gl->DispatchCompute((n + GROUP - 1) / GROUP, 1, 1);
    gl->MemoryBarrier(GL_COMMAND_BARRIER_BIT | GL_SHADER_STORAGE_BARRIER_BIT |
                      GL_BUFFER_UPDATE_BARRIER_BIT);
    gl->BindTexture(GL_TEXTURE_2D, 0);
    /* The draws: one multi-draw per run of one tileset's buffers. */
    for (size_t k = 0; k < g->segment_count; k++) {
        const struct tw_gpu_segment *sg = &g->segments[k];
        tw_renderer_enter_draw_mode(r);
        const struct tw_prototype *proto;
        tw_renderer_bind_content(r, sg->content, &proto);
        tw_renderer_draws_commands(r, at + (size_t)sg->first * sizeof(*g->commands), sg->count);
        r->counters.draws++;
    }
    /* The results into a read-back slot, under a fence. */
    const int s = free_slot(r);
    struct tw_gpu_hzb_slot *sl = &g->slot[s];
    if (sl->bytes < words * 4u) {
        sl->bytes = words * 8u;
        gl->BindBuffer(GL_COPY_WRITE_BUFFER, g->readback[s]);
        gl->BufferData(GL_COPY_WRITE_BUFFER, (GLsizeiptr)sl->bytes, NULL, GL_STREAM_READ);
    }
    gl->BindBuffer(GL_COPY_READ_BUFFER, g->buffers[3]);
    gl->BindBuffer(GL_COPY_WRITE_BUFFER, g->readback[s]);
    gl->CopyBufferSubData(GL_COPY_READ_BUFFER, GL_COPY_WRITE_BUFFER, 0, 0,
                          (GLsizeiptr)(words * 4u));
    gl->BindBuffer(GL_COPY_READ_BUFFER, 0);
    gl->BindBuffer(GL_COPY_WRITE_BUFFER, 0);
    sl->fence = gl->FenceSync(GL_SYNC_GPU_COMMANDS_COMPLETE, 0);
    sl->pending = true;
    sl->count = n;
    sl->frame = g->frame;
    sl->owner = g->owner;
    if (r->recording)
        record_passed(r, s);
    r->counters.ms_backend += tw_clock_monotonic_ms() - t0;
}

static const uint32_t *results(void *ctx, const void *owner, bool wait, uint32_t *count,
                               uint64_t *frame)
{
    struct tw_renderer *r = ctx;
    struct tw_gpu_hzb *g = &r->ghzb;
    const struct tw_gl *gl = &r->gl;
    wait = wait || r->deterministic;
    bool any = false;
    /* Oldest first, so that the last read is the newest finished. */
    for (;;) {
        int s = -1;
        for (int k = 0; k < TW_GPU_HZB_SLOTS; k++)
            if (g->slot[k].pending && g->slot[k].owner == owner &&
                (s < 0 || g->slot[k].frame < g->slot[s].frame))
                s = k;
        if (s < 0)
            break;
        const GLenum st = gl->ClientWaitSync(g->slot[s].fence, wait ? GL_SYNC_FLUSH_COMMANDS_BIT : 0,
                                             wait ? UINT64_MAX : 0);
        if (st != GL_ALREADY_SIGNALED && st != GL_CONDITION_SATISFIED)
            break;
        if (wait)
            r->counters.waits++;
        any = read_slot(r, s);
    }
    if (!any)
        return NULL;
    *count = g->result_count;
    *frame = g->result_frame;
    return g->result + TW_GPU_HZB_RESULT_HEAD;
}

void tw_renderer_gpu_hzb_begin_frame(struct tw_renderer *r, const struct tw_view *v)
{
    r->ghzb.view = *v;
}

bool tw_renderer_use_gpu_hzb(struct tw_renderer *r, bool on)
{
    r->ghzb.on = on && r->ghzb.live;
    return r->ghzb.on;
}

bool tw_renderer_software(const struct tw_renderer *r)
{
    return r->software;
}

void tw_renderer_gpu_hzb_ops(struct tw_renderer *r, struct tw_query_backend *be)
{
    if (!r->ghzb.on)
        return;
    be->gpu_hzb_build = build;
    be->gpu_hzb_candidate = candidate;
    be->gpu_hzb_test = test;
    be->gpu_hzb_results = results;
}
