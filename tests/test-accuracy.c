/* GL accuracy suite (DESIGN.md §8, §11): on every frame of short walks along
 * each built-in path, every conservative method draws every cluster the
 * oracle's ID pass sees (missed_pixels = 0), and the oracle method itself
 * draws exactly the visible clusters (no overdraw, nothing missed). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tileworld/context.h"
#include "tileworld/runtime.h"
#include "tileworld/tilesets.h"
#include "tests/check.h"

enum { W = 160, H = 90 };

static void log_stderr(void *user, enum tw_log_level level, const char *msg)
{
    (void)user;
    if (level <= TW_LOG_WARN)
        fprintf(stderr, "log: %s\n", msg);
}

/* Walks frames [first, frames) of a built-in path: the frames before first
 * are skipped, not rendered, so a test can start just before a teleport or a
 * spin. */
static void walk(struct tw_context *ctx, const char *tileset, const char *path_name,
                 uint32_t first, uint32_t frames)
{
    const struct tw_log log = {log_stderr, NULL};
    struct tw_tileset *ts = NULL;
    if (tw_tilesets_builtin(tileset, 3, 0, &log, &ts) != TW_OK) {
        fprintf(stderr, "cannot build tileset %s\n", tileset);
        failures++;
        return;
    }
    struct tw_path path;
    CHECK(tw_path_builtin(path_name, 3, frames, ts->footprint[0], ts->footprint[1], &path) == TW_OK);
    struct tw_world_settings s = {0};
    s.tileset = ts;
    s.selection.seed = 3;
    s.width = W;
    s.height = H;
    s.view_distance = 500.0f;
    s.verify = true;
    s.get_proc = tw_context_get_proc(ctx);
    s.log = log;
    struct tw_world *w = NULL;
    CHECK(tw_world_create(&s, &w) == TW_OK);
    const enum tw_method methods[] = {TW_METHOD_VFC, TW_METHOD_CHC, TW_METHOD_TILEQUERY,
                                      TW_METHOD_TILEQUERY_CHC, TW_METHOD_ORACLE};
    uint64_t missed[5] = {0}, triangles[5] = {0}, overdraw[5] = {0};
    for (uint32_t f = first; w && f < path.count; f++) {
        for (size_t m = 0; m < 5; m++) {
            struct tw_frame_stats st;
            CHECK(tw_world_set_method(w, methods[m]) == TW_OK);
            CHECK(tw_world_frame(w, &path.keys[f], &st) == TW_OK);
            if (st.missed_pixels != 0)
                fprintf(stderr, "%s/%s frame %u: %s missed %llu pixels in %u clusters\n", tileset,
                        path_name, f, tw_method_name(methods[m]),
                        (unsigned long long)st.missed_pixels, st.missed_clusters);
            CHECK(st.missed_pixels == 0 && st.missed_clusters == 0);
            if (methods[m] == TW_METHOD_ORACLE)
                CHECK(st.overdraw_triangles == 0);
            missed[m] += st.missed_pixels;
            triangles[m] += st.triangles;
            overdraw[m] += st.overdraw_triangles;
        }
    }
    /* The methods really cull: fewer triangles than vfc over the walk. */
    CHECK(triangles[4] <= triangles[1] && triangles[1] <= triangles[0]);
    CHECK(triangles[3] < triangles[0]);
    printf("%-7s %-9s frames %u-%u:", tileset, path_name, first, path.count - 1);
    for (size_t m = 0; m < 5; m++)
        printf(" %s %.0f%%", tw_method_name(methods[m]),
               triangles[0] ? 100.0 * (double)triangles[m] / (double)triangles[0] : 0.0);
    printf(" of vfc's triangles; oracle overdraw %llu\n", (unsigned long long)overdraw[4]);
    tw_world_destroy(w);
    tw_path_finish(&path);
    tw_tileset_destroy(ts);
}

int main(void)
{
    struct tw_context *ctx = NULL;
    if (tw_context_create_headless(W, H, NULL, &ctx) != TW_OK) {
        fprintf(stderr, "cannot create the headless context\n");
        return 1;
    }
    walk(ctx, "city", "street", 0, 16);
    walk(ctx, "city", "flyover", 0, 16);
    walk(ctx, "city", "flyover", 200, 208);  /* high up: grazing, little occlusion */
    walk(ctx, "city", "teleport", 46, 56);   /* the jump at frame 50 */
    walk(ctx, "city", "spin", 38, 48);       /* the 180-degree turn in frames 40-45 */
    walk(ctx, "forest", "forest", 0, 16);
    walk(ctx, "hybrid", "street", 0, 16);
    tw_context_destroy(ctx);
    if (failures) {
        fprintf(stderr, "test-accuracy: %d checks failed\n", failures);
        return 1;
    }
    printf("test-accuracy: all checks passed\n");
    return 0;
}
