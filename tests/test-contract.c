/*
 * The thread contract, as a host that breaks it sees it (runtime.h,
 * "Threading"; README "Threads and callbacks"): a call from a thread
 * without the world's context current, with another context current, from
 * a second thread during a frame, or from the world's own callbacks
 * (selection, provider, logger) is refused with TW_ERR_STATE and one logged
 * line, and the world goes on as if it had not been made; a world moves to
 * another thread with its context; NULL arguments are TW_ERR_INVALID; a
 * world destroyed without its context frees its memory.
 */
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tests/captured-log.h"
#include "tests/check.h"
#include "tests/meshes.h"
#include "tileworld/context.h"
#include "tileworld/runtime.h"
#include "tileworld/tilesets.h"

enum { W = 160, H = 90 };

/* Errors logged since *mark, and whether the last one holds what. */
static bool logged(struct log_lines *l, unsigned *mark, unsigned expect, const char *what)
{
    pthread_mutex_lock(&l->lock);
    const bool ok = l->errors - *mark == expect && (!what || strstr(l->last, what));
    if (!ok)
        fprintf(stderr, "logged %u errors (expected %u), last: %s\n", l->errors - *mark, expect,
                l->last);
    *mark = l->errors;
    pthread_mutex_unlock(&l->lock);
    return ok;
}

static const struct tw_camera cam = {{{0, 0}, {2.0f, 1.7f, 2.0f}}, 30.0f, 2.0f};

/* ---- a call from another thread ------------------------------------------------------- */

struct other_thread {
    struct tw_world *w;
    struct tw_context *ctx;     /* made current there first, when not NULL */
    int frame, read, invalidate, finish, method;
    int current;
};

static void *call_from_other(void *arg)
{
    struct other_thread *o = arg;
    static uint8_t rgb[W * H * 3];
    o->current = o->ctx ? tw_context_make_current(o->ctx) : TW_OK;
    o->frame = tw_world_frame(o->w, &cam, NULL);
    o->read = tw_world_read_rgb(o->w, rgb);
    o->invalidate = tw_world_invalidate(o->w, (struct tw_cell){0, 0});
    o->finish = tw_world_finish(o->w, NULL);
    o->method = tw_world_set_method(o->w, TW_METHOD_VFC);
    if (o->ctx)
        tw_context_release(o->ctx);
    return NULL;
}

static struct other_thread run_other(struct tw_world *w, struct tw_context *ctx)
{
    struct other_thread o = {.w = w, .ctx = ctx};
    pthread_t t;
    if (pthread_create(&t, NULL, call_from_other, &o) == 0)
        pthread_join(t, NULL);
    else
        o.frame = o.read = o.invalidate = o.finish = o.method = o.current = -100;
    return o;
}

/* ---- callbacks that call into the world ----------------------------------------------- */

struct reentry {
    _Atomic(struct tw_world *) w;
    atomic_int frame, invalidate, destroy, set_method, calls;
    atomic_int in_generate;     /* provider: the result of a call from generate() */
    bool on;
};

static uint32_t select_reentering(void *user, struct tw_cell cell)
{
    struct reentry *r = user;
    struct tw_world *w = atomic_load(&r->w);
    if (r->on && w && atomic_fetch_add(&r->calls, 1) == 0) {
        atomic_store(&r->frame, tw_world_frame(w, &cam, NULL));
        atomic_store(&r->invalidate, tw_world_invalidate(w, cell));
        atomic_store(&r->set_method, tw_world_set_method(w, TW_METHOD_VFC));
        const uint32_t left = tw_world_destroy(w);   /* refused: the world stays */
        atomic_store(&r->destroy, (int)left);
    }
    return (uint32_t)(((uint64_t)cell.i ^ (uint64_t)cell.j) & 1u);
}

static int generate_reentering(void *user, struct tw_cell cell, struct tw_tileset *ts)
{
    struct reentry *r = user;
    struct tw_world *w = atomic_load(&r->w);
    if (w && atomic_fetch_add(&r->calls, 1) == 0)
        atomic_store(&r->in_generate, tw_world_invalidate(w, cell));
    const int mat = tw_tileset_add_material(ts, (const float[4]){0.6f, 0.5f, 0.4f, 1.0f});
    const int cube = add_cube(ts);
    const int proto = tw_tileset_add_prototype(ts, "cube", 1.0f);
    const float t[12] = {10, 0, 0, 5, 0, 8, 0, 0, 0, 0, 10, 5};
    if (mat < 0 || cube < 0 || proto < 0 ||
        tw_tileset_add_instance(ts, (uint32_t)proto, (uint32_t)cube, (uint32_t)mat, t) < 0)
        return TW_ERR_NOMEM;
    return TW_OK;
}

/* A logger that calls into the world on every error: the refusal it is told
 * of must not log again (no recursion) nor go through. */
struct reentering_log {
    struct tw_world *w;
    unsigned lines;
    int inner;
};

static void log_reentering(void *user, enum tw_log_level level, const char *msg)
{
    (void)msg;
    struct reentering_log *l = user;
    if (level != TW_LOG_ERROR)
        return;
    l->lines++;
    if (l->w && l->lines < 100)
        l->inner = tw_world_frame(l->w, &cam, NULL);
}

static void host_draw_nothing(void *user, const struct tw_host_draw *batch)
{
    (void)user;
    (void)batch;
}

/* ---- NULL everywhere ------------------------------------------------------------------ */

static void null_arguments(struct tw_world *w)
{
    struct tw_frame_stats st;
    struct tw_cache_totals totals;
    struct tw_world_view view;
    size_t count = 7;
    uint8_t rgb[3];
    CHECK(tw_world_create(NULL, NULL) == TW_ERR_INVALID);
    CHECK(tw_world_destroy(NULL) == 0);
    CHECK(tw_world_frame(NULL, &cam, &st) == TW_ERR_INVALID);
    CHECK(tw_world_frame(w, NULL, &st) == TW_ERR_INVALID);
    CHECK(tw_world_finish(NULL, &st) == TW_ERR_INVALID);
    CHECK(tw_world_read_rgb(NULL, rgb) == TW_ERR_INVALID);
    CHECK(tw_world_read_rgb(w, NULL) == TW_ERR_INVALID);
    CHECK(tw_world_set_method(NULL, TW_METHOD_VFC) == TW_ERR_INVALID);
    CHECK(tw_world_cache_totals(NULL, &totals) == TW_ERR_INVALID);
    CHECK(tw_world_cache_totals(w, NULL) == TW_ERR_INVALID);
    CHECK(tw_world_tile_events(NULL, &count) == NULL && count == 0);
    count = 7;
    CHECK(tw_world_tile_events(w, NULL) == NULL);
    CHECK(tw_world_invalidate(NULL, (struct tw_cell){0, 0}) == TW_ERR_INVALID);
    CHECK(tw_world_invalidate_rect(NULL, (struct tw_cell){0, 0}, (struct tw_cell){1, 1}) ==
          TW_ERR_INVALID);
    CHECK(tw_world_last_view(NULL, &view) == TW_ERR_INVALID);
    CHECK(tw_world_last_view(w, NULL) == TW_ERR_INVALID);
    CHECK(!tw_world_reversed_z(NULL));
    tw_world_record_draws(NULL, true);
    CHECK(tw_world_drawn(NULL, &count) == NULL && count == 0);
    CHECK(tw_world_level(NULL, 0, 0, NULL) == NULL);
    CHECK(tw_world_settings(NULL) == NULL);
    CHECK(tw_world_set_debug(NULL, 0) == TW_ERR_INVALID);
    count = 7;
    CHECK(tw_world_debug_boxes(NULL, &count) == NULL && count == 0);
    CHECK(tw_world_draw_debug(NULL, NULL, 0) == TW_ERR_INVALID);
    CHECK(tw_world_draw_debug(w, NULL, 3) == TW_ERR_INVALID);
    CHECK(tw_world_blit(NULL, 0, 4, 4) == TW_ERR_INVALID);
    CHECK(tw_context_make_current(NULL) == TW_ERR_INVALID);
    CHECK(tw_context_release(NULL) == TW_ERR_INVALID);
    CHECK(tw_context_get_proc(NULL) == NULL);
    struct tw_context_info info;
    tw_context_describe(NULL, &info);
    CHECK(info.kind == NULL && info.device_index == -1);
    tw_context_describe(NULL, NULL);
    tw_context_destroy(NULL);
    CHECK(tw_context_create(NULL, NULL) == TW_ERR_INVALID);
    CHECK(tw_method_from_name(NULL, NULL) == TW_ERR_INVALID);
    CHECK(tw_tiles_normalize(NULL, 1.0f, 1.0f) == TW_ERR_INVALID);
    CHECK(tw_tileset_create(NULL, 1.0f, 1.0f, NULL) == TW_ERR_INVALID);
    CHECK(tw_tileset_add_material(NULL, NULL) < 0);
    CHECK(tw_tileset_add_mesh(NULL, NULL, NULL, 0, NULL, 0) < 0);
    CHECK(tw_tileset_add_prototype(NULL, NULL, 1.0f) < 0);
    CHECK(tw_tileset_add_instance(NULL, 0, 0, 0, NULL) < 0);
    CHECK(tw_tileset_finish(NULL, 0) == TW_ERR_INVALID);
    CHECK(tw_tileset_bytes(NULL) == 0);
    tw_tileset_destroy(NULL);
    CHECK(tw_path_builtin(NULL, 0, 1, 0.0f, 1.0f, 1.0f, NULL) == TW_ERR_INVALID);
    CHECK(tw_path_load_csv(NULL, 0, 1.0f, 1.0f, NULL, NULL, 0) == TW_ERR_INVALID);
    CHECK(tw_path_parse_csv(NULL, 0, NULL, 0, 1.0f, 1.0f, NULL, NULL, 0) == TW_ERR_INVALID);
    tw_path_finish(NULL);
    CHECK(tw_tilesets_builtin(NULL, 0, 0, NULL, NULL) == TW_ERR_INVALID);
    CHECK(tw_tilesets_city(0, NULL, NULL, NULL) == TW_ERR_INVALID);
    CHECK(tw_tilesets_forest(0, NULL, NULL, NULL) == TW_ERR_INVALID);
    tw_tilesets_city_default_settings(NULL);
    tw_tilesets_forest_default_settings(NULL);
    tw_gltf_default_settings(NULL);
    tw_world_default_settings(NULL);
    CHECK(tw_tilesets_provider_create(NULL, 0, 0, NULL, NULL) == TW_ERR_INVALID);
    CHECK(tw_tilesets_provider_get(NULL) == NULL);
    tw_tilesets_provider_destroy(NULL);
    CHECK(tw_gltf_import(NULL, NULL, NULL, NULL) == TW_ERR_INVALID);
    CHECK(tw_gltf_import_memory(NULL, 0, NULL, NULL, NULL, NULL, NULL) == TW_ERR_INVALID);
    CHECK(tw_gltf_bind(NULL, NULL, NULL) == TW_ERR_INVALID);
    CHECK(tw_gltf_place(NULL, NULL, NULL, 0, NULL) == TW_ERR_INVALID);
    tw_gltf_scene_destroy(NULL);
    CHECK(tw_tilesets_load_manifest(NULL, NULL, NULL, NULL) == TW_ERR_INVALID);
    CHECK(tw_tilesets_parse_manifest(NULL, 0, NULL, NULL, NULL, NULL, NULL) == TW_ERR_INVALID);
    /* Moving objects, traffic, the 3D Tiles provider. */
    const struct tw_object car = {.model = 0};
    uint32_t id = 0;
    CHECK(tw_world_object_add(NULL, &car, &id) == TW_ERR_INVALID);
    CHECK(tw_world_object_add(w, NULL, &id) == TW_ERR_INVALID);
    CHECK(tw_world_object_add(w, &car, NULL) == TW_ERR_INVALID);
    CHECK(tw_world_object_update(NULL, 0, &car) == TW_ERR_INVALID);
    CHECK(tw_world_object_update(w, 0, NULL) == TW_ERR_INVALID);
    CHECK(tw_world_object_remove(NULL, 0) == TW_ERR_INVALID);
    CHECK(tw_tilesets_car_models(NULL, NULL) == TW_ERR_INVALID);
    tw_traffic_default_settings(NULL);
    CHECK(tw_traffic_init(NULL, NULL, NULL) == TW_ERR_INVALID);
    CHECK(tw_traffic_place(NULL, 0, 0.0, NULL) == TW_ERR_INVALID);
    tw_tiles3d_default_settings(NULL);
    CHECK(tw_tiles3d_provider_create(NULL, NULL, NULL, NULL) == TW_ERR_INVALID);
    CHECK(tw_tiles3d_provider_get(NULL) == NULL);
    tw_tiles3d_provider_stats(NULL, NULL);
    tw_tiles3d_provider_destroy(NULL);
    CHECK(tw_method_name((enum tw_method)99) != NULL);
    CHECK(tw_error_to_str(12345) != NULL);
    CHECK(tw_context_api_name((enum tw_context_api)99) == NULL);
    CHECK(tw_context_create_headless(0, 0, NULL, NULL) == TW_ERR_INVALID);
}

int main(void)
{
    struct log_lines lines = {.lock = PTHREAD_MUTEX_INITIALIZER};
    const struct tw_log log = {log_line, &lines};
    unsigned mark = 0;
    struct tw_context *ctx = NULL, *other = NULL;
    struct tw_tileset *ts = NULL;
    if (tw_context_create_headless(W, H, &log, &ctx) != TW_OK ||
        tw_context_create_headless(W, H, &log, &other) != TW_OK) {
        fprintf(stderr, "cannot create two headless contexts\n");
        return 1;
    }
    CHECK(tw_context_make_current(ctx) == TW_OK);
    if (tw_tilesets_builtin("city", 1, 0, &log, &ts) != TW_OK)
        return 1;
    struct reentry re = {0};
    struct tw_world_settings s = {0};
    s.tileset = ts;
    s.selection.fn = select_reentering;
    s.selection.user = &re;
    s.width = W;
    s.height = H;
    s.view_distance = 200.0f;
    s.deterministic = true;
    s.get_proc = tw_context_get_proc(ctx);
    s.log = log;
    struct tw_world *w = NULL;
    CHECK(tw_world_create(&s, &w) == TW_OK);
    if (!w)
        return check_summary("test-contract");
    atomic_store(&re.w, w);
    mark = lines.errors;

    /* A reference image, with the contract kept. */
    static uint8_t ref[W * H * 3], img[W * H * 3];
    CHECK(tw_world_frame(w, &cam, NULL) == TW_OK);
    CHECK(tw_world_read_rgb(w, ref) == TW_OK);
    CHECK(logged(&lines, &mark, 0, NULL));

    /* A second thread without a context: every call refused, one line each. */
    struct other_thread o = run_other(w, NULL);
    CHECK_MSG(o.frame == TW_ERR_STATE && o.read == TW_ERR_STATE && o.invalidate == TW_ERR_STATE &&
                  o.finish == TW_ERR_STATE && o.method == TW_ERR_STATE,
              "%d %d %d %d %d", o.frame, o.read, o.invalidate, o.finish, o.method);
    CHECK(logged(&lines, &mark, 5, "not current on the calling thread"));

    /* This thread with another context current: refused too. */
    CHECK(tw_context_make_current(other) == TW_OK);
    CHECK(tw_world_frame(w, &cam, NULL) == TW_ERR_STATE);
    CHECK(tw_world_read_rgb(w, img) == TW_ERR_STATE);
    CHECK(logged(&lines, &mark, 2, "cannot read the image: the world's OpenGL context is not"));
    /* And with none current. */
    CHECK(tw_context_release(other) == TW_OK);
    CHECK(tw_world_frame(w, &cam, NULL) == TW_ERR_STATE);
    CHECK(logged(&lines, &mark, 1, "cannot render a frame"));

    /* The world moves to another thread with its context, and back. */
    CHECK(tw_context_make_current(ctx) == TW_OK);
    CHECK(tw_context_release(ctx) == TW_OK);
    o = run_other(w, ctx);
    CHECK_MSG(o.current == TW_OK && o.frame == TW_OK && o.read == TW_OK &&
                  o.invalidate == TW_OK && o.finish == TW_OK && o.method == TW_OK,
              "%d %d %d %d %d %d", o.current, o.frame, o.read, o.invalidate, o.finish, o.method);
    CHECK(logged(&lines, &mark, 0, NULL));
    CHECK(tw_context_make_current(ctx) == TW_OK);
    CHECK(tw_world_set_method(w, TW_METHOD_DEFAULT) == TW_OK);

    /* The selection re-enters the world: each inner call refused, the outer
     * frame whole and the same as before. */
    re.on = true;
    CHECK(tw_world_invalidate_rect(w, (struct tw_cell){-100, -100}, (struct tw_cell){100, 100}) ==
          TW_OK);
    CHECK(tw_world_frame(w, &cam, NULL) == TW_OK);
    re.on = false;
    CHECK(atomic_load(&re.calls) >= 1);
    CHECK_MSG(atomic_load(&re.frame) == TW_ERR_STATE && atomic_load(&re.invalidate) == TW_ERR_STATE &&
                  atomic_load(&re.set_method) == TW_ERR_STATE && atomic_load(&re.destroy) == 0,
              "%d %d %d %d", atomic_load(&re.frame), atomic_load(&re.invalidate),
              atomic_load(&re.set_method), atomic_load(&re.destroy));
    CHECK(logged(&lines, &mark, 4, "cannot destroy the world: it is in a call already"));
    CHECK(tw_world_read_rgb(w, img) == TW_OK);
    CHECK(memcmp(img, ref, sizeof(img)) == 0);

    null_arguments(w);
    logged(&lines, &mark, lines.errors - mark, NULL);   /* what the NULL calls logged */

    /* A logger that re-enters on the refusal it is told of. */
    struct reentering_log rl = {.w = w};
    struct tw_world_settings s2 = s;
    s2.selection = (struct tw_selection){.seed = 3};
    s2.log = (struct tw_log){log_reentering, &rl};
    struct tw_world *w2 = NULL;
    CHECK(tw_world_create(&s2, &w2) == TW_OK);
    rl.w = w2;
    CHECK(tw_context_release(ctx) == TW_OK);
    CHECK(tw_world_frame(w2, &cam, NULL) == TW_ERR_STATE);
    CHECK_MSG(rl.lines == 1 && rl.inner == TW_ERR_STATE, "%u lines, inner %d", rl.lines, rl.inner);
    /* Destroyed without its context: memory freed (the leak checker sees
     * it), a warning, not an error. */
    CHECK(tw_world_destroy(w2) == 0);
    CHECK(rl.lines == 1);
    CHECK(tw_context_make_current(ctx) == TW_OK);

    /* A provider's generate(), on a worker or on this thread inside the
     * frame, that calls into the world: refused either way. */
    struct reentry pre = {0};
    const struct tw_tile_provider provider = {
        .name = "reentering",
        .footprint = {20.0f, 20.0f},
        .bound = {{0.0f, 0.0f, 0.0f}, {20.0f, 10.0f, 20.0f}},
        .generate = generate_reentering,
        .user = &pre,
    };
    struct tw_world_settings s3 = s;
    s3.tileset = NULL;
    s3.selection = (struct tw_selection){0};
    s3.provider = &provider;
    s3.workers = 2;
    struct tw_world *w3 = NULL;
    CHECK(tw_world_create(&s3, &w3) == TW_OK);
    atomic_store(&pre.w, w3);
    struct tw_frame_stats st;
    CHECK(tw_world_frame(w3, &cam, &st) == TW_OK);
    CHECK(st.tiles_visible > 0);
    CHECK(atomic_load(&pre.in_generate) == TW_ERR_STATE);
    CHECK(logged(&lines, &mark, 1, "cannot invalidate cells"));
    CHECK(tw_world_destroy(w3) == 0);

    /* Host rendering: no image of the world's own, no verify, no HZB. */
    struct tw_world_settings s4 = s;
    s4.selection = (struct tw_selection){0};
    s4.host.draw = host_draw_nothing;
    s4.verify = true;
    struct tw_world *w4 = NULL;
    CHECK(tw_world_create(&s4, &w4) == TW_ERR_INVALID && !w4);
    CHECK(logged(&lines, &mark, 1, "host rendering draws into the host's framebuffer"));
    s4.verify = false;
    CHECK(tw_world_create(&s4, &w4) == TW_OK);
    if (w4) {
        CHECK(tw_world_frame(w4, &cam, NULL) == TW_OK);
        CHECK(tw_world_read_rgb(w4, img) == TW_ERR_STATE);
        CHECK(tw_world_blit(w4, 0, W, H) == TW_ERR_STATE);
        CHECK(tw_world_set_method(w4, TW_METHOD_HZB) == TW_OK);
        CHECK(tw_world_frame(w4, &cam, NULL) == TW_OK);
        CHECK(tw_world_set_method(w4, TW_METHOD_CHC) == TW_OK);
        CHECK(logged(&lines, &mark, 2, "has no image of its own"));
        tw_world_destroy(w4);
    }

    CHECK(tw_world_destroy(w) == 0);
    tw_tileset_destroy(ts);
    tw_context_destroy(other);
    tw_context_destroy(ctx);
    return check_summary("test-contract");
}
