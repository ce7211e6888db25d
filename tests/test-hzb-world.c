/* GL tests of the HZB methods (DESIGN §6, §8; suite gl): on fixed city
 * views and along short walks of every built-in path, hzb and
 * tilequery+hzb draw a superset of what the oracle's ID pass finds visible
 * (0 missed pixels on every frame), cull once warm, issue no query and
 * report their pyramid's cost; with the tested boxes deliberately shrunk
 * the same checks catch missed pixels. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tests/check.h"
#include "tests/drawn-set.h"
#include "tests/headless-world.h"
#include "tiles/tiles-internal.h"

/* Where the pyramid is: the CPU's, or (the "gpu" argument) the GPU's. */
static enum tw_hzb_pyramid pyramid = TW_HZB_PYRAMID_CPU;

static struct tw_world *make_world(struct tw_context *ctx, const struct tw_tileset *ts,
                                   uint32_t w, uint32_t h, float shrink)
{
    struct tw_world_settings s = world_settings(ctx, ts, w, h, 3, 450.0f);
    s.verify = true;
    const struct tw_world_tuning t = {.mutate_query_shrink = shrink, .hzb_pyramid = pyramid};
    struct tw_world *world = NULL;
    CHECK(tw_world_create_tuned(&s, &t, &world) == TW_OK);
    if (world)
        tw_world_record_draws(world, true);
    return world;
}

struct totals {
    uint64_t missed, triangles, vfc_triangles;
    uint32_t frames, warm_culled, warm_frames;
};

/* One camera, every method: the oracle's visible set, then each HZB method
 * checked against it. warm: the methods have seen this neighbourhood. */
static void check_frame(struct tw_world *w, const struct tw_camera *cam, bool warm,
                        struct totals *t, const char *what, uint32_t f)
{
    struct tw_frame_stats st;
    CHECK(tw_world_set_method_or_limit(w, TW_METHOD_VFC) == TW_OK);
    CHECK(tw_world_frame(w, cam, &st) == TW_OK);
    const uint64_t vfc_triangles = st.triangles;
    CHECK(tw_world_set_method_or_limit(w, TW_METHOD_ORACLE) == TW_OK);
    CHECK(tw_world_frame(w, cam, &st) == TW_OK);
    size_t nv = 0;
    struct tw_drawn_cluster *visible = copy_drawn(w, &nv);
    static const enum tw_method methods[2] = {TW_METHOD_HZB, TW_METHOD_TILEQUERY_HZB};
    for (int m = 0; m < 2; m++) {
        CHECK(tw_world_set_method_or_limit(w, methods[m]) == TW_OK);
        CHECK(tw_world_frame(w, cam, &st) == TW_OK);
        size_t n = 0;
        struct tw_drawn_cluster *drawn = copy_drawn(w, &n);
        const bool superset = !has_duplicate(drawn, n) && includes(drawn, n, visible, nv);
        if (st.missed_pixels || !superset)
            fprintf(stderr, "%s frame %u: %s missed %llu pixels in %u clusters%s\n", what, f,
                    tw_method_name(methods[m]), (unsigned long long)st.missed_pixels,
                    st.missed_clusters, superset ? "" : ", not a superset of the visible set");
        CHECK(superset);
        CHECK(st.missed_pixels == 0 && st.missed_clusters == 0);
        CHECK(st.queries == 0);
        if (pyramid != TW_HZB_PYRAMID_GPU)
            CHECK(n == st.clusters);    /* the GPU's are counted when its answers arrive */
        CHECK(st.tiles_late == 0);
        t->missed += st.missed_pixels;
        t->triangles += st.triangles;
        t->vfc_triangles += vfc_triangles;
        t->frames++;
        if (warm) {
            t->warm_frames++;
            t->warm_culled += st.triangles < vfc_triangles;
            /* Phase 1 drew something, so the depth was read and built on
             * (the CPU's), or the GPU tested boxes and its answers came
             * back, a few bytes of them. */
            if (pyramid == TW_HZB_PYRAMID_GPU)
                CHECK(st.ms_hzb_read == 0.0 && st.hzb_boxes > 0 && st.hzb_lag >= 1 &&
                      st.bytes_read_back > 0 && st.bytes_read_back <= 65536);
            else
                CHECK(st.ms_hzb_read > 0.0 && st.hzb_boxes > 0);
        }
        free(drawn);
    }
    free(visible);
}

/* Fixed views: the first frames from each, then small steps. */
static void test_views(struct tw_context *ctx, const struct tw_tileset *ts)
{
    struct tw_world *w = make_world(ctx, ts, 320, 180, 0.0f);
    if (!w)
        return;
    /* The city views of test-runtime, and one from 250 m up. */
    const struct tw_camera views[] = {
        city_views[0], city_views[1], city_views[2], city_views[3], city_views[4],
        {{{4, 4}, {20.0f, 250.0f, 20.0f}}, 60.0f, -20.0f},
    };
    struct totals t = {0};
    for (size_t v = 0; v < sizeof(views) / sizeof(views[0]); v++)
        for (uint32_t f = 0; f < 4; f++) {
            struct tw_camera cam = views[v];
            cam.pos.local[2] += 0.5f * (float)f;
            cam.yaw += 2.0f * (float)f;
            char what[32];
            snprintf(what, sizeof(what), "view %zu", v);
            check_frame(w, &cam, f >= 2, &t, what, f);
        }
    /* Once warm they cull: fewer triangles than vfc on most frames. */
    CHECK(t.warm_culled * 4 >= t.warm_frames * 3);
    CHECK(t.triangles < t.vfc_triangles);
    printf("fixed views: %u frames, %.0f%% of vfc's triangles, %u of %u warm frames culled\n",
           t.frames, 100.0 * (double)t.triangles / (double)t.vfc_triangles, t.warm_culled,
           t.warm_frames);
    tw_world_destroy(w);
}

/* Frames [first, last) of a built-in path at an odd size (partial pyramid
 * blocks at the right and top edges). */
static void test_walk(struct tw_context *ctx, const char *tileset, const char *path_name,
                      uint32_t first, uint32_t last)
{
    struct tw_tileset *ts = NULL;
    if (tw_tilesets_builtin(tileset, 3, 0, &test_log, &ts) != TW_OK) {
        fprintf(stderr, "cannot build tileset %s\n", tileset);
        failures++;
        return;
    }
    struct tw_path path;
    CHECK(tw_path_builtin(path_name, 3, last, 0.0f, ts->footprint[0], ts->footprint[1], &path) == TW_OK);
    struct tw_world *w = make_world(ctx, ts, 161, 91, 0.0f);
    struct totals t = {0};
    char what[64];
    snprintf(what, sizeof(what), "%s/%s", tileset, path_name);
    for (uint32_t f = first; w && f < path.count; f++)
        check_frame(w, &path.keys[f], false, &t, what, f);
    printf("%-7s %-9s frames %u-%u: %.0f%% of vfc's triangles, %llu missed pixels\n", tileset,
           path_name, first, last - 1, 100.0 * (double)t.triangles / (double)t.vfc_triangles,
           (unsigned long long)t.missed);
    tw_world_destroy(w);
    tw_path_finish(&path);
    tw_tileset_destroy(ts);
}

/* The checks can fail: boxes tested shrunk by 40 % hide visible clusters. */
static void test_mutation(struct tw_context *ctx, const struct tw_tileset *ts)
{
    struct tw_world *w = make_world(ctx, ts, 320, 180, 0.4f);
    if (!w)
        return;
    uint64_t missed = 0;
    const struct tw_camera cam = {{{0, 0}, {0.0f, 1.7f, 2.0f}}, 10.0f, 3.0f};
    for (int f = 0; f < 4; f++) {
        struct tw_camera c = cam;
        c.yaw += 3.0f * (float)f;
        struct tw_frame_stats st;
        CHECK(tw_world_set_method_or_limit(w, TW_METHOD_HZB) == TW_OK);
        CHECK(tw_world_frame(w, &c, &st) == TW_OK);
        missed += st.missed_pixels;
    }
    CHECK(missed > 0);
    printf("boxes shrunk by 40%%: %llu missed pixels caught\n", (unsigned long long)missed);
    tw_world_destroy(w);
}

/* With "standard" the test runs in a context without glClipControl (meson
 * sets MESA_GL_VERSION_OVERRIDE=3.3 and takes ARB_clip_control away): the
 * world then renders standard 24-bit depth, and the pyramid is built from
 * that convention; fewer walks. With "gpu" the pyramid is built and tested
 * by compute passes (llvmpipe has them), its answers read a frame later. */
int main(int argc, char **argv)
{
    const bool standard = argc > 1 && strcmp(argv[1], "standard") == 0;
    if (argc > 1 && strcmp(argv[1], "gpu") == 0)
        pyramid = TW_HZB_PYRAMID_GPU;
    struct tw_context *ctx = NULL;
    struct tw_tileset *ts = NULL;
    if (!open_headless(320, 180, "city", 3, &ctx, &ts))
        return 1;
    struct tw_world *probe = make_world(ctx, ts, 16, 16, 0.0f);
    const bool reversed = tw_world_reversed_z(probe);
    CHECK(probe && reversed == !standard);
    tw_world_destroy(probe);
    printf("depth: %s, pyramid on the %s\n", reversed ? "reversed float" : "standard 24-bit",
           pyramid == TW_HZB_PYRAMID_GPU ? "GPU" : "CPU");
    test_views(ctx, ts);
    test_mutation(ctx, ts);
    tw_tileset_destroy(ts);
    test_walk(ctx, "city", "street", 0, 12);
    test_walk(ctx, "city", "teleport", 47, 54);    /* the jump at frame 50 */
    if (!standard) {
        test_walk(ctx, "city", "flyover", 200, 206);   /* high up: grazing, little occlusion */
        test_walk(ctx, "city", "spin", 39, 47);        /* the 180-degree turn */
        test_walk(ctx, "forest", "forest", 0, 10);
        test_walk(ctx, "hybrid", "street", 0, 10);
    }
    tw_context_destroy(ctx);
    return check_summary("test-hzb-world");
}
