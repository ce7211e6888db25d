/* Hierarchical cells in a world (README "Hierarchical cells"), suite gl: a
 * town of boxes seen 16 km out, which cells alone cannot reach, drawn with
 * block proxies far away; every method misses no pixel the oracle sees at
 * the same selection, and a broken culler is still caught; proxies are
 * drawn, at their blocks' first cells; a provider, or a host's selection
 * callback, is refused. The town is light (14 to 110 triangles a cell), so
 * the oracle's and the full-detail image's passes over 20 000 cells stay
 * quick. */
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


/* Five prototypes on 100 m cells: a green ground and 1 to 9 towers each. */
static struct tw_tileset *make_town(void)
{
    struct tw_tileset *ts = NULL;
    CHECK(tw_tileset_create("town", 100, 100, &ts) == TW_OK);
    if (!ts)
        return NULL;
    const int green = tw_tileset_add_material(ts, (const float[4]){0.2f, 0.6f, 0.2f, 1});
    const int colours[3] = {tw_tileset_add_material(ts, (const float[4]){0.8f, 0.3f, 0.2f, 1}),
                            tw_tileset_add_material(ts, (const float[4]){0.3f, 0.3f, 0.8f, 1}),
                            tw_tileset_add_material(ts, (const float[4]){0.9f, 0.9f, 0.8f, 1})};
    const int cube = add_cube(ts);
    CHECK(green >= 0 && colours[0] >= 0 && colours[1] >= 0 && colours[2] >= 0 && cube >= 0);
    for (int p = 0; p < 5; p++) {
        char name[16];
        snprintf(name, sizeof(name), "town-%d", p);
        const int proto = tw_tileset_add_prototype(ts, name, 1.0f);
        const float ground[12] = {100, 0, 0, 0, 0, 0.2f, 0, -0.2f, 0, 0, 100, 0};
        CHECK(tw_tileset_add_instance(ts, (uint32_t)proto, (uint32_t)cube, (uint32_t)green,
                                      ground) >= 0);
        const int towers = 1 + 2 * p;
        for (int k = 0; k < towers; k++) {
            const float x = 10.0f + 27.0f * (float)(k % 3), z = 10.0f + 27.0f * (float)(k / 3);
            const float h = 8.0f + 6.0f * (float)((k + p) % 5);
            const float m[12] = {18, 0, 0, x, 0, h, 0, 0, 0, 0, 18, z};
            CHECK(tw_tileset_add_instance(ts, (uint32_t)proto, (uint32_t)cube,
                                          (uint32_t)colours[(k + p) % 3], m) >= 0);
        }
    }
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
    tw_tileset_destroy(ts);
    tw_context_destroy(ctx);
    return check_summary("hlod-world");
}
