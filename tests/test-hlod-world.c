/* Hierarchical cells in a world (README "Hierarchical cells"), suite gl: a
 * town of boxes seen 16 km out, which cells alone cannot reach, drawn with
 * block proxies far away; every method misses no pixel the oracle sees at
 * the same selection, and a broken culler is still caught; proxies are
 * drawn, at their blocks' first cells; a provider, or a host's selection
 * callback, is refused. A provider with coarser levels of its own (the
 * same town generated, and blocks of its own) is drawn over its blocks at
 * 16 km: each block asked for holds a cell within reach, no method misses
 * a pixel; with moving objects, in host rendering or with --hlod-levels 1
 * its levels are left alone (the world is made, with cells only). The town is light (14 to
 * 110 triangles a cell), so the oracle's and the full-detail image's
 * passes over 20 000 cells stay quick. */
#include <stdatomic.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tests/check.h"
#include "tests/meshes.h"
#include "tests/headless-world.h"

enum { W = 160, H = 90 };

/* 150 m up, looking across the town to the horizon. */
static const struct tw_camera high = {{{0, 0}, {20.0f, 150.0f, 20.0f}}, 35.0f, -3.0f};


/* Town prototype p into ts (its materials and a cube mesh added): a green
 * ground and 1 + 2p towers, 8 to 32 m tall. Returns the prototype. */
static int add_town_prototype(struct tw_tileset *ts, int p)
{
    const int green = tw_tileset_add_material(ts, (const float[4]){0.2f, 0.6f, 0.2f, 1});
    const int colours[3] = {tw_tileset_add_material(ts, (const float[4]){0.8f, 0.3f, 0.2f, 1}),
                            tw_tileset_add_material(ts, (const float[4]){0.3f, 0.3f, 0.8f, 1}),
                            tw_tileset_add_material(ts, (const float[4]){0.9f, 0.9f, 0.8f, 1})};
    const int cube = add_cube(ts);
    char name[24];
    snprintf(name, sizeof(name), "town-%d", p);
    const int proto = tw_tileset_add_prototype(ts, name, 1.0f);
    if (green < 0 || colours[0] < 0 || colours[1] < 0 || colours[2] < 0 || cube < 0 ||
        proto < 0)
        return TW_ERR_NOMEM;
    const float ground[12] = {100, 0, 0, 0, 0, 0.2f, 0, -0.2f, 0, 0, 100, 0};
    int err = tw_tileset_add_instance(ts, (uint32_t)proto, (uint32_t)cube, (uint32_t)green,
                                      ground) < 0;
    const int towers = 1 + 2 * p;
    for (int k = 0; k < towers && !err; k++) {
        const float x = 10.0f + 27.0f * (float)(k % 3), z = 10.0f + 27.0f * (float)(k / 3);
        const float h = 8.0f + 6.0f * (float)((k + p) % 5);
        const float m[12] = {18, 0, 0, x, 0, h, 0, 0, 0, 0, 18, z};
        err = tw_tileset_add_instance(ts, (uint32_t)proto, (uint32_t)cube,
                                      (uint32_t)colours[(k + p) % 3], m) < 0;
    }
    return err ? TW_ERR_NOMEM : proto;
}

/* Five prototypes on 100 m cells. */
static struct tw_tileset *make_town(void)
{
    struct tw_tileset *ts = NULL;
    CHECK(tw_tileset_create("town", 100, 100, &ts) == TW_OK);
    if (!ts)
        return NULL;
    for (int p = 0; p < 5; p++)
        CHECK(add_town_prototype(ts, p) == p);
    CHECK(tw_tileset_finish(ts, 256) == TW_OK);
    return ts;
}

static struct tw_world *make_world(struct tw_context *ctx, const struct tw_tileset *ts,
                                   const struct tw_tile_provider *provider, uint32_t levels,
                                   float view_distance, float shrink, int *err)
{
    struct tw_world_settings s = world_settings(ctx, ts, W, H, 1, view_distance);
    if (provider) {
        s.tileset = NULL;
        s.provider = provider;
    }
    s.workers = 1;
    s.verify = true;
    s.deterministic = true;
    struct tw_world_tuning t = {0};
    t.hlod_levels = levels;
    t.mutate_query_shrink = shrink;
    struct tw_world *w = NULL;
    *err = tw_world_create_tuned(&s, &t, &w);
    return w;
}

static bool frame(struct tw_world *w, enum tw_method m, const struct tw_camera *cam,
                  struct tw_frame_stats *st)
{
    return tw_world_set_method_or_limit(w, m) == TW_OK && tw_world_frame(w, cam, st) == TW_OK &&
           tw_world_finish(w, st) == TW_OK;
}

static void test_methods_over_blocks(struct tw_context *ctx, const struct tw_tileset *ts)
{
    int err;
    /* Cells alone do not reach 16 km: the view distance is refused. */
    struct tw_world *w = make_world(ctx, ts, NULL, 1, 16000.0f, 0.0f, &err);
    CHECK(!w && err == TW_ERR_LIMIT);
    w = make_world(ctx, ts, NULL, 6, 16000.0f, 0.0f, &err);
    CHECK(w && err == TW_OK);
    if (!w)
        return;
    tw_world_record_draws(w, true);
    static const enum tw_method methods[] = {TW_METHOD_VFC, TW_METHOD_TILEQUERY,
                                             TW_METHOD_CHC, TW_METHOD_TILEQUERY_CHC,
                                             TW_METHOD_HZB, TW_METHOD_TILEQUERY_HZB};
    for (size_t m = 0; m < sizeof(methods) / sizeof(methods[0]); m++) {
        struct tw_camera cam = high;
        for (int f = 0; f < 3; f++) {
            struct tw_frame_stats st;
            CHECK(frame(w, methods[m], &cam, &st));
            CHECK(st.missed_pixels == 0);
            if (st.missed_pixels)
                printf("%s, frame %d: %llu pixels missed\n", tw_method_name(methods[m]), f,
                       (unsigned long long)st.missed_pixels);
            CHECK(st.tiles_pending == 0);
            if (f == 0 && methods[m] == TW_METHOD_VFC) {
                /* Proxies among the draws: contents past the tileset's
                 * prototypes (their levels are named by their prototype),
                 * each at the first cell of a block. */
                size_t n, proxies = 0, misplaced = 0;
                const struct tw_drawn_cluster *d = tw_world_drawn(w, &n);
                for (size_t k = 0; k < n; k++)
                    if (d[k].prototype >= ts->prototype_count) {
                        proxies++;
                        misplaced += (d[k].cell.i & 1) != 0 || (d[k].cell.j & 1) != 0;
                    }
                CHECK(proxies > 0 && proxies < n);
                CHECK(misplaced == 0);
                printf("16 km: %zu of %zu clusters drawn are proxies'; %llu triangles, %llu "
                       "pixels differ from full detail\n",
                       proxies, n, (unsigned long long)st.triangles,
                       (unsigned long long)st.lod_pixels);
            }
            cam.pos.local[0] += 15.0f;
            cam.yaw += 2.0f;
        }
    }
    tw_world_destroy(w);
    /* A culler whose queries are shrunk misses pixels, and the oracle at
     * the same selection catches it. */
    w = make_world(ctx, ts, NULL, 6, 16000.0f, 0.9f, &err);
    CHECK(w != NULL);
    uint64_t missed = 0;
    struct tw_camera cam = high;
    for (int f = 0; f < 3 && w; f++) {
        struct tw_frame_stats st;
        CHECK(frame(w, TW_METHOD_TILEQUERY, &cam, &st));
        missed += st.missed_pixels;
        cam.pos.local[0] += 15.0f;
    }
    CHECK(missed > 0);
    tw_world_destroy(w);
}

static uint32_t host_select(void *user, struct tw_cell cell)
{
    (void)user;
    return (uint32_t)((uint64_t)cell.i * 3u + (uint64_t)cell.j) % 5u;
}

/* A proxy needs every cell's content on a worker: a provider, or a host's
 * selection callback (render thread only), is refused. */
static void test_refused_for_host_callbacks(struct tw_context *ctx, const struct tw_tileset *ts)
{
    struct tw_tilesets_provider *p = NULL;
    CHECK(tw_tilesets_provider_create("forest-gen", 1, 0, &test_log, &p) == TW_OK);
    int err;
    struct tw_world *w = make_world(ctx, NULL, tw_tilesets_provider_get(p), 4, 600.0f, 0.0f, &err);
    CHECK(!w && err == TW_ERR_INVALID);
    tw_world_destroy(w);
    tw_tilesets_provider_destroy(p);
    struct tw_world_settings s = world_settings(ctx, ts, W, H, 1, 600.0f);
    s.selection.fn = host_select;
    struct tw_world_tuning t = {0};
    t.hlod_levels = 4;
    w = NULL;
    CHECK(tw_world_create_tuned(&s, &t, &w) == TW_ERR_INVALID && !w);
    /* The same world without blocks is fine. */
    t.hlod_levels = 1;
    CHECK(tw_world_create_tuned(&s, &t, &w) == TW_OK && w);
    tw_world_destroy(w);
}

/* The same town from a provider: each cell's prototype made on the
 * workers, and three coarser levels of its own, a block a ground and one
 * tower 20 m tall. What the world asks for is counted. */
static uint32_t town_of(struct tw_cell cell)
{
    return (uint32_t)((uint64_t)cell.i * 3u + (uint64_t)cell.j) % 5u;
}

struct town_provider {
    struct tw_tile_provider p;
    _Atomic uint32_t cells, blocks[4], outside;
    struct tw_cell view_lo, view_hi;      /* every cell within the view distance */
};

static int town_generate(void *user, struct tw_cell cell, struct tw_tileset *ts)
{
    struct town_provider *tp = user;
    atomic_fetch_add(&tp->cells, 1);
    return add_town_prototype(ts, (int)town_of(cell)) >= 0 ? TW_OK : TW_ERR_NOMEM;
}

static int town_generate_level(void *user, uint32_t level, struct tw_cell block,
                               struct tw_tileset *ts)
{
    struct town_provider *tp = user;
    if (level < 1 || level > 3)
        return tw_tileset_fail(ts, TW_ERR_INVALID, "no level %u", level);
    atomic_fetch_add(&tp->blocks[level], 1);
    /* A block asked for holds a cell within reach of the camera. */
    const int64_t side = (int64_t)1 << level;
    if (block.i * side > tp->view_hi.i || (block.i + 1) * side <= tp->view_lo.i ||
        block.j * side > tp->view_hi.j || (block.j + 1) * side <= tp->view_lo.j)
        atomic_fetch_add(&tp->outside, 1);
    const float s = 100.0f * (float)side;
    const int green = tw_tileset_add_material(ts, (const float[4]){0.2f, 0.6f, 0.2f, 1});
    const int red = tw_tileset_add_material(ts, (const float[4]){0.8f, 0.3f, 0.2f, 1});
    const int cube = add_cube(ts);
    const int proto = tw_tileset_add_prototype(ts, "block", 1.0f);
    const float ground[12] = {s, 0, 0, 0, 0, 0.2f, 0, -0.2f, 0, 0, s, 0};
    const float tower[12] = {0.3f * s, 0, 0, 0.35f * s, 0, 20, 0, 0, 0, 0, 0.3f * s, 0.35f * s};
    if (green < 0 || red < 0 || cube < 0 || proto < 0 ||
        tw_tileset_add_instance(ts, (uint32_t)proto, (uint32_t)cube, (uint32_t)green,
                                ground) < 0 ||
        tw_tileset_add_instance(ts, (uint32_t)proto, (uint32_t)cube, (uint32_t)red, tower) < 0)
        return TW_ERR_NOMEM;
    return TW_OK;
}

static uint32_t town_content(void *user, struct tw_cell cell)
{
    (void)user;
    (void)cell;
    return TW_TILE_OWN;
}

static void host_draw(void *user, const struct tw_host_draw *batch)
{
    (void)user;
    (void)batch;
}

static void test_provider_levels(struct tw_context *ctx, const struct tw_tileset *town)
{
    struct town_provider tp = {0};
    tp.p = (struct tw_tile_provider){
        .name = "town-gen", .footprint = {100, 100}, .bound = town->common_box,
        .content = town_content, .generate = town_generate, .user = &tp,
        .max_cluster_triangles = 256, .levels = 3, .level_error = {40, 80, 160},
        .generate_level = town_generate_level,
    };
    tp.p.bound.max[1] = fmaxf(tp.p.bound.max[1], 20.0f);
    /* Within 16 km of the camera's cell (0, 0), with slack for the look-ahead. */
    tp.view_lo = (struct tw_cell){-180, -180};
    tp.view_hi = (struct tw_cell){180, 180};
    int err;
    struct tw_world *w = make_world(ctx, NULL, &tp.p, 0, 16000.0f, 0.0f, &err);
    CHECK(w && err == TW_OK);
    static const enum tw_method methods[] = {TW_METHOD_VFC, TW_METHOD_TILEQUERY_CHC,
                                             TW_METHOD_HZB};
    for (size_t m = 0; w && m < sizeof(methods) / sizeof(methods[0]); m++) {
        struct tw_camera cam = high;
        for (int f = 0; f < 2; f++) {
            struct tw_frame_stats st;
            CHECK(frame(w, methods[m], &cam, &st));
            CHECK(st.missed_pixels == 0 && st.tiles_pending == 0);
            cam.pos.local[0] += 15.0f;
        }
    }
    tw_world_destroy(w);
    const uint32_t cells = atomic_load(&tp.cells);
    printf("provider levels at 16 km: %u cells, blocks %u / %u / %u (2x2 / 4x4 / 8x8), %u "
           "outside the view\n", cells, atomic_load(&tp.blocks[1]), atomic_load(&tp.blocks[2]),
           atomic_load(&tp.blocks[3]), atomic_load(&tp.outside));
    CHECK(atomic_load(&tp.blocks[1]) > 0 && atomic_load(&tp.blocks[3]) > 0);
    CHECK(atomic_load(&tp.outside) == 0);
    CHECK(cells > 0 && cells < 20000);
    /* Levels that cannot be: refused when the world is made. */
    struct town_provider bad = tp;
    bad.p.user = &bad;
    bad.p.levels = TW_PROVIDER_MAX_LEVELS + 1;
    w = make_world(ctx, NULL, &bad.p, 0, 600.0f, 0.0f, &err);
    CHECK(!w && err == TW_ERR_INVALID);
    bad.p.levels = 1;
    bad.p.generate_level = NULL;
    w = make_world(ctx, NULL, &bad.p, 0, 600.0f, 0.0f, &err);
    CHECK(!w && err == TW_ERR_INVALID);
    bad.p.generate_level = town_generate_level;
    bad.p.level_error[0] = NAN;
    w = make_world(ctx, NULL, &bad.p, 0, 600.0f, 0.0f, &err);
    CHECK(!w && err == TW_ERR_INVALID);
    /* --hlod-levels 1: cells only, and 16 km is out of reach. */
    w = make_world(ctx, NULL, &tp.p, 1, 16000.0f, 0.0f, &err);
    CHECK(!w && err == TW_ERR_LIMIT);
    tw_world_destroy(w);
    /* Moving objects: the levels are left alone (a block would leave the
     * objects out), the world is made. */
    struct tw_tileset *models = NULL;
    CHECK(tw_tileset_create("models", 100, 100, &models) == TW_OK);
    const int cube = models ? add_cube(models) : -1;
    const int red = models ? tw_tileset_add_material(models, (const float[4]){1, 0, 0, 1}) : -1;
    const int car = models ? tw_tileset_add_prototype(models, "car", 1.0f) : -1;
    const float box[12] = {4, 0, 0, -2, 0, 2, 0, 0, 0, 0, 2, -1};
    CHECK(cube >= 0 && red >= 0 && car >= 0 &&
          tw_tileset_add_instance(models, (uint32_t)car, (uint32_t)cube, (uint32_t)red,
                                  box) >= 0 &&
          tw_tileset_finish(models, 256) == TW_OK);
    struct tw_world_settings s = world_settings(ctx, NULL, W, H, 1, 600.0f);
    s.provider = &tp.p;
    s.object_models = models;
    s.workers = 1;
    w = NULL;
    CHECK(tw_world_create(&s, &w) == TW_OK && w);
    struct tw_frame_stats st;
    if (w)
        CHECK(frame(w, TW_METHOD_TILEQUERY_CHC, &high, &st));
    tw_world_destroy(w);
    /* Cells only: 16 km is out of their reach. */
    s.view_distance = 16000.0f;
    w = NULL;
    err = tw_world_create(&s, &w);
    CHECK(!w && err == TW_ERR_LIMIT);
    tw_world_destroy(w);
    tw_tileset_destroy(models);
    /* In host rendering too (the host's hooks are told of cells). */
    s.object_models = NULL;
    s.host.draw = host_draw;
    w = NULL;
    err = tw_world_create(&s, &w);
    CHECK(!w && err == TW_ERR_LIMIT);
    tw_world_destroy(w);
    s.view_distance = 600.0f;
    w = NULL;
    CHECK(tw_world_create(&s, &w) == TW_OK && w);
    tw_world_destroy(w);
}

int main(void)
{
    struct tw_context *ctx;
    if (tw_context_create_headless(W, H, &test_log, &ctx) != TW_OK) {
        fprintf(stderr, "cannot create the headless context\n");
        return 1;
    }
    struct tw_tileset *ts = make_town();
    if (ts)
        test_methods_over_blocks(ctx, ts);
    if (ts)
        test_refused_for_host_callbacks(ctx, ts);
    if (ts)
        test_provider_levels(ctx, ts);
    tw_tileset_destroy(ts);
    tw_context_destroy(ctx);
    return check_summary("hlod-world");
}
