/* The GL query backend (cull/cull.h's struct tw_query_backend): draws
 * clusters, one multi-draw per call (draws.c), and occlusion queries of boxes,
 * with the recording of both for debugging (renderer.h). */
#include "runtime/renderer-private.h"
#include "tiles/array.h"
#include "tiles/clock.h"
#include "tiles/tiles-internal.h"

#include <assert.h>
#include <stdlib.h>
#include <string.h>

/* Boxes in the query ring buffer. */
#define QUERY_RING_BOXES 16384u

void tw_renderer_enter_draw_mode(struct tw_renderer *r)
{
    if (r->mode == TW_RENDERER_MODE_DRAW)
        return;
    const struct tw_gl *gl = &r->gl;
    gl->UseProgram(r->programs.scene.program);
    r->bound_vao = 0;
    gl->ColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
    gl->DepthMask(GL_TRUE);
    gl->Enable(GL_CULL_FACE);
    gl->CullFace(GL_BACK);
    r->mode = TW_RENDERER_MODE_DRAW;
}

static void enter_query_mode(struct tw_renderer *r)
{
    if (r->mode == TW_RENDERER_MODE_QUERY)
        return;
    const struct tw_gl *gl = &r->gl;
    gl->UseProgram(r->programs.query.program);
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
    r->mode = TW_RENDERER_MODE_QUERY;
}

void tw_renderer_record_clusters(struct tw_renderer *r, struct tw_cell cell, uint32_t prototype,
                                 const uint32_t *clusters, uint32_t count)
{
    if (tw_array_reserve((void **)&r->drawn, &r->drawn_cap, r->drawn_count + count,
                         sizeof(*r->drawn), 4096)) {
        tw_log_printf(&r->log, TW_LOG_ERROR, "out of memory recording draws");
        return;
    }
    for (uint32_t k = 0; k < count; k++)
        r->drawn[r->drawn_count++] = (struct tw_drawn_cluster){
            .cell = cell, .prototype = prototype, .cluster = clusters[k]};
}

bool tw_renderer_instance_map(struct tw_renderer *r, uint32_t instances)
{
    if (instances > r->run_instance_cap) {
        uint32_t *seen = realloc(r->run_seen, instances * sizeof(*seen));
        if (!seen)
            return false;
        r->run_seen = seen;
        uint32_t *rec = realloc(r->run_record, instances * sizeof(*rec));
        if (!rec)
            return false;
        r->run_record = rec;
        memset(r->run_seen + r->run_instance_cap, 0,
               (instances - r->run_instance_cap) * sizeof(*r->run_seen));
        r->run_instance_cap = instances;
    }
    if (r->run_stamp >= UINT32_MAX - 1) {
        memset(r->run_seen, 0, r->run_instance_cap * sizeof(*r->run_seen));
        r->run_stamp = 0;
    }
    return true;
}

/* Room to stage count clusters of a prototype of instances instances. */
static bool draw_room(struct tw_renderer *r, uint32_t count, uint32_t instances)
{
    return tw_renderer_draws_reserve(r, count, count) && tw_renderer_instance_map(r, instances);
}

bool tw_renderer_stage_clusters(struct tw_renderer *r, const struct tw_gpu_buffers *b,
                                const struct tw_prototype *proto, const float offset[3],
                                const uint32_t *clusters, uint32_t count, uint32_t first_id,
                                uint32_t *records)
{
    if (!draw_room(r, count, proto->instance_count))
        return false;
    const struct tw_tileset *ts = b->ts;
    const uint32_t stamp = ++r->run_stamp;
    uint32_t n = 0;
    for (uint32_t k = 0; k < count; k++) {
        const struct tw_cluster *c = &proto->clusters[clusters[k]];
        const struct tw_instance *in = &proto->instances[c->instance];
        uint32_t rec;
        if (first_id != UINT32_MAX) {
            /* The ID pass: a record per cluster, for its id. */
            rec = n++;
            tw_renderer_draws_record(&r->stage_records[rec], in, offset,
                                     ts->materials[in->material].base_color,
                                     (float)(first_id + k));
        } else if (r->run_seen[c->instance] == stamp) {
            rec = r->run_record[c->instance];
        } else {
            r->run_seen[c->instance] = stamp;
            rec = r->run_record[c->instance] = n++;
            tw_renderer_draws_record(&r->stage_records[rec], in, offset,
                                     ts->materials[in->material].base_color, 0.0f);
        }
        tw_renderer_draws_command(&r->stage_commands[k], b, ts, c, rec);
    }
    *records = n;
    return true;
}

static void backend_draw(void *ctx, struct tw_cell cell, uint32_t content,
                         const float offset[3], const uint32_t *clusters, uint32_t count);

struct run_place {
    struct tw_cell cell;
    const float *offset;
};

static void draw_run(struct tw_renderer *r, void *user, uint32_t part, const uint32_t *clusters,
                     uint32_t count, uint32_t at)
{
    (void)at;
    const struct run_place *p = user;
    backend_draw(r, p->cell, part, p->offset, clusters, count);
}

static void backend_draw(void *ctx, struct tw_cell cell, uint32_t content,
                         const float offset[3], const uint32_t *clusters, uint32_t count)
{
    struct tw_renderer *r = ctx;
    if (count == 0)
        return;
    if (content < r->content_count && r->contents[content].composite) {
        /* A tile with moving objects: recorded as itself, drawn as its
         * parts. */
        if (r->recording)
            tw_renderer_record_clusters(r, cell, content, clusters, count);
        const bool recording = r->recording;
        r->recording = false;
        struct run_place p = {cell, offset};
        tw_renderer_split(r, content, clusters, count, draw_run, &p);
        r->recording = recording;
        return;
    }
    const double t0 = tw_clock_monotonic_ms();
    if (r->host.draw) {
        /* The host draws them, into its framebuffer: counted as one draw. */
        if (r->recording)
            tw_renderer_record_clusters(r, cell, content, clusters, count);
        const struct tw_prototype *proto = tw_renderer_content(r, content, NULL);
        for (uint32_t k = 0; proto && k < count; k++)
            r->counters.triangles += proto->clusters[clusters[k]].triangle_count;
        r->host.draw(r->host.user, cell, content, offset, clusters, count);
        tw_renderer_after_host(r);
        r->counters.draws++;
        r->counters.clusters += count;
        r->counters.ms_backend += tw_clock_monotonic_ms() - t0;
        return;
    }
    tw_renderer_enter_draw_mode(r);
    const struct tw_prototype *proto;
    const struct tw_gpu_buffers *b = tw_renderer_bind_content(r, content, &proto);
    if (r->recording)
        tw_renderer_record_clusters(r, cell, content, clusters, count);
    /* One multi-draw of every cluster in the order given, each command
     * naming its instance's record. */
    uint32_t records;
    if (!tw_renderer_stage_clusters(r, b, proto, offset, clusters, count, UINT32_MAX, &records)) {
        tw_log_printf(&r->log, TW_LOG_ERROR, "out of memory staging %u draws: not drawn", count);
        return;
    }
    for (uint32_t k = 0; k < count; k++)
        r->counters.triangles += proto->clusters[clusters[k]].triangle_count;
    r->counters.draws +=
        tw_renderer_draws_submit(r, r->stage_records, records, r->stage_commands, count);
    r->counters.clusters += count;
    r->counters.ms_backend += tw_clock_monotonic_ms() - t0;
}

/* Debugging: keeps the boxes of query handle, view-relative, until the
 * next frame; its result is filled in when it is read. */
static void record_query(struct tw_renderer *r, uint32_t handle, const struct tw_box *boxes,
                         uint32_t count, const float offset[3], bool tile)
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
        q->tile = tile;
        q->result = -1;
    }
}

/* The mutation of tw_world_tuning.mutate_query_shrink: b shrunk by f of
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
    /* Said of this query only (tile_query_next). */
    const bool tile = r->next_is_tile;
    r->next_is_tile = false;
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
        record_query(r, handle, boxes, count, offset, tile);
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
    r->counters.waits++;
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
    r->counters.flushes++;
    r->gl.Flush();
    const double dt = tw_clock_monotonic_ms() - t0;
    r->counters.ms_wait += dt;
    r->counters.ms_backend += dt;
}

/* Draws as backend_draw does, only if query (issued, not read yet) passes:
 * the GPU decides, with no wait (GL_QUERY_NO_WAIT: if the result is not in
 * when the draw reaches the GPU, it draws). The query is still read once,
 * with wait(), by its owner. */
static void backend_draw_if(void *ctx, uint32_t query, struct tw_cell cell, uint32_t content,
                            const float offset[3], const uint32_t *clusters, uint32_t count)
{
    struct tw_renderer *r = ctx;
    if (count == 0)
        return;
    if (query == TW_QUERY_VISIBLE) {
        backend_draw(ctx, cell, content, offset, clusters, count);
        return;
    }
    const struct tw_gl *gl = &r->gl;
    gl->BeginConditionalRender(r->queries[query - 1], GL_QUERY_NO_WAIT);
    backend_draw(ctx, cell, content, offset, clusters, count);
    gl->EndConditionalRender();
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
    r->counters.bytes_read_back += (uint64_t)r->width * r->height * 4u;
    const double dt = tw_clock_monotonic_ms() - t0;
    r->counters.ms_wait += dt;
    r->counters.ms_backend += dt;
    return true;
}

static void backend_tile_query_next(void *ctx)
{
    struct tw_renderer *r = ctx;
    r->next_is_tile = true;
}

struct tw_query_backend tw_renderer_backend(struct tw_renderer *r)
{
    struct tw_query_backend be = {
        .ctx = r,
        .issue = backend_issue,
        .ready = backend_ready,
        .wait = backend_wait,
        .draw = backend_draw,
        .draw_if = backend_draw_if,
        .flush = backend_flush,
        .read_depth = backend_read_depth,
        .tile_query_next = backend_tile_query_next,
    };
    if (r->host.draw) {
        /* The host's framebuffer: no conditional draws (the host's draws
         * are its own), and its depth read back for the HZB on the CPU
         * (the GPU's pyramid is built from the renderer's own depth). */
        be.draw_if = NULL;
        return be;
    }
    tw_renderer_gpu_hzb_ops(r, &be);
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

void tw_renderer_record_queries(struct tw_renderer *r, bool on)
{
    r->recording_queries = on;
}

const struct tw_renderer_query_box *tw_renderer_queries(const struct tw_renderer *r, size_t *count)
{
    *count = r->query_box_count;
    return r->query_boxes;
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


void tw_renderer_queries_init(struct tw_renderer *r)
{
    const struct tw_gl *gl = &r->gl;
    /* The unit box's corners and faces, boxes per instance. */
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


void tw_renderer_queries_begin_frame(struct tw_renderer *r, const struct tw_view *v)
{
    memset(&r->counters, 0, sizeof(r->counters));
    r->drawn_count = 0;
    tw_renderer_gpu_hzb_begin_frame(r, v);
    memcpy(r->eye, v->eye, sizeof(r->eye));
    if (r->query_box_count) {
        for (size_t k = 0; k < r->query_box_count; k++)
            r->query_record[r->query_boxes[k].query - 1] = 0;
        r->query_box_count = 0;
    }
}

void tw_renderer_queries_finish(struct tw_renderer *r)
{
    if (r->gl_loaded) {
        if (r->query_count)
            r->gl.DeleteQueries((GLsizei)r->query_count, r->queries);
        r->gl.DeleteVertexArrays(1, &r->query_vao);
        r->gl.DeleteBuffers(1, &r->query_ring);
    }
    free(r->query_boxes);
    free(r->query_corners);
    free(r->run_seen);
    free(r->run_record);
    free(r->query_record);
    free(r->drawn);
    free(r->queries);
    free(r->free_queries);
}
