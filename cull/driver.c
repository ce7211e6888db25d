/*
 * The method drivers (cull.h): one frame over the grid, top-down.
 *
 *   driver -> cells in view (once per frame) -> tile source -> local method
 *   driver -> tile-query propagation -> local method per visible tile
 *
 * where the local method is frustum culling of the tile's clusters (vfc,
 * tilequery) or CHC++ over the tile's BVH (chc, tilequery+chc), and every
 * draw and query goes to the query backend. Tile instances (the per-view
 * CHC++ state of a cell) live in the driver's tile cache.
 */
#include "tileworld/cull.h"

#include <stdlib.h>
#include <string.h>

struct tw_cull_driver {
    struct tw_cull_driver_settings s;
    struct tw_tile_cache *cache;        /* tile instances; NULL for vfc and given sets */
    struct tw_chc *chc;                 /* chc, tilequery+chc */
    struct tw_tilequery *tq;            /* tilequery, tilequery+chc */
    uint32_t *scratch;                  /* cluster indices of one tile */
    uint32_t scratch_cap;
    const struct tw_drawn_cluster *given;
    size_t given_count;
};

/* What one frame's local methods need. */
struct frame {
    struct tw_cull_driver *d;
    const struct tw_view *v;
    const struct tw_cull_grid *g;
    const struct tw_query_backend *be;
    struct tw_cull_frame_stats *st;
    int err;
};

/* ---- a fixed tileset as a tile source -------------------------------------------------- */

static int fixed_get(void *ctx, struct tw_cell cell, float distance, unsigned flags,
                     struct tw_cull_tile *out)
{
    const struct tw_cull_fixed *f = ctx;
    const uint32_t p = tw_tiles_select(f->tileset, f->selection, cell);
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
        memcmp(c->view_proj, v->view_proj, sizeof(c->view_proj)) == 0)
        return TW_OK;
    for (;;) {
        const size_t n = tw_cull_cells_in_view(v, &g->common_box, g->footprint[0],
                                               g->footprint[1], c->cells, c->cap);
        if (n <= c->cap) {
            c->count = n;
            c->valid = true;
            c->cell = v->cell;
            c->view_distance = v->view_distance;
            memcpy(c->view_proj, v->view_proj, sizeof(c->view_proj));
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

int tw_cull_driver_create(const struct tw_cull_driver_settings *settings,
                          struct tw_cull_driver **out)
{
    if (!settings || !out || (unsigned)settings->method >= TW_CULL_METHOD_COUNT)
        return TW_ERR_INVALID;
    struct tw_cull_driver *d = calloc(1, sizeof(*d));
    if (!d)
        return TW_ERR_NOMEM;
    d->s = *settings;
    if (d->s.evict_after_frames == 0)
        d->s.evict_after_frames = 60;
    tw_chc_default_settings(&d->s.chc);
    tw_tilequery_default_settings(&d->s.tilequery);
    const enum tw_cull_method m = d->s.method;
    int err = TW_OK;
    if (m == TW_CULL_TILEQUERY || m == TW_CULL_CHC || m == TW_CULL_TILEQUERY_CHC)
        err = tw_tile_cache_create(d->s.evict_after_frames, &d->cache);
    if (!err && (m == TW_CULL_CHC || m == TW_CULL_TILEQUERY_CHC))
        err = tw_chc_create(&d->s.chc, &d->chc);
    if (!err && (m == TW_CULL_TILEQUERY || m == TW_CULL_TILEQUERY_CHC))
        err = tw_tilequery_create(&d->s.tilequery, &d->tq);
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
    tw_tilequery_destroy(d->tq);
    tw_chc_destroy(d->chc);
    tw_tile_cache_destroy(d->cache);
    free(d->scratch);
    free(d);
}

void tw_cull_driver_give(struct tw_cull_driver *d, const struct tw_drawn_cluster *set,
                         size_t count)
{
    d->given = set;
    d->given_count = count;
}

void tw_cull_driver_set_costs(struct tw_cull_driver *d, const struct tw_cost_model *costs)
{
    if (d && d->chc)
        tw_chc_set_costs(d->chc, costs);
}

enum tw_cull_method tw_cull_driver_method(const struct tw_cull_driver *d)
{
    return d->s.method;
}

const struct tw_tilequery *tw_cull_driver_tilequery(const struct tw_cull_driver *d)
{
    return d->tq;
}

size_t tw_cull_driver_bytes(const struct tw_cull_driver *d)
{
    return sizeof(*d) + (d->cache ? tw_tile_cache_bytes(d->cache) : 0) +
           (d->chc ? tw_chc_bytes(d->chc) : 0) + (d->tq ? tw_tilequery_bytes(d->tq) : 0) +
           sizeof(*d->scratch) * d->scratch_cap;
}

/* Room for n cluster indices. */
static uint32_t *scratch(struct frame *fr, uint32_t n)
{
    struct tw_cull_driver *d = fr->d;
    if (n > d->scratch_cap) {
        uint32_t *s = realloc(d->scratch, sizeof(*s) * n);
        if (!s) {
            fr->err = TW_ERR_NOMEM;
            return NULL;
        }
        d->scratch = s;
        d->scratch_cap = n;
    }
    return d->scratch;
}

/* The tile at cell, if ready; a tile not ready is counted as pending. */
static bool get_tile(struct frame *fr, struct tw_cell cell, float distance,
                     struct tw_cull_tile *tile)
{
    const int err = fr->g->source.get(fr->g->source.ctx, cell, distance, fr->d->s.source_flags,
                                      tile);
    if (err == TW_TILE_PENDING)
        fr->st->tiles_pending++;
    else if (err)
        fr->err = err;
    /* A refused tile is there and empty: nothing to draw. */
    return err == TW_OK && tile->proto != NULL;
}

/* The local method of vfc and tilequery: the tile's clusters in the frustum,
 * in one call. Returns whether anything was drawn. */
static bool draw_tile_vfc(struct frame *fr, struct tw_cell cell, const struct tw_cull_tile *tile,
                          const float offset[3])
{
    uint32_t *out = scratch(fr, tile->proto->cluster_count);
    if (!out)
        return false;
    const uint32_t n = tw_cull_vfc_tile(fr->v, tile->proto, offset, out);
    if (n > 0)
        fr->be->draw(fr->be->ctx, cell, tile->content, offset, out, n);
    return n > 0;
}

/* The instance of a cell found visible, made on first sight (and afresh for
 * content other than its own). */
static void *instance_state(struct frame *fr, struct tw_cell cell, const struct tw_cull_tile *tile,
                            size_t bytes, struct tw_tile_handle *h)
{
    bool created = false;
    const int err = tw_tile_cache_acquire(fr->d->cache, cell, tile->key, bytes,
                                          fr->v->frame, h, &created);
    if (err) {
        fr->err = err;
        return NULL;
    }
    void *state = tw_tile_cache_state(fr->d->cache, *h);
    if (created) {
        fr->st->tiles_new++;
        if (fr->d->chc)
            tw_chc_state_init(state, tile->bvh, fr->v->frame);
    }
    return state;
}

/* The local method of chc and tilequery+chc. Returns whether anything was drawn. */
static bool draw_tile_chc(struct frame *fr, struct tw_cell cell, const struct tw_cull_tile *tile,
                          const float offset[3])
{
    struct tw_tile_handle h;
    struct tw_chc_node_state *state =
        instance_state(fr, cell, tile, tw_chc_state_bytes(tile->bvh), &h);
    if (!state)
        return false;
    struct tw_chc_tile t = {
        .cell = cell,
        .content = tile->content,
        .proto = tile->proto,
        .bvh = tile->bvh,
        .state = state,
        .tag = tw_tile_handle_pack(h),
    };
    memcpy(t.offset, offset, sizeof(t.offset));
    const uint32_t before = tw_chc_stats(fr->d->chc)->clusters_drawn;
    tw_chc_traverse(fr->d->chc, fr->v, fr->be, &t);
    return tw_chc_stats(fr->d->chc)->clusters_drawn > before;
}

/* A deferred V-query names its tile instance by handle; the instance is
 * still that tile only if the cell still shows the content it was made for. */
static struct tw_chc_node_state *resolve_tag(void *user, uint64_t tag, const struct tw_bvh **bvh)
{
    struct frame *fr = user;
    const struct tw_tile_handle h = tw_tile_handle_unpack(tag);
    const struct tw_tile_info *info = tw_tile_cache_info(fr->d->cache, h);
    struct tw_cull_tile tile;
    if (!info ||
        fr->g->source.get(fr->g->source.ctx, info->cell, 0.0f, TW_TILE_SOURCE_RESIDENT, &tile) !=
            TW_OK ||
        tile.key != info->prototype)
        return NULL;
    *bvh = tile.bvh;
    return tw_tile_cache_state(fr->d->cache, h);
}

/* Tile queries are about to be issued on cell's neighbours: their tiles
 * are wanted soon (DESIGN §12: prefetch when a neighbour is queried). */
static void prefetch_neighbours(struct frame *fr, struct tw_cell cell)
{
    static const int8_t di[8] = {1, -1, 0, 0, 1, 1, -1, -1};
    static const int8_t dj[8] = {0, 0, 1, -1, 1, -1, 1, -1};
    const struct tw_cull_grid *g = fr->g;
    for (uint32_t k = 0; k < fr->d->s.tilequery.neighbours; k++) {
        const struct tw_cell c = {(int64_t)((uint64_t)cell.i + (uint64_t)(int64_t)di[k]),
                                  (int64_t)((uint64_t)cell.j + (uint64_t)(int64_t)dj[k])};
        float off[3];
        tw_tiles_cell_offset(c, fr->v->cell, g->footprint[0], g->footprint[1], off);
        const float dist = tw_cull_box_distance(fr->v, &g->common_box, off);
        if (dist <= fr->v->view_distance &&
            tw_cull_frustum_box(&fr->v->frustum, &g->common_box, off) != TW_CULL_OUTSIDE)
            g->source.prefetch(g->source.ctx, c, dist);
    }
}

/* Rendering a cell found visible by tile-query propagation. */
static void render_visible(void *user, struct tw_cell cell, const float offset[3])
{
    struct frame *fr = user;
    if (fr->err)
        return;
    if (fr->g->source.prefetch)
        prefetch_neighbours(fr, cell);
    struct tw_cull_tile tile;
    if (!get_tile(fr, cell, tw_cull_box_distance(fr->v, &fr->g->common_box, offset), &tile))
        return;
    if (fr->d->chc) {
        draw_tile_chc(fr, cell, &tile, offset);
    } else {
        /* tilequery keeps an instance per visible tile, as the system does. */
        struct tw_tile_handle h;
        instance_state(fr, cell, &tile, 0, &h);
        draw_tile_vfc(fr, cell, &tile, offset);
    }
}

static int frame_tilequery(struct frame *fr)
{
    struct tw_tilequery_stats tq;
    const struct tw_cull_grid *g = fr->g;
    int err = tw_tilequery_frame(fr->d->tq, fr->v, fr->be, &g->common_box, g->footprint[0],
                                 g->footprint[1], render_visible, fr, &tq);
    fr->st->tiles_queried = tq.tiles_queried;
    fr->st->predict_fail = tq.predict_fail;
    fr->st->tiles_visible = tq.tiles_visible;
    return err ? err : fr->err;
}

/* vfc and chc: every cell in view, front to back. */
static int frame_cells(struct frame *fr, struct tw_cull_cells *cells)
{
    int err = tw_cull_cells_of_frame(cells, fr->v, fr->g);
    if (err)
        return err;
    for (size_t k = 0; k < cells->count && !fr->err; k++) {
        const struct tw_cell cell = cells->cells[k].cell;
        struct tw_cull_tile tile;
        if (!get_tile(fr, cell, cells->cells[k].distance, &tile)) {
            if (fr->err)
                break;
            continue;
        }
        float offset[3];
        tw_tiles_cell_offset(cell, fr->v->cell, fr->g->footprint[0], fr->g->footprint[1], offset);
        const bool drawn = fr->d->chc ? draw_tile_chc(fr, cell, &tile, offset)
                                      : draw_tile_vfc(fr, cell, &tile, offset);
        fr->st->tiles_visible += drawn;
    }
    return fr->err;
}

/* A given set, one draw call per run of clusters of one tile. */
static int frame_given(struct frame *fr)
{
    const struct tw_drawn_cluster *set = fr->d->given;
    const size_t count = fr->d->given_count;
    size_t k = 0;
    while (k < count) {
        const struct tw_cell cell = set[k].cell;
        const uint32_t content = set[k].prototype;
        size_t end = k;
        while (end < count && set[end].cell.i == cell.i && set[end].cell.j == cell.j &&
               set[end].prototype == content)
            end++;
        uint32_t *out = scratch(fr, (uint32_t)(end - k));
        if (!out)
            return fr->err;
        for (size_t c = k; c < end; c++)
            out[c - k] = set[c].cluster;
        float offset[3];
        tw_tiles_cell_offset(cell, fr->v->cell, fr->g->footprint[0], fr->g->footprint[1], offset);
        fr->be->draw(fr->be->ctx, cell, content, offset, out, (uint32_t)(end - k));
        fr->st->tiles_visible++;
        k = end;
    }
    return TW_OK;
}

int tw_cull_driver_frame(struct tw_cull_driver *d, const struct tw_view *v,
                         const struct tw_cull_grid *g, const struct tw_query_backend *be,
                         struct tw_cull_cells *cells, struct tw_cull_frame_stats *stats)
{
    if (!d || !v || !g || !be || !cells)
        return TW_ERR_INVALID;
    struct tw_cull_frame_stats st = {0};
    struct frame fr = {d, v, g, be, &st, TW_OK};
    if (d->chc)
        tw_chc_begin_frame(d->chc, v, be, resolve_tag, &fr);
    int err;
    switch (d->s.method) {
    case TW_CULL_VFC:
    case TW_CULL_CHC:
        err = frame_cells(&fr, cells);
        break;
    case TW_CULL_TILEQUERY:
    case TW_CULL_TILEQUERY_CHC:
        err = frame_tilequery(&fr);
        break;
    case TW_CULL_GIVEN:
        err = frame_given(&fr);
        break;
    default:
        err = TW_ERR_INVALID;
        break;
    }
    if (d->chc)
        st.queries_skipped = tw_chc_stats(d->chc)->queries_skipped;
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

void tw_cull_driver_forget_rect(struct tw_cull_driver *d, struct tw_cell lo, struct tw_cell hi)
{
    if (d && d->cache)
        tw_tile_cache_remove_rect(d->cache, lo, hi);
}
