/* The GPU store: tilesets' meshes uploaded into GL buffers, the contents
 * they hold, released (renderer.h). */
#include "runtime/renderer-private.h"
#include "tiles/array.h"
#include "tiles/tiles-internal.h"

#include <assert.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

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
static int upload_buffers(struct tw_renderer *r, const struct tw_tileset *ts,
                          struct tw_gpu_buffers *b)
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
    tw_renderer_draws_vertex_array(r);
    gl->BindVertexArray(0);
    /* An upload can come in the middle of a frame (a tile the frame waits
     * for): whatever mode the renderer was in, its vertex array is no
     * longer bound, so the next draw or query sets its state up again. */
    r->bound_vao = 0;
    r->mode = TW_RENDERER_MODE_NONE;
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

static void free_buffers(struct tw_renderer *r, struct tw_gpu_buffers *b)
{
    const struct tw_gl *gl = &r->gl;
    if (!r->gl_loaded) {
        /* The context is gone or not current: its objects went with it. */
        free(b->base_vertex);
        memset(b, 0, sizeof(*b));
        return;
    }
    if (b->vbo)
        gl->DeleteBuffers(1, &b->vbo);
    if (b->ibo)
        gl->DeleteBuffers(1, &b->ibo);
    if (b->vao) {
        if (r->bound_vao == b->vao)
            r->bound_vao = 0;
        gl->DeleteVertexArrays(1, &b->vao);
        r->mode = TW_RENDERER_MODE_NONE;    /* as after an upload */
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
        struct tw_gpu_content *c = realloc(r->contents, sizeof(*c) * cap);
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
    struct tw_gpu_buffers *b = &r->buffers[bi];
    memset(b, 0, sizeof(*b));
    /* A host that holds the tiles draws them: no copy here. */
    err = r->host.no_copies ? TW_OK : upload_buffers(r, ts, b);
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
        r->contents[first + p] = (struct tw_gpu_content){
            .buffers = bi, .proto = p, .bvh = bvhs ? bvhs[p] : NULL, .live = true,
            .base = first + p};
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
    struct tw_gpu_buffers *b = &r->buffers[bi];
    for (uint32_t p = 0; p < b->ts->prototype_count; p++) {
        r->contents[b->first_content + p].live = false;
        r->free_contents[r->free_content_count++] = b->first_content + p;
    }
    free_buffers(r, b);
    r->free_buffers[r->free_buffer_count++] = bi;
}

const struct tw_prototype *tw_renderer_content(const struct tw_renderer *r, uint32_t content,
                                               const struct tw_bvh **bvh)
{
    if (content >= r->content_count || !r->contents[content].live)
        return NULL;
    const struct tw_gpu_content *c = &r->contents[content];
    if (bvh)
        *bvh = c->bvh;
    return c->own ? c->own : &r->buffers[c->buffers].ts->prototypes[c->proto];
}

/* A live content that is no composite: what a content of its own or a
 * composite's part is made from. */
static bool plain_content(const struct tw_renderer *r, uint32_t c)
{
    return c < r->content_count && r->contents[c].live && !r->contents[c].composite;
}

int tw_renderer_add_content(struct tw_renderer *r, uint32_t like, const struct tw_prototype *proto,
                            const struct tw_bvh *bvh, uint32_t *out)
{
    if (!plain_content(r, like))
        return TW_ERR_INVALID;
    const uint32_t buffers = r->contents[like].buffers;
    uint32_t c;
    int err = take_contents(r, 1, &c);
    if (err)
        return err;
    r->contents[c] = (struct tw_gpu_content){
        .buffers = buffers, .proto = UINT32_MAX, .bvh = bvh, .live = true, .base = c, .own = proto};
    *out = c;
    return TW_OK;
}

int tw_renderer_add_composite(struct tw_renderer *r, uint32_t first, uint32_t second,
                              uint32_t split, const struct tw_prototype *proto,
                              const struct tw_bvh *bvh, uint32_t *out)
{
    if (!plain_content(r, second))
        return TW_ERR_INVALID;
    const int err = tw_renderer_add_content(r, first, proto, bvh, out);
    if (err)
        return err;
    struct tw_gpu_content *c = &r->contents[*out];
    c->composite = true;
    c->part[0] = first;
    c->part[1] = second;
    c->split = split;
    return TW_OK;
}

void tw_renderer_set_content_bvh(struct tw_renderer *r, uint32_t content,
                                 const struct tw_bvh *bvh)
{
    if (content < r->content_count && r->contents[content].live && r->contents[content].own)
        r->contents[content].bvh = bvh;
}

void tw_renderer_remove_content(struct tw_renderer *r, uint32_t content)
{
    if (content >= r->content_count || !r->contents[content].live || !r->contents[content].own)
        return;
    r->contents[content].live = false;
    r->free_contents[r->free_content_count++] = content;
}

bool tw_renderer_split(struct tw_renderer *r, uint32_t content, const uint32_t *clusters,
                       uint32_t count, tw_renderer_run_fn fn, void *user)
{
    if (content >= r->content_count || !r->contents[content].live ||
        !r->contents[content].composite)
        return false;
    const struct tw_gpu_content c = r->contents[content];
    if (tw_array_reserve_u32((void **)&r->split_clusters, &r->split_cap, count,
                             sizeof(*r->split_clusters), 1024)) {
        tw_log_printf(&r->log, TW_LOG_ERROR, "out of memory splitting %u draws: not drawn",
                      count);
        return true;
    }
    /* One scratch for every split: the parts fn is given are never
     * composites (tw_renderer_add_composite), so fn never splits again. */
    uint32_t *sub = r->split_clusters;
    for (uint32_t k = 0; k < count; k++)
        sub[k] = clusters[k] < c.split ? clusters[k] : clusters[k] - c.split;
    uint32_t start = 0;
    for (uint32_t k = 1; k <= count; k++) {
        if (k < count && (clusters[k] < c.split) == (clusters[start] < c.split))
            continue;
        fn(r, user, clusters[start] < c.split ? c.part[0] : c.part[1], sub + start, k - start,
           start);
        start = k;
    }
    return true;
}

const struct tw_tileset *tw_renderer_content_tileset(const struct tw_renderer *r, uint32_t content)
{
    if (content >= r->content_count || !r->contents[content].live)
        return NULL;
    return r->buffers[r->contents[content].buffers].ts;
}

void tw_renderer_tag_levels(struct tw_renderer *r, uint32_t base, uint32_t first, uint32_t count)
{
    if (base >= r->content_count || (count && first + count > r->content_count))
        return;
    r->contents[base].levels_first = first;
    r->contents[base].levels_count = count;
    for (uint32_t k = 0; k < count; k++) {
        r->contents[first + k].base = base;
        r->contents[first + k].level = k + 1;
    }
}

void tw_renderer_set_host_data(struct tw_renderer *r, uint32_t content, void *data)
{
    if (content < r->content_count && r->contents[content].live)
        r->contents[content].host_data = data;
}

void *tw_renderer_host_data(const struct tw_renderer *r, uint32_t content)
{
    if (content >= r->content_count || !r->contents[content].live)
        return NULL;
    const uint32_t base = r->contents[content].base;
    return base < r->content_count && r->contents[base].live ? r->contents[base].host_data : NULL;
}

uint32_t tw_renderer_content_base(const struct tw_renderer *r, uint32_t content, uint32_t *level)
{
    *level = 0;
    if (content >= r->content_count || !r->contents[content].live)
        return content;
    *level = r->contents[content].level;
    return r->contents[content].base;
}

uint32_t tw_renderer_level_content(const struct tw_renderer *r, uint32_t base, uint32_t level)
{
    if (base >= r->content_count || !r->contents[base].live)
        return UINT32_MAX;
    const struct tw_gpu_content *c = &r->contents[base];
    if (level == 0)
        return base;
    return level <= c->levels_count ? c->levels_first + level - 1 : UINT32_MAX;
}

const struct tw_gpu_buffers *tw_renderer_bind_content(struct tw_renderer *r, uint32_t content,
                                                      const struct tw_prototype **proto)
{
    assert(content < r->content_count && r->contents[content].live);
    const struct tw_gpu_content *c = &r->contents[content];
    const struct tw_gpu_buffers *b = &r->buffers[c->buffers];
    if (r->bound_vao != b->vao) {
        r->gl.BindVertexArray(b->vao);
        r->bound_vao = b->vao;
    }
    assert(!c->composite);
    *proto = tw_renderer_content(r, content, NULL);
    return b;
}

void tw_renderer_store_finish(struct tw_renderer *r)
{
    for (uint32_t b = 0; b < r->buffer_count; b++)
        if (r->buffers[b].live)
            free_buffers(r, &r->buffers[b]);
    free(r->buffers);
    free(r->free_buffers);
    free(r->contents);
    free(r->free_contents);
    free(r->split_clusters);
}
