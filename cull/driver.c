/*
 * The method drivers (cull.h): one frame over the grid, top-down. A driver
 * keeps what every method shares (the tile cache of their instances, the
 * way to a cell's tile through the tile source, the frame's cells in view)
 * and leaves the rest to its method, one file each behind an ops table
 * (cull-private.h):
 *
 *   method-vfc.c        every cell in view, its clusters in the frustum
 *   method-chc.c        every cell in view, CHC++ over its BVH
 *   method-tilequery.c  tile-query propagation with a local method: frustum
 *                       culling (tilequery), CHC++ (tilequery+chc), the
 *                       depth pyramid (tilequery+hzb)
 *   method-hzb.c        two-phase HZB over every cell in view
 *   method-given.c      a given set of clusters (the oracles, fixed sets)
 */
#include "cull/cull-private.h"
#include "tiles/tiles-internal.h"

#include <stdlib.h>
#include <string.h>

struct tw_cull_driver {
    enum tw_cull_method method;
    unsigned source_flags;
    struct tw_tile_cache *cache;        /* tile instances; NULL for a method without */
    struct tw_cull_method_base *m;
};

/* ---- a fixed tileset as a tile source -------------------------------------------------- */

static int fixed_get(void *ctx, struct tw_cell cell, uint32_t level, float distance,
                     unsigned flags, struct tw_cull_tile *out)
{
    const struct tw_cull_fixed *f = ctx;
    if (level > 0) {
        tw_log_printf(f->log, TW_LOG_ERROR, "a fixed tileset has no tiles for blocks of cells");
        return TW_ERR_INVALID;
    }
    const uint32_t p = tw_tiles_select(f->tileset, f->selection, cell);
    if (p == TW_TILE_EMPTY) {
        *out = (struct tw_cull_tile){.key = TW_CULL_KEY_EMPTY};
        return TW_OK;
    }
    if (p >= f->tileset->prototype_count) {
        tw_log_printf(f->log, TW_LOG_ERROR,
                      "selection: cell (%lld, %lld) shows prototype %u, but the tileset has %u",
                      (long long)cell.i, (long long)cell.j, p, f->tileset->prototype_count);
        return TW_ERR_INVALID;
    }
    out->proto = &f->tileset->prototypes[p];
    out->bvh = f->bvhs[p];
    out->content = p;
    out->key = p;
    return TW_OK;
}

struct tw_tile_source tw_cull_fixed_source(const struct tw_cull_fixed *f)
{
    return (struct tw_tile_source){(void *)f, fixed_get, NULL};
}

struct tw_cull_grid tw_cull_fixed_grid(const struct tw_cull_fixed *f)
{
    struct tw_cull_grid g = {
        .footprint = {f->tileset->footprint[0], f->tileset->footprint[1]},
        .common_box = f->tileset->common_box,
        .source = tw_cull_fixed_source(f),
    };
    return g;
}

/* ---- the cells in view of a frame ----------------------------------------------------- */

int tw_cull_cells_of_frame(struct tw_cull_cells *c, const struct tw_view *v,
                           const struct tw_cull_grid *g)
{
    if (c->valid && c->cell.i == v->cell.i && c->cell.j == v->cell.j &&
        c->view_distance == v->view_distance &&
        memcmp(c->view_proj, v->view_proj, sizeof(c->view_proj)) == 0 &&
        memcmp(&c->levels, &g->levels, sizeof(c->levels)) == 0 &&
        memcmp(&c->common_box, &g->common_box, sizeof(c->common_box)) == 0)
        return TW_OK;
    for (;;) {
        const size_t n = tw_cull_nodes_in_view(v, g, c->cells, c->cap, NULL);
        if (n <= c->cap) {
            c->count = n;
            c->valid = true;
            c->cell = v->cell;
            c->view_distance = v->view_distance;
            memcpy(c->view_proj, v->view_proj, sizeof(c->view_proj));
            c->levels = g->levels;
            c->common_box = g->common_box;
            return TW_OK;
        }
        struct tw_cull_cell *cells = realloc(c->cells, sizeof(*cells) * n);
        if (!cells)
            return TW_ERR_NOMEM;
        c->cells = cells;
        c->cap = n;
    }
}

void tw_cull_cells_finish(struct tw_cull_cells *c)
{
    free(c->cells);
    memset(c, 0, sizeof(*c));
}

/* ---- the driver ------------------------------------------------------------------------ */

typedef int (*method_create_fn)(const struct tw_cull_driver_settings *s,
                                struct tw_cull_method_base **out);

static const method_create_fn method_create[TW_CULL_METHOD_COUNT] = {
    [TW_CULL_VFC] = tw_cull_vfc_method_create,
    [TW_CULL_TILEQUERY] = tw_cull_tilequery_method_create,
    [TW_CULL_CHC] = tw_cull_chc_method_create,
    [TW_CULL_TILEQUERY_CHC] = tw_cull_tilequery_chc_method_create,
    [TW_CULL_GIVEN] = tw_cull_given_method_create,
    [TW_CULL_HZB] = tw_cull_hzb_method_create,
    [TW_CULL_TILEQUERY_HZB] = tw_cull_tilequery_hzb_method_create,
};

int tw_cull_driver_create(const struct tw_cull_driver_settings *settings,
                          struct tw_cull_driver **out)
{
    if (!settings || !out || (unsigned)settings->method >= TW_CULL_METHOD_COUNT)
        return TW_ERR_INVALID;
    struct tw_cull_driver *d = calloc(1, sizeof(*d));
    if (!d)
        return TW_ERR_NOMEM;
    struct tw_cull_driver_settings s = *settings;
    if (s.evict_after_frames == 0)
        s.evict_after_frames = 60;
    tw_chc_default_settings(&s.chc);
    tw_tilequery_default_settings(&s.tilequery);
    d->method = s.method;
    d->source_flags = s.source_flags;
    int err = method_create[s.method](&s, &d->m);
    if (!err && d->m->impl->tile_instances)
        err = tw_tile_cache_create(s.evict_after_frames, &d->cache);
    if (err) {
        tw_cull_driver_destroy(d);
        return err;
    }
    *out = d;
    return TW_OK;
}

void tw_cull_driver_destroy(struct tw_cull_driver *d)
{
    if (!d)
        return;
    if (d->m)
        d->m->impl->destroy(d->m);
    tw_tile_cache_destroy(d->cache);
    free(d);
}

void tw_cull_driver_give(struct tw_cull_driver *d, const struct tw_drawn_cluster *set,
                         size_t count)
{
    if (d->m->impl->give)
        d->m->impl->give(d->m, set, count);
}

void tw_cull_driver_set_costs(struct tw_cull_driver *d, const struct tw_cost_model *costs)
{
    if (d && d->m->impl->set_costs)
        d->m->impl->set_costs(d->m, costs);
}

enum tw_cull_method tw_cull_driver_method(const struct tw_cull_driver *d)
{
    return d->method;
}

const struct tw_tilequery *tw_cull_driver_tilequery(const struct tw_cull_driver *d)
{
    return d->m->impl->tilequery ? d->m->impl->tilequery(d->m) : NULL;
}

size_t tw_cull_driver_bytes(const struct tw_cull_driver *d)
{
    return sizeof(*d) + (d->cache ? tw_tile_cache_bytes(d->cache) : 0) +
           d->m->impl->bytes(d->m);
}

int tw_cull_driver_frame(struct tw_cull_driver *d, const struct tw_view *v,
                         const struct tw_cull_grid *g, const struct tw_query_backend *be,
                         struct tw_cull_cells *cells, struct tw_cull_frame_stats *stats)
{
    if (!d || !v || !g || !be || !cells)
        return TW_ERR_INVALID;
    struct tw_cull_frame_stats st = {0};
    struct tw_cull_frame fr = {
        .v = v, .g = g, .be = be, .cells = cells, .cache = d->cache,
        .source_flags = d->source_flags, .st = &st, .err = TW_OK,
    };
    const int err = d->m->impl->frame(d->m, &fr);
    if (d->cache) {
        tw_tile_cache_evict(d->cache, v->frame);
        st.tiles_cached = tw_tile_cache_count(d->cache);
        st.cache_bytes = tw_tile_cache_bytes(d->cache);
    }
    if (stats)
        *stats = st;
    return err;
}

void tw_cull_driver_forget(struct tw_cull_driver *d, struct tw_cell cell)
{
    if (d && d->cache)
        tw_tile_cache_remove(d->cache, cell);
}

void tw_cull_driver_forget_rect(struct tw_cull_driver *d, struct tw_cell lo, struct tw_cell hi)
{
    if (d && d->cache)
        tw_tile_cache_remove_rect(d->cache, lo, hi);
}

uint64_t tw_cull_driver_trim(struct tw_cull_driver *d, uint64_t excess, uint64_t frame,
                             uint32_t *count)
{
    uint64_t freed = 0;
    while (d->cache && freed < excess) {
        uint64_t bytes = 0;
        if (!tw_tile_cache_evict_oldest(d->cache, frame, &bytes))
            break;
        freed += bytes;
        if (count)
            (*count)++;
    }
    return freed;
}

/* ---- what a frame offers its method ------------------------------------------------------ */

bool tw_cull_frame_reserve(struct tw_cull_frame *fr, void **array, size_t *cap, size_t need,
                           size_t elem)
{
    if (tw_cull_reserve(array, cap, need, elem))
        return true;
    fr->err = TW_ERR_NOMEM;
    return false;
}

uint32_t *tw_cull_frame_clusters(struct tw_cull_frame *fr, struct tw_cull_clusters *c, size_t n)
{
    return tw_cull_frame_reserve(fr, (void **)&c->index, &c->cap, n, sizeof(*c->index))
               ? c->index
               : NULL;
}

bool tw_cull_frame_tile(struct tw_cull_frame *fr, struct tw_cell cell, uint32_t level,
                        float distance, struct tw_cull_tile *tile)
{
    const int err =
        fr->g->source.get(fr->g->source.ctx, cell, level, distance, fr->source_flags, tile);
    tile->level = level;
    if (err == TW_TILE_PENDING)
        fr->st->tiles_pending++;
    else if (err)
        fr->err = err;
    /* A refused tile is there and empty: nothing to draw. */
    return err == TW_OK && tile->proto != NULL;
}

float tw_cull_frame_cell_distance(const struct tw_cull_frame *fr, struct tw_cell cell,
                                  uint32_t level)
{
    float off[3];
    tw_tiles_cell_offset(cell, fr->v->cell, fr->g->footprint[0], fr->g->footprint[1], off);
    const struct tw_box box = tw_cull_node_box(fr->g, level);
    return tw_cull_box_distance(fr->v, &box, off);
}

bool tw_cull_frame_cell_in_view(const struct tw_cull_frame *fr, struct tw_cell cell,
                                uint32_t level, float off[3], float *distance)
{
    const struct tw_cull_grid *g = fr->g;
    tw_tiles_cell_offset(cell, fr->v->cell, g->footprint[0], g->footprint[1], off);
    const struct tw_box box = tw_cull_node_box(g, level);
    *distance = tw_cull_box_distance(fr->v, &box, off);
    return *distance <= fr->v->view_distance &&
           tw_cull_frustum_box(&fr->v->frustum, &box, off) != TW_CULL_OUTSIDE;
}

void *tw_cull_frame_instance(struct tw_cull_frame *fr, struct tw_cell cell,
                             const struct tw_cull_tile *tile, const float offset[3],
                             size_t state_bytes, struct tw_cull_instance *inst, bool *created)
{
    struct tw_tile_handle h;
    *created = false;
    const int err = tw_tile_cache_acquire(fr->cache, cell, tile->key, state_bytes, fr->v->frame,
                                          &h, created);
    if (err) {
        fr->err = err;
        return NULL;
    }
    *inst = (struct tw_cull_instance){
        .cell = cell, .level = tile->level, .content = tile->content, .proto = tile->proto, .bvh = tile->bvh,
        .state = tw_tile_cache_state(fr->cache, h), .tag = tw_tile_handle_pack(h),
    };
    memcpy(inst->offset, offset, sizeof(inst->offset));
    if (*created)
        fr->st->tiles_new++;
    return inst->state;
}

int tw_cull_frame_each_cell(struct tw_cull_method_base *m, struct tw_cull_frame *fr,
                            tw_cull_draw_fn draw)
{
    const int err = tw_cull_cells_of_frame(fr->cells, fr->v, fr->g);
    if (err)
        return err;
    const struct tw_cull_cells *cells = fr->cells;
    for (size_t k = 0; k < cells->count && !fr->err; k++) {
        const struct tw_cell cell = cells->cells[k].cell;
        struct tw_cull_tile tile;
        if (!tw_cull_frame_tile(fr, cell, cells->cells[k].level, cells->cells[k].distance,
                                &tile)) {
            if (fr->err)
                break;
            continue;
        }
        float offset[3];
        tw_tiles_cell_offset(cell, fr->v->cell, fr->g->footprint[0], fr->g->footprint[1], offset);
        fr->st->tiles_visible += draw(m, fr, cell, &tile, offset);
    }
    return fr->err;
}
