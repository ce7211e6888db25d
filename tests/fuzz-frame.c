/* Fuzz target for a whole frame: LLVMFuzzerTestOneInput imports the input as
 * glTF (from memory), builds a tileset of it, the Embree BVH of every
 * prototype (bvh/), and runs two frames of tile-query propagation with
 * CHC++ inside every visible tile (cull/), plus a frustum-culled scan and
 * the two HZB methods (over a depth made of the input's hash), from a few
 * cameras, against a deterministic fake query backend. What the
 * glTF target cannot reach: Embree's build on hostile boxes, the cell scan
 * on hostile footprints and common boxes, CHC++ on hostile trees.
 *
 * Checked on the way: every BVH validates, the cell scan stays within
 * TW_TILES_MAX_CELLS_IN_VIEW, every query is read at most once and only
 * after it was issued, every query box is a box, every drawn cluster
 * exists. Built with libFuzzer when TW_LIBFUZZER is defined;
 * otherwise a plain main replays the files and folders given as arguments
 * (seeds: ../shared/assets/bad and models; regressions: tests/corpus/frame). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bvh/bvh.h"
#include "cull/cull.h"
#include "tileworld/tilesets.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

/* ---- the fake query backend --------------------------------------------------------- */

/* Query handles are never recycled: a handle read twice, or never issued,
 * is a bug wherever it happens. */
struct query {
    uint8_t result, polls_left, live;
};

struct fake {
    uint64_t seed;             /* answers are a hash of (seed, query number) */
    struct query *queries;     /* by handle; [0] unused */
    uint32_t issued, cap;
    const struct tw_tileset *ts;
    uint64_t draws, clusters;
    uint64_t depth_reads;
};

static uint32_t fake_issue(void *ctx, const struct tw_box *boxes, uint32_t count,
                           const float offset[3])
{
    struct fake *fk = ctx;
    for (uint32_t k = 0; k < count; k++)
        if (tw_box_is_empty(&boxes[k]))
            abort();
    (void)offset;
    if (fk->issued + 1 >= fk->cap) {
        const uint32_t cap = fk->cap ? 2 * fk->cap : 4096;
        struct query *grown = cap > fk->cap ? realloc(fk->queries, sizeof(*grown) * cap) : NULL;
        if (!grown)
            abort(); /* 2^32 queries: unbounded work */
        memset(grown + fk->cap, 0, sizeof(*grown) * (cap - fk->cap));
        fk->queries = grown;
        fk->cap = cap;
    }
    const uint32_t q = ++fk->issued;
    const uint64_t h = tw_tiles_hash(fk->seed, q, 0);
    fk->queries[q].result = (h & 3) != 0;
    fk->queries[q].polls_left = (uint8_t)(h >> 8 & 3);
    fk->queries[q].live = 1;
    return q;
}

static bool fake_ready(void *ctx, uint32_t q)
{
    struct fake *fk = ctx;
    if (q == 0 || q > fk->issued || !fk->queries[q].live)
        abort();
    if (fk->queries[q].polls_left) {
        fk->queries[q].polls_left--;
        return false;
    }
    return true;
}

static uint32_t fake_wait(void *ctx, uint32_t q)
{
    struct fake *fk = ctx;
    if (q == 0 || q > fk->issued || !fk->queries[q].live)
        abort(); /* read twice, or never issued */
    fk->queries[q].live = 0;
    return fk->queries[q].result;
}

static void fake_draw(void *ctx, struct tw_cell cell, uint32_t prototype, const float offset[3],
                      const uint32_t *clusters, uint32_t count)
{
    struct fake *fk = ctx;
    (void)cell;
    (void)offset;
    if (prototype >= fk->ts->prototype_count)
        abort();
    for (uint32_t k = 0; k < count; k++)
        if (clusters[k] >= fk->ts->prototypes[prototype].cluster_count)
            abort();
    fk->draws++;
    fk->clusters += count;
}

static void fake_flush(void *ctx)
{
    (void)ctx;
}

/* The HZB methods' depth: a small buffer of blocks at depths drawn from the
 * seed and the number of reads (reversed float depth, some of it far). */
static bool fake_read_depth(void *ctx, float *depth, uint32_t *width, uint32_t *height,
                            bool *reversed)
{
    struct fake *fk = ctx;
    *width = 64;
    *height = 36;
    *reversed = true;
    if (depth) {
        fk->depth_reads++;
        for (uint32_t k = 0; k < 64 * 36; k++) {
            const int64_t block = (k % 64) / 8 + (k / 512) * 8;
            const uint64_t h = tw_tiles_hash(fk->seed, (int64_t)fk->depth_reads, block);
            depth[k] = (h & 3) == 0 ? 0.0f : (float)(h >> 40) / (float)(1u << 24);
        }
    }
    return true;
}

/* ---- frames ------------------------------------------------------------------------- */

/* Cameras: in the middle of the tile, above it, far below the ground, far
 * out along a diagonal, and one drawn from the input's hash. */
static void camera(uint64_t h, int k, const struct tw_tileset *ts, struct tw_cell *cell,
                   float eye[3], float *yaw, float *pitch)
{
    const float w = ts->footprint[0], d = ts->footprint[1];
    const struct tw_box *b = &ts->common_box;
    *cell = (struct tw_cell){(int64_t)(h % 7) - 3, (int64_t)(h >> 8 & 0xffffffffu) << 20};
    eye[0] = 0.5f * w;
    eye[1] = 1.7f;
    eye[2] = 0.5f * d;
    *yaw = (float)(h >> 16 & 0x1ff);
    *pitch = (float)((int)(h >> 28 & 0x7f) - 63) * 1.4f;
    switch (k) {
    case 0:
        break;
    case 1:
        eye[1] = b->max[1] + 0.5f * (b->max[1] - b->min[1]) + 1.0f;
        *pitch = -30.0f;
        break;
    case 2:
        eye[1] = -1e5f;
        *pitch = 80.0f;
        break;
    case 3:
        eye[0] = 0.99f * w;
        eye[2] = 0.01f * d;
        *yaw = 45.0f;
        *pitch = 0.0f;
        *cell = (struct tw_cell){INT64_MAX - 2, INT64_MIN + 2};
        break;
    default:
        eye[0] = (float)(h >> 40 & 0xff) / 255.0f * w;
        eye[2] = (float)(h >> 48 & 0xff) / 255.0f * d;
        eye[1] = b->min[1] + (float)(h >> 56) / 255.0f * (b->max[1] - b->min[1] + 2.0f);
        break;
    }
}

/* Frames of every method driver (cull/driver.c, what a world runs) over the
 * tileset as a fixed tile source, against the fake backend. */
static void run_frames(const struct tw_tileset *ts, struct tw_bvh *const *bvhs, uint64_t h)
{
    struct fake fk;
    memset(&fk, 0, sizeof(fk));
    fk.seed = h;
    fk.ts = ts;
    const struct tw_query_backend be = {.ctx = &fk, .issue = fake_issue, .ready = fake_ready,
                                        .wait = fake_wait, .draw = fake_draw,
                                        .flush = fake_flush, .read_depth = fake_read_depth};
    static const enum tw_cull_method methods[] = {TW_CULL_TILEQUERY_CHC, TW_CULL_VFC,
                                                  TW_CULL_CHC, TW_CULL_TILEQUERY,
                                                  TW_CULL_HZB, TW_CULL_TILEQUERY_HZB};
    enum { METHODS = sizeof(methods) / sizeof(methods[0]) };
    struct tw_cull_driver *drivers[METHODS] = {NULL};
    const struct tw_selection sel = {0};
    const struct tw_cull_fixed fixed = {ts, &sel, bvhs, NULL};
    const struct tw_cull_grid grid = tw_cull_fixed_grid(&fixed);
    struct tw_cull_cells cells = {0};
    for (uint32_t m = 0; m < METHODS; m++) {
        const struct tw_cull_driver_settings ds = {
            .method = methods[m],
            .evict_after_frames = 4,
            .tilequery = {(uint32_t)(h & 1) ? 8u : 4u, 0},
        };
        if (tw_cull_driver_create(&ds, &drivers[m]))
            goto out;
    }
    /* Propagation visits every visible cell within reach: a world runs only
     * where the reach is within the per-frame limit (tiles.h), which is what
     * it refuses otherwise; the scan of the others is bounded whatever the
     * reach. */
    uint64_t frame = 0;
    for (int k = 0; k < 5; k++) {
        struct tw_cell cell;
        float eye[3], yaw, pitch;
        camera(h, k, ts, &cell, eye, &yaw, &pitch);
        const float view_distance = k == 4 ? 2000.0f : 600.0f;
        const double reach = tw_tiles_cells_in_reach(&ts->common_box, ts->footprint[0],
                                                     ts->footprint[1], view_distance);
        const bool within = reach <= TW_TILES_MAX_CELLS_IN_VIEW;
        /* Thousands of tiles in reach: one frame of every method, at the
         * first view. Ten frames of six methods over tens of thousands of
         * tiles spent 19 s of CPU on one input under the sanitizers (a 25 s
         * libFuzzer timeout on a loaded machine); the frames after the first,
         * temporal coherence, are exercised by every smaller input. */
        const bool heavy = reach > 4096.0;
        if (heavy && frame > 0)
            break;
        for (int again = 0; again < (heavy ? 1 : 2); again++) {
            struct tw_view v;
            tw_cull_view_setup(&v, cell, eye, yaw, pitch, 60.0f, 16.0f / 9.0f, 0.2f,
                               view_distance + 1000.0f);
            v.view_distance = view_distance;
            v.frame = ++frame;
            for (uint32_t m = 0; m < METHODS; m++) {
                /* Beyond reach (what a world refuses) one frame of vfc shows
                 * that the scan stops at the limit; more would spend seconds
                 * an input on up to 65 536 tiles of tiny clusters (a
                 * libFuzzer timeout in CI on kenney's grass-trees.glb). */
                if (!within && (methods[m] != TW_CULL_VFC || frame > 1))
                    continue;
                struct tw_cull_frame_stats st;
                tw_cull_driver_frame(drivers[m], &v, &grid, &be, &cells, &st);
                if (cells.count > TW_TILES_MAX_CELLS_IN_VIEW)
                    abort();
            }
            eye[0] += 0.37f * ts->footprint[0];
            yaw += 7.0f;
        }
    }
out:
    for (uint32_t m = 0; m < METHODS; m++)
        tw_cull_driver_destroy(drivers[m]);
    tw_cull_cells_finish(&cells);
    free(fk.queries);
}

/* ---- the target ------------------------------------------------------------------------- */

/* One Embree device for the whole run: creating one per input would cost
 * more than the input. */
static struct tw_bvh_builder *builder(void)
{
    static struct tw_bvh_builder *b;
    if (!b && tw_bvh_builder_create(NULL, 0, &b))
        abort();
    return b;
}

static void exercise(const struct tw_gltf_scene *scene, uint64_t h)
{
    /* A footprint a little larger than the scene (as a manifest would
     * choose), or a hostile one. */
    const struct tw_box *b = &scene->bounds;
    float w = fmaxf(b->max[0] - b->min[0], 1.0f) * 1.25f;
    float d = fmaxf(b->max[2] - b->min[2], 1.0f) * 1.25f;
    float s = 1.0f;
    if ((h & 7) == 0) {
        /* Centimetre tiles, the scene shrunk into one. */
        w = 0.01f;
        d = 0.02f;
        s = 0.008f / fmaxf(fmaxf(b->max[0] - b->min[0], b->max[2] - b->min[2]), 1e-3f);
    }
    struct tw_tileset *ts = NULL;
    struct tw_gltf_binding bind;
    const float placement[12] = {s, 0, 0, -b->min[0] * s, 0, s, 0, 0, 0, 0, s, -b->min[2] * s};
    if (tw_tileset_create("fuzz", w, d, &ts) == 0 && tw_tileset_add_prototype(ts, "a", 1) == 0 &&
        tw_tileset_add_prototype(ts, "b", 3) == 1 && tw_gltf_bind(scene, ts, &bind) == 0 &&
        tw_gltf_place(scene, &bind, ts, 0, placement) == 0 &&
        tw_gltf_place(scene, &bind, ts, 1, NULL) == 0 &&
        tw_tileset_finish(ts, (h >> 3 & 1) ? 16 : 256) == 0) {
        struct tw_bvh *bvhs[2] = {NULL, NULL};
        bool built = true;
        for (uint32_t p = 0; p < 2 && built; p++) {
            struct tw_bvh_settings bs = {0};
            bs.max_depth = (h >> 4 & 1) ? 4 : 0;
            built = tw_bvh_build(builder(), &ts->prototypes[p], &bs, &bvhs[p]) == 0;
            tw_bvh_default_settings(&bs);
            char why[256];
            if (built && tw_bvh_validate(bvhs[p], &ts->prototypes[p], bs.max_depth, why,
                                         sizeof(why)) != 0) {
                fprintf(stderr, "fuzz-frame: invalid BVH: %s\n", why);
                abort();
            }
        }
        if (built)
            run_frames(ts, bvhs, h);
        tw_bvh_destroy(bvhs[0]);
        tw_bvh_destroy(bvhs[1]);
    }
    tw_tileset_destroy(ts);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    const struct tw_gltf_settings limits = {16u << 20, 1u << 18};
    struct tw_gltf_scene *scene = NULL;
    uint64_t h = 0x9e3779b97f4a7c15ull;
    for (size_t k = 0; k < size; k++)
        h = (h ^ data[k]) * 0x100000001b3ull;
    if (tw_gltf_import_memory(data, size, "fuzz-input", NULL, &limits, NULL, &scene) == 0)
        exercise(scene, h);
    tw_gltf_scene_destroy(scene);
    return 0;
}

#ifndef TW_LIBFUZZER
#include "tests/fuzz-driver.h"
#include "tiles/tiles-internal.h"

int main(int argc, char **argv)
{
    struct fuzz_driver d = {.target = "fuzz-frame"};
    const int rc = fuzz_driver_main(argc, argv, &d);
    tw_bvh_builder_destroy(builder());
    return rc;
}
#endif
