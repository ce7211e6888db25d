/* GL accuracy suite (DESIGN.md §8, §11), quick (the slow suite's
 * test-accuracy-slow.sh runs the long walks at 640x360):
 *   - on every frame of short walks along each built-in path, every
 *     conservative method draws every cluster the oracle's ID pass sees
 *     (0 missed pixels, 0 depth errors at the default tolerance), and the
 *     oracle method itself draws exactly the visible clusters (no overdraw);
 *   - the box oracle draws the visible clusters and the ones whose own
 *     boxes show in front of the true depth, and every other method draws
 *     at least that set (it is their floor);
 *   - the ID pass rasterises what the normal pass does: vfc and the oracle,
 *     which draw the same fragments, differ from it in no pixel's depth even
 *     at a tolerance of 1e-30, over fixed views and a flyover window;
 *   - the metric catches real errors: with every query box shrunk
 *     (mutate_query_shrink 0.1 and 0.02, a deliberately broken culler) chc
 *     and tilequery+chc miss pixels and clusters, and without it they miss
 *     none.
 * Every world runs with settings.deterministic, so that the counts do not
 * depend on the GPU's timing: a failure repeats. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tests/check.h"
#include "tests/headless-world.h"
#include "tiles/tiles-internal.h"

enum { W = 160, H = 90 };

/* The settings every test starts from; change a copy. */
static struct tw_world_settings base_settings(struct tw_context *ctx, const struct tw_tileset *ts)
{
    struct tw_world_settings s = world_settings(ctx, ts, W, H, 3, 500.0f);
    s.verify = true;
    s.deterministic = true;
    return s;
}

static bool load_path(const char *name, uint32_t frames, const struct tw_tileset *ts,
                      struct tw_path *path)
{
    const int rc = tw_path_builtin(name, 3, frames, 0.0f, ts->footprint[0], ts->footprint[1], path);
    CHECK(rc == TW_OK);
    return rc == TW_OK;
}

/* Orders drawn clusters by cell, content and cluster (for bsearch). */
static int cmp_drawn(const void *a, const void *b)
{
    const struct tw_drawn_cluster *x = a, *y = b;
    if (x->cell.i != y->cell.i)
        return x->cell.i < y->cell.i ? -1 : 1;
    if (x->cell.j != y->cell.j)
        return x->cell.j < y->cell.j ? -1 : 1;
    if (x->prototype != y->prototype)
        return x->prototype < y->prototype ? -1 : 1;
    return (x->cluster > y->cluster) - (x->cluster < y->cluster);
}

/* How many clusters of floor (sorted) the last frame of w did not draw. */
static size_t not_drawn(const struct tw_world *w, const struct tw_drawn_cluster *floor, size_t n)
{
    size_t count = 0;
    const struct tw_drawn_cluster *d = tw_world_drawn(w, &count);
    struct tw_drawn_cluster *sorted = malloc(sizeof(*sorted) * (count ? count : 1));
    CHECK(sorted != NULL);
    if (!sorted)
        return n;
    memcpy(sorted, d, sizeof(*sorted) * count);
    qsort(sorted, count, sizeof(*sorted), cmp_drawn);
    size_t missing = 0;
    for (size_t k = 0; k < n; k++)
        missing += !bsearch(&floor[k], sorted, count, sizeof(*sorted), cmp_drawn);
    free(sorted);
    return missing;
}

enum { METHODS = 8, VFC = 0, ORACLE = 4, BOX_ORACLE = 7 };

/* Walks frames [first, frames) of a built-in path with every method: the
 * frames before first are skipped, not rendered, so a walk can start just
 * before a teleport or a spin. The box oracle runs first on each view: every
 * other conservative method, which culls only by queries or depth tests of
 * boxes that contain the clusters' own, must draw at least its set. */
static void walk(struct tw_context *ctx, const struct tw_tileset *ts, const char *path_name,
                 uint32_t first, uint32_t frames)
{
    struct tw_path path;
    if (!load_path(path_name, frames, ts, &path))
        return;
    const struct tw_world_settings s = base_settings(ctx, ts);
    struct tw_world *w = NULL;
    CHECK(tw_world_create(&s, &w) == TW_OK);
    if (w)
        tw_world_record_draws(w, true);  /* the box oracle's draws are the floor */
    const enum tw_method methods[METHODS] = {
        TW_METHOD_VFC, TW_METHOD_CHC, TW_METHOD_TILEQUERY, TW_METHOD_TILEQUERY_CHC,
        TW_METHOD_ORACLE, TW_METHOD_HZB, TW_METHOD_TILEQUERY_HZB, TW_METHOD_BOX_ORACLE};
    static const size_t order[METHODS] = {BOX_ORACLE, 0, 1, 2, 3, 4, 5, 6};
    uint64_t triangles[METHODS] = {0}, overdraw[METHODS] = {0}, box_overdraw[METHODS] = {0};
    uint64_t below_floor[METHODS] = {0}, floor_clusters = 0;
    struct tw_drawn_cluster *floor = NULL;
    size_t floor_count = 0;
    for (uint32_t f = first; w && f < path.count; f++) {
        struct tw_frame_stats frame[METHODS];
        for (size_t k = 0; k < METHODS; k++) {
            const size_t m = order[k];
            struct tw_frame_stats *st = &frame[m];
            CHECK(tw_world_set_method_or_limit(w, methods[m]) == TW_OK);
            CHECK(tw_world_frame(w, &path.keys[f], st) == TW_OK);
            if (st->missed_pixels != 0 || st->depth_errors != 0)
                fprintf(stderr, "%s/%s frame %u: %s missed %llu pixels in %u clusters, "
                        "%llu depth errors\n", ts->name, path_name, f,
                        tw_method_name(methods[m]), (unsigned long long)st->missed_pixels,
                        st->missed_clusters, (unsigned long long)st->depth_errors);
            CHECK(tw_method_conservative(methods[m], tw_world_tuning(w)));
            CHECK(st->missed_pixels == 0 && st->missed_clusters == 0);
            CHECK(st->depth_errors == 0);
            if (methods[m] == TW_METHOD_ORACLE)
                CHECK(st->overdraw_triangles == 0);
            CHECK(st->overdraw_box_triangles <= st->overdraw_triangles);
            if (m == BOX_ORACLE) {
                /* All it overdraws shows its box. */
                CHECK(st->overdraw_box_triangles == st->overdraw_triangles);
                const struct tw_drawn_cluster *d = tw_world_drawn(w, &floor_count);
                free(floor);
                floor = malloc(sizeof(*floor) * (floor_count ? floor_count : 1));
                CHECK(floor != NULL);
                if (!floor)
                    floor_count = 0;
                else if (floor_count)
                    memcpy(floor, d, sizeof(*floor) * floor_count);
                qsort(floor, floor_count, sizeof(*floor), cmp_drawn);
                floor_clusters += floor_count;
            } else if (!tw_method_limit(methods[m])) {
                const size_t missing = not_drawn(w, floor, floor_count);
                if (missing)
                    fprintf(stderr, "%s/%s frame %u: %s did not draw %zu of the box oracle's "
                            "%zu clusters\n", ts->name, path_name, f,
                            tw_method_name(methods[m]), missing, floor_count);
                below_floor[m] += missing;
            }
            triangles[m] += st->triangles;
            overdraw[m] += st->overdraw_triangles;
            box_overdraw[m] += st->overdraw_box_triangles;
        }
        /* The box oracle draws the visible clusters and, of the rest, what
         * vfc overdraws with boxes that show: the same box test. */
        CHECK(frame[BOX_ORACLE].overdraw_triangles == frame[VFC].overdraw_box_triangles);
        CHECK(frame[ORACLE].triangles <= frame[BOX_ORACLE].triangles &&
              frame[BOX_ORACLE].triangles <= frame[VFC].triangles);
    }
    /* No conservative method that culls by boxes draws less than the box
     * oracle. */
    for (size_t m = 0; m < METHODS; m++)
        CHECK(below_floor[m] == 0);
    /* vfc draws hidden clusters of both kinds: some whose boxes show in
     * front of the true depth (a query could not cull them), and more
     * whose boxes are hidden too. */
    CHECK(box_overdraw[VFC] > 0 && box_overdraw[VFC] < overdraw[VFC]);
    /* The methods really cull: fewer triangles than vfc over the walk. */
    CHECK(triangles[ORACLE] <= triangles[1] && triangles[1] <= triangles[VFC]);
    CHECK(triangles[3] < triangles[VFC]);
    printf("%-7s %-9s frames %u-%u:", ts->name, path_name, first, path.count - 1);
    for (size_t m = 0; m < METHODS; m++)
        printf(" %s %.0f%%", tw_method_name(methods[m]),
               triangles[VFC] ? 100.0 * (double)triangles[m] / (double)triangles[VFC] : 0.0);
    printf(" of vfc's triangles; oracle overdraw %llu; overdraw whose box shows:",
           (unsigned long long)overdraw[ORACLE]);
    for (size_t m = 0; m < METHODS; m++)
        if (!tw_method_limit(methods[m]))
            printf(" %s %.0f%%", tw_method_name(methods[m]),
                   overdraw[m] ? 100.0 * (double)box_overdraw[m] / (double)overdraw[m] : 0.0);
    uint64_t below = 0;
    for (size_t m = 0; m < METHODS; m++)
        below += below_floor[m];
    printf("; box oracle %llu clusters, %llu of them not drawn by a method\n",
           (unsigned long long)floor_clusters, (unsigned long long)below);
    CHECK(floor_clusters > 0);
    free(floor);
    tw_world_destroy(w);
    tw_path_finish(&path);
}

/* vfc and the oracle draw, at every pixel, the fragment the ID pass keeps:
 * not one depth differs, at any tolerance. */
static void identity(struct tw_context *ctx, const struct tw_tileset *ts)
{
    /* Fixed views at cell (0, 0): along a street at eye height, up at the
     * buildings, down from above, grazing from high up, against a wall. */
    const struct tw_camera views[] = {
        {{{0, 0}, {0.0f, 1.7f, 2.0f}}, 0.0f, 0.0f},
        {{{0, 0}, {0.0f, 1.7f, 20.0f}}, 45.0f, 25.0f},
        {{{0, 0}, {30.0f, 120.0f, 30.0f}}, 30.0f, -60.0f},
        {{{0, 0}, {10.0f, 300.0f, -50.0f}}, 60.0f, -4.0f},
        {{{0, 0}, {0.0f, 1.7f, 40.0f}}, 90.0f, 0.0f},
        {{{0, 0}, {0.0f, 1.7f, 40.0f}}, 270.0f, -10.0f},
    };
    const size_t nviews = sizeof(views) / sizeof(views[0]);
    struct tw_path flyover;
    if (!load_path("flyover", 156, ts, &flyover))
        return;
    struct tw_world_settings s = base_settings(ctx, ts);
    s.verify_tolerance = 1e-30f;
    struct tw_world *w = NULL;
    CHECK(tw_world_create(&s, &w) == TW_OK);
    const enum tw_method methods[] = {TW_METHOD_VFC, TW_METHOD_ORACLE};
    uint64_t errors[2] = {0}, frames = 0;
    /* The fixed views, then a window of the flyover as it rises. */
    for (size_t k = 0; w && k < nviews + 12; k++) {
        const struct tw_camera *cam = k < nviews ? &views[k] : &flyover.keys[144 + (k - nviews)];
        for (size_t m = 0; m < 2; m++) {
            struct tw_frame_stats st;
            CHECK(tw_world_set_method_or_limit(w, methods[m]) == TW_OK);
            CHECK(tw_world_frame(w, cam, &st) == TW_OK);
            if (st.depth_errors != 0)
                fprintf(stderr, "identity: %s view %zu: %llu pixels' depths differ from the ID "
                        "pass's\n", tw_method_name(methods[m]), k,
                        (unsigned long long)st.depth_errors);
            CHECK(st.depth_errors == 0);
            CHECK(st.missed_pixels == 0);
            CHECK(st.triangles > 0);
            errors[m] += st.depth_errors;
        }
        frames++;
    }
    printf("identity: %llu views, vfc %llu and oracle %llu depth differences at tolerance 1e-30\n",
           (unsigned long long)frames, (unsigned long long)errors[0],
           (unsigned long long)errors[1]);
    tw_world_destroy(w);
    tw_path_finish(&flyover);
}

/* Missed pixels and clusters of chc and tilequery+chc over frames of the
 * street walk with query boxes shrunk by shrink. */
static void mutated_walk(struct tw_context *ctx, const struct tw_tileset *ts, float shrink,
                         uint32_t frames, uint64_t missed[2], uint64_t clusters[2])
{
    missed[0] = missed[1] = clusters[0] = clusters[1] = 0;
    struct tw_path path;
    if (!load_path("street", frames, ts, &path))
        return;
    struct tw_world_settings s = base_settings(ctx, ts);
    /* At full detail: at 160x90 and 1 px the street's tiles are drawn at
     * levels of a few large clusters each, whose fringe a shrunk query
     * seldom hides (a shrink of 0.1 went unseen by tilequery+chc over the
     * 12 frames); the finest clusters show what a shrink does. */
    s.max_screen_error = TW_FULL_DETAIL;
    const struct tw_world_tuning t = {.mutate_query_shrink = shrink};
    struct tw_world *w = NULL;
    CHECK(tw_world_create_tuned(&s, &t, &w) == TW_OK);
    const enum tw_method methods[] = {TW_METHOD_CHC, TW_METHOD_TILEQUERY_CHC};
    for (uint32_t f = 0; w && f < path.count; f++)
        for (size_t m = 0; m < 2; m++) {
            struct tw_frame_stats st;
            CHECK(tw_world_set_method_or_limit(w, methods[m]) == TW_OK);
            CHECK(tw_world_frame(w, &path.keys[f], &st) == TW_OK);
            /* A missed pixel is a depth error too (what is shown lies farther). */
            CHECK(st.depth_errors >= st.missed_pixels);
            CHECK((st.missed_pixels > 0) == (st.missed_clusters > 0));
            missed[m] += st.missed_pixels;
            clusters[m] += st.missed_clusters;
        }
    tw_world_destroy(w);
    tw_path_finish(&path);
}

static void mutation(struct tw_context *ctx, const struct tw_tileset *ts)
{
    /* A small shrink hides only a cluster's fringe, a few pixels at this
     * size: it walks longer. */
    const float shrinks[] = {0.0f, 0.1f, 0.02f};
    const uint32_t walk_frames[] = {12, 12, 30};
    for (size_t k = 0; k < 3; k++) {
        uint64_t missed[2], clusters[2];
        const uint32_t frames = walk_frames[k];
        mutated_walk(ctx, ts, shrinks[k], frames, missed, clusters);
        printf("mutation: query boxes shrunk by %.2f: chc missed %llu pixels in %llu clusters, "
               "tilequery+chc %llu pixels in %llu clusters over %u frames\n", shrinks[k],
               (unsigned long long)missed[0], (unsigned long long)clusters[0],
               (unsigned long long)missed[1], (unsigned long long)clusters[1], frames);
        for (size_t m = 0; m < 2; m++) {
            if (shrinks[k] == 0.0f) {
                CHECK(missed[m] == 0 && clusters[m] == 0);
            } else {
                CHECK(missed[m] > 0);
                CHECK(clusters[m] > 0);
            }
        }
    }
}

int main(void)
{
    static const char *const names[] = {"city", "forest", "hybrid"};
    struct tw_context *ctx = NULL;
    struct tw_tileset *ts[3] = {NULL};
    if (!open_headless(W, H, names[0], 3, &ctx, &ts[0]))
        return 1;
    for (size_t k = 1; k < 3; k++)
        if (tw_tilesets_builtin(names[k], 3, 0, &test_log, &ts[k]) != TW_OK) {
            fprintf(stderr, "cannot build tileset %s\n", names[k]);
            return 1;
        }
    walk(ctx, ts[0], "street", 0, 10);
    walk(ctx, ts[0], "flyover", 0, 8);
    walk(ctx, ts[0], "flyover", 200, 206);  /* high up: grazing, little occlusion */
    walk(ctx, ts[0], "teleport", 47, 53);   /* the jump at frame 50 */
    walk(ctx, ts[0], "spin", 39, 47);       /* the 180-degree turn in frames 40-45 */
    walk(ctx, ts[1], "forest", 0, 8);
    walk(ctx, ts[2], "street", 0, 8);
    identity(ctx, ts[0]);
    mutation(ctx, ts[0]);
    for (size_t k = 0; k < 3; k++)
        tw_tileset_destroy(ts[k]);
    tw_context_destroy(ctx);
    return check_summary("test-accuracy");
}
