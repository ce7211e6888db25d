/*
 * Tile-query propagation (DESIGN.md §4) against a deterministic fake query
 * backend. The fake decides visibility with a 2D side view: an infinitely
 * wide wall at z = wall_z with height wall_h hides whatever lies below the
 * line from the eye over its top. Results become ready after a set number
 * of ready() polls.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cull/cull-private.h"
#include "tests/check.h"
#include "tiles/tiles-internal.h"

enum { MAX_QUERIES = 100000, MAX_LOG = 4096 };

struct fake {
    /* the scene */
    float eye_y, eye_z;
    float wall_z, wall_h;
    /* queries */
    bool result[MAX_QUERIES];
    int polls_left[MAX_QUERIES];
    bool read[MAX_QUERIES];
    uint32_t sent_by[MAX_QUERIES]; /* the flushes there had been when it was issued */
    uint32_t issued;
    uint32_t flushes;              /* this frame's */
    uint32_t flushes_total;
    uint32_t unsent_reads;         /* waits on a query no flush had sent yet */
    int delay;                 /* ready() polls before a result is available; < 0: never */
    /* what happened this frame */
    struct tw_cell queried[MAX_LOG];
    uint32_t queried_count;
    struct tw_cell rendered[MAX_LOG];
    uint32_t rendered_count;
    uint32_t waits;
    struct tw_tile_cache *cache;
    uint64_t frame;
    uint32_t tiles_new;
};

/* Is any point of the box above the line from the eye over the wall top? */
static bool box_visible(const struct fake *fk, const struct tw_box *b, const float off[3])
{
    const float z0 = b->min[2] + off[2], z1 = b->max[2] + off[2], top = b->max[1] + off[1];
    if (z1 <= fk->wall_z || fk->eye_z >= fk->wall_z)
        return true;
    const float slope = (fk->wall_h - fk->eye_y) / (fk->wall_z - fk->eye_z);
    const float za = z0 > fk->wall_z ? z0 : fk->wall_z;
    const float ray_a = fk->wall_h + slope * (za - fk->wall_z);
    const float ray_b = fk->wall_h + slope * (z1 - fk->wall_z);
    return top > (ray_a < ray_b ? ray_a : ray_b);
}

static uint32_t fake_issue(void *ctx, const struct tw_box *boxes, uint32_t count, const float off[3])
{
    struct fake *fk = ctx;
    /* Handles recycle: a query lives a frame or two, far fewer than MAX_QUERIES. */
    const uint32_t q = fk->issued++ % (MAX_QUERIES - 1) + 1;
    bool vis = false;
    for (uint32_t k = 0; k < count; k++)
        vis |= box_visible(fk, &boxes[k], off);
    fk->result[q] = vis;
    fk->polls_left[q] = fk->delay;
    fk->read[q] = false;
    fk->sent_by[q] = fk->flushes_total;
    /* The cell is recovered from the offset (footprint 10). */
    if (fk->queried_count < MAX_LOG)
        fk->queried[fk->queried_count++] = (struct tw_cell){(int64_t)lroundf(off[0] / 10.0f),
                                                            (int64_t)lroundf(off[2] / 10.0f)};
    return q;
}

static bool fake_ready(void *ctx, uint32_t q)
{
    struct fake *fk = ctx;
    if (fk->polls_left[q] < 0)
        return false;
    if (fk->polls_left[q] > 0) {
        fk->polls_left[q]--;
        return false;
    }
    return true;
}

static uint32_t fake_wait(void *ctx, uint32_t q)
{
    struct fake *fk = ctx;
    if (fk->read[q]) {
        fprintf(stderr, "query %u read twice\n", q);
        failures++;
    }
    fk->read[q] = true;
    fk->waits++;
    fk->unsent_reads += fk->sent_by[q] == fk->flushes_total;
    return fk->result[q] ? 1 : 0;
}

static void fake_draw(void *ctx, struct tw_cell cell, uint32_t p, const float off[3],
                      const uint32_t *clusters, uint32_t count)
{
    (void)ctx; (void)cell; (void)p; (void)off; (void)clusters; (void)count;
}

static void fake_flush(void *ctx)
{
    struct fake *fk = ctx;
    fk->flushes++;
    fk->flushes_total++;
}

static void render(void *user, struct tw_cell cell, uint32_t level, const float off[3],
                   uint32_t condition)
{
    (void)off;
    (void)condition;
    struct fake *fk = user;
    if (fk->rendered_count < MAX_LOG)
        fk->rendered[fk->rendered_count++] = cell;
    if (fk->cache) {
        struct tw_tile_handle h;
        bool created;
        if (tw_tile_cache_acquire(fk->cache, cell, 0, 256, fk->frame, &h, &created) == TW_OK && created)
            fk->tiles_new++;
    }
}

static bool was_rendered(const struct fake *fk, struct tw_cell c)
{
    for (uint32_t k = 0; k < fk->rendered_count; k++)
        if (fk->rendered[k].i == c.i && fk->rendered[k].j == c.j)
            return true;
    return false;
}

static bool was_queried(const struct fake *fk, struct tw_cell c)
{
    for (uint32_t k = 0; k < fk->queried_count; k++)
        if (fk->queried[k].i == c.i && fk->queried[k].j == c.j)
            return true;
    return false;
}

static const struct tw_box common = {{0, 0, 0}, {10, 20, 10}};

static int run_frame(struct tw_tilequery *tq, struct fake *fk, uint64_t frame, float eye_x,
                     float eye_y, float eye_z, float pitch, float view_distance,
                     struct tw_tilequery_stats *st)
{
    const struct tw_query_backend be = {.ctx = fk, .issue = fake_issue, .ready = fake_ready,
                                        .wait = fake_wait, .draw = fake_draw,
                                        .flush = fake_flush};
    struct tw_view v;
    const float eye[3] = {eye_x, eye_y, eye_z};
    tw_cull_view_setup(&v, (struct tw_cell){0, 0}, eye, 0.0f, pitch, 60.0f, 16.0f / 9.0f, 0.1f,
                       1000.0f);
    v.view_distance = view_distance;
    v.frame = frame;
    fk->eye_y = eye_y;
    fk->eye_z = eye_z;
    fk->queried_count = fk->rendered_count = 0;
    fk->waits = 0;
    fk->flushes = 0;
    fk->unsent_reads = 0;
    fk->frame = frame;
    const struct tw_cull_grid grid = {.footprint = {10.0f, 10.0f}, .common_box = common};
    return tw_tilequery_frame(tq, &v, &be, &grid, render, NULL, fk, st);
}

/* A fake backend (no wall until the test sets one) and a tilequery engine
 * over it; fake_close() frees both, and the fake's tile cache if the test
 * made one. */
static struct fake *fake_open(struct tw_tilequery **tq)
{
    struct fake *fk = calloc(1, sizeof(*fk));
    if (!fk) {
        fprintf(stderr, "test-tilequery: out of memory\n");
        exit(1);
    }
    CHECK(tw_tilequery_create(NULL, tq) == TW_OK);
    return fk;
}

static void fake_close(struct fake *fk, struct tw_tilequery *tq)
{
    tw_tile_cache_destroy(fk->cache);
    tw_tilequery_destroy(tq);
    free(fk);
}

/* A wall too tall to see over, at the far edge of the camera's row: the row
 * behind it is queried and found hidden; nothing beyond is ever queried,
 * rendered or instantiated. */
static void test_stops_behind_occluders(void)
{
    struct tw_tilequery *tq = NULL;
    struct fake *fk = fake_open(&tq);
    CHECK(tw_tile_cache_create(10, &fk->cache) == TW_OK);
    fk->wall_z = 10.0f;
    fk->wall_h = 1000.0f;
    struct tw_tilequery_stats st;
    for (uint64_t f = 1; f <= 5; f++) {
        CHECK(run_frame(tq, fk, f, 5.0f, 1.7f, 5.0f, 0.0f, 200.0f, &st) == TW_OK);
        CHECK(was_rendered(fk, (struct tw_cell){0, 0}));
        CHECK(was_queried(fk, (struct tw_cell){0, 1}));
        CHECK(!was_rendered(fk, (struct tw_cell){0, 1}));
        for (uint32_t k = 0; k < fk->queried_count; k++)
            CHECK(fk->queried[k].j <= 1);
        for (uint32_t k = 0; k < fk->rendered_count; k++)
            CHECK(fk->rendered[k].j <= 0);
        CHECK(st.tiles_visible == fk->rendered_count);
        CHECK(st.tiles_queried == fk->queried_count);
        /* Frame 1 has no prediction to fail; after that the view is steady. */
        CHECK(st.predict_fail == 0);
    }
    /* Only rendered cells were instantiated. */
    CHECK(tw_tile_cache_count(fk->cache) == fk->rendered_count);
    struct tw_tile_handle h;
    CHECK(!tw_tile_cache_find(fk->cache, (struct tw_cell){0, 1}, &h));
    CHECK(!tw_tile_cache_find(fk->cache, (struct tw_cell){0, 3}, &h));
    /* Without the wall, propagation reaches the view distance and no further. */
    fk->wall_h = 0.0f;
    CHECK(run_frame(tq, fk, 6, 5.0f, 1.7f, 5.0f, 0.0f, 200.0f, &st) == TW_OK);
    bool far_row = false;
    for (uint32_t k = 0; k < fk->rendered_count; k++) {
        far_row |= fk->rendered[k].j >= 15;
        CHECK(fk->rendered[k].j <= 21);
    }
    CHECK(far_row);
    fake_close(fk, tq);
}

/* The paper's Figure 7: a low tile (2 m) at j = 1 behind a 10 m wall, a tall
 * tile (20 m) at j = 2 behind it; the camera rises. The tall tile's top
 * shows over the wall once the eye is above 5 m, while the low tile's own
 * box stays hidden until 14 m: propagation through per-tile boxes would stop
 * at j = 1 and the tall tile would pop in late. Through the common box
 * (20 m high everywhere) the tall tile is drawn the first frame it shows. */
static void test_figure7_no_late_tiles(void)
{
    struct tw_tilequery *tq = NULL;
    struct fake *fk = fake_open(&tq);
    fk->wall_z = 10.0f;
    fk->wall_h = 10.0f;
    fk->delay = 1;
    const struct tw_box low_own = {{0, 0, 10}, {10, 2, 20}};
    const struct tw_box tall_own = {{0, 0, 20}, {10, 20, 30}};
    const float zero[3] = {0, 0, 0};
    uint32_t frames_where_it_matters = 0;
    uint64_t f = 1;
    for (float h = 1.0f; h <= 20.0f; h += 0.25f, f++) {
        struct tw_tilequery_stats st;
        CHECK(run_frame(tq, fk, f, 5.0f, h, 5.0f, 0.0f, 28.0f, &st) == TW_OK);
        fk->eye_y = h;
        const bool tall_shows = box_visible(fk, &tall_own, zero);
        const bool low_shows = box_visible(fk, &low_own, zero);
        if (tall_shows && !low_shows)
            frames_where_it_matters++;
        if (tall_shows)
            CHECK(was_rendered(fk, (struct tw_cell){0, 2}));
    }
    CHECK(frames_where_it_matters > 10);
    fake_close(fk, tq);
}

/* Postponed queries: a cell visible last frame whose result is not back is
 * drawn at once; its query is read at the end of the frame, and a negative
 * answer makes it invisible next frame (queried and waited on before it is
 * drawn), counted as a prediction failure. */
static void test_postponed(void)
{
    struct tw_tilequery *tq = NULL;
    struct fake *fk = fake_open(&tq);
    fk->wall_z = 10.0f;
    fk->wall_h = 0.0f;             /* nothing hidden */
    fk->delay = 1;                 /* the first poll says not ready, the second ready */
    struct tw_tilequery_stats st;
    CHECK(run_frame(tq, fk, 1, 5.0f, 1.7f, 5.0f, 0.0f, 40.0f, &st) == TW_OK);
    CHECK(st.postponed == 0);      /* nothing was visible before: every result waited on */
    CHECK(st.waits == st.tiles_queried);
    CHECK(was_rendered(fk, (struct tw_cell){0, 3}));
    /* Frame 2: the same view; every queried cell was visible, so none is waited on. */
    CHECK(run_frame(tq, fk, 2, 5.0f, 1.7f, 5.0f, 0.0f, 40.0f, &st) == TW_OK);
    CHECK(st.postponed == st.tiles_queried);
    CHECK(st.waits == 0);
    CHECK(st.predict_fail == 0);
    const uint32_t visible2 = st.tiles_visible;
    /* Frame 3: a tall wall appears. Cells beyond it are still drawn (last
     * frame's word), their queries read at the frame's end say hidden. */
    fk->wall_h = 1000.0f;
    CHECK(run_frame(tq, fk, 3, 5.0f, 1.7f, 5.0f, 0.0f, 40.0f, &st) == TW_OK);
    CHECK(was_rendered(fk, (struct tw_cell){0, 1}));
    CHECK(st.predict_fail > 0);
    CHECK(tw_tilequery_was_visible(tq, (struct tw_cell){0, 0}, 3));
    CHECK(!tw_tilequery_was_visible(tq, (struct tw_cell){0, 1}, 3));
    CHECK(st.tiles_visible == visible2);
    /* Frame 4: they are waited on, found hidden, not drawn. */
    CHECK(run_frame(tq, fk, 4, 5.0f, 1.7f, 5.0f, 0.0f, 40.0f, &st) == TW_OK);
    CHECK(!was_rendered(fk, (struct tw_cell){0, 1}));
    CHECK(was_queried(fk, (struct tw_cell){0, 1}));
    CHECK(st.waits > 0);
    /* Results that never become ready by the frame's end: drained next frame,
     * never read twice (the fake checks). */
    fk->wall_h = 0.0f;
    fk->delay = -1;
    for (uint64_t f = 5; f <= 8; f++)
        CHECK(run_frame(tq, fk, f, 5.0f, 1.7f, 5.0f, 0.0f, 40.0f, &st) == TW_OK);
    fake_close(fk, tq);
}

/* Propagation goes a wavefront at a time: every query of a wavefront is
 * issued before the one flush that sends them all, and read after it, so a
 * frame flushes once per wavefront (the rings of cells around the start,
 * with 4 neighbours: a cell k steps away is in the k-th), not once per tile,
 * and never reads a query that no flush has sent. The backend here has no
 * draw_if (NULL), as a GL without conditional rendering. */
static void test_one_flush_per_wavefront(void)
{
    struct tw_tilequery *tq = NULL;
    struct fake *fk = fake_open(&tq);
    fk->wall_z = 25.0f;
    fk->wall_h = 3.0f;
    fk->delay = 2;
    struct tw_tilequery_stats st;
    for (uint64_t f = 1; f <= 4; f++) {
        CHECK(run_frame(tq, fk, f, 5.0f, 1.7f, 5.0f, 0.0f, 60.0f, &st) == TW_OK);
        CHECK(st.tiles_queried > 10);
        CHECK(fk->flushes == st.fronts);
        CHECK(fk->unsent_reads == 0);
        /* The farthest ring reached, in steps from the start cell (0, 0). */
        int64_t rings = 0;
        for (uint32_t k = 0; k < fk->queried_count; k++) {
            const int64_t steps = llabs(fk->queried[k].i) + llabs(fk->queried[k].j);
            rings = steps > rings ? steps : rings;
        }
        CHECK_MSG(st.fronts == (uint32_t)rings, "frame %d: %u flushes, %d rings", (int)f,
                  st.fronts, (int)rings);
        CHECK(st.fronts < st.tiles_queried);
    }
    fake_close(fk, tq);
}

/* The camera's cell, and a neighbour whose common box the eye is within
 * near-plane reach of, are visible without a query. */
static void test_near_plane_rule(void)
{
    struct tw_tilequery *tq = NULL;
    struct fake *fk = fake_open(&tq);
    fk->wall_z = 10.0f;
    fk->wall_h = 1000.0f;          /* every query would say hidden */
    struct tw_tilequery_stats st;
    /* At x = 0.05, the eye is 0.05 m from cell (-1, 0)'s box. */
    CHECK(run_frame(tq, fk, 1, 0.05f, 1.7f, 5.0f, 0.0f, 100.0f, &st) == TW_OK);
    CHECK(!was_queried(fk, (struct tw_cell){0, 0}));
    CHECK(!was_queried(fk, (struct tw_cell){-1, 0}));
    CHECK(was_rendered(fk, (struct tw_cell){0, 0}));
    CHECK(was_rendered(fk, (struct tw_cell){-1, 0}));
    CHECK(st.tiles_free >= 2);
    fake_close(fk, tq);
}

/* 20 000 frames straight ahead through rows of walls: the tile cache and the
 * engine keep to what is visible, not to how far the camera went. */
static void test_memory_bounded(void)
{
    struct tw_tilequery *tq = NULL;
    struct fake *fk = fake_open(&tq);
    CHECK(tw_tile_cache_create(30, &fk->cache) == TW_OK);
    fk->wall_h = 8.0f;
    uint64_t peak_1000 = 0, peak_all = 0;
    size_t engine_1000 = 0, engine_all = 0;
    for (uint64_t f = 1; f <= 20000; f++) {
        const float z = 0.5f * (float)f;
        /* A wall every 40 m, just ahead of the camera. */
        fk->wall_z = 40.0f * floorf(z / 40.0f) + 40.0f;
        struct tw_tilequery_stats st;
        /* The view cell is (0, 0): carry the distance in the offsets. */
        if (run_frame(tq, fk, f, 5.0f, 1.7f, z, 0.0f, 120.0f, &st) != TW_OK) {
            CHECK(!"frame failed");
            break;
        }
        tw_tile_cache_evict(fk->cache, f);
        const uint64_t bytes = tw_tile_cache_bytes(fk->cache);
        const size_t engine = tw_tilequery_bytes(tq);
        if (bytes > peak_all) peak_all = bytes;
        if (engine > engine_all) engine_all = engine;
        if (f == 1000) {
            peak_1000 = peak_all;
            engine_1000 = engine_all;
        }
    }
    CHECK(peak_1000 > 0);
    CHECK(peak_all <= peak_1000 + peak_1000 / 10);
    CHECK(engine_all <= engine_1000 + engine_1000 / 10);
    printf("memory: cache peak %llu B after 1000 frames, %llu B after 20000; engine %zu / %zu B\n",
           (unsigned long long)peak_1000, (unsigned long long)peak_all, engine_1000, engine_all);
    fake_close(fk, tq);
}

/* tw_tilequery_last_cells() (the viewer's Figure 6 view) reports what the
 * frame did: the start cell, cells found visible or hidden, cells drawn on
 * last frame's word; the same cells the fake saw rendered and queried. */
struct cell_log {
    struct tw_cell cell[MAX_LOG];
    enum tw_tilequery_cell_state state[MAX_LOG];
    uint32_t count;
};

static void log_cell(void *user, struct tw_cell cell, enum tw_tilequery_cell_state state)
{
    struct cell_log *l = user;
    if (l->count < MAX_LOG) {
        l->cell[l->count] = cell;
        l->state[l->count++] = state;
    }
}

static int state_of(const struct cell_log *l, struct tw_cell c)
{
    for (uint32_t k = 0; k < l->count; k++)
        if (l->cell[k].i == c.i && l->cell[k].j == c.j)
            return (int)l->state[k];
    return -1;
}

static void test_last_cells(void)
{
    struct tw_tilequery *tq = NULL;
    struct fake *fk = fake_open(&tq);
    struct cell_log *l = calloc(1, sizeof(*l));
    fk->wall_z = 10.0f;
    fk->wall_h = 1000.0f;
    struct tw_tilequery_stats st;
    CHECK(run_frame(tq, fk, 1, 5.0f, 1.7f, 5.0f, 0.0f, 200.0f, &st) == TW_OK);
    tw_tilequery_last_cells(tq, log_cell, l);
    CHECK(l->count > 0 && l->state[0] == TW_TILEQUERY_CELL_START);
    CHECK(state_of(l, (struct tw_cell){0, 0}) == TW_TILEQUERY_CELL_START);
    CHECK(state_of(l, (struct tw_cell){0, 1}) == TW_TILEQUERY_CELL_OCCLUDED);
    CHECK(state_of(l, (struct tw_cell){0, 2}) == -1);
    uint32_t drawn = 0, queried = 0;
    for (uint32_t k = 0; k < l->count; k++) {
        const enum tw_tilequery_cell_state s = l->state[k];
        drawn += s != TW_TILEQUERY_CELL_OCCLUDED;
        queried += s == TW_TILEQUERY_CELL_VISIBLE || s == TW_TILEQUERY_CELL_OCCLUDED ||
                   s == TW_TILEQUERY_CELL_POSTPONED;
        CHECK(s == TW_TILEQUERY_CELL_OCCLUDED ? !was_rendered(fk, l->cell[k])
                                              : was_rendered(fk, l->cell[k]));
    }
    CHECK(drawn == st.tiles_visible);
    CHECK(queried == st.tiles_queried);
    /* Nothing hidden, results late: frame 3 draws on frame 2's word. */
    fk->wall_h = 0.0f;
    fk->delay = 1;
    CHECK(run_frame(tq, fk, 2, 5.0f, 1.7f, 5.0f, 0.0f, 40.0f, &st) == TW_OK);
    CHECK(run_frame(tq, fk, 3, 5.0f, 1.7f, 5.0f, 0.0f, 40.0f, &st) == TW_OK);
    CHECK(st.postponed > 0);
    l->count = 0;
    tw_tilequery_last_cells(tq, log_cell, l);
    uint32_t postponed = 0;
    for (uint32_t k = 0; k < l->count; k++)
        postponed += l->state[k] == TW_TILEQUERY_CELL_POSTPONED;
    CHECK(postponed == st.postponed);
    CHECK(state_of(l, (struct tw_cell){0, 3}) == TW_TILEQUERY_CELL_POSTPONED);
    free(l);
    fake_close(fk, tq);
}

int main(void)
{
    test_stops_behind_occluders();
    test_figure7_no_late_tiles();
    test_postponed();
    test_near_plane_rule();
    test_one_flush_per_wavefront();
    test_memory_bounded();
    test_last_cells();
    return check_summary("test-tilequery");
}
