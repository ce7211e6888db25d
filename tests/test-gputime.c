/* GL tests of the frames' GPU time (runtime/gputime.c, suite gl): filled
 * after tw_world_finish() for every method, the ID pass's apart, and the
 * late figures of a host that never finishes, read without waiting. */
#include <stdio.h>
#include <stdlib.h>

#include "tests/check.h"
#include "tests/headless-world.h"
#include "tiles/tiles-internal.h"

enum { W = 320, H = 180, FRAMES = 6 };

static struct tw_world *make_world(struct tw_context *ctx, const struct tw_tileset *ts,
                                   enum tw_method m, bool verify)
{
    struct tw_world_settings s = world_settings(ctx, ts, W, H, 1, 300.0f);
    s.method = m;
    s.verify = verify;
    struct tw_world *w = NULL;
    if (tw_world_create_tuned(&s, NULL, &w) != TW_OK)
        return NULL;
    return w;
}

/* Every method, with and without verify: unknown until finished, then
 * known; an ID pass timed apart exactly when there is one. */
static void test_finished(struct tw_context *ctx, const struct tw_tileset *ts, bool verify)
{
    for (int m = TW_METHOD_FIRST; m < TW_METHOD_ALL; m++) {
        const char *name = tw_method_name((enum tw_method)m);
        struct tw_world *w = make_world(ctx, ts, (enum tw_method)m, verify);
        CHECK_MSG(w != NULL, "%s", name);
        if (!w)
            continue;
        const bool id_pass = verify || tw_method_limit((enum tw_method)m);
        for (int f = 0; f < FRAMES; f++) {
            struct tw_frame_stats st;
            CHECK(tw_world_frame(w, &city_views[f % 5], &st) == TW_OK);
            CHECK_MSG(st.gpu_ms == -1.0, "%s: %g before finish", name, st.gpu_ms);
            CHECK(st.gpu_ms_id == (id_pass ? -1.0 : 0.0));
            CHECK(tw_world_finish(w, &st) == TW_OK);
            CHECK_MSG(st.gpu_ms >= 0.0, "%s%s frame %d: gpu_ms %g", name,
                      verify ? " (verify)" : "", f, st.gpu_ms);
            if (id_pass)
                CHECK_MSG(st.gpu_ms_id > 0.0, "%s%s frame %d: gpu_ms_id %g", name,
                          verify ? " (verify)" : "", f, st.gpu_ms_id);
            else
                CHECK_MSG(st.gpu_ms_id == 0.0, "%s frame %d: gpu_ms_id %g", name, f,
                          st.gpu_ms_id);
            /* Finished frames came back: the next frame knows its predecessor. */
            if (f > 0)
                CHECK_MSG(st.gpu_late_frame == st.frame - 1, "%s frame %llu: late %llu", name,
                          (unsigned long long)st.frame, (unsigned long long)st.gpu_late_frame);
        }
        /* A fixed set's frame has no timers: unknown, and not the last frame's. */
        struct tw_frame_stats st;
        static const struct tw_drawn_cluster none[1];
        CHECK(tw_world_frame_fixed(w, &city_views[0], none, 0, &st) == TW_OK);
        CHECK(tw_world_finish(w, &st) == TW_OK);
        CHECK(st.gpu_ms == -1.0 && st.gpu_ms_id == 0.0);
        tw_world_destroy(w);
    }
}

/* A host that never calls tw_world_finish: each frame says the latest
 * earlier frame whose timers came back, always an earlier one; they do come
 * back, and the figure only moves forward. */
static void test_late(struct tw_context *ctx, const struct tw_tileset *ts)
{
    struct tw_world *w = make_world(ctx, ts, TW_METHOD_TILEQUERY_CHC, false);
    CHECK(w != NULL);
    if (!w)
        return;
    uint64_t last_late = 0, lagged = 0;
    bool came_back = false;
    for (int f = 0; f < 200 && !(came_back && f >= 2 * FRAMES); f++) {
        struct tw_frame_stats st;
        CHECK(tw_world_frame(w, &city_views[f % 5], &st) == TW_OK);
        CHECK(st.gpu_ms == -1.0);
        if (f == 0)
            CHECK(st.gpu_late_frame == 0 && st.gpu_late_ms == -1.0);
        CHECK_MSG(st.gpu_late_frame < st.frame, "frame %llu: late %llu",
                  (unsigned long long)st.frame, (unsigned long long)st.gpu_late_frame);
        CHECK(st.gpu_late_frame >= last_late);
        if (st.gpu_late_frame > 0) {
            CHECK_MSG(st.gpu_late_ms >= 0.0, "late %g", st.gpu_late_ms);
            came_back = true;
        } else {
            CHECK(st.gpu_late_ms == -1.0);
        }
        lagged += st.gpu_late_frame + 1 < st.frame;
        last_late = st.gpu_late_frame;
    }
    CHECK_MSG(came_back && last_late >= 1, "no timer came back in 200 frames");
    printf("test-gputime: %llu frames lagged more than one frame\n", (unsigned long long)lagged);
    tw_world_destroy(w);
}

int main(void)
{
    struct tw_context *ctx = NULL;
    struct tw_tileset *ts = NULL;
    if (!open_headless(W, H, "city", 1, &ctx, &ts))
        return 1;
    test_finished(ctx, ts, false);
    test_finished(ctx, ts, true);
    test_late(ctx, ts);
    tw_tileset_destroy(ts);
    tw_context_destroy(ctx);
    return check_summary("test-gputime");
}
