/*
 * Hierarchical cells in the world (DESIGN §17, README "Hierarchical
 * cells"): the culling runs over a cut of blocks of 2^k x 2^k cells
 * (cull/hierarchy.c), and a block's tile is its proxy: every cell's shared
 * prototype at its coarsest level whose error is within the block level's
 * error, merged into one tile (tiles/hlod.c). Each level's proxies are
 * made on worker threads by a stream of their own, whose "cells" are the
 * blocks of that level; they count in the budget like any tile.
 *
 * A level-k block is used where it projects to at most block_px pixels
 * across, that is from the distance r_k = 2^k W f / block_px (f: the focal
 * length in pixels) on; there max_screen_error pixels are E_k = 2^k W
 * max_screen_error / block_px metres, the error its proxy may have. E_k is
 * fixed when the world is made; r_k follows the view's focal length, so a
 * proxy stays valid whatever the image size.
 */
#include "runtime/world-private.h"
#include "tiles/tiles-internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Instance keys of a level's proxies: above the shared contents and their
 * levels, and below the stream's level bits. */
#define HLOD_KEY_BASE 0x08000000u
#define HLOD_KEY_SHIFT 22

/* The base cell of the level's block with block coordinates b. */
static struct tw_cell block_base(struct tw_cell b, uint32_t level)
{
    return (struct tw_cell){(int64_t)((uint64_t)b.i << level), (int64_t)((uint64_t)b.j << level)};
}

/* The block coordinates of the level's block whose base is cell (two's
 * complement shifts round towards -inf). */
static struct tw_cell block_of(struct tw_cell cell, uint32_t level)
{
    return (struct tw_cell){cell.i >> level, cell.j >> level};
}

/* The shared prototype of each cell of level l's block (TW_HLOD_EMPTY:
 * none), row by row; NULL when out of memory. */
static uint32_t *block_protos(const struct tw_world_hlod_level *l, struct tw_cell block)
{
    const struct tw_world *w = l->w;
    const uint32_t side = 1u << l->level;
    const struct tw_cell base = block_base(block, l->level);
    uint32_t *protos = malloc(sizeof(*protos) * side * side);
    if (!protos)
        return NULL;
    const struct tw_tile_provider *p = &w->provider;
    for (uint32_t z = 0; z < side; z++)
        for (uint32_t x = 0; x < side; x++) {
            const struct tw_cell c = {(int64_t)((uint64_t)base.i + x),
                                      (int64_t)((uint64_t)base.j + z)};
            const uint32_t content = p->content(p->user, c);
            protos[z * side + x] = content < w->shared_count ? content : TW_HLOD_EMPTY;
        }
    return protos;
}

/* A proxy, on a worker: the block's cells' prototypes at their coarsest
 * level within the level's error, into ts (the block's footprint). */
static int proxy_generate(void *user, struct tw_cell block, struct tw_tileset *ts)
{
    const struct tw_world_hlod_level *l = user;
    const struct tw_world *w = l->w;
    const uint32_t side = 1u << l->level;
    uint32_t *protos = block_protos(l, block);
    if (!protos)
        return TW_ERR_NOMEM;
    const struct tw_tile_provider *p = &w->provider;
    float input_error;
    const int err = tw_hlod_block_fill(p->shared, w->lods->levels ? w->lods : NULL, protos, side,
                                       l->error, ts, &input_error);
    free(protos);
    return err;
}

/* A proxy's levels of detail, on a worker: the same cells at their coarser
 * levels (tw_hlod_block_levels()), not the proxy simplified (ts, unused,
 * is what proxy_generate() made of them). */
static int proxy_levels(void *user, struct tw_cell block, const struct tw_tileset *ts,
                        const atomic_bool *stop, struct tw_lods *out)
{
    (void)ts;
    const struct tw_world_hlod_level *l = user;
    const struct tw_world *w = l->w;
    uint32_t *protos = block_protos(l, block);
    if (!protos) {
        memset(out, 0, sizeof(*out));
        return TW_ERR_NOMEM;
    }
    const int err = tw_hlod_block_levels(w->provider.shared, w->lods->levels ? w->lods : NULL,
                                         protos, 1u << l->level, l->error,
                                         w->provider.shared->max_cluster_triangles, stop, out);
    free(protos);
    return err;
}

_Static_assert(TW_PROVIDER_MAX_LEVELS + 1 <= TW_CULL_MAX_LEVELS,
               "a provider's levels and its cells fit the hierarchy");

/* A block of the provider's own coarser levels, on a worker. */
static int provider_level_generate(void *user, struct tw_cell block, struct tw_tileset *ts)
{
    const struct tw_world_hlod_level *l = user;
    const struct tw_tile_provider *p = &l->w->provider;
    return p->generate_level(p->user, l->level, block, ts);
}

uint32_t tw_world_hlod_wanted(const struct tw_world *w)
{
    if (!w->lod_on)
        return 0;
    const struct tw_tile_provider *p = &w->provider;
    const uint32_t own = p->generate_level ? p->levels : 0;
    /* 0: the provider's own levels where it has them, unless the world
     * has moving objects (a block would leave them out) or a host draws it
     * (its hooks are told of cells, not blocks); else cells only. */
    if (w->t.hlod_levels == 0)
        return own && !w->s.object_models && !w->s.host.draw ? own + 1 : 0;
    return own && w->t.hlod_levels > own + 1 ? own + 1 : w->t.hlod_levels;
}

/* Level k's stream: its "cells" are the level's blocks, each a tile of
 * the block's footprint inside the common box stretched over the block,
 * made by generate (l its user). */
static int start_level(struct tw_world *w, struct tw_world_hlod_level *l,
                       int (*generate)(void *, struct tw_cell, struct tw_tileset *),
                       uint32_t max_cluster_triangles)
{
    const struct tw_tile_provider *p = &w->provider;
    const uint32_t k = l->level;
    struct tw_cull_grid g = {.footprint = {p->footprint[0], p->footprint[1]},
                             .common_box = p->bound};
    snprintf(l->name, sizeof(l->name), "%.24s blocks of %ux%u", p->name ? p->name : "",
             1u << k, 1u << k);
    l->provider = (struct tw_tile_provider){
        .name = l->name,
        .footprint = {(float)(1u << k) * p->footprint[0], (float)(1u << k) * p->footprint[1]},
        .bound = tw_cull_node_box(&g, k),
        .generate = generate,
        .user = l,
        .max_cluster_triangles = max_cluster_triangles,
    };
    struct tw_stream_settings ss =
        tw_world_stream_settings(w, &l->provider, HLOD_KEY_BASE + (k << HLOD_KEY_SHIFT));
    if (generate == proxy_generate) {
        ss.levels = proxy_levels;
        ss.levels_user = l;
    }
    return tw_stream_create(&ss, &l->stream);
}

/* The world uses a provider's own coarser levels: each level's blocks are
 * the provider's, with the provider's error. */
static int start_provider_levels(struct tw_world *w, uint32_t count)
{
    struct tw_world_hlod *h = &w->hlod;
    const struct tw_tile_provider *p = &w->provider;
    h->count = count;
    for (uint32_t k = 1; k < count; k++) {
        struct tw_world_hlod_level *l = &h->levels[k];
        l->w = w;
        l->level = k;
        l->error = p->level_error[k - 1];
        tw_log_printf(&w->s.log, TW_LOG_INFO,
                      "hierarchical cells: the provider's blocks of %ux%u cells, error %.3g m",
                      1u << k, 1u << k, (double)l->error);
        const int err = start_level(w, l, provider_level_generate, p->max_cluster_triangles);
        if (err)
            return err;
    }
    return TW_OK;
}

int tw_world_hlod_start(struct tw_world *w)
{
    struct tw_world_hlod *h = &w->hlod;
    const uint32_t count = tw_world_hlod_wanted(w);
    if (count < 2)
        return TW_OK;
    const struct tw_tile_provider *p = &w->provider;
    /* (tw_world_resolve_provider() has checked the levels.) */
    if (p->generate_level && p->levels > 0)
        return start_provider_levels(w, count);
    if (count > TW_CULL_MAX_LEVELS) {
        tw_log_printf(&w->s.log, TW_LOG_ERROR, "hierarchical cells: %u levels, at most %u",
                      count, TW_CULL_MAX_LEVELS);
        return TW_ERR_INVALID;
    }
    /* A proxy needs the prototype of every cell of its block, on a worker:
     * the tileset's own selection (a hash), not a host's callback, which
     * is called on the render thread only. */
    if (w->s.provider || w->s.selection.fn) {
        tw_log_printf(&w->s.log, TW_LOG_ERROR,
                      "hierarchical cells need a tileset selected by the library or a provider "
                      "with coarser levels of its own (%s %s)",
                      w->s.provider ? "provider" : "the selection of",
                      w->s.provider ? (p->name ? p->name : "(unnamed)")
                                    : "the tileset is a host's callback");
        return TW_ERR_INVALID;
    }
    h->count = count;
    for (uint32_t k = 1; k < count; k++) {
        struct tw_world_hlod_level *l = &h->levels[k];
        l->w = w;
        l->level = k;
        l->error = tw_hlod_level_error(p->footprint, k, w->s.max_screen_error,
                                       w->t.hlod_block_px);
        /* A proxy is unique geometry where cells share prototypes: a level
         * whose proxies would be large (their cells still detailed at its
         * error) costs memory and time for nothing, and is always refined
         * (no stream). */
        uint64_t input;
        const bool pays = tw_hlod_level_pays(p->shared, w->lods, k, l->error, &input);
        tw_log_printf(&w->s.log, TW_LOG_INFO,
                      "hierarchical cells: blocks of %ux%u cells, error %.3g m, proxies of up "
                      "to %llu triangles: %s",
                      1u << k, 1u << k, (double)l->error, (unsigned long long)input,
                      pays ? "used" : "too many, always refined");
        if (!pays)
            continue;
        const int err = start_level(w, l, proxy_generate, p->shared->max_cluster_triangles);
        if (err)
            return err;
    }
    /* Levels above the coarsest that pays are refined always: none. */
    while (h->count > 1 && !h->levels[h->count - 1].stream)
        h->count--;
    if (h->count > 1)
        return TW_OK;
    /* No level pays: cells only, and their reach within the bound. */
    h->count = 0;
    const double reach = tw_tiles_cells_in_reach(&p->bound, p->footprint[0], p->footprint[1],
                                                 w->s.view_distance);
    if (!(reach <= TW_TILES_MAX_CELLS_IN_VIEW)) {
        tw_log_printf(&w->s.log, TW_LOG_ERROR,
                      "cannot create the world: %s: no level of hierarchical cells pays (every "
                      "block's proxy would hold more than %u triangles), and a view distance of "
                      "%g m reaches about %.3g cells, more than the limit of %u a frame",
                      p->name ? p->name : "the world", TW_HLOD_MAX_INPUT,
                      (double)w->s.view_distance, reach, TW_TILES_MAX_CELLS_IN_VIEW);
        return TW_ERR_LIMIT;
    }
    return TW_OK;
}

uint32_t tw_world_hlod_stop(struct tw_world *w)
{
    uint32_t left = 0;
    for (uint32_t k = 1; k < TW_CULL_MAX_LEVELS; k++) {
        left += tw_stream_destroy(w->hlod.levels[k].stream);
        w->hlod.levels[k].stream = NULL;
    }
    return left;
}

void tw_world_hlod_begin_frame(struct tw_world *w)
{
    struct tw_world_hlod *h = &w->hlod;
    w->grid.levels = (struct tw_cull_levels){0};
    if (h->count < 2)
        return;
    w->grid.levels.count = h->count;
    for (uint32_t k = 1; k < h->count; k++)
        w->grid.levels.refine[k] =
            h->levels[k].stream ? h->levels[k].error * w->lod_px_per_m / w->s.max_screen_error
                                : INFINITY;
    for (uint32_t k = 1; k < h->count; k++)
        if (h->levels[k].stream)
            tw_stream_begin_frame(h->levels[k].stream, w->frame_serial);
}

int tw_world_hlod_get(struct tw_world *w, struct tw_cell cell, uint32_t level, float distance,
                      unsigned flags, float max_error, struct tw_cull_tile *out)
{
    if (level >= w->hlod.count || !w->hlod.levels[level].stream)
        return TW_ERR_INVALID;
    /* A proxy's levels' errors are counted beyond the level's, which its
     * cells already have (tw_hlod_block_levels(), or a provider's own
     * simplified): what is left for them. */
    const float left = max_error - w->hlod.levels[level].error;
    return tw_stream_get(w->hlod.levels[level].stream, block_of(cell, level), distance, flags,
                         left > 0.0f ? left : 0.0f, out);
}

void tw_world_hlod_prefetch(struct tw_world *w, struct tw_cell cell, uint32_t level,
                            float distance)
{
    if (level < w->hlod.count && w->hlod.levels[level].stream)
        tw_stream_prefetch(w->hlod.levels[level].stream, block_of(cell, level), distance);
}

void tw_world_hlod_bytes(const struct tw_world *w, uint64_t *cpu, uint64_t *gpu)
{
    for (uint32_t k = 1; k < w->hlod.count; k++) {
        uint64_t c = 0, g = 0;
        if (w->hlod.levels[k].stream)
            tw_stream_bytes(w->hlod.levels[k].stream, &c, &g);
        *cpu += c;
        *gpu += g;
    }
}

uint64_t tw_world_hlod_trim(struct tw_world *w, uint64_t excess)
{
    uint64_t freed = 0;
    /* Level by level, the finest first; each stream evicts its least
     * recently drawn proxies. */
    for (uint32_t k = 1; k < w->hlod.count && freed < excess; k++)
        if (w->hlod.levels[k].stream)
            freed += tw_stream_trim(w->hlod.levels[k].stream, excess - freed, tw_world_keep_from(w), NULL,
                                NULL);
    return freed;
}

void tw_world_hlod_invalidate(struct tw_world *w, struct tw_cell lo, struct tw_cell hi)
{
    for (uint32_t k = 1; k < w->hlod.count; k++)
        if (w->hlod.levels[k].stream)
            tw_stream_invalidate_rect(w->hlod.levels[k].stream, block_of(lo, k), block_of(hi, k));
}

void tw_world_hlod_stats(const struct tw_world *w, struct tw_frame_stats *st)
{
    for (uint32_t k = 1; k < w->hlod.count; k++) {
        const struct tw_stream *s = w->hlod.levels[k].stream;
        if (!s)
            continue;
        const struct tw_stream_stats *ss = tw_stream_stats(s);
        st->bytes_needed = st->bytes_needed - tw_stream_tile_bytes(s) + ss->bytes_used;
        st->loads_requested += ss->loads_requested;
        st->loads_done += ss->loads_done;
        st->evictions += ss->evictions;
        st->ms_upload += ss->ms_upload;
        st->bytes_loading += ss->bytes_loading;
        st->tiles_loading += ss->tiles_loading;
    }
}
