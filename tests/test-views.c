/*
 * Several views of one world (runtime.h, tw_viewport_*): a viewport's
 * camera sees what a world of its own would show it, frame for frame, while
 * the two share one stream, one cache and one budget: the tiles both see are
 * made once, the memory is not doubled, and a tile the other view drew last
 * is not evicted for this one.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tests/check.h"
#include "tileworld/context.h"
#include "tileworld/runtime.h"
#include "tileworld/tilesets.h"

enum { W = 192, H = 108, FRAMES = 40 };

static void log_stderr(void *user, enum tw_log_level level, const char *msg)
{
    (void)user;
    if (level <= TW_LOG_WARN)
        fprintf(stderr, "log: %s\n", msg);
}

/* Walking a street, and a camera 25 m behind and 12 m above it (a chase view). */
static struct tw_camera chase(struct tw_camera c)
{
    c.pos.local[0] -= 25.0f * sinf(c.yaw * 3.14159265f / 180.0f);
    c.pos.local[2] -= 25.0f * cosf(c.yaw * 3.14159265f / 180.0f);
    c.pos.local[1] += 12.0f;
    c.pitch -= 10.0f;
    return c;
}

static uint64_t bytes_of(const struct tw_frame_stats *st)
{
    return st->bytes_cpu + st->bytes_gpu;
}

int main(void)
{
    const struct tw_log log = {log_stderr, NULL};
    struct tw_context *ctx = NULL;
    struct tw_tilesets_provider *gen = NULL;
    if (tw_context_create_headless(W, H, &log, &ctx) != TW_OK ||
        tw_tilesets_provider_create("city-gen", 3, 0, &log, &gen) != TW_OK) {
        fprintf(stderr, "test-views: cannot set up\n");
        return 1;
    }
    const struct tw_tile_provider *provider = tw_tilesets_provider_get(gen);
    struct tw_world_settings s = {0};
    s.provider = provider;
    s.width = W;
    s.height = H;
    s.view_distance = 300.0f;
    s.deterministic = true;
    s.workers = 2;
    s.get_proc = tw_context_get_proc(ctx);
    s.log = log;
    struct tw_path path;
    if (tw_path_builtin("street", 5, FRAMES, 3.0f, provider->footprint[0], provider->footprint[1],
                        &path) != TW_OK)
        return 1;

    /* One world with a viewport, and two worlds of one camera each. */
    struct tw_world *shared = NULL, *alone_a = NULL, *alone_b = NULL;
    struct tw_viewport *vp = NULL;
    CHECK(tw_world_create(&s, &shared) == TW_OK);
    CHECK(tw_world_create(&s, &alone_a) == TW_OK);
    CHECK(tw_world_create(&s, &alone_b) == TW_OK);
    if (!shared || !alone_a || !alone_b)
        return check_summary("test-views");
    CHECK(tw_viewport_create(shared, &vp) == TW_OK);
    if (!vp)
        return check_summary("test-views");
    CHECK(tw_viewport_create(NULL, &vp) == TW_ERR_INVALID);
    CHECK(tw_viewport_frame(NULL, &path.keys[0], NULL) == TW_ERR_INVALID);

    static uint8_t img[W * H * 3], ref[W * H * 3];
    uint64_t differ_a = 0, differ_b = 0, peak_shared = 0, peak_alone = 0;
    for (uint32_t f = 0; f < FRAMES; f++) {
        const struct tw_camera a = path.keys[f], b = chase(path.keys[f]);
        struct tw_frame_stats sa, sb, ra, rb;
        /* Each view's image against its own world's. */
        CHECK(tw_world_frame(shared, &a, &sa) == TW_OK);
        CHECK(tw_world_read_rgb(shared, img) == TW_OK);
        CHECK(tw_world_frame(alone_a, &a, &ra) == TW_OK);
        CHECK(tw_world_read_rgb(alone_a, ref) == TW_OK);
        differ_a += memcmp(img, ref, sizeof(img)) != 0;
        CHECK(tw_viewport_frame(vp, &b, &sb) == TW_OK);
        CHECK(tw_world_read_rgb(shared, img) == TW_OK);
        CHECK(tw_world_frame(alone_b, &b, &rb) == TW_OK);
        CHECK(tw_world_read_rgb(alone_b, ref) == TW_OK);
        differ_b += memcmp(img, ref, sizeof(img)) != 0;
        /* Frames counted per view; the same work as alone. */
        CHECK(sa.frame == f + 1 && sb.frame == f + 1);
        CHECK_MSG(sa.triangles == ra.triangles && sb.triangles == rb.triangles,
                  "frame %u: %llu/%llu and %llu/%llu triangles", f,
                  (unsigned long long)sa.triangles, (unsigned long long)ra.triangles,
                  (unsigned long long)sb.triangles, (unsigned long long)rb.triangles);
        peak_shared = bytes_of(&sb) > peak_shared ? bytes_of(&sb) : peak_shared;
        peak_alone = bytes_of(&ra) + bytes_of(&rb) > peak_alone ? bytes_of(&ra) + bytes_of(&rb)
                                                                : peak_alone;
    }
    CHECK_MSG(differ_a == 0 && differ_b == 0, "frames whose image differs: %llu and %llu",
              (unsigned long long)differ_a, (unsigned long long)differ_b);
    struct tw_cache_totals ts, ta, tb;
    CHECK(tw_world_cache_totals(shared, &ts) == TW_OK);
    CHECK(tw_world_cache_totals(alone_a, &ta) == TW_OK);
    CHECK(tw_world_cache_totals(alone_b, &tb) == TW_OK);
    /* The tiles both views see are made once; the memory is not doubled. */
    CHECK_MSG(ts.loads_done < ta.loads_done + tb.loads_done &&
                  ts.loads_done >= (ta.loads_done > tb.loads_done ? ta.loads_done : tb.loads_done),
              "tiles made: %llu shared, %llu + %llu alone", (unsigned long long)ts.loads_done,
              (unsigned long long)ta.loads_done, (unsigned long long)tb.loads_done);
    CHECK_MSG(peak_shared * 10 < peak_alone * 8, "peak bytes: %llu shared, %llu alone (two worlds)",
              (unsigned long long)peak_shared, (unsigned long long)peak_alone);
    printf("views: tiles made %llu shared against %llu + %llu alone; peak bytes %.1f MiB shared "
           "against %.1f MiB for two worlds (%.2f)\n",
           (unsigned long long)ts.loads_done, (unsigned long long)ta.loads_done,
           (unsigned long long)tb.loads_done, (double)peak_shared / 1048576.0,
           (double)peak_alone / 1048576.0, (double)peak_shared / (double)peak_alone);

    /* Under a budget that holds less than the walk needs: a tile that one
     * view drew in its latest frame is never evicted by the other's. */
    tw_viewport_destroy(vp);
    tw_world_destroy(shared);
    s.cache_budget_bytes = peak_shared / 2;
    shared = NULL;
    vp = NULL;
    CHECK(tw_world_create(&s, &shared) == TW_OK && tw_viewport_create(shared, &vp) == TW_OK);
    if (!shared || !vp)
        return check_summary("test-views");
    tw_world_record_draws(shared, true);
    struct tw_cell drawn[2][4096];
    size_t drawn_count[2] = {0, 0};
    uint64_t evicted = 0, lost = 0;
    for (uint32_t f = 0; f < FRAMES; f++) {
        const struct tw_camera b = chase(path.keys[f]);
        for (int view = 0; view < 2; view++) {
            struct tw_frame_stats st;
            CHECK((view == 0 ? tw_world_frame(shared, &path.keys[f], &st)
                             : tw_viewport_frame(vp, &b, &st)) == TW_OK);
            /* Evictions of this frame: none of the other view's last frame. */
            size_t n;
            const struct tw_tile_event *ev = tw_world_tile_events(shared, &n);
            for (size_t k = 0; k < n; k++) {
                if (ev[k].kind != TW_TILE_EVICTED)
                    continue;
                evicted++;
                for (size_t q = 0; q < drawn_count[1 - view]; q++)
                    lost += drawn[1 - view][q].i == ev[k].cell.i &&
                            drawn[1 - view][q].j == ev[k].cell.j;
            }
            const struct tw_drawn_cluster *d = tw_world_drawn(shared, &n);
            drawn_count[view] = 0;
            for (size_t k = 0; k < n && drawn_count[view] < 4096; k++)
                if (k == 0 || d[k].cell.i != d[k - 1].cell.i || d[k].cell.j != d[k - 1].cell.j)
                    drawn[view][drawn_count[view]++] = d[k].cell;
        }
    }
    CHECK(tw_world_cache_totals(shared, &ts) == TW_OK);
    printf("views: under a budget of %.1f MiB: %llu tiles evicted, %llu of them drawn by the "
           "other view's latest frame, %llu reloads\n",
           (double)s.cache_budget_bytes / 1048576.0, (unsigned long long)evicted,
           (unsigned long long)lost, (unsigned long long)ts.reloads);
    CHECK(evicted > 0);
    CHECK_MSG(lost == 0, "%llu tiles the other view drew last were evicted",
              (unsigned long long)lost);

    /* A viewport outlives nothing: destroyed with its world. */
    tw_path_finish(&path);
    tw_world_destroy(shared);
    tw_world_destroy(alone_a);
    tw_world_destroy(alone_b);
    tw_tilesets_provider_destroy(gen);
    tw_context_destroy(ctx);
    return check_summary("test-views");
}
