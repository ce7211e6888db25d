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
 *
 * The HZB methods (hzb, tilequery+hzb) run in two phases:
 *
 *   phase 1  the tiles found visible last frame, front to back: their
 *            clusters found visible last frame, in the frustum
 *   pyramid  depth read back, depth pyramid built (cull/hzb.c)
 *   phase 2  hzb: every cell in view, front to back; tilequery+hzb: the
 *            cells reached by propagation from the camera's, nearest first.
 *            A cell's common box is tested against the pyramid; a visible
 *            cell's BVH is traversed testing node boxes, drawing what
 *            phase 1 did not
 */
#include "cull/cull-private.h"
#include "tiles/clock.h"
#include "tiles/tiles-internal.h"
#include "tiles/neighbours.h"

#include <stdlib.h>
#include <string.h>

struct tw_cull_driver {
    struct tw_cull_driver_settings s;
    struct tw_tile_cache *cache;        /* tile instances; NULL for vfc and given sets */
    struct tw_chc *chc;                 /* chc, tilequery+chc */
    struct tw_tilequery *tq;            /* tilequery, tilequery+chc */
    uint32_t *scratch;                  /* cluster indices of one tile */
    size_t scratch_cap;
    const struct tw_drawn_cluster *given;
    size_t given_count;
    /* hzb, tilequery+hzb */
    struct tw_hzb *hzb;                 /* the pyramid, the per-tile traversals */
    struct tw_cull_cell *hz_last, *hz_next;  /* cells with a visible node: last frame's
                                           (phase 1 draws them), this frame's */
    size_t hz_last_count, hz_last_cap, hz_next_count, hz_next_cap;
    struct tw_cell_map *hz_verdict;     /* cell -> frame << 4 | HZ_* flags of that frame */
    uint64_t hz_last_prune;
    struct tw_cull_cell *hz_found;      /* tilequery+hzb: cells found visible this frame */
    size_t hz_found_count, hz_found_cap;
    struct tw_distance_entry *hz_heap;  /* of them, those to visit, nearest first */
    size_t hz_heap_count, hz_heap_cap;
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
    const bool hzb = m == TW_CULL_HZB || m == TW_CULL_TILEQUERY_HZB;
    int err = TW_OK;
    if (m == TW_CULL_TILEQUERY || m == TW_CULL_CHC || m == TW_CULL_TILEQUERY_CHC || hzb)
        err = tw_tile_cache_create(d->s.evict_after_frames, &d->cache);
    if (!err && (m == TW_CULL_CHC || m == TW_CULL_TILEQUERY_CHC))
        err = tw_chc_create(&d->s.chc, &d->chc);
    if (!err && (m == TW_CULL_TILEQUERY || m == TW_CULL_TILEQUERY_CHC))
        err = tw_tilequery_create(&d->s.tilequery, &d->tq);
    if (!err && hzb)
        err = tw_hzb_create(&d->hzb);
    if (!err && hzb)
        err = tw_cell_map_create(&d->hz_verdict);
    if (!err && hzb)
        tw_hzb_set_mutation(d->hzb, d->s.hzb_mutate_shrink);
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
    tw_hzb_destroy(d->hzb);
    tw_cell_map_destroy(d->hz_verdict);
    free(d->hz_last);
    free(d->hz_next);
    free(d->hz_found);
    free(d->hz_heap);
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
           sizeof(*d->scratch) * d->scratch_cap + tw_hzb_bytes(d->hzb) +
           (d->hz_verdict ? tw_cell_map_bytes(d->hz_verdict) : 0) +
           sizeof(*d->hz_last) * (d->hz_last_cap + d->hz_next_cap) +
           sizeof(*d->hz_found) * d->hz_found_cap + sizeof(*d->hz_heap) * d->hz_heap_cap;
}

static bool grow(struct frame *fr, void **array, size_t *cap, size_t need, size_t elem);

/* Room for n cluster indices. */
static uint32_t *scratch(struct frame *fr, uint32_t n)
{
    struct tw_cull_driver *d = fr->d;
    return grow(fr, (void **)&d->scratch, &d->scratch_cap, n, sizeof(*d->scratch)) ? d->scratch
                                                                                  : NULL;
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
        /* HZB state starts zeroed: never visible, never drawn. */
    }
    return state;
}

/* The local method of chc and tilequery+chc. Returns whether anything was
 * drawn; with async, the pass may be suspended where it would block
 * (tw_chc_traverse_async), and what it draws later is not counted. */
static bool draw_tile_chc(struct frame *fr, struct tw_cell cell, const struct tw_cull_tile *tile,
                          const float offset[3], bool async)
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
    if (async)
        tw_chc_traverse_async(fr->d->chc, fr->v, fr->be, &t);
    else
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
    const struct tw_cull_grid *g = fr->g;
    for (uint32_t k = 0; k < fr->d->s.tilequery.neighbours; k++) {
        const struct tw_cell c = tw_cell_neighbour(cell, k);
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
        /* The tile query already found the cell visible: while a tile's
         * pass waits, the next tiles' work goes to the GPU. */
        draw_tile_chc(fr, cell, &tile, offset, true);
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
    tw_chc_finish(fr->d->chc);
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
        const bool drawn = fr->d->chc ? draw_tile_chc(fr, cell, &tile, offset, false)
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

/* ---- hzb and tilequery+hzb ---------------------------------------------------------- */

/* What a frame learnt of a cell, kept in hz_verdict as frame << 4 | flags. */
#define HZ_VISIBLE 1u       /* its common box passed the pyramid (or needed no test) */
#define HZ_PHASE1 2u        /* phase 1 took it for visible: it had a visible node last frame */
#define HZ_DREW1 4u         /* phase 1 drew some of its clusters */
#define HZ_TESTED 8u        /* phase 2 decided on it */
#define HZ_SHIFT 4

static int compare_cells(const void *a, const void *b)
{
    return tw_cull_cell_order(a, b);
}

/* Room for need elements of size elem in *array; out of memory ends the frame. */
static bool grow(struct frame *fr, void **array, size_t *cap, size_t need, size_t elem)
{
    if (tw_cull_reserve(array, cap, need, elem))
        return true;
    fr->err = TW_ERR_NOMEM;
    return false;
}

/* The cell's common box meets the frustum within the view distance. */
static bool hz_in_view(const struct frame *fr, struct tw_cell cell, float off[3], float *distance)
{
    const struct tw_cull_grid *g = fr->g;
    tw_tiles_cell_offset(cell, fr->v->cell, g->footprint[0], g->footprint[1], off);
    *distance = tw_cull_box_distance(fr->v, &g->common_box, off);
    return *distance <= fr->v->view_distance &&
           tw_cull_frustum_box(&fr->v->frustum, &g->common_box, off) != TW_CULL_OUTSIDE;
}

static uint64_t hz_verdict(const struct frame *fr, struct tw_cell cell)
{
    const uint64_t *p = tw_cell_map_find(fr->d->hz_verdict, cell);
    return p ? *p : 0;
}

static void hz_set_verdict(struct frame *fr, struct tw_cell cell, uint64_t flags)
{
    if (tw_cell_map_set(fr->d->hz_verdict, cell, fr->v->frame << HZ_SHIFT | flags))
        fr->err = TW_ERR_NOMEM;
}

static bool hz_prune_old(void *user, struct tw_cell cell, uint64_t value)
{
    (void)cell;
    return (value >> HZ_SHIFT) + 1 < *(const uint64_t *)user;
}

/* The HZB state of the cell's tile, made on first sight; *t is set up for
 * the traversals. NULL when the tile is not there (pending, refused). */
static struct tw_hzb_node_state *hz_tile(struct frame *fr, struct tw_cell cell, float distance,
                                         const float off[3], struct tw_hzb_tile *t)
{
    struct tw_cull_tile tile;
    if (!get_tile(fr, cell, distance, &tile))
        return NULL;
    struct tw_tile_handle h;
    struct tw_hzb_node_state *state =
        instance_state(fr, cell, &tile, tw_hzb_state_bytes(tile.bvh), &h);
    if (!state)
        return NULL;
    *t = (struct tw_hzb_tile){
        .cell = cell, .content = tile.content, .proto = tile.proto, .bvh = tile.bvh,
        .state = state,
    };
    memcpy(t->offset, off, sizeof(t->offset));
    return state;
}

/* Phase 1: last frame's visible tiles still in view, front to back, each
 * drawing its clusters visible last frame. Returns how many clusters were
 * drawn. */
static uint32_t hz_phase1(struct frame *fr)
{
    struct tw_cull_driver *d = fr->d;
    size_t n = 0;
    for (size_t k = 0; k < d->hz_last_count; k++) {
        float off[3], dist;
        if (hz_in_view(fr, d->hz_last[k].cell, off, &dist))
            d->hz_last[n++] = (struct tw_cull_cell){d->hz_last[k].cell, dist};
    }
    if (n > 1) /* qsort() wants a valid pointer even for no elements */
        qsort(d->hz_last, n, sizeof(*d->hz_last), compare_cells);
    uint32_t drawn = 0;
    for (size_t k = 0; k < n && !fr->err; k++) {
        const struct tw_cell cell = d->hz_last[k].cell;
        float off[3];
        tw_tiles_cell_offset(cell, fr->v->cell, fr->g->footprint[0], fr->g->footprint[1], off);
        struct tw_hzb_tile t;
        uint32_t c = 0;
        if (hz_tile(fr, cell, d->hz_last[k].distance, off, &t))
            c = tw_hzb_draw_last_visible(d->hzb, fr->v, fr->be, &t);
        if (c > 0)
            fr->st->tiles_visible++;
        drawn += c;
        hz_set_verdict(fr, cell, HZ_PHASE1 | (c > 0 ? HZ_DREW1 : 0));
    }
    return drawn;
}

/* The depth of phase 1 as a pyramid; none (every box visible) when phase 1
 * drew nothing or there is no depth to read. */
static void hz_pyramid(struct frame *fr, bool drawn)
{
    struct tw_hzb *h = fr->d->hzb;
    const struct tw_query_backend *be = fr->be;
    uint32_t w = 0, hh = 0;
    bool reversed = false;
    tw_hzb_clear(h);
    if (!drawn || !be->read_depth || !be->read_depth(be->ctx, NULL, &w, &hh, &reversed))
        return;
    float *depth = tw_hzb_depth_buffer(h, w, hh);
    if (!depth)
        return;     /* out of memory: no pyramid, nothing culled */
    const double t0 = tw_clock_monotonic_ms();
    if (!be->read_depth(be->ctx, depth, &w, &hh, &reversed))
        return;
    const double t1 = tw_clock_monotonic_ms();
    tw_hzb_build(h, reversed);
    fr->st->ms_hzb_read += t1 - t0;
    fr->st->ms_hzb_build += tw_clock_monotonic_ms() - t1;
}

/* Phase 2's verdict on a cell in view: free (visible without a test: the
 * start of propagation, the near-plane rule) or its common box tested
 * against the pyramid. Counts a failed prediction and records the verdict;
 * *prev receives what phase 1 recorded. */
static bool hz_decide(struct frame *fr, struct tw_cell cell, const float off[3], bool free_pass,
                      uint64_t *prev)
{
    const uint64_t f = fr->v->frame;
    const uint64_t old = hz_verdict(fr, cell);
    bool visible = true;
    if (!free_pass) {
        fr->st->tiles_queried++;
        fr->st->hzb_boxes++;
        visible = tw_hzb_visible(fr->d->hzb, fr->v, &fr->g->common_box, off);
    }
    /* A prediction: phase 1 drew the cell (predicted visible), or last
     * frame's phase 2 decided on it. */
    const bool this_frame = old >> HZ_SHIFT == f;
    const bool known = this_frame || (old >> HZ_SHIFT == f - 1 && (old & HZ_TESTED));
    const bool predicted = this_frame ? (old & HZ_PHASE1) != 0 : (old & HZ_VISIBLE) != 0;
    if (known && predicted != visible)
        fr->st->predict_fail++;
    *prev = this_frame ? old : 0;
    hz_set_verdict(fr, cell, (*prev & (HZ_PHASE1 | HZ_DREW1)) | HZ_TESTED |
                                 (visible ? HZ_VISIBLE : 0));
    return visible;
}

/* Phase 2 in a visible cell: its BVH against the pyramid; the cell is kept
 * for the next frame's phase 1 if a node of it was found visible. */
static void hz_visit(struct frame *fr, struct tw_cell cell, float distance, const float off[3],
                     uint64_t prev)
{
    struct tw_cull_driver *d = fr->d;
    struct tw_hzb_tile t;
    if (!hz_tile(fr, cell, distance, off, &t))
        return;
    const uint32_t tested = tw_hzb_stats(d->hzb)->boxes_tested;
    const uint32_t c = tw_hzb_traverse(d->hzb, fr->v, fr->be, &t);
    fr->st->hzb_boxes += tw_hzb_stats(d->hzb)->boxes_tested - tested;
    if (c > 0 && !(prev & HZ_DREW1))
        fr->st->tiles_visible++;
    if (t.state[0].visible_frame == fr->v->frame &&
        grow(fr, (void **)&d->hz_next, &d->hz_next_cap, d->hz_next_count + 1,
             sizeof(*d->hz_next)))
        d->hz_next[d->hz_next_count++] = (struct tw_cull_cell){cell, distance};
}

/* hzb's phase 2: every cell in view, front to back. */
static void hz_cells(struct frame *fr, struct tw_cull_cells *cells)
{
    int err = tw_cull_cells_of_frame(cells, fr->v, fr->g);
    if (err) {
        fr->err = err;
        return;
    }
    for (size_t k = 0; k < cells->count && !fr->err; k++) {
        const struct tw_cell cell = cells->cells[k].cell;
        float off[3];
        tw_tiles_cell_offset(cell, fr->v->cell, fr->g->footprint[0], fr->g->footprint[1], off);
        uint64_t prev;
        if (hz_decide(fr, cell, off, tw_cull_near_box(fr->v, &fr->g->common_box, off), &prev))
            hz_visit(fr, cell, cells->cells[k].distance, off, prev);
    }
}

/* Reached by this frame's propagation already. */
static bool hz_reached(const struct frame *fr, struct tw_cell cell)
{
    const uint64_t v = hz_verdict(fr, cell);
    return v >> HZ_SHIFT == fr->v->frame && (v & HZ_TESTED);
}

/* A cell found visible by propagation, queued for its visit. */
static void hz_queue(struct frame *fr, struct tw_cell cell, float distance)
{
    struct tw_cull_driver *d = fr->d;
    const size_t n = d->hz_found_count;
    if (!grow(fr, (void **)&d->hz_found, &d->hz_found_cap, n + 1, sizeof(*d->hz_found)) ||
        !grow(fr, (void **)&d->hz_heap, &d->hz_heap_cap, n + 1, sizeof(*d->hz_heap)))
        return;
    d->hz_found[d->hz_found_count++] = (struct tw_cull_cell){cell, distance};
    tw_distance_push(d->hz_heap, &d->hz_heap_count, distance, (uint32_t)n);
}

/* tilequery+hzb's phase 2: §4 with immediate answers. From the camera's
 * cell (or the nearest cell in view), visible cells are visited nearest
 * first; each visit traverses the cell's tile, then decides on its
 * neighbours in view not reached yet, and the visible ones join the queue.
 * A hidden cell stops propagation there. No pending or postponed queue:
 * the pyramid answers at once. */
static void hz_propagate(struct frame *fr, struct tw_cull_cells *cells)
{
    struct tw_cull_driver *d = fr->d;
    const struct tw_cull_grid *g = fr->g;
    struct tw_cull_cell start;
    float off[3];
    if (hz_in_view(fr, fr->v->cell, off, &start.distance)) {
        start.cell = fr->v->cell;
    } else {
        const int err = tw_cull_cells_of_frame(cells, fr->v, g);
        if (err) {
            fr->err = err;
            return;
        }
        if (cells->count == 0)
            return;
        start = cells->cells[0];
    }
    d->hz_found_count = d->hz_heap_count = 0;
    uint64_t prev;
    tw_tiles_cell_offset(start.cell, fr->v->cell, g->footprint[0], g->footprint[1], off);
    hz_decide(fr, start.cell, off, true, &prev);
    hz_queue(fr, start.cell, start.distance);
    while (d->hz_heap_count > 0 && !fr->err) {
        const struct tw_cull_cell c = d->hz_found[tw_distance_pop(d->hz_heap, &d->hz_heap_count)];
        tw_tiles_cell_offset(c.cell, fr->v->cell, g->footprint[0], g->footprint[1], off);
        if (g->source.prefetch)
            prefetch_neighbours(fr, c.cell);
        hz_visit(fr, c.cell, c.distance, off, hz_verdict(fr, c.cell));
        for (uint32_t k = 0; k < d->s.tilequery.neighbours && !fr->err; k++) {
            const struct tw_cell nc = tw_cell_neighbour(c.cell, k);
            float noff[3], dist;
            if (hz_reached(fr, nc) || !hz_in_view(fr, nc, noff, &dist))
                continue;
            /* Decided once per frame (hz_reached), so queued at most once. */
            const bool free_pass = tw_cull_near_box(fr->v, &g->common_box, noff);
            if (hz_decide(fr, nc, noff, free_pass, &prev))
                hz_queue(fr, nc, dist);
        }
    }
}

/* The visible set for the next frame, decided again against the frame's
 * final depth: the tiles kept are those with a node still visible. */
static void hz_retest(struct frame *fr)
{
    struct tw_cull_driver *d = fr->d;
    const struct tw_cull_grid *g = fr->g;
    const uint32_t tested = tw_hzb_stats(d->hzb)->boxes_tested;
    size_t n = 0;
    for (size_t k = 0; k < d->hz_next_count; k++) {
        const struct tw_cell cell = d->hz_next[k].cell;
        struct tw_cull_tile tile;
        struct tw_tile_handle h;
        const struct tw_tile_info *info;
        /* The tile was at hand a moment ago: never wait, never request. */
        if (g->source.get(g->source.ctx, cell, 0.0f,
                          d->s.source_flags | TW_TILE_SOURCE_RESIDENT | TW_TILE_SOURCE_QUIET,
                          &tile) != TW_OK ||
            !tile.proto || !tw_tile_cache_find(d->cache, cell, &h) ||
            !(info = tw_tile_cache_info(d->cache, h)) || info->prototype != tile.key) {
            d->hz_next[n++] = d->hz_next[k];    /* kept: the next phase 1 sorts it out */
            continue;
        }
        struct tw_hzb_tile t = {
            .cell = cell, .content = tile.content, .proto = tile.proto, .bvh = tile.bvh,
            .state = tw_tile_cache_state(d->cache, h),
        };
        tw_tiles_cell_offset(cell, fr->v->cell, g->footprint[0], g->footprint[1], t.offset);
        if (tw_hzb_retest(d->hzb, fr->v, &t))
            d->hz_next[n++] = d->hz_next[k];
    }
    d->hz_next_count = n;
    fr->st->hzb_boxes += tw_hzb_stats(d->hzb)->boxes_tested - tested;
}

static int frame_hzb(struct frame *fr, struct tw_cull_cells *cells)
{
    struct tw_cull_driver *d = fr->d;
    const uint64_t f = fr->v->frame;
    if (f >= d->hz_last_prune + 16) {
        tw_cell_map_filter(d->hz_verdict, hz_prune_old, (void *)&f);
        d->hz_last_prune = f;
    }
    tw_hzb_begin_frame(d->hzb);
    d->hz_next_count = 0;
    const uint32_t phase1 = hz_phase1(fr);
    if (!fr->err)
        hz_pyramid(fr, phase1 > 0);
    if (!fr->err) {
        if (d->s.method == TW_CULL_HZB)
            hz_cells(fr, cells);
        else
            hz_propagate(fr, cells);
    }
    /* Phase 2 drew more than phase 1 (the first frame, a jump, a fast turn):
     * what it drew was tested against too little depth, and would all be
     * drawn blind by the next phase 1. Worth a second readback. */
    const uint32_t phase2 = tw_hzb_stats(d->hzb)->clusters_drawn - phase1;
    if (!fr->err && phase2 > phase1) {
        hz_pyramid(fr, true);
        if (tw_hzb_built(d->hzb))
            hz_retest(fr);
    }
    /* This frame's visible cells are the next one's phase 1. */
    struct tw_cull_cell *t = d->hz_last;
    const size_t cap = d->hz_last_cap;
    d->hz_last = d->hz_next;
    d->hz_last_cap = d->hz_next_cap;
    d->hz_last_count = d->hz_next_count;
    d->hz_next = t;
    d->hz_next_cap = cap;
    d->hz_next_count = 0;
    return fr->err;
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
    case TW_CULL_HZB:
    case TW_CULL_TILEQUERY_HZB:
        err = frame_hzb(&fr, cells);
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
