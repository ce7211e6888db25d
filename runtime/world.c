/*
 * The world (runtime.h): a tileset on the infinite grid, drawn with a method.
 * A frame sets up the view, hands it to the method's driver (cull/), which
 * culls and draws through the renderer's query backend, and collects the
 * statistics. The oracle and the debug views have files of their own.
 */
#include "runtime/world-private.h"
#include "tiles/array.h"
#include "tiles/clock.h"
#include "tiles/tiles-internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static const char *const method_names[TW_METHOD_ALL] = {
    [TW_METHOD_DEFAULT] = "default",
    [TW_METHOD_VFC] = "vfc",
    [TW_METHOD_TILEQUERY] = "tilequery",
    [TW_METHOD_CHC] = "chc",
    [TW_METHOD_TILEQUERY_CHC] = "tilequery+chc",
    [TW_METHOD_HZB] = "hzb",
    [TW_METHOD_TILEQUERY_HZB] = "tilequery+hzb",
    [TW_METHOD_ORACLE] = "oracle",
    [TW_METHOD_BOX_ORACLE] = "box-oracle",
};

const char *tw_method_name(enum tw_method m)
{
    return (unsigned)m < TW_METHOD_ALL ? method_names[m] : "unknown";
}

static int from_name(const char *name, int count, enum tw_method *out)
{
    if (!name || !out)
        return TW_ERR_INVALID;
    for (int m = TW_METHOD_FIRST; m < count; m++)
        if (strcmp(name, method_names[m]) == 0) {
            *out = (enum tw_method)m;
            return TW_OK;
        }
    return TW_ERR_INVALID;
}

int tw_method_from_name(const char *name, enum tw_method *out)
{
    return from_name(name, TW_METHOD_COUNT, out);
}

int tw_method_or_limit_from_name(const char *name, enum tw_method *out)
{
    return from_name(name, TW_METHOD_ALL, out);
}

enum tw_method tw_method_resolve(enum tw_method m)
{
    return m == TW_METHOD_DEFAULT ? TW_METHOD_TILEQUERY_CHC : m;
}

bool tw_method_conservative(enum tw_method m, const struct tw_world_tuning *t)
{
    const uint32_t chc_t = t ? t->chc.threshold : 0;
    const uint32_t tq_t = t ? t->tilequery.threshold : 0;
    if (tw_method_limit(m))
        return true;
    switch (tw_method_resolve(m)) {
    case TW_METHOD_VFC:
    case TW_METHOD_HZB:             /* no queries, no threshold */
    case TW_METHOD_TILEQUERY_HZB:
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

bool tw_method_limit(enum tw_method m)
{
    return m == TW_METHOD_ORACLE || m == TW_METHOD_BOX_ORACLE;
}

static uint32_t default_workers(void);

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
    if (s->max_screen_error == 0.0f)
        s->max_screen_error = 1.0f;
    if (s->evict_after_frames == 0)
        s->evict_after_frames = 60;
    if (s->workers == 0)
        s->workers = default_workers();
    if (s->upload_budget_bytes == 0)
        s->upload_budget_bytes = 32u << 20;
    if (!(s->upload_budget_ms > 0.0f))
        s->upload_budget_ms = 4.0f;
    if (s->shutdown_timeout_ms == 0)
        s->shutdown_timeout_ms = 5000;
    if (s->retry_after_frames == 0)
        s->retry_after_frames = 30;
    if (s->retry_max == 0)
        s->retry_max = 4;
    if (s->max_tile_triangles == 0)
        s->max_tile_triangles = TW_MAX_TILE_TRIANGLES;
    if (s->max_tile_bytes == 0) {
        s->max_tile_bytes = TW_MAX_TILE_BYTES;
        if (s->cache_budget_bytes && s->cache_budget_bytes / 4 < s->max_tile_bytes)
            s->max_tile_bytes = s->cache_budget_bytes / 4 ? s->cache_budget_bytes / 4 : 1;
    }
    if (!(s->verify_tolerance > 0.0f))
        s->verify_tolerance = TW_VERIFY_TOLERANCE;
}

void tw_world_default_tuning(struct tw_world_tuning *t)
{
    if (!t)
        return;
    tw_chc_default_settings(&t->chc);
    tw_tilequery_default_settings(&t->tilequery);
    tw_bvh_default_settings(&t->bvh);
    if (!(t->hlod_block_px > 0.0f) || !isfinite(t->hlod_block_px))
        t->hlod_block_px = TW_HLOD_BLOCK_PX;
}

/* The driver of method m (the oracles' timed parts draw a given set). */
static int create_driver(const struct tw_world *w, enum tw_method m, struct tw_cull_driver **out)
{
    static const enum tw_cull_method drivers[TW_METHOD_ALL] = {
        [TW_METHOD_VFC] = TW_CULL_VFC,
        [TW_METHOD_TILEQUERY] = TW_CULL_TILEQUERY,
        [TW_METHOD_CHC] = TW_CULL_CHC,
        [TW_METHOD_TILEQUERY_CHC] = TW_CULL_TILEQUERY_CHC,
        [TW_METHOD_ORACLE] = TW_CULL_GIVEN,
        [TW_METHOD_HZB] = TW_CULL_HZB,
        [TW_METHOD_TILEQUERY_HZB] = TW_CULL_TILEQUERY_HZB,
        [TW_METHOD_BOX_ORACLE] = TW_CULL_GIVEN,
    };
    const struct tw_cull_driver_settings ds = {
        .method = drivers[m],
        .evict_after_frames = w->s.evict_after_frames,
        .chc = w->t.chc,
        .tilequery = w->t.tilequery,
        .hzb_mutate_shrink = w->t.mutate_query_shrink,
    };
    return tw_cull_driver_create(&ds, out);
}

static uint32_t default_workers(void)
{
    const long cores = sysconf(_SC_NPROCESSORS_ONLN);
    return cores > 2 ? (uint32_t)(cores - 1) : 1u;
}

/* What is wrong with s's numbers, or NULL. */
static const char *out_of_range(const struct tw_world_settings *s, int methods)
{
    if (s->width > 16384 || s->height > 16384)
        return "the image is larger than 16384 pixels across";
    if (!isfinite(s->fov_y) || s->fov_y >= 179.0f)
        return "the field of view is not a finite angle below 179 degrees";
    if (!isfinite(s->view_distance) || !isfinite(s->near_plane))
        return "the view distance or the near plane is not a finite number";
    if (!isfinite(s->max_screen_error) || s->max_screen_error > 1000.0f)
        return "the max screen error is not a finite number of pixels up to 1000";
    if ((unsigned)s->method >= (unsigned)methods)
        return "the method is unknown";
    if (!s->host.draw && (s->host.prepare || s->host.prepare_worker || s->host.release))
        return "the host's prepare and release hooks are for host rendering: host.draw is "
               "not set";
    if (s->host.prepare_worker && !s->host.prepare)
        return "host.prepare_worker needs host.prepare, which takes what it made";
    if (s->host.draw && s->verify)
        return "host rendering draws into the host's framebuffer, and verify compares the "
               "world's own image: one or the other";
    if (!(s->verify_tolerance >= 0.0f && s->verify_tolerance < 1.0f))
        return "the verify tolerance is not in [0, 1)";
    if ((unsigned)s->policy > TW_STREAM_SKIP)
        return "the stream policy is unknown";
    if (s->workers > 256)
        return "more than 256 tile workers";
    if (!(s->upload_budget_ms >= 0.0f))
        return "the upload budget in milliseconds is negative or not a number";
    return NULL;
}

static int create(const struct tw_world_settings *settings, const struct tw_world_tuning *tuning,
                  int methods, struct tw_world **out);

/* A world without levels: none for any prototype. */
static const struct tw_lods no_lods;

/* The levels of detail of the shared prototypes (DESIGN §17): built once
 * for their tileset (the other worlds over it share them), their BVHs
 * built, uploaded and counted with the shared content. */
static int shared_levels(struct tw_world *w, const struct tw_tileset *ts)
{
    int err = tw_lods_of_tileset(ts, w->lods_store, &w->lods);
    if (err) {
        w->lods = &no_lods;
        tw_log_printf(&w->s.log, TW_LOG_ERROR, "cannot build the levels of detail of %s: %s",
                      ts->name, tw_error_to_str(err));
        return err;
    }
    const struct tw_tileset *levels = w->lods->levels;
    if (!levels)
        return TW_OK;   /* nothing simplifies */
    w->lod_bvhs = calloc(levels->prototype_count, sizeof(*w->lod_bvhs));
    struct tw_bvh_builder *builder = NULL;
    err = w->lod_bvhs ? tw_bvh_builder_create(&w->s.log, 0, &builder) : TW_ERR_NOMEM;
    if (!err)
        w->lod_count = levels->prototype_count;
    for (uint32_t k = 0; k < w->lod_count && !err; k++)
        err = tw_bvh_build(builder, &levels->prototypes[k], &w->t.bvh, &w->lod_bvhs[k]);
    tw_bvh_builder_destroy(builder);
    uint64_t gpu = 0;
    if (!err)
        err = tw_renderer_upload(w->renderer, levels, (const struct tw_bvh *const *)w->lod_bvhs,
                                 &w->lod_first, &gpu);
    w->shared_gpu += gpu;
    w->shared_cpu += tw_lods_bytes(w->lods);
    for (uint32_t k = 0; k < w->lod_count && !err; k++)
        w->shared_cpu += w->lod_bvhs[k]->bytes;
    for (uint32_t p = 0; p < ts->prototype_count && !err; p++) {
        tw_renderer_tag_levels(w->renderer, w->calibration_first + p,
                               w->lod_first + w->lods->first[p], w->lods->count[p]);
        if (w->lods->count[p] > 0)
            w->lod_least_error = fminf(w->lod_least_error, w->lods->error[w->lods->first[p]]);
    }
    return err;
}

/* ---- the thread contract ---------------------------------------------------------------- */

static void refuse(struct tw_world *w, const char *what, const char *why)
{
    /* A logger that calls into the world again is refused silently. */
    if (atomic_exchange(&w->refusing, true))
        return;
    tw_log_printf(&w->s.log, TW_LOG_ERROR, "cannot %s: %s", what, why);
    atomic_store(&w->refusing, false);
}

int tw_world_enter(struct tw_world *w, const char *what, bool gl)
{
    if (atomic_exchange_explicit(&w->busy, true, memory_order_acquire)) {
        refuse(w, what, "the world is in a call already: a callback (selection, provider, "
                        "logger) called into it, or a second thread did at the same time; a "
                        "world is used from one thread at a time, and never from its callbacks");
        return TW_ERR_STATE;
    }
    if (gl && !tw_renderer_current(w->renderer)) {
        atomic_store_explicit(&w->busy, false, memory_order_release);
        refuse(w, what, "the world's OpenGL context is not current on the calling thread "
                        "(make it current first; a world is used on the thread where its "
                        "context is current)");
        return TW_ERR_STATE;
    }
    if (gl)
        tw_renderer_enter(w->renderer);
    return TW_OK;
}

void tw_world_leave(struct tw_world *w, bool gl)
{
    if (gl)
        tw_renderer_leave(w->renderer);
    atomic_store_explicit(&w->busy, false, memory_order_release);
}

/* Host rendering: the renderer's batch as the host names it. */
static void host_draw(void *user, struct tw_cell cell, uint32_t content, const float offset[3],
                      const uint32_t *clusters, uint32_t count)
{
    const struct tw_world *w = user;
    struct tw_host_draw d = {.cell = cell, .clusters = clusters, .count = count};
    d.prototype = tw_renderer_content_base(w->renderer, content, &d.level);
    d.host_data = tw_renderer_host_data(w->renderer, content);
    memcpy(d.offset, offset, sizeof(d.offset));
    w->s.host.draw(w->s.host.user, &d);
}

/* Calls that need the world's own image, refused in host rendering. */
static int own_image(struct tw_world *w, const char *what)
{
    if (!w->s.host.draw)
        return TW_OK;
    tw_log_printf(&w->s.log, TW_LOG_ERROR, "cannot %s: the world draws into the host's "
                  "framebuffer (host rendering) and has no image of its own", what);
    return TW_ERR_STATE;
}

/* A host's world draws with a method; the tools' may draw a limit too. */
int tw_world_create(const struct tw_world_settings *settings, struct tw_world **out)
{
    return create(settings, NULL, TW_METHOD_COUNT, out);
}

int tw_world_create_tuned(const struct tw_world_settings *settings,
                          const struct tw_world_tuning *tuning, struct tw_world **out)
{
    return create(settings, tuning, TW_METHOD_ALL, out);
}

static int create(const struct tw_world_settings *settings, const struct tw_world_tuning *tuning,
                  int methods, struct tw_world **out)
{
    if (!settings || !out)
        return TW_ERR_INVALID;
    const struct tw_log *log = &settings->log;
    if (tuning && !(tuning->mutate_query_shrink >= 0.0f && tuning->mutate_query_shrink < 1.0f)) {
        tw_log_printf(log, TW_LOG_ERROR, "cannot create the world: the query shrink is not in [0, 1)");
        return TW_ERR_INVALID;
    }
    if (settings->provider && settings->tileset) {
        tw_log_printf(log, TW_LOG_ERROR, "cannot create the world: its settings give both a "
                      "tileset and a provider (one of them, not both)");
        return TW_ERR_INVALID;
    }
    if (!settings->provider && (!settings->tileset || !settings->tileset->finished)) {
        tw_log_printf(log, TW_LOG_ERROR, "cannot create the world: its settings give no tileset "
                      "or provider, or an unfinished tileset");
        return TW_ERR_INVALID;
    }
    if (!settings->get_proc) {
        tw_log_printf(log, TW_LOG_ERROR, "cannot create the world: its settings give no OpenGL "
                      "loader (get_proc)");
        return TW_ERR_INVALID;
    }
    const char *bad = out_of_range(settings, methods);
    if (bad) {
        tw_log_printf(log, TW_LOG_ERROR, "cannot create the world: %s", bad);
        return TW_ERR_INVALID;
    }
    struct tw_world *w = calloc(1, sizeof(*w));
    if (w)
        w->lods = &no_lods;
    if (!w) {
        tw_log_printf(log, TW_LOG_ERROR, "cannot create the world: out of memory");
        return TW_ERR_NOMEM;
    }
    w->s = *settings;
    tw_world_default_settings(&w->s);
    w->cur = w->last = &w->own;
    w->view_count = 1;
    w->lod_on = w->s.max_screen_error > 0.0f;
    if (w->lod_on && w->s.levels_cache_dir && w->s.levels_cache_dir[0]) {
        /* A store that cannot be made costs time, not the world. */
        char why[320];
        if (tw_lods_store(w->s.levels_cache_dir, w->s.levels_cache_bytes, &w->lods_store, why,
                          sizeof(why)) != TW_OK)
            tw_log_printf(log, TW_LOG_WARN, "levels of detail are built, not kept on disk: %s",
                          why);
    }
    w->lod_least_error = INFINITY;
    if (tuning)
        w->t = *tuning;
    tw_world_default_tuning(&w->t);
    int err = tw_world_resolve_provider(w);
    /* Every frame's cost is bounded: tile-query propagation may visit every
     * cell within reach, so the reach must stay within the per-frame limit. */
    if (!err && tw_world_hlod_wanted(w) < 2) {
        const double reach = tw_tiles_cells_in_reach(&w->provider.bound, w->provider.footprint[0],
                                                     w->provider.footprint[1], w->s.view_distance);
        if (!(reach <= TW_TILES_MAX_CELLS_IN_VIEW)) {
            tw_log_printf(log, TW_LOG_ERROR,
                          "cannot create the world: %s: a view distance of %g m over %g x %g "
                          "m tiles reaches about %.3g cells, more than the limit of %u a frame "
                          "may consider: shorten the view distance or use larger tiles",
                          w->provider.name ? w->provider.name : "the world",
                          (double)w->s.view_distance, (double)w->provider.footprint[0],
                          (double)w->provider.footprint[1], reach, TW_TILES_MAX_CELLS_IN_VIEW);
            err = TW_ERR_LIMIT;
        }
    }
    if (!err)
        err = tw_renderer_create(w->s.width, w->s.height, w->s.get_proc, &w->s.log, &w->renderer);
    if (err)
        goto fail;
    {
        /* In host rendering the depth is the host's: read back, built on the CPU. */
        const enum tw_hzb_pyramid hp = w->t.hzb_pyramid;
        const bool want = !w->s.host.draw &&
                          (hp == TW_HZB_PYRAMID_GPU ||
                           (hp == TW_HZB_PYRAMID_AUTO && !tw_renderer_software(w->renderer)));
        if (!tw_renderer_use_gpu_hzb(w->renderer, want) && hp == TW_HZB_PYRAMID_GPU)
            tw_log_printf(&w->s.log, TW_LOG_WARN, "the HZB's pyramid is built on the CPU: %s",
                          w->s.host.draw ? "in host rendering the depth is the host's"
                                         : "the GL context has no compute shaders (4.3)");
    }
    tw_renderer_enter(w->renderer);
    const struct tw_tileset *ts = w->provider.shared;
    if (ts) {
        w->shared_count = ts->prototype_count;
        w->bvhs = calloc(ts->prototype_count, sizeof(*w->bvhs));
        struct tw_bvh_builder *builder = NULL;
        err = w->bvhs ? tw_bvh_builder_create(&w->s.log, 0, &builder) : TW_ERR_NOMEM;
        for (uint32_t p = 0; p < ts->prototype_count && !err; p++)
            err = tw_bvh_build(builder, &ts->prototypes[p], &w->t.bvh, &w->bvhs[p]);
        tw_bvh_builder_destroy(builder);
        uint32_t first = 0;
        if (!err)
            err = tw_renderer_upload(w->renderer, ts, (const struct tw_bvh *const *)w->bvhs, &first,
                                     &w->shared_gpu);
        w->shared_cpu = tw_tileset_bytes(ts);
        for (uint32_t p = 0; p < ts->prototype_count && !err; p++)
            w->shared_cpu += w->bvhs[p]->bytes;
        w->calibration_first = first;
        if (!err && w->lod_on)
            err = shared_levels(w, ts);
    }
    /* What queries and draws cost here (DESIGN §14). */
    if (!err && w->t.calibration.query_ms > 0.0) {
        w->calibration = w->t.calibration;
        w->calibration.measured = false;
    } else if (!err && w->s.deterministic) {
        tw_calibrate_nominal(&w->calibration);
    } else if (!err) {
        err = tw_calibrate_measure(w->renderer, ts, w->calibration_first, w->s.width, w->s.height,
                                   w->s.fov_y, &w->calibration);
    }
    if (!err && w->provider.generate)
        err = tw_world_start_stream(w);
    if (!err)
        err = tw_world_hlod_start(w);
    if (!err)
        err = tw_objects_create(w);
    tw_renderer_leave(w->renderer);
    if (err)
        goto fail;
    w->grid = (struct tw_cull_grid){
        .footprint = {w->provider.footprint[0], w->provider.footprint[1]},
        .common_box = w->provider.bound,
        .source = {w, tw_world_get_tile, w->stream ? tw_world_prefetch_tile : NULL},
    };
    if (w->s.host.draw)
        tw_renderer_set_host(w->renderer,
                             &(struct tw_renderer_host){host_draw, w, w->s.host.clear,
                                                        w->s.host.prepare != NULL});
    tw_renderer_set_deterministic(w->renderer, w->s.deterministic);
    tw_renderer_set_count_samples(w->renderer, w->t.chc.threshold > 0 || w->t.tilequery.threshold > 0);
    tw_renderer_set_mutation(w->renderer, w->t.mutate_query_shrink);
    tw_gputime_init(&w->own.gputime, tw_renderer_gl(w->renderer));
    const struct tw_cull_driver_settings given = {.method = TW_CULL_GIVEN};
    err = tw_oracle_init(w);
    if (!err)
        err = tw_cull_driver_create(&given, &w->fixed_set);
    if (!err)
        err = tw_world_set_method_or_limit(w, w->s.method);
    if (err)
        goto fail;
    *out = w;
    return TW_OK;
fail:
    tw_world_destroy(w);
    return err;
}

/* Frees what a view holds; with gl, its GPU timers too (between enter and
 * leave). */
static void view_state_finish(struct tw_world *w, struct tw_view_state *vs, bool gl)
{
    for (int m = 0; m < TW_METHOD_ALL; m++)
        tw_cull_driver_destroy(vs->methods[m].driver);
    tw_cull_cells_finish(&vs->cells);
    tw_cull_cells_finish(&vs->ahead);
    if (gl)
        tw_gputime_finish(&vs->gputime);
    if (w->cur == vs)
        w->cur = &w->own;
    if (w->last == vs)
        w->last = &w->own;
}

struct tw_view_state *tw_world_next_view(struct tw_world *w, struct tw_viewport **k,
                                         bool *started)
{
    if (!*started) {
        *started = true;
        *k = w->viewports;
        return &w->own;
    }
    if (!*k)
        return NULL;
    struct tw_view_state *vs = &(*k)->state;
    *k = (*k)->next;
    return vs;
}

uint64_t tw_world_keep_from(const struct tw_world *w)
{
    return w->frame_serial + 1 > w->view_count ? w->frame_serial + 1 - w->view_count : 0;
}

/* ---- viewports ---------------------------------------------------------------------------- */

/* The streams count frames of every view: their frame counts stretch. */
static void views_changed(struct tw_world *w)
{
    if (w->stream)
        tw_stream_set_views(w->stream, w->view_count);
    for (uint32_t k = 1; k < w->hlod.count; k++)
        if (w->hlod.levels[k].stream)
            tw_stream_set_views(w->hlod.levels[k].stream, w->view_count);
}

int tw_viewport_create(struct tw_world *w, struct tw_viewport **out)
{
    if (!w || !out)
        return TW_ERR_INVALID;
    int err = tw_world_enter(w, "create a viewport", true);
    if (err)
        return err;
    struct tw_viewport *vp = calloc(1, sizeof(*vp));
    if (!vp) {
        tw_world_leave(w, true);
        return TW_ERR_NOMEM;
    }
    vp->w = w;
    tw_gputime_init(&vp->state.gputime, tw_renderer_gl(w->renderer));
    w->cur = &vp->state;
    err = tw_world_set_method_or_limit(w, w->own.method);
    w->cur = &w->own;
    if (err) {
        view_state_finish(w, &vp->state, true);
        free(vp);
        tw_world_leave(w, true);
        return err;
    }
    vp->next = w->viewports;
    w->viewports = vp;
    w->view_count++;
    views_changed(w);
    tw_world_leave(w, true);
    *out = vp;
    return TW_OK;
}

void tw_viewport_destroy(struct tw_viewport *vp)
{
    if (!vp)
        return;
    struct tw_world *w = vp->w;
    if (atomic_load(&w->busy)) {
        refuse(w, "destroy a viewport", "its world is in a call already (destroyed from one of "
                                        "its callbacks, or while another thread uses it): left "
                                        "as it is");
        return;
    }
    const bool gl = tw_renderer_current(w->renderer);
    if (gl)
        tw_renderer_enter(w->renderer);
    view_state_finish(w, &vp->state, gl);
    if (gl)
        tw_renderer_leave(w->renderer);
    for (struct tw_viewport **p = &w->viewports; *p; p = &(*p)->next)
        if (*p == vp) {
            *p = vp->next;
            break;
        }
    w->view_count--;
    views_changed(w);
    free(vp);
}

int tw_viewport_set_method(struct tw_viewport *vp, enum tw_method m)
{
    if (!vp || (unsigned)m >= TW_METHOD_COUNT)
        return TW_ERR_INVALID;
    return tw_viewport_set_method_or_limit(vp, m);
}

int tw_viewport_set_method_or_limit(struct tw_viewport *vp, enum tw_method m)
{
    if (!vp)
        return TW_ERR_INVALID;
    struct tw_world *w = vp->w;
    int err = tw_world_enter(w, "switch a viewport's culling method", true);
    if (err)
        return err;
    w->cur = &vp->state;
    err = tw_world_set_method_or_limit(w, m);
    w->cur = &w->own;
    tw_world_leave(w, true);
    return err;
}

static int frame(struct tw_world *w, const struct tw_camera *cam, struct tw_frame_stats *out);

int tw_viewport_frame(struct tw_viewport *vp, const struct tw_camera *cam,
                      struct tw_frame_stats *stats)
{
    if (!vp || !cam)
        return TW_ERR_INVALID;
    struct tw_world *w = vp->w;
    int err = tw_world_enter(w, "render a viewport's frame", true);
    if (err)
        return err;
    w->cur = &vp->state;
    err = frame(w, cam, stats);
    w->cur = &w->own;
    tw_world_leave(w, true);
    return err;
}

uint32_t tw_world_destroy(struct tw_world *w)
{
    if (!w)
        return 0;
    if (atomic_load(&w->busy)) {
        /* From a callback, inside a call on the world: freeing it would pull
         * the frame from under that call. */
        refuse(w, "destroy the world", "it is in a call already (destroyed from one of its "
                                       "callbacks, or while another thread uses it): left as "
                                       "it is");
        return 0;
    }
    uint32_t left_behind = 0;
    while (w->viewports)
        tw_viewport_destroy(w->viewports);
    view_state_finish(w, &w->own, false);
    tw_cull_driver_destroy(w->fixed_set);
    free(w->fixed_order);
    tw_oracle_finish(&w->oracle);
    tw_lod_image_finish(&w->lod_image);
    tw_debug_finish(w);
    if (w->renderer) {
        tw_renderer_enter(w->renderer);
        left_behind = tw_stream_destroy(w->stream) + tw_world_hlod_stop(w);
        tw_objects_destroy(w);
        tw_gputime_finish(&w->own.gputime);
        tw_renderer_leave(w->renderer);
        if (w->own.gputime.dropped)
            tw_log_printf(&w->s.log, TW_LOG_DEBUG,
                          "GPU time: the timers of %llu frames were not back when their entry "
                          "was reused (their GPU time unknown)",
                          (unsigned long long)w->own.gputime.dropped);
    }
    if (w->bvhs)
        for (uint32_t p = 0; p < w->shared_count; p++)
            tw_bvh_destroy(w->bvhs[p]);
    free(w->bvhs);
    for (uint32_t k = 0; w->lod_bvhs && k < w->lod_count; k++)
        tw_bvh_destroy(w->lod_bvhs[k]);
    free(w->lod_bvhs);
    free(w->drawn);
    free(w->events);
    free(w->next_events);
    tw_renderer_destroy(w->renderer);
    free(w);
    return left_behind;
}

int tw_world_set_method(struct tw_world *w, enum tw_method m)
{
    if (!w || (unsigned)m >= TW_METHOD_COUNT)
        return TW_ERR_INVALID;
    int err = tw_world_enter(w, "switch the culling method", true);
    if (err)
        return err;
    err = tw_world_set_method_or_limit(w, m);
    tw_world_leave(w, true);
    return err;
}

int tw_world_set_method_or_limit(struct tw_world *w, enum tw_method m)
{
    if (!w || (unsigned)m >= TW_METHOD_ALL)
        return TW_ERR_INVALID;
    m = tw_method_resolve(m);
    if (w->s.host.draw && tw_method_limit(m)) {
        tw_log_printf(&w->s.log, TW_LOG_ERROR, "cannot switch to %s: host rendering has no "
                      "oracles (their ID pass draws the world's own geometry)", tw_method_name(m));
        return TW_ERR_INVALID;
    }
    struct method_state *ms = &w->cur->methods[m];
    if (!ms->driver) {
        int err = create_driver(w, m, &ms->driver);
        if (err)
            return err;
    }
    w->cur->method = m;
    w->s.method = m;
    return TW_OK;
}

const struct tw_world_settings *tw_world_settings(const struct tw_world *w)
{
    return w ? &w->s : NULL;
}

const struct tw_bvh *tw_world_bvh(const struct tw_world *w, uint32_t p)
{
    return w && p < w->shared_count ? w->bvhs[p] : NULL;
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
    const float *fp = w->provider.footprint;
    struct tw_world_pos pos = cam->pos;
    int err = tw_tiles_normalize(&pos, fp[0], fp[1]);
    if (err) {
        tw_log_printf(&w->s.log, TW_LOG_ERROR, "camera position cannot be normalised");
        return err;
    }
    const struct tw_box *cb = &w->grid.common_box;
    const float diag = sqrtf((cb->max[0] - cb->min[0]) * (cb->max[0] - cb->min[0]) +
                             (cb->max[1] - cb->min[1]) * (cb->max[1] - cb->min[1]) +
                             (cb->max[2] - cb->min[2]) * (cb->max[2] - cb->min[2]));
    /* The far plane lies beyond anything within view distance, so that no
     * drawn tile is cut by it. */
    tw_cull_view_setup(v, pos.cell, pos.local, cam->yaw, cam->pitch, w->s.fov_y,
                       (float)w->s.width / (float)w->s.height, w->s.near_plane,
                       w->s.view_distance + diag);
    v->view_distance = w->s.view_distance;
    /* proj[5] = 1 / tan(fov_y / 2): the focal length in half-heights. */
    w->lod_px_per_m = 0.5f * v->proj[5] * (float)w->s.height;
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
    st->waits = rc->waits;
    st->flushes = rc->flushes;
    st->bytes_read_back = rc->bytes_read_back;
}

static int public_draws(struct tw_world *w);

static int frame(struct tw_world *w, const struct tw_camera *cam, struct tw_frame_stats *out)
{
    struct tw_view v;
    int err = tw_objects_apply(w);
    if (!err)
        err = setup_view(w, cam, &v);
    if (err)
        return err;
    struct method_state *ms = &w->cur->methods[w->cur->method];
    struct tw_frame_stats st = {0};
    w->last = w->cur;
    st.frame = ++ms->frame;
    st.method = w->cur->method;
    v.frame = st.frame;
    w->cur->last_view = v;
    w->cur->has_view = true;

    tw_world_hlod_begin_frame(w);
    const bool verify = w->s.verify;
    const unsigned debug = w->debug.flags;
    const bool recording = verify || w->record_draws || (debug & (TW_DEBUG_CELLS | TW_DEBUG_NODES));
    tw_renderer_record_draws(w->renderer, recording);
    if (debug)
        tw_renderer_record_queries(w->renderer, (debug & TW_DEBUG_QUERIES) != 0);
    w->frame_serial++;
    const bool oracle = tw_method_limit(w->cur->method);
    tw_gputime_begin(&w->cur->gputime, w->cur->method, st.frame);
    tw_gputime_late(&w->cur->gputime, w->cur->method, &st.gpu_late_frame, &st.gpu_late_ms);
    st.gpu_ms = -1.0;
    st.gpu_ms_id = oracle || verify ? -1.0 : 0.0;
    /* The full-detail image that the frame's is compared with: not the
     * method's work, before its clocks (GPU time included) start; none
     * where no cell in view can be drawn coarser (the image is then full
     * detail already). */
    bool lod_compare = false;
    if (verify && w->lod_on) {
        err = tw_world_levels_in_view(w, &v, &lod_compare);
        if (!err && lod_compare)
            err = tw_lod_image_full_pass(w, &v);
        if (err)
            return err;
    }
    double t0 = tw_clock_monotonic_ms(), cpu0 = tw_renderer_cpu_ms();
    if (!oracle)
        tw_gputime_mark(&w->cur->gputime, TW_GPUTIME_FRAME_BEGIN);
    if (w->stream)
        tw_stream_begin_frame(w->stream, w->frame_serial);
    if (oracle) {
        /* The ID pass (and the box test) is an oracle's knowledge, not its
         * work: untimed. */
        const double ts0 = tw_clock_monotonic_ms(), cs0 = tw_renderer_cpu_ms();
        const bool box = w->cur->method == TW_METHOD_BOX_ORACLE;
        tw_gputime_mark(&w->cur->gputime, TW_GPUTIME_ID_BEGIN);
        err = tw_oracle_pass(w, &v);
        if (!err && box)
            err = tw_oracle_box_set(w, &v);
        if (err)
            return err;
        tw_gputime_mark(&w->cur->gputime, TW_GPUTIME_ID_END);
        tw_cull_driver_give(ms->driver, box ? w->oracle.box_visible : w->oracle.visible,
                            box ? w->oracle.box_visible_count : w->oracle.visible_count);
        t0 += tw_clock_monotonic_ms() - ts0;
        cpu0 += tw_renderer_cpu_ms() - cs0;
        tw_gputime_mark(&w->cur->gputime, TW_GPUTIME_FRAME_BEGIN);
    }
    struct tw_cost_model costs;
    tw_calibrate_model(&w->calibration, w->s.width, w->s.height, &costs);
    tw_cull_driver_set_costs(ms->driver, &costs);
    tw_renderer_begin_frame(w->renderer, &v);
    const struct tw_query_backend be = tw_renderer_backend(w->renderer);
    struct tw_cull_frame_stats cs = {0};
    err = tw_cull_driver_frame(ms->driver, &v, &w->grid, &be, &w->cur->cells, &cs);
    const double t1 = tw_clock_monotonic_ms();
    tw_gputime_mark(&w->cur->gputime, TW_GPUTIME_FRAME_END);
    tw_renderer_end_frame(w->renderer);
    st.tiles_queried = cs.tiles_queried;
    st.tiles_visible = cs.tiles_visible;
    st.tiles_new = cs.tiles_new;
    st.tiles_cached = cs.tiles_cached;
    st.cache_bytes = cs.cache_bytes;
    st.predict_fail = cs.predict_fail;
    st.tiles_pending = cs.tiles_pending;
    st.queries_skipped = cs.queries_skipped;
    st.hzb_boxes = cs.hzb_boxes;
    st.ms_hzb_build = cs.ms_hzb_build;
    st.ms_hzb_read = cs.ms_hzb_read;
    st.tiles_late = cs.tiles_late;
    st.hzb_lag = cs.hzb_results_lag;
    if (err)
        return err;
    if (w->stream)
        tw_world_look_ahead(w, &v);
    collect_counters(w, &st);
    st.ms_cull = (t1 - t0) - tw_renderer_counters(w->renderer)->ms_backend;
    if (st.ms_cull < 0.0)
        st.ms_cull = 0.0;
    st.ms_frame = tw_clock_monotonic_ms() - t0;
    st.cpu_ms = tw_renderer_cpu_ms() - cpu0;

    if (verify) {
        /* The frame's time ends where the GPU is done with it; the ID pass
         * after it is not the method's work. */
        tw_renderer_finish(w->renderer);
        st.ms_frame = tw_clock_monotonic_ms() - t0;
        st.cpu_ms = tw_renderer_cpu_ms() - cpu0;
        if (lod_compare)
            err = tw_lod_image_compare(w, &v, &st);
        if (!err && !oracle) {
            tw_gputime_mark(&w->cur->gputime, TW_GPUTIME_ID_BEGIN);
            err = tw_oracle_pass(w, &v);
            tw_gputime_mark(&w->cur->gputime, TW_GPUTIME_ID_END);
        }
        if (err)
            return err;
        tw_oracle_compare(w, &st);
    }
    if (w->lod_on && recording) {
        err = public_draws(w);
        if (err)
            return err;
    }
    if (debug) {
        err = tw_debug_collect(w, ms, &v);
        if (err)
            return err;
    }
    tw_world_keep_budget(w, ms, &st);
    tw_objects_stats(w, &st);
    st.ms_frame += st.ms_objects;   /* the moves placed before the frame's clock started */
    st.ms_cull += st.ms_objects;
    /* The events of this frame (and of invalidations since the last one). */
    struct tw_tile_event *e = w->events;
    w->events = w->next_events;
    w->event_count = w->next_event_count;
    w->next_events = e;
    const size_t cap = w->event_cap;
    w->event_cap = w->next_event_cap;
    w->next_event_cap = cap;
    w->next_event_count = 0;
    if (out)
        *out = st;
    return TW_OK;
}

int tw_world_frame(struct tw_world *w, const struct tw_camera *cam, struct tw_frame_stats *out)
{
    if (!w || !cam)
        return TW_ERR_INVALID;
    int err = tw_world_enter(w, "render a frame", true);
    if (err)
        return err;
    err = frame(w, cam, out);
    tw_world_leave(w, true);
    return err;
}

int tw_world_finish(struct tw_world *w, struct tw_frame_stats *st)
{
    if (!w)
        return TW_ERR_INVALID;
    const int err = tw_world_enter(w, "finish the frame", true);
    if (err)
        return err;
    const double t0 = tw_clock_monotonic_ms(), cpu0 = tw_renderer_cpu_ms();
    tw_renderer_finish(w->renderer);
    if (st) {
        st->ms_frame += tw_clock_monotonic_ms() - t0;
        st->cpu_ms += tw_renderer_cpu_ms() - cpu0;
        /* After glFinish the timers are back: reading them waits no more. */
        tw_gputime_current(&w->last->gputime, &st->gpu_ms, &st->gpu_ms_id);
    }
    tw_world_leave(w, true);
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
    int err = own_image(w, "read the image");
    if (!err)
        err = tw_world_enter(w, "read the image", true);
    if (err)
        return err;
    err = tw_renderer_read_rgb(w->renderer, rgb);
    tw_world_leave(w, true);
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
    if (!w->lod_on)
        return tw_renderer_drawn(w->renderer, count);
    *count = w->drawn_count;
    return w->drawn;
}

const struct tw_prototype *tw_world_level(const struct tw_world *w, uint32_t prototype,
                                          uint32_t level, const struct tw_tileset **ts)
{
    if (!w)
        return NULL;
    const uint32_t content = tw_renderer_level_content(w->renderer, prototype, level);
    const struct tw_prototype *p = tw_renderer_content(w->renderer, content, NULL);
    if (ts)
        *ts = p ? tw_renderer_content_tileset(w->renderer, content) : NULL;
    return p;
}

/* The frame's recorded draws as a host reads them: each content named by
 * its full-detail content and the level drawn. */
static int public_draws(struct tw_world *w)
{
    size_t n;
    const struct tw_drawn_cluster *d = tw_renderer_drawn(w->renderer, &n);
    w->drawn_count = 0;
    if (tw_array_reserve((void **)&w->drawn, &w->drawn_cap, n, sizeof(*w->drawn), 256))
        return TW_ERR_NOMEM;
    for (size_t k = 0; k < n; k++) {
        w->drawn[k] = d[k];
        w->drawn[k].prototype = tw_renderer_content_base(w->renderer, d[k].prototype,
                                                         &w->drawn[k].level);
    }
    w->drawn_count = n;
    return TW_OK;
}

int tw_world_last_view(const struct tw_world *w, struct tw_world_view *out)
{
    if (!w || !out)
        return TW_ERR_INVALID;
    if (!w->last->has_view)
        return TW_ERR_STATE;
    const struct tw_view *v = &w->last->last_view;
    *out = (struct tw_world_view){
        .cell = v->cell,
        .near_plane = v->near_plane,
        .far_plane = v->far_plane,
        .frame = v->frame,
    };
    memcpy(out->eye, v->eye, sizeof(out->eye));
    memcpy(out->view, v->view, sizeof(out->view));
    memcpy(out->proj, v->proj, sizeof(out->proj));
    memcpy(out->proj_rz, v->proj_rz, sizeof(out->proj_rz));
    memcpy(out->view_proj, v->view_proj, sizeof(out->view_proj));
    memcpy(out->view_proj_rz, v->view_proj_rz, sizeof(out->view_proj_rz));
    return TW_OK;
}

const struct tw_world_tuning *tw_world_tuning(const struct tw_world *w)
{
    return w ? &w->t : NULL;
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
    for (size_t k = 0; k < count; k++) {
        const uint32_t content =
            tw_renderer_level_content(w->renderer, clusters[k].prototype, clusters[k].level);
        const struct tw_prototype *proto = tw_renderer_content(w->renderer, content, NULL);
        if (!proto || clusters[k].cluster >= proto->cluster_count) {
            tw_log_printf(&w->s.log, TW_LOG_ERROR,
                          "cannot draw the given set: its entry %zu names no cluster of the "
                          "tileset", k);
            return TW_ERR_INVALID;
        }
    }
    struct tw_frame_stats st = {0};
    w->last = w->cur;
    st.frame = w->cur->methods[w->cur->method].frame;
    st.method = w->cur->method;
    st.gpu_ms = st.gpu_late_ms = -1.0;
    tw_gputime_forget(&w->cur->gputime);
    v.frame = st.frame;
    w->cur->last_view = v;
    w->cur->has_view = true;
    /* Drawn tile by tile (one run of draws each, as the oracle draws its
     * set), each tile's clusters in the order given. */
    err = tw_array_reserve((void **)&w->fixed_order, &w->fixed_order_cap, count,
                           sizeof(*w->fixed_order), 256);
    if (!err && count) {
        /* Each level by its own content, as the backend draws it. */
        for (size_t k = 0; k < count; k++) {
            w->fixed_order[k] = clusters[k];
            w->fixed_order[k].prototype =
                tw_renderer_level_content(w->renderer, clusters[k].prototype, clusters[k].level);
            w->fixed_order[k].level = 0;
        }
        err = tw_oracle_order(w, &v, w->fixed_order, count, false);
    }
    if (err)
        return err;
    tw_renderer_record_draws(w->renderer, false);
    tw_renderer_record_queries(w->renderer, false);
    const double t0 = tw_clock_monotonic_ms(), cpu0 = tw_renderer_cpu_ms();
    tw_renderer_begin_frame(w->renderer, &v);
    const struct tw_query_backend be = tw_renderer_backend(w->renderer);
    struct tw_cull_frame_stats cs = {0};
    tw_cull_driver_give(w->fixed_set, w->fixed_order, count);
    err = tw_cull_driver_frame(w->fixed_set, &v, &w->grid, &be, &w->cur->cells, &cs);
    tw_cull_driver_give(w->fixed_set, NULL, 0);
    tw_renderer_end_frame(w->renderer);
    if (err)
        return err;
    collect_counters(w, &st);
    st.tiles_visible = cs.tiles_visible;
    st.ms_frame = tw_clock_monotonic_ms() - t0;
    st.cpu_ms = tw_renderer_cpu_ms() - cpu0;
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
    int err = tw_world_enter(w, "draw the given set", true);
    if (err)
        return err;
    err = frame_fixed(w, cam, clusters, count, out);
    tw_world_leave(w, true);
    return err;
}

int tw_world_blit_depth(struct tw_world *w, uint32_t target)
{
    if (!w)
        return TW_ERR_INVALID;
    int err = own_image(w, "copy the depth");
    if (!err && !w->last->has_view) {
        tw_log_printf(&w->s.log, TW_LOG_ERROR, "cannot copy the depth: no frame has been "
                      "rendered yet");
        err = TW_ERR_STATE;
    }
    if (!err)
        err = tw_world_enter(w, "copy the depth", true);
    if (err)
        return err;
    err = tw_renderer_blit_depth(w->renderer, target);
    tw_world_leave(w, true);
    return err;
}

uint32_t tw_world_depth_format(const struct tw_world *w)
{
    return w ? tw_renderer_depth_format(w->renderer) : 0;
}

int tw_world_blit(struct tw_world *w, uint32_t target, uint32_t width, uint32_t height)
{
    if (!w || width == 0 || height == 0 || width > 16384 || height > 16384)
        return TW_ERR_INVALID;
    int err = own_image(w, "copy the image");
    if (!err)
        err = tw_world_enter(w, "copy the image", true);
    if (err)
        return err;
    tw_renderer_blit(w->renderer, target, width, height);
    tw_world_leave(w, true);
    return TW_OK;
}
