/*
 * The world (runtime.h): a tileset on the infinite grid, drawn with a method.
 * A frame sets up the view, hands it to the method's driver (cull/), which
 * culls and draws through the renderer's query backend, and collects the
 * statistics. The oracle and the debug views have files of their own.
 */
#include "runtime/world-private.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

static const char *const method_names[TW_METHOD_COUNT] = {
    [TW_METHOD_DEFAULT] = "default",
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
    if (!name || !out)
        return TW_ERR_INVALID;
    for (int m = TW_METHOD_FIRST; m < TW_METHOD_COUNT; m++)
        if (strcmp(name, method_names[m]) == 0) {
            *out = (enum tw_method)m;
            return TW_OK;
        }
    return TW_ERR_INVALID;
}

enum tw_method tw_method_resolve(enum tw_method m)
{
    return m == TW_METHOD_DEFAULT ? TW_METHOD_TILEQUERY_CHC : m;
}

bool tw_method_available(enum tw_method m)
{
    return (unsigned)m < TW_METHOD_COUNT;
}

bool tw_method_conservative(enum tw_method m, const struct tw_world_settings *s)
{
    const uint32_t chc_t = s ? s->chc.threshold : 0;
    const uint32_t tq_t = s ? s->tilequery.threshold : 0;
    switch (tw_method_resolve(m)) {
    case TW_METHOD_VFC:
    case TW_METHOD_ORACLE:
        return true;
    case TW_METHOD_TILEQUERY:
        return tq_t == 0;
    case TW_METHOD_CHC:
        return chc_t == 0;
    case TW_METHOD_TILEQUERY_CHC:
        return tq_t == 0 && chc_t == 0;
    default:
        return false;
    }
}

void tw_world_default_settings(struct tw_world_settings *s)
{
    if (!s)
        return;
    s->method = tw_method_resolve(s->method);
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
    if (!(s->verify_tolerance > 0.0f))
        s->verify_tolerance = TW_VERIFY_TOLERANCE;
    tw_chc_default_settings(&s->chc);
    tw_tilequery_default_settings(&s->tilequery);
    tw_bvh_default_settings(&s->bvh);
}

/* The driver of method m (the oracle's timed part draws a given set). */
static int create_driver(const struct tw_world *w, enum tw_method m, struct tw_cull_driver **out)
{
    static const enum tw_cull_method drivers[TW_METHOD_COUNT] = {
        [TW_METHOD_VFC] = TW_CULL_VFC,
        [TW_METHOD_TILEQUERY] = TW_CULL_TILEQUERY,
        [TW_METHOD_CHC] = TW_CULL_CHC,
        [TW_METHOD_TILEQUERY_CHC] = TW_CULL_TILEQUERY_CHC,
        [TW_METHOD_ORACLE] = TW_CULL_GIVEN,
    };
    const struct tw_cull_driver_settings ds = {
        .method = drivers[m],
        .evict_after_frames = w->s.evict_after_frames,
        .chc = w->s.chc,
        .tilequery = w->s.tilequery,
    };
    return tw_cull_driver_create(&ds, out);
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
    if (!settings->get_proc) {
        tw_log_printf(log, TW_LOG_ERROR, "tw_world_create: get_proc (the GL loader) is missing");
        return TW_ERR_INVALID;
    }
    if (settings->width > 16384 || settings->height > 16384 || !isfinite(settings->fov_y) ||
        settings->fov_y >= 179.0f || !isfinite(settings->view_distance) ||
        !isfinite(settings->near_plane) || (unsigned)settings->method >= TW_METHOD_COUNT ||
        !(settings->verify_tolerance >= 0.0f && settings->verify_tolerance < 1.0f) ||
        !(settings->mutate_query_shrink >= 0.0f && settings->mutate_query_shrink < 1.0f)) {
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
    if (!w->bvhs) {
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
    if (w->s.calibration.query_ms > 0.0) {
        w->calibration = w->s.calibration;
        w->calibration.measured = false;
    } else if (w->s.deterministic) {
        tw_calibrate_nominal(&w->calibration);
    } else {
        tw_renderer_enter(w->renderer);
        err = tw_calibrate_measure(w->renderer, ts, w->s.width, w->s.height, w->s.fov_y,
                                   &w->calibration);
        tw_renderer_leave(w->renderer);
        if (err)
            goto fail;
    }
    if (!(w->calibration.query_scale > 0.0))
        w->calibration.query_scale = w->calibration.draw_scale = 1.0;
    w->fixed = (struct tw_cull_fixed){ts, &w->s.selection, w->bvhs, &w->s.log};
    w->grid = tw_cull_fixed_grid(&w->fixed);
    tw_renderer_set_tile_query_box(w->renderer, &w->grid.common_box);
    tw_renderer_set_deterministic(w->renderer, w->s.deterministic);
    tw_renderer_set_count_samples(w->renderer, w->s.chc.threshold > 0 || w->s.tilequery.threshold > 0);
    tw_renderer_set_mutation(w->renderer, w->s.mutate_query_shrink);
    const struct tw_cull_driver_settings given = {.method = TW_CULL_GIVEN};
    err = tw_oracle_init(w);
    if (!err)
        err = tw_cull_driver_create(&given, &w->fixed_set);
    if (!err)
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
    for (int m = 0; m < TW_METHOD_COUNT; m++)
        tw_cull_driver_destroy(w->methods[m].driver);
    tw_cull_driver_destroy(w->fixed_set);
    tw_oracle_finish(&w->oracle);
    tw_debug_finish(w);
    tw_cull_cells_finish(&w->cells);
    if (w->bvhs)
        for (uint32_t p = 0; p < w->s.tileset->prototype_count; p++)
            tw_bvh_destroy(w->bvhs[p]);
    free(w->bvhs);
    tw_renderer_destroy(w->renderer);
    free(w);
}

int tw_world_set_method(struct tw_world *w, enum tw_method m)
{
    if (!w || (unsigned)m >= TW_METHOD_COUNT)
        return TW_ERR_INVALID;
    m = tw_method_resolve(m);
    if (!tw_method_available(m)) {
        tw_log_printf(&w->s.log, TW_LOG_ERROR, "method '%s' is not implemented yet",
                      tw_method_name(m));
        return TW_ERR_INVALID;
    }
    struct method_state *ms = &w->methods[m];
    if (!ms->driver) {
        int err = create_driver(w, m, &ms->driver);
        if (err)
            return err;
    }
    w->method = m;
    w->s.method = m;
    return TW_OK;
}

const struct tw_world_settings *tw_world_settings(const struct tw_world *w)
{
    return w ? &w->s : NULL;
}

const struct tw_bvh *tw_world_bvh(const struct tw_world *w, uint32_t p)
{
    return w && p < w->s.tileset->prototype_count ? w->bvhs[p] : NULL;
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

/* The drawing counters of the renderer's last frame into st. */
static void collect_counters(const struct tw_world *w, struct tw_frame_stats *st)
{
    const struct tw_render_counters *rc = tw_renderer_counters(w->renderer);
    st->ms_wait = rc->ms_wait;
    st->triangles = rc->triangles;
    st->clusters = rc->clusters;
    st->draws = rc->draws;
    st->queries = rc->queries;
    st->blocking_reads = rc->blocking_reads;
}

static int frame(struct tw_world *w, const struct tw_camera *cam, struct tw_frame_stats *out)
{
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
    const unsigned debug = w->debug.flags;
    tw_renderer_record_draws(w->renderer,
                             verify || w->record_draws || (debug & (TW_DEBUG_CELLS | TW_DEBUG_NODES)));
    if (debug)
        tw_renderer_record_queries(w->renderer, (debug & TW_DEBUG_QUERIES) != 0);
    if (w->method == TW_METHOD_ORACLE) {
        /* The ID pass is the oracle's knowledge, not its work: untimed. */
        err = tw_oracle_pass(w, &v);
        if (err)
            return err;
        tw_cull_driver_give(ms->driver, w->oracle.visible, w->oracle.visible_count);
    }
    struct tw_cost_model costs;
    tw_calibrate_model(&w->calibration, w->s.width, w->s.height, w->s.fov_y, &costs);
    tw_cull_driver_set_costs(ms->driver, &costs);
    const double t0 = tw_renderer_now_ms(), cpu0 = tw_renderer_cpu_ms();
    tw_renderer_begin_frame(w->renderer, &v);
    const struct tw_query_backend be = tw_renderer_backend(w->renderer);
    struct tw_cull_frame_stats cs = {0};
    err = tw_cull_driver_frame(ms->driver, &v, &w->grid, &be, &w->cells, &cs);
    const double t1 = tw_renderer_now_ms();
    tw_renderer_end_frame(w->renderer);
    st.tiles_queried = cs.tiles_queried;
    st.tiles_visible = cs.tiles_visible;
    st.tiles_new = cs.tiles_new;
    st.tiles_cached = cs.tiles_cached;
    st.cache_bytes = cs.cache_bytes;
    st.predict_fail = cs.predict_fail;
    st.queries_skipped = cs.queries_skipped;
    if (err)
        return err;
    collect_counters(w, &st);
    st.ms_cull = (t1 - t0) - tw_renderer_counters(w->renderer)->ms_backend;
    if (st.ms_cull < 0.0)
        st.ms_cull = 0.0;
    st.ms_frame = tw_renderer_now_ms() - t0;
    st.cpu_ms = tw_renderer_cpu_ms() - cpu0;

    if (verify) {
        /* The frame's time ends where the GPU is done with it; the ID pass
         * after it is not the method's work. */
        tw_renderer_finish(w->renderer);
        st.ms_frame = tw_renderer_now_ms() - t0;
        st.cpu_ms = tw_renderer_cpu_ms() - cpu0;
        if (w->method != TW_METHOD_ORACLE)
            err = tw_oracle_pass(w, &v);
        if (err)
            return err;
        tw_oracle_compare(w, &st);
    }
    if (debug) {
        err = tw_debug_collect(w, ms, &v);
        if (err)
            return err;
    }
    if (out)
        *out = st;
    return TW_OK;
}

int tw_world_frame(struct tw_world *w, const struct tw_camera *cam, struct tw_frame_stats *out)
{
    if (!w || !cam)
        return TW_ERR_INVALID;
    tw_renderer_enter(w->renderer);
    const int err = frame(w, cam, out);
    tw_renderer_leave(w->renderer);
    return err;
}

int tw_world_finish(struct tw_world *w, struct tw_frame_stats *st)
{
    if (!w)
        return TW_ERR_INVALID;
    const double t0 = tw_renderer_now_ms(), cpu0 = tw_renderer_cpu_ms();
    tw_renderer_finish(w->renderer);
    if (st) {
        st->ms_frame += tw_renderer_now_ms() - t0;
        st->cpu_ms += tw_renderer_cpu_ms() - cpu0;
        /* A finished frame's CPU time refines what queries and draws cost. */
        const struct tw_render_counters *rc = tw_renderer_counters(w->renderer);
        tw_calibrate_refine(&w->fit, &w->calibration, st->cpu_ms, rc->queries, rc->query_boxes,
                            rc->draws, rc->triangles);
    }
    return TW_OK;
}

const struct tw_calibration *tw_world_calibration(const struct tw_world *w)
{
    return w ? &w->calibration : NULL;
}

int tw_world_read_rgb(struct tw_world *w, uint8_t *rgb)
{
    if (!w || !rgb)
        return TW_ERR_INVALID;
    tw_renderer_enter(w->renderer);
    const int err = tw_renderer_read_rgb(w->renderer, rgb);
    tw_renderer_leave(w->renderer);
    return err;
}

void tw_world_record_draws(struct tw_world *w, bool on)
{
    if (w)
        w->record_draws = on;
}

const struct tw_drawn_cluster *tw_world_drawn(const struct tw_world *w, size_t *count)
{
    if (!w || !count) {
        if (count)
            *count = 0;
        return NULL;
    }
    return tw_renderer_drawn(w->renderer, count);
}

int tw_world_last_view(const struct tw_world *w, struct tw_view *out)
{
    if (!w || !out)
        return TW_ERR_INVALID;
    if (!w->has_view)
        return TW_ERR_STATE;
    *out = w->last_view;
    return TW_OK;
}

bool tw_world_reversed_z(const struct tw_world *w)
{
    return w && tw_renderer_reversed_z(w->renderer);
}

static int frame_fixed(struct tw_world *w, const struct tw_camera *cam,
                       const struct tw_drawn_cluster *clusters, size_t count,
                       struct tw_frame_stats *out)
{
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
    struct tw_cull_frame_stats cs = {0};
    tw_cull_driver_give(w->fixed_set, clusters, count);
    err = tw_cull_driver_frame(w->fixed_set, &v, &w->grid, &be, &w->cells, &cs);
    tw_cull_driver_give(w->fixed_set, NULL, 0);
    tw_renderer_end_frame(w->renderer);
    if (err)
        return err;
    collect_counters(w, &st);
    st.tiles_visible = cs.tiles_visible;
    st.ms_frame = tw_renderer_now_ms() - t0;
    st.ms_wait = 0.0;
    st.queries = 0;
    if (out)
        *out = st;
    return TW_OK;
}

int tw_world_frame_fixed(struct tw_world *w, const struct tw_camera *cam,
                         const struct tw_drawn_cluster *clusters, size_t count,
                         struct tw_frame_stats *out)
{
    if (!w || !cam || (count && !clusters))
        return TW_ERR_INVALID;
    tw_renderer_enter(w->renderer);
    const int err = frame_fixed(w, cam, clusters, count, out);
    tw_renderer_leave(w->renderer);
    return err;
}

int tw_world_blit(struct tw_world *w, uint32_t target, uint32_t width, uint32_t height)
{
    if (!w || width == 0 || height == 0 || width > 16384 || height > 16384)
        return TW_ERR_INVALID;
    tw_renderer_enter(w->renderer);
    tw_renderer_blit(w->renderer, target, width, height);
    tw_renderer_leave(w->renderer);
    return TW_OK;
}
