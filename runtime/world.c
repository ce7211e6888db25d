/* The world: a tileset on the infinite grid, drawn with a method (runtime.h). */
#include "runtime/renderer.h"
#include "tileworld/runtime.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

static const char *const method_names[TW_METHOD_COUNT] = {
    [TW_METHOD_VFC] = "vfc",
    [TW_METHOD_TILEQUERY] = "tilequery",
    [TW_METHOD_CHC] = "chc",
    [TW_METHOD_TILEQUERY_CHC] = "tilequery+chc",
    [TW_METHOD_ORACLE] = "oracle",
};

const char *tw_method_name(enum tw_method m)
{
    return (unsigned)m < TW_METHOD_COUNT ? method_names[m] : "unknown";
}

int tw_method_from_name(const char *name, enum tw_method *out)
{
    for (int m = 0; m < TW_METHOD_COUNT; m++)
        if (name && strcmp(name, method_names[m]) == 0) {
            *out = (enum tw_method)m;
            return TW_OK;
        }
    return TW_ERR_INVALID;
}

bool tw_method_available(enum tw_method m)
{
    return (unsigned)m < TW_METHOD_COUNT;
}

bool tw_method_conservative(enum tw_method m)
{
    return (unsigned)m < TW_METHOD_COUNT;
}

/* Temporal state of one method; methods alternate in a bench run, so each
 * keeps its own cache, CHC++ engine and propagation state. */
struct method_state {
    bool ready;
    uint64_t frame;
    struct tw_tile_cache *cache;
    struct tw_chc *chc;
    struct tw_tilequery *tq;
};

/* What the per-tile callbacks need during one frame. */
struct frame_ctx {
    struct tw_world *w;
    struct method_state *ms;
    const struct tw_view *v;
    const struct tw_query_backend *be;
    struct tw_frame_stats *st;
    uint32_t tiles_drawn;
    int err;
};

/* The accuracy oracle (DESIGN §8): every cluster vfc would draw, rendered
 * into an object-ID buffer; id k names entries[k]. */
struct oracle {
    struct tw_drawn_cluster *entries;
    size_t count, cap;
    uint32_t *pixels;              /* visible pixels per id */
    uint8_t *drawn;                /* per id: drawn by the method */
    size_t per_id_cap;
    uint32_t *ids;                 /* the ID buffer, width * height */
    struct tw_cell_map *tiles;     /* cell -> first id << 32 | cluster count */
};

struct tw_world {
    struct tw_world_settings s;
    struct oracle oracle;
    bool record_draws;
    struct tw_renderer *renderer;
    struct tw_bvh **bvhs;
    struct tw_cull_cell *cells;
    size_t cell_cap;
    uint32_t *cluster_scratch;
    enum tw_method method;
    struct method_state methods[TW_METHOD_COUNT];

    /* Debug views (tw_world_set_debug); untouched while debug is 0. */
    unsigned debug;
    struct tw_view last_view;
    bool has_view;
    struct tw_debug_box *debug_boxes;
    size_t debug_count, debug_cap;
    struct tw_cell_map *debug_seen;     /* cells reported this frame */
    uint32_t **debug_leaf_of;           /* per prototype: cluster -> its BVH leaf */
    uint32_t *debug_stamp;              /* per node: the tile that last marked it */
    uint32_t debug_stamp_now;
    struct tw_renderer_debug_box *debug_draw;
    size_t debug_draw_cap;
};

void tw_world_default_settings(struct tw_world_settings *s)
{
    if (s->width == 0)
        s->width = 640;
    if (s->height == 0)
        s->height = 360;
    if (!(s->fov_y > 0.0f))
        s->fov_y = 60.0f;
    if (!(s->near_plane > 0.0f))
        s->near_plane = 0.2f;
    if (!(s->view_distance > 0.0f))
        s->view_distance = 600.0f;
    if (s->evict_after_frames == 0)
        s->evict_after_frames = 60;
    tw_chc_default_settings(&s->chc);
    tw_tilequery_default_settings(&s->tilequery);
    tw_bvh_default_settings(&s->bvh);
}

int tw_world_create(const struct tw_world_settings *settings, struct tw_world **out)
{
    if (!settings || !out)
        return TW_ERR_INVALID;
    const struct tw_log *log = &settings->log;
    if (!settings->tileset || !settings->tileset->finished) {
        tw_log_printf(log, TW_LOG_ERROR, "tw_world_create: the tileset is missing or unfinished");
        return TW_ERR_INVALID;
    }
    if (settings->width > 16384 || settings->height > 16384 || !isfinite(settings->fov_y) ||
        settings->fov_y >= 179.0f || !isfinite(settings->view_distance) ||
        !isfinite(settings->near_plane) || (unsigned)settings->method >= TW_METHOD_COUNT) {
        tw_log_printf(log, TW_LOG_ERROR, "tw_world_create: settings out of range");
        return TW_ERR_INVALID;
    }
    struct tw_world *w = calloc(1, sizeof(*w));
    if (!w)
        return TW_ERR_NOMEM;
    w->s = *settings;
    tw_world_default_settings(&w->s);
    const struct tw_tileset *ts = w->s.tileset;
    int err = tw_renderer_create(ts, w->s.width, w->s.height, w->s.get_proc, &w->s.log,
                                 &w->renderer);
    if (err)
        goto fail;

    w->bvhs = calloc(ts->prototype_count, sizeof(*w->bvhs));
    uint32_t max_clusters = 1;
    for (uint32_t p = 0; p < ts->prototype_count; p++)
        if (ts->prototypes[p].cluster_count > max_clusters)
            max_clusters = ts->prototypes[p].cluster_count;
    w->cluster_scratch = malloc(sizeof(uint32_t) * max_clusters);
    if (!w->bvhs || !w->cluster_scratch) {
        err = TW_ERR_NOMEM;
        goto fail;
    }
    struct tw_bvh_builder *builder = NULL;
    err = tw_bvh_builder_create(&w->s.log, &builder);
    if (err)
        goto fail;
    for (uint32_t p = 0; p < ts->prototype_count && !err; p++)
        err = tw_bvh_build(builder, &ts->prototypes[p], &w->s.bvh, &w->bvhs[p]);
    tw_bvh_builder_destroy(builder);
    if (err)
        goto fail;
    w->oracle.ids = malloc(sizeof(uint32_t) * w->s.width * w->s.height);
    err = w->oracle.ids ? tw_cell_map_create(&w->oracle.tiles) : TW_ERR_NOMEM;
    if (err)
        goto fail;
    err = tw_world_set_method(w, w->s.method);
    if (err)
        goto fail;
    *out = w;
    return TW_OK;
fail:
    tw_world_destroy(w);
    return err;
}

void tw_world_destroy(struct tw_world *w)
{
    if (!w)
        return;
    for (int m = 0; m < TW_METHOD_COUNT; m++) {
        tw_tile_cache_destroy(w->methods[m].cache);
        tw_chc_destroy(w->methods[m].chc);
        tw_tilequery_destroy(w->methods[m].tq);
    }
    if (w->bvhs)
        for (uint32_t p = 0; p < w->s.tileset->prototype_count; p++)
            tw_bvh_destroy(w->bvhs[p]);
    free(w->bvhs);
    free(w->oracle.entries);
    free(w->oracle.pixels);
    free(w->oracle.drawn);
    free(w->oracle.ids);
    tw_cell_map_destroy(w->oracle.tiles);
    if (w->debug_leaf_of)
        for (uint32_t p = 0; p < w->s.tileset->prototype_count; p++)
            free(w->debug_leaf_of[p]);
    free(w->debug_leaf_of);
    free(w->debug_stamp);
    free(w->debug_boxes);
    free(w->debug_draw);
    tw_cell_map_destroy(w->debug_seen);
    free(w->cells);
    free(w->cluster_scratch);
    tw_renderer_destroy(w->renderer);
    free(w);
}

int tw_world_set_method(struct tw_world *w, enum tw_method m)
{
    if (!w || (unsigned)m >= TW_METHOD_COUNT)
        return TW_ERR_INVALID;
    if (!tw_method_available(m)) {
        tw_log_printf(&w->s.log, TW_LOG_ERROR, "method '%s' is not implemented yet",
                      tw_method_name(m));
        return TW_ERR_INVALID;
    }
    struct method_state *ms = &w->methods[m];
    if (!ms->ready) {
        /* vfc keeps no tile instances: it has no per-tile state. */
        int err = m == TW_METHOD_VFC ? TW_OK : tw_tile_cache_create(w->s.evict_after_frames, &ms->cache);
        if (!err && (m == TW_METHOD_CHC || m == TW_METHOD_TILEQUERY_CHC))
            err = tw_chc_create(&w->s.chc, &ms->chc);
        if (!err && (m == TW_METHOD_TILEQUERY || m == TW_METHOD_TILEQUERY_CHC))
            err = tw_tilequery_create(&w->s.tilequery, &ms->tq);
        if (err)
            return err;
        ms->ready = true;
    }
    w->method = m;
    w->s.method = m;
    return TW_OK;
}

const struct tw_world_settings *tw_world_settings(const struct tw_world *w)
{
    return &w->s;
}

const struct tw_bvh *tw_world_bvh(const struct tw_world *w, uint32_t p)
{
    return p < w->s.tileset->prototype_count ? w->bvhs[p] : NULL;
}

/* Every cell in the frustum within view distance, front to back. */
static int gather_cells(struct tw_world *w, const struct tw_view *v, size_t *count)
{
    const struct tw_tileset *ts = w->s.tileset;
    for (;;) {
        size_t n = tw_cull_cells_in_view(v, &ts->common_box, ts->footprint[0], ts->footprint[1],
                                         w->cells, w->cell_cap);
        if (n <= w->cell_cap) {
            *count = n;
            return TW_OK;
        }
        struct tw_cull_cell *c = realloc(w->cells, sizeof(*c) * n);
        if (!c)
            return TW_ERR_NOMEM;
        w->cells = c;
        w->cell_cap = n;
    }
}

static int frame_vfc(struct frame_ctx *fc)
{
    struct tw_world *w = fc->w;
    const struct tw_tileset *ts = w->s.tileset;
    size_t n = 0;
    int err = gather_cells(w, fc->v, &n);
    if (err)
        return err;
    for (size_t k = 0; k < n; k++) {
        const struct tw_cell cell = w->cells[k].cell;
        const uint32_t p = tw_tiles_select(ts, &w->s.selection, cell);
        float offset[3];
        tw_tiles_cell_offset(cell, fc->v->cell, ts->footprint[0], ts->footprint[1], offset);
        const uint32_t count = tw_cull_vfc_tile(fc->v, &ts->prototypes[p], offset, w->cluster_scratch);
        if (count > 0) {
            fc->be->draw(fc->be->ctx, cell, p, offset, w->cluster_scratch, count);
            fc->tiles_drawn++;
        }
    }
    return TW_OK;
}

/* The tile instance of a cell found visible: created on first sight. */
static void *instance_state(struct frame_ctx *fc, struct tw_cell cell, uint32_t p, size_t bytes,
                            struct tw_tile_handle *h)
{
    bool created = false;
    if (tw_tile_cache_acquire(fc->ms->cache, cell, p, bytes, fc->v->frame, h, &created)) {
        fc->err = TW_ERR_NOMEM;
        return NULL;
    }
    void *state = tw_tile_cache_state(fc->ms->cache, *h);
    if (created) {
        fc->st->tiles_new++;
        if (fc->ms->chc)
            tw_chc_state_init(state, fc->w->bvhs[p], fc->v->frame);
    }
    return state;
}

/* Local method of tilequery: the visible tile drawn whole, frustum-culled. */
static void render_tile_vfc(void *user, struct tw_cell cell, const float offset[3])
{
    struct frame_ctx *fc = user;
    struct tw_world *w = fc->w;
    const uint32_t p = tw_tiles_select(w->s.tileset, &w->s.selection, cell);
    struct tw_tile_handle h;
    instance_state(fc, cell, p, 0, &h);
    const uint32_t count = tw_cull_vfc_tile(fc->v, &w->s.tileset->prototypes[p], offset,
                                            w->cluster_scratch);
    if (count > 0)
        fc->be->draw(fc->be->ctx, cell, p, offset, w->cluster_scratch, count);
}

/* Local method of chc and tilequery+chc: CHC++ over the shared tile BVH. */
static void render_tile_chc(void *user, struct tw_cell cell, const float offset[3])
{
    struct frame_ctx *fc = user;
    struct tw_world *w = fc->w;
    const uint32_t p = tw_tiles_select(w->s.tileset, &w->s.selection, cell);
    const struct tw_bvh *bvh = w->bvhs[p];
    struct tw_tile_handle h;
    struct tw_chc_node_state *state = instance_state(fc, cell, p, tw_chc_state_bytes(bvh), &h);
    if (!state)
        return;
    struct tw_chc_tile tile = {
        .cell = cell,
        .prototype = p,
        .proto = &w->s.tileset->prototypes[p],
        .bvh = bvh,
        .state = state,
        .tag = tw_tile_handle_pack(h),
    };
    memcpy(tile.offset, offset, sizeof(tile.offset));
    tw_chc_traverse(fc->ms->chc, fc->v, fc->be, &tile);
}

static struct tw_chc_node_state *resolve_tag(void *user, uint64_t tag, const struct tw_bvh **bvh)
{
    struct frame_ctx *fc = user;
    const struct tw_tile_handle h = tw_tile_handle_unpack(tag);
    const struct tw_tile_info *info = tw_tile_cache_info(fc->ms->cache, h);
    if (!info)
        return NULL;
    *bvh = fc->w->bvhs[info->prototype];
    return tw_tile_cache_state(fc->ms->cache, h);
}

/* Per-tile CHC++ over every tile in the frustum, front to back. */
static int frame_chc(struct frame_ctx *fc)
{
    struct tw_world *w = fc->w;
    const struct tw_tileset *ts = w->s.tileset;
    size_t n = 0;
    int err = gather_cells(w, fc->v, &n);
    if (err)
        return err;
    for (size_t k = 0; k < n && !fc->err; k++) {
        const struct tw_cell cell = w->cells[k].cell;
        float offset[3];
        tw_tiles_cell_offset(cell, fc->v->cell, ts->footprint[0], ts->footprint[1], offset);
        const uint32_t before = tw_chc_stats(fc->ms->chc)->clusters_drawn;
        render_tile_chc(fc, cell, offset);
        fc->tiles_drawn += tw_chc_stats(fc->ms->chc)->clusters_drawn > before;
    }
    return fc->err;
}

static int frame_tilequery(struct frame_ctx *fc, tw_tilequery_render_fn render)
{
    const struct tw_tileset *ts = fc->w->s.tileset;
    struct tw_tilequery_stats tq;
    int err = tw_tilequery_frame(fc->ms->tq, fc->v, fc->be, &ts->common_box, ts->footprint[0],
                                 ts->footprint[1], render, fc, &tq);
    fc->st->tiles_queried = tq.tiles_queried;
    fc->st->predict_fail = tq.predict_fail;
    fc->tiles_drawn = tq.tiles_visible;
    return err ? err : fc->err;
}

/* The ID pass: renders every cluster vfc would draw with its id, then
 * counts each id's visible pixels. Untimed. */
static int oracle_pass(struct tw_world *w, const struct tw_view *v)
{
    struct oracle *o = &w->oracle;
    const struct tw_tileset *ts = w->s.tileset;
    size_t n = 0;
    int err = gather_cells(w, v, &n);
    if (err)
        return err;
    o->count = 0;
    tw_cell_map_clear(o->tiles);
    tw_renderer_id_begin(w->renderer, v);
    for (size_t k = 0; k < n; k++) {
        const struct tw_cell cell = w->cells[k].cell;
        const uint32_t p = tw_tiles_select(ts, &w->s.selection, cell);
        float offset[3];
        tw_tiles_cell_offset(cell, v->cell, ts->footprint[0], ts->footprint[1], offset);
        const uint32_t count = tw_cull_vfc_tile(v, &ts->prototypes[p], offset, w->cluster_scratch);
        if (count == 0)
            continue;
        if (o->count + count > o->cap) {
            size_t cap = o->cap ? o->cap : 4096;
            while (cap < o->count + count)
                cap *= 2;
            struct tw_drawn_cluster *e = realloc(o->entries, sizeof(*e) * cap);
            if (!e)
                return TW_ERR_NOMEM;
            o->entries = e;
            o->cap = cap;
        }
        if (tw_cell_map_set(o->tiles, cell, ((uint64_t)o->count << 32) | count))
            return TW_ERR_NOMEM;
        tw_renderer_id_draw(w->renderer, p, offset, w->cluster_scratch, count, (uint32_t)o->count);
        for (uint32_t c = 0; c < count; c++)
            o->entries[o->count++] = (struct tw_drawn_cluster){cell, p, w->cluster_scratch[c]};
    }
    if (o->count > o->per_id_cap) {
        free(o->pixels);
        free(o->drawn);
        o->pixels = malloc(sizeof(*o->pixels) * o->count);
        o->drawn = malloc(o->count);
        o->per_id_cap = o->pixels && o->drawn ? o->count : 0;
        if (!o->per_id_cap)
            return TW_ERR_NOMEM;
    }
    memset(o->pixels, 0, sizeof(*o->pixels) * o->count);
    tw_renderer_id_read(w->renderer, o->ids);
    const size_t npix = (size_t)w->s.width * w->s.height;
    for (size_t k = 0; k < npix; k++)
        if (o->ids[k] < o->count)
            o->pixels[o->ids[k]]++;
    return TW_OK;
}

/* Compares what the method drew with the oracle's ID buffer. */
static void oracle_compare(struct tw_world *w, struct tw_frame_stats *st)
{
    struct oracle *o = &w->oracle;
    const struct tw_tileset *ts = w->s.tileset;
    memset(o->drawn, 0, o->count);
    size_t n = 0;
    const struct tw_drawn_cluster *d = tw_world_drawn(w, &n);
    for (size_t k = 0; k < n; k++) {
        const uint64_t *range = tw_cell_map_find(o->tiles, d[k].cell);
        const struct tw_cluster *cl = &ts->prototypes[d[k].prototype].clusters[d[k].cluster];
        if (!range) {
            /* Drawn where vfc would draw nothing: wasted. */
            st->overdraw_triangles += cl->triangle_count;
            continue;
        }
        /* Ids of a tile are its clusters in ascending order: binary search. */
        uint32_t lo = (uint32_t)(*range >> 32), hi = lo + (uint32_t)*range;
        while (lo < hi) {
            const uint32_t mid = lo + (hi - lo) / 2;
            if (o->entries[mid].cluster < d[k].cluster)
                lo = mid + 1;
            else
                hi = mid;
        }
        if (lo < (uint32_t)(*range >> 32) + (uint32_t)*range && o->entries[lo].cluster == d[k].cluster) {
            if (!o->drawn[lo] && o->pixels[lo] == 0)
                st->overdraw_triangles += cl->triangle_count;
            o->drawn[lo] = 1;
        } else {
            st->overdraw_triangles += cl->triangle_count;
        }
    }
    for (size_t id = 0; id < o->count; id++) {
        if (o->drawn[id] || o->pixels[id] == 0)
            continue;
        st->missed_pixels += o->pixels[id];
        st->missed_clusters++;
    }
}

/* The oracle method's timed part: exactly the clusters the ID pass saw. */
static int frame_oracle(struct frame_ctx *fc)
{
    struct tw_world *w = fc->w;
    const struct oracle *o = &w->oracle;
    const struct tw_tileset *ts = w->s.tileset;
    size_t k = 0;
    while (k < o->count) {
        const struct tw_cell cell = o->entries[k].cell;
        const uint32_t p = o->entries[k].prototype;
        uint32_t n = 0;
        for (; k < o->count && o->entries[k].cell.i == cell.i && o->entries[k].cell.j == cell.j; k++)
            if (o->pixels[k] > 0)
                w->cluster_scratch[n++] = o->entries[k].cluster;
        if (n == 0)
            continue;
        float offset[3];
        tw_tiles_cell_offset(cell, fc->v->cell, ts->footprint[0], ts->footprint[1], offset);
        fc->be->draw(fc->be->ctx, cell, p, offset, w->cluster_scratch, n);
        fc->tiles_drawn++;
    }
    return TW_OK;
}

static bool camera_valid(const struct tw_camera *cam)
{
    return isfinite(cam->pos.local[0]) && isfinite(cam->pos.local[1]) &&
           isfinite(cam->pos.local[2]) && isfinite(cam->yaw) && isfinite(cam->pitch) &&
           cam->pitch > -89.9f && cam->pitch < 89.9f;
}

/* The view of camera cam (validated, its position normalised); v->frame is
 * left for the caller. */
static int setup_view(struct tw_world *w, const struct tw_camera *cam, struct tw_view *v)
{
    if (!camera_valid(cam)) {
        tw_log_printf(&w->s.log, TW_LOG_ERROR,
                      "camera has a non-finite position or angle, or |pitch| >= 89.9");
        return TW_ERR_INVALID;
    }
    const struct tw_tileset *ts = w->s.tileset;
    struct tw_world_pos pos = cam->pos;
    int err = tw_tiles_normalize(&pos, ts->footprint[0], ts->footprint[1]);
    if (err) {
        tw_log_printf(&w->s.log, TW_LOG_ERROR, "camera position cannot be normalised");
        return err;
    }
    const struct tw_box *cb = &ts->common_box;
    const float diag = sqrtf((cb->max[0] - cb->min[0]) * (cb->max[0] - cb->min[0]) +
                             (cb->max[1] - cb->min[1]) * (cb->max[1] - cb->min[1]) +
                             (cb->max[2] - cb->min[2]) * (cb->max[2] - cb->min[2]));
    /* The far plane lies beyond anything within view distance, so that no
     * drawn tile is cut by it. */
    tw_cull_view_setup(v, pos.cell, pos.local, cam->yaw, cam->pitch, w->s.fov_y,
                       (float)w->s.width / (float)w->s.height, w->s.near_plane,
                       w->s.view_distance + diag);
    v->view_distance = w->s.view_distance;
    return TW_OK;
}

static int collect_debug(struct tw_world *w, const struct method_state *ms,
                         const struct tw_view *v);

int tw_world_frame(struct tw_world *w, const struct tw_camera *cam, struct tw_frame_stats *out)
{
    if (!w || !cam)
        return TW_ERR_INVALID;
    struct tw_view v;
    int err = setup_view(w, cam, &v);
    if (err)
        return err;
    struct method_state *ms = &w->methods[w->method];
    struct tw_frame_stats st = {0};
    st.frame = ++ms->frame;
    st.method = w->method;
    v.frame = st.frame;
    w->last_view = v;
    w->has_view = true;

    const bool verify = w->s.verify;
    tw_renderer_record_draws(w->renderer, verify || w->record_draws ||
                                              (w->debug & (TW_DEBUG_CELLS | TW_DEBUG_NODES)));
    if (w->debug)
        tw_renderer_record_queries(w->renderer, (w->debug & TW_DEBUG_QUERIES) != 0);
    if (w->method == TW_METHOD_ORACLE) {
        /* The ID pass is the oracle's knowledge, not its work: untimed. */
        err = oracle_pass(w, &v);
        if (err)
            return err;
    }
    const double t0 = tw_renderer_now_ms();
    tw_renderer_begin_frame(w->renderer, &v);
    const struct tw_query_backend be = tw_renderer_backend(w->renderer);
    struct frame_ctx fc = {w, ms, &v, &be, &st, 0, TW_OK};
    if (ms->chc)
        tw_chc_begin_frame(ms->chc, &v, &be, resolve_tag, &fc);
    switch (w->method) {
    case TW_METHOD_VFC:
        err = frame_vfc(&fc);
        break;
    case TW_METHOD_CHC:
        err = frame_chc(&fc);
        break;
    case TW_METHOD_TILEQUERY:
        err = frame_tilequery(&fc, render_tile_vfc);
        break;
    case TW_METHOD_TILEQUERY_CHC:
        err = frame_tilequery(&fc, render_tile_chc);
        break;
    case TW_METHOD_ORACLE:
        err = frame_oracle(&fc);
        break;
    default:
        err = TW_ERR_INVALID;
        break;
    }
    st.tiles_visible = fc.tiles_drawn;
    if (ms->cache) {
        tw_tile_cache_evict(ms->cache, st.frame);
        st.tiles_cached = tw_tile_cache_count(ms->cache);
        st.cache_bytes = tw_tile_cache_bytes(ms->cache);
    }
    const double t1 = tw_renderer_now_ms();
    tw_renderer_end_frame(w->renderer);
    const double t2 = tw_renderer_now_ms();
    if (err)
        return err;

    if (verify) {
        if (w->method != TW_METHOD_ORACLE)
            err = oracle_pass(w, &v);
        if (err)
            return err;
        oracle_compare(w, &st);
    }
    if (w->debug) {
        err = collect_debug(w, ms, &v);
        if (err)
            return err;
    }

    const struct tw_render_counters *rc = tw_renderer_counters(w->renderer);
    st.ms_frame = t2 - t0;
    st.ms_wait = rc->ms_wait;
    st.ms_cull = (t1 - t0) - rc->ms_backend;
    if (st.ms_cull < 0.0)
        st.ms_cull = 0.0;
    st.triangles = rc->triangles;
    st.clusters = rc->clusters;
    st.draws = rc->draws;
    st.queries = rc->queries;
    if (out)
        *out = st;
    return TW_OK;
}

int tw_world_read_rgb(struct tw_world *w, uint8_t *rgb)
{
    if (!w || !rgb)
        return TW_ERR_INVALID;
    return tw_renderer_read_rgb(w->renderer, rgb);
}

void tw_world_record_draws(struct tw_world *w, bool on)
{
    w->record_draws = on;
}

const struct tw_drawn_cluster *tw_world_drawn(const struct tw_world *w, size_t *count)
{
    return tw_renderer_drawn(w->renderer, count);
}

/* ---- debugging and the viewer ------------------------------------------------------ */

static const char *const debug_kind_names[TW_DEBUG_KIND_COUNT] = {
    [TW_DEBUG_CELL_START] = "start",
    [TW_DEBUG_CELL_FREE] = "free",
    [TW_DEBUG_CELL_VISIBLE] = "visible",
    [TW_DEBUG_CELL_POSTPONED] = "postponed",
    [TW_DEBUG_CELL_OCCLUDED] = "occluded",
    [TW_DEBUG_CELL_NOT_REACHED] = "not reached",
    [TW_DEBUG_NODE_LEAF] = "leaf",
    [TW_DEBUG_NODE_INNER] = "node",
    [TW_DEBUG_QUERY_VISIBLE] = "query visible",
    [TW_DEBUG_QUERY_HIDDEN] = "query hidden",
    [TW_DEBUG_QUERY_UNREAD] = "query unread",
};

/* Cells after the paper's Figure 6: yellow where propagation starts, light
 * blue visible, dark blue hidden; the states it does not show get colours
 * of their own. */
static const float debug_kind_colors[TW_DEBUG_KIND_COUNT][4] = {
    [TW_DEBUG_CELL_START] = {1.00f, 0.86f, 0.10f, 0.55f},
    [TW_DEBUG_CELL_FREE] = {1.00f, 0.55f, 0.10f, 0.55f},
    [TW_DEBUG_CELL_VISIBLE] = {0.35f, 0.80f, 1.00f, 0.50f},
    [TW_DEBUG_CELL_POSTPONED] = {0.80f, 0.35f, 1.00f, 0.55f},
    [TW_DEBUG_CELL_OCCLUDED] = {0.05f, 0.12f, 0.60f, 0.65f},
    [TW_DEBUG_CELL_NOT_REACHED] = {0.45f, 0.45f, 0.45f, 0.35f},
    [TW_DEBUG_NODE_LEAF] = {0.10f, 0.95f, 0.90f, 0.90f},
    [TW_DEBUG_NODE_INNER] = {1.00f, 0.85f, 0.25f, 0.70f},
    [TW_DEBUG_QUERY_VISIBLE] = {0.55f, 1.00f, 0.15f, 0.95f},
    [TW_DEBUG_QUERY_HIDDEN] = {1.00f, 0.20f, 0.15f, 0.95f},
    [TW_DEBUG_QUERY_UNREAD] = {1.00f, 0.30f, 1.00f, 0.95f},
};

const char *tw_debug_kind_name(enum tw_debug_kind kind)
{
    return (unsigned)kind < TW_DEBUG_KIND_COUNT ? debug_kind_names[kind] : "unknown";
}

void tw_debug_kind_color(enum tw_debug_kind kind, float rgba[4])
{
    static const float none[4] = {1.0f, 1.0f, 1.0f, 1.0f};
    memcpy(rgba, (unsigned)kind < TW_DEBUG_KIND_COUNT ? debug_kind_colors[kind] : none,
           sizeof(float) * 4);
}

int tw_world_set_debug(struct tw_world *w, unsigned flags)
{
    if (!w || (flags & ~TW_DEBUG_ALL))
        return TW_ERR_INVALID;
    int err = TW_OK;
    if ((flags & TW_DEBUG_CELLS) && !w->debug_seen)
        err = tw_cell_map_create(&w->debug_seen);
    if (!err && (flags & TW_DEBUG_NODES) && !w->debug_leaf_of) {
        /* Which leaf holds each cluster, once per prototype. */
        const struct tw_tileset *ts = w->s.tileset;
        uint32_t max_nodes = 1;
        w->debug_leaf_of = calloc(ts->prototype_count ? ts->prototype_count : 1,
                                  sizeof(*w->debug_leaf_of));
        for (uint32_t p = 0; w->debug_leaf_of && p < ts->prototype_count; p++) {
            const struct tw_bvh *bvh = w->bvhs[p];
            uint32_t *leaf_of = malloc(sizeof(uint32_t) * (ts->prototypes[p].cluster_count + 1));
            if (!leaf_of) {
                err = TW_ERR_NOMEM;
                break;
            }
            for (uint32_t c = 0; c < ts->prototypes[p].cluster_count; c++)
                leaf_of[c] = TW_BVH_NONE;
            for (uint32_t n = 0; n < bvh->node_count; n++) {
                const struct tw_bvh_node *node = &bvh->nodes[n];
                for (uint32_t k = 0; k < node->cluster_count; k++)
                    leaf_of[bvh->cluster_order[node->first_cluster + k]] = n;
            }
            w->debug_leaf_of[p] = leaf_of;
            if (bvh->node_count > max_nodes)
                max_nodes = bvh->node_count;
        }
        w->debug_stamp = calloc(max_nodes, sizeof(*w->debug_stamp));
        if (!w->debug_leaf_of || !w->debug_stamp)
            err = TW_ERR_NOMEM;
        if (err) {
            if (w->debug_leaf_of)
                for (uint32_t p = 0; p < ts->prototype_count; p++)
                    free(w->debug_leaf_of[p]);
            free(w->debug_leaf_of);
            free(w->debug_stamp);
            w->debug_leaf_of = NULL;
            w->debug_stamp = NULL;
        }
    }
    if (err)
        return err;
    w->debug = flags;
    w->debug_count = 0;
    if (!(flags & TW_DEBUG_QUERIES))
        tw_renderer_record_queries(w->renderer, false);
    return TW_OK;
}

const struct tw_debug_box *tw_world_debug_boxes(const struct tw_world *w, size_t *count)
{
    *count = w->debug_count;
    return w->debug_boxes;
}

static struct tw_debug_box *push_debug(struct tw_world *w)
{
    if (w->debug_count == w->debug_cap) {
        size_t cap = w->debug_cap ? 2 * w->debug_cap : 1024;
        struct tw_debug_box *b = realloc(w->debug_boxes, sizeof(*b) * cap);
        if (!b)
            return NULL;
        w->debug_boxes = b;
        w->debug_cap = cap;
    }
    struct tw_debug_box *b = &w->debug_boxes[w->debug_count++];
    memset(b, 0, sizeof(*b));
    return b;
}

/* A cell's quad: its footprint inset by half a percent, so that
 * neighbours stay apart and a street on the border still shows both. */
static int push_cell(struct tw_world *w, struct tw_cell cell, enum tw_debug_kind kind)
{
    const float *fp = w->s.tileset->footprint;
    struct tw_debug_box *b = push_debug(w);
    if (!b || tw_cell_map_set(w->debug_seen, cell, 1))
        return TW_ERR_NOMEM;
    b->cell = cell;
    b->box = (struct tw_box){{0.005f * fp[0], 0.3f, 0.005f * fp[1]},
                             {0.995f * fp[0], 0.3f, 0.995f * fp[1]}};
    b->kind = (uint16_t)kind;
    return TW_OK;
}

struct cell_report {
    struct tw_world *w;
    int err;
};

static void report_cell(void *user, struct tw_cell cell, enum tw_tilequery_cell_state state)
{
    static const enum tw_debug_kind kinds[] = {
        [TW_TILEQUERY_CELL_START] = TW_DEBUG_CELL_START,
        [TW_TILEQUERY_CELL_FREE] = TW_DEBUG_CELL_FREE,
        [TW_TILEQUERY_CELL_VISIBLE] = TW_DEBUG_CELL_VISIBLE,
        [TW_TILEQUERY_CELL_OCCLUDED] = TW_DEBUG_CELL_OCCLUDED,
        [TW_TILEQUERY_CELL_POSTPONED] = TW_DEBUG_CELL_POSTPONED,
    };
    struct cell_report *cr = user;
    if (!cr->err && (unsigned)state < sizeof(kinds) / sizeof(kinds[0]))
        cr->err = push_cell(cr->w, cell, kinds[state]);
}

static int collect_cells(struct tw_world *w, const struct method_state *ms, const struct tw_view *v)
{
    struct cell_report cr = {w, TW_OK};
    tw_cell_map_clear(w->debug_seen);
    if (ms->tq) {
        tw_tilequery_last_cells(ms->tq, report_cell, &cr);
    } else {
        size_t n = 0;
        const struct tw_drawn_cluster *d = tw_renderer_drawn(w->renderer, &n);
        for (size_t k = 0; k < n && !cr.err; k++)
            if (!tw_cell_map_find(w->debug_seen, d[k].cell))
                cr.err = push_cell(w, d[k].cell, TW_DEBUG_CELL_VISIBLE);
    }
    size_t n = 0;
    int err = cr.err ? cr.err : gather_cells(w, v, &n);
    for (size_t k = 0; k < n && !err; k++)
        if (!tw_cell_map_find(w->debug_seen, w->cells[k].cell))
            err = push_cell(w, w->cells[k].cell, TW_DEBUG_CELL_NOT_REACHED);
    return err;
}

/* Every node on the way from a drawn cluster's leaf to the root, once per tile. */
static int collect_nodes(struct tw_world *w)
{
    size_t n = 0;
    const struct tw_drawn_cluster *d = tw_renderer_drawn(w->renderer, &n);
    for (size_t k = 0; k < n; k++) {
        if (k == 0 || d[k].cell.i != d[k - 1].cell.i || d[k].cell.j != d[k - 1].cell.j) {
            if (++w->debug_stamp_now == 0) {
                /* Wrapped around: forget every old mark. */
                uint32_t max_nodes = 1;
                for (uint32_t p = 0; p < w->s.tileset->prototype_count; p++)
                    if (w->bvhs[p]->node_count > max_nodes)
                        max_nodes = w->bvhs[p]->node_count;
                memset(w->debug_stamp, 0, sizeof(*w->debug_stamp) * max_nodes);
                w->debug_stamp_now = 1;
            }
        }
        const struct tw_bvh *bvh = w->bvhs[d[k].prototype];
        uint32_t node = w->debug_leaf_of[d[k].prototype][d[k].cluster];
        while (node != TW_BVH_NONE && w->debug_stamp[node] != w->debug_stamp_now) {
            w->debug_stamp[node] = w->debug_stamp_now;
            struct tw_debug_box *b = push_debug(w);
            if (!b)
                return TW_ERR_NOMEM;
            b->cell = d[k].cell;
            b->box = bvh->nodes[node].box;
            b->kind = bvh->nodes[node].cluster_count ? TW_DEBUG_NODE_LEAF : TW_DEBUG_NODE_INNER;
            b->level = (uint16_t)bvh->nodes[node].depth;
            node = bvh->nodes[node].parent;
        }
    }
    return TW_OK;
}

static int collect_queries(struct tw_world *w, const struct tw_view *v)
{
    size_t n = 0;
    const struct tw_renderer_query_box *q = tw_renderer_queries(w->renderer, &n);
    for (size_t k = 0; k < n; k++) {
        struct tw_debug_box *b = push_debug(w);
        if (!b)
            return TW_ERR_NOMEM;
        b->cell = v->cell;
        memcpy(b->box.min, q[k].min, sizeof(b->box.min));
        memcpy(b->box.max, q[k].max, sizeof(b->box.max));
        b->kind = q[k].result > 0    ? TW_DEBUG_QUERY_VISIBLE
                  : q[k].result == 0 ? TW_DEBUG_QUERY_HIDDEN
                                     : TW_DEBUG_QUERY_UNREAD;
        b->level = (uint16_t)(q[k].boxes < UINT16_MAX ? q[k].boxes : UINT16_MAX);
        b->tile_query = q[k].tile;
    }
    return TW_OK;
}

/* After the timed part of the frame: the boxes of the debug views on. */
static int collect_debug(struct tw_world *w, const struct method_state *ms,
                         const struct tw_view *v)
{
    w->debug_count = 0;
    int err = TW_OK;
    if (w->debug & TW_DEBUG_CELLS)
        err = collect_cells(w, ms, v);
    if (!err && (w->debug & TW_DEBUG_NODES))
        err = collect_nodes(w);
    if (!err && (w->debug & TW_DEBUG_QUERIES))
        err = collect_queries(w, v);
    return err;
}

int tw_world_draw_debug(struct tw_world *w, const struct tw_debug_box *boxes, size_t count)
{
    if (!w || (count && !boxes))
        return TW_ERR_INVALID;
    if (!w->has_view) {
        tw_log_printf(&w->s.log, TW_LOG_ERROR, "tw_world_draw_debug: no frame rendered yet");
        return TW_ERR_STATE;
    }
    if (count > w->debug_draw_cap) {
        struct tw_renderer_debug_box *d = realloc(w->debug_draw, sizeof(*d) * count);
        if (!d)
            return TW_ERR_NOMEM;
        w->debug_draw = d;
        w->debug_draw_cap = count;
    }
    const struct tw_view *v = &w->last_view;
    const float *fp = w->s.tileset->footprint;
    /* Five layers, one renderer call each: cell quads, inner nodes, leaves,
     * tile queries (wider), node queries. */
    static const struct {
        bool fill;
        float line_px;
    } layers[5] = {{true, 0.0f}, {false, 1.0f}, {false, 1.25f}, {false, 2.5f}, {false, 1.5f}};
    for (int layer = 0; layer < 5; layer++) {
        size_t n = 0;
        for (size_t k = 0; k < count; k++) {
            const struct tw_debug_box *b = &boxes[k];
            int in;
            if (b->kind <= TW_DEBUG_CELL_NOT_REACHED)
                in = 0;
            else if (b->kind == TW_DEBUG_NODE_INNER)
                in = 1;
            else if (b->kind == TW_DEBUG_NODE_LEAF)
                in = 2;
            else if (b->kind < TW_DEBUG_KIND_COUNT)
                in = b->tile_query ? 3 : 4;
            else
                continue;
            if (in != layer)
                continue;
            struct tw_renderer_debug_box *r = &w->debug_draw[n++];
            float offset[3];
            tw_tiles_cell_offset(b->cell, v->cell, fp[0], fp[1], offset);
            for (int a = 0; a < 3; a++) {
                r->min[a] = b->box.min[a] + offset[a];
                r->max[a] = b->box.max[a] + offset[a];
            }
            tw_debug_kind_color((enum tw_debug_kind)b->kind, r->color);
            if (b->kind == TW_DEBUG_NODE_INNER) {
                /* Deeper nodes fainter: the root frames the tile, leaves show detail. */
                r->color[3] *= 1.0f / (1.0f + 0.25f * (float)b->level);
            }
        }
        tw_renderer_draw_debug(w->renderer, v, w->debug_draw, n, layers[layer].fill,
                               layers[layer].line_px);
    }
    return TW_OK;
}

int tw_world_frame_fixed(struct tw_world *w, const struct tw_camera *cam,
                         const struct tw_drawn_cluster *clusters, size_t count,
                         struct tw_frame_stats *out)
{
    if (!w || !cam || (count && !clusters))
        return TW_ERR_INVALID;
    struct tw_view v;
    int err = setup_view(w, cam, &v);
    if (err)
        return err;
    const struct tw_tileset *ts = w->s.tileset;
    for (size_t k = 0; k < count; k++)
        if (clusters[k].prototype >= ts->prototype_count ||
            clusters[k].cluster >= ts->prototypes[clusters[k].prototype].cluster_count) {
            tw_log_printf(&w->s.log, TW_LOG_ERROR,
                          "tw_world_frame_fixed: cluster %zu names no cluster of the tileset", k);
            return TW_ERR_INVALID;
        }
    struct tw_frame_stats st = {0};
    st.frame = w->methods[w->method].frame;
    st.method = w->method;
    v.frame = st.frame;
    w->last_view = v;
    w->has_view = true;
    tw_renderer_record_draws(w->renderer, false);
    tw_renderer_record_queries(w->renderer, false);
    const double t0 = tw_renderer_now_ms();
    tw_renderer_begin_frame(w->renderer, &v);
    const struct tw_query_backend be = tw_renderer_backend(w->renderer);
    size_t k = 0;
    while (k < count) {
        /* One draw call per run of clusters of the same tile. */
        const struct tw_cell cell = clusters[k].cell;
        const uint32_t p = clusters[k].prototype;
        uint32_t n = 0;
        for (; k < count && clusters[k].cell.i == cell.i && clusters[k].cell.j == cell.j &&
               clusters[k].prototype == p && n < ts->prototypes[p].cluster_count;
             k++)
            w->cluster_scratch[n++] = clusters[k].cluster;
        float offset[3];
        tw_tiles_cell_offset(cell, v.cell, ts->footprint[0], ts->footprint[1], offset);
        be.draw(be.ctx, cell, p, offset, w->cluster_scratch, n);
        st.tiles_visible++;
    }
    tw_renderer_end_frame(w->renderer);
    const struct tw_render_counters *rc = tw_renderer_counters(w->renderer);
    st.ms_frame = tw_renderer_now_ms() - t0;
    st.triangles = rc->triangles;
    st.clusters = rc->clusters;
    st.draws = rc->draws;
    if (out)
        *out = st;
    return TW_OK;
}

int tw_world_blit(struct tw_world *w, uint32_t target, uint32_t width, uint32_t height)
{
    if (!w || width == 0 || height == 0 || width > 16384 || height > 16384)
        return TW_ERR_INVALID;
    tw_renderer_blit(w->renderer, target, width, height);
    return TW_OK;
}
