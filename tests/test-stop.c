/*
 * A world destroyed while its workers build a tile's levels of detail
 * (DESIGN §12, §17), headless GL: the workers stop there (tw_lods_build's
 * stop, which test-lod checks on its own), so the destroy does not wait
 * out what the levels take, and no worker is left behind to run on after
 * the program returns: a worker left in Embree at exit aborts the program
 * (CI's ThreadSanitizer run of test-tiles3d-nginx did).
 *
 * A program of its own, not a part of test-stream: under ThreadSanitizer
 * each world's first shader compiles in llvmpipe (LLVM's JIT) leave a lock
 * on the render thread's list that the deadlock detector never sees
 * released, and one more world there went past its 64 locks a thread.
 */
#include <stdatomic.h>
#include <stdio.h>
#include <time.h>

#include "tests/captured-log.h"
#include "tests/check.h"
#include "tests/meshes.h"
#include "tiles/tiles-internal.h"
#include "tileworld/context.h"
#include "tileworld/runtime.h"

#define W 160
#define H 90
#define FOOTPRINT 40.0f
#define ROUGH_N 160     /* quads a side: one tile's levels take about 0.57 s of CPU time here */

static double now_s(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

struct rough {
    atomic_uint returned;
};

static int generate_rough(void *user, struct tw_cell cell, struct tw_tileset *ts)
{
    struct rough *r = user;
    const int proto = tw_tileset_add_prototype(ts, "rough", 1.0f);
    const bool ok = add_rough_ground(ts, proto, ROUGH_N, FOOTPRINT, 8,
                                     tw_tiles_hash(99, cell.i, cell.j));
    atomic_fetch_add(&r->returned, 1u);
    return ok ? TW_OK : TW_ERR_NOMEM;
}

/* The destroy comes as both workers leave generate(): what follows it
 * before the levels (the tile's clusters and BVH) does not stop. Here the
 * levels would finish within the timeout anyway; under ThreadSanitizer
 * they take far longer than it, and without the stop the workers were
 * left behind. */
static void test_stop_levels(struct tw_context *ctx)
{
    static struct rough r;
    atomic_init(&r.returned, 0u);
    const struct tw_tile_provider p = {
        .name = "rough",
        .footprint = {FOOTPRINT, FOOTPRINT},
        .bound = {{0.0f, 0.0f, 0.0f}, {FOOTPRINT, 4.0f, FOOTPRINT}},
        .generate = generate_rough,
        .user = &r,
    };
    struct captured_log cap = {0};
    struct tw_world_settings s = {0};
    s.provider = &p;
    s.workers = 2;
    s.policy = TW_STREAM_SKIP;      /* the frame does not wait for the tiles */
    s.width = W;
    s.height = H;
    s.view_distance = 300.0f;
    s.deterministic = true;
    s.get_proc = tw_context_get_proc(ctx);
    s.log = (struct tw_log){capture, &cap};
    struct tw_world *w = NULL;
    CHECK(tw_world_create(&s, &w) == TW_OK);
    if (!w)
        return;
    CHECK(tw_world_settings(w)->shutdown_timeout_ms == 5000);
    const struct tw_camera cam = {.pos = {.cell = {0, 0}, .local = {1.0f, 1.7f, 1.0f}}};
    CHECK(tw_world_frame(w, &cam, NULL) == TW_OK);
    const double end = now_s() + 120.0;
    while (atomic_load(&r.returned) < 2 && now_s() < end) {
        const struct timespec t = {0, 1000000L};
        nanosleep(&t, NULL);
    }
    CHECK(atomic_load(&r.returned) >= 2);
    const double t0 = now_s();
    const uint32_t left = tw_world_destroy(w);
    const double waited = now_s() - t0;
    CHECK_MSG(left == 0 && cap.errors == 0, "%u left behind: \"%s\"", left, cap.last);
    printf("levels stopped: destroyed in %.3f s, %u workers left behind\n", waited, left);
}

int main(void)
{
    struct tw_context *ctx = NULL;
    if (tw_context_create_headless(W, H, NULL, &ctx) != TW_OK) {
        fprintf(stderr, "test-stop: no headless context\n");
        return 1;
    }
    test_stop_levels(ctx);
    tw_context_destroy(ctx);
    return check_summary("test-stop");
}
