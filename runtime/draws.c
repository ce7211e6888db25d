/* Draw submission (renderer-private.h): every draw of clusters, the
 * scene's and the ID pass's, is a list of indirect commands over one
 * tileset's buffers, each naming a per-draw record (its instance's
 * transform, the tile's offset, its colour or ID) by its base instance.
 * With GL 4.3 the list is one glMultiDrawElementsIndirect; without it, one
 * draw per command with the record's attributes pointed at directly. */
#include "runtime/renderer-private.h"
#include "tiles/array.h"
#include "tiles/tiles-internal.h"

#include <stdlib.h>
#include <string.h>

/* Room in the rings; a submission larger than a ring grows it. */
#define RECORD_RING 16384u
#define COMMAND_RING 65536u
/* Offsets into the command ring that a compute pass binds are aligned to
 * this (GL's shader storage offset alignment is at most 256 bytes). */
#define COMMAND_ALIGN 256u

bool tw_renderer_draws_reserve(struct tw_renderer *r, uint32_t records, uint32_t commands)
{
    return !tw_array_reserve((void **)&r->stage_records, &r->stage_record_cap, records,
                             sizeof(*r->stage_records), 256) &&
           !tw_array_reserve((void **)&r->stage_commands, &r->stage_command_cap, commands,
                             sizeof(*r->stage_commands), 256);
}

static void ring_storage(struct tw_renderer *r, GLenum target, GLuint buffer, size_t bytes)
{
    r->gl.BindBuffer(target, buffer);
    r->gl.BufferData(target, (GLsizeiptr)bytes, NULL, GL_STREAM_DRAW);
}

void tw_renderer_draws_init(struct tw_renderer *r, bool mdi)
{
    const struct tw_gl *gl = &r->gl;
    r->has_mdi = mdi;
    r->record_ring_cap = RECORD_RING;
    r->command_ring_cap = COMMAND_RING;
    gl->GenBuffers(1, &r->record_ring);
    ring_storage(r, GL_ARRAY_BUFFER, r->record_ring,
                 (size_t)r->record_ring_cap * sizeof(struct tw_draw_record));
    if (mdi) {
        gl->GenBuffers(1, &r->command_ring);
        ring_storage(r, GL_DRAW_INDIRECT_BUFFER, r->command_ring,
                     (size_t)r->command_ring_cap * sizeof(struct tw_draw_command));
        gl->BindBuffer(GL_DRAW_INDIRECT_BUFFER, 0);
    }
}

void tw_renderer_draws_finish(struct tw_renderer *r)
{
    if (r->gl_loaded) {
        if (r->record_ring)
            r->gl.DeleteBuffers(1, &r->record_ring);
        if (r->command_ring)
            r->gl.DeleteBuffers(1, &r->command_ring);
    }
    r->record_ring = r->command_ring = 0;
    free(r->stage_records);
    free(r->stage_commands);
    r->stage_records = NULL;
    r->stage_commands = NULL;
    r->stage_record_cap = r->stage_command_cap = 0;
}

/* Points the record attributes (locations 3 to 7) of the bound vertex
 * array at record `first` of the ring. */
static void point_records(const struct tw_gl *gl, GLuint ring, uint32_t first)
{
    gl->BindBuffer(GL_ARRAY_BUFFER, ring);
    const size_t at = (size_t)first * sizeof(struct tw_draw_record);
    for (GLuint k = 0; k < 5; k++)
        gl->VertexAttribPointer(3 + k, 4, GL_FLOAT, GL_FALSE, sizeof(struct tw_draw_record),
                                (const void *)(at + 16u * k));
}

void tw_renderer_draws_vertex_array(struct tw_renderer *r)
{
    const struct tw_gl *gl = &r->gl;
    for (GLuint k = 0; k < 5; k++) {
        gl->EnableVertexAttribArray(3 + k);
        gl->VertexAttribDivisor(3 + k, 1);
    }
    point_records(gl, r->record_ring, 0);
}

uint32_t tw_renderer_draws_put_records(struct tw_renderer *r, const struct tw_draw_record *rec,
                                       uint32_t n)
{
    const struct tw_gl *gl = &r->gl;
    if (n > r->record_ring_cap) {
        while (r->record_ring_cap < n)
            r->record_ring_cap *= 2;
        r->record_ring_next = r->record_ring_cap;   /* storage made below */
    }
    if (r->record_ring_next + n > r->record_ring_cap) {
        /* Wrapped: fresh storage, so that draws still queued keep theirs. */
        ring_storage(r, GL_ARRAY_BUFFER, r->record_ring,
                     (size_t)r->record_ring_cap * sizeof(*rec));
        r->record_ring_next = 0;
    } else {
        gl->BindBuffer(GL_ARRAY_BUFFER, r->record_ring);
    }
    const uint32_t first = r->record_ring_next;
    gl->BufferSubData(GL_ARRAY_BUFFER, (GLintptr)((size_t)first * sizeof(*rec)),
                      (GLsizeiptr)((size_t)n * sizeof(*rec)), rec);
    r->record_ring_next += n;
    return first;
}

size_t tw_renderer_draws_put_commands(struct tw_renderer *r, const struct tw_draw_command *cmd,
                                      uint32_t n)
{
    const struct tw_gl *gl = &r->gl;
    /* Each run starts on a COMMAND_ALIGN boundary, where a compute pass
     * may bind it. */
    size_t at = r->command_ring_bytes;
    at = (at + COMMAND_ALIGN - 1) / COMMAND_ALIGN * COMMAND_ALIGN;
    const size_t bytes = (size_t)n * sizeof(*cmd);
    size_t cap = (size_t)r->command_ring_cap * sizeof(*cmd);
    if (bytes > cap) {
        while ((size_t)r->command_ring_cap * sizeof(*cmd) < bytes)
            r->command_ring_cap *= 2;
        cap = (size_t)r->command_ring_cap * sizeof(*cmd);
        at = cap;   /* storage made below */
    }
    if (at + bytes > cap) {
        ring_storage(r, GL_DRAW_INDIRECT_BUFFER, r->command_ring, cap);
        at = 0;
    } else {
        gl->BindBuffer(GL_DRAW_INDIRECT_BUFFER, r->command_ring);
    }
    gl->BufferSubData(GL_DRAW_INDIRECT_BUFFER, (GLintptr)at, (GLsizeiptr)bytes, cmd);
    r->command_ring_bytes = at + bytes;
    return at;
}

void tw_renderer_draws_commands(struct tw_renderer *r, size_t at, uint32_t n)
{
    const struct tw_gl *gl = &r->gl;
    gl->BindBuffer(GL_DRAW_INDIRECT_BUFFER, r->command_ring);
    gl->MultiDrawElementsIndirect(GL_TRIANGLES, GL_UNSIGNED_INT, (const void *)at, (GLsizei)n,
                                  0);
}

uint32_t tw_renderer_draws_submit(struct tw_renderer *r, const struct tw_draw_record *rec,
                                  uint32_t records, struct tw_draw_command *cmd, uint32_t commands)
{
    if (commands == 0)
        return 0;
    const struct tw_gl *gl = &r->gl;
    const uint32_t first = tw_renderer_draws_put_records(r, rec, records);
    if (r->has_mdi) {
        for (uint32_t k = 0; k < commands; k++)
            cmd[k].base_instance += first;
        const size_t at = tw_renderer_draws_put_commands(r, cmd, commands);
        tw_renderer_draws_commands(r, at, commands);
        return 1;
    }
    /* GL before 4.3: one draw per command, the record attributes pointed at
     * its record (the vertex array's pointers are put back after). */
    for (uint32_t k = 0; k < commands; k++) {
        if (k == 0 || cmd[k].base_instance != cmd[k - 1].base_instance)
            point_records(gl, r->record_ring, first + cmd[k].base_instance);
        gl->DrawElementsBaseVertex(GL_TRIANGLES, (GLsizei)cmd[k].count, GL_UNSIGNED_INT,
                                   (const void *)((size_t)cmd[k].first_index * sizeof(uint32_t)),
                                   cmd[k].base_vertex);
    }
    point_records(gl, r->record_ring, 0);
    return commands;
}

void tw_renderer_draws_record(struct tw_draw_record *rec, const struct tw_instance *in,
                              const float offset[3], const float color[4], float id)
{
    memcpy(rec->model, in->transform, sizeof(rec->model));
    rec->offset[0] = offset[0];
    rec->offset[1] = offset[1];
    rec->offset[2] = offset[2];
    rec->offset[3] = id;
    memcpy(rec->color, color, sizeof(rec->color));
}

void tw_renderer_draws_command(struct tw_draw_command *c, const struct tw_gpu_buffers *b,
                               const struct tw_tileset *ts, const struct tw_cluster *cl,
                               uint32_t record)
{
    const struct tw_mesh_part *part = &ts->parts[cl->part];
    c->count = 3u * part->triangle_count;
    c->instance_count = 1;
    c->first_index = b->first_index[part->mesh] + 3u * part->first_triangle;
    c->base_vertex = (int32_t)b->base_vertex[part->mesh];
    c->base_instance = record;
}
