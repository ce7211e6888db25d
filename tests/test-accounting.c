/*
 * The tile cache's byte accounting (DESIGN §13), headless GL, with
 * the built-in city-gen provider under a budget that forces evictions: the
 * bytes added and removed per tile add up exactly.
 *   - every READY event is a cell not already held, every EVICTED event
 *     frees exactly the bytes its READY event said;
 *   - on every frame, the tiles and bytes that tw_world_cache_totals()
 *     reports live are the sum of ready less evicted, and its counters are
 *     the events' counts (loads_done - evictions = tiles ready);
 *   - a tile loaded again after its eviction (the walk turns back) costs
 *     exactly what it cost the first time (the provider is pure);
 *   - the frame's own figures hold the live tiles: bytes_cpu + bytes_gpu >=
 *     tile bytes, and under the budget except by what the frame needed.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tests/check.h"
#include "tiles/tiles-internal.h"
#include "tileworld/context.h"
#include "tileworld/runtime.h"
#include "tileworld/tilesets.h"

enum { W = 96, H = 54, FORWARD = 150, FRAMES = 300 };

int main(void)
{
    struct tw_context *ctx = NULL;
    if (tw_context_create_headless(W, H, NULL, &ctx) != TW_OK) {
        fprintf(stderr, "test-accounting: no headless context\n");
        return 1;
    }
    struct tw_tilesets_provider *gen = NULL;
    CHECK(tw_tilesets_provider_create("city-gen", 5, 0, NULL, &gen) == TW_OK);
    const struct tw_tile_provider *p = tw_tilesets_provider_get(gen);
    struct tw_path path = {0};
    CHECK(p && tw_path_builtin("straight", 5, FORWARD, 0.0f, p->footprint[0],
                                     p->footprint[1], &path) == TW_OK);
    const uint64_t budget = 24u << 20;
    struct tw_world_settings s = {0};
    s.provider = p;
    s.workers = 2;
    s.cache_budget_bytes = budget;
    s.width = W;
    s.height = H;
    s.view_distance = 400.0f;
    s.get_proc = tw_context_get_proc(ctx);
    struct tw_world *w = NULL;
    CHECK(path.count == FORWARD && tw_world_create(&s, &w) == TW_OK);
    struct tw_cell_map *live = NULL, *first_bytes = NULL;
    CHECK(tw_cell_map_create(&live) == TW_OK && tw_cell_map_create(&first_bytes) == TW_OK);
    if (!w || !live || !first_bytes)
        return 1;

    uint64_t live_bytes = 0, ready = 0, evicted = 0, reloads = 0, reload_flags = 0;
    uint32_t mismatched = 0, over_beyond_need = 0, busy_frames = 0;
    for (uint32_t f = 0; f < FRAMES; f++) {
        /* Out along the street, then back the same way, looking back. */
        struct tw_camera cam = path.keys[f < FORWARD ? f : 2 * FORWARD - 1 - f];
        if (f >= FORWARD)
            cam.yaw += 180.0f;
        struct tw_frame_stats st;
        CHECK(tw_world_frame(w, &cam, &st) == TW_OK);
        CHECK(tw_world_finish(w, &st) == TW_OK);
        /* After the finish: between frames the loading count can only fall,
         * so loading now means loading when the finish looked. */
        struct tw_cache_totals busy;
        CHECK(tw_world_cache_totals(w, &busy) == TW_OK);
        if (st.loads_done > 0 || busy.tiles_loading > 0) {
            busy_frames++;
        }
        size_t n = 0;
        const struct tw_tile_event *e = tw_world_tile_events(w, &n);
        for (size_t k = 0; k < n; k++) {
            if (e[k].kind == TW_TILE_READY) {
                CHECK(tw_cell_map_find(live, e[k].cell) == NULL);
                CHECK(e[k].bytes > 0);
                tw_cell_map_set(live, e[k].cell, e[k].bytes);
                live_bytes += e[k].bytes;
                ready++;
                reload_flags += e[k].reload;
                const uint64_t *before = tw_cell_map_find(first_bytes, e[k].cell);
                if (before) {
                    /* The same cell, the same tile: the same bytes. */
                    CHECK(*before == e[k].bytes);
                    reloads++;
                } else {
                    tw_cell_map_set(first_bytes, e[k].cell, e[k].bytes);
                }
            } else if (e[k].kind == TW_TILE_EVICTED) {
                const uint64_t *b = tw_cell_map_find(live, e[k].cell);
                CHECK(b != NULL && *b == e[k].bytes);
                if (b) {
                    live_bytes -= *b;
                    tw_cell_map_remove(live, e[k].cell);
                }
                evicted++;
            } else {
                CHECK(!"a city-gen tile was refused");
            }
        }
        struct tw_cache_totals t;
        CHECK(tw_world_cache_totals(w, &t) == TW_OK);
        const bool same = t.tiles_ready == tw_cell_map_count(live) && t.tile_bytes == live_bytes &&
                          t.loads_done == ready && t.evictions == evicted &&
                          t.tiles_ready + t.evictions == t.loads_done && t.reloads == reload_flags;
        if (!same && mismatched++ < 5)
            fprintf(stderr, "frame %u: totals %u tiles, %llu bytes, %llu loads, %llu evictions; "
                    "events %zu tiles, %llu bytes, %llu loads, %llu evictions\n", f,
                    t.tiles_ready, (unsigned long long)t.tile_bytes,
                    (unsigned long long)t.loads_done, (unsigned long long)t.evictions,
                    tw_cell_map_count(live), (unsigned long long)live_bytes,
                    (unsigned long long)ready, (unsigned long long)evicted);
        const uint64_t total = st.bytes_cpu + st.bytes_gpu;
        CHECK(total >= t.tile_bytes);
        over_beyond_need += total > budget && total > st.bytes_needed;
    }
    CHECK(mismatched == 0);
    CHECK(busy_frames > 0);
    CHECK(over_beyond_need == 0);
    CHECK(evicted > 0);
    CHECK(reloads > 0);
    /* The library remembers evictions for a while only: its reloads are
     * among the test's, which remembers every one. */
    CHECK(reload_flags <= reloads);
    printf("accounting: %llu tiles ready, %llu evicted, %llu reloaded (%llu flagged by the "
           "library), %zu live, %llu bytes live; %u frames where the totals differed\n",
           (unsigned long long)ready, (unsigned long long)evicted, (unsigned long long)reloads,
           (unsigned long long)reload_flags, tw_cell_map_count(live),
           (unsigned long long)live_bytes, mismatched);
    tw_world_destroy(w);
    tw_cell_map_destroy(live);
    tw_cell_map_destroy(first_bytes);
    tw_path_finish(&path);
    tw_tilesets_provider_destroy(gen);
    tw_context_destroy(ctx);
    return check_summary("test-accounting");
}
