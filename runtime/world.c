/* The world: a tileset on the infinite grid, drawn with a method (runtime.h). */
#include "runtime/renderer.h"
#include "runtime/runtime.h"

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

int tw_world_frame(struct tw_world *w, const struct tw_camera *cam, struct tw_frame_stats *out)
{
    if (!w || !cam)
        return TW_ERR_INVALID;
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
    struct method_state *ms = &w->methods[w->method];
    struct tw_frame_stats st = {0};
    st.frame = ++ms->frame;
    st.method = w->method;

    struct tw_view v;
    const struct tw_box *cb = &ts->common_box;
    const float diag = sqrtf((cb->max[0] - cb->min[0]) * (cb->max[0] - cb->min[0]) +
                             (cb->max[1] - cb->min[1]) * (cb->max[1] - cb->min[1]) +
                             (cb->max[2] - cb->min[2]) * (cb->max[2] - cb->min[2]));
    /* The far plane lies beyond anything within view distance, so that no
     * drawn tile is cut by it. */
    tw_cull_view_setup(&v, pos.cell, pos.local, cam->yaw, cam->pitch, w->s.fov_y,
                       (float)w->s.width / (float)w->s.height, w->s.near_plane,
                       w->s.view_distance + diag);
    v.view_distance = w->s.view_distance;
    v.frame = st.frame;

    const bool verify = w->s.verify;
    tw_renderer_record_draws(w->renderer, verify || w->record_draws);
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
