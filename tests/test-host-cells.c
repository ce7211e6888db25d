/*
 * What a world generator says about its cells (tiles.h, runtime.h): empty
 * cells (TW_TILE_EMPTY from a selection or content(), TW_GENERATE_EMPTY from
 * generate()) show nothing, cost no error and let visibility through; a
 * refused cell's event carries the error and the provider's own message, is
 * asked for again on the retry policy's schedule, and by the host
 * (tw_world_retry_cell); a runaway tile is refused by the caps, naming the
 * cell and the cap.
 */
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tests/captured-log.h"
#include "tests/check.h"
#include "tests/meshes.h"
#include "tileworld/context.h"
#include "tileworld/runtime.h"
#include "tileworld/tilesets.h"

enum { W = 192, H = 108 };
#define FOOTPRINT 32.0f

/* Looking along +z from the sea (rows j = 1 .. sea_last) to the land
 * beyond: visibility has to cross the empty cells, the camera's own first. */
static const struct tw_camera cam = {{{0, 1}, {16.0f, 6.0f, 1.0f}}, 0.0f, -2.0f};
static int64_t sea_last = 3;

static bool sea(struct tw_cell c)
{
    return c.j >= 1 && c.j <= sea_last;
}

/* ---- a provider: sea, cells it finds empty, failing cells, a runaway cell ---------- */

static const struct tw_cell flaky = {1, 6};     /* fails twice, then works */
static const struct tw_cell broken = {-1, 6};   /* always fails */
static const struct tw_cell runaway = {0, 8};   /* too many triangles */

struct world_gen {
    atomic_uint flaky_calls, broken_calls, runaway_calls;
};

static uint32_t gen_content(void *user, struct tw_cell cell)
{
    (void)user;
    return sea(cell) ? TW_TILE_EMPTY : TW_TILE_OWN;
}

static bool same(struct tw_cell a, struct tw_cell b)
{
    return a.i == b.i && a.j == b.j;
}

static int gen_generate(void *user, struct tw_cell cell, struct tw_tileset *ts)
{
    struct world_gen *g = user;
    if (cell.j == 5)
        return TW_GENERATE_EMPTY;   /* a row the generator finds empty once it looks */
    if (same(cell, flaky) && atomic_fetch_add(&g->flaky_calls, 1) < 2)
        return tw_tileset_fail(ts, TW_ERR_IO, "height field %lld_%lld.raw: %s",
                               (long long)cell.i, (long long)cell.j, "connection reset");
    if (same(cell, broken)) {
        atomic_fetch_add(&g->broken_calls, 1);
        return tw_tileset_fail(ts, TW_ERR_FORMAT, "biome table has no entry %d", 42);
    }
    const int mat = tw_tileset_add_material(
        ts, (const float[4]){0.3f + 0.1f * (float)((uint64_t)cell.i % 5), 0.5f, 0.4f, 1.0f});
    const int proto = tw_tileset_add_prototype(ts, "block", 1.0f);
    const int cube = add_cube(ts);
    const int ground = add_grid(ts, same(cell, runaway) ? 40 : 4, FOOTPRINT, false);
    if (same(cell, runaway))
        atomic_fetch_add(&g->runaway_calls, 1);
    if (mat < 0 || proto < 0 || cube < 0 || ground < 0)
        return TW_ERR_NOMEM;
    const float t[12] = {12, 0, 0, 10, 0, 4.0f + 2.0f * (float)((uint64_t)cell.j % 4), 0, 0,
                         0, 0, 12, 10};
    if (tw_tileset_add_instance(ts, (uint32_t)proto, (uint32_t)ground, (uint32_t)mat, NULL) < 0 ||
        tw_tileset_add_instance(ts, (uint32_t)proto, (uint32_t)cube, (uint32_t)mat, t) < 0)
        return TW_ERR_NOMEM;
    return TW_OK;
}

static const struct tw_tile_event *find_event(struct tw_world *w, struct tw_cell cell,
                                              enum tw_tile_event_kind kind)
{
    size_t n;
    const struct tw_tile_event *ev = tw_world_tile_events(w, &n);
    for (size_t k = 0; k < n; k++)
        if (same(ev[k].cell, cell) && ev[k].kind == kind)
            return &ev[k];
    return NULL;
}

/* ---- a host's selection with sea --------------------------------------------------- */

static uint32_t select_with_sea(void *user, struct tw_cell cell)
{
    const struct tw_tileset *ts = user;
    return sea(cell) ? TW_TILE_EMPTY
                     : (uint32_t)(tw_tiles_hash(7, cell.i, cell.j) % ts->prototype_count);
}

/* Every method over the sea: nothing missed (visibility crossed the empty
 * cells to the land beyond), something drawn beyond, no error. */
static void every_method(struct tw_world *w, struct log_lines *lines, const char *what,
                         bool no_errors)
{
    const unsigned errors = lines->errors;
    for (int m = TW_METHOD_FIRST; m < TW_METHOD_COUNT; m++) {
        CHECK(tw_world_set_method(w, (enum tw_method)m) == TW_OK);
        struct tw_frame_stats st = {0};
        for (int f = 0; f < 3; f++)
            CHECK(tw_world_frame(w, &cam, &st) == TW_OK);
        size_t n;
        const struct tw_drawn_cluster *d = tw_world_drawn(w, &n);
        bool beyond = false;    /* land past the sea drawn */
        for (size_t k = 0; k < n; k++) {
            CHECK(!sea(d[k].cell));
            beyond |= d[k].cell.j > sea_last;
        }
        CHECK_MSG(st.missed_pixels == 0 && beyond,
                  "%s, %s: %llu missed pixels, land beyond the sea %s", what,
                  tw_method_name((enum tw_method)m), (unsigned long long)st.missed_pixels,
                  beyond ? "drawn" : "not drawn");
    }
    CHECK_MSG(!no_errors || lines->errors == errors, "%s: %u errors, last: %s", what,
              lines->errors - errors, lines->last);
}

int main(void)
{
    struct log_lines lines = {.lock = PTHREAD_MUTEX_INITIALIZER};
    const struct tw_log log = {log_line, &lines};
    struct tw_context *ctx = NULL;
    struct tw_tileset *city = NULL;
    if (tw_context_create_headless(W, H, &log, &ctx) != TW_OK ||
        tw_tilesets_builtin("city", 2, 0, &log, &city) != TW_OK) {
        fprintf(stderr, "cannot create the context or the city\n");
        return 1;
    }
    struct tw_world_settings base = {0};
    base.width = W;
    base.height = H;
    base.view_distance = 300.0f;
    base.deterministic = true;
    base.verify = true;
    base.workers = 2;
    base.get_proc = tw_context_get_proc(ctx);
    base.log = log;

    /* Defaults of the caps and of the retries. */
    struct tw_world_settings d = {.cache_budget_bytes = 6u << 20};
    tw_world_default_settings(&d);
    CHECK(d.max_tile_triangles == TW_MAX_TILE_TRIANGLES);
    CHECK(d.max_tile_bytes == (6u << 20) / 4);
    CHECK(d.retry_after_frames == 30 && d.retry_max == 4);
    d = (struct tw_world_settings){0};
    tw_world_default_settings(&d);
    CHECK(d.max_tile_bytes == TW_MAX_TILE_BYTES);

    /* A selection with sea: the city across it (80 m cells). */
    sea_last = 2;
    struct tw_world_settings s = base;
    s.tileset = city;
    s.selection.fn = select_with_sea;
    s.selection.user = city;
    struct tw_world *w = NULL;
    CHECK(tw_world_create(&s, &w) == TW_OK);
    if (w) {
        tw_world_record_draws(w, true);
        every_method(w, &lines, "selection", true);
    }
    tw_world_destroy(w);

    /* A provider with sea (32 m cells), empty rows, failing cells and a
     * runaway one. */
    sea_last = 3;
    struct world_gen gen = {0};
    const struct tw_tile_provider provider = {
        .name = "coast",
        .footprint = {FOOTPRINT, FOOTPRINT},
        .bound = {{0.0f, -1.0f, 0.0f}, {FOOTPRINT, 20.0f, FOOTPRINT}},
        .content = gen_content,
        .generate = gen_generate,
        .user = &gen,
    };
    s = base;
    s.provider = &provider;
    s.retry_after_frames = 2;
    s.retry_max = 3;
    s.max_tile_triangles = 2000;    /* the runaway cell has 3 212 */
    s.max_screen_error = TW_FULL_DETAIL;    /* frames counted as the stream counts them */
    w = NULL;
    CHECK(tw_world_create(&s, &w) == TW_OK);
    if (!w)
        return check_summary("test-host-cells");
    tw_world_record_draws(w, true);
    unsigned errors = lines.errors;
    struct tw_frame_stats st;
    CHECK(tw_world_frame(w, &cam, &st) == TW_OK);
    CHECK(st.missed_pixels == 0 && st.tiles_visible > 0);

    /* Refusals, with their cause. */
    const struct tw_tile_event *e = find_event(w, flaky, TW_TILE_REFUSED);
    CHECK(e && e->error == TW_ERR_IO && e->attempt == 1 && e->retry_in == 2);
    CHECK_MSG(e && strstr(e->message, "height field 1_6.raw: connection reset"), "%s",
              e ? e->message : "no event");
    e = find_event(w, broken, TW_TILE_REFUSED);
    CHECK(e && e->error == TW_ERR_FORMAT && strstr(e->message, "biome table has no entry 42"));
    e = find_event(w, runaway, TW_TILE_REFUSED);
    CHECK(e && e->error == TW_ERR_LIMIT && strstr(e->message, "3212 triangles") &&
          strstr(e->message, "cap of 2000") && strstr(e->message, "max_tile_triangles"));
    /* Empty cells: a READY event that says so, no refusal, no error. */
    e = find_event(w, (struct tw_cell){0, 5}, TW_TILE_READY);
    CHECK(e && e->empty && e->bytes == 0);
    CHECK(!find_event(w, (struct tw_cell){0, 5}, TW_TILE_REFUSED));
    CHECK(!find_event(w, (struct tw_cell){0, 2}, TW_TILE_REFUSED));
    CHECK_MSG(lines.errors - errors == 3, "%u errors", lines.errors - errors);
    CHECK(strstr(lines.last, "cell (") != NULL);
    struct tw_cache_totals totals;
    CHECK(tw_world_cache_totals(w, &totals) == TW_OK && totals.refused == 3);

    /* The schedule: asked again 2, 4 and 8 frames after each refusal (the
     * flaky cell works on its third call); the broken one stops after its
     * fourth refusal (retry_max 3); the runaway cell likewise. */
    uint64_t broken_frames[8] = {0}, flaky_ready = 0;
    uint32_t broken_count = 0;
    broken_frames[broken_count++] = st.frame;
    for (int f = 0; f < 24; f++) {
        CHECK(tw_world_frame(w, &cam, &st) == TW_OK);
        CHECK(st.missed_pixels == 0);
        if (find_event(w, flaky, TW_TILE_READY))
            flaky_ready = st.frame;
        e = find_event(w, broken, TW_TILE_REFUSED);
        if (e && broken_count < 8) {
            CHECK(e->attempt == broken_count + 1);
            broken_frames[broken_count++] = st.frame;
            CHECK(e->retry_in == (e->attempt <= 3 ? 2u << (e->attempt - 1) : 0));
        }
    }
    CHECK_MSG(flaky_ready == 1 + 2 + 4, "flaky cell ready in frame %llu",
              (unsigned long long)flaky_ready);
    CHECK(atomic_load(&gen.flaky_calls) == 3);
    CHECK_MSG(broken_count == 4 && broken_frames[1] == 3 && broken_frames[2] == 7 &&
                  broken_frames[3] == 15,
              "%u refusals, frames %llu %llu %llu %llu", broken_count,
              (unsigned long long)broken_frames[0], (unsigned long long)broken_frames[1],
              (unsigned long long)broken_frames[2], (unsigned long long)broken_frames[3]);
    CHECK(atomic_load(&gen.broken_calls) == 4);
    CHECK(atomic_load(&gen.runaway_calls) == 4);

    /* The host asks for it again: one more call, whatever the policy. */
    CHECK(tw_world_retry_cell(w, broken) == TW_OK);
    CHECK(tw_world_retry_cell(w, (struct tw_cell){0, 4}) == TW_OK);   /* not refused: nothing */
    CHECK(tw_world_frame(w, &cam, &st) == TW_OK);
    e = find_event(w, broken, TW_TILE_REFUSED);
    CHECK(e && e->attempt == 1 && atomic_load(&gen.broken_calls) == 5);
    CHECK(!find_event(w, (struct tw_cell){0, 4}, TW_TILE_READY));
    every_method(w, &lines, "provider", false);   /* the broken cell still fails */
    tw_world_destroy(w);

    /* A byte cap: every own tile refused, naming the cap. */
    s.max_tile_triangles = 0;
    s.max_tile_bytes = 4096;
    s.retry_after_frames = TW_NEVER_RETRY;
    w = NULL;
    CHECK(tw_world_create(&s, &w) == TW_OK);
    if (w) {
        CHECK(tw_world_frame(w, &cam, &st) == TW_OK);
        e = find_event(w, (struct tw_cell){0, 4}, TW_TILE_REFUSED);
        CHECK(e && e->error == TW_ERR_LIMIT && strstr(e->message, "max_tile_bytes") &&
              e->retry_in == 0);
        CHECK_MSG(st.triangles == 0, "%llu triangles drawn", (unsigned long long)st.triangles);
    }
    tw_world_destroy(w);

    tw_tileset_destroy(city);
    tw_context_destroy(ctx);
    return check_summary("test-host-cells");
}
