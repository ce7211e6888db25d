/* GL tests (suite gl, headless) of the runtime's debugging API, what the
 * viewer builds on: debug views recorded by tw_world_frame() agree with the
 * frame's statistics and change nothing that is drawn; tw_world_draw_debug()
 * draws over the image; tw_world_frame_fixed() redraws a culled set exactly. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tests/check.h"
#include "tests/headless-world.h"
#include "tests/image-diff.h"
#include "tiles/tiles-internal.h"

enum { W = 320, H = 180, FRAMES = 8 };

/* deterministic: no query result ready before it is waited on, and the
 * nominal cost model, so that two worlds given the same cameras draw the
 * same clusters in the same order, whatever the GPU's timing. */
static struct tw_world *make_world_as(struct tw_context *ctx, const struct tw_tileset *ts,
                                      enum tw_method method, bool deterministic)
{
    struct tw_world_settings s = world_settings(ctx, ts, W, H, 1, 400.0f);
    s.method = method;
    s.deterministic = deterministic;
    struct tw_world *w = NULL;
    return tw_world_create_tuned(&s, NULL, &w) == TW_OK ? w : NULL;
}

static struct tw_world *make_world(struct tw_context *ctx, const struct tw_tileset *ts,
                                   enum tw_method method)
{
    return make_world_as(ctx, ts, method, false);
}

/* Frame k of a short walk down a street, the last two from 300 m up (above
 * every common box: tile queries' boxes are stretched up to the eye). */
static struct tw_camera camera(int k)
{
    struct tw_camera cam = {{{0, 0}, {0.0f, 1.7f, 2.0f + 1.5f * (float)k}}, 10.0f, 3.0f};
    if (k >= FRAMES - 2) {
        cam.pos.local[1] = 300.0f;
        cam.pitch = -30.0f;
    }
    return cam;
}

/* Debug views off: nothing recorded. Bad masks and drawing before any
 * frame are refused. */
static void test_off(struct tw_context *ctx, const struct tw_tileset *ts)
{
    struct tw_world *w = make_world(ctx, ts, TW_METHOD_TILEQUERY_CHC);
    CHECK(w != NULL);
    if (!w)
        return;
    CHECK(tw_world_set_debug(w, 1u << 7) == TW_ERR_INVALID);
    CHECK(tw_world_draw_debug(w, NULL, 0) == TW_ERR_STATE);
    const struct tw_camera cam = camera(0);
    CHECK(tw_world_frame(w, &cam, NULL) == TW_OK);
    size_t n = 1;
    tw_world_debug_boxes(w, &n);
    CHECK(n == 0);
    tw_world_drawn(w, &n);
    CHECK(n == 0);
    tw_world_destroy(w);
}

/* With every view on, the records agree with the statistics, and the frame
 * is the one a world without debug views draws, pixel for pixel, with the
 * same counts (both deterministic: otherwise CHC++'s sets, and so the
 * pixels where two clusters' surfaces tie, follow the GPU's timing). */
static void test_records(struct tw_context *ctx, const struct tw_tileset *ts, enum tw_method m)
{
    struct tw_world *w = make_world_as(ctx, ts, m, true), *plain = make_world_as(ctx, ts, m, true);
    uint8_t *a = malloc(W * H * 3), *b = malloc(W * H * 3);
    CHECK(w && plain && a && b);
    if (!w || !plain || !a || !b)
        goto out;
    CHECK(tw_world_set_debug(w, TW_DEBUG_ALL) == TW_OK);
    const bool tq = m == TW_METHOD_TILEQUERY || m == TW_METHOD_TILEQUERY_CHC;
    for (int f = 0; f < FRAMES; f++) {
        const struct tw_camera cam = camera(f);
        struct tw_frame_stats st, st_plain;
        CHECK(tw_world_frame(w, &cam, &st) == TW_OK);
        CHECK(tw_world_read_rgb(w, a) == TW_OK);
        CHECK(tw_world_frame(plain, &cam, &st_plain) == TW_OK);
        CHECK(tw_world_read_rgb(plain, b) == TW_OK);
        CHECK(memcmp(a, b, W * H * 3) == 0);
        CHECK(st.clusters == st_plain.clusters && st.triangles == st_plain.triangles &&
              st.queries == st_plain.queries);

        size_t n = 0;
        const struct tw_debug_box *d = tw_world_debug_boxes(w, &n);
        uint32_t kinds[TW_DEBUG_KIND_COUNT] = {0}, tile_queries = 0, tile_hidden = 0;
        uint32_t query_boxes = 0;
        bool duplicate_cell = false;
        for (size_t k = 0; k < n; k++) {
            CHECK(d[k].kind < TW_DEBUG_KIND_COUNT);
            if (d[k].kind >= TW_DEBUG_KIND_COUNT)
                continue;
            kinds[d[k].kind]++;
            if (d[k].kind >= TW_DEBUG_QUERY_VISIBLE) {
                query_boxes++;
                tile_queries += d[k].tile_query;
                tile_hidden += d[k].tile_query && d[k].kind == TW_DEBUG_QUERY_HIDDEN;
            }
            if (d[k].kind <= TW_DEBUG_CELL_NOT_REACHED)
                for (size_t q = 0; q < k; q++)
                    duplicate_cell |= d[q].kind <= TW_DEBUG_CELL_NOT_REACHED &&
                                      d[q].cell.i == d[k].cell.i && d[q].cell.j == d[k].cell.j;
        }
        CHECK(!duplicate_cell);
        const uint32_t drawn_cells = kinds[TW_DEBUG_CELL_START] + kinds[TW_DEBUG_CELL_FREE] +
                                     kinds[TW_DEBUG_CELL_VISIBLE] + kinds[TW_DEBUG_CELL_POSTPONED];
        CHECK(drawn_cells == st.tiles_visible);
        CHECK(kinds[TW_DEBUG_NODE_LEAF] > 0 && kinds[TW_DEBUG_NODE_INNER] > 0);
        /* Every query is one box or more; tile queries are one box each. */
        CHECK(query_boxes >= st.queries);
        if (tq) {
            CHECK(kinds[TW_DEBUG_CELL_START] == 1);
            CHECK(kinds[TW_DEBUG_CELL_VISIBLE] + kinds[TW_DEBUG_CELL_OCCLUDED] +
                      kinds[TW_DEBUG_CELL_POSTPONED] == st.tiles_queried);
            CHECK(tile_queries == st.tiles_queried);
            CHECK(tile_hidden == kinds[TW_DEBUG_CELL_OCCLUDED]);
        } else {
            CHECK(kinds[TW_DEBUG_CELL_START] == 0 && tile_queries == 0);
        }
        if (m == TW_METHOD_VFC)
            CHECK(query_boxes == 0);

        /* Drawn over the image: the colour changes, the world's frame does not. */
        CHECK(tw_world_draw_debug(w, d, n) == TW_OK);
        CHECK(tw_world_read_rgb(w, b) == TW_OK);
        CHECK(count_differing(a, b, W * H) > W * H / 20);
    }
    printf("debug views of %s: records agree with the statistics on %d frames\n",
           tw_method_name(m), FRAMES);
out:
    free(a);
    free(b);
    tw_world_destroy(w);
    tw_world_destroy(plain);
}

/* A culled set redrawn by tw_world_frame_fixed() from the same camera gives
 * the same image; from elsewhere it still draws exactly that set. */
static void test_fixed(struct tw_context *ctx, const struct tw_tileset *ts)
{
    struct tw_world *w = make_world(ctx, ts, TW_METHOD_TILEQUERY_CHC);
    uint8_t *a = malloc(W * H * 3), *b = malloc(W * H * 3);
    struct tw_drawn_cluster *set = NULL;
    CHECK(w && a && b);
    if (!w || !a || !b)
        goto out;
    tw_world_record_draws(w, true);
    struct tw_frame_stats st;
    for (int f = 0; f < 4; f++) {
        const struct tw_camera cam = camera(f);
        CHECK(tw_world_frame(w, &cam, &st) == TW_OK);
    }
    CHECK(tw_world_read_rgb(w, a) == TW_OK);
    size_t n = 0;
    const struct tw_drawn_cluster *d = tw_world_drawn(w, &n);
    CHECK(n == st.clusters && n > 0);
    set = malloc(sizeof(*set) * (n ? n : 1));
    if (!set)
        goto out;
    memcpy(set, d, sizeof(*set) * n);
    const uint64_t frame = st.frame;

    const struct tw_camera same = camera(3);
    struct tw_frame_stats fixed;
    CHECK(tw_world_frame_fixed(w, &same, set, n, &fixed) == TW_OK);
    CHECK(tw_world_read_rgb(w, b) == TW_OK);
    CHECK(fixed.clusters == n && fixed.triangles == st.triangles && fixed.queries == 0);
    CHECK(count_differing(a, b, W * H) == 0);
    CHECK(fixed.draws <= st.draws && fixed.cpu_ms > 0.0);

    /* The set is drawn as the oracle draws its own, tile by tile, whatever
     * its order: dealt from both ends, its tiles interleave, and it still
     * takes the same draws and gives the same image. */
    struct tw_drawn_cluster *dealt = malloc(sizeof(*dealt) * n);
    CHECK(dealt != NULL);
    if (dealt) {
        for (size_t k = 0, lo = 0, hi = n; k < n; k++)
            dealt[k] = k % 2 ? set[--hi] : set[lo++];
        size_t breaks = 0;
        for (size_t k = 1; k < n; k++)
            breaks += dealt[k].cell.i != dealt[k - 1].cell.i || dealt[k].cell.j != dealt[k - 1].cell.j;
        struct tw_frame_stats again;
        CHECK(tw_world_frame_fixed(w, &same, dealt, n, &again) == TW_OK);
        CHECK(tw_world_read_rgb(w, b) == TW_OK);
        CHECK(breaks > 2 * (size_t)fixed.tiles_visible);
        CHECK(again.draws == fixed.draws && again.triangles == fixed.triangles &&
              again.tiles_visible == fixed.tiles_visible);
        CHECK(count_differing(a, b, W * H) == 0);
        free(dealt);
    }

    /* From 300 m up, looking down the street: the same clusters. */
    struct tw_camera above = camera(3);
    above.pos.local[1] = 300.0f;
    above.pos.local[2] -= 250.0f;
    above.pitch = -40.0f;
    CHECK(tw_world_frame_fixed(w, &above, set, n, &fixed) == TW_OK);
    CHECK(fixed.clusters == n && fixed.triangles == st.triangles);
    CHECK(tw_world_read_rgb(w, b) == TW_OK);
    CHECK(count_differing(a, b, W * H) > W * H / 10);

    /* The methods' state was left alone: the next frame is frame + 1. */
    const struct tw_camera next = camera(4);
    CHECK(tw_world_frame(w, &next, &st) == TW_OK);
    CHECK(st.frame == frame + 1);

    /* A fixed set's finish adds its time to the set's figures. */
    CHECK(tw_world_finish(w, &st) == TW_OK);
    CHECK(tw_world_frame_fixed(w, &same, set, n, &fixed) == TW_OK);
    const double cpu_drawn = fixed.cpu_ms;
    CHECK(tw_world_finish(w, &fixed) == TW_OK);
    CHECK(fixed.cpu_ms >= cpu_drawn);

    /* A cluster that names nothing is refused. */
    struct tw_drawn_cluster bad = set[0];
    bad.cluster = UINT32_MAX;
    CHECK(tw_world_frame_fixed(w, &same, &bad, 1, NULL) == TW_ERR_INVALID);
    printf("frozen set: %zu clusters redrawn, same image from the same camera\n", n);
out:
    free(set);
    free(a);
    free(b);
    tw_world_destroy(w);
}

int main(void)
{
    struct tw_context *ctx = NULL;
    struct tw_tileset *ts = NULL;
    if (!open_headless(W, H, "city", 1, &ctx, &ts))
        return 1;
    test_off(ctx, ts);
    for (int m = TW_METHOD_FIRST; m < TW_METHOD_ALL; m++)
        test_records(ctx, ts, (enum tw_method)m);
    test_fixed(ctx, ts);
    tw_tileset_destroy(ts);
    tw_context_destroy(ctx);
    return check_summary("test-debug-views");
}
